//! The harness side of FMI 2.0 Model Exchange: the legality table of the
//! model-exchange state machine (FMI 2.0.4 §3.2.3, written from the standard).
//!
//! The importer side (instantiation for Model Exchange, the ten Model Exchange
//! calls on an [`Instance`](crate::Instance), the state vector that
//! modelDescription declares and a fixed-step integrator) lives in
//! `fmi2_import::model_exchange`; its free items are re-exported here under
//! the names the checks and the fuzzer use.

pub use fmi2_import::model_exchange::{EventInfo, state_of, state_references};

use crate::State;

/// The Model Exchange functions (FMI 2.0.4 §3.2.2), from the layer's one
/// list of FMI functions.
pub use fmi2_cosim::functions::MODEL_EXCHANGE_FUNCTIONS;

/// Whether `function` belongs to a co-simulation slave only: never legal on a
/// model-exchange instance.
fn co_simulation_only(function: &str) -> bool {
    fmi2_cosim::functions::by_name(function)
        .is_some_and(|f| f.interfaces == fmi2_cosim::functions::Interfaces::CoSimulation)
}

/// Whether the standard allows `function` on a model-exchange instance in
/// `state` (FMI 2.0.4 §3.2.3, the table of the model-exchange state machine).
/// Written from the standard, not from the layer under test.
pub fn allowed_in_model_exchange(function: &str, state: State) -> bool {
    use State::*;
    if co_simulation_only(function) {
        return false;
    }
    let live: &[State] = &[
        Instantiated,
        InitializationMode,
        EventMode,
        ContinuousTimeMode,
        Terminated,
        Error,
    ];
    let states: &[State] = match function {
        "fmi2SetDebugLogging"
        | "fmi2Reset"
        | "fmi2GetFMUstate"
        | "fmi2SetFMUstate"
        | "fmi2FreeFMUstate"
        | "fmi2SerializedFMUstateSize"
        | "fmi2SerializeFMUstate"
        | "fmi2DeSerializeFMUstate" => live,
        "fmi2SetupExperiment" | "fmi2EnterInitializationMode" => &[Instantiated],
        "fmi2ExitInitializationMode" => &[InitializationMode],
        "fmi2Terminate" => &[EventMode, ContinuousTimeMode],
        "fmi2GetReal"
        | "fmi2GetInteger"
        | "fmi2GetBoolean"
        | "fmi2GetString"
        | "fmi2GetDirectionalDerivative"
        | "fmi2GetEventIndicators"
        | "fmi2GetContinuousStates" => &[
            InitializationMode,
            EventMode,
            ContinuousTimeMode,
            Terminated,
            Error,
        ],
        "fmi2SetReal" => &[
            Instantiated,
            InitializationMode,
            EventMode,
            ContinuousTimeMode,
        ],
        "fmi2SetInteger" | "fmi2SetBoolean" | "fmi2SetString" => {
            &[Instantiated, InitializationMode, EventMode]
        }
        "fmi2EnterEventMode" | "fmi2SetTime" => &[EventMode, ContinuousTimeMode],
        "fmi2NewDiscreteStates" | "fmi2EnterContinuousTimeMode" => &[EventMode],
        "fmi2CompletedIntegratorStep" | "fmi2SetContinuousStates" => &[ContinuousTimeMode],
        "fmi2GetDerivatives" => &[EventMode, ContinuousTimeMode, Terminated, Error],
        "fmi2GetNominalsOfContinuousStates" => &[
            Instantiated,
            EventMode,
            ContinuousTimeMode,
            Terminated,
            Error,
        ],
        other => panic!("no model-exchange legality entry for {other}"),
    };
    states.contains(&state)
}

//! The call vocabulary: every instance-taking FMI function the fuzzer calls,
//! as a type, grouped by what their arguments look like, so that choosing a
//! call and making it are one exhaustive `match` each.

use super::*;

/// A type of variable value (`fmi2GetReal` .. `fmi2SetString`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ValueType {
    Real,
    Integer,
    Boolean,
    String,
}

impl ValueType {
    /// The name of the type element in modelDescription (`VariableInfo::kind`).
    pub(super) fn name(self) -> &'static str {
        match self {
            ValueType::Real => "Real",
            ValueType::Integer => "Integer",
            ValueType::Boolean => "Boolean",
            ValueType::String => "String",
        }
    }
}

/// Functions whose only argument is the instance.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Simple {
    EnterInitializationMode,
    Terminate,
    Reset,
    CancelStep,
}

/// The capabilities modelDescription declares absent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum NotOffered {
    GetDirectionalDerivative,
    SetRealInputDerivatives,
    GetRealOutputDerivatives,
}

/// `fmi2GetStatus` and its typed forms.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum StatusQuery {
    Status,
    Real,
    Integer,
    Boolean,
    String,
}

/// The Model Exchange getters of vectors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum VectorGetter {
    Derivatives,
    EventIndicators,
    ContinuousStates,
    Nominals,
}

/// The Model Exchange mode changes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum ModeChange {
    EnterEventMode,
    EnterContinuousTimeMode,
}

/// An instance-taking FMI function.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Function {
    SetDebugLogging,
    SetupExperiment,
    ExitInitializationMode,
    Simple(Simple),
    Get(ValueType),
    Set(ValueType),
    GetFmuState,
    SetFmuState,
    FreeFmuState,
    SerializedFmuStateSize,
    SerializeFmuState,
    DeSerializeFmuState,
    NotOffered(NotOffered),
    DoStep,
    StatusQuery(StatusQuery),
    FreeInstance,
    // Model Exchange (FMI 2.0.4 §3.2.2).
    ModeChange(ModeChange),
    NewDiscreteStates,
    CompletedIntegratorStep,
    SetTime,
    SetContinuousStates,
    GetVector(VectorGetter),
}

impl Function {
    /// The C name, as the standard and the FMU's log spell it.
    pub(super) fn name(self) -> &'static str {
        use Function as F;
        match self {
            F::SetDebugLogging => "fmi2SetDebugLogging",
            F::SetupExperiment => "fmi2SetupExperiment",
            F::ExitInitializationMode => "fmi2ExitInitializationMode",
            F::Simple(Simple::EnterInitializationMode) => "fmi2EnterInitializationMode",
            F::Simple(Simple::Terminate) => "fmi2Terminate",
            F::Simple(Simple::Reset) => "fmi2Reset",
            F::Simple(Simple::CancelStep) => "fmi2CancelStep",
            F::Get(ValueType::Real) => "fmi2GetReal",
            F::Get(ValueType::Integer) => "fmi2GetInteger",
            F::Get(ValueType::Boolean) => "fmi2GetBoolean",
            F::Get(ValueType::String) => "fmi2GetString",
            F::Set(ValueType::Real) => "fmi2SetReal",
            F::Set(ValueType::Integer) => "fmi2SetInteger",
            F::Set(ValueType::Boolean) => "fmi2SetBoolean",
            F::Set(ValueType::String) => "fmi2SetString",
            F::GetFmuState => "fmi2GetFMUstate",
            F::SetFmuState => "fmi2SetFMUstate",
            F::FreeFmuState => "fmi2FreeFMUstate",
            F::SerializedFmuStateSize => "fmi2SerializedFMUstateSize",
            F::SerializeFmuState => "fmi2SerializeFMUstate",
            F::DeSerializeFmuState => "fmi2DeSerializeFMUstate",
            F::NotOffered(NotOffered::GetDirectionalDerivative) => "fmi2GetDirectionalDerivative",
            F::NotOffered(NotOffered::SetRealInputDerivatives) => "fmi2SetRealInputDerivatives",
            F::NotOffered(NotOffered::GetRealOutputDerivatives) => "fmi2GetRealOutputDerivatives",
            F::DoStep => "fmi2DoStep",
            F::StatusQuery(StatusQuery::Status) => "fmi2GetStatus",
            F::StatusQuery(StatusQuery::Real) => "fmi2GetRealStatus",
            F::StatusQuery(StatusQuery::Integer) => "fmi2GetIntegerStatus",
            F::StatusQuery(StatusQuery::Boolean) => "fmi2GetBooleanStatus",
            F::StatusQuery(StatusQuery::String) => "fmi2GetStringStatus",
            F::FreeInstance => "fmi2FreeInstance",
            F::ModeChange(ModeChange::EnterEventMode) => "fmi2EnterEventMode",
            F::ModeChange(ModeChange::EnterContinuousTimeMode) => "fmi2EnterContinuousTimeMode",
            F::NewDiscreteStates => "fmi2NewDiscreteStates",
            F::CompletedIntegratorStep => "fmi2CompletedIntegratorStep",
            F::SetTime => "fmi2SetTime",
            F::SetContinuousStates => "fmi2SetContinuousStates",
            F::GetVector(VectorGetter::Derivatives) => "fmi2GetDerivatives",
            F::GetVector(VectorGetter::EventIndicators) => "fmi2GetEventIndicators",
            F::GetVector(VectorGetter::ContinuousStates) => "fmi2GetContinuousStates",
            F::GetVector(VectorGetter::Nominals) => "fmi2GetNominalsOfContinuousStates",
        }
    }
}

/// Co-simulation and common functions, with their weights in the random
/// choice (the order is part of a seed's meaning: keep it).
pub(super) const FUNCTIONS: &[(Function, u32)] = {
    use Function as F;
    &[
        (F::SetDebugLogging, 3),
        (F::SetupExperiment, 5),
        (F::Simple(Simple::EnterInitializationMode), 5),
        (F::ExitInitializationMode, 5),
        (F::Simple(Simple::Terminate), 2),
        (F::Simple(Simple::Reset), 3),
        (F::Get(ValueType::Real), 10),
        (F::Get(ValueType::Integer), 3),
        (F::Get(ValueType::Boolean), 3),
        (F::Get(ValueType::String), 1),
        (F::Set(ValueType::Real), 12),
        (F::Set(ValueType::Integer), 3),
        (F::Set(ValueType::Boolean), 3),
        (F::Set(ValueType::String), 1),
        (F::GetFmuState, 5),
        (F::SetFmuState, 5),
        (F::FreeFmuState, 3),
        (F::SerializedFmuStateSize, 2),
        (F::SerializeFmuState, 4),
        (F::DeSerializeFmuState, 6),
        (F::NotOffered(NotOffered::GetDirectionalDerivative), 1),
        (F::NotOffered(NotOffered::SetRealInputDerivatives), 1),
        (F::NotOffered(NotOffered::GetRealOutputDerivatives), 1),
        (F::DoStep, 16),
        (F::Simple(Simple::CancelStep), 1),
        (F::StatusQuery(StatusQuery::Status), 1),
        (F::StatusQuery(StatusQuery::Real), 2),
        (F::StatusQuery(StatusQuery::Integer), 1),
        (F::StatusQuery(StatusQuery::Boolean), 1),
        (F::StatusQuery(StatusQuery::String), 1),
        (F::FreeInstance, 1),
    ]
};

/// Model Exchange functions and their weights, for an FMU that offers it.
pub(super) const MODEL_EXCHANGE_FUNCTIONS: &[(Function, u32)] = {
    use Function as F;
    &[
        (F::ModeChange(ModeChange::EnterEventMode), 4),
        (F::NewDiscreteStates, 4),
        (F::ModeChange(ModeChange::EnterContinuousTimeMode), 6),
        (F::CompletedIntegratorStep, 6),
        (F::SetTime, 6),
        (F::SetContinuousStates, 6),
        (F::GetVector(VectorGetter::Derivatives), 8),
        (F::GetVector(VectorGetter::EventIndicators), 2),
        (F::GetVector(VectorGetter::ContinuousStates), 4),
        (F::GetVector(VectorGetter::Nominals), 3),
    ]
};

/// Whether the standard allows `function` on an instance of `interface` in
/// `state` (freeing an instance is always allowed).
pub(super) fn legal(interface: Interface, function: Function, state: State) -> bool {
    function == Function::FreeInstance || allowed(interface, function.name(), state)
}

/// The legal calls that bring an instance of `interface` from `state` to where
/// it runs: StepComplete for co-simulation, continuous-time mode for Model
/// Exchange. Empty from a state the interface never reaches.
pub(super) fn path_to_running(interface: Interface, state: State) -> &'static [Function] {
    use Function as F;
    const SETUP: Function = F::SetupExperiment;
    const ENTER: Function = F::Simple(Simple::EnterInitializationMode);
    const EXIT: Function = F::ExitInitializationMode;
    const CONTINUOUS: Function = F::ModeChange(ModeChange::EnterContinuousTimeMode);
    const RESET: Function = F::Simple(Simple::Reset);
    match (interface, state) {
        (Interface::CoSimulation, State::Instantiated) => &[SETUP, ENTER, EXIT],
        (Interface::CoSimulation, State::InitializationMode) => &[EXIT],
        (Interface::CoSimulation, State::Terminated | State::Error) => &[RESET, SETUP, ENTER, EXIT],
        (Interface::ModelExchange, State::Instantiated) => &[SETUP, ENTER, EXIT, CONTINUOUS],
        (Interface::ModelExchange, State::InitializationMode) => &[EXIT, CONTINUOUS],
        (Interface::ModelExchange, State::EventMode) => &[CONTINUOUS],
        (Interface::ModelExchange, State::Terminated | State::Error) => {
            &[RESET, SETUP, ENTER, EXIT, CONTINUOUS]
        }
        (
            Interface::CoSimulation,
            State::StepComplete | State::EventMode | State::ContinuousTimeMode,
        )
        | (Interface::ModelExchange, State::StepComplete | State::ContinuousTimeMode) => &[],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The vocabulary spells every instance-taking function of the layer's
    /// one list, each once, in the interface the list gives it: a function
    /// added to the layer and not to the fuzzer (or misspelled here) fails.
    #[test]
    fn the_vocabulary_is_the_layers_function_list() {
        use fmi2_cosim::functions::{ALL, Interfaces};
        let listed = |interfaces: &[Interfaces]| -> Vec<&'static str> {
            ALL.iter()
                .filter(|f| f.state_checked.is_some() && interfaces.contains(&f.interfaces))
                .map(|f| f.name)
                .collect()
        };
        let mut co_simulation: Vec<_> = FUNCTIONS.iter().map(|(f, _)| f.name()).collect();
        let mut model_exchange: Vec<_> = MODEL_EXCHANGE_FUNCTIONS
            .iter()
            .map(|(f, _)| f.name())
            .collect();
        let mut expected_co_simulation = listed(&[Interfaces::Both, Interfaces::CoSimulation]);
        let mut expected_model_exchange = listed(&[Interfaces::ModelExchange]);
        for list in [
            &mut co_simulation,
            &mut model_exchange,
            &mut expected_co_simulation,
            &mut expected_model_exchange,
        ] {
            list.sort_unstable();
        }
        assert_eq!(co_simulation, expected_co_simulation);
        assert_eq!(model_exchange, expected_model_exchange);
    }
}

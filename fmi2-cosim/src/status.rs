//! Return statuses and the FMI 2.0 state machines as data.
//!
//! Every entry point names an [`FmiFunction`]; each function carries the mask of
//! [`FmiState`]s in which the standard allows it (FMI 2.0.4, section 3.2.3 for
//! Model Exchange, section 4.2.4 for Co-Simulation) and the interface it
//! belongs to. The two machines share their first and last states
//! (Instantiated, InitializationMode, Terminated, Error, Fatal) and agree on
//! every common function there, so one mask per function serves both; a
//! function of one interface called on an instance of the other is refused by
//! [`FmiFunction::interface`]. One check at the top of every entry point
//! compares the instance state with that mask.

use fmi_sys::fmi2 as sys;

use crate::functions;

/// Status returned by an FMI function, ordered by severity.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Status {
    Ok,
    Warning,
    Discard,
    Error,
    Fatal,
}

impl Status {
    pub fn to_raw(self) -> sys::fmi2Status {
        match self {
            Status::Ok => sys::fmi2Status_fmi2OK,
            Status::Warning => sys::fmi2Status_fmi2Warning,
            Status::Discard => sys::fmi2Status_fmi2Discard,
            Status::Error => sys::fmi2Status_fmi2Error,
            Status::Fatal => sys::fmi2Status_fmi2Fatal,
        }
    }

    /// The worse of two statuses: a call that logged a warning and then
    /// succeeded still returns `fmi2Warning`.
    pub fn worst(self, other: Status) -> Status {
        self.max(other)
    }

    pub fn name(self) -> &'static str {
        match self {
            Status::Ok => "fmi2OK",
            Status::Warning => "fmi2Warning",
            Status::Discard => "fmi2Discard",
            Status::Error => "fmi2Error",
            Status::Fatal => "fmi2Fatal",
        }
    }
}

/// The interface an instance was instantiated for (`fmuType` of
/// `fmi2Instantiate`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum Interface {
    ModelExchange,
    CoSimulation,
}

impl Interface {
    pub fn name(self) -> &'static str {
        match self {
            Interface::ModelExchange => "Model Exchange",
            Interface::CoSimulation => "Co-Simulation",
        }
    }

    /// The states only an instance of this interface is ever in
    /// (co-simulation's step states, model exchange's event and
    /// continuous-time modes). The layer keeps every instance in a state of
    /// its own interface or a common one (a restored state of the other
    /// interface is refused), so a state of this set also names the
    /// interface.
    #[inline(always)]
    pub const fn own_states(self) -> StateMask {
        match self {
            Interface::ModelExchange => StateMask::of(&[EventMode, ContinuousTimeMode]),
            Interface::CoSimulation => StateMask::of(&[StepComplete, StepFailed]),
        }
    }
}

/// States of a co-simulation slave (FMI 2.0.4 Fig. 10) and of a model-exchange
/// model (Fig. 6) that an instance of this layer can be in. The standard's
/// `stepInProgress` and `stepCanceled` exist only with asynchronous steps
/// (`fmi2DoStep` returning `fmi2Pending`), which this layer never runs
/// (`canRunAsynchronuously="false"`): they are left out, so that every state
/// here is one an instance reaches (tested).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum FmiState {
    Instantiated,
    InitializationMode,
    StepComplete,
    /// `fmi2DoStep` returned `fmi2Discard`: the step was not completed, the
    /// instance stands at its last successful time (FMI 2.0.4 §4.2.4
    /// `stepFailed`). The importer may read values and the status, restore
    /// an FMU state, terminate or reset.
    StepFailed,
    Terminated,
    Error,
    Fatal,
    /// Model Exchange: discrete states and events are handled here.
    EventMode,
    /// Model Exchange: the importer's integrator advances the continuous states.
    ContinuousTimeMode,
}

impl FmiState {
    /// Whether an instance in this state went through
    /// `fmi2ExitInitializationMode`, which checks the parameters' declared
    /// ranges and builds the model: so its parameters hold their ranges and
    /// the model is built from them. Before it the importer may still be
    /// setting them, and an error state may come from a refused
    /// initialization. What a restored FMU state is checked against
    /// ([`CoSimModel::validate_restored`](crate::CoSimModel::validate_restored)).
    pub const fn initialized(self) -> bool {
        use FmiState::*;
        match self {
            StepComplete | StepFailed | Terminated | EventMode | ContinuousTimeMode => true,
            Instantiated | InitializationMode | Error | Fatal => false,
        }
    }

    /// Every state, in declaration order.
    pub const ALL: [FmiState; 9] = [
        FmiState::Instantiated,
        FmiState::InitializationMode,
        FmiState::StepComplete,
        FmiState::StepFailed,
        FmiState::Terminated,
        FmiState::Error,
        FmiState::Fatal,
        FmiState::EventMode,
        FmiState::ContinuousTimeMode,
    ];

    #[inline(always)]
    const fn bit(self) -> u16 {
        1 << (self as u16)
    }

    pub fn name(self) -> &'static str {
        match self {
            FmiState::Instantiated => "Instantiated",
            FmiState::InitializationMode => "InitializationMode",
            FmiState::StepComplete => "StepComplete",
            FmiState::StepFailed => "StepFailed",
            FmiState::Terminated => "Terminated",
            FmiState::Error => "Error",
            FmiState::Fatal => "Fatal",
            FmiState::EventMode => "EventMode",
            FmiState::ContinuousTimeMode => "ContinuousTimeMode",
        }
    }
}

/// A set of states, as a bit mask.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StateMask(u16);

impl StateMask {
    const fn of(states: &[FmiState]) -> StateMask {
        let mut bits = 0;
        let mut i = 0;
        while i < states.len() {
            bits |= states[i].bit();
            i += 1;
        }
        StateMask(bits)
    }

    #[inline(always)]
    pub const fn contains(self, state: FmiState) -> bool {
        self.0 & state.bit() != 0
    }

    /// Whether every state of this mask is in `other`.
    #[inline(always)]
    pub const fn within(self, other: StateMask) -> bool {
        self.0 & !other.0 == 0
    }
}

use FmiState::*;

/// Everything but the start and the fatal state: where freeing, resetting and
/// FMU-state handling are allowed.
const ANY_LIVE: StateMask = StateMask::of(&[
    Instantiated,
    InitializationMode,
    StepComplete,
    StepFailed,
    Terminated,
    Error,
    EventMode,
    ContinuousTimeMode,
]);
const AFTER_INSTANTIATION: StateMask = StateMask::of(&[
    InitializationMode,
    StepComplete,
    StepFailed,
    Terminated,
    Error,
    EventMode,
    ContinuousTimeMode,
]);
/// fmi2SetReal: inputs in continuous-time mode too (the instance checks
/// which variables).
const REAL_SETTABLE: StateMask = StateMask::of(&[
    Instantiated,
    InitializationMode,
    StepComplete,
    EventMode,
    ContinuousTimeMode,
]);
/// fmi2SetInteger/Boolean/String: discrete values change at events only.
const DISCRETE_SETTABLE: StateMask =
    StateMask::of(&[Instantiated, InitializationMode, StepComplete, EventMode]);
const CS_SETTABLE: StateMask = StateMask::of(&[Instantiated, InitializationMode, StepComplete]);
/// FMI 2.0.4 §4.2.4: the status of a slave can be asked after a step, a
/// discarded step included (that is what fmi2LastSuccessfulTime and
/// fmi2Terminated are for), and after termination.
const STATUS_QUERY: StateMask = StateMask::of(&[StepComplete, StepFailed, Terminated]);
/// Where a model-exchange model's continuous states and event indicators can be
/// read (FMI 2.0.4 §3.2.3).
const ME_READABLE: StateMask = StateMask::of(&[
    InitializationMode,
    EventMode,
    ContinuousTimeMode,
    Terminated,
    Error,
]);

/// How many functions of [`functions::ALL`] take an instance: the length of
/// the state table.
const STATE_TABLE_LEN: usize = {
    let mut count = 0;
    let mut i = 0;
    while i < functions::ALL.len() {
        if functions::ALL[i].state_checked.is_some() {
            count += 1;
        }
        i += 1;
    }
    count
};

/// [`FmiFunction::ALL`] and [`FmiFunction::ENTRY`], built from
/// [`functions::ALL`]. Compilation fails unless the k-th function there that
/// takes an instance is the variant declared k-th: each variant is then
/// listed exactly once, and its name and interface are read from the list.
const fn state_table() -> ([FmiFunction; STATE_TABLE_LEN], [usize; STATE_TABLE_LEN]) {
    let mut functions = [FmiFunction::SetDebugLogging; STATE_TABLE_LEN];
    let mut entries = [0; STATE_TABLE_LEN];
    let mut k = 0;
    let mut i = 0;
    while i < functions::ALL.len() {
        if let Some(function) = functions::ALL[i].state_checked {
            assert!(
                function as usize == k,
                "FmiFunction's variants must be declared in the order of functions::ALL"
            );
            functions[k] = function;
            entries[k] = i;
            k += 1;
        }
        i += 1;
    }
    (functions, entries)
}

/// The FMI 2.0 functions that take an instance, each with its allowed states.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FmiFunction {
    SetDebugLogging,
    FreeInstance,
    SetupExperiment,
    EnterInitializationMode,
    ExitInitializationMode,
    Terminate,
    Reset,
    GetReal,
    GetInteger,
    GetBoolean,
    GetString,
    SetReal,
    SetInteger,
    SetBoolean,
    SetString,
    GetFmuState,
    SetFmuState,
    FreeFmuState,
    SerializedFmuStateSize,
    SerializeFmuState,
    DeSerializeFmuState,
    GetDirectionalDerivative,
    SetRealInputDerivatives,
    GetRealOutputDerivatives,
    DoStep,
    CancelStep,
    GetStatus,
    GetRealStatus,
    GetIntegerStatus,
    GetBooleanStatus,
    GetStringStatus,
    EnterEventMode,
    NewDiscreteStates,
    EnterContinuousTimeMode,
    CompletedIntegratorStep,
    SetTime,
    SetContinuousStates,
    GetDerivatives,
    GetEventIndicators,
    GetContinuousStates,
    GetNominalsOfContinuousStates,
}

impl FmiFunction {
    /// Every function of the table: those of [`functions::ALL`] that take an
    /// instance, in its order, which is also the variants' declaration order
    /// (checked at compile time, so the list of functions is written once,
    /// there).
    pub const ALL: [FmiFunction; STATE_TABLE_LEN] = state_table().0;

    /// Each variant's position in [`functions::ALL`], by discriminant.
    const ENTRY: [usize; STATE_TABLE_LEN] = state_table().1;

    /// The C name (`fmi2DoStep`), from [`functions::ALL`].
    pub const fn name(self) -> &'static str {
        functions::ALL[Self::ENTRY[self as usize]].name
    }

    /// The interface the function belongs to; `None` for the functions
    /// common to both. From [`functions::ALL`]; inlined into every entry
    /// point, where the function is a constant and this folds away.
    #[inline(always)]
    pub const fn interface(self) -> Option<Interface> {
        functions::ALL[Self::ENTRY[self as usize]].interfaces.only()
    }

    /// Whether the function may be called on an instance of `interface` in
    /// `state`. Inlined into every entry point, where the function is a
    /// constant: the check folds to one mask test and one compare. A
    /// function allowed only in its own interface's states (`fmi2DoStep`:
    /// stepComplete) needs no compare of the interface: an instance in one of
    /// those states is of that interface ([`Interface::own_states`]).
    #[inline(always)]
    pub fn allowed(self, interface: Interface, state: FmiState) -> bool {
        self.allowed_states().contains(state)
            && match self.interface() {
                None => true,
                Some(own) if self.allowed_states().within(own.own_states()) => true,
                Some(own) => own == interface,
            }
    }

    /// States in which the standard allows the call. `fmi2FreeInstance` is also
    /// accepted in the fatal state: releasing memory never makes things worse.
    #[inline(always)]
    pub fn allowed_states(self) -> StateMask {
        use FmiFunction::*;
        match self {
            SetDebugLogging => ANY_LIVE,
            FreeInstance => StateMask(ANY_LIVE.0 | Fatal.bit()),
            SetupExperiment | EnterInitializationMode => StateMask::of(&[Instantiated]),
            ExitInitializationMode => StateMask::of(&[InitializationMode]),
            Terminate => StateMask::of(&[StepComplete, StepFailed, EventMode, ContinuousTimeMode]),
            Reset => ANY_LIVE,
            GetReal | GetInteger | GetBoolean | GetString => AFTER_INSTANTIATION,
            SetReal => REAL_SETTABLE,
            SetInteger | SetBoolean | SetString => DISCRETE_SETTABLE,
            GetFmuState
            | SetFmuState
            | FreeFmuState
            | SerializedFmuStateSize
            | SerializeFmuState
            | DeSerializeFmuState => ANY_LIVE,
            GetDirectionalDerivative => AFTER_INSTANTIATION,
            SetRealInputDerivatives => CS_SETTABLE,
            GetRealOutputDerivatives => {
                StateMask::of(&[StepComplete, StepFailed, Terminated, Error])
            }
            DoStep => StateMask::of(&[StepComplete]),
            // Only legal while an asynchronous step runs, which never happens
            // here: refused in every state.
            CancelStep => StateMask::of(&[]),
            GetStatus | GetRealStatus | GetIntegerStatus | GetBooleanStatus | GetStringStatus => {
                STATUS_QUERY
            }
            EnterEventMode => StateMask::of(&[EventMode, ContinuousTimeMode]),
            NewDiscreteStates | EnterContinuousTimeMode => StateMask::of(&[EventMode]),
            CompletedIntegratorStep | SetContinuousStates => StateMask::of(&[ContinuousTimeMode]),
            SetTime => StateMask::of(&[EventMode, ContinuousTimeMode]),
            GetEventIndicators | GetContinuousStates => ME_READABLE,
            GetDerivatives => StateMask::of(&[EventMode, ContinuousTimeMode, Terminated, Error]),
            GetNominalsOfContinuousStates => StateMask::of(&[
                Instantiated,
                EventMode,
                ContinuousTimeMode,
                Terminated,
                Error,
            ]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn do_step_only_after_initialization() {
        let mask = FmiFunction::DoStep.allowed_states();
        assert!(mask.contains(StepComplete));
        for s in [Instantiated, InitializationMode, Terminated, Error, Fatal] {
            assert!(!mask.contains(s), "{s:?}");
        }
    }

    #[test]
    fn free_instance_allowed_everywhere() {
        let mask = FmiFunction::FreeInstance.allowed_states();
        for s in [
            Instantiated,
            InitializationMode,
            StepComplete,
            StepFailed,
            Terminated,
            Error,
            Fatal,
        ] {
            assert!(mask.contains(s), "{s:?}");
        }
    }

    /// A function of one interface is refused on an instance of the other,
    /// also in the states the two machines share.
    #[test]
    fn interface_functions_stay_with_their_interface() {
        use FmiFunction::*;
        assert!(!GetRealStatus.allowed(Interface::ModelExchange, Terminated));
        assert!(GetRealStatus.allowed(Interface::CoSimulation, Terminated));
        assert!(!GetContinuousStates.allowed(Interface::CoSimulation, InitializationMode));
        assert!(GetContinuousStates.allowed(Interface::ModelExchange, InitializationMode));
        assert!(!GetNominalsOfContinuousStates.allowed(Interface::CoSimulation, Instantiated));
        assert!(Terminate.allowed(Interface::ModelExchange, ContinuousTimeMode));
        assert!(!SetInteger.allowed(Interface::ModelExchange, ContinuousTimeMode));
        assert!(SetReal.allowed(Interface::ModelExchange, ContinuousTimeMode));
        assert!(!DoStep.allowed(Interface::ModelExchange, EventMode));
    }

    /// `allowed` leaves out the interface compare where the state names the
    /// interface: on every state an instance of each interface can be in
    /// (its own states and the common ones, never the other's), it answers
    /// as the full rule, state and interface, does.
    #[test]
    fn allowed_is_the_full_rule_on_every_reachable_state() {
        let interfaces = [Interface::ModelExchange, Interface::CoSimulation];
        let [me, cs] = interfaces.map(Interface::own_states);
        assert_eq!(me.0 & cs.0, 0, "no state is of both interfaces");
        for interface in interfaces {
            let other = interfaces.into_iter().find(|&i| i != interface).unwrap();
            for state in FmiState::ALL {
                if other.own_states().contains(state) {
                    continue;
                }
                for function in FmiFunction::ALL {
                    let full = function.allowed_states().contains(state)
                        && function.interface().is_none_or(|own| own == interface);
                    assert_eq!(
                        function.allowed(interface, state),
                        full,
                        "{function:?} on {interface:?} in {state:?}"
                    );
                }
            }
        }
        // The shortcut is taken where it matters: fmi2DoStep's states are
        // Co-Simulation's own.
        assert!(
            FmiFunction::DoStep
                .allowed_states()
                .within(Interface::CoSimulation.own_states())
        );
    }

    /// `FmiState::ALL` lists every state once (the match forgets none:
    /// adding a state without listing it fails to compile here).
    #[test]
    fn all_lists_every_state_once() {
        for (i, s) in FmiState::ALL.iter().enumerate() {
            assert_eq!(*s as usize, i, "{s:?}");
            match s {
                Instantiated | InitializationMode | StepComplete | StepFailed | Terminated
                | Error | Fatal | EventMode | ContinuousTimeMode => {}
            }
        }
    }

    /// No dead states: every state of the table is one in which some
    /// function is allowed. Where each is entered (the integration tests
    /// drive each there, StepFailed in `tests/step_outcome.rs`):
    /// Instantiated by fmi2Instantiate/fmi2Reset, InitializationMode by
    /// fmi2EnterInitializationMode, StepComplete by fmi2ExitInitializationMode
    /// (Co-Simulation) and completed steps, StepFailed by a discarded
    /// fmi2DoStep, Terminated by fmi2Terminate, Error and Fatal by the
    /// statuses of that name, EventMode and ContinuousTimeMode by Model
    /// Exchange's mode changes (`instance.rs`, `model_exchange.rs`).
    #[test]
    fn no_state_is_dead() {
        for state in FmiState::ALL {
            assert!(
                FmiFunction::ALL
                    .iter()
                    .any(|f| f.allowed_states().contains(state)),
                "no function is allowed in {state:?}"
            );
        }
        // A discarded step leaves the slave where the importer can ask why
        // and go on from a saved state, and nowhere else.
        use FmiFunction::*;
        for f in [
            GetReal,
            GetRealStatus,
            GetBooleanStatus,
            SetFmuState,
            Terminate,
            Reset,
            FreeInstance,
        ] {
            assert!(f.allowed(Interface::CoSimulation, StepFailed), "{f:?}");
        }
        for f in [DoStep, SetReal, SetInteger, ExitInitializationMode] {
            assert!(!f.allowed(Interface::CoSimulation, StepFailed), "{f:?}");
        }
        assert!(
            !FmiState::ALL
                .iter()
                .any(|s| CancelStep.allowed(Interface::CoSimulation, *s)),
            "fmi2CancelStep is legal only during an asynchronous step"
        );
    }

    #[test]
    fn status_order_is_severity() {
        assert!(Status::Ok < Status::Warning);
        assert!(Status::Warning < Status::Discard);
        assert!(Status::Discard < Status::Error);
        assert_eq!(Status::Warning.worst(Status::Error), Status::Error);
    }
}

//! Return statuses and the FMI 2.0 co-simulation state machine as data.
//!
//! Every entry point names an [`FmiFunction`]; each function carries the mask of
//! [`FmiState`]s in which the standard allows it (FMI 2.0.4, section 4.2.4,
//! state machine of a co-simulation slave). One check at the top of every entry
//! point compares the instance state with that mask.

use fmi_sys::fmi2 as sys;

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

/// States of a co-simulation slave (FMI 2.0.4 Fig. 10). `StepInProgress` and
/// `StepCanceled` only occur with asynchronous steps, which this layer does not
/// offer, but they stay in the table so that the masks read like the standard.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FmiState {
    Instantiated,
    InitializationMode,
    StepComplete,
    StepInProgress,
    StepFailed,
    StepCanceled,
    Terminated,
    Error,
    Fatal,
}

impl FmiState {
    const fn bit(self) -> u16 {
        1 << (self as u16)
    }

    pub fn name(self) -> &'static str {
        match self {
            FmiState::Instantiated => "Instantiated",
            FmiState::InitializationMode => "InitializationMode",
            FmiState::StepComplete => "StepComplete",
            FmiState::StepInProgress => "StepInProgress",
            FmiState::StepFailed => "StepFailed",
            FmiState::StepCanceled => "StepCanceled",
            FmiState::Terminated => "Terminated",
            FmiState::Error => "Error",
            FmiState::Fatal => "Fatal",
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

    pub const fn contains(self, state: FmiState) -> bool {
        self.0 & state.bit() != 0
    }
}

use FmiState::*;

/// Everything but the slave's start and the fatal state: where freeing,
/// resetting and FMU-state handling are allowed.
const ANY_LIVE: StateMask = StateMask::of(&[
    Instantiated,
    InitializationMode,
    StepComplete,
    StepInProgress,
    StepFailed,
    StepCanceled,
    Terminated,
    Error,
]);
const AFTER_INSTANTIATION: StateMask = StateMask::of(&[
    InitializationMode,
    StepComplete,
    StepFailed,
    StepCanceled,
    Terminated,
    Error,
]);
const SETTABLE: StateMask = StateMask::of(&[Instantiated, InitializationMode, StepComplete]);
const STATUS_QUERY: StateMask =
    StateMask::of(&[StepComplete, StepInProgress, StepFailed, Terminated]);

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
}

impl FmiFunction {
    pub fn name(self) -> &'static str {
        use FmiFunction::*;
        match self {
            SetDebugLogging => "fmi2SetDebugLogging",
            FreeInstance => "fmi2FreeInstance",
            SetupExperiment => "fmi2SetupExperiment",
            EnterInitializationMode => "fmi2EnterInitializationMode",
            ExitInitializationMode => "fmi2ExitInitializationMode",
            Terminate => "fmi2Terminate",
            Reset => "fmi2Reset",
            GetReal => "fmi2GetReal",
            GetInteger => "fmi2GetInteger",
            GetBoolean => "fmi2GetBoolean",
            GetString => "fmi2GetString",
            SetReal => "fmi2SetReal",
            SetInteger => "fmi2SetInteger",
            SetBoolean => "fmi2SetBoolean",
            SetString => "fmi2SetString",
            GetFmuState => "fmi2GetFMUstate",
            SetFmuState => "fmi2SetFMUstate",
            FreeFmuState => "fmi2FreeFMUstate",
            SerializedFmuStateSize => "fmi2SerializedFMUstateSize",
            SerializeFmuState => "fmi2SerializeFMUstate",
            DeSerializeFmuState => "fmi2DeSerializeFMUstate",
            GetDirectionalDerivative => "fmi2GetDirectionalDerivative",
            SetRealInputDerivatives => "fmi2SetRealInputDerivatives",
            GetRealOutputDerivatives => "fmi2GetRealOutputDerivatives",
            DoStep => "fmi2DoStep",
            CancelStep => "fmi2CancelStep",
            GetStatus => "fmi2GetStatus",
            GetRealStatus => "fmi2GetRealStatus",
            GetIntegerStatus => "fmi2GetIntegerStatus",
            GetBooleanStatus => "fmi2GetBooleanStatus",
            GetStringStatus => "fmi2GetStringStatus",
        }
    }

    /// States in which the standard allows the call. `fmi2FreeInstance` is also
    /// accepted in the fatal state: releasing memory never makes things worse.
    pub fn allowed_states(self) -> StateMask {
        use FmiFunction::*;
        match self {
            SetDebugLogging => ANY_LIVE,
            FreeInstance => StateMask(ANY_LIVE.0 | Fatal.bit()),
            SetupExperiment | EnterInitializationMode => StateMask::of(&[Instantiated]),
            ExitInitializationMode => StateMask::of(&[InitializationMode]),
            Terminate => StateMask::of(&[StepComplete, StepFailed]),
            Reset => ANY_LIVE,
            GetReal | GetInteger | GetBoolean | GetString => AFTER_INSTANTIATION,
            SetReal | SetInteger | SetBoolean | SetString => SETTABLE,
            GetFmuState
            | SetFmuState
            | FreeFmuState
            | SerializedFmuStateSize
            | SerializeFmuState
            | DeSerializeFmuState => ANY_LIVE,
            GetDirectionalDerivative => AFTER_INSTANTIATION,
            SetRealInputDerivatives => SETTABLE,
            GetRealOutputDerivatives => {
                StateMask::of(&[StepComplete, StepFailed, StepCanceled, Terminated, Error])
            }
            DoStep => StateMask::of(&[StepComplete]),
            CancelStep => StateMask::of(&[StepInProgress]),
            GetStatus | GetRealStatus | GetIntegerStatus | GetBooleanStatus | GetStringStatus => {
                STATUS_QUERY
            }
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

    #[test]
    fn status_order_is_severity() {
        assert!(Status::Ok < Status::Warning);
        assert!(Status::Warning < Status::Discard);
        assert!(Status::Discard < Status::Error);
        assert_eq!(Status::Warning.worst(Status::Error), Status::Error);
    }
}

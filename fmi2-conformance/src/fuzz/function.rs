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

/// The FMU-state functions (FMI 2.0.4 §2.1.8): get, set and free a state,
/// and its serialization.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum FmuStateCall {
    Get,
    Set,
    Free,
    SerializedSize,
    Serialize,
    DeSerialize,
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
    FmuState(FmuStateCall),
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
    /// The C name, as the standard and the FMU's log spell it (from the
    /// layer's one list of functions).
    pub(super) fn name(self) -> &'static str {
        self.layer_function().name()
    }

    /// The layer's state-table entry of this function.
    pub(super) fn layer_function(self) -> fmi2_cosim::status::FmiFunction {
        use Function as F;
        use fmi2_cosim::status::FmiFunction as L;
        match self {
            F::SetDebugLogging => L::SetDebugLogging,
            F::SetupExperiment => L::SetupExperiment,
            F::ExitInitializationMode => L::ExitInitializationMode,
            F::Simple(Simple::EnterInitializationMode) => L::EnterInitializationMode,
            F::Simple(Simple::Terminate) => L::Terminate,
            F::Simple(Simple::Reset) => L::Reset,
            F::Simple(Simple::CancelStep) => L::CancelStep,
            F::Get(ValueType::Real) => L::GetReal,
            F::Get(ValueType::Integer) => L::GetInteger,
            F::Get(ValueType::Boolean) => L::GetBoolean,
            F::Get(ValueType::String) => L::GetString,
            F::Set(ValueType::Real) => L::SetReal,
            F::Set(ValueType::Integer) => L::SetInteger,
            F::Set(ValueType::Boolean) => L::SetBoolean,
            F::Set(ValueType::String) => L::SetString,
            F::FmuState(FmuStateCall::Get) => L::GetFmuState,
            F::FmuState(FmuStateCall::Set) => L::SetFmuState,
            F::FmuState(FmuStateCall::Free) => L::FreeFmuState,
            F::FmuState(FmuStateCall::SerializedSize) => L::SerializedFmuStateSize,
            F::FmuState(FmuStateCall::Serialize) => L::SerializeFmuState,
            F::FmuState(FmuStateCall::DeSerialize) => L::DeSerializeFmuState,
            F::NotOffered(NotOffered::GetDirectionalDerivative) => L::GetDirectionalDerivative,
            F::NotOffered(NotOffered::SetRealInputDerivatives) => L::SetRealInputDerivatives,
            F::NotOffered(NotOffered::GetRealOutputDerivatives) => L::GetRealOutputDerivatives,
            F::DoStep => L::DoStep,
            F::StatusQuery(StatusQuery::Status) => L::GetStatus,
            F::StatusQuery(StatusQuery::Real) => L::GetRealStatus,
            F::StatusQuery(StatusQuery::Integer) => L::GetIntegerStatus,
            F::StatusQuery(StatusQuery::Boolean) => L::GetBooleanStatus,
            F::StatusQuery(StatusQuery::String) => L::GetStringStatus,
            F::FreeInstance => L::FreeInstance,
            F::ModeChange(ModeChange::EnterEventMode) => L::EnterEventMode,
            F::ModeChange(ModeChange::EnterContinuousTimeMode) => L::EnterContinuousTimeMode,
            F::NewDiscreteStates => L::NewDiscreteStates,
            F::CompletedIntegratorStep => L::CompletedIntegratorStep,
            F::SetTime => L::SetTime,
            F::SetContinuousStates => L::SetContinuousStates,
            F::GetVector(VectorGetter::Derivatives) => L::GetDerivatives,
            F::GetVector(VectorGetter::EventIndicators) => L::GetEventIndicators,
            F::GetVector(VectorGetter::ContinuousStates) => L::GetContinuousStates,
            F::GetVector(VectorGetter::Nominals) => L::GetNominalsOfContinuousStates,
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
        (F::FmuState(FmuStateCall::Get), 5),
        (F::FmuState(FmuStateCall::Set), 5),
        (F::FmuState(FmuStateCall::Free), 3),
        (F::FmuState(FmuStateCall::SerializedSize), 2),
        (F::FmuState(FmuStateCall::Serialize), 4),
        (F::FmuState(FmuStateCall::DeSerialize), 6),
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

    /// The vocabulary holds every instance-taking function of the layer's
    /// one list, each once, in the interface the list gives it: a function
    /// added to the layer and not to the fuzzer fails.
    #[test]
    fn the_vocabulary_is_the_layers_function_list() {
        use fmi2_cosim::Interface as Layer;
        use fmi2_cosim::status::FmiFunction;
        let vocabulary = |functions: &[(Function, u32)]| {
            let mut listed: Vec<usize> = functions
                .iter()
                .map(|(f, _)| f.layer_function() as usize)
                .collect();
            listed.sort_unstable();
            listed
        };
        let layer = |interfaces: &[Option<Layer>]| -> Vec<usize> {
            FmiFunction::ALL
                .into_iter()
                .filter(|f| interfaces.contains(&f.interface()))
                .map(|f| f as usize)
                .collect()
        };
        assert_eq!(
            vocabulary(FUNCTIONS),
            layer(&[None, Some(Layer::CoSimulation)])
        );
        assert_eq!(
            vocabulary(MODEL_EXCHANGE_FUNCTIONS),
            layer(&[Some(Layer::ModelExchange)])
        );
    }
}

//! What a model provides to the FMI layer: its identity, units, variable table,
//! start-up values, initialization and step.

use serde::{Serialize, de::DeserializeOwned};
use std::fmt;
use std::path::Path;

use crate::logging::{LogCategory, Logger};
use crate::status::{FmiFunction, FmiState, Interface, Status};
use crate::variables::Variable;

/// `DefaultExperiment` of modelDescription.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DefaultExperiment {
    pub start_time: f64,
    pub stop_time: f64,
    /// Preferred communication step size.
    pub step_size: f64,
}

/// Identity of the model, written to modelDescription.
#[derive(Clone, Copy, Debug)]
pub struct ModelInfo {
    /// C identifier: the binary's file name and `modelIdentifier`.
    pub model_identifier: &'static str,
    pub model_name: &'static str,
    pub description: &'static str,
    pub author: &'static str,
    pub version: &'static str,
    pub license: &'static str,
    pub default_experiment: DefaultExperiment,
}

/// Exponents of the SI base units, with `factor`/`offset` to the base unit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaseUnit {
    pub kg: i8,
    pub m: i8,
    pub s: i8,
    pub a: i8,
    pub k: i8,
    pub mol: i8,
    pub cd: i8,
    pub rad: i8,
    pub factor: f64,
    pub offset: f64,
}

impl BaseUnit {
    pub const NONE: BaseUnit = BaseUnit {
        kg: 0,
        m: 0,
        s: 0,
        a: 0,
        k: 0,
        mol: 0,
        cd: 0,
        rad: 0,
        factor: 1.0,
        offset: 0.0,
    };
}

/// A display unit: `display = factor * value + offset` (FMI 2.0 DisplayUnit).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DisplayUnit {
    pub name: &'static str,
    pub factor: f64,
    pub offset: f64,
}

/// A `<Unit>` of modelDescription.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnitDefinition {
    pub name: &'static str,
    pub base: BaseUnit,
    pub display_units: &'static [DisplayUnit],
}

/// A failure the model reports; the layer logs it with the function's name and
/// returns `fmi2Error`.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelError(pub String);

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ModelError {}

/// How a co-simulation step ended (the model's answer to
/// [`CoSimModel::do_step`]); the layer maps it onto the standard's statuses
/// and states (FMI 2.0.4 §4.2.2, §4.2.4). A model that cannot compute the
/// step at all returns `Err(ModelError)` instead: `fmi2Error`, error state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum StepOutcome {
    /// The step reached `current_time + step_size`: `fmi2OK`.
    Completed,
    /// The step reached its end and the model logged a warning through the
    /// context: `fmi2Warning`.
    CompletedWithWarning,
    /// The model could not complete the step but stopped, consistently, at
    /// `last_successful_time` (in `[current_time, current_time + step_size)`;
    /// the model's values are those at that time): `fmi2Discard`, the slave
    /// enters `stepFailed`, `fmi2GetRealStatus(fmi2LastSuccessfulTime)`
    /// answers `last_successful_time` and `fmi2GetBooleanStatus(fmi2Terminated)`
    /// false. The importer may restore an earlier FMU state and retry with a
    /// shorter step.
    Discarded { last_successful_time: f64 },
    /// The model asks the importer to end the simulation (it reached the end
    /// of what it can simulate) at `last_successful_time`, in the same range:
    /// `fmi2Discard`, `stepFailed`, and `fmi2GetBooleanStatus(fmi2Terminated)`
    /// answers true.
    Terminate { last_successful_time: f64 },
}

/// What modelDescription's `<ModelExchange>` element and
/// `numberOfEventIndicators` say of a model that implements
/// [`ModelExchange`](crate::model_exchange::ModelExchange) as well.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ModelExchangeInfo {
    /// Length of the continuous-state vector: the number of state derivatives
    /// in the variable table (checked when the description is generated).
    pub number_of_continuous_states: usize,
    /// Length of the event-indicator vector (`fmi2GetEventIndicators`).
    pub number_of_event_indicators: usize,
}

/// A model served by the FMI layer. The model knows nothing of C, pointers or
/// the state machine: the layer calls these methods only in legal states, with
/// validated arguments.
///
/// The whole model value is the FMU state: `Clone` gives `fmi2GetFMUstate`,
/// serde gives `fmi2SerializeFMUstate` (values only, never pointers).
pub trait CoSimModel: Clone + Serialize + DeserializeOwned + 'static {
    const INFO: ModelInfo;
    const UNITS: &'static [UnitDefinition];
    /// `Some` for a model that can also be instantiated for Model Exchange:
    /// it implements [`ModelExchange`](crate::model_exchange::ModelExchange)
    /// and is exported with `export_fmi2!(Model, model_exchange)`, which checks
    /// that the two agree. Co-simulation only by default.
    const MODEL_EXCHANGE: Option<ModelExchangeInfo> = None;

    /// The variable table; a variable's value reference is its index.
    fn variables() -> &'static [Variable<Self>];

    /// A model holding its start values (the same values modelDescription
    /// declares, because modelDescription is generated from this).
    fn new() -> Self;

    /// Called by `fmi2ExitInitializationMode` after the declared ranges of all
    /// parameters were checked: validate the rest and build the initial state.
    /// A getter in Initialization Mode that reads a calculated value calls it
    /// too, on a copy of the model, to read the initial values the values set
    /// so far give (FMI 2.0's InitialUnknowns); what it logs then is logged
    /// under that getter's name.
    fn exit_initialization_mode(
        &mut self,
        ctx: &mut Context<'_>,
        start_time: f64,
    ) -> Result<(), ModelError>;

    /// Advance from `current_time` by `step_size` (> 0, finite). Must not
    /// allocate on its normal path. Returns how the step ended (see
    /// [`StepOutcome`]); `CompletedWithWarning` when it logged a warning.
    fn do_step(
        &mut self,
        ctx: &mut Context<'_>,
        current_time: f64,
        step_size: f64,
    ) -> Result<StepOutcome, ModelError>;

    /// Called when an FMU state replaces the instance's values
    /// (`fmi2SetFMUstate`, and `fmi2DeSerializeFMUstate` for bytes from
    /// outside), on the candidate model value, after the layer checked that
    /// every Real of the variable table is finite (state derivatives aside:
    /// they are not evaluated before this hook rebuilt what they are
    /// computed from), that no String parameter or input holds a NUL byte,
    /// that every constant holds its start value and, in `state`s past
    /// initialization, that every parameter is in its declared range
    /// (tunable ones included: `fmi2SetReal` refuses them outside it while
    /// running). The
    /// model checks the rest of its invariants (what its own constructor
    /// would refuse) and rebuilds whatever it derives from its parameters,
    /// so that a state with valid checksum but made-up values never runs.
    /// `state` is the machine state the FMU state was taken in. An `Err` is
    /// `fmi2Error`; the instance keeps its values.
    ///
    /// The default accepts: right for a model whose every value is in its
    /// variable table.
    fn validate_restored(
        &mut self,
        ctx: &mut Context<'_>,
        state: FmiState,
    ) -> Result<(), ModelError> {
        let _ = (ctx, state);
        Ok(())
    }
}

/// What a model may use of its instance while the layer runs it: logging
/// through the importer's callback, and the resources folder.
///
/// Building one is on every step's path, so it is two words: the instance's
/// [`Environment`] by reference and the function by one byte (its name is
/// looked up only when a line is logged).
pub struct Context<'a> {
    pub(crate) env: &'a Environment,
    /// The FMI function being served.
    pub(crate) function: FmiFunction,
}

/// What an instance lends its model through a [`Context`]: its logger, its
/// resources folder and its interface, kept together so that a context
/// refers to them with one pointer.
pub(crate) struct Environment {
    pub(crate) logger: Logger,
    pub(crate) resource_dir: Option<std::path::PathBuf>,
    pub(crate) interface: Interface,
}

impl Context<'_> {
    /// Logs `args`, prefixed with the FMI function being served. Formats into a
    /// stack buffer: no allocation.
    pub fn log(&self, status: Status, category: LogCategory, args: fmt::Arguments<'_>) {
        self.env
            .logger
            .log_in(self.function.name(), status, category, args);
    }

    pub fn warning(&self, args: fmt::Arguments<'_>) {
        self.log(Status::Warning, LogCategory::StatusWarning, args);
    }

    pub fn event(&self, args: fmt::Arguments<'_>) {
        self.log(Status::Ok, LogCategory::Events, args);
    }

    /// The FMU's `resources` folder, when the importer gave its location.
    pub fn resource_dir(&self) -> Option<&Path> {
        self.env.resource_dir.as_deref()
    }

    /// The interface the instance was instantiated for.
    pub fn interface(&self) -> Interface {
        self.env.interface
    }
}

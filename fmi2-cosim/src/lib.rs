//! FMI 2.0 co-simulation and model-exchange layer, generic over the model.
//!
//! This crate knows nothing of piezos. A model implements
//! [`CoSimModel`](model::CoSimModel) (identity, units, a variable table, start
//! values, initialization and step), and
//! [`ModelExchange`](model_exchange::ModelExchange) (continuous states,
//! derivatives, nominals, events) when it also runs under the importer's own
//! integrator; [`export_fmi2!`] exports the standard C entry points for it;
//! [`model_description::model_description`] writes the `modelDescription.xml`
//! that matches the binary, from the same table.
//!
//! Layers, as in the Reference FMUs: [`abi`] is pure FMI glue (pointers, panics,
//! the state check), the instance implements the rules of each call, and the model
//! never sees an FMI type.

pub mod abi;
pub mod describe;
mod export;
pub mod fmu_state;
pub mod functions;
mod instance;
pub mod logging;
pub mod model;
pub mod model_description;
pub mod model_exchange;
pub mod parameter_set;
pub mod resources;
pub mod status;
pub mod units;
pub mod variables;

pub use functions::{EXPORTED_FUNCTIONS, MODEL_EXCHANGE_FUNCTIONS};
pub use instance::Instance;
pub use logging::LogCategory;
pub use model::{
    BaseUnit, CoSimModel, Context, DefaultExperiment, DisplayUnit, ModelError, ModelExchangeInfo,
    ModelInfo, StepOutcome, UnitDefinition,
};
pub use model_exchange::{EventUpdate, ModelExchange};
pub use status::{FmiState, Interface, Status};
pub use variables::{Causality, Variability, Variable};

#[doc(hidden)]
pub use fmi_sys;

//! Piezo flexure-stage physics and control math (no FMI).
//!
//! Plain structs and functions: the asymmetric Bouc-Wen hysteresis of seed 001
//! ([`AsymmetricBoucWen`]), the amplifier, creep, structural modes and sensor
//! noise, and the 3-DOF stage of seed 000 that combines them
//! ([`FlexureStage`]); and the control math of seed 000, starting with the
//! modified inverse Prandtl-Ishlinskii feedforward ([`ModifiedInversePi`]),
//! and of seed 001: the inverse Bouc-Wen feedforward and model-based
//! decoupling ([`InverseBoucWen`], [`CouplingEstimator`]).
//! `MODEL.md` beside this crate gives the equations, the
//! integration scheme and the calibration.

pub mod amplifier;
pub mod bouc_wen;
pub mod creep;
pub mod decoupling;
pub mod fingerprint;
pub mod flexure_stage;
pub mod inverse_bouc_wen;
pub mod inverse_pi;
pub mod oscillator;
pub mod parameter;
pub mod piezo_controller;
pub mod restore;
pub mod sensor_noise;

pub use amplifier::{Amplifier, AmplifierParams};
pub use bouc_wen::{AsymmetricBoucWen, BoucWenParams, hysteretic_states_into, simulate};
pub use creep::Creep;
pub use decoupling::{DecoupledReferences, DecouplingParams, decouple};
pub use flexure_stage::{
    ActuatorParams, CouplingParams, FlexureStage, FlexureStageParams, ParamError, Pose,
    SolverParams, StepReport,
};
pub use inverse_bouc_wen::{
    BoucWenFeedforward, BoucWenModels, CouplingEstimate, CouplingEstimator, InverseBoucWen,
};
pub use inverse_pi::{InversePiModels, InversePiParams, ModifiedInversePi};
pub use oscillator::{ModeParams, ModeSet, Oscillator};
pub use parameter::{Bound, Range, RealParameter};
pub use piezo_controller::{
    ControllerOutput, ControllerParams, DecouplingModel, HysteresisModel, PiController, PiGains,
    PiezoController,
};
pub use restore::UnreachableState;
pub use sensor_noise::{SensorNoise, SensorNoiseParams};

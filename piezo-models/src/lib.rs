//! Piezo flexure-stage physics and control math (no FMI).
//!
//! Plain structs and functions: the asymmetric Bouc-Wen hysteresis of seed 001
//! ([`AsymmetricBoucWen`]), the amplifier, creep, structural modes and sensor
//! noise, and the 3-DOF stage of seed 000 that combines them
//! ([`FlexureStage`]). `MODEL.md` beside this crate gives the equations, the
//! integration scheme and the calibration.

pub mod amplifier;
pub mod bouc_wen;
pub mod creep;
pub mod fingerprint;
pub mod flexure_stage;
pub mod oscillator;
pub mod sensor_noise;

pub use amplifier::{Amplifier, AmplifierParams};
pub use bouc_wen::{AsymmetricBoucWen, BoucWenParams, simulate};
pub use creep::Creep;
pub use flexure_stage::{
    ActuatorParams, CouplingParams, FlexureStage, FlexureStageParams, ParamError, Pose,
    SolverParams, StepReport,
};
pub use oscillator::{ModeParams, ModeSet, Oscillator};
pub use sensor_noise::{SensorNoise, SensorNoiseParams};

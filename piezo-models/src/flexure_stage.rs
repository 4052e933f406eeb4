//! The 3-DOF piezo-driven flexure stage of seed 000 (§2), with the actuator and
//! coupled-hysteresis models of seed 001 (eq. (3)-(4), (7)-(8)).
//!
//! PZT1 drives y; PZT2 and PZT3 are the parallel pair that drives x (together)
//! and θ_z (in opposition). Signal chain per step:
//!
//! 1. amplifier: V_t = clamp(G·clamp(u, u_min, u_max), v_min, v_max),
//!    V̇ = 2π f_a (V_t − V);
//! 2. actuator i: extension e_i = BW_i(V_i) + c_i (asymmetric Bouc-Wen plus creep);
//! 3. coupled hysteresis (seed 001 eq. (7)-(8)): d_x1 = H(V1), d_rot1 = H(V1),
//!    d_y2 = H(V2), d_y3 = H(V3), each an asymmetric Bouc-Wen model of its own;
//! 4. quasi-static pose: x = (e2 + e3)/2 + d_x1, θ = (e2 − e3 + d_rot1)/L,
//!    y = e1 + d_y2 + d_y3;
//! 5. structure: each DOF a damped mode q̈ + 2ζω q̇ + ω² q = ω² q_qs;
//! 6. sensors (seed 000 Fig. 1b): s1 = y, s2 = x + θL/2, s3 = x − θL/2, plus
//!    optional Gaussian noise.
//!
//! Integration: the commands are held over a step, so every amplifier voltage
//! is an exact exponential. The step is cut into pieces over which no voltage
//! moves more than `solver.max_voltage_step`; within a piece each Bouc-Wen model
//! is advanced along its voltage path (one RK4 step in voltage) and its output
//! replaced by the chord in voltage, which makes every forcing a constant plus
//! exponentials in time, and the creep elements and the modes are then
//! propagated in closed form. MODEL.md gives the details and the error bound.

use crate::amplifier::{Amplifier, AmplifierParams};
use crate::bouc_wen::{AsymmetricBoucWen, BoucWenParams};
use crate::creep::{Creep, CreepPath};
use crate::oscillator::{ModeParams, ModeSet, Oscillator, exponential_particular};
pub use crate::parameter::ParamError;
use crate::parameter::{Bound, Range};
use crate::restore::UnreachableState;
use crate::sensor_noise::{SensorNoise, SensorNoiseParams};
use serde::{Deserialize, Serialize};

/// The same stage as a system of ordinary differential equations in time, for
/// integrators other than [`FlexureStage::step`] (FMI Model Exchange).
#[path = "flexure_stage_ode.rs"]
pub mod ode;

/// One piezo stack: its hysteresis and its creep.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActuatorParams {
    /// Extension versus amplifier voltage, seed 001 eq. (3)-(4) [u in V, y in µm].
    pub hysteresis: BoucWenParams,
    /// κ, creep extension per volt once settled [µm/V].
    pub creep_gain: f64,
    /// T, creep time constant [s].
    pub creep_time: f64,
}

/// The coupled-hysteresis models (seed 001 eq. (7)-(8)): displacement of a
/// non-driven axis versus one actuator's voltage, each a Bouc-Wen model.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CouplingParams {
    /// PZT1 voltage → x [µm].
    pub x_from_pzt1: BoucWenParams,
    /// PZT1 voltage → differential displacement s2 − s3 at the sensors [µm].
    pub rot_from_pzt1: BoucWenParams,
    /// PZT2 voltage → y [µm].
    pub y_from_pzt2: BoucWenParams,
    /// PZT3 voltage → y [µm].
    pub y_from_pzt3: BoucWenParams,
}

/// Settings of the step integration.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolverParams {
    /// Largest amplifier-voltage change within one integration piece [V]; the
    /// hysteresis chord error scales with its square.
    pub max_voltage_step: f64,
}

/// Everything that defines a stage. `Default` is the preset calibrated to seed
/// 000's stage (`presets/flexure_stage.json`): the stacks close their minor
/// loops, the modes set by the Ziegler-Nichols figures of the loop on the
/// moving stage (MODEL.md §5-6).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FlexureStageParams {
    pub amplifier: AmplifierParams,
    /// PZT1 (y), PZT2 and PZT3 (the x pair).
    pub actuators: [ActuatorParams; 3],
    pub coupling: CouplingParams,
    /// The actuators' working loop that sets the rest the stage starts from
    /// [V]: every hysteresis model (actuators and couplings) starts at the
    /// 0 V end of its loop between 0 and this voltage, the readings zeroed
    /// there, as a stack rests after it has been operated (MODEL.md §2).
    /// 0: the virgin state h = 0 of seed 001's model.
    pub rest_cycle_voltage: f64,
    /// Whether every hysteresis model (actuators and couplings) closes its
    /// minor loops, as a real stack does (`bouc_wen::ReturnPointMemory`:
    /// eq. (3)'s branches, each tilted to end at the reversal it returns
    /// to; on in the default preset). `false` (a file without the key):
    /// seed 001's model as integrated, whose minor loops drift and which
    /// dither ratchets (MODEL.md §6).
    /// In Model Exchange the memory is discrete state, changed at its events
    /// (`flexure_stage::ode`).
    #[serde(default)]
    pub return_point_memory: bool,
    pub modes: ModeSet,
    /// L, distance between the two x sensors (s2, s3) [mm].
    pub sensor_spacing_mm: f64,
    pub noise: SensorNoiseParams,
    pub solver: SolverParams,
}

/// The calibrated preset, the single source of the default parameters:
/// seed 000's stage with its stacks' return-point memory on, calibrated with
/// it (`examples/calibrate.rs -- --memory --moving`), its Ziegler-Nichols
/// figures taken while it moves: the modes are set by the loop on the
/// branches a tracking stage runs along rather than on a held point's small
/// loops (MODEL.md §5-6).
const PRESET_JSON: &str = include_str!("../presets/flexure_stage.json");

/// Seed 001's XY200S stage as a parameter set of this model, built from the
/// paper's Tables 1-2 by `piezo-identify xy200s-preset` (readings, units and
/// conversion in `piezo_identify::xy200s`).
const XY200S_JSON: &str = include_str!("../presets/xy200s_stage.json");

/// Seed 000's stage calibrated with its stacks' return-point memory on, the
/// Ziegler-Nichols figures taken at a held point (`examples/calibrate.rs --
/// --memory`): the same loop shapes, strokes, rotation and couplings, the
/// modes moved so that those figures hold on the memory's flatter small
/// loops (MODEL.md §6).
const MEMORY_JSON: &str = include_str!("../presets/flexure_stage_memory.json");

/// Seed 000's stage as calibrated before the stacks closed their minor
/// loops (`examples/calibrate.rs`): seed 001's eq. (3) as integrated, the
/// Ziegler-Nichols figures taken at a held point. The default until the
/// memory ran in Model Exchange and in the controller (docs/seed000.md
/// measures both beside each other).
const NO_MEMORY_JSON: &str = include_str!("../presets/flexure_stage_no_memory.json");

impl FlexureStageParams {
    /// Seed 000's stage with `return_point_memory` on, its Ziegler-Nichols
    /// figures taken at a held point (`presets/flexure_stage_memory.json`;
    /// docs/seed000.md measures it beside the default).
    pub fn with_closed_minor_loops() -> Self {
        serde_json::from_str(MEMORY_JSON)
            .expect("presets/flexure_stage_memory.json must parse (a test checks it)")
    }

    /// Seed 000's stage without the return-point memory, its Ziegler-Nichols
    /// figures taken at a held point (`presets/flexure_stage_no_memory.json`).
    pub fn without_memory() -> Self {
        serde_json::from_str(NO_MEMORY_JSON)
            .expect("presets/flexure_stage_no_memory.json must parse (a test checks it)")
    }

    /// The XY200S preset (seed 001 §5.1): PZT1 is the Y actuator, PZT2 and
    /// PZT3 both the X actuator (drive them together), amplifier 0..10 V to
    /// 0..150 V, strokes 144.37 µm (x) and 149.27 µm (y).
    pub fn xy200s() -> Self {
        serde_json::from_str(XY200S_JSON)
            .expect("presets/xy200s_stage.json must parse (a test checks it)")
    }
}

impl Default for FlexureStageParams {
    fn default() -> Self {
        serde_json::from_str(PRESET_JSON)
            .expect("presets/flexure_stage.json must parse (a test checks it)")
    }
}

/// Most integration pieces one step takes. An actuator range of 200 V at the
/// finest solver step (1e-4 V) needs 2e6; more only comes from parameters no
/// stage has (a range of 1e10 V), for which the pieces then grow past
/// `max_voltage_step`: the step's time (about a second) stays bounded,
/// not its accuracy.
const MAX_PIECES: f64 = 2_097_152.0;

fn ensure(ok: bool, parameter: &str, value: f64, allowed: &str) -> Result<(), ParamError> {
    if ok {
        Ok(())
    } else {
        Err(ParamError {
            parameter: parameter.to_owned(),
            value,
            allowed: allowed.to_owned(),
        })
    }
}

impl ActuatorParams {
    /// κ >= 0: creep extends the stack in the direction of the voltage.
    pub const CREEP_GAIN: Range = Range::NON_NEGATIVE;
    /// T > 0; the stage also needs T > 10 amplifier time constants
    /// (checked with the amplifier, in [`FlexureStageParams::validate`]).
    pub const CREEP_TIME: Range = Range::POSITIVE;
}

impl FlexureStageParams {
    /// 0: the virgin state; a working loop's amplitude otherwise.
    pub const REST_CYCLE_VOLTAGE: Range = Range::NON_NEGATIVE;
    pub const SENSOR_SPACING_MM: Range = Range::POSITIVE;
}

impl SolverParams {
    /// Smallest and largest accepted `max_voltage_step` [V]. Below the lower
    /// bound a full 100 V swing would take more than 10⁶ pieces; above the
    /// upper one the single RK4 step per piece and the chord stop being
    /// accurate.
    pub const MAX_VOLTAGE_STEP: Range = Range {
        min: Bound::Closed(1e-4),
        max: Bound::Closed(10.0),
    };
}

impl FlexureStageParams {
    /// Checks every parameter against its declared range (the ranges the
    /// FMU's variable table states), then the conditions between parameters;
    /// the first one out of range is reported.
    pub fn validate(&self) -> Result<(), ParamError> {
        let amp = &self.amplifier;
        AmplifierParams::GAIN.check("amplifier.gain", amp.gain)?;
        AmplifierParams::BANDWIDTH_HZ.check("amplifier.bandwidth_hz", amp.bandwidth_hz)?;
        Range::FINITE.check("amplifier.input_min", amp.input_min)?;
        ensure(
            amp.input_max.is_finite() && amp.input_max > amp.input_min,
            "amplifier.input_max",
            amp.input_max,
            &format!("input_max > input_min = {} (finite)", amp.input_min),
        )?;
        Range::FINITE.check("amplifier.v_min", amp.v_min)?;
        ensure(
            amp.v_max.is_finite() && amp.v_max > amp.v_min,
            "amplifier.v_max",
            amp.v_max,
            &format!("v_max > v_min = {} (finite)", amp.v_min),
        )?;
        let tau = amp.time_constant();
        for (i, act) in self.actuators.iter().enumerate() {
            act.hysteresis
                .validate(&format!("actuators[{i}].hysteresis"))?;
            ActuatorParams::CREEP_GAIN
                .check(&format!("actuators[{i}].creep_gain"), act.creep_gain)?;
            ActuatorParams::CREEP_TIME
                .check(&format!("actuators[{i}].creep_time"), act.creep_time)?;
            // The creep and amplifier exponentials must never coincide (the exact
            // creep solution divides by τ − T), and creep is the slow process.
            ensure(
                act.creep_time > 10.0 * tau,
                &format!("actuators[{i}].creep_time"),
                act.creep_time,
                &format!(
                    "creep_time > 10 x amplifier time constant = {:e} s (finite)",
                    10.0 * tau
                ),
            )?;
        }
        let c = &self.coupling;
        FlexureStageParams::REST_CYCLE_VOLTAGE
            .check("rest_cycle_voltage", self.rest_cycle_voltage)?;
        c.x_from_pzt1.validate("coupling.x_from_pzt1")?;
        c.rot_from_pzt1.validate("coupling.rot_from_pzt1")?;
        c.y_from_pzt2.validate("coupling.y_from_pzt2")?;
        c.y_from_pzt3.validate("coupling.y_from_pzt3")?;
        for (name, mode) in [
            ("x", &self.modes.x),
            ("y", &self.modes.y),
            ("theta", &self.modes.theta),
        ] {
            ModeParams::FREQUENCY_HZ
                .check(&format!("modes.{name}.frequency_hz"), mode.frequency_hz)?;
            ModeParams::DAMPING_RATIO
                .check(&format!("modes.{name}.damping_ratio"), mode.damping_ratio)?;
        }
        FlexureStageParams::SENSOR_SPACING_MM.check("sensor_spacing_mm", self.sensor_spacing_mm)?;
        SensorNoiseParams::RMS_UM.check("noise.rms_um", self.noise.rms_um)?;
        SolverParams::MAX_VOLTAGE_STEP
            .check("solver.max_voltage_step", self.solver.max_voltage_step)
    }
}

/// The serde paths of the stage's seven Bouc-Wen models: the three stacks,
/// then the four couplings.
const HYSTERESIS_NAMES: [&str; 7] = [
    "actuators[0].hysteresis",
    "actuators[1].hysteresis",
    "actuators[2].hysteresis",
    "coupling.x_from_pzt1",
    "coupling.rot_from_pzt1",
    "coupling.y_from_pzt2",
    "coupling.y_from_pzt3",
];

/// Refuses a Bouc-Wen model whose hysteretic state runs away somewhere in
/// the amplifier's output range (within ±1 kV;
/// [`BoucWenParams::check_bounded`]).
fn diverging_model(
    params: &BoucWenParams,
    name: &str,
    amplifier: &AmplifierParams,
) -> Result<(), ParamError> {
    params.check_bounded(
        name,
        amplifier.v_min,
        amplifier.v_max,
        "the amplifier's output range",
    )
}

/// Position and orientation of the moving platform.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub x_um: f64,
    pub y_um: f64,
    /// θ_z, anticlockwise positive [rad].
    pub theta_rad: f64,
}

/// What happened during one step (nothing is rejected at run time).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepReport {
    /// Per channel: the amplifier limits cut the target G·u this step.
    pub clipped: [bool; 3],
    /// The first state variable that is non-finite or beyond any physical
    /// bound after the step (after a NaN command, or a parameter set whose
    /// hysteresis diverges); `None` when the state is sound.
    pub fault: Option<StateFault>,
}

/// A state variable that left the physical domain: the stage has diverged and
/// its outputs mean nothing from here on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StateFault {
    /// What the variable is, for the user (a static name: the step reports it
    /// without allocating).
    pub variable: &'static str,
    pub value: f64,
}

/// |displacement| beyond which the stage has diverged [µm]: 1 m, four orders
/// above the largest stroke any preset has (150 µm), so it never trips on a
/// sound state and catches a divergence while its numbers still print.
pub const DIVERGED_DISPLACEMENT_UM: f64 = 1e6;
/// |θ_z| beyond which the stage has diverged [rad]: a flexure platform turned
/// by a radian is not a flexure any more (its range is ~1e-4 rad).
pub const DIVERGED_ROTATION_RAD: f64 = 1.0;

const ACTUATOR_STATES: [&str; 3] = [
    "hysteretic state h of PZT1 (actuators[0].hysteresis)",
    "hysteretic state h of PZT2 (actuators[1].hysteresis)",
    "hysteretic state h of PZT3 (actuators[2].hysteresis)",
];
const COUPLING_STATES: [&str; 4] = [
    "hysteretic state h of the coupling x from PZT1 (coupling.x_from_pzt1)",
    "hysteretic state h of the coupling s2 - s3 from PZT1 (coupling.rot_from_pzt1)",
    "hysteretic state h of the coupling y from PZT2 (coupling.y_from_pzt2)",
    "hysteretic state h of the coupling y from PZT3 (coupling.y_from_pzt3)",
];
const ACTUATOR_INPUTS: [&str; 3] = [
    "input voltage of the hysteresis of PZT1",
    "input voltage of the hysteresis of PZT2",
    "input voltage of the hysteresis of PZT3",
];
const COUPLING_INPUTS: [&str; 4] = [
    "input voltage of the coupling x from PZT1",
    "input voltage of the coupling s2 - s3 from PZT1",
    "input voltage of the coupling y from PZT2",
    "input voltage of the coupling y from PZT3",
];
const NOISE_SAMPLES: [&str; 3] = [
    "noise sample of sensor s1",
    "noise sample of sensor s2",
    "noise sample of sensor s3",
];
const CREEP_STATES: [&str; 3] = [
    "creep displacement of PZT1",
    "creep displacement of PZT2",
    "creep displacement of PZT3",
];
const AMPLIFIER_STATES: [&str; 3] = [
    "amplifier output voltage of PZT1",
    "amplifier output voltage of PZT2",
    "amplifier output voltage of PZT3",
];
const MODE_POSITIONS: [&str; 3] = ["platform x", "platform y", "platform theta_z"];
const MODE_VELOCITIES: [&str; 3] = [
    "platform x velocity",
    "platform y velocity",
    "platform theta_z velocity",
];

/// Index of the amplifier channel that drives each coupling model, in the
/// order x_from_pzt1, rot_from_pzt1, y_from_pzt2, y_from_pzt3.
const COUPLING_DRIVER: [usize; 4] = [0, 0, 1, 2];

/// Number of distinct exponential rates in a piece's forcing: 1/τ (amplifier),
/// then 1/T_1, 1/T_2, 1/T_3 (creep).
const RATES: usize = 4;

/// Constant plus exponentials at the rates [1/τ, 1/T_1, 1/T_2, 1/T_3] of the
/// time since the start of a piece.
#[derive(Clone, Copy, Debug, Default)]
struct ExponentialSum {
    constant: f64,
    amplitudes: [f64; RATES],
}

impl ExponentialSum {
    fn plus(self, other: Self) -> Self {
        self.combine(other, 1.0)
    }

    fn minus(self, other: Self) -> Self {
        self.combine(other, -1.0)
    }

    fn combine(mut self, other: Self, sign: f64) -> Self {
        self.constant += sign * other.constant;
        for (a, b) in self.amplitudes.iter_mut().zip(other.amplitudes) {
            *a += sign * b;
        }
        self
    }

    fn scaled(mut self, factor: f64) -> Self {
        self.constant *= factor;
        for a in &mut self.amplitudes {
            *a *= factor;
        }
        self
    }
}

/// [`PieceDecays::dt`] before any piece.
const NO_PIECE_DT: f64 = -1.0;

/// Exponential factors for one piece length (cached: at a fixed communication
/// step every step is one piece of the same length).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
struct PieceDecays {
    /// Piece length the factors belong to [s]; negative: none yet.
    dt: f64,
    /// e^{−dt/τ}, e^{−dt/T_1}, e^{−dt/T_2}, e^{−dt/T_3}.
    decays: [f64; RATES],
    /// 1 − e^{−dt/τ}, without cancellation for short pieces.
    amplifier_travel: f64,
}

/// The stage: parameters, state and the constants derived at construction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FlexureStage {
    params: FlexureStageParams,
    amplifier: Amplifier,
    /// Hysteresis of PZT1, PZT2, PZT3 versus their voltages.
    actuators: [AsymmetricBoucWen; 3],
    creep: [Creep; 3],
    /// x_from_pzt1, rot_from_pzt1, y_from_pzt2, y_from_pzt3.
    couplings: [AsymmetricBoucWen; 4],
    /// x [µm], y [µm], θ [rad].
    modes: [Oscillator; 3],
    noise: SensorNoise,
    /// τ = 1/(2π f_a) [s].
    tau: f64,
    /// L [µm].
    spacing_um: f64,
    /// 1/τ, 1/T_1, 1/T_2, 1/T_3 [1/s].
    rates: [f64; RATES],
    /// Per mode (x, y, θ), the particular-solution gain of each rate.
    gains: [[f64; RATES]; 3],
    /// RK4 substep limit handed to the Bouc-Wen models: max_voltage_step with
    /// a hair of slack, so that a piece of exactly max_voltage_step (up to
    /// rounding) is one substep.
    max_du: f64,
    piece: PieceDecays,
}

impl FlexureStage {
    /// A stage at rest: all voltages 0, every hysteresis model at its
    /// exercised rest (`rest_cycle_voltage`), creep 0, modes at rest, every
    /// reading 0, sensors noise-free until the first step.
    pub fn new(params: FlexureStageParams) -> Result<Self, ParamError> {
        Self::settled(params, None)
    }

    /// The stage [`FlexureStage::new`] builds from `params`, at rest, taking
    /// from this stage every Bouc-Wen model whose parameters and rest cycle
    /// did not change, returned to its rest instead of settled again (a
    /// model's rest depends on those alone). Settling the seven models is
    /// most of a build's cost: an FMU that built its stage at instantiation
    /// and is initialized with other parameters (a noise seed, a mode, a
    /// gain) builds the rest of it only.
    pub fn at_rest_with(&self, params: FlexureStageParams) -> Result<Self, ParamError> {
        Self::settled(params, Some(self))
    }

    /// Validates `params` and builds the stage at rest, each Bouc-Wen model
    /// taken from `reuse` when it has the same parameters and rest cycle.
    fn settled(params: FlexureStageParams, reuse: Option<&Self>) -> Result<Self, ParamError> {
        params.validate()?;
        let c = &params.coupling;
        let models = [
            params.actuators[0].hysteresis,
            params.actuators[1].hysteresis,
            params.actuators[2].hysteresis,
            c.x_from_pzt1,
            c.rot_from_pzt1,
            c.y_from_pzt2,
            c.y_from_pzt3,
        ];
        for (model, name) in models.iter().zip(HYSTERESIS_NAMES) {
            diverging_model(model, name, &params.amplifier)?;
        }
        let cycle = params.rest_cycle_voltage;
        let memory = params.return_point_memory;
        let same_cycle = reuse.filter(|old| {
            old.params.rest_cycle_voltage.to_bits() == cycle.to_bits()
                && old.params.return_point_memory == memory
        });
        let at_rest = |hysteresis: BoucWenParams, old: Option<&AsymmetricBoucWen>| match old {
            Some(old) if old.params() == &hysteresis => {
                let mut model = old.clone();
                model.reset();
                model
            }
            _ => {
                let model = AsymmetricBoucWen::at_exercised_rest(hysteresis, cycle);
                if memory {
                    model.with_return_point_memory(cycle)
                } else {
                    model
                }
            }
        };
        let actuators: [AsymmetricBoucWen; 3] = std::array::from_fn(|i| {
            at_rest(
                params.actuators[i].hysteresis,
                same_cycle.map(|old| &old.actuators[i]),
            )
        });
        let couplings_params = [c.x_from_pzt1, c.rot_from_pzt1, c.y_from_pzt2, c.y_from_pzt3];
        let couplings: [AsymmetricBoucWen; 4] = std::array::from_fn(|i| {
            at_rest(couplings_params[i], same_cycle.map(|old| &old.couplings[i]))
        });
        // Parameters each inside its range can still make a Bouc-Wen model
        // diverge on the exercised rest cycle (the fuzzer's restored states
        // found such sets): a stage built on a non-finite rest would hand
        // NaN to every state and output, so it is refused here.
        if let Some(name) = actuators
            .iter()
            .chain(&couplings)
            .zip(HYSTERESIS_NAMES)
            .find_map(|(model, name)| (!model.hysteretic_state().is_finite()).then_some(name))
        {
            return Err(ParamError {
                parameter: "rest_cycle_voltage".to_owned(),
                value: params.rest_cycle_voltage,
                allowed: format!(
                    "a rest cycle that {name} settles on: with its Bouc-Wen parameters the \
                     hysteretic state diverges to a non-finite value (use 0 for a virgin rest, \
                     or check {name})"
                ),
            });
        }
        Ok(Self::assemble(params, actuators, couplings))
    }

    /// Everything but the hysteresis models, built at rest from `params`
    /// (validated), around the given models.
    fn assemble(
        params: FlexureStageParams,
        actuators: [AsymmetricBoucWen; 3],
        couplings: [AsymmetricBoucWen; 4],
    ) -> Self {
        let tau = params.amplifier.time_constant();
        let rates = [
            1.0 / tau,
            1.0 / params.actuators[0].creep_time,
            1.0 / params.actuators[1].creep_time,
            1.0 / params.actuators[2].creep_time,
        ];
        let modes = [
            Oscillator::new(&params.modes.x),
            Oscillator::new(&params.modes.y),
            Oscillator::new(&params.modes.theta),
        ];
        let gains = [0, 1, 2].map(|m| rates.map(|rate| modes[m].exponential_gain(rate)));
        Self {
            amplifier: Amplifier::new(params.amplifier),
            actuators,
            creep: params
                .actuators
                .map(|a| Creep::new(a.creep_gain, a.creep_time)),
            couplings,
            modes,
            noise: SensorNoise::new(params.noise),
            tau,
            spacing_um: params.sensor_spacing_mm * 1e3,
            rates,
            gains,
            max_du: params.solver.max_voltage_step * (1.0 + 1e-9),
            piece: PieceDecays {
                dt: NO_PIECE_DT,
                decays: [1.0; RATES],
                amplifier_travel: 0.0,
            },
            params,
        }
    }

    pub fn params(&self) -> &FlexureStageParams {
        &self.params
    }

    /// This stage rebuilt from its parameters and its dynamic state alone
    /// (see [`crate::restore`]): for a stage that comes from outside, such as
    /// a deserialized FMU state. The parameters are validated and everything
    /// derived from them is built as [`FlexureStage::new`] builds it (the
    /// components' copies of the parameters, the rates and gains, the
    /// exercised rests, the caches); the dynamic state (amplifier voltages,
    /// every Bouc-Wen model's input and hysteretic state, creep, modes, the
    /// noise generator and its current samples) is carried over as it is
    /// ([`FlexureStage::unreachable_state`] checks it). The rebuilt stage
    /// steps exactly as the original would have.
    pub fn rebuilt(&self) -> Result<FlexureStage, ParamError> {
        let mut stage = FlexureStage::new(self.params.clone())?;
        stage.amplifier.set_voltages(self.amplifier.voltages());
        for i in 0..3 {
            stage.actuators[i].carry_point(&self.actuators[i]);
            stage.creep[i].set_value(self.creep[i].value());
            stage.modes[i].carry_state(&self.modes[i]);
        }
        for (rebuilt, own) in stage.couplings.iter_mut().zip(&self.couplings) {
            rebuilt.carry_point(own);
        }
        stage.noise.carry_state(&self.noise);
        // The piece cache for the length the original cached: the rebuilt
        // stage is then the same value the original would be with these
        // parameters (a state taken from it serializes to the same bytes).
        if self.piece.dt != NO_PIECE_DT {
            stage.piece_decays(self.piece.dt);
        }
        Ok(stage)
    }

    /// The first dynamic state variable that is not finite. Any finite state
    /// is one a run can hold: a Model Exchange importer's integrator sets
    /// the continuous states to whatever it computes, and a co-simulation
    /// step checks its divergence bounds itself.
    pub fn unreachable_state(&self) -> Option<UnreachableState> {
        let inputs = self.actuators.iter().zip(ACTUATOR_INPUTS);
        let coupling_inputs = self.couplings.iter().zip(COUPLING_INPUTS);
        ode::STATES
            .into_iter()
            .zip(self.continuous_states())
            .chain(
                inputs
                    .chain(coupling_inputs)
                    .map(|(m, name)| (name, m.input())),
            )
            .chain(NOISE_SAMPLES.into_iter().zip(self.noise.current()))
            .chain(
                self.actuators
                    .iter()
                    .chain(&self.couplings)
                    .filter_map(AsymmetricBoucWen::unreachable_memory),
            )
            .find_map(|(variable, value)| UnreachableState::unless_finite(variable, value))
    }

    /// Advances the stage by `h` seconds with the three commands (PZT1, PZT2,
    /// PZT3, volts before the amplifier, 0..10 V nominal) held constant.
    /// `h` must be positive and finite (the caller guarantees it). Allocates
    /// nothing and does no I/O.
    pub fn step(&mut self, commands: [f64; 3], h: f64) -> StepReport {
        let (targets, clipped) = self.amplifier.targets(commands);
        let start = self.amplifier.voltages();
        // D = max_i |V_0,i − V_t,i|; NaN propagates (and then yields one piece).
        let mut distance = 0.0f64;
        for (v, t) in start.iter().zip(&targets) {
            let d = (v - t).abs();
            if d > distance || d.is_nan() {
                distance = d;
            }
        }
        // Every voltage moves along V_t + (V_0 − V_t)·E(s), E = e^{−s/τ} falling
        // from 1 to e^{−h/τ}; equal increments of E are equal voltage increments.
        let whole = self.piece_decays(h);
        let travel = distance * whole.amplifier_travel / self.params.solver.max_voltage_step;
        // ceil(travel) > 1 exactly when travel > 1: the usual single piece then
        // costs no ceil (a libm call on baseline x86-64), nor does the cap.
        if travel > 1.0 && travel.is_finite() {
            let pieces = travel.ceil();
            // For any state the stage produced, D ≤ v_max − v_min; the cap only
            // keeps a corrupted (e.g. deserialised) state from looping for ages.
            // MAX_PIECES bounds it where the parameters themselves ask for ages
            // (a range of 1e10 V in 1e-4 V pieces).
            let cap = (((self.params.amplifier.v_max - self.params.amplifier.v_min)
                / self.params.solver.max_voltage_step)
                .ceil()
                + 1.0)
                .min(MAX_PIECES);
            let count = pieces.min(cap) as usize;
            // Capped pieces are longer than max_voltage_step: one RK4 substep
            // each, or the hysteresis would split them again.
            let max_du = if pieces > cap {
                f64::INFINITY
            } else {
                self.max_du
            };
            let increment = whole.amplifier_travel / count as f64;
            let mut elapsed = 0.0;
            for k in 1..count {
                // Piece k takes E from 1 − (k−1)·ΔE to E_k = 1 − k·ΔE:
                // dt = τ·ln(E_{k−1}/E_k) = τ·ln(1 + ΔE/E_k).
                let e_k = 1.0 - k as f64 * increment;
                let dt = self.tau * (increment / e_k).ln_1p();
                self.advance_piece(&targets, dt, max_du);
                elapsed += dt;
            }
            // The last piece ends exactly at h (it may be very long when the
            // voltages settle early in a long step).
            self.advance_piece(&targets, (h - elapsed).max(0.0), max_du);
        } else {
            // One piece: no voltage motion beyond max_voltage_step, or a path
            // too long to count (advance_to bounds its substeps then).
            self.advance_piece(&targets, h, self.max_du);
        }
        self.noise.draw();
        StepReport {
            clipped,
            fault: self.state_fault(),
        }
    }

    /// One piece of length `dt` with the amplifier relaxing towards `targets`,
    /// the hysteresis integrated in voltage substeps of at most `max_du`.
    fn advance_piece(&mut self, targets: &[f64; 3], dt: f64, max_du: f64) {
        let piece = self.piece_decays(dt);
        let relax = piece.decays[0];
        let tau = self.tau;
        let v_a = self.amplifier.voltages();
        let mut v_b = [0.0; 3];
        for i in 0..3 {
            v_b[i] = targets[i] + (v_a[i] - targets[i]) * relax;
        }

        // Advances one Bouc-Wen model along its voltage path (one RK4 step, since
        // |ΔV| ≤ max_voltage_step) and returns its chord in voltage as a function
        // of time: y(V(σ)) ≈ y_a + slope·(V(σ) − V_a) = (y_a − a) + a·e^{−σ/τ},
        // a = slope·(V_a − V_t).
        let chord = |model: &mut AsymmetricBoucWen, i: usize| {
            let y_a = model.output();
            model.advance_to(v_b[i], max_du);
            let dv = v_b[i] - v_a[i];
            // a = slope·(V_a − V_t) with slope = Δy/ΔV, taken as
            // Δy·((V_a − V_t)/ΔV): the ratio of the two voltage differences
            // is −1/(1 − e^{−dt/τ}) and finite for any ΔV ≠ 0, where Δy/ΔV
            // overflows once ΔV is subnormal (a voltage settling onto its
            // target) and Δy carries a rounding error.
            let a = if dv != 0.0 {
                (model.output() - y_a) * ((v_a[i] - targets[i]) / dv)
            } else {
                0.0
            };
            let mut sum = ExponentialSum {
                constant: y_a - a,
                ..ExponentialSum::default()
            };
            sum.amplitudes[0] = a;
            sum
        };

        // Actuator extensions e_i = BW_i(V_i) + c_i with the creep solved exactly.
        let mut extension = [ExponentialSum::default(); 3];
        let mut creep_paths = [CreepPath::default(); 3];
        for i in 0..3 {
            let hysteresis = chord(&mut self.actuators[i], i);
            let path = self.creep[i].path(v_a[i], targets[i], tau);
            let mut creep = ExponentialSum {
                constant: path.steady,
                ..ExponentialSum::default()
            };
            creep.amplitudes[0] = path.amplifier_term;
            creep.amplitudes[1 + i] = path.own_term;
            extension[i] = hysteresis.plus(creep);
            creep_paths[i] = path;
        }
        // Coupled hysteresis, seed 001 eq. (7)-(8).
        let mut coupled = [ExponentialSum::default(); 4];
        for (k, model) in self.couplings.iter_mut().enumerate() {
            coupled[k] = chord(model, COUPLING_DRIVER[k]);
        }
        let [x_from_1, rot_from_1, y_from_2, y_from_3] = coupled;

        // Quasi-static pose (seed 000 §2 kinematics: the x pair acts in parallel,
        // their difference over L turns the platform).
        let x_qs = extension[1].plus(extension[2]).scaled(0.5).plus(x_from_1);
        let y_qs = extension[0].plus(y_from_2).plus(y_from_3);
        let theta_qs = extension[1]
            .minus(extension[2])
            .plus(rot_from_1)
            .scaled(1.0 / self.spacing_um);

        for (m, forcing) in [x_qs, y_qs, theta_qs].iter().enumerate() {
            let (start, end) = exponential_particular(
                forcing.constant,
                &forcing.amplitudes,
                &self.gains[m],
                &self.rates,
                &piece.decays,
            );
            self.modes[m].propagate(dt, start, end);
        }
        for (i, (creep, path)) in self.creep.iter_mut().zip(&creep_paths).enumerate() {
            creep.follow(path, relax, piece.decays[1 + i]);
        }
        self.amplifier.set_voltages(v_b);
    }

    /// The exponential factors for a piece of length `dt`, from the cache when
    /// the length repeats.
    fn piece_decays(&mut self, dt: f64) -> PieceDecays {
        if dt != self.piece.dt {
            let mut decays = [0.0; RATES];
            for (d, rate) in decays.iter_mut().zip(self.rates) {
                *d = (-dt * rate).exp();
            }
            self.piece = PieceDecays {
                dt,
                decays,
                amplifier_travel: -(-dt * self.rates[0]).exp_m1(),
            };
        }
        self.piece
    }

    /// The first state variable that is non-finite or beyond the divergence
    /// bounds, in the order amplifier, actuators, couplings, creep, modes.
    fn state_fault(&self) -> Option<StateFault> {
        // Every step asks, and the answer is almost always "sound": one pass
        // without early exits first (|v| <= bound is false for NaN, and
        // |v| <= f64::MAX is finiteness), the named search below only when it
        // fails.
        let voltages = self.amplifier.voltages();
        let mut sound = true;
        for v in voltages {
            sound &= v.abs() <= f64::MAX;
        }
        for model in &self.actuators {
            sound &= model.hysteretic_state().abs() <= DIVERGED_DISPLACEMENT_UM;
        }
        for model in &self.couplings {
            sound &= model.hysteretic_state().abs() <= DIVERGED_DISPLACEMENT_UM;
        }
        for creep in &self.creep {
            sound &= creep.value().abs() <= DIVERGED_DISPLACEMENT_UM;
        }
        for (i, mode) in self.modes.iter().enumerate() {
            let state = mode.state();
            let bound = if i == 2 {
                DIVERGED_ROTATION_RAD
            } else {
                DIVERGED_DISPLACEMENT_UM
            };
            sound &= state.position.abs() <= bound;
            sound &= state.velocity.abs() <= f64::MAX;
        }
        if sound {
            return None;
        }
        let finite =
            |variable, value: f64| (!value.is_finite()).then_some(StateFault { variable, value });
        let bounded = |variable, value: f64, bound: f64| {
            (value.is_nan() || value.abs() > bound).then_some(StateFault { variable, value })
        };
        (0..3)
            .find_map(|i| finite(AMPLIFIER_STATES[i], voltages[i]))
            .or_else(|| {
                (0..3).find_map(|i| {
                    bounded(
                        ACTUATOR_STATES[i],
                        self.actuators[i].hysteretic_state(),
                        DIVERGED_DISPLACEMENT_UM,
                    )
                })
            })
            .or_else(|| {
                (0..4).find_map(|i| {
                    // All four are displacements at the sensors [µm], the
                    // rotational one a difference s2 − s3.
                    bounded(
                        COUPLING_STATES[i],
                        self.couplings[i].hysteretic_state(),
                        DIVERGED_DISPLACEMENT_UM,
                    )
                })
            })
            .or_else(|| {
                (0..3).find_map(|i| {
                    bounded(
                        CREEP_STATES[i],
                        self.creep[i].value(),
                        DIVERGED_DISPLACEMENT_UM,
                    )
                })
            })
            .or_else(|| {
                (0..3).find_map(|i| {
                    let state = self.modes[i].state();
                    let bound = if i == 2 {
                        DIVERGED_ROTATION_RAD
                    } else {
                        DIVERGED_DISPLACEMENT_UM
                    };
                    bounded(MODE_POSITIONS[i], state.position, bound)
                        .or_else(|| finite(MODE_VELOCITIES[i], state.velocity))
                })
            })
    }

    /// Platform pose (noise-free).
    pub fn pose(&self) -> Pose {
        Pose {
            x_um: self.modes[0].position(),
            y_um: self.modes[1].position(),
            theta_rad: self.modes[2].position(),
        }
    }

    /// Sensor readings s1 = y, s2 = x + θL/2, s3 = x − θL/2 [µm], including the
    /// noise drawn at the last step.
    pub fn sensors(&self) -> [f64; 3] {
        let pose = self.pose();
        let half_turn = 0.5 * self.spacing_um * pose.theta_rad;
        let noise = self.noise.current();
        [
            pose.y_um + noise[0],
            pose.x_um + half_turn + noise[1],
            pose.x_um - half_turn + noise[2],
        ]
    }

    /// Amplifier output voltages of PZT1, PZT2, PZT3 [V].
    pub fn amplifier_voltages(&self) -> [f64; 3] {
        self.amplifier.voltages()
    }

    /// Actuator extensions e_i = BW_i(V_i) + c_i of PZT1, PZT2, PZT3 [µm].
    pub fn actuator_extensions(&self) -> [f64; 3] {
        [0, 1, 2].map(|i| self.actuators[i].output() + self.creep[i].value())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preset_parses_and_validates() {
        let params: FlexureStageParams = serde_json::from_str(PRESET_JSON).unwrap();
        params.validate().unwrap();
        assert_eq!(params, FlexureStageParams::default());
        assert!(!params.noise.enabled, "noise is off by default");
        assert!(
            params.return_point_memory,
            "the default stage closes its minor loops"
        );
        for (name, set, memory) in [
            (
                "3dof_memory",
                FlexureStageParams::with_closed_minor_loops(),
                true,
            ),
            (
                "3dof_no_memory",
                FlexureStageParams::without_memory(),
                false,
            ),
            ("xy200s", FlexureStageParams::xy200s(), false),
        ] {
            set.validate().unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(set.return_point_memory, memory, "{name}");
        }
    }

    #[test]
    fn starts_at_rest() {
        let stage = FlexureStage::new(FlexureStageParams::default()).unwrap();
        assert_eq!(stage.pose(), Pose::default());
        assert_eq!(stage.sensors(), [0.0; 3]);
        assert_eq!(stage.amplifier_voltages(), [0.0; 3]);
    }

    /// `at_rest_with` is the stage `new` builds, field for field, from any
    /// state (a driven stage with noise on, its generator moved, every
    /// Bouc-Wen model off its rest, the piece cache filled) and for
    /// parameters that keep, change some or change all of the rests.
    #[test]
    fn at_rest_with_equals_a_stage_built_from_the_same_parameters() {
        let mut params = FlexureStageParams::default();
        params.noise.enabled = true;
        let mut stage = FlexureStage::new(params.clone()).unwrap();
        for k in 0..2000 {
            let t = k as f64 * 1e-4;
            let wave = (2.0 * std::f64::consts::PI * 5.0 * t).sin();
            stage.step([4.0 + 3.0 * wave, 5.0 - 4.0 * wave, 2.0 * wave], 1e-4);
        }
        assert_ne!(stage, FlexureStage::new(params.clone()).unwrap());
        let same = params.clone();
        let mut other_mode_and_seed = params.clone();
        other_mode_and_seed.modes.theta.frequency_hz *= 1.05;
        other_mode_and_seed.noise.seed += 1;
        let mut one_rest_moves = params.clone();
        one_rest_moves.coupling.y_from_pzt3.a *= 1.1;
        one_rest_moves.actuators[1].hysteresis.q *= 0.9;
        let mut every_rest_moves = params.clone();
        every_rest_moves.rest_cycle_voltage *= 0.8;
        for wanted in [same, other_mode_and_seed, one_rest_moves, every_rest_moves] {
            assert_eq!(
                stage.at_rest_with(wanted.clone()).unwrap(),
                FlexureStage::new(wanted).unwrap()
            );
        }
        let mut invalid = params;
        invalid.modes.theta.damping_ratio = -1.0;
        assert!(
            stage.at_rest_with(invalid).is_err(),
            "parameters are validated"
        );
    }

    /// MODEL.md §2: a stack cycled 0 → 100 → 0 V from the exercised rest
    /// comes back to its zero in its hysteresis (within 0.001 µm with creep
    /// off); the creep element, which follows the voltage with its 1.5 s
    /// time constant, still holds +0.04 µm as the ramp down ends, and lets
    /// go of it over the next seconds.
    #[test]
    fn a_full_cycle_returns_to_the_rest_but_for_the_creep() {
        let y_after_cycle = |creep: bool, hold_s: f64| {
            let mut params = FlexureStageParams::default();
            if !creep {
                params.actuators.iter_mut().for_each(|a| a.creep_gain = 0.0);
            }
            let mut stage = FlexureStage::new(params).unwrap();
            let ramp = 10_000;
            for k in 1..=2 * ramp {
                let up = k.min(2 * ramp - k) as f64 / ramp as f64;
                stage.step([10.0 * up, 0.0, 0.0], 1e-4);
            }
            for _ in 0..(hold_s / 1e-4).round() as usize {
                stage.step([0.0; 3], 1e-4);
            }
            stage.sensors()[0]
        };
        let hysteresis = y_after_cycle(false, 0.0);
        assert!(hysteresis.abs() < 1e-3, "{hysteresis}");
        let with_creep = y_after_cycle(true, 0.0);
        assert!((0.035..0.05).contains(&with_creep), "{with_creep}");
        let settled = y_after_cycle(true, 10.0);
        assert!(settled.abs() < 0.005, "{settled}");
    }

    /// A voltage settling onto its target passes through subnormal steps
    /// (1.5e-323 V to 0): the chord of such a piece stays finite, with and
    /// without the return-point memory. With the memory, a rounding-sized
    /// change of the output over that piece divided by the 1.5e-323 V
    /// overflowed: NaN after a 0 → 100 → 0 V cycle and 40 ms of rest.
    #[test]
    fn a_voltage_settling_through_subnormal_steps_keeps_the_stage_finite() {
        for memory in [false, true] {
            let params = FlexureStageParams {
                return_point_memory: memory,
                ..FlexureStageParams::default()
            };
            let mut stage = FlexureStage::new(params).unwrap();
            let ramp = 10_000;
            for k in 1..=2 * ramp {
                let up = k.min(2 * ramp - k) as f64 / ramp as f64;
                stage.step([10.0 * up, 0.0, 0.0], 1e-4);
            }
            let mut reached_subnormal = false;
            for _ in 0..2_000 {
                let report = stage.step([0.0; 3], 1e-4);
                assert!(
                    report.fault.is_none(),
                    "memory {memory}: {:?}",
                    report.fault
                );
                let v = stage.amplifier_voltages()[0];
                reached_subnormal |= v != 0.0 && v.abs() < f64::MIN_POSITIVE;
            }
            assert!(
                reached_subnormal,
                "memory {memory}: the voltage settles through subnormals"
            );
            assert!(
                stage.sensors().iter().all(|s| s.is_finite()),
                "memory {memory}"
            );
        }
    }

    /// Zero commands from rest keep everything exactly at rest.
    #[test]
    fn zero_commands_keep_the_stage_at_rest() {
        let mut stage = FlexureStage::new(FlexureStageParams::default()).unwrap();
        for _ in 0..100 {
            let report = stage.step([0.0; 3], 1e-4);
            assert_eq!(report.clipped, [false; 3]);
            assert_eq!(report.fault, None);
        }
        assert_eq!(stage.pose(), Pose::default());
    }

    /// beta + gamma < 0 with n = 2: dh/du = A + c·h² escapes to infinity at
    /// u = π/(2·sqrt(A·c)) of travel; with c = 1.2e-5 that lies past the 1 kV
    /// the build checks, inside a 10 kV amplifier's range. The step that
    /// crosses the bound names the state.
    #[test]
    fn a_diverging_hysteresis_state_is_named() {
        let mut params = FlexureStageParams::default();
        params.amplifier.v_max = 1e4;
        params.amplifier.gain = 1e3;
        params.amplifier.input_max = 10.0;
        let model = &mut params.coupling.y_from_pzt3;
        model.n = 2.0;
        model.beta = -0.8e-5;
        model.gamma = -0.4e-5;
        let escape = std::f64::consts::FRAC_PI_2 / (model.a.abs() * 1.2e-5).sqrt();
        assert!(escape > 1000.0 && escape < 1e4, "{escape} V");
        params.rest_cycle_voltage = 0.0;
        let mut stage = FlexureStage::new(params).unwrap();
        let mut fault = None;
        for k in 1..=20_000 {
            fault = stage.step([0.0, 0.0, 5e-4 * k as f64], 1e-4).fault;
            if fault.is_some() {
                break;
            }
        }
        let fault = fault.expect("the state diverges before 10 V of command");
        assert_eq!(
            fault.variable,
            "hysteretic state h of the coupling y from PZT3 (coupling.y_from_pzt3)"
        );
        assert!(fault.value.is_nan() || fault.value.abs() > DIVERGED_DISPLACEMENT_UM);
    }

    /// Parameters each inside its range whose Bouc-Wen model runs away inside
    /// the amplifier's range are refused at construction, naming the model.
    #[test]
    fn a_model_that_runs_away_in_the_amplifier_range_is_refused() {
        let mut params = FlexureStageParams::default();
        params.coupling.y_from_pzt3.beta = -0.55;
        params.coupling.y_from_pzt3.gamma = -0.13;
        let error = FlexureStage::new(params.clone()).expect_err("the model runs away");
        assert_eq!(error.parameter, "coupling.y_from_pzt3.gamma");
        assert!(
            error.allowed.contains("beta + gamma = -0.68")
                && error.allowed.contains("steepens the loading branch"),
            "{}",
            error.allowed
        );
        // One stack's gamma alone, as a user would mistype it.
        let mut params = FlexureStageParams::default();
        params.actuators[2].hysteresis.gamma = -1.0;
        let error = FlexureStage::new(params).expect_err("the stack runs away");
        assert_eq!(error.parameter, "actuators[2].hysteresis.gamma");
        // Every shipped parameter set holds over its amplifier's range.
        FlexureStage::new(FlexureStageParams::default()).unwrap();
        FlexureStage::new(FlexureStageParams::xy200s()).unwrap();
    }

    /// Parameters that validate but ask for 2e14 pieces of 1e-4 V per step
    /// (a 2e10 V actuator range): without a bound a step runs for days. The
    /// bounded step takes about a second in release; 10 s (300 s unoptimized,
    /// some 30 times slower) leaves room for a slow machine and none for an
    /// unbounded loop.
    #[test]
    fn absurd_voltage_ranges_keep_a_step_bounded() {
        let mut params = FlexureStageParams::default();
        params.amplifier.v_min = -1e10;
        params.amplifier.v_max = 1e10;
        params.amplifier.gain = 1e9;
        params.solver.max_voltage_step = 1e-4;
        let mut stage = FlexureStage::new(params).unwrap();
        let started = std::time::Instant::now();
        stage.step([10.0, -10.0, 5.0], 1.0);
        let limit = if cfg!(debug_assertions) { 300 } else { 10 };
        assert!(
            started.elapsed() < std::time::Duration::from_secs(limit),
            "{:?}",
            started.elapsed()
        );
    }

    #[test]
    fn clipping_and_non_finite_commands_are_reported_not_rejected() {
        let mut stage = FlexureStage::new(FlexureStageParams::default()).unwrap();
        let report = stage.step([14.0, -3.5, 5.0], 1e-4);
        assert_eq!(report.clipped, [true, true, false]);
        assert_eq!(report.fault, None);
        let report = stage.step([f64::NAN, 0.0, 0.0], 1e-4);
        let fault = report.fault.expect("a NaN command is reported");
        assert_eq!(fault.variable, "amplifier output voltage of PZT1");
        assert!(fault.value.is_nan());
    }

    /// The amplifier is exact: after a step of h from rest with command u, the
    /// voltage is G·u·(1 − e^{−h/τ}) whatever h.
    #[test]
    fn amplifier_voltage_is_the_exact_exponential() {
        let params = FlexureStageParams::default();
        let tau = params.amplifier.time_constant();
        for h in [1e-6, 1e-4, 3.7e-4, 1e-2, 10.0] {
            let mut stage = FlexureStage::new(params.clone()).unwrap();
            stage.step([2.0, 5.0, 10.0], h);
            let factor = -(-h / tau).exp_m1();
            let v = stage.amplifier_voltages();
            for (i, u) in [2.0, 5.0, 10.0].iter().enumerate() {
                let exact = params.amplifier.gain * u * factor;
                assert!(
                    (v[i] - exact).abs() < 1e-12 * 100.0,
                    "h = {h}: {} vs {exact}",
                    v[i]
                );
            }
        }
    }

    /// After a long hold the pose equals the quasi-static kinematics of the
    /// actuator and coupling outputs (seed 000 §2), and the sensors obey
    /// x = (s2 + s3)/2, θ = (s2 − s3)/L.
    #[test]
    fn settled_pose_is_the_quasi_static_kinematics() {
        let params = FlexureStageParams::default();
        let mut stage = FlexureStage::new(params.clone()).unwrap();
        stage.step([3.0, 7.0, 4.0], 60.0);
        let v = stage.amplifier_voltages();
        let bw = |p: BoucWenParams, v: f64| {
            let mut m = AsymmetricBoucWen::at_exercised_rest(p, params.rest_cycle_voltage);
            m.advance_to(v, 0.01);
            m.output()
        };
        let creep = |i: usize| params.actuators[i].creep_gain * v[i];
        let e = [0, 1, 2].map(|i| bw(params.actuators[i].hysteresis, v[i]) + creep(i));
        let c = &params.coupling;
        let l = params.sensor_spacing_mm * 1e3;
        let x = (e[1] + e[2]) / 2.0 + bw(c.x_from_pzt1, v[0]);
        let y = e[0] + bw(c.y_from_pzt2, v[1]) + bw(c.y_from_pzt3, v[2]);
        let theta = (e[1] - e[2] + bw(c.rot_from_pzt1, v[0])) / l;
        let pose = stage.pose();
        // One path from rest at 0.05 V per RK4 step versus 0.01 V: both within 1e-9 µm.
        assert!((pose.x_um - x).abs() < 1e-8, "{} vs {x}", pose.x_um);
        assert!((pose.y_um - y).abs() < 1e-8, "{} vs {y}", pose.y_um);
        assert!((pose.theta_rad - theta).abs() * l < 1e-8);
        let s = stage.sensors();
        assert_eq!(s[0], pose.y_um);
        assert!(((s[1] + s[2]) / 2.0 - pose.x_um).abs() < 1e-12);
        assert!(((s[1] - s[2]) / l - pose.theta_rad).abs() < 1e-15);
        for (ext, expected) in stage.actuator_extensions().iter().zip(e) {
            assert!((ext - expected).abs() < 1e-8);
        }
    }
}

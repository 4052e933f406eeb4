//! Seed 000's controller for the 3-DOF stage: modified inverse P-I feedforward
//! per actuator channel, PI feedback per axis (eq. 10, §3.2) and the decoupling
//! law (eq. 11-12), sampled at a fixed period.
//!
//! Channels: PZT1 (y), PZT2 and PZT3 (the x pair). x and θz are commanded
//! through the pair: equal commands translate, opposite commands rotate (§3.2),
//! so the demanded extensions of the pair are x_d2,3 = x_ref ± θ_ref·L/2.
//!
//! Feedback (eq. 10): e_x = x_ref − (s2+s3)/2, e_y = y_ref − s1,
//! e_θ = θ_ref − (s2−s3)/L. The rotational PI acts on the rotation error
//! expressed as the differential displacement at the actuators, e_θ·L/2 in µm,
//! so that its gains (§3.2: kp 0.06, ki 70) are in V/µm like the translational
//! ones (kp 0.05, ki 50); §3.2 gives no unit, and in radians these gains would
//! be ineffective (θ is of order 10⁻⁴ rad). Channel feedback: fb1 = v_y,
//! fb2 = v_x + v_θ, fb3 = v_x − v_θ.
//!
//! Integrators: backward Euler (the right rectangle), I ← I + e·T with the
//! current sample's error included.
//! Anti-windup by conditional integration: an axis's integrator holds while a
//! channel it drives was limited (command_min or command_max) at the previous
//! sample and the axis's error pushes that channel further into the limit. The
//! command thus reaches its limit, the integrator passes it by at most one
//! sample's increment (ki·e·T), and it leaves the limit as soon as the error
//! turns.

use serde::{Deserialize, Serialize};

use crate::bouc_wen::AsymmetricBoucWen;
use crate::decoupling::{DecoupledReferences, DecouplingParams, decouple};
use crate::flexure_stage::{FlexureStageParams, ParamError};
use crate::inverse_bouc_wen::{BoucWenFeedforward, BoucWenModels, CouplingEstimator};
use crate::inverse_pi::{InversePiModels, InversePiParams, ModifiedInversePi};
use crate::parameter::Range;
use crate::restore::UnreachableState;

/// Proportional and integral gains of one axis [V/µm, V/(µm·s)].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PiGains {
    pub kp: f64,
    pub ki: f64,
}

impl PiGains {
    /// kp and ki: a negative gain turns the loop's feedback positive.
    pub const GAIN: Range = Range::NON_NEGATIVE;
}

/// A PI law's running integral of the error (eq. 10).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PiController {
    integral: f64,
}

impl PiController {
    pub fn reset(&mut self) {
        self.integral = 0.0;
    }

    pub fn integral(&self) -> f64 {
        self.integral
    }

    /// kp·e + ki·I after integrating this sample's error when `integrate`.
    fn update(&mut self, gains: PiGains, error: f64, dt: f64, integrate: bool) -> f64 {
        if integrate {
            self.integral += error * dt;
        }
        gains.kp * error + gains.ki * self.integral
    }
}

/// Which inverse hysteresis model the feedforward uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HysteresisModel {
    /// Seed 000's modified inverse Prandtl-Ishlinskii model (eq. 3-5).
    ModifiedPi,
    /// Seed 001's inverse asymmetric Bouc-Wen model (eq. 6).
    BoucWen,
}

/// Which law corrects the references for the cross-axis coupling when
/// `decoupling` is on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DecouplingModel {
    /// Seed 000's piecewise-linear compensations D1..D4 (eq. 11-12).
    PiecewiseLinear,
    /// Seed 001's coupling models H_XY, H_YX run on the applied commands
    /// (eq. 7-16).
    ModelBased,
}

/// Integer codes of the two selectors, as the FMU's Integer parameters carry
/// them (1-based, in the order above).
impl HysteresisModel {
    pub const CODES: [(i32, HysteresisModel); 2] = [
        (1, HysteresisModel::ModifiedPi),
        (2, HysteresisModel::BoucWen),
    ];
}

impl DecouplingModel {
    pub const CODES: [(i32, DecouplingModel); 2] = [
        (1, DecouplingModel::PiecewiseLinear),
        (2, DecouplingModel::ModelBased),
    ];
}

/// Everything that defines the controller.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControllerParams {
    pub feedforward: bool,
    pub decoupling: bool,
    pub feedback_x: bool,
    pub feedback_y: bool,
    pub feedback_theta: bool,
    /// x and y axes (seed 000 §3.2: kp 0.05, ki 50).
    pub translation_gains: PiGains,
    /// θz axis, on the differential displacement e_θ·L/2 (kp 0.06, ki 70).
    pub rotation_gains: PiGains,
    /// L, distance between the x sensors s2 and s3 [mm].
    pub sensor_spacing_mm: f64,
    /// Shared by PZT2 and PZT3 (two instances with their own memories).
    pub x_model: InversePiParams,
    /// PZT1.
    pub y_model: InversePiParams,
    pub decoupling_params: DecouplingParams,
    /// Feedforward model (fixed while running).
    pub hysteresis_model: HysteresisModel,
    /// Decoupling law (fixed while running; `decoupling` switches it).
    pub decoupling_model: DecouplingModel,
    /// Seed 001's four Bouc-Wen models, in command volts.
    pub bouc_wen: BoucWenModels,
    /// Command range of every channel [V]. Seed 000's stage: −2..12 V, the
    /// control input range PI recommends for its LVPZT amplifiers such as
    /// the E-505 (−20..120 V at the stacks; MODEL.md §4).
    pub command_min: f64,
    pub command_max: f64,
    /// Each sensor's reading (s1, s2, s3) at the displacement the references
    /// and the inverse models count from [µm], subtracted from the sensors
    /// before the PI laws: the feedback then shares the feedforward's zero.
    /// 0 for sensors that read 0 there (the presets' plant); a model fitted
    /// on raw readings counts from its own zero (`piezo-identify`'s
    /// `displacement_offset_um`, `sensor_offset_um`), which goes here.
    #[serde(default)]
    pub sensor_offsets: [f64; 3],
}

impl ControllerParams {
    /// Seed 000's controller as printed: Table 1 and eq. (8)-(9) (see
    /// `InversePiModels::paper`), Table 2, the §3.2 gains; L of the plant preset.
    pub fn paper() -> Self {
        let models = InversePiModels::paper();
        ControllerParams {
            feedforward: true,
            decoupling: false,
            feedback_x: true,
            feedback_y: true,
            feedback_theta: true,
            translation_gains: PiGains { kp: 0.05, ki: 50.0 },
            rotation_gains: PiGains { kp: 0.06, ki: 70.0 },
            sensor_spacing_mm: FlexureStageParams::default().sensor_spacing_mm,
            x_model: models.x,
            y_model: models.y,
            decoupling_params: DecouplingParams::paper(),
            hysteresis_model: HysteresisModel::ModifiedPi,
            decoupling_model: DecouplingModel::PiecewiseLinear,
            // Seed 000 has no Bouc-Wen models; those identified on this
            // project's plant stand in, so the seed 001 paths can be tried.
            bouc_wen: ControllerParams::stage().bouc_wen,
            command_min: -2.0,
            command_max: 12.0,
            sensor_offsets: [0.0; 3],
        }
    }

    /// L [mm].
    pub const SENSOR_SPACING_MM: Range = Range::POSITIVE;

    /// A sensor's offset [µm] (`sensor_offsets`).
    pub const SENSOR_OFFSET_UM: Range = Range::FINITE;

    /// Checks every value against its declared range (the ranges the FMU's
    /// variable table states), then the command range; the error names the
    /// parameter by its serde path.
    pub fn validate(&self) -> Result<(), ParamError> {
        for (name, gains) in [
            ("translation_gains", self.translation_gains),
            ("rotation_gains", self.rotation_gains),
        ] {
            PiGains::GAIN.check(&format!("{name}.kp"), gains.kp)?;
            PiGains::GAIN.check(&format!("{name}.ki"), gains.ki)?;
        }
        Self::SENSOR_SPACING_MM.check("sensor_spacing_mm", self.sensor_spacing_mm)?;
        for (k, offset) in self.sensor_offsets.iter().enumerate() {
            Self::SENSOR_OFFSET_UM.check(&format!("sensor_offsets[{k}]"), *offset)?;
        }
        if !(self.command_min.is_finite() && self.command_max.is_finite())
            || self.command_max <= self.command_min
        {
            return Err(ParamError {
                parameter: "command_max".to_owned(),
                value: self.command_max,
                allowed: "> command_min (finite)".to_owned(),
            });
        }
        let feedforward = self.hysteresis_model == HysteresisModel::BoucWen;
        let model_based = self.decoupling_model == DecouplingModel::ModelBased;
        for (name, model, selected) in [
            ("bouc_wen.x", &self.bouc_wen.x, feedforward),
            ("bouc_wen.y", &self.bouc_wen.y, feedforward),
            ("bouc_wen.x_from_y", &self.bouc_wen.x_from_y, model_based),
            ("bouc_wen.y_from_x", &self.bouc_wen.y_from_x, model_based),
        ] {
            model.validate(name)?;
            // Only a selected model runs (the selectors are fixed while
            // running): an unused one is not held to what running needs.
            if selected {
                model.check_bounded(
                    name,
                    self.command_min,
                    self.command_max,
                    "the command range",
                )?;
            }
        }
        // Eq. (6) inverts y = p·u + q·h: the x and y models must rise with
        // their command where they start from virgin (h = 0: slope p + q·A),
        // or the inverse has no command to give for a rising demand.
        for (name, model) in [
            ("bouc_wen.x", &self.bouc_wen.x),
            ("bouc_wen.y", &self.bouc_wen.y),
        ]
        .into_iter()
        .filter(|_| feedforward)
        {
            let slope = model.p + model.q * model.a;
            if slope.is_nan() || slope <= 0.0 {
                return Err(ParamError {
                    parameter: format!("{name}.p"),
                    value: model.p,
                    allowed: format!(
                        "a model that rises with its command, p + q·A > 0 (eq. 4 at h = 0), as \
                         the inverse of eq. (6) needs; here p + q·A = {} + {}·{} = {slope}",
                        model.p, model.q, model.a
                    ),
                });
            }
        }
        BoucWenModels::REST_CYCLE.check("bouc_wen.rest_cycle", self.bouc_wen.rest_cycle)?;
        self.x_model.validate("x_model")?;
        self.y_model.validate("y_model")?;
        let d = &self.decoupling_params;
        for (field, values) in [("dk", d.dk), ("db", d.db), ("p", d.p), ("q", d.q)] {
            for (i, v) in values.iter().enumerate() {
                Range::FINITE.check(&format!("decoupling_params.{field}[{i}]"), *v)?;
            }
        }
        // Eq. (11) clips D_i between the lower cutoff q_i and the upper p_i:
        // a q above p makes D_i the constant p_i whatever the demand (Table
        // 2's misprinted q_1 = 10 beside p_1 = 2.05 does), which is no
        // compensation, so it is refused rather than run.
        for (i, (p, q)) in d.p.iter().zip(d.q).enumerate() {
            if q > *p {
                return Err(ParamError {
                    parameter: format!("decoupling_params.q[{i}]"),
                    value: q,
                    allowed: format!(
                        "at most the upper cutoff p of the same compensation, {p} (eq. 11 \
                         clips D{} between q and p; ±10 marks an unused cutoff)",
                        i + 1
                    ),
                });
            }
        }
        Ok(())
    }
}

/// The `stage` preset: seed 000's identification procedure run on the
/// FlexureStage plant by `piezo-identify stage` (`make stage-preset`).
const STAGE_PRESET_JSON: &str = include_str!("../presets/piezo_controller_stage.json");

impl ControllerParams {
    /// The controller identified on this project's FlexureStage plant as
    /// seed 000 identified its own stage: eq. (6) records and inverse-model
    /// fits of x and y, single-axis runs and fitted decoupling compensations.
    /// The paper's own numbers ([`ControllerParams::paper`]) describe the
    /// paper's stage, not this plant.
    pub fn stage() -> Self {
        serde_json::from_str(STAGE_PRESET_JSON)
            .expect("presets/piezo_controller_stage.json must parse (a test checks it)")
    }
}

/// PiezoController's start values: the [`ControllerParams::stage`] preset.
impl Default for ControllerParams {
    fn default() -> Self {
        ControllerParams::stage()
    }
}

/// One sample's commands and the diagnostics users plot.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ControllerOutput {
    /// Commands of PZT1, PZT2, PZT3 [V], within the command range.
    pub u: [f64; 3],
    /// Feedforward part of each command [V].
    pub feedforward: [f64; 3],
    /// Feedback part of each command [V].
    pub feedback: [f64; 3],
    pub e_x: f64,
    pub e_y: f64,
    /// [rad]
    pub e_theta: f64,
    /// The inverse models' inputs (eq. 11); without decoupling, the demands.
    pub decoupled: DecoupledReferences,
}

impl ControllerOutput {
    /// What each of [`ControllerOutput::values`] is, for the user.
    pub const NAMES: [&'static str; 16] = [
        "last command u1",
        "last command u2",
        "last command u3",
        "last feedforward of PZT1",
        "last feedforward of PZT2",
        "last feedforward of PZT3",
        "last feedback of PZT1",
        "last feedback of PZT2",
        "last feedback of PZT3",
        "last error e_x",
        "last error e_y",
        "last error e_theta",
        "last decoupled reference x_r2",
        "last decoupled reference x_r3",
        "last decoupled reference y_rx",
        "last decoupled reference y_rtheta",
    ];

    /// Every value of the sample, in [`ControllerOutput::NAMES`] order.
    #[inline]
    pub fn values(&self) -> [f64; 16] {
        let d = &self.decoupled;
        [
            self.u[0],
            self.u[1],
            self.u[2],
            self.feedforward[0],
            self.feedforward[1],
            self.feedforward[2],
            self.feedback[0],
            self.feedback[1],
            self.feedback[2],
            self.e_x,
            self.e_y,
            self.e_theta,
            d.x_r2,
            d.x_r3,
            d.y_rx,
            d.y_rtheta,
        ]
    }

    /// Whether every value of the sample is finite: a step that overflowed
    /// (a huge step size over the integrators) is not. This runs at every
    /// sample, so without a compare or branch per value: the values are
    /// summed in two lanes (one vector register, one addition per pair), and
    /// a sum with an infinity or a NaN in it is not finite. A finite sum
    /// proves every value finite; a sum that is not finite is checked value
    /// by value, since finite values huge enough can overflow it (a sample
    /// that is that far gone is rare and need not be fast).
    #[inline]
    #[expect(clippy::eq_op, reason = "x − x is the finiteness test")]
    pub fn is_finite(&self) -> bool {
        let values = self.values();
        // The lanes start at the first pair, not at zero: 0.0 + x is not x
        // for x = −0.0, so an addition of zero would be kept.
        let mut lanes = [values[0], values[1]];
        for pair in values[2..].chunks_exact(2) {
            lanes[0] += pair[0];
            lanes[1] += pair[1];
        }
        // x − x is +0 for a finite x and NaN otherwise (∞ − ∞, NaN − NaN):
        // a test of its bits for zero is one compare for the whole sample.
        let sum = lanes[0] + lanes[1];
        (sum - sum).to_bits() == 0 || self.each_is_finite()
    }

    #[cold]
    #[inline(never)]
    fn each_is_finite(&self) -> bool {
        self.values().iter().all(|v| v.is_finite())
    }
}

/// The inverse models' inputs at a sample and the time to the next one.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
struct PreviousSample {
    references: [f64; 3],
    /// The sample's dt: the time from it to the next sample, over which
    /// that sample's rate of eq. (4) is taken.
    period: f64,
}

/// The sampled controller.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PiezoController {
    params: ControllerParams,
    /// Inverse models of PZT1, PZT2, PZT3.
    models: [ModifiedInversePi; 3],
    /// Seed 001's inverse models of PZT1, PZT2, PZT3 (run only when
    /// selected: `hysteresis_model` is fixed while running).
    bouc_wen: BoucWenFeedforward,
    /// Seed 001's coupling models (run only with the model-based law).
    coupling: CouplingEstimator,
    /// Previous inputs of the three models and the period they were held
    /// for (that sample's dt), for the rates of eq. (4).
    previous_references: Option<PreviousSample>,
    pi_x: PiController,
    pi_y: PiController,
    pi_theta: PiController,
    /// Which limit each channel hit at the previous sample: +1 upper, −1
    /// lower, 0 none (for the anti-windup).
    limited: [i8; 3],
    output: ControllerOutput,
}

/// Channel directions of each axis's feedback: y → PZT1; x → PZT2, PZT3;
/// θ → +PZT2, −PZT3.
const Y_DIRECTIONS: [f64; 3] = [1.0, 0.0, 0.0];
const X_DIRECTIONS: [f64; 3] = [0.0, 1.0, 1.0];
const THETA_DIRECTIONS: [f64; 3] = [0.0, 1.0, -1.0];

/// Input substep of the Bouc-Wen models [V of command]: one RK4 step per
/// sample at 10 kHz for any command the stage follows.
const BOUC_WEN_MAX_DU: f64 = 0.01;

/// The output before the first sample: the rest, 0 V, as far as the command
/// range lets it (the commands are always inside it).
fn rest_output(params: &ControllerParams) -> ControllerOutput {
    ControllerOutput {
        u: [0.0f64.clamp(params.command_min, params.command_max); 3],
        ..ControllerOutput::default()
    }
}

impl PiezoController {
    pub fn new(params: ControllerParams) -> Result<Self, ParamError> {
        params.validate()?;
        // Only the selected Bouc-Wen models are settled on their exercised
        // loops: the settling is most of a construction's cost (about 3.5 ms
        // for the five), and the others never run (the selectors are fixed
        // while running, see `set_tuning`), so they stay virgin.
        let unused = BoucWenModels {
            rest_cycle: 0.0,
            return_point_memory: false,
            ..params.bouc_wen
        };
        let selected = |yes: bool| if yes { &params.bouc_wen } else { &unused };
        let feedforward_models = selected(params.hysteresis_model == HysteresisModel::BoucWen);
        let coupling_models = selected(params.decoupling_model == DecouplingModel::ModelBased);
        let output = rest_output(&params);
        Ok(PiezoController {
            models: [
                ModifiedInversePi::new(params.y_model),
                ModifiedInversePi::new(params.x_model),
                ModifiedInversePi::new(params.x_model),
            ],
            bouc_wen: BoucWenFeedforward::new(feedforward_models, BOUC_WEN_MAX_DU),
            coupling: CouplingEstimator::new(coupling_models, BOUC_WEN_MAX_DU),
            params,
            previous_references: None,
            pi_x: PiController::default(),
            pi_y: PiController::default(),
            pi_theta: PiController::default(),
            limited: [0; 3],
            output,
        })
    }

    pub fn params(&self) -> &ControllerParams {
        &self.params
    }

    /// This controller rebuilt from its parameters and its dynamic state
    /// alone (see [`crate::restore`]): for a controller that comes from
    /// outside, such as a deserialized FMU state. The parameters are
    /// validated as [`PiezoController::new`] validates them (the tunable
    /// ones included: an importer's tuning holds their ranges, which the FMI
    /// layer checks when they are set), and everything derived from them is
    /// built again (the inverse models' thresholds and
    /// exercised rests). The dynamic state (backlash memories, every
    /// Bouc-Wen model's point, the previous references, the integrators, the
    /// limit flags and the last sample) is carried over as it is
    /// ([`PiezoController::unreachable_state`] checks it). The rebuilt
    /// controller steps exactly as the original would have.
    pub fn rebuilt(&self) -> Result<PiezoController, ParamError> {
        let mut controller = PiezoController::new(self.params.clone())?;
        for (model, own) in controller.models.iter_mut().zip(&self.models) {
            model.carry_memories(own);
        }
        controller.bouc_wen.carry_points(&self.bouc_wen);
        controller.coupling.carry_points(&self.coupling);
        controller.previous_references = self.previous_references;
        controller.pi_x = self.pi_x;
        controller.pi_y = self.pi_y;
        controller.pi_theta = self.pi_theta;
        controller.limited = self.limited;
        controller.output = self.output;
        Ok(controller)
    }

    /// The first dynamic state variable that holds what no run of the
    /// controller does: a value that is not finite, or a limit flag other
    /// than -1, 0 or 1.
    pub fn unreachable_state(&self) -> Option<UnreachableState> {
        const MEMORIES: [&str; 3] = [
            "backlash memory of the inverse P-I model of PZT1",
            "backlash memory of the inverse P-I model of PZT2",
            "backlash memory of the inverse P-I model of PZT3",
        ];
        const BOUC_WEN: [[&str; 2]; 5] = [
            [
                "input of the inverse Bouc-Wen model of PZT1",
                "hysteretic state of the inverse Bouc-Wen model of PZT1",
            ],
            [
                "input of the inverse Bouc-Wen model of PZT2",
                "hysteretic state of the inverse Bouc-Wen model of PZT2",
            ],
            [
                "input of the inverse Bouc-Wen model of PZT3",
                "hysteretic state of the inverse Bouc-Wen model of PZT3",
            ],
            [
                "input of the coupling model x from y",
                "hysteretic state of the coupling model x from y",
            ],
            [
                "input of the coupling model y from x",
                "hysteretic state of the coupling model y from x",
            ],
        ];
        let memories = self.models.iter().zip(MEMORIES).flat_map(|(model, name)| {
            model
                .memories()
                .into_iter()
                .map(move |memory| (name, memory))
        });
        let bouc_wen = self
            .bouc_wen
            .models()
            .into_iter()
            .chain(self.coupling.models())
            .zip(BOUC_WEN)
            .flat_map(|(model, [input, state])| {
                [(input, model.input()), (state, model.hysteretic_state())]
            });
        let previous = self.previous_references.unwrap_or(PreviousSample {
            references: [0.0; 3],
            period: 1.0,
        });
        let references = previous
            .references
            .map(|reference| ("previous reference", reference));
        let integrals = [
            ("integral of the x PI controller", self.pi_x.integral),
            ("integral of the y PI controller", self.pi_y.integral),
            (
                "integral of the theta_z PI controller",
                self.pi_theta.integral,
            ),
        ];
        let output = ControllerOutput::NAMES
            .into_iter()
            .zip(self.output.values());
        let bouc_wen_memories = self
            .bouc_wen
            .models()
            .into_iter()
            .chain(self.coupling.models())
            .filter_map(AsymmetricBoucWen::unreachable_memory);
        memories
            .chain(bouc_wen)
            .chain(bouc_wen_memories)
            .chain(references)
            .chain(integrals)
            .chain(output)
            .find_map(|(variable, value)| UnreachableState::unless_finite(variable, value))
            .or_else(|| {
                // A period is a step's dt: finite and positive.
                if previous.period.is_finite() && previous.period > 0.0 {
                    None
                } else {
                    Some(UnreachableState {
                        variable: "period of the previous sample",
                        value: previous.period,
                        allowed: "a positive finite step size",
                    })
                }
            })
            .or_else(|| {
                let flag = self
                    .limited
                    .into_iter()
                    .find(|flag| !(-1..=1).contains(flag))?;
                Some(UnreachableState {
                    variable: "limit flag of a channel",
                    value: f64::from(flag),
                    allowed: "-1 (at command_min), 0 or 1 (at command_max)",
                })
            })
    }

    /// The parameters that may change while running: switches and gains.
    /// Turning an axis's feedback off empties its integrator. The model
    /// selectors (`hysteresis_model`, `decoupling_model`) are not among them:
    /// they keep the values the controller was built with (build a new
    /// controller to change them).
    pub fn set_tuning(&mut self, tuning: impl FnOnce(&mut ControllerParams)) {
        let selectors = (self.params.hysteresis_model, self.params.decoupling_model);
        tuning(&mut self.params);
        (self.params.hysteresis_model, self.params.decoupling_model) = selectors;
        for (on, pi) in [
            (self.params.feedback_x, &mut self.pi_x),
            (self.params.feedback_y, &mut self.pi_y),
            (self.params.feedback_theta, &mut self.pi_theta),
        ] {
            if !on {
                pi.reset();
            }
        }
    }

    pub fn reset(&mut self) {
        for model in &mut self.models {
            model.reset();
        }
        self.bouc_wen.reset();
        self.coupling.reset();
        self.previous_references = None;
        self.pi_x.reset();
        self.pi_y.reset();
        self.pi_theta.reset();
        self.limited = [0; 3];
        self.output = rest_output(&self.params);
    }

    pub fn output(&self) -> &ControllerOutput {
        &self.output
    }

    /// Per channel, whether the last sample's command was limited: 1 at
    /// `command_max`, −1 at `command_min`, 0 inside (what the anti-windup
    /// of the next sample acts on).
    pub fn limited(&self) -> [i8; 3] {
        self.limited
    }

    /// One sample of period `dt` (> 0): references x_ref, y_ref [µm],
    /// theta_ref [rad]; sensors s1, s2, s3 [µm].
    #[inline]
    pub fn step(
        &mut self,
        x_ref: f64,
        y_ref: f64,
        theta_ref: f64,
        sensors: [f64; 3],
        dt: f64,
    ) -> ControllerOutput {
        let p = &self.params;
        let half_spacing_um = 0.5 * p.sensor_spacing_mm * 1e3;
        let x_d2 = x_ref + theta_ref * half_spacing_um;
        let x_d3 = x_ref - theta_ref * half_spacing_um;
        let (decoupled, references) = match (p.decoupling, p.decoupling_model) {
            (true, DecouplingModel::PiecewiseLinear) => {
                let d = decouple(&p.decoupling_params, x_d2, x_d3, y_ref, p.sensor_spacing_mm);
                (d, [d.y_r(y_ref), d.x_r2, d.x_r3])
            }
            (true, DecouplingModel::ModelBased) => {
                // Seed 001 eq. (9)-(16) as a correction of the references:
                // subtract the coupled displacements H_XY[v_y], H_YX[v_x].
                let estimate = self.coupling.estimate();
                let y_r = y_ref - estimate.y_from_x;
                let d = DecoupledReferences {
                    x_r2: x_d2 - estimate.x_from_y,
                    x_r3: x_d3 - estimate.x_from_y,
                    y_rx: y_r,
                    y_rtheta: y_ref,
                };
                (d, [y_r, d.x_r2, d.x_r3])
            }
            (false, _) => {
                let d = DecoupledReferences {
                    x_r2: x_d2,
                    x_r3: x_d3,
                    y_rx: y_ref,
                    y_rtheta: y_ref,
                };
                (d, [y_ref, x_d2, x_d3])
            }
        };
        // Eq. (4)'s rate is the backward difference over the time since
        // the previous sample, that sample's dt: with steps of changing size
        // (a master that aligns to events or output points), this step's dt
        // would scale the rate by the ratio of the two.
        let previous = self.previous_references.unwrap_or(PreviousSample {
            references,
            period: dt,
        });
        self.previous_references = Some(PreviousSample {
            references,
            period: dt,
        });
        // The selected models always advance (the P-I memories here, the
        // Bouc-Wen states after limiting below), so switching the
        // feedforward on later starts from memories that followed the demand.
        let mut feedforward = [0.0; 3];
        match p.hysteresis_model {
            HysteresisModel::ModifiedPi => {
                for (channel, model) in self.models.iter_mut().enumerate() {
                    let rate =
                        (references[channel] - previous.references[channel]) / previous.period;
                    let u = model.evaluate(references[channel], rate);
                    if p.feedforward {
                        feedforward[channel] = u;
                    }
                }
            }
            HysteresisModel::BoucWen => {
                if p.feedforward {
                    feedforward = self.bouc_wen.commands(references);
                }
            }
        }

        // Displacements from the references' zero.
        let [s1, s2, s3] = [0, 1, 2].map(|k| sensors[k] - p.sensor_offsets[k]);
        let e_x = x_ref - 0.5 * (s2 + s3);
        let e_y = y_ref - s1;
        let e_theta = theta_ref - (s2 - s3) / (2.0 * half_spacing_um);
        let axes = [
            (p.feedback_y, p.translation_gains, e_y, Y_DIRECTIONS),
            (p.feedback_x, p.translation_gains, e_x, X_DIRECTIONS),
            (
                p.feedback_theta,
                p.rotation_gains,
                e_theta * half_spacing_um,
                THETA_DIRECTIONS,
            ),
        ];
        let (lo, hi) = (p.command_min, p.command_max);
        let limited = self.limited;
        let mut feedback = [0.0; 3];
        for ((on, gains, error, directions), pi) in
            axes.into_iter()
                .zip([&mut self.pi_y, &mut self.pi_x, &mut self.pi_theta])
        {
            if !on {
                continue;
            }
            let winds_up = (0..3).any(|c| f64::from(limited[c]) * directions[c] * error > 0.0);
            let v = pi.update(gains, error, dt, !winds_up);
            for c in 0..3 {
                feedback[c] += directions[c] * v;
            }
        }
        let raw = [0, 1, 2].map(|c| feedforward[c] + feedback[c]);
        self.limited = raw.map(|u| {
            if u >= hi {
                1
            } else if u <= lo {
                -1
            } else {
                0
            }
        });
        let u = raw.map(|u| u.clamp(lo, hi));
        // Seed 001's models follow the commands actually applied.
        if p.hysteresis_model == HysteresisModel::BoucWen {
            self.bouc_wen.commit(u);
        }
        if p.decoupling_model == DecouplingModel::ModelBased {
            self.coupling.commit(u);
        }
        self.output = ControllerOutput {
            u,
            feedforward,
            feedback,
            e_x,
            e_y,
            e_theta,
            decoupled,
        };
        self.output
    }
}

//! The `stage` controller preset: seed 000's identification procedure run on
//! a plant FMU (FlexureStage by default).
//!
//! 1. Inverse models (§3.1): eq. (6) drives PZT1 (y) and, separately, the x
//!    pair (u2 = u3) from rest for 10 s at 10 kHz; the modified inverse P-I
//!    model of each axis is fitted to (displacement, command) by separable
//!    least squares (best of N random starts, [`crate::fit`]).
//! 2. Decoupling (§4): with those models, the §3.2 PI gains and no
//!    decoupling, three single-axis runs as in Fig. 7 (feedback on the driven
//!    axis only, feedforward of the constant demand on the others) record the
//!    coupling errors; the four compensations D_i are fitted to them
//!    ([`crate::decoupling`]).
//! 3. Further rounds repeat the runs with the decoupling on and refit each
//!    compensation, whole, to what it applied plus the coupling left (the
//!    plant's coupling moves once the compensations move the actuators).
//!    Seed 000 fits the compensations once (step 2 alone,
//!    [`StageIdentification::fitted_once`]); the rounds go beyond it, fitted
//!    on the very runs Table 3 is measured on. The
//!    static coupling of the x pair at home into y belongs to D3; D4 fits
//!    what D3 leaves of the rotation run's y error, since y_r = y_d + D3 + D4
//!    applies both.
//!
//! 4. Seed 001's models (§5.2-5.3): a 2 Hz sine from 0 to 10 V drives PZT1
//!    and, separately, the x pair from rest (three periods at 10 kHz); the
//!    asymmetric Bouc-Wen models H_YY, H_XX of the driven axes (with the
//!    `monotone` option: the feedforward inverts them) and H_XY, H_YX of the
//!    coupled displacements are fitted by GA-PSO and Levenberg-Marquardt
//!    ([`crate::bouc_wen_fit`]), in command volts, with no offset (the plant
//!    starts at rest at 0). They fill `bouc_wen` of the preset; the preset
//!    keeps seed 000's feedforward and decoupling selected.
//! 5. Whether the Bouc-Wen models close their minor loops
//!    (`bouc_wen.return_point_memory`), chosen from one more record per
//!    driven axis, taken for it: from rest up to 7 V, then four 2 Hz cycles
//!    between 7 and 3 V (minor loops inside the 0-10 V loop of step 4, where
//!    a stack's loops close and eq. (3)'s drift). H_XX and H_YY, at the rest
//!    the controller starts them at, predict those records with and without
//!    the memory; the smaller summed RMS error decides, for all four models.
//!    The fit of step 4 is on the major loop, which the memory leaves as it
//!    is (its rest loop is eq. (3)'s own), so it serves both.
//!
//! Single-axis runs, as seed 000 §5 prints them: "the motion axis was driven
//! (10 µm or 9.2×10⁻³ deg), with the demand on the other two axes held at
//! zero". Demands are absolute, from the de-energized rest: a y or x run is a
//! 1 Hz sine from 0 to 10 µm starting at the bottom (y = 5 − 5 cos 2πt) with
//! the other axes demanded at 0; a θ run is ±9.2·10⁻³° (eq. 16's amplitude)
//! about x at half its stroke, where §3.2 puts x's home "in order to implement
//! the rotational motion", y at 0. The reference reaches the start pose by a
//! raised cosine over 0.5 s (only the θ run's x moves), holds 0.5 s, then the
//! sine runs for 5 s; the fit uses the last 2 s. These are the conditions of
//! the demo's Fig. 7/10 runs, read from the one file both use,
//! `demo/experiment_conditions.json` ([`conditions`]).

use std::f64::consts::PI;
use std::sync::LazyLock;

use piezo_models::bouc_wen::AsymmetricBoucWen;
use piezo_models::decoupling::rotation_demand;
use piezo_models::{
    BoucWenModels, BoucWenParams, ControllerParams, DecouplingModel, DecouplingParams,
    HysteresisModel, InversePiParams, PiGains,
};
use serde::{Deserialize, Serialize};

use crate::bouc_wen_fit::{
    BoucWenFitError, BoucWenFitOptions, identify_bouc_wen, wide_shape_bounds,
};
use crate::decoupling::{
    Compensation, DecouplingError, NO_CUTOFF, decoupling_params, fit_compensation_with_cutoff,
};
use crate::fit::{Fit, FitError, FitOptions, StartResult, fit_modified_inverse_pi_with_progress};
use crate::gapso::GaPsoOptions;
use crate::plant::{
    PlantError, PlantFmu, RecordAxis, closed_loop, command_records, eq6_record, exercise_samples,
    sine_records,
};
use crate::protocol::LINEAR_RSS_INCREASE;

/// The experiment conditions this procedure shares with the demo's
/// single-axis runs (`demo/experiments.py`), which measure what the fitted
/// decoupling achieves: one data file, read by both.
pub const CONDITIONS_JSON: &str = include_str!("../../demo/experiment_conditions.json");

/// How the reference leaves rest: a raised cosine from the origin to the
/// start pose over `time_s`, then held for `settle_time_s`.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Approach {
    pub shape: ApproachShape,
    pub time_s: f64,
    pub settle_time_s: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ApproachShape {
    /// 0.5·(1 − cos πt/T): no step at either end.
    RaisedCosine,
}

/// Where a translation sine starts: `Bottom` is base + span/2·(1 − cos 2πft).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SineStart {
    Bottom,
}

/// A translation pose [µm].
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PlanePoint {
    pub x: f64,
    pub y: f64,
}

/// Seed 000 §5's single-axis runs as printed.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SingleAxisConditions {
    pub sine_frequency_hz: f64,
    pub sine_start: SineStart,
    /// Peak-to-peak of the translation sines, from 0 (seed 000 §5: 10 µm).
    pub translation_span_um: f64,
    /// Held translations: x during the y run, y during the x run.
    pub held_um: PlanePoint,
    /// θ sine amplitude (eq. 16's 9.2·10⁻³°).
    pub rotation_amplitude_deg: f64,
    /// Cycles run before the measured (fitted) ones: the plant's Bouc-Wen
    /// minor loops settle within about four cycles of a new excursion.
    pub settling_cycles: u32,
    pub measured_cycles: u32,
}

/// The homes the experiments run about [µm].
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Homes {
    /// x at half its stroke (seed 000 §2: 12.74 µm), where §3.2 puts x's home
    /// "in order to implement the rotational motion".
    pub rotation: PlanePoint,
    pub mid_stroke: PlanePoint,
    pub single_axis_flexure: PlanePoint,
    pub single_axis_xy200s: PlanePoint,
}

/// `demo/experiment_conditions.json`.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentConditions {
    pub about: String,
    pub approach: Approach,
    pub single_axis: SingleAxisConditions,
    pub homes_um: Homes,
}

impl ExperimentConditions {
    /// Time from rest to the start of the trajectory [s].
    pub fn start_time(&self) -> f64 {
        self.approach.time_s + self.approach.settle_time_s
    }

    /// Length of a single-axis run after the start [s].
    pub fn run_time(&self) -> f64 {
        let cycles = self.single_axis.settling_cycles + self.single_axis.measured_cycles;
        f64::from(cycles) / self.single_axis.sine_frequency_hz
    }

    /// The measured (fitted) part at the end of a run [s].
    pub fn fitted_time(&self) -> f64 {
        f64::from(self.single_axis.measured_cycles) / self.single_axis.sine_frequency_hz
    }

    /// The raised-cosine blend 0 → 1 at time `t` of the approach.
    pub fn approach_blend(&self, t: f64) -> f64 {
        match self.approach.shape {
            ApproachShape::RaisedCosine => {
                let s = (t / self.approach.time_s).clamp(0.0, 1.0);
                0.5 * (1.0 - (PI * s).cos())
            }
        }
    }
}

/// The shared conditions, parsed once (a malformed file fails the
/// `conditions_file_parses` test and names the problem).
pub fn conditions() -> &'static ExperimentConditions {
    static CONDITIONS: LazyLock<ExperimentConditions> = LazyLock::new(|| {
        serde_json::from_str(CONDITIONS_JSON)
            .unwrap_or_else(|error| panic!("demo/experiment_conditions.json: {error}"))
    });
    &CONDITIONS
}

pub const SAMPLE_PERIOD: f64 = 1e-4;
pub const PREVIEW: usize = 2;
/// eq. (6) is applied for 10 s (one period of its 0.2 Hz component).
pub const IDENTIFICATION_TIME: f64 = 10.0;
/// The exercise cycle before eq. (6), 0 → 10 → 0 V [s]: it runs the stack
/// over the loop it rests on, so the model's memories (set by running the
/// operators through the cycle, not fitted) start in the stack's state.
pub const EXERCISE_TIME: f64 = 2.0;

/// The axis a single-axis run drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum DrivenAxis {
    Y,
    X,
    Theta,
}

impl DrivenAxis {
    /// The axis as messages name it.
    pub fn name(self) -> &'static str {
        match self {
            DrivenAxis::Y => "y",
            DrivenAxis::X => "x",
            DrivenAxis::Theta => "theta_z",
        }
    }
}

/// How hard and where the single-axis runs drive a stage. The defaults are
/// seed 000's as printed (§5, §3.2); another stage scales them to its
/// strokes (seed 001's XY200S, 144 µm, runs the same procedure at 11.3x the
/// amplitudes), and its PI gains by the inverse of its gain in µm per
/// command volt relative to seed 000's stage, which keeps the loop gain that
/// Ziegler-Nichols gave seed 000 (the §3.2 gains make the XY200S's loops
/// unstable).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct StageConditions {
    /// Peak-to-peak of the x and y sines, from 0 [µm].
    pub translation_span_um: f64,
    /// Demand of the held translation while the other one is driven [µm]:
    /// x during the y run, y during the x run (seed 000: 0, 0). A stage
    /// whose actuators cannot go below 0 V can only cancel a coupling that
    /// lifts the held axis from a home above it (seed 000 §3.2's reason
    /// for x's home at half stroke).
    pub held_um: [f64; 2],
    /// x demand of the θ run [µm] (half the x stroke).
    pub rotation_x_um: f64,
    /// Amplitude of the θ sine [deg]; `None`: the stage has no rotation to
    /// identify (its x actuators move together), D4 stays zero.
    pub rotation_amplitude_deg: Option<f64>,
    /// Factor on both PI gain pairs of §3.2.
    pub gain_scale: f64,
    /// Command range of the controller [V].
    pub command_range: (f64, f64),
    /// The cutoff value that means "no cutoff" [µm]: Table 2's ±10 µm on a
    /// 12 µm stage, scaled with the stroke on another one.
    pub no_cutoff_um: f64,
}

impl Default for StageConditions {
    fn default() -> Self {
        let shared = conditions();
        // PI's recommended control input of its LVPZT amplifiers (E-505:
        // −2..12 V, −20..120 V at the stack; MODEL.md §4): the controller's
        // own start values.
        let controller = ControllerParams::default();
        StageConditions {
            translation_span_um: shared.single_axis.translation_span_um,
            held_um: [shared.single_axis.held_um.x, shared.single_axis.held_um.y],
            rotation_x_um: shared.homes_um.rotation.x,
            rotation_amplitude_deg: Some(shared.single_axis.rotation_amplitude_deg),
            gain_scale: 1.0,
            command_range: (controller.command_min, controller.command_max),
            no_cutoff_um: NO_CUTOFF,
        }
    }
}

impl StageConditions {
    /// Seed 000's conditions on a stage whose strokes are `scale` times seed
    /// 000's (cutoffs and amplitudes scaled; no rotation run when the stage
    /// does not rotate).
    pub fn scaled(scale: f64, rotation: bool) -> Self {
        let printed = StageConditions::default();
        StageConditions {
            translation_span_um: printed.translation_span_um * scale,
            rotation_x_um: printed.rotation_x_um * scale,
            rotation_amplitude_deg: printed.rotation_amplitude_deg.filter(|_| rotation),
            no_cutoff_um: printed.no_cutoff_um * scale,
            ..printed
        }
    }
}

/// The reference of a single-axis run at time `t` (x [µm], y [µm], θ [rad]).
pub fn single_axis_reference(axis: DrivenAxis, conditions: &StageConditions, t: f64) -> [f64; 3] {
    let shared = self::conditions();
    let start = shared.start_time();
    let path = |tau: f64| {
        let phase = 2.0 * PI * shared.single_axis.sine_frequency_hz * tau;
        // SineStart::Bottom, the only start: from 0 up.
        let half = 0.5 * conditions.translation_span_um;
        match axis {
            DrivenAxis::Y => [conditions.held_um[0], half - half * phase.cos(), 0.0],
            DrivenAxis::X => [half - half * phase.cos(), conditions.held_um[1], 0.0],
            DrivenAxis::Theta => [
                conditions.rotation_x_um,
                0.0,
                conditions
                    .rotation_amplitude_deg
                    .unwrap_or(0.0)
                    .to_radians()
                    * phase.sin(),
            ],
        }
    };
    if t >= start {
        return path(t - start);
    }
    let blend = shared.approach_blend(t);
    path(0.0).map(|v| blend * v)
}

/// The pairs (driving demand, coupling error) of the compensations one run
/// feeds: y runs feed D1 (x2) and D2 (x3), x runs D3, θ runs D4.
fn coupling_pairs(
    axis: DrivenAxis,
    run: &crate::plant::ClosedLoopRun,
    spacing_um: f64,
) -> Vec<(usize, Vec<f64>, Vec<f64>)> {
    let shared = conditions();
    let from = shared.start_time() + shared.run_time() - shared.fitted_time() - 1e-9;
    let window: Vec<usize> = (0..run.t.len()).filter(|&k| run.t[k] >= from).collect();
    let half = spacing_um / 2.0;
    let collect = |demand: &dyn Fn(usize) -> f64, error: &dyn Fn(usize) -> f64| {
        (
            window.iter().map(|&k| demand(k)).collect::<Vec<_>>(),
            window.iter().map(|&k| error(k)).collect::<Vec<_>>(),
        )
    };
    let r = &run.references;
    let s = &run.sensors;
    match axis {
        DrivenAxis::Y => {
            let (f1, e1) = collect(&|k| r[k][1], &|k| r[k][0] + r[k][2] * half - s[k][1]);
            let (f2, e2) = collect(&|k| r[k][1], &|k| r[k][0] - r[k][2] * half - s[k][2]);
            vec![(0, f1, e1), (1, f2, e2)]
        }
        DrivenAxis::X => {
            let (f, e) = collect(&|k| r[k][0], &|k| r[k][1] - s[k][0]);
            vec![(2, f, e)]
        }
        DrivenAxis::Theta => {
            // D4 takes θ_zd in the controller's unit for it.
            let (f, e) = collect(&|k| rotation_demand(r[k][2]), &|k| r[k][1] - s[k][0]);
            vec![(3, f, e)]
        }
    }
}

/// Everything the `stage` identification measured.
#[derive(Clone, Debug, Serialize)]
pub struct StageIdentification {
    pub controller: ControllerParams,
    pub x_fit: FitSummary,
    pub y_fit: FitSummary,
    /// Compensations of each round.
    pub rounds: Vec<[Compensation; 4]>,
    /// Seed 001's models: name and eq. (5) RMS of the refined fit [µm].
    pub bouc_wen_fits: Vec<(String, f64)>,
    /// Step 5 (module comment): the minor-loop records' prediction errors,
    /// and the choice.
    pub bouc_wen_memory: MemoryChoice,
}

/// Step 5 (module comment): RMS errors [µm] of H_XX and H_YY, summed, on the
/// minor-loop records, without and with the return-point memory.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct MemoryChoice {
    pub rms_without_um: f64,
    pub rms_with_um: f64,
    pub return_point_memory: bool,
}

/// Step 5's record: from rest up to the top, then cycles between top and
/// bottom [V], at seed 001's identification frequency.
const MINOR_LOOP_TOP: f64 = 7.0;
const MINOR_LOOP_BOTTOM: f64 = 3.0;
const MINOR_LOOP_CYCLES: f64 = 4.0;

/// Step 5's command: a raised cosine from 0 to the top over half a period,
/// then `MINOR_LOOP_CYCLES` cosine cycles between top and bottom.
fn minor_loop_command(sample_rate: f64) -> Vec<f64> {
    let period = 1.0 / BOUC_WEN_HZ;
    let rise = (0.5 * period * sample_rate).round() as usize;
    let cycles = (MINOR_LOOP_CYCLES * period * sample_rate).round() as usize;
    let phase = |n: usize, samples_per_period: f64| {
        2.0 * std::f64::consts::PI * n as f64 / samples_per_period
    };
    let per_period = period * sample_rate;
    let middle = 0.5 * (MINOR_LOOP_TOP + MINOR_LOOP_BOTTOM);
    let half_span = 0.5 * (MINOR_LOOP_TOP - MINOR_LOOP_BOTTOM);
    (0..rise)
        .map(|n| 0.5 * MINOR_LOOP_TOP * (1.0 - phase(n, per_period).cos()))
        .chain((0..cycles).map(|n| middle + half_span * phase(n, per_period).cos()))
        .collect()
}

/// Step 5 (module comment).
fn choose_bouc_wen_memory(
    plant: &PlantFmu,
    models: &BoucWenModels,
) -> Result<MemoryChoice, StageError> {
    let input = minor_loop_command(1.0 / SAMPLE_PERIOD);
    let mut rms = [0.0; 2];
    for (axis, params) in [(RecordAxis::X, models.x), (RecordAxis::Y, models.y)] {
        let (driven, _) = command_records(plant, axis, &input, 1.0 / SAMPLE_PERIOD)?;
        for (memory, total) in [false, true].into_iter().zip(&mut rms) {
            let mut model = AsymmetricBoucWen::at_exercised_rest(params, models.rest_cycle);
            if memory {
                model = model.with_return_point_memory(models.rest_cycle);
            }
            let squares: f64 = driven
                .input
                .iter()
                .zip(&driven.output)
                .map(|(&u, &y)| {
                    model.advance_to(u, MINOR_LOOP_MAX_DU);
                    (model.output() - y).powi(2)
                })
                .sum();
            *total += (squares / driven.input.len() as f64).sqrt();
        }
    }
    Ok(MemoryChoice {
        rms_without_um: rms[0],
        rms_with_um: rms[1],
        return_point_memory: rms[1] < rms[0],
    })
}

/// Substep of step 5's predictions [V]: the controller's own (its
/// `BOUC_WEN_MAX_DU`).
const MINOR_LOOP_MAX_DU: f64 = 0.01;

impl StageIdentification {
    /// The preset with the compensations of the first round alone: D1..D4
    /// fitted once, on single-axis runs without decoupling, as seed 000 §4
    /// computes them "based on the experimental results from single axis
    /// actuation testing (Fig. 7)". Later rounds refit them on runs with
    /// the decoupling on, which the paper does not.
    pub fn fitted_once(&self) -> ControllerParams {
        let mut once = self.controller.clone();
        if let Some(first) = self.rounds.first() {
            once.decoupling_params = decoupling_params(first);
        }
        once
    }
}

/// Seed 001 §5.2's identification run on the plant: 2 Hz, 0 to 10 V.
const BOUC_WEN_HZ: f64 = 2.0;
const BOUC_WEN_PEAK: f64 = 10.0;
const BOUC_WEN_PERIODS: f64 = 3.0;

/// Step 4 (module comment): the four Bouc-Wen models in command volts.
fn fit_bouc_wen_models(
    plant: &PlantFmu,
    progress: &dyn Fn(&str),
) -> Result<(BoucWenModels, Vec<(String, f64)>), StageError> {
    let mut fitted: Vec<(BoucWenParams, (String, f64))> = Vec::new();
    for (axis, own, coupled) in [
        (RecordAxis::X, "H_XX", "H_YX"),
        (RecordAxis::Y, "H_YY", "H_XY"),
    ] {
        progress(&format!(
            "seed 001 sine run and Bouc-Wen fits of {own} and {coupled}"
        ));
        let (driven, coupling) = sine_records(
            plant,
            axis,
            BOUC_WEN_HZ,
            BOUC_WEN_PEAK,
            BOUC_WEN_PERIODS,
            1.0 / SAMPLE_PERIOD,
        )?;
        for (name, record, monotone) in [(own, &driven, true), (coupled, &coupling, false)] {
            // The wide box: a stage's loops need not look like seed 000's
            // (the XY200S's, converted from seed 001's printed models, lie
            // outside the default box).
            let options = BoucWenFitOptions {
                gapso: GaPsoOptions::default(),
                bounds: wide_shape_bounds(),
                // The monotone check must hold on every sample, which a
                // search on a decimated record does not see.
                decimation: if monotone { 1 } else { 10 },
                // The first period runs the model from h = 0 onto the loop
                // the stage rests on; the fit starts after it.
                warm_up_samples: (SAMPLE_PERIOD.recip() / BOUC_WEN_HZ).round() as usize,
                // The readings are zeroed at the stage's rest, the model's
                // output after its first cycle is not: the offset between
                // them is fitted and dropped, since the controller's models
                // start at their own rest, zeroed there (`rest_cycle`).
                fit_offset: true,
                monotone,
                ..BoucWenFitOptions::default()
            };
            let fit = identify_bouc_wen(&record.input, &record.output, &options, |_, _| {})
                .map_err(|source| StageError::BoucWen {
                    model: name,
                    source,
                })?;
            fitted.push((fit.best().params, (name.to_owned(), fit.best().rms)));
        }
    }
    let models = BoucWenModels {
        x: fitted[0].0,
        y_from_x: fitted[1].0,
        y: fitted[2].0,
        x_from_y: fitted[3].0,
        // The plant rests on its loop to 10 V of command (100 V): so do the
        // models.
        rest_cycle: BOUC_WEN_PEAK,
        // Step 5 decides.
        return_point_memory: false,
    };
    Ok((
        models,
        fitted.into_iter().map(|(_, summary)| summary).collect(),
    ))
}

#[derive(Clone, Debug, Serialize)]
pub struct FitSummary {
    /// F = ‖u_model − u‖² over the 10 s record at 10 kHz (eq. 7) [V²].
    pub f: f64,
    pub rms_v: f64,
    pub max_v: f64,
}

impl FitSummary {
    fn of(fit: &Fit<InversePiParams>) -> FitSummary {
        FitSummary {
            f: fit.quality.objective,
            rms_v: fit.quality.rms,
            max_v: fit.quality.max_abs,
        }
    }
}

/// Why the stage identification failed.
#[derive(Debug, thiserror::Error)]
pub enum StageError {
    #[error(transparent)]
    Plant(#[from] PlantError),
    #[error("fitting the {axis} inverse model: {source}")]
    Fit {
        axis: &'static str,
        #[source]
        source: FitError,
    },
    #[error("fitting the Bouc-Wen model {model}: {source}")]
    BoucWen {
        model: &'static str,
        #[source]
        source: BoucWenFitError,
    },
    #[error("fitting compensation D{index}: {source}")]
    Decoupling {
        index: usize,
        #[source]
        source: DecouplingError,
    },
    #[error("{0}: the plant has no parameter L (sensor spacing) to read")]
    NoSpacing(String),
    #[error(
        "the single-axis {axis} run does not track: its error is {rms_um:.3} um RMS on a demand \
         spanning {span_um:.3} um, so the couplings it shows are the loop's, not the stage's; \
         seed 000's PI gains times --gain-scale {gain_scale} are unstable or saturate on this \
         plant (try a smaller --gain-scale)"
    )]
    DoesNotTrack {
        axis: &'static str,
        rms_um: f64,
        span_um: f64,
        gain_scale: f64,
    },
}

/// Largest tracking RMS of a single-axis run's driven axis, as a share of its
/// demand's span, for the run's couplings to be the stage's: a loop that
/// tracks errs by a few per cent of the span, one that oscillates or sits on
/// a command limit by its whole span or more.
const MAX_TRACKING_SHARE: f64 = 0.5;

/// The driven axis's tracking error over the fitted window of `run`, RMS
/// [µm at the actuators, for θ], and its demand's span there.
fn driven_tracking(
    axis: DrivenAxis,
    run: &crate::plant::ClosedLoopRun,
    spacing_um: f64,
) -> (f64, f64) {
    let shared = conditions();
    let from = shared.start_time() + shared.run_time() - shared.fitted_time() - 1e-9;
    let half = spacing_um / 2.0;
    let (mut sum, mut count, mut low, mut high) = (0.0, 0usize, f64::INFINITY, f64::NEG_INFINITY);
    for k in (0..run.t.len()).filter(|&k| run.t[k] >= from) {
        let (r, s) = (run.references[k], run.sensors[k]);
        let (demand, reached) = match axis {
            DrivenAxis::Y => (r[1], s[0]),
            DrivenAxis::X => (r[0], 0.5 * (s[1] + s[2])),
            DrivenAxis::Theta => (r[2] * half, 0.5 * (s[1] - s[2])),
        };
        sum += (demand - reached).powi(2);
        count += 1;
        low = low.min(demand);
        high = high.max(demand);
    }
    ((sum / count.max(1) as f64).sqrt(), high - low)
}

/// Runs steps 1-3 on `plant`; `progress(message)` is told what runs.
pub fn identify_stage(
    plant: &PlantFmu,
    options: &FitOptions,
    rounds: usize,
    conditions: &StageConditions,
    progress: &dyn Fn(&str),
    fit_progress: &(dyn Fn(usize) + Sync),
) -> Result<StageIdentification, StageError> {
    let spacing_mm = plant
        .start("L")
        .ok_or_else(|| StageError::NoSpacing("plant".to_owned()))?;
    let sample_rate = 1.0 / SAMPLE_PERIOD;
    let (command_min, command_max) = conditions.command_range;
    let mut fits = Vec::new();
    for (axis, name) in [(RecordAxis::X, "x"), (RecordAxis::Y, "y")] {
        progress(&format!(
            "eq. (6) record and fit of the {name} inverse model"
        ));
        let record = eq6_record(
            plant,
            axis,
            IDENTIFICATION_TIME,
            sample_rate,
            command_max,
            EXERCISE_TIME,
        )?;
        let warm_up = exercise_samples(EXERCISE_TIME, sample_rate);
        // The final linear solve is regularised as the identification
        // protocol's is (`protocol::LINEAR_RSS_INCREASE`). After the exercise
        // cycle, eq. (6)'s record barely moves the two widest backlash
        // operators (r_9, r_10 near u1max/2), so their columns are nearly
        // each other and G's constant, and the plain solve's weights along
        // that direction are set by rounding: centring the constant
        // (`least_squares::solve_least_squares_with_intercept`) turned
        // b_9, b_10, a_4 = 0.017, -0.012, 0.48 into 96, -96, -187 with the
        // same fitted voltages (RMS 0.019674 V). Such weights cancel on the
        // record and nowhere else.
        //
        // Backlash operators that do not reverse over the fitted samples get
        // no weight, as in the identification protocol
        // (`regressors::reversing_operators` says why). Regularising cannot
        // do it: on the XY200S's x record eq. (5)'s r_9 = u1max/2 moves by
        // 4e-4 of z's span, only when a peak of the record passes the
        // highest before, and least squares made it a tracker of the stage's
        // Bouc-Wen drift (b_9 = b_10 = -382 V/um against a_4 = +6915 V). That
        // direction carried two thirds of F, so no 0.1 % of RSS removed it;
        // the controller, whose memories start at its own rest, was then off
        // by 0.4 V (6.8 um at 90 um) where the record was not.
        let options = FitOptions {
            warm_up_samples: options.warm_up_samples.max(warm_up),
            rss_increase: options.rss_increase.max(LINEAR_RSS_INCREASE),
            reversing_operators_only: true,
            ..options.clone()
        };
        let mut fit = fit_modified_inverse_pi_with_progress(
            &record.output,
            &record.input,
            record.sample_period,
            &options,
            &|s: &StartResult| fit_progress(s.start),
        )
        .map_err(|source| StageError::Fit { axis: name, source })?;
        // The stage rests on the loop the exercise cycle ran: the model's
        // memories start where that cycle left them (eq. 1's "initial energy
        // condition").
        fit.params.rest_cycle = record.output[..warm_up].iter().copied().fold(0.0, f64::max);
        fits.push(fit);
    }
    let (x_fit, y_fit) = (fits.remove(0), fits.remove(0));
    let (mut bouc_wen, bouc_wen_fits) = fit_bouc_wen_models(plant, progress)?;
    progress("minor-loop runs: do the Bouc-Wen models need a return-point memory");
    let bouc_wen_memory = choose_bouc_wen_memory(plant, &bouc_wen)?;
    bouc_wen.return_point_memory = bouc_wen_memory.return_point_memory;
    let mut controller = ControllerParams {
        feedforward: true,
        decoupling: false,
        feedback_x: true,
        feedback_y: true,
        feedback_theta: true,
        translation_gains: PiGains {
            kp: 0.05 * conditions.gain_scale,
            ki: 50.0 * conditions.gain_scale,
        },
        rotation_gains: PiGains {
            kp: 0.06 * conditions.gain_scale,
            ki: 70.0 * conditions.gain_scale,
        },
        sensor_spacing_mm: spacing_mm,
        x_model: x_fit.params,
        y_model: y_fit.params,
        decoupling_params: DecouplingParams {
            dk: [0.0; 4],
            db: [0.0; 4],
            p: [conditions.no_cutoff_um; 4],
            q: [-conditions.no_cutoff_um; 4],
        },
        hysteresis_model: HysteresisModel::ModifiedPi,
        decoupling_model: DecouplingModel::PiecewiseLinear,
        bouc_wen,
        command_min,
        command_max,
        // The procedure's models count from the plant's rest, where its
        // sensors read 0 (step 4 above).
        sensor_offsets: [0.0; 3],
    };
    let spacing_um = spacing_mm * 1e3;
    let mut all_rounds = Vec::new();
    for round in 0..rounds {
        // Round 0 runs without decoupling, so its errors are the whole
        // coupling; later rounds run with the compensations so far, and what
        // is applied plus what is left is the coupling to fit again.
        let applied = controller.decoupling_params;
        let applied_eval = |i: usize, f: f64| {
            if round == 0 {
                0.0
            } else {
                Compensation::of(&applied, i).eval(f)
            }
        };
        let mut pairs: [Option<(Vec<f64>, Vec<f64>)>; 4] = Default::default();
        let axes: &[DrivenAxis] = if conditions.rotation_amplitude_deg.is_some() {
            &[DrivenAxis::Y, DrivenAxis::X, DrivenAxis::Theta]
        } else {
            &[DrivenAxis::Y, DrivenAxis::X]
        };
        for &axis in axes {
            progress(&format!(
                "decoupling round {}: single-axis {axis:?} run",
                round + 1
            ));
            let mut run_params = controller.clone();
            run_params.decoupling = round > 0;
            run_params.feedback_x = axis == DrivenAxis::X;
            run_params.feedback_y = axis == DrivenAxis::Y;
            run_params.feedback_theta = axis == DrivenAxis::Theta;
            let run = closed_loop(
                plant,
                &run_params,
                |t| single_axis_reference(axis, conditions, t),
                self::conditions().start_time() + self::conditions().run_time(),
                SAMPLE_PERIOD,
                PREVIEW,
            )?;
            let (rms_um, span_um) = driven_tracking(axis, &run, spacing_um);
            // A NaN error (a run that diverged) does not track either.
            let tracks = rms_um <= MAX_TRACKING_SHARE * span_um;
            if !tracks {
                return Err(StageError::DoesNotTrack {
                    axis: axis.name(),
                    rms_um,
                    span_um,
                    gain_scale: conditions.gain_scale,
                });
            }
            for (index, f, e) in coupling_pairs(axis, &run, spacing_um) {
                let total = f
                    .iter()
                    .zip(&e)
                    .map(|(f, e)| e + applied_eval(index, *f))
                    .collect();
                pairs[index] = Some((f, total));
            }
        }
        let fit = |index: usize, e: &[f64], f: &[f64]| {
            fit_compensation_with_cutoff(f, e, conditions.no_cutoff_um).map_err(|source| {
                StageError::Decoupling {
                    index: index + 1,
                    source,
                }
            })
        };
        let pair = |index: usize| {
            pairs[index]
                .as_ref()
                .expect("every compensation that is fitted has its run")
        };
        let d1 = fit(0, &pair(0).1, &pair(0).0)?;
        let d2 = fit(1, &pair(1).1, &pair(1).0)?;
        let d3 = fit(2, &pair(2).1, &pair(2).0)?;
        let d4 = if pairs[3].is_some() {
            // y's two compensations add up (y_r = y_d + D3 + D4), and the
            // rotation run holds x at half stroke, so its y error also holds
            // the static coupling of the x pair there, which D3 compensates:
            // D4 gets what D3 leaves of it (otherwise the offset is
            // compensated twice).
            let x = conditions.rotation_x_um;
            let x_share = d3.eval(x) - applied_eval(2, x);
            let theta_target: Vec<f64> = pair(3).1.iter().map(|e| e - x_share).collect();
            fit(3, &theta_target, &pair(3).0)?
        } else {
            Compensation::none(conditions.no_cutoff_um)
        };
        let fitted = [d1, d2, d3, d4];
        controller.decoupling_params = decoupling_params(&fitted);
        all_rounds.push(fitted);
    }
    controller.decoupling = true;
    Ok(StageIdentification {
        controller,
        x_fit: FitSummary::of(&x_fit),
        y_fit: FitSummary::of(&y_fit),
        rounds: all_rounds,
        bouc_wen_fits,
        bouc_wen_memory,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A run that follows its sine within 1 % tracks; one whose x pair
    /// swings far past its demand (an unstable loop, as the PI gains of
    /// seed 000 on a stiffer, lighter stage make it) does not.
    #[test]
    fn driven_tracking_tells_a_loop_that_follows_from_one_that_swings() {
        let stage = StageConditions::default();
        let end = conditions().start_time() + conditions().run_time();
        let t: Vec<f64> = (0..=(end / 1e-3) as usize)
            .map(|k| k as f64 * 1e-3)
            .collect();
        let references: Vec<[f64; 3]> = t
            .iter()
            .map(|&t| single_axis_reference(DrivenAxis::X, &stage, t))
            .collect();
        let run = |gain: f64, swing: f64| crate::plant::ClosedLoopRun {
            t: t.clone(),
            references: references.clone(),
            sensors: t
                .iter()
                .zip(&references)
                .map(|(t, r)| {
                    let x = gain * r[0] + swing * (2.0 * std::f64::consts::PI * 600.0 * t).sin();
                    [0.0, x, x]
                })
                .collect(),
        };
        let (rms, span) = driven_tracking(DrivenAxis::X, &run(0.99, 0.0), 76_580.0);
        assert!((span - stage.translation_span_um).abs() < 1e-6, "{span}");
        assert!(
            rms < 0.01 * span && rms <= MAX_TRACKING_SHARE * span,
            "{rms}"
        );
        let (rms, span) = driven_tracking(DrivenAxis::X, &run(1.0, 150.0), 76_580.0);
        assert!(rms > MAX_TRACKING_SHARE * span, "{rms} of {span}");
    }

    #[test]
    fn conditions_file_parses_into_the_printed_protocol() {
        let shared = conditions();
        // Seed 000 §5's single-axis runs: 10 µm from 0, ±9.2·10⁻³°, x at
        // half its 12.74 µm stroke while the platform rotates.
        assert_eq!(shared.single_axis.translation_span_um, 10.0);
        assert_eq!(shared.single_axis.rotation_amplitude_deg, 9.2e-3);
        assert!((shared.homes_um.rotation.x - 12.74 / 2.0).abs() < 1e-12);
        assert!(shared.run_time() > shared.fitted_time() && shared.fitted_time() > 0.0);
    }

    #[test]
    fn single_axis_runs_start_at_rest_and_sine_from_the_bottom() {
        let shared = conditions();
        let stage = StageConditions::default();
        let start = shared.start_time();
        for axis in [DrivenAxis::Y, DrivenAxis::X, DrivenAxis::Theta] {
            assert_eq!(single_axis_reference(axis, &stage, 0.0), [0.0, 0.0, 0.0]);
        }
        // The θ run's x reaches its home by the end of the approach, smoothly.
        let half_way =
            single_axis_reference(DrivenAxis::Theta, &stage, 0.5 * shared.approach.time_s);
        assert!((half_way[0] - 0.5 * stage.rotation_x_um).abs() < 1e-12);
        let home = single_axis_reference(DrivenAxis::Theta, &stage, start);
        assert_eq!(home[0], stage.rotation_x_um);
        // Half a period after the start the translation sine is at its top.
        let top = start + 0.5 / shared.single_axis.sine_frequency_hz;
        let y = single_axis_reference(DrivenAxis::Y, &stage, top)[1];
        assert!((y - stage.translation_span_um).abs() < 1e-9);
    }
}

//! Identification of seed 001's asymmetric Bouc-Wen model (eq. 3-4) from an
//! input/displacement record: GA-PSO on the RMS fitness of eq. (5) (seed 001
//! §3), then a Levenberg-Marquardt refinement that the paper does not make.
//!
//! # Structure used
//!
//! Eq. (3)-(4) have seven parameters (p, q, A, β, γ, n, δ), but one of them is
//! redundant: scaling the hysteretic state h by s > 0 and (q, A, β, γ, δ) as
//! [`BoucWenParams::with_state_scale`] says leaves the output unchanged, so
//! no record can identify all seven, and a search over all seven wanders
//! along a valley of equal fitness. And given the shape of the loop, the
//! output y = p·u + q·h (+ a sensor offset) is linear in p and q. So:
//!
//! - input and output are scaled to order one (ũ = u/U with U = max|u|,
//!   ỹ = y/Y with Y the output span), and the state scale is fixed by Ã = 1;
//! - GA-PSO ([`crate::gapso`]) searches only the shape (β̃, γ̃, n, δ̃) in
//!   these units, and for each candidate the state h̃ is simulated and
//!   (p̃, q̃, offset) solved by linear least squares (variable projection), so
//!   the fitness of a shape is the best eq. (5) RMS any (p, q, offset) can
//!   reach with it;
//! - Levenberg-Marquardt (the `levenberg-marquardt` crate) then minimises the
//!   same projected residual from the GA-PSO optimum, on every sample, with a
//!   forward-difference Jacobian. It only accepts steps that lower the
//!   residual, so the refined fit is never worse than the GA-PSO one;
//! - the result is written back in physical units in the representative
//!   with |q| = 1 (h in output units, y = p·u ± h + offset); any other
//!   representative follows from `with_state_scale`.
//!
//! The model and its rate-independent reading of eq. (3)'s asymmetry term are
//! those of [`piezo_models::bouc_wen`]: the fit and the plant share one
//! implementation.

use std::ops::Range;
use std::time::Instant;

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use lm_nalgebra::{DMatrix as LmMatrix, DVector as LmVector, Dyn, Owned};
use nalgebra::DMatrix;
use piezo_models::{BoucWenParams, hysteretic_states_into};
use serde::{Deserialize, Serialize};

use crate::gapso::{self, Bounds, GaPsoError, GaPsoOptions};
use crate::least_squares::solve_least_squares;

/// Names of the searched shape parameters, in the order of [`Bounds`].
pub const SHAPE_PARAMETERS: [&str; 4] = ["beta", "gamma", "n", "delta"];

/// Input substeps of the state integration per unit of the scaled input
/// (RK4, error far below the data's noise; see `piezo_models::bouc_wen`).
pub const SUBSTEPS_PER_INPUT_SCALE: f64 = 500.0;

/// |h̃| beyond which a candidate shape counts as diverged (h̃ is of order one
/// for any shape that describes a loop).
const DIVERGED_STATE: f64 = 1e12;

/// Smallest n: below 1, |h|^(n−1) is singular at h = 0.
pub const MIN_EXPONENT: f64 = 1.0;

/// Default search box of the scaled shape (β̃, γ̃, n, δ̃): β̃ ≥ 0 keeps the
/// loop dissipative; |β̃|, |γ̃| ≤ 10 let the state saturate within a tenth
/// of the input scale; n from 1 to 3 spans the printed identifications (seed
/// 001 Tables 1-2: 1.5 to 2.5); |δ̃| ≤ 2 tilts the two branches' slopes by
/// up to their whole value.
pub fn default_shape_bounds() -> Bounds {
    Bounds {
        lower: vec![0.0, -10.0, MIN_EXPONENT, -2.0],
        upper: vec![10.0, 10.0, 3.0, 2.0],
    }
}

/// A box ten times [`default_shape_bounds`] in β̃, γ̃ and δ̃, and n up to
/// 5: for loops far from a plain piezo's, such as those the printed models
/// of seed 001 draw (their conversion reaches β̃ ≈ 51 and n ≈ 2.8) and the
/// XY200S actuators built from them. GA-PSO then needs more generations to
/// search it as finely.
pub fn wide_shape_bounds() -> Bounds {
    Bounds {
        lower: vec![0.0, -100.0, MIN_EXPONENT, -20.0],
        upper: vec![100.0, 100.0, 5.0, 20.0],
    }
}

/// Settings of [`identify_bouc_wen`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BoucWenFitOptions {
    pub gapso: GaPsoOptions,
    /// Box of the scaled shape (β̃, γ̃, n, δ̃) ([`default_shape_bounds`]).
    pub bounds: Bounds,
    /// GA-PSO evaluates every N-th sample (the model is rate independent, so
    /// a coarser input path changes it only between samples); the
    /// refinement and every reported error use all samples.
    pub decimation: usize,
    /// Samples at the start that drive the model but are not fitted nor
    /// scored (a start-up transient).
    pub warm_up_samples: usize,
    /// Further samples that drive the model but are not fitted (rest
    /// segments, the settling after a voltage step: `segments`).
    #[serde(default)]
    pub excluded: Vec<Range<usize>>,
    /// Fit a constant sensor offset with p and q (else the output is taken
    /// as zero at rest).
    pub fit_offset: bool,
    /// Accept only models whose every branch rises with the input on the
    /// record (dy/du > 0), i.e. models with an inverse for feedforward (off
    /// by default: seed 001 fits the data without it, and a measured loop
    /// fitted best may turn back briefly at reversals).
    pub monotone: bool,
    /// RK4 substeps per unit of the scaled input in GA-PSO's evaluations
    /// (the refinement and every reported figure use
    /// [`SUBSTEPS_PER_INPUT_SCALE`]). At 100, the state of a 1 Hz loop
    /// differs from the one at 500 by at most 6·10⁻⁶ of its span even at the
    /// default box's stiffest corner (γ̃ = −10, n = 1, δ̃ = 2), 10⁻⁹ to
    /// 10⁻⁷ elsewhere: far below any sensor's noise, at a fifth of the cost.
    #[serde(default = "default_search_substeps")]
    pub search_substeps: f64,
    /// Refine the GA-PSO optimum by Levenberg-Marquardt.
    pub refine: bool,
    /// Keep the refinement inside `bounds` (see `refine`). Off in
    /// [`BoucWenFitOptions::default`], which the conversion of seed 001's
    /// printed models (`xy200s`) and the stage preset use: there the box is
    /// only where GA-PSO searches a noise-free printed model, and the
    /// refinement may leave it towards a closer copy (H_XY: 0.10 % of its
    /// span outside the wide box, 0.12 % inside). On measured data the box is
    /// what is plausible, and a refinement that leaves it fits noise: the
    /// identification protocol (`protocol::BoucWenSettings`, the CLI) keeps
    /// it on.
    #[serde(default)]
    pub refine_within_bounds: bool,
    /// Fit the model with a return-point memory: its minor loops close
    /// (`piezo_models::bouc_wen::ReturnPointMemory`), as FlexureStage's
    /// `return_point_memory` runs its stacks. A model fitted so is run so
    /// ([`predict`]); off, seed 001's eq. (3) as integrated.
    #[serde(default)]
    pub return_point_memory: bool,
}

fn default_search_substeps() -> f64 {
    SUBSTEPS_PER_INPUT_SCALE
}

impl BoucWenFitOptions {
    /// Which of `len` samples are fitted: those after the warm-up and outside
    /// every excluded range.
    pub fn fitted_samples(&self, len: usize) -> Vec<bool> {
        let mut fitted: Vec<bool> = (0..len).map(|n| n >= self.warm_up_samples).collect();
        for range in &self.excluded {
            for flag in &mut fitted[range.start.min(len)..range.end.min(len)] {
                *flag = false;
            }
        }
        fitted
    }
}

impl Default for BoucWenFitOptions {
    fn default() -> Self {
        BoucWenFitOptions {
            gapso: GaPsoOptions::default(),
            bounds: default_shape_bounds(),
            decimation: 1,
            warm_up_samples: 0,
            excluded: Vec::new(),
            fit_offset: true,
            monotone: false,
            search_substeps: SUBSTEPS_PER_INPUT_SCALE,
            refine: true,
            refine_within_bounds: false,
            return_point_memory: false,
        }
    }
}

/// One fitted Bouc-Wen model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BoucWenModelFit {
    /// Physical parameters, representative with |q| = 1.
    pub params: BoucWenParams,
    /// Constant sensor offset added to eq. (4) [output units].
    pub offset: f64,
    /// Eq. (5) on the identification record's scored samples [output units].
    pub rms: f64,
    /// Largest |error| there [output units].
    pub max_error: f64,
    /// Signed extremes of the error (model − measurement) there [output
    /// units]: seed 001 §5.2 reports its fits this way.
    pub error_range: (f64, f64),
    /// The scaled shape (β̃, γ̃, n, δ̃, [`SHAPE_PARAMETERS`]) the model was
    /// made from: where it lies in the search box.
    pub shape: Vec<f64>,
}

impl BoucWenModelFit {
    /// The shape parameters that sit on a wall of `bounds` (within 0.1 % of
    /// the box's width) where the wall is only the search's: the best model
    /// may lie beyond it. n = 1 and β̃ = 0 are limits of the model itself
    /// (the smallest exponent; a loop that dissipates), so a fit on them is
    /// no sign of a short box.
    pub fn on_search_walls(&self, bounds: &Bounds) -> Vec<(&'static str, f64)> {
        SHAPE_PARAMETERS
            .iter()
            .enumerate()
            .filter_map(|(i, &name)| {
                let (low, high, value) = (bounds.lower[i], bounds.upper[i], self.shape[i]);
                let near = 1e-3 * (high - low);
                let model_limit =
                    (name == "n" && low <= MIN_EXPONENT) || (name == "beta" && low <= 0.0);
                if high - value <= near {
                    Some((name, high))
                } else if value - low <= near && !model_limit {
                    Some((name, low))
                } else {
                    None
                }
            })
            .collect()
    }
}

/// GA-PSO's fit and its refinement.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BoucWenIdentification {
    pub gapso: BoucWenModelFit,
    /// The model after the refinement step (when asked): Levenberg-Marquardt
    /// from the GA-PSO optimum if that lowered the fitted RMS, else GA-PSO's.
    pub refined: Option<BoucWenModelFit>,
    /// Whether Levenberg-Marquardt's result was kept (it lowered the RMS on
    /// the fitted samples).
    #[serde(default)]
    pub refinement_kept: bool,
    /// RMS of Levenberg-Marquardt's result on the fitted samples, kept or
    /// not [output units].
    #[serde(default)]
    pub refinement_rms: Option<f64>,
    /// Best eq. (5) RMS after each GA-PSO generation, on the searched
    /// (decimated) samples [output units].
    pub history: Vec<f64>,
    /// Fitness evaluations by GA-PSO and by the refinement.
    pub gapso_evaluations: usize,
    pub refinement_evaluations: usize,
    /// Wall time of each stage [s].
    pub gapso_seconds: f64,
    pub refinement_seconds: f64,
}

impl BoucWenIdentification {
    /// The refined fit when there is one, else GA-PSO's.
    pub fn best(&self) -> &BoucWenModelFit {
        self.refined.as_ref().unwrap_or(&self.gapso)
    }
}

/// Why a record cannot be fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BoucWenFitError {
    #[error("input has {input} samples, output {output}; they must be equal")]
    Lengths { input: usize, output: usize },
    #[error(
        "{scored} samples to fit after the warm-up{}; at least {needed} are needed",
        if *decimation > 1 { format!(", one in {decimation} searched") } else { String::new() }
    )]
    TooShort {
        scored: usize,
        needed: usize,
        /// The search's every-N-th sample, which a too-large --decimation
        /// makes the cause (the message blamed the warm-up alone).
        decimation: usize,
    },
    #[error("sample {index} is not finite")]
    NotFinite { index: usize },
    #[error("the input is zero throughout: nothing drives the model")]
    NoInput,
    #[error("the output is constant: there is no response to fit")]
    NoResponse,
    #[error(
        "no shape in the search box gives a usable model (every candidate diverged{}); widen --bounds",
        ", or drew a branch that falls as the input rises"
    )]
    NoUsableShape,
    #[error(
        "the GA-PSO optimum, searched on one sample in {decimation}, is unusable on the whole \
         record (it diverges or draws a falling branch there); search with --decimation 1"
    )]
    UnusableOnAllSamples { decimation: usize },
    #[error("decimation must be at least 1")]
    Decimation,
    #[error("the search's substeps per input scale must be a finite number of at least 1")]
    Substeps,
    #[error("GA-PSO: {0}")]
    Search(#[from] GaPsoError),
}

/// A record in the scaled units of the module comment.
#[derive(Clone)]
struct ScaledRecord {
    input: Vec<f64>,
    output: Vec<f64>,
    /// Which samples are fitted.
    fitted: Vec<bool>,
    fit_offset: bool,
    monotone: bool,
    /// RK4 substeps per unit of the scaled input.
    substeps: f64,
    return_point_memory: bool,
}

impl ScaledRecord {
    fn decimated(&self, step: usize) -> ScaledRecord {
        ScaledRecord {
            input: self.input.iter().step_by(step).copied().collect(),
            output: self.output.iter().step_by(step).copied().collect(),
            fitted: self.fitted.iter().step_by(step).copied().collect(),
            fit_offset: self.fit_offset,
            monotone: self.monotone,
            substeps: self.substeps,
            return_point_memory: self.return_point_memory,
        }
    }

    /// Indices of the fitted samples.
    fn fitted_indices(&self) -> impl Iterator<Item = usize> + Clone + '_ {
        self.fitted
            .iter()
            .enumerate()
            .filter(|(_, f)| **f)
            .map(|(i, _)| i)
    }

    /// The state h̃ of the shape `shape` = (β̃, γ̃, n, δ̃) along the input.
    fn states(&self, shape: &[f64]) -> Vec<f64> {
        let mut states = vec![0.0; self.input.len()];
        hysteretic_states_into(
            scaled_params(shape),
            &self.input,
            1.0 / self.substeps,
            self.return_point_memory,
            &mut states,
        );
        states
    }

    /// Variable projection: the least-squares (p̃, q̃, offset) for `shape`
    /// and the residuals (model − measurement) on the scored samples.
    fn project(&self, shape: &[f64]) -> Option<([f64; 3], Vec<f64>)> {
        let states = self.states(shape);
        let columns = if self.fit_offset { 3 } else { 2 };
        let scored: Vec<usize> = self.fitted_indices().collect();
        let rows = scored.len();
        // A shape far outside the data's range can drive h to overflow; such
        // a candidate is unusable, not an error (and QR must not see it).
        if scored
            .iter()
            .any(|&i| states[i].is_nan() || states[i].abs() >= DIVERGED_STATE)
        {
            return None;
        }
        let regressors = DMatrix::from_fn(rows, columns, |i, j| match j {
            0 => self.input[scored[i]],
            1 => states[scored[i]],
            _ => 1.0,
        });
        let targets: Vec<f64> = scored.iter().map(|&i| self.output[i]).collect();
        let solution = solve_least_squares(regressors, &targets);
        if !solution.coefficients.iter().all(|c| c.is_finite()) {
            return None;
        }
        let mut coefficients = [0.0; 3];
        coefficients[..columns].copy_from_slice(&solution.coefficients);
        if self.monotone && !self.is_increasing(shape, &states, coefficients) {
            return None;
        }
        let residuals = scored
            .iter()
            .map(|&i| {
                coefficients[0] * self.input[i] + coefficients[1] * states[i] + coefficients[2]
                    - self.output[i]
            })
            .collect();
        Some((coefficients, residuals))
    }

    /// Whether dy/du = p̃ + q̃·dh̃/dũ (eq. 3-4) is positive at the start and
    /// the end of every input segment, in the segment's direction: every
    /// branch the record draws then rises with the input, and the model has
    /// the inverse that seed 001's feedforward (eq. 6) needs.
    fn is_increasing(&self, shape: &[f64], states: &[f64], coefficients: [f64; 3]) -> bool {
        let params = scaled_params(shape);
        let slope = |u: f64, h: f64, direction: f64| {
            coefficients[0] + coefficients[1] * params.state_slope(u, h, direction)
        };
        let (mut u0, mut h0) = (0.0, 0.0);
        for (&u1, &h1) in self.input.iter().zip(states) {
            let direction = (u1 - u0).signum();
            if u1 != u0 && (slope(u0, h0, direction) <= 0.0 || slope(u1, h1, direction) <= 0.0) {
                return false;
            }
            (u0, h0) = (u1, h1);
        }
        true
    }

    /// Eq. (5) in scaled units; infinite for an unusable shape.
    fn rms(&self, shape: &[f64]) -> f64 {
        match self.project(shape) {
            Some((_, residuals)) => root_mean_square(&residuals),
            None => f64::INFINITY,
        }
    }
}

fn root_mean_square(values: &[f64]) -> f64 {
    (values.iter().map(|r| r * r).sum::<f64>() / values.len() as f64).sqrt()
}

/// The scaled model of a shape: Ã = 1, the output part left to the projection.
fn scaled_params(shape: &[f64]) -> BoucWenParams {
    BoucWenParams {
        p: 0.0,
        q: 1.0,
        a: 1.0,
        beta: shape[0],
        gamma: shape[1],
        n: shape[2].max(MIN_EXPONENT),
        delta: shape[3],
    }
}

/// Scales of the record: U = max|u|, Y = output span.
#[derive(Clone, Copy)]
struct Scales {
    input: f64,
    output: f64,
}

/// Physical parameters (|q| = 1 representative) and offset of a scaled fit.
fn physical(shape: &[f64], coefficients: [f64; 3], scales: Scales) -> (BoucWenParams, f64) {
    let (u, y) = (scales.input, scales.output);
    let [p, q, offset] = coefficients;
    let n = shape[2].max(MIN_EXPONENT);
    // h̃ as a function of the physical input u = U·ũ (module comment).
    let in_physical_input = BoucWenParams {
        p: y * p / u,
        q: y * q,
        a: 1.0 / u,
        beta: shape[0] / u,
        gamma: shape[1] / u,
        n,
        delta: shape[3] / (u * u),
    };
    let state_scale = (y * q).abs();
    let params = if state_scale > f64::MIN_POSITIVE {
        in_physical_input.with_state_scale(state_scale)
    } else {
        in_physical_input
    };
    (params, y * offset)
}

/// The model's prediction of `input` (from rest): eq. (4) plus `offset`,
/// integrated with substeps of max|u|/500, with a return-point memory when
/// the model was fitted with one.
pub fn predict(
    params: BoucWenParams,
    offset: f64,
    input: &[f64],
    return_point_memory: bool,
) -> Vec<f64> {
    let scale = input.iter().fold(0.0_f64, |m, u| m.max(u.abs()));
    let max_du = if scale > 0.0 {
        scale / SUBSTEPS_PER_INPUT_SCALE
    } else {
        1.0
    };
    let mut states = vec![0.0; input.len()];
    hysteretic_states_into(params, input, max_du, return_point_memory, &mut states);
    input
        .iter()
        .zip(states)
        .map(|(u, h)| params.p * u + params.q * h + offset)
        .collect()
}

/// Errors of a prediction against a measured record.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PredictionError {
    pub samples: usize,
    /// RMS and extremes of (model − measurement) [output units].
    pub rms: f64,
    pub min: f64,
    pub max: f64,
    /// Span of the measured output over the scored samples [output units].
    pub stroke: f64,
    /// RMS and max |error| as % of that span.
    pub rms_percent: f64,
    pub max_percent: f64,
}

impl PredictionError {
    pub fn max_abs(&self) -> f64 {
        self.min.abs().max(self.max.abs())
    }
}

/// Compares `model` with `measured` from sample `scored_from` on.
pub fn prediction_error(model: &[f64], measured: &[f64], scored_from: usize) -> PredictionError {
    let errors: Vec<f64> = model[scored_from..]
        .iter()
        .zip(&measured[scored_from..])
        .map(|(m, y)| m - y)
        .collect();
    let (lo, hi) = measured[scored_from..]
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), y| {
            (lo.min(*y), hi.max(*y))
        });
    let stroke = hi - lo;
    let rms = root_mean_square(&errors);
    let min = errors.iter().copied().fold(f64::INFINITY, f64::min);
    let max = errors.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    PredictionError {
        samples: errors.len(),
        rms,
        min,
        max,
        stroke,
        rms_percent: 100.0 * rms / stroke,
        max_percent: 100.0 * min.abs().max(max.abs()) / stroke,
    }
}

/// Fits eq. (3)-(4) to `output` driven by `input` (module comment).
/// `progress(generation, best_rms)` follows GA-PSO (RMS in output units).
pub fn identify_bouc_wen(
    input: &[f64],
    output: &[f64],
    options: &BoucWenFitOptions,
    mut progress: impl FnMut(usize, f64),
) -> Result<BoucWenIdentification, BoucWenFitError> {
    if input.len() != output.len() {
        return Err(BoucWenFitError::Lengths {
            input: input.len(),
            output: output.len(),
        });
    }
    if options.decimation == 0 {
        return Err(BoucWenFitError::Decimation);
    }
    let fitted = options.fitted_samples(input.len());
    let needed = 20;
    let scored = fitted
        .iter()
        .step_by(options.decimation)
        .filter(|f| **f)
        .count();
    if scored < needed {
        return Err(BoucWenFitError::TooShort {
            scored,
            needed,
            decimation: options.decimation,
        });
    }
    if let Some(index) = input
        .iter()
        .zip(output)
        .position(|(u, y)| !(u.is_finite() && y.is_finite()))
    {
        return Err(BoucWenFitError::NotFinite { index });
    }
    let input_scale = input.iter().fold(0.0_f64, |m, u| m.max(u.abs()));
    if input_scale == 0.0 {
        return Err(BoucWenFitError::NoInput);
    }
    let (lo, hi) = output
        .iter()
        .zip(&fitted)
        .filter(|(_, f)| **f)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (y, _)| {
            (lo.min(*y), hi.max(*y))
        });
    if hi - lo <= 0.0 {
        return Err(BoucWenFitError::NoResponse);
    }
    let scales = Scales {
        input: input_scale,
        output: hi - lo,
    };
    let record = ScaledRecord {
        input: input.iter().map(|u| u / scales.input).collect(),
        output: output.iter().map(|y| y / scales.output).collect(),
        fitted,
        fit_offset: options.fit_offset,
        monotone: options.monotone,
        substeps: SUBSTEPS_PER_INPUT_SCALE,
        return_point_memory: options.return_point_memory,
    };
    if !(options.search_substeps.is_finite() && options.search_substeps >= 1.0) {
        return Err(BoucWenFitError::Substeps);
    }
    let searched = ScaledRecord {
        substeps: options.search_substeps,
        ..record.decimated(options.decimation)
    };

    let started = Instant::now();
    let search = gapso::minimize(
        |shape| searched.rms(shape),
        &options.bounds,
        &options.gapso,
        |generation, best| progress(generation, best * scales.output),
    )?;
    let gapso_seconds = started.elapsed().as_secs_f64();
    if !search.fitness.is_finite() {
        return Err(BoucWenFitError::NoUsableShape);
    }
    let gapso_fit =
        model_fit(&record, &search.best, scales).ok_or(BoucWenFitError::UnusableOnAllSamples {
            decimation: options.decimation,
        })?;

    let started = Instant::now();
    let (refined, refinement_kept, refinement_rms, refinement_evaluations) = if options.refine {
        let bounds = options.refine_within_bounds.then_some(&options.bounds);
        let (shape, evaluations) = refine(&record, &search.best, bounds);
        // LM accepts only descending steps, but its result must also pass
        // the record's own conditions; it is kept only when it lowers the
        // RMS on the fitted samples.
        match model_fit(&record, &shape, scales) {
            Some(fit) if fit.rms < gapso_fit.rms => {
                let rms = fit.rms;
                (Some(fit), true, Some(rms), evaluations)
            }
            other => (
                Some(gapso_fit.clone()),
                false,
                other.map(|f| f.rms),
                evaluations,
            ),
        }
    } else {
        (None, false, None, 0)
    };
    Ok(BoucWenIdentification {
        gapso: gapso_fit,
        refined,
        refinement_kept,
        refinement_rms,
        history: search.history.iter().map(|h| h * scales.output).collect(),
        gapso_evaluations: search.evaluations,
        refinement_evaluations,
        gapso_seconds,
        refinement_seconds: started.elapsed().as_secs_f64(),
    })
}

/// The fit of `shape` on the whole record; None when the shape is unusable
/// there (it can pass on the searched samples and not on all of them).
fn model_fit(record: &ScaledRecord, shape: &[f64], scales: Scales) -> Option<BoucWenModelFit> {
    let (coefficients, residuals) = record.project(shape)?;
    let (params, offset) = physical(shape, coefficients, scales);
    let max_error = residuals.iter().fold(0.0_f64, |m, r| m.max(r.abs()));
    let low = residuals.iter().copied().fold(f64::INFINITY, f64::min);
    let high = residuals.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Some(BoucWenModelFit {
        params,
        offset,
        rms: root_mean_square(&residuals) * scales.output,
        max_error: max_error * scales.output,
        error_range: (low * scales.output, high * scales.output),
        shape: shape.to_vec(),
    })
}

/// Levenberg-Marquardt on the projected residual from `start`, kept inside
/// `bounds` when given; returns the shape and the residual evaluations spent.
///
/// LM itself knows no bounds. It first runs on the shape as it is (the
/// quickest and most precise way down while the optimum is inside the box);
/// if it ends outside the box (seed 001's n, say, walking past the n = 3
/// the search allowed), it runs again from `start` on the box mapped onto
/// the whole line, θ = lo + (hi − lo)·(1 + sin φ)/2, so that every trial
/// point lies inside and the optimum on a wall is reached, not passed.
fn refine(record: &ScaledRecord, start: &[f64], bounds: Option<&Bounds>) -> (Vec<f64>, usize) {
    // LM needs a residual at every trial point: a trial that breaks the
    // monotone condition (a forward difference across its edge, say) would
    // stop it at once. It therefore minimises the unconstrained residual and
    // the result is checked against `record`'s own conditions below (the
    // caller keeps GA-PSO's fit if it fails them).
    let unconstrained = ScaledRecord {
        monotone: false,
        ..record.clone()
    };
    let (mut shape, mut evaluations) = levenberg_marquardt(&unconstrained, start, None);
    shape[2] = shape[2].max(MIN_EXPONENT);
    if let Some(bounds) = bounds {
        if !bounds.contains(&shape) {
            let (bounded, more) = levenberg_marquardt(&unconstrained, start, Some(bounds));
            shape = bounded;
            evaluations += more;
        }
        // The sine map can round a hair past a wall.
        shape = bounds.clamp(&shape);
    }
    if record.rms(&shape).is_finite() {
        (shape, evaluations)
    } else {
        (start.to_vec(), evaluations)
    }
}

/// One LM run from `start`, on the shape itself or on its box map.
fn levenberg_marquardt(
    record: &ScaledRecord,
    start: &[f64],
    bounds: Option<&Bounds>,
) -> (Vec<f64>, usize) {
    let point: Vec<f64> = match bounds {
        None => start.to_vec(),
        Some(b) => start
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                let fraction = (v - b.lower[i]) / (b.upper[i] - b.lower[i]);
                (2.0 * fraction - 1.0).clamp(-1.0, 1.0).asin()
            })
            .collect(),
    };
    let problem = ProjectedResidual {
        record,
        point: LmVector::from_vec(point),
        bounds,
        evaluations: std::cell::Cell::new(0),
    };
    let (problem, _report) = LevenbergMarquardt::new()
        .with_patience(50)
        .minimize(problem);
    let shape = problem.shape(problem.point.as_slice());
    (shape, problem.evaluations.get())
}

/// The projected residual r(θ) = Φ(θ)·Φ(θ)⁺ỹ − ỹ of the shape θ, as a
/// function of θ itself or of φ with θ = lo + (hi − lo)·(1 + sin φ)/2.
struct ProjectedResidual<'a> {
    record: &'a ScaledRecord,
    point: LmVector<f64>,
    bounds: Option<&'a Bounds>,
    evaluations: std::cell::Cell<usize>,
}

impl ProjectedResidual<'_> {
    fn shape(&self, point: &[f64]) -> Vec<f64> {
        match self.bounds {
            None => point.to_vec(),
            Some(b) => point
                .iter()
                .enumerate()
                .map(|(i, phi)| b.lower[i] + (b.upper[i] - b.lower[i]) * 0.5 * (1.0 + phi.sin()))
                .collect(),
        }
    }

    fn residuals_at(&self, point: &[f64]) -> Option<Vec<f64>> {
        self.evaluations.set(self.evaluations.get() + 1);
        self.record.project(&self.shape(point)).map(|(_, r)| r)
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for ProjectedResidual<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &LmVector<f64>) {
        self.point.copy_from(x);
    }

    fn params(&self) -> LmVector<f64> {
        self.point.clone()
    }

    fn residuals(&self) -> Option<LmVector<f64>> {
        self.residuals_at(self.point.as_slice())
            .map(LmVector::from_vec)
    }

    /// Forward differences: each column one extra simulation. The exponent
    /// is stepped upwards so that the difference never crosses n = 1.
    fn jacobian(&self) -> Option<LmMatrix<f64>> {
        let point: Vec<f64> = self.point.iter().copied().collect();
        let base = self.residuals_at(&point)?;
        let mut jacobian = LmMatrix::zeros(base.len(), point.len());
        for j in 0..point.len() {
            let step = 1e-7 * point[j].abs().max(1e-2);
            let mut moved = point.clone();
            moved[j] += step;
            let r = self.residuals_at(&moved)?;
            for (i, (a, b)) in r.iter().zip(&base).enumerate() {
                jacobian[(i, j)] = (a - b) / step;
            }
        }
        Some(jacobian)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With and without the return-point memory: the loops shrink, so the
    /// memory's nested reversals are exercised, and its tilts scale with
    /// the input and the state as eq. (3) does.
    #[test]
    fn physical_parameters_reproduce_the_scaled_fit() {
        let input: Vec<f64> = (0..400)
            .map(|i| 40.0 * (1.0 - (i as f64 * 0.05).cos()) * (1.0 - i as f64 / 800.0))
            .collect();
        let scales = Scales {
            input: 80.0,
            output: 12.0,
        };
        let shape = [2.0, -0.5, 1.6, 0.3];
        let coefficients = [0.9, -0.4, 0.05];
        for return_point_memory in [false, true] {
            let record = ScaledRecord {
                input: input.iter().map(|u| u / scales.input).collect(),
                output: vec![0.0; input.len()],
                fitted: vec![true; 400],
                fit_offset: true,
                monotone: false,
                substeps: SUBSTEPS_PER_INPUT_SCALE,
                return_point_memory,
            };
            let states = record.states(&shape);
            let (params, offset) = physical(&shape, coefficients, scales);
            assert_eq!(params.q.abs(), 1.0);
            let predicted = predict(params, offset, &input, return_point_memory);
            for (i, y) in predicted.iter().enumerate() {
                let scaled = coefficients[0] * record.input[i]
                    + coefficients[1] * states[i]
                    + coefficients[2];
                assert!(
                    (y - scales.output * scaled).abs() < 1e-6,
                    "memory {return_point_memory}, sample {i}: {y} vs {}",
                    scales.output * scaled
                );
            }
        }
    }

    /// γ̃ = −100 with n = 2 makes dh̃/dũ = 1 + 100·h̃² on the way up: h̃
    /// blows up within a fraction of the input range. Such a candidate is
    /// scored unusable; it must not reach the QR solver as inf/NaN.
    #[test]
    fn a_diverging_shape_is_unusable_not_a_panic() {
        let record = ScaledRecord {
            input: (0..200).map(|i| i as f64 / 200.0).collect(),
            output: (0..200).map(|i| i as f64 / 200.0).collect(),
            fitted: vec![true; 200],
            fit_offset: true,
            monotone: false,
            substeps: SUBSTEPS_PER_INPUT_SCALE,
            return_point_memory: false,
        };
        assert_eq!(record.rms(&[0.0, -100.0, 2.0, 0.0]), f64::INFINITY);
        assert!(record.rms(&[1.0, 0.0, 2.0, 0.0]).is_finite());
    }

    /// A model whose output falls as the input rises has no inverse: with
    /// `monotone` it is unusable, without it the projection fits it.
    #[test]
    fn the_monotone_option_rejects_a_falling_model() {
        let ramp: Vec<f64> = (0..100).map(|i| i as f64 / 100.0).collect();
        let record = |monotone| ScaledRecord {
            input: ramp.clone(),
            output: ramp.iter().map(|u| -u).collect(),
            fitted: vec![true; 100],
            fit_offset: false,
            monotone,
            substeps: SUBSTEPS_PER_INPUT_SCALE,
            return_point_memory: false,
        };
        // β = γ = δ = 0, n = 1: h = ũ, so the best fit is y = −ũ, slope −1.
        let linear = [0.0, 0.0, 1.0, 0.0];
        assert!(record(false).rms(&linear) < 1e-12);
        assert_eq!(record(true).rms(&linear), f64::INFINITY);
    }

    #[test]
    fn refuses_unusable_records() {
        let options = BoucWenFitOptions::default();
        let u = vec![1.0; 100];
        assert!(matches!(
            identify_bouc_wen(&u, &u[..50], &options, |_, _| {}),
            Err(BoucWenFitError::Lengths { .. })
        ));
        assert!(matches!(
            identify_bouc_wen(&u[..10], &u[..10], &options, |_, _| {}),
            Err(BoucWenFitError::TooShort { .. })
        ));
        let zero = vec![0.0; 100];
        assert_eq!(
            identify_bouc_wen(&zero, &u, &options, |_, _| {}),
            Err(BoucWenFitError::NoInput)
        );
        assert_eq!(
            identify_bouc_wen(&u, &u, &options, |_, _| {}),
            Err(BoucWenFitError::NoResponse)
        );
        let mut nan = u.clone();
        nan[7] = f64::NAN;
        assert_eq!(
            identify_bouc_wen(&nan, &u, &options, |_, _| {}),
            Err(BoucWenFitError::NotFinite { index: 7 })
        );
    }
}

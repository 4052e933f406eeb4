//! Separable least-squares identification (seed 000 §3.1, objective eq. 7:
//! F = ‖u_model − u‖²).
//!
//! For the proposed model and its traditional rivals the parameters split in
//! two: given c and the dead-zone weights w_s (and u1max, which follows from
//! them and the data's range, eq. 5), the model is linear in (a, k, b), solved
//! exactly by [`crate::least_squares`]. Only (c, w_s) is searched, by
//! Nelder-Mead (argmin) from random initial values, best of N starts (30 by
//! default, as the paper), the starts run in parallel with rayon.
//!
//! Structure of the search space:
//! - Scale of w_s. Backlash is positively homogeneous (H_{λr}[λz] = λ·H_r[z]
//!   for λ > 0) and odd (H_r[−z] = −H_r[z] from the zero memory of eq. 1), and
//!   u1max = max |z| scales with |w_s|, so the backlash thresholds scale with
//!   it: multiplying w_s by any λ ≠ 0 multiplies every H_i by λ, which (k, b)
//!   absorb exactly. Only the direction of w_s matters; it is fixed by
//!   ‖w_s‖₂ = 1 and searched in hyperspherical angles φ_1…φ_{m−1}
//!   (w_s,1 = cos φ_1, w_s,2 = sin φ_1 cos φ_2, …), m − 1 free values for m
//!   dead zones. A first attempt fixed w_s,1 = 1 instead; on the simulated
//!   stage the best proposed model wants w_s,1 → 0 (z ≈ 0 below c), which that
//!   normalisation can only reach with the other weights running off to 10⁷;
//!   the sphere has no such edge.
//! - c > 0 is searched as ln c.
//! - Nelder-Mead minimises F/F_0 with F_0 = Σ(u − ū)² over the fitted samples
//!   (the same minimiser as F; a scale-free cost makes the termination
//!   tolerance mean the same on every data set).
//!
//! Random initial values: c is a scale, drawn log-uniformly over
//! [0.001, 0.11]·y_max (the last dead-zone threshold 9c starts between 0.9 %
//! and 99 % of the range), stratified: start k of N draws from the k-th of N
//! equal slices of that log range. F is strongly multimodal in c (each
//! placement of the dead-zone kinks across the data is a basin; on a test
//! model with mild dead zones a start 10 % below the true c already ended in
//! another one), so plain random draws leave gaps that a best-of-30 can miss;
//! one draw per slice covers the range at a spacing of a factor 1.17 for
//! N = 30. A first version drew c uniformly from [0.02, 0.11]·y_max and
//! missed the lowest-F region of the P-885 record, which lies at small c
//! (README). w_s starts as the direction of (1, U(−1, 1), …,
//! U(−1, 1)): a dominant d = 0 (linear) operator with random corrections.
//! Start k draws from its own Xoshiro256++ stream: the seed's generator
//! advanced by k jumps (2¹²⁸ steps each), so the starts are independent of
//! each other and of the thread that runs them, and the best start (lowest F,
//! ties to the lowest index) is bit-identical for any number of rayon
//! threads.
//!
//! `FitOptions::c_range` bounds c instead (the identification protocol
//! does, `protocol::DEAD_ZONE_SCALE_RANGE` says why); the starts are then
//! stratified over the bounds.
//!
//! Decimation: the search may use every m-th sample (m = `decimation`) with the
//! rates by backward difference at m·T, which is far cheaper at 10 kHz; the
//! final linear part (a, k, b) is then solved once on all samples for the
//! chosen (c, w_s), and F is reported on all samples.

use argmin::core::{CostFunction, Executor, State};
use argmin::solver::neldermead::NelderMead;
use nalgebra::DMatrix;
use piezo_models::InversePiParams;
use piezo_models::inverse_pi::{BACKLASH_OPERATORS, DEAD_ZONE_OPERATORS};
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;
use serde::Serialize;
use std::ops::Range;

use crate::least_squares::{
    LinearSolution, NormalEquations, solve_least_squares_regularized,
    solve_least_squares_with_intercept_regularized,
};
use crate::models::{
    ClassicalPi, ClassicalPiParams, InverseHysteresis, TraditionalInversePi,
    TraditionalInversePiParams, predict, u1max_for,
};
use crate::regressors::{
    PROPOSED, RateDependentLayout, TRADITIONAL_SIX, TRADITIONAL_TEN, for_each_rate_dependent_row,
    masked_classical_regressors, masked_rate_dependent_regressors, reversing_classical_operators,
    reversing_operators,
};

/// Nelder-Mead stops when the standard deviation of the simplex's normalised
/// costs falls below this (cost F/F_0, module comment).
const SIMPLEX_COST_TOLERANCE: f64 = 1e-14;
/// Initial simplex edge in ln c and in each hyperspherical angle of w_s.
const SIMPLEX_STEP: f64 = 0.2;
/// Simplex edge of the fresh simplex a screened start continues from: a
/// quarter of the first, about a point that is already in its basin.
const POLISH_SIMPLEX_STEP: f64 = 0.05;
/// A run to convergence is restarted from its end while a restart lowers F
/// by more than this fraction of it ([`SeparableProblem::run_to_rest`]):
/// digits of F beyond the data's own do not change the model.
const RESTART_LEAST_GAIN: f64 = 1e-6;
/// Range of the random initial c, in units of y_max, drawn log-uniformly and
/// stratified over the starts.
pub const INITIAL_C_RANGE: (f64, f64) = (1e-3, 0.11);
/// Range of the random initial w_s,j/w_s,1, j ≥ 2 (before normalising).
const INITIAL_WEIGHT_RANGE: (f64, f64) = (-1.0, 1.0);
/// Cost returned for parameters the model cannot use (c not finite, z not
/// finite): far above any real cost (≤ about 1), finite so that Nelder-Mead's
/// sort stays well defined.
const UNUSABLE_COST: f64 = 1e30;

/// Settings of a fit.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FitOptions {
    /// Random starts of the Nelder-Mead search; the best is kept (seed 000: 30).
    pub starts: usize,
    /// Seed of the random initial values.
    pub seed: u64,
    /// Nelder-Mead iterations per start at most.
    pub max_iterations: u64,
    /// The search uses every `decimation`-th sample (1: all).
    pub decimation: usize,
    /// The first samples run the operators but are not fitted nor scored (a
    /// start-up transient that no hysteresis model describes).
    pub warm_up_samples: usize,
    /// Further samples that run the operators but are not fitted (rest
    /// segments, the settling after a voltage step: `segments`).
    pub excluded: Vec<Range<usize>>,
    /// Rate-dependent backlash weights w_h = k·ẏ + b (seed 000 eq. 4); false
    /// fits constant weights (k = 0) for the proposed and traditional models.
    pub rate_dependent: bool,
    /// Successive halving of the starts (None: every start runs to
    /// convergence, seed 000's best of N).
    pub screening: Option<Screening>,
    /// Runs to convergence are restarted from their end while a restart
    /// lowers F (`SeparableProblem::run_to_rest` says why); false: each runs
    /// once, as seed 000's procedure does (the `stage` presets and the model
    /// comparison reproduce it).
    pub restarts: bool,
    /// The final linear solve is regularised, allowing F to grow by this
    /// fraction (`least_squares::solve_least_squares_regularized`; 0: plain
    /// least squares).
    pub rss_increase: f64,
    /// Backlash operators that do not reverse over the fitted samples get no
    /// weight (`regressors::reversing_operators` says why), in the search
    /// and in the final solve.
    pub reversing_operators_only: bool,
    /// Bounds (low, high) on c in units of y_max, the top of the working
    /// range (None: c is free, as in seed 000, and its initial values are
    /// drawn from [`INITIAL_C_RANGE`]). Within bounds the search runs on
    /// ln c = ln(y_max·low) + ln(high/low)·(1 + sin θ)/2, smooth and
    /// periodic in θ, and the initial values are drawn from the bounds.
    pub c_range: Option<(f64, f64)>,
}

/// Every start first runs `iterations` Nelder-Mead iterations; only the
/// `kept` best then continue, from a fresh simplex about their point, up to
/// `FitOptions::max_iterations` (restarted at their end as every run to
/// convergence is when `FitOptions::restarts` is set). The starts that lead after a short run are
/// nearly always those that end best (the basins of F in c are set early),
/// and most of a start's iterations are spent creeping along a valley it
/// will not leave: screening spends them only where they can matter.
///
/// The continued runs stop when the spread of the simplex's costs falls
/// below `relative_tolerance` times the cost it continues from (or the
/// absolute floor of an unscreened run, whichever is larger): digits of F
/// beyond the data's own do not change the model.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Screening {
    pub iterations: u64,
    pub kept: usize,
    pub relative_tolerance: f64,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            starts: 30,
            seed: 0,
            max_iterations: 2000,
            decimation: 1,
            warm_up_samples: 0,
            excluded: Vec::new(),
            rate_dependent: true,
            screening: None,
            restarts: false,
            rss_increase: 0.0,
            reversing_operators_only: false,
            c_range: None,
        }
    }
}

impl FitOptions {
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

/// Why a fit could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    #[error("displacement has {displacement} samples but voltage has {voltage}")]
    LengthMismatch { displacement: usize, voltage: usize },
    #[error("{found} samples to fit (after warm-up and decimation), at least {minimum} are needed")]
    TooFewSamples { found: usize, minimum: usize },
    #[error("{signal} sample {index} is {value}, not finite")]
    NotFinite {
        signal: &'static str,
        index: usize,
        value: f64,
    },
    #[error("sample period {0} s is not positive and finite")]
    InvalidSamplePeriod(f64),
    #[error(
        "displacement never exceeds 0 (largest {0} um); shift it so that the de-energized position is 0"
    )]
    NoPositiveDisplacement(f64),
    #[error("invalid option: {0}")]
    InvalidOption(&'static str),
    #[error("Nelder-Mead failed: {0}")]
    Optimizer(String),
}

/// Error figures of a model's voltage against the measured one.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FitQuality {
    /// F of eq. (7): Σ (u_model − u)² over the scored samples [V²].
    pub objective: f64,
    /// √(F / samples) [V].
    pub rms: f64,
    /// Largest |u_model − u| [V].
    pub max_abs: f64,
    /// Index of the sample where it occurs (in the record given).
    pub max_abs_sample: usize,
    /// Number of scored samples.
    pub samples: usize,
}

impl FitQuality {
    /// Scores a prediction against measured voltages from sample `scored_from`.
    pub fn of(prediction: &[f64], measured: &[f64], scored_from: usize) -> FitQuality {
        let scored: Vec<bool> = (0..prediction.len()).map(|n| n >= scored_from).collect();
        FitQuality::of_samples(prediction, measured, &scored)
    }

    /// Scores a prediction against measured values on the samples n where
    /// `scored[n]`.
    pub fn of_samples(prediction: &[f64], measured: &[f64], scored: &[bool]) -> FitQuality {
        let mut objective = 0.0;
        let mut max_abs: f64 = 0.0;
        let mut max_abs_sample = scored.iter().position(|s| *s).unwrap_or(0);
        let mut samples = 0;
        for (n, ((p, m), _)) in prediction
            .iter()
            .zip(measured)
            .zip(scored)
            .enumerate()
            .filter(|(_, (_, s))| **s)
        {
            let e = p - m;
            objective += e * e;
            if e.abs() > max_abs {
                max_abs = e.abs();
                max_abs_sample = n;
            }
            samples += 1;
        }
        FitQuality {
            objective,
            rms: (objective / samples.max(1) as f64).sqrt(),
            max_abs,
            max_abs_sample,
            samples,
        }
    }
}

/// The outcome of one random start.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StartResult {
    /// Index of the start (its random stream).
    pub start: usize,
    pub initial_c: f64,
    pub initial_ws: Vec<f64>,
    /// c and w_s at the end of the search.
    pub c: f64,
    pub ws: Vec<f64>,
    /// F on the samples the search used (decimated, after warm-up) [V²].
    pub objective: f64,
    /// Iterations and cost evaluations of all its runs (screening, polish
    /// and restarts; a restart that gains without iterating counts one).
    pub iterations: u64,
    pub cost_evaluations: u64,
    /// Whether it survived screening and ran to convergence (always, without
    /// screening).
    pub polished: bool,
}

/// A fitted model.
#[derive(Clone, Debug, PartialEq)]
pub struct Fit<P> {
    pub params: P,
    /// Quality on all samples given (after warm-up), at the full rate.
    pub quality: FitQuality,
    /// Every start, in start order (empty for the purely linear classical fit).
    pub starts: Vec<StartResult>,
    /// Index of the start that was kept.
    pub best_start: Option<usize>,
}

/// Called once per finished start (from the rayon worker that ran it).
pub type Progress<'a> = &'a (dyn Fn(&StartResult) + Sync);

/// Fits seed 000's proposed modified inverse P-I model (eq. 3-5): displacement
/// `y` [µm] (de-energized position at 0) and command `u` [V] sampled every
/// `sample_period` seconds.
pub fn fit_modified_inverse_pi(
    y: &[f64],
    u: &[f64],
    sample_period: f64,
    options: &FitOptions,
) -> Result<Fit<InversePiParams>, FitError> {
    fit_modified_inverse_pi_with_progress(y, u, sample_period, options, &|_| {})
}

/// [`fit_modified_inverse_pi`] reporting each finished start.
pub fn fit_modified_inverse_pi_with_progress(
    y: &[f64],
    u: &[f64],
    sample_period: f64,
    options: &FitOptions,
    progress: Progress,
) -> Result<Fit<InversePiParams>, FitError> {
    let layout = PROPOSED.with_rate_dependence(options.rate_dependent);
    let fit = fit_rate_dependent(layout, y, u, sample_period, options, progress)?;
    let (a, k, b) = split_coefficients(layout, &fit.coefficients);
    let params = InversePiParams {
        a: std::array::from_fn(|i| a[i]),
        k,
        b,
        ws: std::array::from_fn::<f64, DEAD_ZONE_OPERATORS, _>(|j| fit.ws[j]),
        c: fit.c,
        u1max: fit.u1max,
        rest_cycle: 0.0,
    };
    let quality = score_samples(
        &mut piezo_models::ModifiedInversePi::new(params),
        y,
        u,
        sample_period,
        &options.fitted_samples(y.len()),
    );
    Ok(Fit {
        params,
        quality,
        starts: fit.starts,
        best_start: Some(fit.best_start),
    })
}

/// Seed 000's proposed model for given (c, w_s): only its linear part
/// (a, k, b) fitted, on the samples and with the settings of `options`
/// (the search settings are not used).
pub fn modified_inverse_pi_for(
    y: &[f64],
    u: &[f64],
    sample_period: f64,
    options: &FitOptions,
    c: f64,
    ws: &[f64],
) -> Result<Fit<InversePiParams>, FitError> {
    let layout = PROPOSED.with_rate_dependence(options.rate_dependent);
    check_signals(y, u, sample_period, options, layout.parameter_count())?;
    if ws.len() != DEAD_ZONE_OPERATORS {
        return Err(FitError::InvalidOption("six dead-zone weights are needed"));
    }
    let fitted = options.fitted_samples(y.len());
    let (_, y_max) = range_of(y, &fitted);
    if y_max <= 0.0 {
        return Err(FitError::NoPositiveDisplacement(y_max));
    }
    let mut problem = SeparableProblem::new(layout, y, u, &fitted, sample_period, y_max);
    problem.reversing_only = options.reversing_operators_only;
    problem.c_range = options.c_range;
    let (u1max, solution) =
        problem
            .solve(c, ws, options.rss_increase)
            .ok_or(FitError::Optimizer(format!(
                "c = {c} and w_s = {ws:?} are unusable"
            )))?;
    let (a, k, b) = split_coefficients(layout, &solution.coefficients);
    let params = InversePiParams {
        a: std::array::from_fn(|i| a[i]),
        k,
        b,
        ws: std::array::from_fn(|j| ws[j]),
        c,
        u1max,
        // Memories from zero; a caller that knows the record's exercised
        // rest sets it (`stage`).
        rest_cycle: 0.0,
    };
    let quality = score_samples(
        &mut piezo_models::ModifiedInversePi::new(params),
        y,
        u,
        sample_period,
        &fitted,
    );
    Ok(Fit {
        params,
        quality,
        starts: Vec::new(),
        best_start: None,
    })
}

/// Fits a traditional inverse P-I model with `D` dead-zone operators (6 or 10,
/// see [`crate::models`]).
pub fn fit_traditional_inverse_pi<const D: usize>(
    y: &[f64],
    u: &[f64],
    sample_period: f64,
    options: &FitOptions,
    progress: Progress,
) -> Result<Fit<TraditionalInversePiParams<D>>, FitError> {
    let layout = match D {
        6 => TRADITIONAL_SIX,
        10 => TRADITIONAL_TEN,
        _ => {
            return Err(FitError::InvalidOption(
                "traditional models have 6 or 10 dead zones",
            ));
        }
    }
    .with_rate_dependence(options.rate_dependent);
    let fit = fit_rate_dependent(layout, y, u, sample_period, options, progress)?;
    let (_, k, b) = split_coefficients(layout, &fit.coefficients);
    let params = TraditionalInversePiParams::<D> {
        k,
        b,
        ws: std::array::from_fn(|j| fit.ws[j]),
        c: fit.c,
        u1max: fit.u1max,
    };
    let quality = score_samples(
        &mut TraditionalInversePi::new(params),
        y,
        u,
        sample_period,
        &options.fitted_samples(y.len()),
    );
    Ok(Fit {
        params,
        quality,
        starts: fit.starts,
        best_start: Some(fit.best_start),
    })
}

/// Fits the classical P-I model (see [`crate::models`]): thresholds evenly
/// spaced over the range of the fitted samples of `y`, weights and offset by
/// linear least squares. The search settings are not used.
pub fn fit_classical_pi(
    y: &[f64],
    u: &[f64],
    sample_period: f64,
    options: &FitOptions,
) -> Result<Fit<ClassicalPiParams>, FitError> {
    let linear_only = FitOptions {
        decimation: 1,
        ..options.clone()
    };
    check_signals(
        y,
        u,
        sample_period,
        &linear_only,
        ClassicalPiParams::PARAMETER_COUNT,
    )?;
    let fitted = options.fitted_samples(y.len());
    // The range of the fitted samples: a start-up transient in the warm-up is
    // not part of the working range.
    let (low, high) = range_of(y, &fitted);
    let thresholds = ClassicalPiParams::evenly_spaced_thresholds(high - low);
    let targets: Vec<f64> = selected(u, &fitted);
    let mut x = masked_classical_regressors(&thresholds, y, &fitted);
    if options.reversing_operators_only {
        let reversing = reversing_classical_operators(&thresholds, y, &fitted);
        for (column, _) in reversing.iter().enumerate().filter(|(_, r)| !**r) {
            x.column_mut(column).fill(0.0);
        }
    }
    let solution = solve_least_squares_with_intercept_regularized(
        x,
        &targets,
        crate::models::CLASSICAL_OPERATORS,
        options.rss_increase,
    );
    let params = ClassicalPiParams {
        weights: std::array::from_fn(|i| solution.coefficients[i]),
        thresholds,
        offset: solution.coefficients[crate::models::CLASSICAL_OPERATORS],
    };
    let quality = score_samples(&mut ClassicalPi::new(params), y, u, sample_period, &fitted);
    Ok(Fit {
        params,
        quality,
        starts: Vec::new(),
        best_start: None,
    })
}

/// The values at the samples where `flags` is set.
pub(crate) fn selected(values: &[f64], flags: &[bool]) -> Vec<f64> {
    values
        .iter()
        .zip(flags)
        .filter(|(_, f)| **f)
        .map(|(v, _)| *v)
        .collect()
}

/// The coefficient vector of a layout as (a, k, b); absent parts are zero.
fn split_coefficients(
    layout: RateDependentLayout,
    theta: &[f64],
) -> (
    [f64; 4],
    [f64; BACKLASH_OPERATORS],
    [f64; BACKLASH_OPERATORS],
) {
    let mut a = [0.0; 4];
    let mut k = [0.0; BACKLASH_OPERATORS];
    let (cubic, rest) = theta.split_at(layout.cubic_columns());
    a[..cubic.len()].copy_from_slice(cubic);
    let (rates, constants) = rest.split_at(layout.rate_columns());
    k[..rates.len()].copy_from_slice(rates);
    let b = std::array::from_fn(|i| constants[i]);
    (a, k, b)
}

/// A model's quality on a record, run from the de-energized start.
pub fn score<M: InverseHysteresis>(
    model: &mut M,
    y: &[f64],
    u: &[f64],
    sample_period: f64,
    scored_from: usize,
) -> FitQuality {
    FitQuality::of(&predict(model, y, sample_period), u, scored_from)
}

/// A model's quality on the samples n where `scored[n]`, run from the
/// de-energized start through every sample.
pub fn score_samples<M: InverseHysteresis>(
    model: &mut M,
    y: &[f64],
    u: &[f64],
    sample_period: f64,
    scored: &[bool],
) -> FitQuality {
    FitQuality::of_samples(&predict(model, y, sample_period), u, scored)
}

/// The nonlinear and linear parameters of a fitted eq. (3)-(5) model.
struct RateDependentFit {
    c: f64,
    ws: Vec<f64>,
    u1max: f64,
    coefficients: Vec<f64>,
    starts: Vec<StartResult>,
    best_start: usize,
}

fn fit_rate_dependent(
    layout: RateDependentLayout,
    y: &[f64],
    u: &[f64],
    sample_period: f64,
    options: &FitOptions,
    progress: Progress,
) -> Result<RateDependentFit, FitError> {
    check_signals(y, u, sample_period, options, layout.parameter_count())?;
    if options.starts == 0 {
        return Err(FitError::InvalidOption("starts must be at least 1"));
    }
    if let Some(screening) = options.screening
        && (screening.kept == 0 || screening.iterations == 0)
    {
        return Err(FitError::InvalidOption(
            "screening must keep at least one start and run at least one iteration",
        ));
    }
    let fitted = options.fitted_samples(y.len());
    // The working range of eq. (5) is that of the fitted samples.
    let (_, y_max) = range_of(y, &fitted);
    if y_max <= 0.0 {
        return Err(FitError::NoPositiveDisplacement(y_max));
    }

    let m = options.decimation;
    let y_search: Vec<f64> = y.iter().step_by(m).copied().collect();
    let u_search: Vec<f64> = u.iter().step_by(m).copied().collect();
    let fitted_search: Vec<bool> = fitted.iter().step_by(m).copied().collect();
    let mut search = SeparableProblem::new(
        layout,
        &y_search,
        &u_search,
        &fitted_search,
        sample_period * m as f64,
        y_max,
    );
    search.reversing_only = options.reversing_operators_only;
    search.c_range = options.c_range;
    search.restarts = options.restarts;

    let starts = run_starts(&search, options, progress)?;
    // Lowest F, ties to the lowest start index (`min_by` keeps the first).
    let best = starts
        .iter()
        .min_by(|a, b| a.objective.total_cmp(&b.objective))
        .expect("at least one start")
        .start;

    // The linear part on all samples for the chosen (c, w_s).
    let c = starts[best].c;
    let ws = starts[best].ws.clone();
    let mut full = SeparableProblem::new(layout, y, u, &fitted, sample_period, y_max);
    full.reversing_only = options.reversing_operators_only;
    full.c_range = options.c_range;
    let (u1max, solution) = full
        .solve(c, &ws, options.rss_increase)
        .ok_or(FitError::Optimizer(format!(
            "the best start (c = {c}) is unusable"
        )))?;
    Ok(RateDependentFit {
        c,
        ws,
        u1max,
        coefficients: solution.coefficients,
        starts,
        best_start: best,
    })
}

/// Every start of the search, in start order (module comment and
/// [`Screening`]).
fn run_starts(
    search: &SeparableProblem,
    options: &FitOptions,
    progress: Progress,
) -> Result<Vec<StartResult>, FitError> {
    let Some(screening) = options.screening else {
        return (0..options.starts)
            .into_par_iter()
            .map(|start| {
                let initial = search.initial_point(start, options.starts, options.seed);
                let result = search.run_to_rest(
                    start,
                    &initial,
                    SIMPLEX_STEP,
                    options.max_iterations,
                    SIMPLEX_COST_TOLERANCE,
                );
                if let Ok(result) = &result {
                    progress(result);
                }
                result
            })
            .collect();
    };
    let screening_iterations = screening.iterations.min(options.max_iterations);
    let mut starts: Vec<StartResult> = (0..options.starts)
        .into_par_iter()
        .map(|start| {
            let initial = search.initial_point(start, options.starts, options.seed);
            let mut result = search.run(
                start,
                &initial,
                SIMPLEX_STEP,
                screening_iterations,
                SIMPLEX_COST_TOLERANCE,
            )?;
            result.polished = false;
            Ok(result)
        })
        .collect::<Result<_, FitError>>()?;
    let mut ranking: Vec<usize> = (0..starts.len()).collect();
    ranking.sort_by(|a, b| {
        starts[*a]
            .objective
            .total_cmp(&starts[*b].objective)
            .then(a.cmp(b))
    });
    for start in ranking.iter().skip(screening.kept) {
        progress(&starts[*start]);
    }
    let remaining = options.max_iterations - screening_iterations;
    let polished: Vec<StartResult> = ranking
        .iter()
        .take(screening.kept)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|&start| {
            let screened = &starts[start];
            let point = search.encode(screened.c, &screened.ws);
            let tolerance = (screening.relative_tolerance * screened.objective / search.reference)
                .max(SIMPLEX_COST_TOLERANCE);
            let mut result = if remaining > 0 {
                search.run_to_rest(start, &point, POLISH_SIMPLEX_STEP, remaining, tolerance)?
            } else {
                screened.clone()
            };
            // The polished run starts where screening stopped: never worse.
            if result.objective > screened.objective {
                result.c = screened.c;
                result.ws.clone_from(&screened.ws);
                result.objective = screened.objective;
            }
            result.initial_c = screened.initial_c;
            result.initial_ws.clone_from(&screened.initial_ws);
            result.iterations += screened.iterations;
            result.cost_evaluations += screened.cost_evaluations;
            result.polished = true;
            progress(&result);
            Ok(result)
        })
        .collect::<Result<_, FitError>>()?;
    for result in polished {
        let start = result.start;
        starts[start] = result;
    }
    Ok(starts)
}

fn check_signals(
    y: &[f64],
    u: &[f64],
    sample_period: f64,
    options: &FitOptions,
    parameters: usize,
) -> Result<(), FitError> {
    if y.len() != u.len() {
        return Err(FitError::LengthMismatch {
            displacement: y.len(),
            voltage: u.len(),
        });
    }
    if !(sample_period.is_finite() && sample_period > 0.0) {
        return Err(FitError::InvalidSamplePeriod(sample_period));
    }
    if options.decimation == 0 {
        return Err(FitError::InvalidOption("decimation must be at least 1"));
    }
    for (signal, values) in [("displacement", y), ("voltage", u)] {
        if let Some((index, &value)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(FitError::NotFinite {
                signal,
                index,
                value,
            });
        }
    }
    // At least twice as many fitted samples as parameters, so that F measures
    // more than the freedom of the model.
    let minimum = 2 * parameters;
    let fitted = options
        .fitted_samples(y.len())
        .iter()
        .step_by(options.decimation)
        .filter(|f| **f)
        .count();
    if fitted < minimum {
        return Err(FitError::TooFewSamples {
            found: fitted,
            minimum,
        });
    }
    Ok(())
}

fn range(values: &[f64]) -> (f64, f64) {
    values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(*v), hi.max(*v))
        })
}

/// (min, max) of the values at the samples where `flags` is set.
pub(crate) fn range_of(values: &[f64], flags: &[bool]) -> (f64, f64) {
    range(&selected(values, flags))
}

/// The search problem over (ln c, φ_1…φ_{m−1}) on one record.
#[derive(Clone, Copy)]
struct SeparableProblem<'a> {
    layout: RateDependentLayout,
    /// Displacement, every sample (the operators run through all).
    y: &'a [f64],
    /// Voltage, every sample.
    u: &'a [f64],
    /// Which samples are fitted.
    fitted: &'a [bool],
    sample_period: f64,
    /// Upper end of the working range for u1max (eq. 5).
    y_max: f64,
    /// F_0 = Σ (u − ū)² over the fitted samples (the cost's unit).
    reference: f64,
    /// Number of fitted samples.
    rows: usize,
    /// Only operators that reverse get a weight.
    reversing_only: bool,
    /// Bounds on c in units of y_max (`FitOptions::c_range`).
    c_range: Option<(f64, f64)>,
    /// Runs to convergence are restarted (`FitOptions::restarts`).
    restarts: bool,
}

impl<'a> SeparableProblem<'a> {
    fn new(
        layout: RateDependentLayout,
        y: &'a [f64],
        u: &'a [f64],
        fitted: &'a [bool],
        sample_period: f64,
        y_max: f64,
    ) -> Self {
        let targets = selected(u, fitted);
        let mean = targets.iter().sum::<f64>() / targets.len().max(1) as f64;
        let spread: f64 = targets.iter().map(|u| (u - mean) * (u - mean)).sum();
        SeparableProblem {
            layout,
            y,
            u,
            fitted,
            sample_period,
            y_max,
            // A constant voltage would make every cost 0/0; any positive unit
            // keeps the minimiser.
            reference: if spread > 0.0 { spread } else { 1.0 },
            rows: targets.len(),
            reversing_only: false,
            c_range: None,
            restarts: false,
        }
    }

    /// (c, w_s) from the search vector [ln c, φ_1 … φ_{m−1}].
    fn decode(&self, theta: &[f64]) -> (f64, Vec<f64>) {
        let c = match self.c_range {
            Some((low, high)) => {
                let fraction = (1.0 + theta[0].sin()) / 2.0;
                self.y_max * low * ((high / low).ln() * fraction).exp()
            }
            None => theta[0].exp(),
        };
        (c, from_hyperspherical(&theta[1..]))
    }

    /// The search coordinate of c (inverse of [`Self::decode`]'s first
    /// value; a c outside the bounds goes to the nearest bound).
    fn encode_c(&self, c: f64) -> f64 {
        match self.c_range {
            Some((low, high)) => {
                let fraction = (c / (self.y_max * low)).ln() / (high / low).ln();
                (2.0 * fraction - 1.0).clamp(-1.0, 1.0).asin()
            }
            None => c.ln(),
        }
    }

    /// The search point of (c, w_s) (inverse of [`Self::decode`]).
    fn encode(&self, c: f64, ws: &[f64]) -> Vec<f64> {
        let mut point = vec![self.encode_c(c)];
        point.extend(to_hyperspherical(ws));
        point
    }

    /// The dead-zone thresholds and u1max (eq. 5) of (c, w_s); None when they
    /// are unusable.
    fn thresholds(&self, c: f64, ws: &[f64]) -> Option<f64> {
        if !(c.is_finite() && c > 0.0) || ws.iter().any(|w| !w.is_finite()) {
            return None;
        }
        let thresholds: Vec<f64> = self
            .layout
            .dead_zone_pattern
            .iter()
            .map(|p| p * c)
            .collect();
        let u1max = u1max_for(ws, &thresholds, self.y_max);
        u1max.is_finite().then_some(u1max)
    }

    /// u1max (eq. 5) and the linear least-squares solution for (c, w_s) by
    /// QR (the final, accurate solve), regularised by `rss_increase`; None
    /// when they are unusable.
    fn solve(&self, c: f64, ws: &[f64], rss_increase: f64) -> Option<(f64, LinearSolution)> {
        let u1max = self.thresholds(c, ws)?;
        let mut x: DMatrix<f64> = masked_rate_dependent_regressors(
            self.layout,
            c,
            ws,
            u1max,
            self.y,
            self.sample_period,
            self.fitted,
        );
        for column in self.inactive_columns(c, ws, u1max) {
            x.column_mut(column).fill(0.0);
        }
        let targets = selected(self.u, self.fitted);
        let solution = match self.layout.intercept_column() {
            Some(intercept) => {
                solve_least_squares_with_intercept_regularized(x, &targets, intercept, rss_increase)
            }
            None => solve_least_squares_regularized(x, &targets, rss_increase),
        };
        solution
            .residual_sum_of_squares
            .is_finite()
            .then_some((u1max, solution))
    }

    /// F for (c, w_s) by the normal equations and a direct sum of the
    /// residuals (`least_squares::NormalEquations`): the search's cost,
    /// several times cheaper than QR.
    fn objective(&self, c: f64, ws: &[f64]) -> Option<f64> {
        let u1max = self.thresholds(c, ws)?;
        let mut normal = NormalEquations::new(self.layout.linear_columns(), self.rows);
        for_each_rate_dependent_row(
            self.layout,
            c,
            ws,
            u1max,
            self.y,
            self.sample_period,
            self.fitted,
            |n, x| normal.add_row(x, self.u[n]),
        );
        let mut active = vec![true; self.layout.linear_columns()];
        for column in self.inactive_columns(c, ws, u1max) {
            active[column] = false;
        }
        let theta = normal.solve_with(&active)?;
        let residual_sum_of_squares = normal.residual_sum_of_squares(&theta);
        residual_sum_of_squares
            .is_finite()
            .then_some(residual_sum_of_squares)
    }

    /// The columns of the operators that get no weight (none unless
    /// `reversing_only`).
    fn inactive_columns(&self, c: f64, ws: &[f64], u1max: f64) -> Vec<usize> {
        if !self.reversing_only {
            return Vec::new();
        }
        let reversing = reversing_operators(self.layout, c, ws, u1max, self.y, self.fitted);
        (0..BACKLASH_OPERATORS)
            .filter(|&i| !reversing[i])
            .flat_map(|i| self.layout.operator_columns(i))
            .collect()
    }

    fn normalised_cost(&self, theta: &[f64]) -> f64 {
        let (c, ws) = self.decode(theta);
        match self.objective(c, &ws) {
            Some(objective) => objective / self.reference,
            None => UNUSABLE_COST,
        }
    }

    /// The initial point of start `start` of `starts` (module comment).
    fn initial_point(&self, start: usize, starts: usize, seed: u64) -> Vec<f64> {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        for _ in 0..start {
            rng.jump();
        }
        let range = self.c_range.unwrap_or(INITIAL_C_RANGE);
        let (low, high) = (range.0.ln(), range.1.ln());
        let slice = (start as f64 + rng.random_range(0.0..1.0)) / starts as f64;
        let c = self.y_max * (low + slice * (high - low)).exp();
        let mut direction = vec![1.0];
        for _ in 1..self.layout.dead_zone_count() {
            direction.push(rng.random_range(INITIAL_WEIGHT_RANGE.0..INITIAL_WEIGHT_RANGE.1));
        }
        let mut theta = vec![self.encode_c(c)];
        theta.extend(to_hyperspherical(&direction));
        theta
    }

    /// Nelder-Mead from `initial` with simplex edge `step`, at most
    /// `max_iterations` iterations, until the spread of the simplex's
    /// normalised costs is below `tolerance`.
    fn run(
        &self,
        start: usize,
        initial: &[f64],
        step: f64,
        max_iterations: u64,
        tolerance: f64,
    ) -> Result<StartResult, FitError> {
        let mut simplex = vec![initial.to_vec()];
        for i in 0..initial.len() {
            let mut vertex = initial.to_vec();
            vertex[i] += step;
            simplex.push(vertex);
        }
        let solver = NelderMead::new(simplex)
            .with_sd_tolerance(tolerance)
            .map_err(|e| FitError::Optimizer(e.to_string()))?;
        let result = Executor::new(*self, solver)
            .configure(|state| state.max_iters(max_iterations))
            .run()
            .map_err(|e| FitError::Optimizer(e.to_string()))?;
        let state = result.state();
        let best = state
            .get_best_param()
            .cloned()
            .unwrap_or_else(|| initial.to_vec());
        let (c, ws) = self.decode(&best);
        let (initial_c, initial_ws) = self.decode(initial);
        Ok(StartResult {
            start,
            initial_c,
            initial_ws,
            c,
            ws,
            objective: state.get_best_cost() * self.reference,
            iterations: state.get_iter(),
            cost_evaluations: result
                .problem()
                .counts
                .get("cost_count")
                .copied()
                .unwrap_or(0),
            polished: true,
        })
    }

    /// [`Self::run`], then, when `restarts` is set (else that run alone),
    /// restarted from its best point with a fresh simplex of the first edge
    /// ([`SIMPLEX_STEP`]) for as long as a restart lowers F by more than
    /// [`RESTART_LEAST_GAIN`] of it, within
    /// `max_iterations` in all. Nelder-Mead's simplex flattens across a
    /// curved valley and stops short of its bottom (McKinnon, SIAM J. Optim.
    /// 9 (1998) 148-158); Numerical Recipes (§10.5) restarts at the claimed
    /// minimum for that reason. On the 200 Hz lab staircase, seeds 0 and 2
    /// had converged at F 0.0326 and 0.0327; restarted, they went on to
    /// 0.0321 and 0.0245 (docs/identification.md).
    fn run_to_rest(
        &self,
        start: usize,
        initial: &[f64],
        step: f64,
        max_iterations: u64,
        tolerance: f64,
    ) -> Result<StartResult, FitError> {
        let mut result = self.run(start, initial, step, max_iterations, tolerance)?;
        while self.restarts && result.iterations < max_iterations {
            let point = self.encode(result.c, &result.ws);
            let again = self.run(
                start,
                &point,
                SIMPLEX_STEP,
                max_iterations - result.iterations,
                tolerance,
            )?;
            // At least one, so that restarts that gain without iterating
            // (a vertex of the fresh simplex below its centre) still end.
            result.iterations += again.iterations.max(1);
            result.cost_evaluations += again.cost_evaluations;
            let gain = result.objective - again.objective;
            if gain > 0.0 {
                result.c = again.c;
                result.ws = again.ws;
                result.objective = again.objective;
            }
            if gain <= RESTART_LEAST_GAIN * result.objective {
                break;
            }
        }
        Ok(result)
    }
}

/// The unit vector with hyperspherical angles φ_1…φ_{m−1}:
/// x_1 = cos φ_1, x_j = sin φ_1 ⋯ sin φ_{j−1} cos φ_j, x_m = sin φ_1 ⋯ sin φ_{m−1}.
pub fn from_hyperspherical(angles: &[f64]) -> Vec<f64> {
    let mut x = Vec::with_capacity(angles.len() + 1);
    let mut sines = 1.0;
    for phi in angles {
        x.push(sines * phi.cos());
        sines *= phi.sin();
    }
    x.push(sines);
    x
}

/// Angles of the direction of a nonzero vector (inverse of
/// [`from_hyperspherical`] for its normalised input).
pub fn to_hyperspherical(x: &[f64]) -> Vec<f64> {
    (0..x.len() - 1)
        .map(|j| {
            let rest: f64 = x[j + 1..].iter().map(|v| v * v).sum::<f64>().sqrt();
            if j + 2 == x.len() {
                // The last angle carries the sign of the last component.
                x[j + 1].atan2(x[j])
            } else {
                rest.atan2(x[j])
            }
        })
        .collect()
}

impl CostFunction for SeparableProblem<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, theta: &Self::Param) -> Result<f64, argmin::core::Error> {
        Ok(self.normalised_cost(theta))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A restarted run keeps within the one iteration budget, never ends
    /// above the run it restarts, and goes on where Nelder-Mead alone stops
    /// short: on a hysteretic record (a backlash of the displacement, a
    /// cubic) some of seed 0's starts converge above a point their restart
    /// then finds.
    #[test]
    fn a_run_restarted_at_its_end_goes_on_where_one_run_stops_short() {
        let sample_period = 2e-3;
        let y: Vec<f64> = (0..1500)
            .map(|n| {
                let t = n as f64 * sample_period;
                5.0 + 4.5 * (1.0 - t / 6.0) * (2.0 * std::f64::consts::PI * t).sin()
            })
            .collect();
        let mut play = y[0];
        let u: Vec<f64> = y
            .iter()
            .map(|&y| {
                play = play.clamp(y - 0.4, y + 0.4);
                0.9 * play + 0.2 * y + 0.002 * y * y * y
            })
            .collect();
        let fitted = vec![true; y.len()];
        let mut problem = SeparableProblem::new(PROPOSED, &y, &u, &fitted, sample_period, 9.5);
        problem.restarts = true;
        let budget = 2000;
        let mut gains = 0;
        for start in 0..30 {
            let initial = problem.initial_point(start, 30, 0);
            let once = problem
                .run(
                    start,
                    &initial,
                    SIMPLEX_STEP,
                    budget,
                    SIMPLEX_COST_TOLERANCE,
                )
                .unwrap();
            let restarted = problem
                .run_to_rest(
                    start,
                    &initial,
                    SIMPLEX_STEP,
                    budget,
                    SIMPLEX_COST_TOLERANCE,
                )
                .unwrap();
            assert!(
                restarted.iterations <= budget,
                "start {start}: {restarted:?}"
            );
            assert!(
                restarted.objective <= once.objective,
                "start {start}: {} after restarts, {} without",
                restarted.objective,
                once.objective
            );
            if once.iterations < budget && restarted.objective < 0.99 * once.objective {
                gains += 1;
            }
        }
        assert!(gains > 0, "no converged start went on when restarted");
    }

    #[test]
    fn hyperspherical_angles_round_trip() {
        for x in [
            vec![1.0, 0.5, -0.3, 0.2, -0.9, 0.1],
            vec![-0.2, 0.0, 0.0, 0.7, -0.1, -0.4, 0.3, 0.0, 0.2, -0.5],
            vec![0.0, 1.0],
            vec![0.3, -0.4],
        ] {
            let norm: f64 = x.iter().map(|v| v * v).sum::<f64>().sqrt();
            let back = from_hyperspherical(&to_hyperspherical(&x));
            for (b, v) in back.iter().zip(&x) {
                assert!((b - v / norm).abs() < 1e-15, "{back:?} vs {x:?}");
            }
        }
    }
}

//! The default identification of a measured record: what `piezo-identify
//! inverse-pi FILE --split 0.5` and `bouc-wen FILE --split 0.5` do when the
//! user gives nothing else, and why (README, "Protocol").
//!
//! - **Fit part and scored part.** A record split in two (`--split`,
//!   `--validate-from`) is fitted on its first part and scored on the rest
//!   with the model run from the start of the record: its state at the first
//!   scored sample is the one the measured history left. A separate
//!   validation file is run from rest at its own first sample and scored
//!   after its own warm-up. When both begin at rest at the same input, the
//!   validation file's displacement is read from the same zero as the fit
//!   record's ([`Plan::zero_alignment`]): a sensor's zero moves between
//!   sessions (zeroed again, remounted), and the model, which starts both
//!   from the same rest, cannot tell a new zero from a new position.
//! - **What is fitted** ([`Plan`], [`crate::segments`]): not the rest
//!   segments, not the settling after each voltage step, not the first
//!   settling time of the record; the models run through all of them. The
//!   same samples are left out of the score. Over the settling after a
//!   step onto a held input the inverse models are driven with the settled
//!   displacement ([`crate::validation::held_over_settling`] says why). An
//!   input that stands at fewer than [`MIN_INPUT_LEVELS`] levels over the
//!   fitted samples is no loop to fit.
//! - **Choices made from the fit part only** (inverse P-I): the smoothing of
//!   the displacement (none, or a centred moving average over 1/160, 1/80 or
//!   1/40 of the fastest cycle: at most 0.1 % amplitude loss at that cycle)
//!   and rate-dependent or constant backlash weights are chosen by forward
//!   validation inside the fit part: the (c, w_s) search runs on its first
//!   70 % of fitted samples; with each of its [`INNER_CANDIDATES`] best
//!   distinct ends every candidate's linear part is solved there, and the
//!   candidates are compared on the last 30 %, predicted with the operator
//!   state carried over, as the scored part will be. Rate-dependent weights
//!   (ten more parameters) are taken only when their best error is lower
//!   than the constant weights' best by more than 5 %. The classical P-I baseline gets its own smoothing by
//!   the same comparison.
//! - **Cost**: the (c, w_s) searches run on every m-th sample, m such that
//!   at most about 3000 samples are searched and at least 100 per fastest
//!   cycle remain; 30 starts are screened for 60 Nelder-Mead iterations and
//!   the best 5 run on to convergence, restarted from their end until a
//!   restart no longer lowers F ([`crate::fit::Screening`]). The
//!   linear part and every error use all samples.
//! - **What the fit may use**: c, the scale of the dead-zone thresholds,
//!   stays within [`DEAD_ZONE_SCALE_RANGE`] of the fitted working range,
//!   and only backlash operators that travel at least
//!   [`crate::regressors::MIN_REVERSING_TRAVEL`] of z's span back and forth
//!   get a weight: both say how far the model may be trusted beyond the
//!   loops it was fitted on.
//! - **Baselines**, fitted on the same samples: the classical P-I model and
//!   a straight line; for Bouc-Wen also the best straight line of the scored
//!   part itself (fitted on what it is scored on: no line can do better).
//!
//! Errors are given as RMS and largest |error| and as % of the fit part's
//! span: the input span for the inverse models (voltage errors), the output
//! span (stroke) for the forward ones.

use std::ops::Range;
use std::time::Instant;

use nalgebra::DMatrix;
use piezo_models::InversePiParams;
use serde::Serialize;

use crate::bouc_wen_fit::{
    BoucWenFitError, BoucWenFitOptions, BoucWenIdentification, default_shape_bounds,
    identify_bouc_wen, predict as predict_bouc_wen,
};
use crate::data::Record;
use crate::fit::{
    FitError, FitOptions, FitQuality, Screening, StartResult, fit_classical_pi,
    fit_modified_inverse_pi_with_progress, range_of, selected,
};
use crate::gapso::{Bounds, GaPsoOptions};
use crate::least_squares::{solve_least_squares, solve_least_squares_with_intercept_regularized};
use crate::models::{
    CLASSICAL_OPERATORS, ClassicalPi, ClassicalPiParams, SIX_DEAD_ZONE_PATTERN, predict, u1max_for,
};
use crate::regressors::{
    PROPOSED, masked_classical_regressors, masked_rate_dependent_regressors,
    reversing_classical_operators, reversing_operators,
};
use crate::segments::{
    REVERSAL_SPAN_FRACTION, SegmentOptions, SegmentThresholds, Segments, detect_segments,
    fastest_cycle, first_loading_end, merge, reversals, thresholds,
};
use crate::validation::{Steps, inverse_model_input, smoothed_between_steps};

/// Share of the fit part's fitted samples the inner search runs on; the rest
/// scores the candidates.
pub const INNER_TRAIN_FRACTION: f64 = 0.7;
/// Ends of the inner search compared by the forward validation: one end
/// alone made the choice of weights depend on the seed where two basins of
/// the search fit alike and extrapolate differently.
pub const INNER_CANDIDATES: usize = 5;
/// Rate-dependent weights must lower the inner validation error by more than
/// this fraction.
pub const RATE_DEPENDENCE_MARGIN: f64 = 0.05;
/// ... and by more than this fraction of the input span: below it the
/// difference is rounding (a record the models fit exactly, as a staircase
/// of three levels, compared 1.2·10⁻¹⁴ with 1.5·10⁻¹⁴ V).
pub const RATE_DEPENDENCE_FLOOR: f64 = 1e-6;
/// Smoothing windows tried, as fractions of the fastest cycle.
pub const SMOOTHING_CYCLE_FRACTIONS: [f64; 3] = [1.0 / 160.0, 1.0 / 80.0, 1.0 / 40.0];
/// The search keeps at least this many samples per fastest cycle ...
pub const SEARCH_SAMPLES_PER_CYCLE: f64 = 100.0;
/// ... and otherwise decimates to about this many samples.
pub const SEARCH_SAMPLES: usize = 3000;

/// Bounds on c, the scale of the dead-zone thresholds d = c·[0, 1, 3, 5, 7,
/// 9] (seed 000 eq. 5), in units of y_max, the top of the fitted working
/// range (its span, with the default offset): every threshold inside the
/// working range and at least 5 % of it from either end (c ≥ 0.05,
/// 9c ≤ 0.95). z(y) is linear between thresholds, and
/// beyond the working range the model continues with the slope of the
/// outermost piece; a piece narrower than the growth it must carry (5 %, as
/// for [`crate::regressors::MIN_REVERSING_TRAVEL`]) has its slope set by
/// the few samples at the loops' turning points, which least squares uses to
/// shape the turn, not the branch. Left free, the search puts c at 0.4 % of
/// the span on the P-885 test record: z rises 5× faster below c than above
/// and, with the weights of the moving operators summing negative, the
/// model's descending branch turns back below y = c; the scored half's
/// loops reach 0.75 µm lower and the model's voltage there is 0.1 V (3 % of
/// the input span) too high. An upper threshold beyond the range would be
/// worse: its weight is not seen by the fit at all.
pub const DEAD_ZONE_SCALE_RANGE: (f64, f64) = (0.05, 0.95 / 9.0);

/// The linear parts are regularised, allowing their residual sum of squares
/// to grow by this fraction (RMS by 0.05 %):
/// `least_squares::solve_least_squares_regularized` says why.
pub const LINEAR_RSS_INCREASE: f64 = 1e-3;

/// RK4 substeps per scaled input unit in GA-PSO's evaluations
/// (`BoucWenFitOptions::search_substeps` says why 100 is enough).
pub const BOUC_WEN_SEARCH_SUBSTEPS: f64 = 100.0;

/// A validation file's sensor zero, aligned with the fit record's
/// ([`Plan::zero_alignment`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ZeroAlignment {
    /// The input both records rest at when they begin.
    pub rest_input: f64,
    /// The samples of each rest that were averaged (after settling).
    pub fit_rest: Range<usize>,
    pub validation_rest: Range<usize>,
    /// The validation file's rest reading minus the fit record's: subtracted
    /// from every output sample of the validation file.
    pub shift: f64,
}

/// Fewer distinct input levels than this over the fitted samples are no
/// loop to fit ([`ProtocolError::TooFewLevels`]): on a two-level staircase
/// (a square wave) the proposed model scored 8·10⁻¹² V, "0.000 %", and
/// rate-dependent weights were chosen on rounding noise.
pub const MIN_INPUT_LEVELS: usize = 3;

/// The levels among `values`: sorted and grouped, a group spanning at most
/// `tolerance` (the rest tolerance). An input that moves through its range
/// (a sine) makes as many groups as its span holds tolerances; a staircase
/// one per stair.
fn value_levels(mut values: Vec<f64>, tolerance: f64) -> usize {
    values.sort_by(f64::total_cmp);
    let mut levels = 0;
    let mut group_start = f64::NEG_INFINITY;
    for v in values {
        if v - group_start > tolerance {
            levels += 1;
            group_start = v;
        }
    }
    levels
}

/// The levels of a staircase over the `fitted` samples: when at least
/// [`STAIRCASE_HELD_SHARE`] of them lie in holds (runs of at least
/// `min_run` consecutive fitted samples within `tolerance` of the run's
/// first), the levels of those holds grouped by [`value_levels`]; None
/// otherwise. A sine sampled a whole number of times per cycle
/// takes few values (11 for 10 Hz at 200 Hz) but holds none of them.
pub fn held_levels(u: &[f64], fitted: &[bool], tolerance: f64, min_run: usize) -> Option<usize> {
    let mut held = Vec::new();
    let mut run: Vec<f64> = Vec::new();
    let close = |run: &mut Vec<f64>, held: &mut Vec<f64>| {
        if run.len() >= min_run {
            held.append(run);
        }
        run.clear();
    };
    for (&value, &fit) in u.iter().zip(fitted) {
        if !fit
            || run
                .first()
                .is_some_and(|first| (value - first).abs() > tolerance)
        {
            close(&mut run, &mut held);
        }
        if fit {
            run.push(value);
        }
    }
    close(&mut run, &mut held);
    let total = fitted.iter().filter(|f| **f).count();
    if total == 0 || (held.len() as f64) < STAIRCASE_HELD_SHARE * total as f64 {
        return None;
    }
    Some(value_levels(held, tolerance))
}

/// Share of the fitted samples in holds that makes an input a staircase.
pub const STAIRCASE_HELD_SHARE: f64 = 0.9;

/// Why a validation file's zero was not aligned ([`Plan::zero_alignment`]).
#[derive(Clone, Debug, PartialEq, Serialize, thiserror::Error)]
pub enum NoZeroAlignment {
    #[error("the {record} does not begin at rest")]
    NotAtRest { record: &'static str },
    #[error("the {record}'s rest at its start ({seconds} s) ends within the settling time")]
    RestWithinSettling { record: &'static str, seconds: f64 },
    #[error("the two rest at different inputs ({fit} and {validation})")]
    DifferentInputs { fit: f64, validation: f64 },
}

impl ZeroAlignment {
    /// `output` read from the fit record's zero.
    pub fn aligned(&self, output: &[f64]) -> Vec<f64> {
        output.iter().map(|y| y - self.shift).collect()
    }
}

/// Where the record is cut and what is left out.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PlanOptions {
    pub segments: SegmentOptions,
    /// Seconds at the start of the record not fitted (None: the settling
    /// time, the start of a record being treated as a step).
    pub warm_up_seconds: Option<f64>,
    /// Find rest segments and steps and leave them out (else only the
    /// warm-up is left out).
    pub detect_segments: bool,
}

impl Default for PlanOptions {
    fn default() -> Self {
        PlanOptions {
            segments: SegmentOptions::default(),
            warm_up_seconds: None,
            detect_segments: true,
        }
    }
}

/// Why the protocol cannot run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProtocolError {
    #[error("the input never changes in the fit part: nothing drives the stage")]
    NoExcitation,
    #[error("the fit part is empty (the split is at sample {0})")]
    EmptyFitPart(usize),
    #[error(
        "no sample is left to fit: {}",
        nothing_to_fit(*warm_up, *first_loading, *rests, *steps)
    )]
    NothingToFit {
        /// The warm-up given (`--warm-up`) [samples]; 0 when the default
        /// (settling and first loading) applies.
        warm_up: usize,
        /// Samples of the default start: settling and first loading, up to
        /// the input's second turning point.
        first_loading: usize,
        rests: usize,
        steps: usize,
    },
    #[error(
        "no sample is left to score: the warm-up ({warm_up} samples), rest segments and settling after steps cover the {samples} samples after the split"
    )]
    NothingScored { warm_up: usize, samples: usize },
    #[error(
        "the input stands at {0} level(s) over the fitted samples, and a loop needs at least {MIN_INPUT_LEVELS}: any model that tells {0} levels apart fits them exactly and says nothing of the loop between them; drive the stage through more levels (a staircase of 3 or more, a sine)"
    )]
    TooFewLevels(usize),
    #[error("{0}")]
    Fit(#[from] FitError),
    #[error("{0}")]
    BoucWen(#[from] BoucWenFitError),
}

/// What covered the fit part when nothing was left to fit, and what to do
/// about each cause (a hint only where it would help: with rests and steps
/// kept, the start alone may still cover a record that never turns).
fn nothing_to_fit(warm_up: usize, first_loading: usize, rests: usize, steps: usize) -> String {
    let mut causes = Vec::new();
    let mut hints = Vec::new();
    if warm_up > 0 {
        causes.push(format!("the warm-up given ({warm_up} samples)"));
        hints.push("a shorter --warm-up");
    }
    if first_loading > 0 {
        causes.push(format!(
            "the start ({first_loading} samples: the settling and the first loading, up to the \
             input's second turning point, which a drive that never turns twice never reaches)"
        ));
        hints.push("a longer fit part, or --warm-up 0 to fit from the first sample");
    }
    if rests > 0 {
        causes.push(format!(
            "{rests} rest segment(s) (the input held for --min-rest or longer)"
        ));
    }
    if steps > 0 {
        causes.push(format!("the settling (--settle) after {steps} step(s)"));
        hints.push("a shorter --settle (a stair shorter than the settling is all settling)");
    }
    if rests > 0 || steps > 0 {
        hints.push("--keep-rest-and-steps to fit rests and steps too");
    }
    format!(
        "{} cover the fit part; try {}",
        causes.join(", "),
        hints.join("; or ")
    )
}

/// The end of the first loading from a record's start (`segments::first_loading_end`),
/// its settling included: the input's second turning point before the first
/// step (an input that does not turn twice before it is a first loading all
/// the way to it, from a state the record does not show), or later, when
/// the input turns twice before `limit` only across steps. From the start
/// the state is unknown until then, wherever steps fall: a staircase from a
/// rest climbs its first stairs from whatever state the stage was left in,
/// and each step carries that state on. The turning points are counted
/// outside the settling after each step, where a command's overshoot is no
/// turn of the loop.
fn start_first_loading(
    u: &[f64],
    steps: &[usize],
    thresholds: &SegmentThresholds,
    limit: usize,
) -> usize {
    let settled = thresholds.settle_samples;
    let first_step = steps.first().copied().unwrap_or(u.len());
    let before_first_step =
        match first_loading_end(u, settled, first_step, thresholds.least_turn(), &[]) {
            Some(end) => end.max(settled),
            // Never turned before the first step (a rest): on to the end of
            // that step's first loading, as after any step of the fit part,
            // so that a validation file waits as long.
            None => after_step_first_loading(
                u,
                first_step,
                steps.get(1).copied().unwrap_or(u.len()),
                thresholds,
            ),
        };
    let settlings: Vec<Range<usize>> = steps
        .iter()
        .map(|&s| s..s + thresholds.settle_samples)
        .collect();
    first_loading_end(u, settled, limit, thresholds.least_turn(), &settlings)
        .map_or(before_first_step, |across| before_first_step.max(across))
}

/// The end of the first loading after the step at `step` (before the next
/// step, `next`): its second turning point once settled
/// (`segments::first_loading_end`), or the end of its settling when it
/// does not turn twice (a quasi-static stair). After a step the model has
/// run through what came before, so a stair that never turns is fitted
/// once settled.
fn after_step_first_loading(
    u: &[f64],
    step: usize,
    next: usize,
    thresholds: &SegmentThresholds,
) -> usize {
    let settled = step + thresholds.settle_samples;
    first_loading_end(u, settled, next, thresholds.least_turn(), &[])
        .unwrap_or(settled)
        .max(settled)
}

/// Which samples of a record are fitted and which scored.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Plan {
    pub samples: usize,
    /// The fit part is 0..fit_end, the scored part fit_end..samples.
    pub fit_end: usize,
    pub sample_period: f64,
    pub thresholds: SegmentThresholds,
    /// Rests and steps of the whole record.
    pub segments: Segments,
    pub warm_up_samples: usize,
    /// Whether the warm-up was set (`--warm-up`, or a plant run's period), in
    /// place of the default start: settling and the first loading.
    pub warm_up_given: bool,
    /// Samples of the fit part that are not fitted (warm-up included).
    pub fit_excluded: Vec<Range<usize>>,
    /// Samples of the scored part that are not scored.
    pub scored_excluded: Vec<Range<usize>>,
    /// Fastest cycle of the input over the fit part, rests aside [samples].
    pub fastest_cycle: Option<f64>,
    /// The levels a staircase holds over the fitted samples (None when the
    /// input is no staircase: [`held_levels`]).
    pub stairs: Option<usize>,
}

impl Plan {
    /// The steps in the fit part.
    pub fn fit_steps(&self) -> Vec<usize> {
        let fit_end = self.fit_end;
        self.segments
            .steps
            .iter()
            .copied()
            .filter(|&s| s < fit_end)
            .collect()
    }

    /// The plan of a record of input `u`, fitted on 0..fit_end.
    pub fn new(
        u: &[f64],
        sample_period: f64,
        fit_end: usize,
        options: &PlanOptions,
    ) -> Result<Plan, ProtocolError> {
        let fit_end = fit_end.min(u.len());
        if fit_end == 0 {
            return Err(ProtocolError::EmptyFitPart(fit_end));
        }
        let thresholds = thresholds(&u[..fit_end], sample_period, &options.segments)
            .ok_or(ProtocolError::NoExcitation)?;
        let segments = if options.detect_segments {
            detect_segments(u, &thresholds).staircase(u, fit_end, &thresholds)
        } else {
            Segments::default()
        };
        // The start of the record and every step: settling, then the first
        // loading (segments::first_loading_end), unless a warm-up is given
        // for the start.
        let mut starts: Vec<usize> = segments.steps.clone();
        let warm_up_samples = match options.warm_up_seconds {
            Some(seconds) => (seconds / sample_period).round() as usize,
            None => {
                starts.insert(0, 0);
                0
            }
        };
        // Samples of the default start (settling and first loading).
        let mut first_loading = 0;
        let excluded = {
            let mut all = segments.excluded(thresholds.settle_samples, u.len());
            all.push(0..warm_up_samples.min(u.len()));
            for (i, &start) in starts.iter().enumerate() {
                let next = starts.get(i + 1).copied().unwrap_or(u.len());
                // At the record's start, an input that does not turn twice
                // before the first step is a first loading all the way, from
                // a state the record does not show: none of it is fitted.
                let end = if start == 0 {
                    start_first_loading(u, &segments.steps, &thresholds, fit_end)
                } else {
                    after_step_first_loading(u, start, next, &thresholds)
                };
                // Only the fit part: a step in the scored part is scored once
                // settled (its state is the one the model computed).
                if start < fit_end {
                    all.push(start..end.min(fit_end));
                }
                if start == 0 && options.warm_up_seconds.is_none() {
                    first_loading = end.min(fit_end);
                }
            }
            merge(&mut all);
            all
        };
        let clip = |range: Range<usize>| -> Range<usize> {
            range.start.clamp(0, u.len())..range.end.clamp(0, u.len())
        };
        let fit_excluded: Vec<Range<usize>> = excluded
            .iter()
            .map(|r| clip(r.start..r.end.min(fit_end)))
            .filter(|r| !r.is_empty())
            .collect();
        let scored_excluded: Vec<Range<usize>> = excluded
            .iter()
            .map(|r| clip(r.start.max(fit_end)..r.end))
            .filter(|r| !r.is_empty())
            .collect();
        let mut plan = Plan {
            samples: u.len(),
            fit_end,
            sample_period,
            thresholds,
            segments,
            warm_up_samples,
            warm_up_given: options.warm_up_seconds.is_some(),
            fit_excluded,
            scored_excluded,
            fastest_cycle: None,
            stairs: None,
        };
        let fitted = plan.fitted();
        if !fitted.iter().any(|f| *f) {
            let in_fit_part = |start: usize| start < fit_end;
            return Err(ProtocolError::NothingToFit {
                warm_up: warm_up_samples.min(fit_end),
                first_loading,
                rests: plan
                    .segments
                    .rests
                    .iter()
                    .filter(|r| in_fit_part(r.start))
                    .count(),
                steps: plan
                    .segments
                    .steps
                    .iter()
                    .filter(|s| in_fit_part(**s))
                    .count(),
            });
        }
        if fit_end < u.len() && !plan.scored().iter().any(|s| *s) {
            return Err(ProtocolError::NothingScored {
                warm_up: warm_up_samples,
                samples: u.len() - fit_end,
            });
        }
        let levels = value_levels(selected(&u[..fit_end], &fitted), thresholds.rest_tolerance);
        if levels < MIN_INPUT_LEVELS {
            return Err(ProtocolError::TooFewLevels(levels));
        }
        plan.stairs = held_levels(
            &u[..fit_end],
            &fitted,
            thresholds.rest_tolerance,
            (thresholds.settle_samples / 2).max(3),
        );
        // The excitation's cycle, over the whole fit part but its rests (the
        // first loading is excluded from the fit, not from the excitation).
        let moving = flags(fit_end, 0, &plan.segments.rests);
        plan.fastest_cycle = fastest_cycle(&u[..fit_end], &moving, thresholds.span);
        Ok(plan)
    }

    /// Which samples of the fit part (0..fit_end) are fitted.
    pub fn fitted(&self) -> Vec<bool> {
        flags(self.fit_end, 0, &self.fit_excluded)
    }

    /// Which samples of the record are scored (none of the fit part).
    pub fn scored(&self) -> Vec<bool> {
        flags(self.samples, self.fit_end, &self.scored_excluded)
    }

    /// The record's voltage steps and the settling after each; `input` the
    /// record's input.
    pub fn steps<'a>(&'a self, input: &'a [f64]) -> Steps<'a> {
        Steps {
            starts: &self.segments.steps,
            settle: self.thresholds.settle_samples,
            input,
            hold_band: self.thresholds.hold_band(),
        }
    }

    /// The steps of a validation file (`segments` found in it by
    /// [`Self::validation_scored`], `input` its input, sampled every
    /// `sample_period` s), with this plan's settling in its samples.
    pub fn validation_steps<'a>(
        &self,
        segments: &'a Segments,
        input: &'a [f64],
        sample_period: f64,
    ) -> Steps<'a> {
        let thresholds = self.thresholds.resampled(self.sample_period, sample_period);
        Steps {
            starts: &segments.steps,
            settle: thresholds.settle_samples,
            input,
            hold_band: thresholds.hold_band(),
        }
    }

    /// The turning points of the input `u` over the fitted samples (turns
    /// of at least 1 % of the span, wherever between fitted samples they
    /// fall): fewer than two, and no whole loop, up and down, was fitted.
    pub fn fitted_turns(&self, u: &[f64]) -> usize {
        let end = self.fit_end.min(u.len());
        reversals(
            &u[..end],
            &self.fitted()[..end],
            REVERSAL_SPAN_FRACTION * self.thresholds.span,
        )
        .len()
    }

    /// Whether the record has a scored part.
    pub fn has_scored_part(&self) -> bool {
        self.fit_end < self.samples
    }

    /// The scored samples of a separate record of the same experiment
    /// (sampled every `sample_period` s), run from rest at its first sample:
    /// all but its warm-up (`warm_up_samples`, or by default the settling
    /// time and the first loading, as at the start of the fit part: its state
    /// before the record is assumed) and, with `detect`, its rests and
    /// settling after steps (found with this plan's thresholds, their
    /// durations in seconds).
    pub fn validation_scored(
        &self,
        u: &[f64],
        sample_period: f64,
        warm_up_samples: Option<usize>,
        detect: bool,
    ) -> (Segments, Vec<bool>) {
        let thresholds = self.thresholds.resampled(self.sample_period, sample_period);
        let segments = if detect {
            detect_segments(u, &thresholds).staircase(u, u.len(), &thresholds)
        } else {
            Segments::default()
        };
        let warm_up = warm_up_samples
            .unwrap_or_else(|| start_first_loading(u, &segments.steps, &thresholds, u.len()));
        let mut excluded = segments.excluded(thresholds.settle_samples, u.len());
        excluded.push(0..warm_up.min(u.len()));
        merge(&mut excluded);
        (segments, flags(u.len(), 0, &excluded))
    }

    /// The sensor zero of a separate validation file, aligned with the fit
    /// record's: when both records begin at rest (a rest from their first
    /// sample, found with this plan's thresholds whether or not rests are
    /// left out) at the same input (within the rest tolerance), the
    /// validation file's output is read relative to its rest as the fit
    /// record's is to its own. Both rests are taken after the settling time
    /// (a sensor's start-up transient), in seconds of each file's own
    /// sampling. This assumes what the scoring already assumes, that both
    /// start from the same rest state; it uses only samples that are neither
    /// fitted nor scored.
    pub fn zero_alignment(
        &self,
        fit: &Record,
        validation: &Record,
    ) -> Result<ZeroAlignment, NoZeroAlignment> {
        let settled_rest = |input: &[f64], thresholds: &SegmentThresholds, period, record| {
            let rest = detect_segments(input, thresholds)
                .rests
                .into_iter()
                .next()
                .filter(|rest| rest.start == 0)
                .ok_or(NoZeroAlignment::NotAtRest { record })?;
            let settled = (rest.start + thresholds.settle_samples)..rest.end;
            if settled.is_empty() {
                return Err(NoZeroAlignment::RestWithinSettling {
                    record,
                    seconds: rest.len() as f64 * period,
                });
            }
            Ok(settled)
        };
        let fit_part = &fit.input[..self.fit_end.min(fit.input.len())];
        let fit_rest = settled_rest(fit_part, &self.thresholds, self.sample_period, "fit record")?;
        let validation_thresholds = self
            .thresholds
            .resampled(self.sample_period, validation.sample_period);
        let validation_rest = settled_rest(
            &validation.input,
            &validation_thresholds,
            validation.sample_period,
            "validation file",
        )?;
        let mean = |values: &[f64]| values.iter().sum::<f64>() / values.len() as f64;
        let fit_input = mean(&fit.input[fit_rest.clone()]);
        let validation_input = mean(&validation.input[validation_rest.clone()]);
        if (fit_input - validation_input).abs() > self.thresholds.rest_tolerance {
            return Err(NoZeroAlignment::DifferentInputs {
                fit: fit_input,
                validation: validation_input,
            });
        }
        let shift =
            mean(&validation.output[validation_rest.clone()]) - mean(&fit.output[fit_rest.clone()]);
        Ok(ZeroAlignment {
            rest_input: fit_input,
            fit_rest,
            validation_rest,
            shift,
        })
    }

    /// Search decimation for `fitted` samples (module comment).
    pub fn search_decimation(&self, fitted: usize) -> usize {
        let by_samples = fitted.div_ceil(SEARCH_SAMPLES).max(1);
        let by_cycle = self.fastest_cycle.map_or(by_samples, |c| {
            ((c / SEARCH_SAMPLES_PER_CYCLE).floor() as usize).max(1)
        });
        by_samples.min(by_cycle)
    }

    /// Smoothing half widths to try [samples]: none, and windows of the
    /// fractions [`SMOOTHING_CYCLE_FRACTIONS`] of the fastest cycle.
    pub fn smoothing_candidates(&self) -> Vec<usize> {
        let mut widths = vec![0];
        if let Some(cycle) = self.fastest_cycle {
            for fraction in SMOOTHING_CYCLE_FRACTIONS {
                let window = cycle * fraction;
                let half = ((window - 1.0) / 2.0).floor();
                if half >= 1.0 {
                    widths.push(half as usize);
                }
            }
        }
        widths.dedup();
        widths
    }
}

/// `len` flags, false before `from` and in every range of `excluded`.
fn flags(len: usize, from: usize, excluded: &[Range<usize>]) -> Vec<bool> {
    let mut flags: Vec<bool> = (0..len).map(|n| n >= from).collect();
    for r in excluded {
        for f in &mut flags[r.start.min(len)..r.end.min(len)] {
            *f = false;
        }
    }
    flags
}

/// The ranges where `flags` is false.
fn unset_ranges(flags: &[bool]) -> Vec<Range<usize>> {
    let mut ranges = Vec::new();
    let mut start = None;
    for (n, f) in flags.iter().enumerate() {
        match (f, start) {
            (false, None) => start = Some(n),
            (true, Some(s)) => {
                ranges.push(s..n);
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        ranges.push(s..flags.len());
    }
    ranges
}

/// What the protocol reports while it runs: a phase with its number of
/// steps, then one call per step with the best objective so far.
#[derive(Clone, Copy, Debug)]
pub enum ProgressEvent<'a> {
    Phase { name: &'a str, steps: usize },
    Step { best: f64 },
}

/// Receives [`ProgressEvent`]s, from any thread.
pub type ProgressSink<'a> = &'a (dyn Fn(ProgressEvent) + Sync);

/// RMS and largest error on a set of samples, also as % of a span.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ErrorFigures {
    pub samples: usize,
    pub rms: f64,
    pub max_abs: f64,
    /// Sample of the largest error (in the record scored).
    pub max_abs_sample: usize,
    pub rms_percent: f64,
    pub max_percent: f64,
}

impl ErrorFigures {
    fn of(prediction: &[f64], measured: &[f64], scored: &[bool], span: f64) -> ErrorFigures {
        let q = FitQuality::of_samples(prediction, measured, scored);
        ErrorFigures {
            samples: q.samples,
            rms: q.rms,
            max_abs: q.max_abs,
            max_abs_sample: q.max_abs_sample,
            rms_percent: 100.0 * q.rms / span,
            max_percent: 100.0 * q.max_abs / span,
        }
    }
}

/// Settings of [`identify_inverse_pi`]; `None` means "chosen by the
/// protocol" (module comment).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InversePiSettings {
    pub starts: usize,
    pub seed: u64,
    pub max_iterations: u64,
    pub screening: Option<Screening>,
    /// Runs to convergence restarted at their end (`FitOptions::restarts`).
    pub restarts: bool,
    pub decimation: Option<usize>,
    /// Half width of the displacement's moving average [samples].
    pub smoothing: Option<usize>,
    pub rate_dependent: Option<bool>,
    /// Displacement offset [µm] (None: the smallest fitted displacement).
    pub offset: Option<f64>,
}

impl Default for InversePiSettings {
    fn default() -> Self {
        InversePiSettings {
            starts: 30,
            seed: 0,
            max_iterations: 2000,
            screening: Some(Screening {
                iterations: 60,
                kept: 5,
                relative_tolerance: 1e-6,
            }),
            restarts: true,
            decimation: None,
            smoothing: None,
            rate_dependent: None,
            offset: None,
        }
    }
}

/// One candidate of the forward validation inside the fit part.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Candidate {
    /// Half width of the moving average [samples].
    pub smoothing: usize,
    pub rate_dependent: bool,
    /// The start of the inner search whose (c, w_s) it takes (None for the
    /// classical model).
    pub start: Option<usize>,
    /// RMS error on the validation samples [V].
    pub validation_rms: f64,
}

/// The forward validation inside the fit part.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CrossValidation {
    /// The search ran on the fitted samples before this one ...
    pub train_end: usize,
    pub train_samples: usize,
    /// ... and the candidates were scored on those after it.
    pub validation_samples: usize,
    /// The (c, w_s) of that search, shared by every candidate.
    pub c: f64,
    pub ws: Vec<f64>,
    pub proposed: Vec<Candidate>,
    pub classical: Vec<Candidate>,
}

/// The errors of the inverse models on a set of samples [V], % of the fit
/// part's input span.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct InversePiErrors {
    pub proposed: ErrorFigures,
    pub classical: ErrorFigures,
    pub line: ErrorFigures,
}

/// What [`identify_inverse_pi`] found.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InversePiIdentification {
    pub params: InversePiParams,
    /// Half width of the displacement's moving average [samples].
    pub smoothing: usize,
    pub rate_dependent: bool,
    /// Whether each was chosen by the validation inside the fit part (else
    /// given).
    pub smoothing_validated: bool,
    pub weights_validated: bool,
    pub cross_validation: Option<CrossValidation>,
    /// Subtracted from the (smoothed) displacement [µm].
    pub offset: f64,
    pub decimation: usize,
    pub starts: Vec<StartResult>,
    pub best_start: Option<usize>,
    pub classical: ClassicalPiParams,
    pub classical_smoothing: usize,
    pub classical_offset: f64,
    /// u = line[0]·(y − offset) + line[1].
    pub line: [f64; 2],
    /// Input span and displacement span of the fitted samples.
    pub input_span: f64,
    pub stroke: f64,
    pub fit_errors: InversePiErrors,
    /// On the scored part of the record (when split).
    pub unseen: Option<InversePiErrors>,
    pub seconds: f64,
}

/// Each model's voltage for a record's displacement, sample by sample, run
/// from rest at its first sample [V].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InversePiPredictions {
    pub proposed: Vec<f64>,
    pub classical: Vec<f64>,
    pub line: Vec<f64>,
}

impl InversePiIdentification {
    /// Each model's voltage for the measured displacement `y` of a record
    /// run from its first sample; `steps` its voltage steps (the models are
    /// driven with [`inverse_model_input`]).
    pub fn predictions_on(
        &self,
        y: &[f64],
        sample_period: f64,
        steps: Steps,
    ) -> InversePiPredictions {
        let prepared = |half_width: usize, offset: f64| -> Vec<f64> {
            inverse_model_input(y, half_width, steps)
                .iter()
                .map(|v| v - offset)
                .collect()
        };
        let y_proposed = prepared(self.smoothing, self.offset);
        let proposed = predict(
            &mut piezo_models::ModifiedInversePi::new(self.params),
            &y_proposed,
            sample_period,
        );
        let y_classical = prepared(self.classical_smoothing, self.classical_offset);
        let classical = predict(
            &mut ClassicalPi::new(self.classical),
            &y_classical,
            sample_period,
        );
        let line = y_proposed
            .iter()
            .map(|v| self.line[0] * v + self.line[1])
            .collect();
        InversePiPredictions {
            proposed,
            classical,
            line,
        }
    }

    /// The models' errors on a record (`y` measured displacement, `u`
    /// voltage) run from its first sample; `steps` its voltage steps (as
    /// for [`Self::predictions_on`]), `scored` the samples scored.
    pub fn errors_on(
        &self,
        y: &[f64],
        u: &[f64],
        sample_period: f64,
        steps: Steps,
        scored: &[bool],
    ) -> InversePiErrors {
        let predictions = self.predictions_on(y, sample_period, steps);
        let span = self.input_span;
        InversePiErrors {
            proposed: ErrorFigures::of(&predictions.proposed, u, scored, span),
            classical: ErrorFigures::of(&predictions.classical, u, scored, span),
            line: ErrorFigures::of(&predictions.line, u, scored, span),
        }
    }
}

/// The fitted samples before `train_end` and the index that splits the
/// fitted samples of `fitted` at `fraction`.
fn inner_split(fitted: &[bool], fraction: f64) -> usize {
    let total = fitted.iter().filter(|f| **f).count();
    let wanted = ((total as f64) * fraction).round() as usize;
    let mut seen = 0;
    for (n, f) in fitted.iter().enumerate() {
        if *f {
            if seen == wanted {
                return n;
            }
            seen += 1;
        }
    }
    fitted.len()
}

/// The (c, w_s) the forward validation compares: the best
/// [`INNER_CANDIDATES`] distinct ends of the inner search's polished starts.
fn inner_candidates(starts: &[StartResult]) -> Vec<&StartResult> {
    let mut polished: Vec<&StartResult> = starts.iter().filter(|s| s.polished).collect();
    polished.sort_by(|a, b| a.objective.total_cmp(&b.objective));
    let mut kept: Vec<&StartResult> = Vec::new();
    for start in polished {
        // One basin, reached by two starts that stopped a little apart
        // (F within 10⁻⁵ of each other, c within 10⁻³).
        let same = |other: &&StartResult| {
            (other.objective - start.objective).abs() <= 1e-5 * start.objective.abs()
                && (other.c - start.c).abs() <= 1e-3 * start.c.abs()
        };
        if !kept.iter().any(same) && kept.len() < INNER_CANDIDATES {
            kept.push(start);
        }
    }
    kept
}

/// The forward validation inside the fit part: the linear part fitted on
/// the fitted samples before `train_end`, scored on those after it.
struct InnerSplit {
    /// The fitted samples of the whole fit part.
    fitted: Vec<bool>,
    /// The fitted samples before `train_end` (the operators' reversals are
    /// judged where the linear part is fitted).
    train_mask: Vec<bool>,
    /// The voltage at each fitted sample, in sample order.
    targets: Vec<f64>,
    /// Positions in `targets` of the train and validation samples.
    train: Vec<usize>,
    validation: Vec<usize>,
}

impl InnerSplit {
    fn new(fitted: &[bool], u: &[f64], train_end: usize) -> InnerSplit {
        let rows: Vec<usize> = (0..fitted.len()).filter(|&n| fitted[n]).collect();
        InnerSplit {
            fitted: fitted.to_vec(),
            train_mask: (0..fitted.len())
                .map(|n| fitted[n] && n < train_end)
                .collect(),
            targets: rows.iter().map(|&n| u[n]).collect(),
            train: (0..rows.len()).filter(|&i| rows[i] < train_end).collect(),
            validation: (0..rows.len()).filter(|&i| rows[i] >= train_end).collect(),
        }
    }

    /// The proposed model's validation RMS [V] for (c, w_s) on the shifted
    /// displacement `y`, one per layout (rate-dependent or constant
    /// backlash weights).
    fn proposed_rms(&self, y: &[f64], dt: f64, c: f64, ws: &[f64], layouts: &[bool]) -> Vec<f64> {
        let y_max = range_of(y, &self.train_mask).1;
        let thresholds = SIX_DEAD_ZONE_PATTERN.map(|p| p * c);
        let u1max = u1max_for(ws, &thresholds, y_max);
        let mut x = masked_rate_dependent_regressors(PROPOSED, c, ws, u1max, y, dt, &self.fitted);
        let reversing = reversing_operators(PROPOSED, c, ws, u1max, y, &self.train_mask);
        for operator in (0..reversing.len()).filter(|&i| !reversing[i]) {
            for column in PROPOSED.operator_columns(operator) {
                x.column_mut(column).fill(0.0);
            }
        }
        layouts
            .iter()
            .map(|&rate_dependent| {
                let columns: Vec<usize> = if rate_dependent {
                    (0..PROPOSED.linear_columns()).collect()
                } else {
                    (0..4).chain(14..24).collect()
                };
                self.rms(&x, &columns, 3)
            })
            .collect()
    }

    /// Least squares of the targets on the given columns of the train rows
    /// (`intercept` the position of the constant among them), RMS of the
    /// prediction on the validation rows.
    fn rms(&self, x: &DMatrix<f64>, columns: &[usize], intercept: usize) -> f64 {
        let sub = |rows: &[usize]| {
            DMatrix::from_fn(rows.len(), columns.len(), |i, j| x[(rows[i], columns[j])])
        };
        let train_targets: Vec<f64> = self.train.iter().map(|&r| self.targets[r]).collect();
        let solution = solve_least_squares_with_intercept_regularized(
            sub(&self.train),
            &train_targets,
            intercept,
            LINEAR_RSS_INCREASE,
        );
        let predicted = sub(&self.validation) * nalgebra::DVector::from_vec(solution.coefficients);
        let sum: f64 = self
            .validation
            .iter()
            .zip(predicted.iter())
            .map(|(&r, p)| (p - self.targets[r]).powi(2))
            .sum();
        (sum / self.validation.len().max(1) as f64).sqrt()
    }
}

/// Fits seed 000's proposed model to `record` by the protocol of the module
/// comment, with the classical P-I model and a straight line as baselines,
/// and scores all three on the scored part of `plan` when there is one.
pub fn identify_inverse_pi(
    record: &Record,
    plan: &Plan,
    settings: &InversePiSettings,
    progress: ProgressSink,
) -> Result<InversePiIdentification, ProtocolError> {
    let started = Instant::now();
    let dt = record.sample_period;
    let fit_end = plan.fit_end;
    let y_fit = &record.output[..fit_end];
    let u_fit = &record.input[..fit_end];
    let fitted = plan.fitted();
    let fit_steps = plan.fit_steps();
    let fit_settling = Steps {
        starts: &fit_steps,
        ..plan.steps(u_fit)
    };
    let smooth = |half_width: usize| inverse_model_input(y_fit, half_width, fit_settling);
    let smoothings = match settings.smoothing {
        Some(h) => vec![h],
        None => plan.smoothing_candidates(),
    };
    let layouts = match settings.rate_dependent {
        Some(r) => vec![r],
        None => vec![false, true],
    };
    let search_options = |starts: usize, flags: &[bool], rate_dependent: bool| FitOptions {
        starts,
        seed: settings.seed,
        max_iterations: settings.max_iterations,
        decimation: settings
            .decimation
            .unwrap_or_else(|| plan.search_decimation(flags.iter().filter(|f| **f).count())),
        warm_up_samples: 0,
        excluded: unset_ranges(flags),
        rate_dependent,
        screening: settings.screening,
        restarts: settings.restarts,
        rss_increase: LINEAR_RSS_INCREASE,
        reversing_operators_only: true,
        c_range: Some(DEAD_ZONE_SCALE_RANGE),
    };
    let tick = |s: &StartResult| progress(ProgressEvent::Step { best: s.objective });

    // Forward validation inside the fit part.
    let (smoothing, rate_dependent, classical_smoothing, cross_validation) =
        if smoothings.len() == 1 && layouts.len() == 1 {
            (smoothings[0], layouts[0], smoothings[0], None)
        } else {
            let train_end = inner_split(&fitted, INNER_TRAIN_FRACTION);
            let train_flags: Vec<bool> = fitted[..train_end].to_vec();
            let heaviest = *smoothings.iter().max().expect("at least one candidate");
            let prepared = |half_width: usize| -> (Vec<f64>, f64) {
                let y = smooth(half_width);
                let offset = settings
                    .offset
                    .unwrap_or_else(|| range_of(&y[..train_end], &train_flags).0);
                (y.iter().map(|v| v - offset).collect(), offset)
            };
            let (y_search, _) = prepared(heaviest);
            let options = search_options(settings.starts, &train_flags, layouts == [true]);
            progress(ProgressEvent::Phase {
                name: "validation search",
                steps: options.starts,
            });
            let inner = fit_modified_inverse_pi_with_progress(
                &y_search[..train_end],
                &u_fit[..train_end],
                dt,
                &options,
                &tick,
            )?;
            let (c, ws) = (inner.params.c, inner.params.ws);
            let searched = inner_candidates(&inner.starts);
            let split = InnerSplit::new(&fitted, u_fit, train_end);
            let mut proposed = Vec::new();
            let mut classical = Vec::new();
            for &half_width in &smoothings {
                let (y, _) = prepared(half_width);
                for start in &searched {
                    let errors = split.proposed_rms(&y, dt, start.c, &start.ws, &layouts);
                    for (&rate_dependent, validation_rms) in layouts.iter().zip(errors) {
                        proposed.push(Candidate {
                            smoothing: half_width,
                            rate_dependent,
                            start: Some(start.start),
                            validation_rms,
                        });
                    }
                }
                let (low, high) = range_of(&y[..train_end], &train_flags);
                let thresholds = ClassicalPiParams::evenly_spaced_thresholds(high - low);
                let mut x = masked_classical_regressors(&thresholds, &y, &fitted);
                let reversing = reversing_classical_operators(&thresholds, &y, &split.train_mask);
                for column in (0..reversing.len()).filter(|&i| !reversing[i]) {
                    x.column_mut(column).fill(0.0);
                }
                let columns: Vec<usize> = (0..x.ncols()).collect();
                classical.push(Candidate {
                    smoothing: half_width,
                    rate_dependent: false,
                    start: None,
                    validation_rms: split.rms(&x, &columns, CLASSICAL_OPERATORS),
                });
            }
            let best = |rate: bool| {
                proposed
                    .iter()
                    .filter(|c| c.rate_dependent == rate)
                    .min_by(|a, b| a.validation_rms.total_cmp(&b.validation_rms))
                    .copied()
            };
            let chosen = match (best(false), best(true)) {
                (Some(constant), Some(rated)) => {
                    let gain = constant.validation_rms - rated.validation_rms;
                    if gain > RATE_DEPENDENCE_MARGIN * constant.validation_rms
                        && gain > RATE_DEPENDENCE_FLOOR * plan.thresholds.span
                    {
                        rated
                    } else {
                        constant
                    }
                }
                (Some(only), None) | (None, Some(only)) => only,
                (None, None) => unreachable!("at least one layout"),
            };
            let classical_best = classical
                .iter()
                .min_by(|a, b| a.validation_rms.total_cmp(&b.validation_rms))
                .expect("at least one candidate")
                .smoothing;
            (
                chosen.smoothing,
                chosen.rate_dependent,
                classical_best,
                Some(CrossValidation {
                    train_end,
                    train_samples: split.train.len(),
                    validation_samples: split.validation.len(),
                    c,
                    ws: ws.to_vec(),
                    proposed,
                    classical,
                }),
            )
        };

    // The final fit on every fitted sample of the fit part.
    let shift = |half_width: usize| -> (Vec<f64>, f64) {
        let y = smooth(half_width);
        let offset = settings.offset.unwrap_or_else(|| range_of(&y, &fitted).0);
        (y.iter().map(|v| v - offset).collect(), offset)
    };
    let (y, offset) = shift(smoothing);
    let options = search_options(settings.starts, &fitted, rate_dependent);
    progress(ProgressEvent::Phase {
        name: "proposed model",
        steps: options.starts,
    });
    let fit = fit_modified_inverse_pi_with_progress(&y, u_fit, dt, &options, &tick)?;
    let (y_classical, classical_offset) = shift(classical_smoothing);
    let classical = fit_classical_pi(&y_classical, u_fit, dt, &options)?;
    let rows: Vec<f64> = selected(&y, &fitted);
    let line_solution = solve_least_squares(
        DMatrix::from_fn(rows.len(), 2, |i, j| if j == 0 { rows[i] } else { 1.0 }),
        &selected(u_fit, &fitted),
    );
    let (u_low, u_high) = range_of(u_fit, &fitted);
    let (y_low, y_high) = range_of(&y, &fitted);
    let mut identification = InversePiIdentification {
        params: fit.params,
        smoothing,
        rate_dependent,
        smoothing_validated: settings.smoothing.is_none(),
        weights_validated: settings.rate_dependent.is_none(),
        cross_validation,
        offset,
        decimation: options.decimation,
        starts: fit.starts,
        best_start: fit.best_start,
        classical: classical.params,
        classical_smoothing,
        classical_offset,
        line: [line_solution.coefficients[0], line_solution.coefficients[1]],
        input_span: u_high - u_low,
        stroke: y_high - y_low,
        // Filled in below, by the method that scores any record.
        fit_errors: InversePiErrors::default(),
        unseen: None,
        seconds: 0.0,
    };
    identification.fit_errors = identification.errors_on(y_fit, u_fit, dt, fit_settling, &fitted);
    if plan.has_scored_part() {
        identification.unseen = Some(identification.errors_on(
            &record.output,
            &record.input,
            dt,
            plan.steps(&record.input),
            &plan.scored(),
        ));
    }
    identification.seconds = started.elapsed().as_secs_f64();
    Ok(identification)
}

/// Settings of [`identify_bouc_wen_protocol`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BoucWenSettings {
    pub gapso: GaPsoOptions,
    pub bounds: Bounds,
    /// GA-PSO's decimation (None: as the inverse model's search).
    pub decimation: Option<usize>,
    /// Half width of a moving average of the fitted displacement [samples];
    /// the score is always against the measured displacement.
    pub smoothing: usize,
    pub fit_offset: bool,
    pub monotone: bool,
    pub refine: bool,
    /// Fit (and score) the model with a return-point memory
    /// (`BoucWenFitOptions::return_point_memory`).
    pub return_point_memory: bool,
}

impl Default for BoucWenSettings {
    fn default() -> Self {
        BoucWenSettings {
            gapso: GaPsoOptions::default(),
            bounds: default_shape_bounds(),
            decimation: None,
            smoothing: 0,
            fit_offset: true,
            monotone: false,
            refine: true,
            return_point_memory: false,
        }
    }
}

/// Errors of the forward models on a set of samples [µm], % of the fit
/// part's stroke.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct ForwardErrors {
    /// The kept model (refined when refinement was kept).
    pub bouc_wen: ErrorFigures,
    pub gapso: ErrorFigures,
    pub classical: ErrorFigures,
    /// The straight line fitted on the fit part.
    pub line: ErrorFigures,
    /// The best straight line of the scored samples themselves.
    pub best_line: ErrorFigures,
}

/// A GA-PSO search whose optimum was unusable on the fitted samples.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct UnusableSearch {
    /// It searched one sample in `decimation` ...
    pub decimation: usize,
    /// ... for this long [s].
    pub seconds: f64,
}

/// What [`identify_bouc_wen_protocol`] found.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BoucWenProtocolFit {
    pub identification: BoucWenIdentification,
    /// The decimations, chosen by the protocol, whose GA-PSO optimum was
    /// unusable on the fitted samples (a falling branch or a divergence
    /// between the searched samples), each followed by a search on half as
    /// many samples apart; empty when the first search's optimum was usable.
    pub unusable_searches: Vec<UnusableSearch>,
    /// The options the fit ran with (decimation and excluded samples
    /// included).
    pub options: BoucWenFitOptions,
    /// Classical P-I model of the output from the input.
    pub classical: ClassicalPiParams,
    /// y = line[0]·u + line[1].
    pub line: [f64; 2],
    /// Output span of the fitted samples.
    pub stroke: f64,
    pub fit_errors: ForwardErrors,
    pub unseen: Option<ForwardErrors>,
    pub seconds: f64,
}

/// Each model's displacement for a record's voltage, sample by sample, run
/// from rest at its first sample [µm].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ForwardPredictions {
    /// The kept fit (Levenberg-Marquardt's when it was kept, else GA-PSO's).
    pub bouc_wen: Vec<f64>,
    pub classical: Vec<f64>,
    pub line: Vec<f64>,
}

impl BoucWenProtocolFit {
    /// Each model's displacement for the voltage `u` of a record run from
    /// rest at its first sample.
    pub fn predictions_on(&self, u: &[f64], sample_period: f64) -> ForwardPredictions {
        let best = self.identification.best();
        ForwardPredictions {
            bouc_wen: predict_bouc_wen(
                best.params,
                best.offset,
                u,
                self.options.return_point_memory,
            ),
            classical: predict(&mut ClassicalPi::new(self.classical), u, sample_period),
            line: u.iter().map(|v| self.line[0] * v + self.line[1]).collect(),
        }
    }

    /// The models' errors on a record (input `u`, measured output `y`) run
    /// from rest at its first sample, on the samples `scored`.
    pub fn errors_on(
        &self,
        u: &[f64],
        y: &[f64],
        sample_period: f64,
        scored: &[bool],
    ) -> ForwardErrors {
        let predictions = self.predictions_on(u, sample_period);
        let gapso = &self.identification.gapso;
        let rows_u = selected(u, scored);
        let best_line = solve_least_squares(
            DMatrix::from_fn(rows_u.len(), 2, |i, j| if j == 0 { rows_u[i] } else { 1.0 }),
            &selected(y, scored),
        )
        .coefficients;
        let best_line: Vec<f64> = u.iter().map(|v| best_line[0] * v + best_line[1]).collect();
        let span = self.stroke;
        ForwardErrors {
            bouc_wen: ErrorFigures::of(&predictions.bouc_wen, y, scored, span),
            gapso: ErrorFigures::of(
                &predict_bouc_wen(
                    gapso.params,
                    gapso.offset,
                    u,
                    self.options.return_point_memory,
                ),
                y,
                scored,
                span,
            ),
            classical: ErrorFigures::of(&predictions.classical, y, scored, span),
            line: ErrorFigures::of(&predictions.line, y, scored, span),
            best_line: ErrorFigures::of(&best_line, y, scored, span),
        }
    }
}

/// Fits seed 001's Bouc-Wen model to `record` on the fitted samples of
/// `plan` (GA-PSO, then Levenberg-Marquardt kept inside the box and only if
/// it improves the fit part), with the classical P-I model and straight
/// lines as baselines, and scores them on the scored part when there is one.
pub fn identify_bouc_wen_protocol(
    record: &Record,
    plan: &Plan,
    settings: &BoucWenSettings,
    progress: ProgressSink,
) -> Result<BoucWenProtocolFit, ProtocolError> {
    let started = Instant::now();
    let dt = record.sample_period;
    let fit_end = plan.fit_end;
    let u_fit = &record.input[..fit_end];
    let y_fit = &record.output[..fit_end];
    let fitted = plan.fitted();
    let fit_steps = plan.fit_steps();
    let target = smoothed_between_steps(y_fit, settings.smoothing, &fit_steps);
    let mut options = BoucWenFitOptions {
        gapso: settings.gapso.clone(),
        bounds: settings.bounds.clone(),
        decimation: settings
            .decimation
            .unwrap_or_else(|| plan.search_decimation(fitted.iter().filter(|f| **f).count())),
        warm_up_samples: 0,
        excluded: unset_ranges(&fitted),
        fit_offset: settings.fit_offset,
        monotone: settings.monotone,
        search_substeps: BOUC_WEN_SEARCH_SUBSTEPS,
        refine: settings.refine,
        refine_within_bounds: true,
        return_point_memory: settings.return_point_memory,
    };
    progress(ProgressEvent::Phase {
        name: "GA-PSO",
        steps: options.gapso.generations,
    });
    // The decimated search sees the loops' turning points only to within its
    // decimation, so with --monotone its optimum can draw a falling branch
    // right after a reversal it did not sample. Then it searches again on
    // twice as many samples, down to every sample, where every branch is
    // checked as the model is then scored: each search costs about twice the
    // one before, the whole at most about twice the last. A decimation the
    // user gave is kept, and the error says what to do.
    let mut unusable_searches = Vec::new();
    let identification = loop {
        let search_started = Instant::now();
        match identify_bouc_wen(u_fit, &target, &options, |_, best| {
            progress(ProgressEvent::Step { best })
        }) {
            Err(BoucWenFitError::UnusableOnAllSamples { decimation })
                if decimation > 1 && settings.decimation.is_none() =>
            {
                unusable_searches.push(UnusableSearch {
                    decimation,
                    seconds: search_started.elapsed().as_secs_f64(),
                });
                options.decimation = decimation / 2;
                progress(ProgressEvent::Phase {
                    name: "GA-PSO on more samples",
                    steps: options.gapso.generations,
                });
            }
            other => break other?,
        }
    };
    let fit_options = FitOptions {
        excluded: options.excluded.clone(),
        rss_increase: LINEAR_RSS_INCREASE,
        reversing_operators_only: true,
        ..FitOptions::default()
    };
    let classical = fit_classical_pi(u_fit, &target, dt, &fit_options)?;
    let rows_u = selected(u_fit, &fitted);
    let line = solve_least_squares(
        DMatrix::from_fn(rows_u.len(), 2, |i, j| if j == 0 { rows_u[i] } else { 1.0 }),
        &selected(&target, &fitted),
    )
    .coefficients;
    let (low, high) = range_of(y_fit, &fitted);
    let mut result = BoucWenProtocolFit {
        identification,
        unusable_searches,
        options,
        classical: classical.params,
        line: [line[0], line[1]],
        stroke: high - low,
        // Filled in below, by the method that scores any record.
        fit_errors: ForwardErrors::default(),
        unseen: None,
        seconds: 0.0,
    };
    result.fit_errors = result.errors_on(u_fit, y_fit, dt, &fitted);
    if plan.has_scored_part() {
        result.unseen = Some(result.errors_on(&record.input, &record.output, dt, &plan.scored()));
    }
    result.seconds = started.elapsed().as_secs_f64();
    Ok(result)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Uniform};
    use rand_xoshiro::Xoshiro256PlusPlus;

    #[test]
    fn unset_ranges_and_flags_are_inverse() {
        let excluded = vec![0..3, 5..6, 9..10];
        let f = flags(10, 0, &excluded);
        assert_eq!(unset_ranges(&f), excluded);
        assert_eq!(unset_ranges(&flags(4, 2, &[])), vec![0..2]);
    }

    #[test]
    fn inner_split_puts_the_fraction_of_fitted_samples_before_it() {
        let fitted: Vec<bool> = (0..20).map(|n| n >= 10).collect();
        assert_eq!(inner_split(&fitted, 0.7), 17);
    }

    #[test]
    fn a_plan_leaves_out_rest_steps_and_warm_up_and_scores_the_rest() {
        // 1 s rest, step onto a 1 Hz sine, 200 Hz, 5 s; split at 3 s.
        let u: Vec<f64> = (0..1000)
            .map(|n| {
                if n < 200 {
                    0.0
                } else {
                    2.0 + (std::f64::consts::TAU * (n - 200) as f64 / 200.0).sin()
                }
            })
            .collect();
        let plan = Plan::new(&u, 0.005, 600, &PlanOptions::default()).unwrap();
        assert_eq!(plan.segments.rests, vec![0..200]);
        assert_eq!(plan.segments.steps, vec![200]);
        // Rest, settling (to 220), first loading: the sine's first maximum
        // at 250 and first minimum at 350.
        assert_eq!(plan.fit_excluded, vec![0..350]);
        assert!(plan.scored_excluded.is_empty());
        assert_eq!(plan.fitted().iter().filter(|f| **f).count(), 250);
        assert_eq!(plan.scored().iter().filter(|f| **f).count(), 400);
        let cycle = plan.fastest_cycle.unwrap();
        assert!((cycle - 200.0).abs() <= 2.0, "{cycle}");
        assert_eq!(plan.smoothing_candidates(), vec![0, 2]);
        // A warm-up over the whole scored part is refused.
        let options = PlanOptions {
            warm_up_seconds: Some(5.0),
            ..PlanOptions::default()
        };
        assert!(matches!(
            Plan::new(&u, 0.005, 600, &options),
            Err(ProtocolError::NothingToFit { .. })
        ));
    }

    /// A record whose input turns once (rest, then one cycle 0 -> 10 -> 0 V)
    /// is a first loading all the way: nothing is fitted, and the error says
    /// why; a cycle and a half turns twice, and is fitted from its second
    /// turning point on. The first loading used to be fitted, though the
    /// summary said it was left out. A staircase's stairs, after its first
    /// step, are fitted once settled.
    #[test]
    fn an_input_that_never_turns_twice_is_no_record_to_fit() {
        let record = |cycles: f64| -> Vec<f64> {
            let moving = (cycles * 200.0) as usize;
            (0..100 + moving)
                .map(|n| match n.checked_sub(100) {
                    None => 0.0,
                    Some(k) => 5.0 * (1.0 - (std::f64::consts::TAU * k as f64 / 200.0).cos()),
                })
                .collect()
        };
        let one = record(1.0);
        let e = Plan::new(&one, 0.005, one.len(), &PlanOptions::default()).unwrap_err();
        assert!(matches!(e, ProtocolError::NothingToFit { .. }), "{e}");
        assert!(
            e.to_string()
                .contains("the first loading, up to the input's second turning point")
        );
        let longer = record(1.5);
        let plan = Plan::new(&longer, 0.005, longer.len(), &PlanOptions::default()).unwrap();
        // The second turning point: the minimum after the first maximum, at
        // 100 + 200 samples.
        let first_fitted = plan.fitted().iter().position(|f| *f).unwrap();
        assert!((299..=301).contains(&first_fitted), "{first_fitted}");
        // Three triangles of 1 V stairs held 0.3 s each (60 samples).
        let stairs: Vec<f64> = (0..3 * 20 * 60)
            .map(|n| {
                let stair = (n / 60) % 20;
                (if stair < 10 { stair } else { 20 - stair }) as f64
            })
            .collect();
        let plan = Plan::new(&stairs, 0.005, stairs.len(), &PlanOptions::default()).unwrap();
        // Every 1 V jump is a step onto a hold (10 % of the span; on 1.7 %
        // of the samples, more than the 1 % the percentile rule allows), so
        // the first triangle is the first loading and each later stair is
        // fitted after its 20 samples of settling.
        assert_eq!(plan.segments.steps.len(), 3 * 20 - 1);
        let fitted = plan.fitted().iter().filter(|f| **f).count();
        assert_eq!(fitted, 2 * 20 * 40, "{fitted} of {}", stairs.len());
    }

    /// A staircase from a rest climbs its first stairs from a state the
    /// record does not show, and each step carries that state on: the fit
    /// starts at the input's second turning point counted across the steps
    /// (the first stair of the second triangle), once settled. It used to
    /// start at the first stair's settling; on the 5 kHz staircase of
    /// docs/identification.md that first climb was 0.59 % of the input span
    /// off the model fitted to everything after it, dominated the objective
    /// and sent each seed to another minimum.
    #[test]
    fn a_staircase_from_a_rest_is_fitted_from_its_second_turning_point() {
        // 1 s rest at 0 V, then three triangles of 1 V stairs 1..5..2 V held
        // 1 s each, at 200 Hz: the top at sample 200 + 4·200, the bottom
        // (1 V again) at 200 + 8·200.
        let stairs: Vec<f64> = (0..200 + 3 * 8 * 200usize)
            .map(|n| match n.checked_sub(200) {
                None => 0.0,
                Some(k) => {
                    let stair = (k / 200) % 8;
                    (if stair < 5 { stair + 1 } else { 9 - stair }) as f64
                }
            })
            .collect();
        let plan = Plan::new(&stairs, 0.005, stairs.len(), &PlanOptions::default()).unwrap();
        let settle = plan.thresholds.settle_samples;
        assert_eq!(settle, 20);
        let first_fitted = plan.fitted().iter().position(|f| *f).unwrap();
        assert_eq!(first_fitted, 1800 + settle);
        // A validation file of the same staircase is scored from the same
        // sample (it was scored from the first stair on, climb and all).
        let (_, scored) = plan.validation_scored(&stairs, 0.005, None, true);
        assert_eq!(scored.iter().position(|s| *s).unwrap(), 1800 + settle);
        // A command that overshoots each stair by 1.2 % of the span on its
        // first sample turns there by more than the 1 % a turning point
        // needs; inside the settling that is no turn of the loop.
        let mut overshooting = stairs.clone();
        for n in (400..stairs.len()).step_by(200) {
            overshooting[n] += 0.06 * (stairs[n] - stairs[n - 1]).signum();
        }
        let plan = Plan::new(&overshooting, 0.005, stairs.len(), &PlanOptions::default()).unwrap();
        assert_eq!(
            plan.segments.steps,
            (200..stairs.len()).step_by(200).collect::<Vec<_>>()
        );
        assert_eq!(
            plan.fitted().iter().position(|f| *f).unwrap(),
            1800 + settle
        );
        // A measured command with noise of 0.3 % of the span: its noise turns
        // by more than 1 % of the span now and then, but not by 10σ. The
        // turning point is read at the bottom stair's lowest sample, so the
        // fit starts within that stair.
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
        let uniform = Uniform::new_inclusive(-0.015 * 3f64.sqrt(), 0.015 * 3f64.sqrt()).unwrap();
        let noisy: Vec<f64> = stairs
            .iter()
            .map(|v| v + uniform.sample(&mut rng))
            .collect();
        // Within a stair, some sample moves by more than 1 % of the 5 V span.
        assert!(
            noisy
                .windows(2)
                .any(|w| (0.05..0.5).contains(&(w[1] - w[0]).abs()))
        );
        let plan = Plan::new(&noisy, 0.005, stairs.len(), &PlanOptions::default()).unwrap();
        assert_eq!(
            plan.segments.steps,
            (200..stairs.len()).step_by(200).collect::<Vec<_>>()
        );
        let first_fitted = plan.fitted().iter().position(|f| *f).unwrap();
        assert!(
            (1800 + settle..2000).contains(&first_fitted),
            "{first_fitted}"
        );
        let (_, scored) = plan.validation_scored(&noisy, 0.005, None, true);
        assert_eq!(scored.iter().position(|s| *s).unwrap(), first_fitted);
        // A record that starts on its stairs waits for the same turn.
        let without_rest = &stairs[200..];
        let plan = Plan::new(
            without_rest,
            0.005,
            without_rest.len(),
            &PlanOptions::default(),
        )
        .unwrap();
        assert_eq!(
            plan.fitted().iter().position(|f| *f).unwrap(),
            1600 + settle
        );
        // A fit part that never turns twice keeps the rule of each step:
        // every stair after the rest, once settled.
        let plan = Plan::new(&stairs, 0.005, 1000, &PlanOptions::default()).unwrap();
        assert_eq!(plan.fitted().iter().position(|f| *f).unwrap(), 200 + settle);
    }

    /// Stairs held longer than the shortest rest are the excitation of a
    /// staircase, not rests: with holds at 3 or more levels they are fitted
    /// once settled (every one of them was left out as a rest, and nothing
    /// was left to fit). A record that waits at one level keeps its rests.
    #[test]
    fn a_staircase_held_longer_than_a_rest_is_fitted() {
        // Three triangles of 1 V stairs held 1 s each (200 samples at 200
        // Hz), 0..5 V, the 0.5 s shortest rest well inside every stair; the
        // first two fitted (the first loading, to the second turning point,
        // is the first triangle), the third scored.
        let stairs: Vec<f64> = (0..3 * 10 * 200)
            .map(|n| {
                let stair = (n / 200) % 10;
                (if stair < 5 { stair } else { 10 - stair }) as f64
            })
            .collect();
        let plan = Plan::new(&stairs, 0.005, 4000, &PlanOptions::default()).unwrap();
        assert!(plan.segments.rests.is_empty(), "{:?}", plan.segments.rests);
        assert!(
            plan.segments.stairs.len() >= 28,
            "{:?}",
            plan.segments.stairs
        );
        // Every jump is a step, and its settling (0.1 s, 20 samples) is
        // neither fitted nor scored; the rest of each stair is, once the
        // first loading (the first triangle) is over.
        let jumps: Vec<usize> = (1..stairs.len())
            .filter(|&n| stairs[n] != stairs[n - 1])
            .collect();
        assert_eq!(plan.segments.steps, jumps);
        let (fitted, scored) = (plan.fitted(), plan.scored());
        let used = |n: usize| fitted.get(n).copied().unwrap_or(false) || scored[n];
        for &jump in jumps.iter().filter(|&&j| j >= 2000) {
            let settle = plan.thresholds.settle_samples;
            assert!((jump..jump + settle).all(|n| !used(n)), "{jump}");
            assert!((jump + settle..jump + 200).all(used), "{jump}");
        }
        let fitted = fitted.iter().filter(|f| **f).count();
        let scored = scored.iter().filter(|f| **f).count();
        assert!(fitted > 1500, "{fitted} of 4000");
        assert!(scored > 1500, "{scored} of 2000");
        // A validation file of the same staircase is scored the same way
        // (its holds were left out as rests, and nothing was scored).
        let (segments, validation) = plan.validation_scored(&stairs, 0.005, None, true);
        assert!(segments.rests.is_empty() && !segments.stairs.is_empty());
        assert!(validation.iter().filter(|s| **s).count() > 3000);

        // Rests at one level (0 V) between bursts of a sine: rests still.
        let waits: Vec<f64> = (0..2000)
            .map(|n| {
                let k = n % 500;
                if k < 200 {
                    0.0
                } else {
                    5.0 * (1.0 - (std::f64::consts::TAU * (k - 200) as f64 / 100.0).cos())
                }
            })
            .collect();
        let plan = Plan::new(&waits, 0.005, 1000, &PlanOptions::default()).unwrap();
        assert!(plan.segments.stairs.is_empty());
        assert_eq!(plan.segments.rests.len(), 4, "{:?}", plan.segments.rests);
    }

    /// When nothing is left to fit, the error names what covered the fit
    /// part and suggests only what would help: rests and steps name
    /// --keep-rest-and-steps, a start that never turns names the warm-up
    /// (it once blamed a warm-up of 0 samples and suggested
    /// --keep-rest-and-steps, which then failed the same way).
    /// A staircase stands at one level per stair, a sine at as many as its
    /// span holds tolerances; only the fitted samples count.
    #[test]
    fn value_levels_count_values_and_staircases_their_holds() {
        let stairs: Vec<f64> = [0.0, 1.0, 2.0, 1.0, 0.0, 1.0]
            .iter()
            .flat_map(|level| (0..10).map(move |n| level + if n % 2 == 0 { 0.001 } else { -0.001 }))
            .collect();
        let all = vec![true; stairs.len()];
        assert_eq!(value_levels(stairs.clone(), 0.01), 3);
        let first_two: Vec<bool> = (0..stairs.len()).map(|n| n < 20).collect();
        assert_eq!(value_levels(stairs[..20].to_vec(), 0.01), 2);
        assert_eq!(held_levels(&stairs, &all, 0.01, 5), Some(3));
        assert_eq!(held_levels(&stairs, &first_two, 0.01, 5), Some(2));
        // A sine of 20 samples a cycle takes 11 values and holds none.
        let periodic: Vec<f64> = (0..400)
            .map(|n| (std::f64::consts::TAU * n as f64 / 20.0).sin())
            .collect();
        let every = vec![true; 400];
        assert!(value_levels(periodic.clone(), 0.004) <= 11);
        assert_eq!(held_levels(&periodic, &every, 0.004, 5), None);
        let sine: Vec<f64> = (0..1000).map(|n| (n as f64 * 0.01).sin()).collect();
        let levels = value_levels(sine, 0.004);
        // Far more than a staircase: 398 groups for 0.004 on a span of 2.
        assert!(levels > 300, "{levels}");
    }

    #[test]
    fn nothing_to_fit_names_its_causes() {
        let ramp: Vec<f64> = (0..400).map(|n| n as f64 * 0.01).collect();
        let e = Plan::new(&ramp, 0.005, 400, &PlanOptions::default()).unwrap_err();
        let message = e.to_string();
        assert!(message.contains("the start (400 samples"), "{message}");
        assert!(message.contains("--warm-up 0"), "{message}");
        assert!(!message.contains("--keep-rest-and-steps"), "{message}");
        let e = Plan::new(
            &ramp,
            0.005,
            400,
            &PlanOptions {
                warm_up_seconds: Some(5.0),
                ..PlanOptions::default()
            },
        )
        .unwrap_err();
        assert!(
            e.to_string().contains("the warm-up given (400 samples)"),
            "{e}"
        );
        // Triangles of 1 V stairs held 0.075 s (15 samples at 200 Hz),
        // shorter than the 0.1 s settling: every stair is a step, and all
        // settling, at 200 Hz as at 5 kHz; the error says to settle shorter.
        for rate in [200.0, 5000.0] {
            let stair = (0.075 * rate) as usize;
            let stairs: Vec<f64> = (0..40 * stair)
                .map(|n| {
                    let k = (n / stair) % 18;
                    (if k < 10 { k } else { 18 - k }) as f64
                })
                .collect();
            let e =
                Plan::new(&stairs, 1.0 / rate, stairs.len(), &PlanOptions::default()).unwrap_err();
            let message = e.to_string();
            assert!(
                message.contains("the settling (--settle) after 39 step(s)"),
                "{message}"
            );
            assert!(message.contains("a shorter --settle"), "{message}");
        }
    }
}

//! What a measured record holds besides the excitation: rest segments,
//! voltage steps, and the start of the record, and how long its fastest
//! cycle is.
//!
//! A lab record often begins with the stage at rest (the input held, often at
//! 0 V, for seconds), then the command steps onto the excitation. Neither
//! teaches a hysteresis model anything: a rest segment is one point of the
//! loop repeated thousands of times, and after a step the displacement rings
//! (structural modes), lags (amplifier) and the sensor may overshoot, none of
//! which a rate-independent hysteresis model describes. Fitted by least
//! squares they dominate: a 2 s rest at 5 kHz outweighs a 1 Hz loop ten
//! to one. So they are found here and left out of the fit (the models still
//! run through them, so that their memories are right afterwards), and the
//! report says what was left out.
//!
//! Detection uses only the input (the command, which the experimenter set)
//! and only the fit part's statistics, so it never looks at what is scored:
//! - the input's noise σ from the median absolute fourth difference
//!   (σ·√70 for white noise; a smooth signal's fourth differences are tiny);
//! - a rest is a run of at least [`SegmentOptions::min_rest_seconds`] in which
//!   the input stays within max(0.2 % of the input span, 5σ) of the run's
//!   first value. A sine of 0.1 Hz or faster stays that close to one value
//!   for at most 0.3 s at its turning points (0.2 % of its span is reached
//!   0.09 rad either side of the peak), so the 0.5 s default never takes a
//!   turning point for a rest;
//! - a step is a sample-to-sample change larger than both 5 % of the span
//!   and 2.5 times the 99th percentile of the changes outside rest segments.
//!   A sine sampled at only 20 points per cycle changes by at most 31 % of
//!   its amplitude per sample, so the 99th percentile is about that, while a
//!   step onto a sine from rest is typically its whole amplitude or more;
//!   a change of more than 5 % of the span onto an input that then holds is
//!   a step whatever the percentile ([`detect_segments`] says why);
//! - after each step, [`SegmentOptions::settle_seconds`] are not fitted
//!   (0.1 s by default: a flexure stage's modes of 100 Hz and more with
//!   damping ratios of a few per cent ring down, and amplifiers settle, in a
//!   few tens of ms; the P-885 sensor's start-up transient lasts about
//!   50 ms). The start of a record is treated as a step: the state before it
//!   is unknown, and a record usually starts with the drive switched on.
//!
//! After the start and each step, the fit also waits for the end of the
//! first loading ([`first_loading_end`]): the input's second turning point,
//! from which on the state no longer depends on what was assumed before.
//!
//! The fastest cycle is estimated from the input's reversals (turning points
//! of at least 1 % of the span): twice the 10th percentile of the time
//! between consecutive reversals. Smoothing windows and the search's
//! decimation are set in fractions of it, so that they mean the same at
//! 200 Hz and at 5 kHz.

use std::ops::Range;

use serde::Serialize;

/// Settings of [`detect_segments`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SegmentOptions {
    /// Seconds after each step (and after the start of a record) that are
    /// not fitted.
    pub settle_seconds: f64,
    /// Shortest held input that counts as a rest [s].
    pub min_rest_seconds: f64,
}

impl Default for SegmentOptions {
    fn default() -> Self {
        SegmentOptions {
            settle_seconds: 0.1,
            min_rest_seconds: 0.5,
        }
    }
}

/// Fraction of the input span within which a held input counts as at rest.
const REST_SPAN_FRACTION: f64 = 0.002;
/// Multiple of the input noise within which a held input counts as at rest.
const REST_NOISE_MULTIPLE: f64 = 5.0;
/// A step changes the input by more than this fraction of its span ...
const STEP_SPAN_FRACTION: f64 = 0.05;
/// ... and by more than this multiple of the 99th percentile of the changes.
const STEP_PERCENTILE_MULTIPLE: f64 = 2.5;
/// Smallest turning point counted as a reversal, as a fraction of the span.
pub(crate) const REVERSAL_SPAN_FRACTION: f64 = 0.01;

/// The thresholds the fit part gives, applied to any record of the same
/// experiment (the rest of the record, a validation file).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SegmentThresholds {
    /// Input span of the fit part [input units].
    pub span: f64,
    /// Largest deviation from a held value that is still rest.
    pub rest_tolerance: f64,
    /// Smallest sample-to-sample change that is a step.
    pub step: f64,
    /// Shortest rest [samples].
    pub min_rest_samples: usize,
    /// Samples not fitted after a step [samples].
    pub settle_samples: usize,
}

impl SegmentThresholds {
    /// The same thresholds for a record sampled every `to` s instead of every
    /// `from` s: the durations (shortest rest, settling) stay the same in
    /// seconds. The step threshold, a change from one sample to the next, is
    /// kept: a record at the fit record's rate or faster changes less per
    /// sample, so its steps are found as the fit record's are.
    pub fn resampled(self, from: f64, to: f64) -> SegmentThresholds {
        let samples = |n: usize| (n as f64 * from / to).round() as usize;
        SegmentThresholds {
            min_rest_samples: samples(self.min_rest_samples).max(2),
            settle_samples: samples(self.settle_samples),
            ..self
        }
    }
}

/// What [`detect_segments`] found in a record.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Segments {
    /// Held input, each a range of samples.
    pub rests: Vec<Range<usize>>,
    /// Samples at which the input has just stepped (u[n] − u[n−1] is a step).
    pub steps: Vec<usize>,
    /// Held input that is the excitation, not a pause in it: the stairs of a
    /// staircase ([`Segments::staircase`]), fitted and scored like any other
    /// sample once settled.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub stairs: Vec<Range<usize>>,
}

/// Held levels, at least this many, make the holds a staircase: a record
/// that rests waits at one level
/// or two (its rest, the middle of its range), a staircase climbs through
/// many.
pub const STAIRCASE_LEVELS: usize = 3;
/// ... at least this share of the span apart, or [`SegmentThresholds::least_move`]
/// when that is less (2 % of the span on a clean command: a staircase of 20
/// levels is 5 % a stair).
const STAIRCASE_LEVEL_SHARE: f64 = 0.05;

impl Segments {
    /// Reads the holds of a quasi-static staircase as its excitation: when
    /// the rests of `u[..fit_end]` stand at [`STAIRCASE_LEVELS`] or more
    /// levels far enough apart ([`STAIRCASE_LEVEL_SHARE`]), every rest
    /// becomes a stair, kept in the fit once settled: the start of each
    /// stair is a step, unless a step was found since the stair before
    /// (a command that overshoots or lags into its level holds from a few
    /// samples after the step) or the stair stands where the one before
    /// stood (a hold that noise split in two). Left out as rests, the stairs of a
    /// staircase held longer than the shortest rest left nothing to fit;
    /// and a jump onto a stair that is not a step (under 5 % of the span)
    /// still moves the stage, whose settling is left out.
    pub fn staircase(
        mut self,
        u: &[f64],
        fit_end: usize,
        thresholds: &SegmentThresholds,
    ) -> Segments {
        let mean = |r: &Range<usize>| u[r.start..r.end].iter().sum::<f64>() / r.len() as f64;
        let mut levels: Vec<f64> = self
            .rests
            .iter()
            .filter(|r| r.start < fit_end)
            .map(mean)
            .collect();
        levels.sort_by(f64::total_cmp);
        let apart = thresholds
            .least_move()
            .min(STAIRCASE_LEVEL_SHARE * thresholds.span);
        let distinct = levels
            .windows(2)
            .filter(|pair| pair[1] - pair[0] >= apart)
            .count()
            + usize::from(!levels.is_empty());
        if distinct >= STAIRCASE_LEVELS {
            self.stairs = std::mem::take(&mut self.rests);
            let mut since = 0;
            let mut previous: Option<f64> = None;
            let mut starts = Vec::new();
            for stair in &self.stairs {
                let level = mean(stair);
                // The steps are sorted: the first at or after `since`.
                let stepped = self
                    .steps
                    .get(self.steps.partition_point(|&s| s < since))
                    .is_some_and(|&s| s <= stair.start);
                // A hold that noise split in two is one stair.
                let moved = previous.is_none_or(|p| (level - p).abs() > thresholds.hold_band());
                if stair.start > 0 && !stepped && moved {
                    starts.push(stair.start);
                }
                since = stair.end;
                previous = Some(level);
            }
            self.steps.extend(starts);
            self.steps.sort_unstable();
            self.steps.dedup();
        }
        self
    }

    /// The samples to leave out of a fit: every rest, and `settle` samples
    /// from each step on (clipped to `len`), merged and sorted.
    pub fn excluded(&self, settle: usize, len: usize) -> Vec<Range<usize>> {
        let mut ranges: Vec<Range<usize>> = self
            .rests
            .iter()
            .cloned()
            .chain(self.steps.iter().map(|&s| s..s + settle))
            .map(|r| r.start.min(len)..r.end.min(len))
            .filter(|r| !r.is_empty())
            .collect();
        merge(&mut ranges);
        ranges
    }
}

/// Sorts and merges overlapping or touching ranges.
pub fn merge(ranges: &mut Vec<Range<usize>>) {
    ranges.sort_by_key(|r| (r.start, r.end));
    let mut merged: Vec<Range<usize>> = Vec::with_capacity(ranges.len());
    for r in ranges.drain(..) {
        match merged.last_mut() {
            Some(last) if r.start <= last.end => last.end = last.end.max(r.end),
            _ => merged.push(r),
        }
    }
    *ranges = merged;
}

/// Thresholds from the input `u` of the fit part (module comment). None when
/// the input never changes.
pub fn thresholds(
    u: &[f64],
    sample_period: f64,
    options: &SegmentOptions,
) -> Option<SegmentThresholds> {
    let (low, high) = u
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(*v), hi.max(*v))
        });
    let span = high - low;
    if !(span > 0.0 && span.is_finite()) {
        return None;
    }
    let noise = input_noise(u);
    let rest_tolerance = (REST_SPAN_FRACTION * span).max(REST_NOISE_MULTIPLE * noise);
    let min_rest_samples = ((options.min_rest_seconds / sample_period).round() as usize).max(2);
    let rests = find_rests(u, rest_tolerance, min_rest_samples);
    let mut changes: Vec<f64> = Vec::with_capacity(u.len());
    let mut rest = rests.iter().peekable();
    for n in 1..u.len() {
        while rest.peek().is_some_and(|r| r.end <= n) {
            rest.next();
        }
        if rest
            .peek()
            .is_some_and(|r| r.contains(&n) && r.contains(&(n - 1)))
        {
            continue;
        }
        changes.push((u[n] - u[n - 1]).abs());
    }
    let typical = percentile(&mut changes, 0.99).unwrap_or(0.0);
    Some(SegmentThresholds {
        span,
        rest_tolerance,
        step: (STEP_SPAN_FRACTION * span).max(STEP_PERCENTILE_MULTIPLE * typical),
        min_rest_samples,
        settle_samples: (options.settle_seconds / sample_period).round() as usize,
    })
}

/// Fewest samples over which an input must hold after a change for the
/// change to be a step onto a hold (with `--settle 0` too).
const MIN_HOLD_SAMPLES: usize = 6;

/// A move onto a hold is a step when it is this many rest tolerances or
/// more (2 % of the span, or 50σ of a noisy command). A sampled sine holds
/// at its peaks too, but no sine can both move that far within the first
/// quarter of a window and then stay within twice the rest tolerance over
/// the other three quarters: holding there keeps it within ±0.126 rad of
/// its peak over three quarters of the window (at the 0.2 % tolerance of a
/// clean command), so it turns by at most 0.084 rad over the first quarter,
/// and moves there by at most 1.1 % of its span.
const HOLD_MOVE_TOLERANCES: f64 = 10.0;

/// An input within this many rest tolerances of a level holds there (0.4 %
/// of the span on a clean command, 10σ of a noisy one's noise): a stair's
/// samples, a settling's last three quarters, and a turn of the loop must
/// move further.
const HOLD_BAND_TOLERANCES: f64 = 2.0;

impl SegmentThresholds {
    /// How far an input may stray from a level and still hold there
    /// ([`HOLD_BAND_TOLERANCES`]).
    pub fn hold_band(&self) -> f64 {
        HOLD_BAND_TOLERANCES * self.rest_tolerance
    }

    /// The smallest move onto a hold that is a step, and the smallest gap
    /// between a staircase's levels ([`HOLD_MOVE_TOLERANCES`]).
    pub fn least_move(&self) -> f64 {
        HOLD_MOVE_TOLERANCES * self.rest_tolerance
    }

    /// The smallest turn that counts as a turning point of the loop: 1 % of
    /// the span, or the hold band on a noisy command (10σ), so that its
    /// noise turns nothing.
    pub fn least_turn(&self) -> f64 {
        (REVERSAL_SPAN_FRACTION * self.span).max(self.hold_band())
    }
}

/// Rests and steps of the input `u` under `thresholds`.
///
/// A move of [`SegmentThresholds::least_move`] or more onto an input that
/// then holds is a step too, whatever the percentile: a staircase of 0.2 s
/// stairs at 200 Hz jumps on 2.5 % of its samples, so the 99th percentile
/// of its changes is a jump and none of them passed (at 5 kHz, on 0.1 % of
/// them, all did). The move starts at a sample that moves by more than
/// twice the rest tolerance and is measured from the sample before it to
/// the level held, so a measured command that lags into its level over a
/// few samples steps once, at its first moving sample. The hold is tested
/// over the settling after it ([`settles_onto_hold`]), cut short by the
/// record's end and by the next jump (a change of `least_move` or more,
/// twice the change before it or more: a lag's changes only shrink), so a
/// stair shorter than the settling is still a stair, and all of it
/// settling.
pub fn detect_segments(u: &[f64], thresholds: &SegmentThresholds) -> Segments {
    let rests = find_rests(u, thresholds.rest_tolerance, thresholds.min_rest_samples);
    let moving = thresholds.hold_band();
    let least_move = thresholds.least_move();
    let settling = thresholds.settle_samples.max(MIN_HOLD_SAMPLES);
    let change = |m: usize| (u[m] - u[m - 1]).abs();
    // The first sample of the hold that a move starting at `n` settles onto,
    // if it does.
    let onto_hold = |n: usize| -> Option<usize> {
        let mut end = (n + settling).min(u.len());
        if let Some(next) =
            (n + 1..end).find(|&m| change(m) > least_move && change(m) > 2.0 * change(m - 1))
        {
            end = next;
        }
        let window = &u[n..end];
        if window.len() < MIN_HOLD_SAMPLES || !settles_onto_hold(window, thresholds.hold_band()) {
            return None;
        }
        let level = window[window.len() - 1];
        let held_from = window
            .iter()
            .rposition(|v| (v - level).abs() > moving)
            .map_or(0, |last_off| last_off + 1);
        ((level - u[n - 1]).abs() >= least_move).then_some(n + held_from)
    };
    let mut steps = Vec::new();
    let mut n = 1;
    while n < u.len() {
        if change(n) > moving
            && let Some(held) = onto_hold(n)
        {
            // The change into the first held sample is the move's too.
            steps.push(n);
            n = held.max(n) + 1;
            continue;
        }
        if change(n) > thresholds.step {
            steps.push(n);
        }
        n += 1;
    }
    Segments {
        rests,
        steps,
        stairs: Vec::new(),
    }
}

/// Whether an input over `window` (the settling after a change) settles
/// onto a hold: its last three quarters within `band`
/// ([`SegmentThresholds::hold_band`]) of its last value. The first quarter may still move: a
/// measured command lags into its level (over the default 0.1 s settling,
/// to within 0.4 % of the span in 25 ms: a lag of up to about 7 ms on a
/// jump of a tenth of the span) and carries noise; a sine moves on by far
/// more.
pub fn settles_onto_hold(window: &[f64], band: f64) -> bool {
    let Some(last) = window.last() else {
        return false;
    };
    window[window.len() / 4..]
        .iter()
        .all(|u| (u - last).abs() <= band)
}

/// Maximal runs of at least `min_samples` within `tolerance` of their first
/// value.
fn find_rests(u: &[f64], tolerance: f64, min_samples: usize) -> Vec<Range<usize>> {
    let mut rests = Vec::new();
    let mut start = 0;
    for n in 1..=u.len() {
        if n == u.len() || (u[n] - u[start]).abs() > tolerance {
            if n - start >= min_samples {
                rests.push(start..n);
            }
            start = n;
        }
    }
    rests
}

/// σ of white noise on `u` from the median absolute fourth difference
/// (1.4826·MAD is σ for a normal distribution; the fourth difference of
/// white noise has variance 70σ², while a sine of ω rad per sample shrinks
/// by ω⁴: 0.01 at 20 samples per cycle).
pub fn input_noise(u: &[f64]) -> f64 {
    let mut fourth: Vec<f64> = u
        .windows(5)
        .map(|w| (w[4] - 4.0 * w[3] + 6.0 * w[2] - 4.0 * w[1] + w[0]).abs())
        .collect();
    percentile(&mut fourth, 0.5).map_or(0.0, |m| 1.4826 * m / 70f64.sqrt())
}

/// The `q`-quantile (0..1, nearest rank) of `values`, reordering them.
pub fn percentile(values: &mut [f64], q: f64) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let rank = ((q * (values.len() - 1) as f64).round() as usize).min(values.len() - 1);
    let (_, value, _) = values.select_nth_unstable_by(rank, f64::total_cmp);
    Some(*value)
}

/// Turning points of `u` over the samples where `flags` is set: indices of
/// the extremes after which the input moved back by more than `threshold`.
pub fn reversals(u: &[f64], flags: &[bool], threshold: f64) -> Vec<usize> {
    let mut reversals: Vec<usize> = Vec::new();
    // Direction of the current run (0: not known yet) and its extreme.
    let mut direction = 0.0;
    let mut extreme: Option<(usize, f64)> = None;
    for (n, (&v, _)) in u.iter().zip(flags).enumerate().filter(|(_, (_, f))| **f) {
        let Some((at, value)) = extreme else {
            extreme = Some((n, v));
            continue;
        };
        let moved = v - value;
        if direction == 0.0 {
            if moved.abs() > threshold {
                direction = moved.signum();
                extreme = Some((n, v));
            }
        } else if moved * direction > 0.0 {
            extreme = Some((n, v));
        } else if -moved * direction > threshold {
            reversals.push(at);
            direction = -direction;
            extreme = Some((n, v));
        }
    }
    reversals
}

/// The travels between consecutive turning points of `u` over the samples
/// where `flags` is set (turning points as [`reversals`] finds them, at 1 %
/// of `span`): the sizes of the loops and half-loops the samples run.
pub fn loop_travels(u: &[f64], flags: &[bool], span: f64) -> Vec<f64> {
    reversals(u, flags, REVERSAL_SPAN_FRACTION * span)
        .windows(2)
        .map(|w| (u[w[1]] - u[w[0]]).abs())
        .collect()
}

/// When the scored samples run smaller loops than the fitted ones: the
/// median travel between their turning points, and the fitted samples' 10th
/// percentile of it, if the first is under half the second (a model then
/// answers loops of a size it was not fitted on: small loops are where
/// hysteresis models differ most, P-I's first backlash threshold, Bouc-Wen's
/// minor loops). None with fewer than two travels in either part.
pub fn smaller_loops(u: &[f64], fitted: &[bool], scored: &[bool]) -> Option<(f64, f64)> {
    let (low, high) = u
        .iter()
        .zip(fitted)
        .filter(|(_, f)| **f)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (v, _)| {
            (lo.min(*v), hi.max(*v))
        });
    let span = high - low;
    if span.is_nan() || span <= 0.0 {
        return None;
    }
    let mut fitted_travels = loop_travels(u, fitted, span);
    let mut scored_travels = loop_travels(u, scored, span);
    if fitted_travels.len() < 2 || scored_travels.len() < 2 {
        return None;
    }
    let scored_median = percentile(&mut scored_travels, 0.5)?;
    let fitted_small = percentile(&mut fitted_travels, 0.1)?;
    (scored_median < 0.5 * fitted_small).then_some((scored_median, fitted_small))
}

/// The end of the first loading of `u` from sample `from` (before `to`):
/// the second turning point of at least `least_turn`
/// ([`SegmentThresholds::least_turn`]). Until the input has
/// turned at both ends of a cycle, a hysteresis model's state still depends
/// on the state assumed before `from` (the wiping-out property of Preisach
/// and Prandtl-Ishlinskii models: each turning point erases the memory of
/// smaller earlier ones), and operators that only move on that first
/// loading are fitted to a transient. None with fewer than two turning
/// points. Samples in `skipped` (the settling after steps, where a
/// command's overshoot is no turn of the loop) are not looked at.
pub fn first_loading_end(
    u: &[f64],
    from: usize,
    to: usize,
    least_turn: f64,
    skipped: &[Range<usize>],
) -> Option<usize> {
    let to = to.min(u.len());
    if from >= to {
        return None;
    }
    let mut flags = vec![true; to - from];
    for range in skipped {
        for n in range.start.max(from)..range.end.min(to) {
            flags[n - from] = false;
        }
    }
    reversals(&u[from..to], &flags, least_turn)
        .get(1)
        .map(|r| from + r)
}

/// Length of the fastest cycle of the input over the samples where `flags`
/// is set [samples] (module comment); None with fewer than three reversals.
pub fn fastest_cycle(u: &[f64], flags: &[bool], span: f64) -> Option<f64> {
    let reversals = reversals(u, flags, REVERSAL_SPAN_FRACTION * span);
    if reversals.len() < 3 {
        return None;
    }
    let mut halves: Vec<f64> = reversals.windows(2).map(|w| (w[1] - w[0]) as f64).collect();
    percentile(&mut halves, 0.1).map(|half| 2.0 * half)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Uniform};
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// 1 s of rest at 0, then a step onto a 2 Hz sine about 5 (amplitude 4),
    /// at 200 Hz.
    fn lab_input() -> Vec<f64> {
        (0..1000)
            .map(|n| {
                if n < 200 {
                    0.0
                } else {
                    let t = (n - 200) as f64 / 200.0;
                    5.0 + 4.0 * (std::f64::consts::TAU * 2.0 * t).sin()
                }
            })
            .collect()
    }

    #[test]
    fn finds_the_rest_the_step_and_the_cycle() {
        let u = lab_input();
        let thresholds = thresholds(&u, 0.005, &SegmentOptions::default()).unwrap();
        assert_eq!(thresholds.settle_samples, 20);
        let segments = detect_segments(&u, &thresholds);
        assert_eq!(segments.rests, vec![0..200]);
        assert_eq!(segments.steps, vec![200]);
        assert_eq!(segments.excluded(20, u.len()), vec![0..220]);
        let all = vec![true; u.len()];
        let cycle = fastest_cycle(&u, &all, thresholds.span).unwrap();
        assert!((cycle - 100.0).abs() <= 2.0, "2 Hz at 200 Hz: {cycle}");
        // From the step: the sine rises to its first maximum (25 samples
        // later) and falls to its first minimum (75 samples later).
        assert_eq!(
            first_loading_end(&u, 200, u.len(), thresholds.least_turn(), &[]),
            Some(275)
        );
        assert_eq!(
            first_loading_end(&u, 200, 260, thresholds.least_turn(), &[]),
            None
        );
    }

    #[test]
    fn a_slow_sine_has_no_rest_and_no_step() {
        // 0.1 Hz, 200 Hz, 30 s: its turning points are slow but not rests.
        let u: Vec<f64> = (0..6000)
            .map(|n| 1.0 + (std::f64::consts::TAU * 0.1 * n as f64 / 200.0).sin())
            .collect();
        let thresholds = thresholds(&u, 0.005, &SegmentOptions::default()).unwrap();
        let segments = detect_segments(&u, &thresholds);
        assert!(segments.rests.is_empty(), "{:?}", segments.rests);
        assert!(segments.steps.is_empty(), "{:?}", segments.steps);
    }

    #[test]
    fn a_coarsely_sampled_fast_sine_is_not_a_train_of_steps() {
        // 10 Hz at 200 Hz: 20 samples per cycle, changes up to 31 % of the
        // amplitude per sample; the step from rest onto it is still found.
        let u: Vec<f64> = (0..400)
            .map(|n| {
                if n < 100 {
                    0.0
                } else {
                    3.0 + 2.0 * (std::f64::consts::TAU * 10.0 * (n - 100) as f64 / 200.0).sin()
                }
            })
            .collect();
        let thresholds = thresholds(&u, 0.005, &SegmentOptions::default()).unwrap();
        let segments = detect_segments(&u, &thresholds);
        assert_eq!(segments.steps, vec![100]);
        assert_eq!(segments.rests, vec![0..100]);
    }

    /// A staircase of 0.2 s stairs at 200 Hz jumps on one sample in 40, so
    /// the 99th percentile of its changes is a jump and the percentile rule
    /// alone found no step (at 5 kHz it found them all); a move onto a hold
    /// is a step at any rate: each stair steps once, at its first moving
    /// sample, also when a noisy measured command lags into its level (in
    /// two jumps, or through a first-order lag: 6 ms at 200 Hz, 2 ms at
    /// 5 kHz, where no change is 5 % of the span), when the record's end
    /// cuts the last stair short, and when the stairs are shorter than the
    /// settling (15 and 10 samples at 200 Hz, 375 and 100 at 5 kHz; with
    /// fewer than about 10 samples a stair, the command's noise, read from
    /// its fourth differences, is read from the jumps), or a twentieth of
    /// the span high.
    #[test]
    fn every_stair_of_a_staircase_is_a_step_at_any_rate() {
        #[derive(Clone, Copy, Debug)]
        enum Command {
            Exact,
            TwoJumps,
            Lagging(f64),
        }
        let cases: [(f64, f64, f64, usize, Command); 13] = [
            (200.0, 0.2, 20.0, 10, Command::Exact),
            (5000.0, 0.2, 20.0, 10, Command::Exact),
            (200.0, 0.2, 20.0, 10, Command::TwoJumps),
            (5000.0, 0.2, 20.0, 10, Command::TwoJumps),
            (200.0, 0.2, 20.0, 10, Command::Lagging(0.006)),
            (5000.0, 0.2, 20.0, 10, Command::Lagging(0.002)),
            (200.0, 0.2, 19.95, 10, Command::Exact),
            (200.0, 0.075, 20.0, 10, Command::Exact),
            (5000.0, 0.075, 20.0, 10, Command::Exact),
            (200.0, 0.05, 40.0, 10, Command::Exact),
            (5000.0, 0.02, 40.0, 10, Command::Exact),
            (200.0, 0.2, 60.0, 21, Command::Exact),
            (5000.0, 0.2, 60.0, 21, Command::Exact),
        ];
        for (rate, stair_seconds, stairs, levels, command) in cases {
            let stair = (stair_seconds * rate).round() as usize;
            let samples = (stairs * stair as f64) as usize;
            // Triangles of 1 V stairs, 0..levels-1..1 V.
            let top = levels - 1;
            let levels: Vec<f64> = (0..samples)
                .map(|n| {
                    let k = (n / stair) % (2 * top);
                    (if k <= top { k } else { 2 * top - k }) as f64
                })
                .collect();
            let mut u = levels.clone();
            match command {
                Command::Exact => {}
                Command::TwoJumps => {
                    for n in (stair..samples).step_by(stair) {
                        u[n] = (levels[n - 1] + levels[n]) / 2.0;
                    }
                }
                Command::Lagging(seconds) => {
                    let kept = (-1.0 / (seconds * rate)).exp();
                    for n in 1..samples {
                        u[n] = kept * u[n - 1] + (1.0 - kept) * levels[n];
                    }
                }
            }
            for (n, v) in u.iter_mut().enumerate() {
                *v += 1e-4 * ((n * 7919) % 13) as f64;
            }
            let thresholds = thresholds(&u, 1.0 / rate, &SegmentOptions::default()).unwrap();
            let segments = detect_segments(&u, &thresholds);
            let stair_starts: Vec<usize> = (stair..samples).step_by(stair).collect();
            assert_eq!(
                segments.steps, stair_starts,
                "{rate} Hz, {stair_seconds} s stairs, {command:?}"
            );
        }
        // A sine holds at its peaks for a while, after moving towards them
        // by more than 5 % of its span, but moves only a little of that in
        // any one sample; a coarsely sampled one (16.3 Hz at 200 Hz: 12
        // samples a cycle, up to 40 % of its span a sample) holds nowhere.
        // No step in any, with the default settling, none or 0.5 s, and none
        // on a command with noise of 0.5 % of its span (the tolerances grow
        // with it).
        // Uniform on ±√3·σ, σ = 0.01 (0.5 % of the span 2).
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(12345);
        let uniform = Uniform::new_inclusive(-0.01 * 3f64.sqrt(), 0.01 * 3f64.sqrt()).unwrap();
        let mut noise = || uniform.sample(&mut rng);
        for (frequency, rate, noisy) in [
            (0.2, 200.0, false),
            (1.0, 200.0, false),
            (2.67, 200.0, false),
            (16.3, 200.0, false),
            (1.0, 5000.0, false),
            (5.0, 200.0, true),
            (8.0, 200.0, true),
            (1.0, 5000.0, true),
        ] {
            let sine: Vec<f64> = (0..(10.0 * rate) as usize)
                .map(|n| {
                    (std::f64::consts::TAU * frequency * n as f64 / rate).sin()
                        + if noisy { noise() } else { 0.0 }
                })
                .collect();
            for settle_seconds in [0.1, 0.0, 0.5] {
                let options = SegmentOptions {
                    settle_seconds,
                    ..SegmentOptions::default()
                };
                let thresholds = thresholds(&sine, 1.0 / rate, &options).unwrap();
                assert_eq!(
                    detect_segments(&sine, &thresholds).steps,
                    Vec::<usize>::new(),
                    "{frequency} Hz at {rate} Hz, settling {settle_seconds} s, noisy {noisy}"
                );
            }
        }
    }

    #[test]
    fn noise_on_a_measured_input_does_not_break_a_rest() {
        let u: Vec<f64> = lab_input()
            .iter()
            .enumerate()
            .map(|(n, v)| v + 0.004 * ((n as f64 * 12.9898).sin() * 43758.5453).fract())
            .collect();
        let thresholds = thresholds(&u, 0.005, &SegmentOptions::default()).unwrap();
        let segments = detect_segments(&u, &thresholds);
        assert_eq!(segments.rests.len(), 1);
        assert!(segments.rests[0].start == 0 && segments.rests[0].end >= 199);
        assert_eq!(segments.steps, vec![200]);
    }

    #[test]
    fn merges_ranges() {
        let mut ranges = vec![5..9, 0..3, 2..4, 9..10];
        merge(&mut ranges);
        assert_eq!(ranges, vec![0..4, 5..10]);
    }

    #[test]
    fn a_constant_input_has_no_thresholds() {
        assert!(thresholds(&[1.0; 50], 0.01, &SegmentOptions::default()).is_none());
    }

    /// Sines of `amplitude` about 5 V, `cycles` of 100 samples each.
    fn sine(amplitude: f64, cycles: usize) -> Vec<f64> {
        (0..100 * cycles)
            .map(|n| 5.0 + amplitude * (2.0 * std::f64::consts::PI * n as f64 / 100.0).sin())
            .collect()
    }

    #[test]
    fn scored_loops_smaller_than_any_fitted_are_found() {
        // Fit part: 4 cycles of amplitude 4; scored part: 4 of amplitude 1.
        let u = [sine(4.0, 4), sine(1.0, 4)].concat();
        let fitted: Vec<bool> = (0..u.len()).map(|n| n < 400).collect();
        let scored: Vec<bool> = fitted.iter().map(|f| !f).collect();
        let (scored_median, fitted_small) = smaller_loops(&u, &fitted, &scored).unwrap();
        assert!((scored_median - 2.0).abs() < 0.01, "{scored_median}");
        assert!((fitted_small - 8.0).abs() < 0.01, "{fitted_small}");
        // Loops of the fitted size, or half of it, are no news.
        for amplitude in [4.0, 2.5] {
            let u = [sine(4.0, 4), sine(amplitude, 4)].concat();
            assert_eq!(smaller_loops(&u, &fitted, &scored), None, "{amplitude}");
        }
        // Too few turning points to tell.
        let short: Vec<bool> = (0..u.len()).map(|n| n >= 760).collect();
        assert_eq!(smaller_loops(&u, &fitted, &short), None);
    }
}

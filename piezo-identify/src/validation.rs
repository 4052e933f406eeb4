//! Preparing measured records and expressing a model's voltage error in terms
//! that compare across stages.
//!
//! Offset. The models' zero memories (eq. 1) and dead-zone thresholds c·[0, 1,
//! …] (eq. 5) measure displacement from the de-energized position, so a sensor
//! offset must be removed. One offset is taken from the identification record,
//! [`displacement_offset`]: its smallest displacement over the scored samples
//! (after the warm-up), which on a record that visits 0 V is the de-energized
//! position. The same offset is subtracted from every record the fitted model
//! is evaluated on, so the validation sees the sensor as the fit did.
//!
//! Percentages. For a voltage error e [V]:
//! - % of input span: 100·e/(u_max − u_min), with the span of the
//!   identification record's input;
//! - the equivalent displacement error is e·g with the mean gain
//!   g = stroke/input span [µm/V], stroke = y_max − y_min of the
//!   identification record's displacement: the displacement that an error e
//!   in the command moves a stage of that mean slope;
//! - as % of stroke, 100·e·g/stroke, which equals the % of input span by
//!   construction (both are the error over the same span, once in volts and
//!   once in micrometres).
//!
//! All spans are taken over the scored samples of the identification record,
//! so both files are measured against the same yardstick.

use serde::Serialize;

use crate::fit::FitQuality;
use crate::segments::settles_onto_hold;

/// The smallest displacement from sample `scored_from` on (module comment).
pub fn displacement_offset(y: &[f64], scored_from: usize) -> f64 {
    y.iter()
        .skip(scored_from)
        .copied()
        .fold(f64::INFINITY, f64::min)
}

/// Subtracts `offset` from every sample.
pub fn shifted(y: &[f64], offset: f64) -> Vec<f64> {
    y.iter().map(|v| v - offset).collect()
}

/// Centred moving average over 2·`half_width` + 1 samples (shorter at the
/// ends), zero phase. The inverse model is driven by a smooth reference in
/// use; a measured displacement carries sensor noise that enters the fit as
/// noise in the regressors (errors in variables) and, through the backward
/// difference, in the rates. At 200 Hz a 5-sample average (half width 2)
/// passes 1 Hz with a gain of 0.999 and has its first zero at 40 Hz.
pub fn centred_moving_average(y: &[f64], half_width: usize) -> Vec<f64> {
    if half_width == 0 {
        return y.to_vec();
    }
    // Prefix sums: O(N) for any width (windows of hundreds of samples at
    // 5 kHz); the sums of a record of 10⁵ samples of 10² µm lose 10⁻⁹ µm.
    let mut prefix = Vec::with_capacity(y.len() + 1);
    prefix.push(0.0);
    let mut sum = 0.0;
    for v in y {
        sum += v;
        prefix.push(sum);
    }
    (0..y.len())
        .map(|n| {
            let (low, high) = (
                n.saturating_sub(half_width),
                (n + half_width + 1).min(y.len()),
            );
            (prefix[high] - prefix[low]) / (high - low) as f64
        })
        .collect()
}

/// [`centred_moving_average`] of each stretch between voltage steps
/// (`steps`: the first sample after each, sorted): a window never averages
/// across a step, where the displacement jumps; at the data's first and last
/// samples it shrinks on both sides and stays centred.
pub fn smoothed_between_steps(y: &[f64], half_width: usize, steps: &[usize]) -> Vec<f64> {
    if half_width == 0 {
        return y.to_vec();
    }
    let mut smoothed = Vec::with_capacity(y.len());
    let mut start = 0;
    for &step in steps.iter().filter(|&&s| s > 0 && s < y.len()) {
        smoothed.extend(centred_moving_average(&y[start..step], half_width));
        start = step;
    }
    smoothed.extend(centred_moving_average(&y[start..], half_width));
    // At the two ends of the data (not at a step, where the input holds
    // after the settling) the signal moves on, and a window cut on one side
    // lags it: the window shrinks on both sides there instead, down to the
    // sample itself, so the average stays centred.
    let first_step = steps.iter().copied().find(|&s| s > 0).unwrap_or(y.len());
    let last_step = steps
        .iter()
        .copied()
        .rev()
        .find(|&s| s < y.len())
        .unwrap_or(0);
    let centred_at = |n: usize, low: usize, high: usize| {
        let reach = half_width.min(n - low).min(high - 1 - n);
        y[n - reach..=n + reach].iter().sum::<f64>() / (2 * reach + 1) as f64
    };
    let head = half_width.min(first_step);
    for (n, value) in smoothed[..head].iter_mut().enumerate() {
        *value = centred_at(n, 0, first_step);
    }
    let tail = y.len().saturating_sub(half_width).max(last_step);
    for (n, value) in smoothed.iter_mut().enumerate().skip(tail) {
        *value = centred_at(n, last_step, y.len());
    }
    smoothed
}

/// A record's voltage steps and the settling after each.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Steps<'a> {
    /// The first sample after each step, sorted.
    pub starts: &'a [usize],
    /// Samples of settling after each step.
    pub settle: usize,
    /// The record's input, and how far it may stray from a level and still
    /// hold there (`SegmentThresholds::hold_band`): only the settling of a
    /// step onto a held input is held ([`held_over_settling`]).
    pub input: &'a [f64],
    pub hold_band: f64,
}

/// The displacement with the settling of each step onto a held input held
/// at its settled value: from the step's first sample to the end of its
/// settling (cut short by the next step and by the record's end) the
/// displacement is its mean over as long again after the settling, for as
/// long as the input stays at the level it settled to (cut short by the
/// next step, the record's end and the input leaving that level: a move
/// too small to be a step is no part of the stair); the last sample of the
/// settling when nothing of the stair is left after it. A step is onto a
/// held input when the window's input settles onto a hold
/// ([`settles_onto_hold`]: its last three quarters within `hold_band` of
/// its last value); a step onto an input that moves on (onto a sine) is
/// left as measured: the actuator may turn there, and its turns are the
/// model's.
///
/// The mean, not one sample: one sample would carry its sensor noise into
/// every operator the settling turns (a 3σ sample is a level 0.06 µm off on
/// the lab-like records' 0.02 µm noise).
///
/// A step moves the actuator's voltage once, one way, and its hysteresis
/// with it; the stage's structural modes meanwhile ring in the measured
/// displacement (FlexureStage's 790 Hz mode swings past the new position
/// and back several times at 5 kHz). An inverse hysteresis model driven by
/// that ringing turns its play operators at reversals the actuator never
/// made, and leaves them in a state its fit must then explain: on a 5 kHz
/// staircase of 0.2 s stairs the ringing made the (c, w_s) search's
/// objective a field of local minima, each seed ending in another. The
/// settling is neither fitted nor scored; only the models' state after it
/// depends on what they are driven with there.
pub fn held_over_settling(y: &[f64], steps: Steps) -> Vec<f64> {
    let mut held = y.to_vec();
    if y.is_empty() || steps.settle == 0 {
        return held;
    }
    let starts: Vec<usize> = steps
        .starts
        .iter()
        .copied()
        .filter(|&s| s < y.len())
        .collect();
    for (k, &start) in starts.iter().enumerate() {
        let next = starts.get(k + 1).copied().unwrap_or(y.len());
        let end = (start + steps.settle).min(next);
        let window = &steps.input[start.min(steps.input.len())..end.min(steps.input.len())];
        if !settles_onto_hold(window, steps.hold_band) {
            continue;
        }
        let level = window[window.len() - 1];
        let stair_end = (end + steps.settle).min(next);
        let held_to = (end..stair_end)
            .find(|&n| {
                steps
                    .input
                    .get(n)
                    .is_none_or(|u| (u - level).abs() > steps.hold_band)
            })
            .unwrap_or(stair_end);
        let settled = if held_to > end {
            y[end..held_to].iter().sum::<f64>() / (held_to - end) as f64
        } else {
            y[end - 1]
        };
        held[start..end].fill(settled);
    }
    held
}

/// What an inverse model is driven with: the displacement held over each
/// step's settling ([`held_over_settling`]), then smoothed between steps
/// ([`smoothed_between_steps`]).
pub fn inverse_model_input(y: &[f64], half_width: usize, steps: Steps) -> Vec<f64> {
    smoothed_between_steps(&held_over_settling(y, steps), half_width, steps.starts)
}

/// The spans that turn voltage errors into relative figures.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ScaleReference {
    /// u_max − u_min of the identification input [V].
    pub input_span: f64,
    /// y_max − y_min of the identification displacement [µm].
    pub stroke: f64,
}

impl ScaleReference {
    /// The spans of a record from sample `scored_from` on.
    pub fn of(u: &[f64], y: &[f64], scored_from: usize) -> ScaleReference {
        let span = |values: &[f64]| {
            let (lo, hi) = values
                .iter()
                .skip(scored_from)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                    (lo.min(*v), hi.max(*v))
                });
            hi - lo
        };
        ScaleReference {
            input_span: span(u),
            stroke: span(y),
        }
    }

    /// g = stroke / input span [µm/V].
    pub fn mean_gain(&self) -> f64 {
        self.stroke / self.input_span
    }
}

/// A model's voltage error on a record in volts, relative, and as the
/// equivalent displacement (module comment).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ErrorReport {
    pub samples: usize,
    pub rms_volts: f64,
    pub max_volts: f64,
    /// RMS and max as % of the input span (= equivalent displacement as % of
    /// stroke).
    pub rms_percent: f64,
    pub max_percent: f64,
    /// Equivalent displacement errors e·g [µm].
    pub rms_displacement_um: f64,
    pub max_displacement_um: f64,
}

impl ErrorReport {
    pub fn new(quality: &FitQuality, reference: &ScaleReference) -> ErrorReport {
        let percent = |e: f64| 100.0 * e / reference.input_span;
        let gain = reference.mean_gain();
        ErrorReport {
            samples: quality.samples,
            rms_volts: quality.rms,
            max_volts: quality.max_abs,
            rms_percent: percent(quality.rms),
            max_percent: percent(quality.max_abs),
            rms_displacement_um: quality.rms * gain,
            max_displacement_um: quality.max_abs * gain,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moving_average_is_centred_and_shortens_at_the_ends() {
        let y = [0.0, 3.0, 6.0, 9.0, 30.0];
        assert_eq!(centred_moving_average(&y, 0), y.to_vec());
        assert_eq!(
            centred_moving_average(&y, 1),
            vec![1.5, 3.0, 6.0, 15.0, 19.5]
        );
    }

    #[test]
    fn smoothing_stops_at_steps() {
        let y = [0.0, 0.0, 0.0, 9.0, 9.0, 9.0];
        assert_eq!(smoothed_between_steps(&y, 1, &[3]), y.to_vec());
        assert_eq!(
            smoothed_between_steps(&y, 1, &[]),
            centred_moving_average(&y, 1)
        );
        assert_eq!(centred_moving_average(&y, 1)[2], 3.0);
    }

    /// At the data's two ends the window shrinks on both sides, so a ramp
    /// (a moving input) is passed unlagged to its first and last samples,
    /// where a window cut on one side lagged it by up to half its width; at
    /// a step the window stays cut on one side (the input holds there).
    #[test]
    fn smoothing_stays_centred_at_the_ends_of_the_data() {
        let ramp: Vec<f64> = (0..10).map(|n| n as f64).collect();
        assert_eq!(smoothed_between_steps(&ramp, 3, &[]), ramp);
        assert_eq!(centred_moving_average(&ramp, 3)[9], 7.5, "one-sided");
        let smoothed = smoothed_between_steps(&ramp, 2, &[5]);
        assert_eq!(&smoothed[..2], &ramp[..2]);
        assert_eq!(smoothed[4], 3.0, "cut on one side before the step");
        assert_eq!(smoothed[5], 6.0, "cut on one side after it");
        assert_eq!(&smoothed[8..], &ramp[8..]);
    }

    #[test]
    fn the_settling_after_a_step_onto_a_hold_is_held_at_its_settled_value() {
        // Steps at 2 (settled at 5) and 7 (cut short by the end at 9), each
        // onto a held input.
        let y = [0.0, 0.0, 9.0, 12.0, 7.0, 10.0, 10.0, 4.0, 1.0];
        let u = [0.0, 0.0, 5.0, 5.0, 5.0, 5.0, 5.0, 1.0, 1.0];
        let steps = |starts, input| Steps {
            starts,
            settle: 3,
            input,
            hold_band: 0.02,
        };
        assert_eq!(
            held_over_settling(&y, steps(&[2, 7], &u)),
            vec![0.0, 0.0, 10.0, 10.0, 10.0, 10.0, 10.0, 1.0, 1.0]
        );
        // A step before the settling ends holds the last sample before it;
        // so does the next step's settling (4..7), whose input leaves its
        // level (5) at once after it, at 7, by a move too small to be a
        // step here: nothing after the settling belongs to its stair.
        assert_eq!(
            held_over_settling(&y, steps(&[2, 4], &u)),
            vec![0.0, 0.0, 12.0, 12.0, 10.0, 10.0, 10.0, 4.0, 1.0]
        );
        // The mean runs as long as the input stays at its level: from 5 to
        // 6, where the input moves on by 0.3.
        let moving_on = [0.0, 0.0, 5.0, 5.0, 5.0, 5.0, 5.3, 5.3, 5.3];
        assert_eq!(
            held_over_settling(&y, steps(&[2], &moving_on)),
            vec![0.0, 0.0, 10.0, 10.0, 10.0, 10.0, 10.0, 4.0, 1.0]
        );
        let moving_on = [0.0, 0.0, 5.0, 5.0, 5.0, 5.0, 5.0, 5.3, 5.3];
        assert_eq!(
            held_over_settling(
                &[0.0, 0.0, 9.0, 12.0, 7.0, 9.0, 11.0, 4.0, 1.0],
                steps(&[2], &moving_on)
            )[2..5],
            [10.0; 3]
        );
        // The settled level is a mean, not the noise of one sample: a level
        // of 10 read with ±0.5 of noise is held at 10, whatever sample
        // follows the settling.
        let noisy = [
            0.0, 0.0, 15.0, 15.0, 15.0, 10.5, 9.5, 10.0, 10.5, 9.5, 10.0, 10.5,
        ];
        let held_input = [0.0, 0.0, 5.0, 5.0, 5.0, 5.0, 5.0, 5.0, 5.0, 5.0, 5.0, 5.0];
        let held = held_over_settling(&noisy, steps(&[2], &held_input));
        assert_eq!(held[2..5], [10.0; 3], "{held:?}");
        assert_eq!(held[5..], noisy[5..]);
        // A command that lags into its level is held once settled.
        let lagging = [0.0, 0.0, 3.0, 5.0, 5.0, 5.0, 5.0, 1.0, 1.0];
        assert_eq!(
            held_over_settling(
                &y,
                Steps {
                    settle: 4,
                    ..steps(&[2, 7], &lagging)
                }
            ),
            vec![0.0, 0.0, 10.0, 10.0, 10.0, 10.0, 10.0, 1.0, 1.0]
        );
        // Onto an input that moves on (a sine): as measured.
        let moving = [0.0, 0.0, 5.0, 6.0, 7.0, 6.0, 5.0, 1.0, 1.0];
        assert_eq!(
            held_over_settling(&y, steps(&[2, 7], &moving)),
            vec![0.0, 0.0, 9.0, 12.0, 7.0, 10.0, 10.0, 1.0, 1.0]
        );
        // No settling, no steps: the record as measured.
        for steps in [
            Steps {
                settle: 0,
                ..steps(&[2], &u)
            },
            Steps::default(),
        ] {
            assert_eq!(held_over_settling(&y, steps), y.to_vec());
        }
        assert_eq!(
            inverse_model_input(&y, 1, steps(&[2, 7], &u)),
            smoothed_between_steps(
                &[0.0, 0.0, 10.0, 10.0, 10.0, 10.0, 10.0, 1.0, 1.0],
                1,
                &[2, 7]
            )
        );
    }

    #[test]
    fn offset_and_percentages() {
        let y = [-123.0, -119.0, -100.0, -74.0, -110.0];
        assert_eq!(displacement_offset(&y, 1), -119.0);
        assert_eq!(shifted(&y, -119.0), vec![-4.0, 0.0, 19.0, 45.0, 9.0]);
        let u = [9.0, 0.0, 1.8, 3.6, 1.0];
        let reference = ScaleReference::of(&u, &y, 1);
        assert_eq!(reference.input_span, 3.6);
        assert_eq!(reference.stroke, 45.0);
        let quality = FitQuality {
            objective: 0.0,
            rms: 0.036,
            max_abs: 0.072,
            max_abs_sample: 2,
            samples: 4,
        };
        let report = ErrorReport::new(&quality, &reference);
        assert!((report.rms_percent - 1.0).abs() < 1e-12);
        assert!((report.max_percent - 2.0).abs() < 1e-12);
        // g = 12.5 µm/V: 0.036 V ↔ 0.45 µm = 1 % of 45 µm.
        assert!((report.rms_displacement_um - 0.45).abs() < 1e-12);
        assert!(
            (100.0 * report.max_displacement_um / reference.stroke - report.max_percent).abs()
                < 1e-12
        );
    }
}

//! Records taken the way a lab takes them, from the simulated stage.
//!
//! A measured hysteresis record is rarely a clean loop from rest: the
//! amplifier is switched on and the stack sits at 0 V for a while (a rest
//! segment), the function generator then starts and the command steps onto
//! the excitation, the displacement sensor reads with an offset and noise, and
//! the sample rate is whatever the acquisition card was set to (200 Hz for a
//! slow loop, 5 kHz for a fast one). These records are what the
//! identification's defaults must cope with; [`lab_record`] makes them with
//! the y actuator (PZT1) of [`piezo_models::FlexureStage`] (asymmetric
//! Bouc-Wen hysteresis, creep, amplifier lag and structural modes), so that a
//! test can score a fit on a part of the record it has not seen;
//! [`lab_record_on`] on the x pair too, and on a stage of the user's own
//! parameters.
//!
//! The records are taken from seed 000's stage without the return-point
//! memory (`FlexureStageParams::without_memory`, the default when they were
//! specified), its amplifier limits set here, not taken from the preset: a
//! bipolar drive needs a negative limit, and a test must not change meaning
//! when the default preset does. [`LAB_AMPLIFIER_LIMITS`] is the
//! output range of a PI E-505 (−30..130 V); the commands stay within −2..10 V
//! (−20..100 V after the gain of 10). A stage of the user's own keeps its own
//! amplifier. A command the stage clips is refused, not recorded.

use piezo_models::{FlexureStage, FlexureStageParams, ParamError, SensorNoiseParams};
use serde::{Deserialize, Serialize};

use crate::data::Record;
use crate::plant::RecordAxis;

/// Output range of the amplifier in every lab record [V] (PI E-505).
pub const LAB_AMPLIFIER_LIMITS: (f64, f64) = (-30.0, 130.0);

/// The command's range over the excitation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Drive {
    /// 0.5..9.5 V (5..95 V at the stack): a sine about 5 V.
    Unipolar,
    /// −2..8 V (−20..80 V at the stack): a sine about 3 V, below 0 V for a
    /// fifth of its swing, as a stack's bipolar drive is.
    Bipolar,
}

impl Drive {
    /// (mean, amplitude) of the command sine [V].
    pub fn command_sine(self) -> (f64, f64) {
        match self {
            Drive::Unipolar => (5.0, 4.5),
            Drive::Bipolar => (3.0, 5.0),
        }
    }
}

/// The excitation after the step.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Excitation {
    /// One sine of this frequency [Hz], starting at its mean and rising.
    Sine { frequency: f64 },
    /// A sine of this frequency [Hz] whose amplitude falls linearly from the
    /// full one to a fifth of it and rises back over `envelope_period`
    /// seconds: minor loops of every size, nested in the major one.
    SweptSine {
        frequency: f64,
        envelope_period: f64,
    },
    /// The command's range in `levels` evenly spaced stairs, climbed from
    /// the lowest to the highest and back down again and again, each held
    /// `hold` seconds: the quasi-static record a lab takes with a DC source
    /// stepped by hand or by a script (a loop of held points).
    Staircase { levels: usize, hold: f64 },
}

/// How the record is taken.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LabRecordSpec {
    /// Acquisition rate [Hz]; the command is held between samples.
    pub sample_rate: f64,
    pub drive: Drive,
    pub excitation: Excitation,
    /// Rest at 0 V before the step onto the excitation [s].
    pub rest_seconds: f64,
    /// Length of the excitation after the step [s].
    pub excitation_seconds: f64,
    /// Constant added to every displacement sample [µm] (a sensor zero that
    /// is not the stage's rest position).
    pub sensor_offset_um: f64,
    /// Standard deviation of the sensor noise [µm].
    pub noise_rms_um: f64,
    /// Seed of the sensor noise.
    pub noise_seed: u32,
}

impl LabRecordSpec {
    /// A record as the identification tests take them: 2 s of rest, sensor
    /// offset −42.7 µm, noise 0.02 µm RMS (0.15 % of the 13 µm stroke), the
    /// excitation for `excitation_seconds`.
    pub fn new(
        sample_rate: f64,
        drive: Drive,
        excitation: Excitation,
        excitation_seconds: f64,
    ) -> LabRecordSpec {
        LabRecordSpec {
            sample_rate,
            drive,
            excitation,
            rest_seconds: 2.0,
            excitation_seconds,
            sensor_offset_um: -42.7,
            noise_rms_um: 0.02,
            noise_seed: 7,
        }
    }

    /// The command [V] at time `t` after the step (t ≥ 0).
    pub fn command_after_step(&self, t: f64) -> f64 {
        let (mean, amplitude) = self.drive.command_sine();
        match self.excitation {
            Excitation::Sine { frequency } => {
                mean + amplitude * (std::f64::consts::TAU * frequency * t).sin()
            }
            Excitation::SweptSine {
                frequency,
                envelope_period,
            } => {
                // Triangle from 1 down to 0.2 and back over one envelope period.
                let phase = (t / envelope_period).fract();
                let envelope = 1.0 - 0.8 * (1.0 - (2.0 * phase - 1.0).abs());
                mean + amplitude * envelope * (std::f64::consts::TAU * frequency * t).sin()
            }
            Excitation::Staircase { levels, hold } => {
                // 2 ≤ levels ≤ the record's samples (checked by `lab_record`):
                // up 0..L−1, down L−2..1. The relative nudge keeps a sample
                // time that lands on a stair's start (t = k·hold, computed
                // as n·T) on that stair, so every stair holds as many
                // samples (at 200 Hz a 0.2 s stair was 39, 40 or 41).
                let last = levels - 1;
                let stair = (t / hold * (1.0 + 1e-12)).floor() as usize % (2 * last);
                let level = if stair <= last {
                    stair
                } else {
                    2 * last - stair
                };
                mean - amplitude + 2.0 * amplitude * level as f64 / last as f64
            }
        }
    }
}

/// The most samples a lab record may have: 100 million, 100 s at 1 MHz
/// (1.6 GB held, several GB of text), far beyond any stage record.
pub const MAX_LAB_SAMPLES: usize = 100_000_000;

/// Why a lab record could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LabRecordError {
    #[error("stage parameters: {0}")]
    Parameters(#[from] ParamError),
    #[error("{0} must be positive and finite")]
    Setting(&'static str),
    #[error(
        "a staircase of {levels} levels held {hold} s each must have 2 levels or more and climb its range within the {seconds} s of the record ({} s per climb)",
        (*levels as f64 - 1.0) * hold
    )]
    Levels {
        levels: usize,
        hold: f64,
        seconds: f64,
    },
    #[error(
        "{samples} samples asked (rate times rest and excitation), more than the {MAX_LAB_SAMPLES} a record is allowed here"
    )]
    TooLong { samples: f64 },
    #[error(
        "the amplifier clipped the command {command} V at {time} s: the record would not be the drive it claims"
    )]
    Clipped { command: f64, time: f64 },
}

/// Takes a record (module comment): input the command [V], output the y
/// sensor [µm] with offset and noise.
pub fn lab_record(spec: &LabRecordSpec) -> Result<Record, LabRecordError> {
    lab_record_on(spec, None, RecordAxis::Y)
}

/// [`lab_record`] on `axis` (y: u1 driven, s1 read; x: u2 = u3 driven, the
/// mean of s2 and s3 read, each sensor with the spec's noise) of the stage
/// `stage` (default: FlexureStage's preset with the lab's amplifier limits;
/// its own noise settings are replaced by the spec's).
pub fn lab_record_on(
    spec: &LabRecordSpec,
    stage: Option<&FlexureStageParams>,
    axis: RecordAxis,
) -> Result<Record, LabRecordError> {
    for (name, value) in [
        ("sample_rate", spec.sample_rate),
        ("excitation_seconds", spec.excitation_seconds),
    ] {
        if !(value.is_finite() && value > 0.0) {
            return Err(LabRecordError::Setting(name));
        }
    }
    if !(spec.rest_seconds.is_finite() && spec.rest_seconds >= 0.0) {
        return Err(LabRecordError::Setting("rest_seconds"));
    }
    // Two f64 per sample are held and written: a rate of 1e12 Hz asked for
    // 24 TB and aborted the process instead of saying so.
    let asked = (spec.rest_seconds + spec.excitation_seconds) * spec.sample_rate;
    if asked > MAX_LAB_SAMPLES as f64 {
        return Err(LabRecordError::TooLong { samples: asked });
    }
    if let Excitation::Staircase { levels, hold } = spec.excitation {
        if !(hold.is_finite() && hold > 0.0) {
            return Err(LabRecordError::Setting("hold"));
        }
        // One climb of the range at least: --levels 2000 at 0.2 s climbed
        // 2 % of it in 20 s.
        let climb = (levels as f64 - 1.0) * hold;
        if levels < 2 || climb > spec.excitation_seconds {
            return Err(LabRecordError::Levels {
                levels,
                hold,
                seconds: spec.excitation_seconds,
            });
        }
    }
    let mut params = match stage {
        Some(own) => own.clone(),
        None => {
            // The stage the lab records were first taken from (seed 000's
            // without the return-point memory): as with the amplifier, a
            // record must not change when the default preset does.
            let mut params = FlexureStageParams::without_memory();
            (params.amplifier.v_min, params.amplifier.v_max) = LAB_AMPLIFIER_LIMITS;
            params
        }
    };
    params.noise = SensorNoiseParams {
        enabled: spec.noise_rms_um > 0.0,
        rms_um: spec.noise_rms_um,
        seed: spec.noise_seed,
    };
    let mut stage = FlexureStage::new(params)?;
    let sample_period = 1.0 / spec.sample_rate;
    let rest = (spec.rest_seconds * spec.sample_rate).round() as usize;
    let samples = rest + (spec.excitation_seconds * spec.sample_rate).round() as usize;
    let mut input = Vec::with_capacity(samples);
    let mut output = Vec::with_capacity(samples);
    for n in 0..samples {
        let command = if n < rest {
            0.0
        } else {
            spec.command_after_step((n - rest) as f64 * sample_period)
        };
        let (commands, driven) = match axis {
            RecordAxis::Y => ([command, 0.0, 0.0], &[0][..]),
            RecordAxis::X => ([0.0, command, command], &[1, 2][..]),
        };
        let report = stage.step(commands, sample_period);
        if driven.iter().any(|&channel| report.clipped[channel]) {
            return Err(LabRecordError::Clipped {
                command,
                time: n as f64 * sample_period,
            });
        }
        // Sample n pairs the command held over [t_n, t_n + T] with the
        // displacement at the end of it (as compare::synthetic_plant_record).
        let sensors = stage.sensors();
        let displacement = match axis {
            RecordAxis::Y => sensors[0],
            RecordAxis::X => 0.5 * (sensors[1] + sensors[2]),
        };
        input.push(command);
        output.push(displacement + spec.sensor_offset_um);
    }
    Ok(Record {
        input,
        output,
        sample_period,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_rests_then_steps_onto_the_sine_with_offset_and_noise() {
        let spec = LabRecordSpec::new(
            200.0,
            Drive::Bipolar,
            Excitation::Sine { frequency: 1.0 },
            3.0,
        );
        let record = lab_record(&spec).unwrap();
        assert_eq!(record.input.len(), 1000);
        assert!(record.input[..400].iter().all(|u| *u == 0.0));
        assert_eq!(record.input[400], 3.0);
        let low = record.input.iter().copied().fold(f64::INFINITY, f64::min);
        assert!(
            (low + 2.0).abs() < 1e-3,
            "bipolar drive reaches -2 V: {low}"
        );
        // At rest the sensor reads its offset and noise.
        let rest = &record.output[100..400];
        let mean = rest.iter().sum::<f64>() / rest.len() as f64;
        let sd = (rest.iter().map(|y| (y - mean).powi(2)).sum::<f64>() / rest.len() as f64).sqrt();
        assert!((mean + 42.7).abs() < 0.01, "rest reads the offset: {mean}");
        assert!((sd - 0.02).abs() < 0.004, "noise 0.02 um RMS: {sd}");
    }

    /// The x pair driven together reads x, the mean of s2 and s3 (noise
    /// RMS over √2); a stage of the user's own keeps its own amplifier, so
    /// the XY200S's 0..150 V refuses the bipolar drive's negative commands.
    #[test]
    fn the_x_pair_and_a_stage_of_ones_own() {
        let mut spec = LabRecordSpec::new(
            200.0,
            Drive::Unipolar,
            Excitation::Sine { frequency: 1.0 },
            3.0,
        );
        let x = lab_record_on(&spec, None, RecordAxis::X).unwrap();
        let y = lab_record(&spec).unwrap();
        assert_eq!(x.input, y.input);
        let span = |r: &Record| {
            let w = &r.output[500..];
            w.iter().copied().fold(f64::MIN, f64::max) - w.iter().copied().fold(f64::MAX, f64::min)
        };
        // 9 V of command span: the x pair's stroke per volt is 12.74/10
        // against y's 12.22/10.
        let ratio = span(&x) / span(&y);
        assert!((ratio - 12.74 / 12.22).abs() < 0.03, "{ratio}");
        let rest = &x.output[100..400];
        let mean = rest.iter().sum::<f64>() / rest.len() as f64;
        let sd = (rest.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / rest.len() as f64).sqrt();
        assert!((sd - 0.02 / 2f64.sqrt()).abs() < 0.003, "{sd}");
        let xy200s = FlexureStageParams::xy200s();
        let own = lab_record_on(&spec, Some(&xy200s), RecordAxis::Y).unwrap();
        assert!(span(&own) > 8.0 * span(&y), "the XY200S's 150 um stroke");
        spec.drive = Drive::Bipolar;
        assert!(matches!(
            lab_record_on(&spec, Some(&xy200s), RecordAxis::Y),
            Err(LabRecordError::Clipped { .. })
        ));
    }

    #[test]
    fn a_staircase_climbs_the_drive_range_and_comes_back_down() {
        let spec = LabRecordSpec::new(
            100.0,
            Drive::Unipolar,
            Excitation::Staircase {
                levels: 4,
                hold: 0.5,
            },
            4.0,
        );
        let record = lab_record(&spec).unwrap();
        let rest = 200;
        // Stairs 0.5, 3.5, 6.5, 9.5 V up, 6.5, 3.5 down, 0.5 again.
        let held: Vec<f64> = (0..8).map(|k| record.input[rest + 50 * k + 25]).collect();
        let expected = [0.5, 3.5, 6.5, 9.5, 6.5, 3.5, 0.5, 3.5];
        for (got, want) in held.iter().zip(expected) {
            assert!((got - want).abs() < 1e-12, "{held:?}");
        }
        // Held within each stair.
        assert!(record.input[rest..rest + 50].iter().all(|u| *u == 0.5));
    }

    #[test]
    fn refuses_bad_settings() {
        let mut spec = LabRecordSpec::new(
            0.0,
            Drive::Unipolar,
            Excitation::Sine { frequency: 1.0 },
            1.0,
        );
        assert_eq!(
            lab_record(&spec),
            Err(LabRecordError::Setting("sample_rate"))
        );
        spec.sample_rate = 100.0;
        spec.rest_seconds = -1.0;
        assert_eq!(
            lab_record(&spec),
            Err(LabRecordError::Setting("rest_seconds"))
        );
        // Refused before anything is held (it aborted the process).
        spec.rest_seconds = 1.0;
        for levels in [1, 7, usize::MAX / 2 + 2, usize::MAX] {
            // One climb of 0.2 s stairs fits 1 s for 6 levels, not 7.
            spec.excitation = Excitation::Staircase { levels, hold: 0.2 };
            assert_eq!(
                lab_record(&spec),
                Err(LabRecordError::Levels {
                    levels,
                    hold: 0.2,
                    seconds: 1.0
                })
            );
        }
        spec.excitation = Excitation::Staircase {
            levels: 6,
            hold: 0.2,
        };
        assert!(lab_record(&spec).is_ok());
        spec.excitation = Excitation::Staircase {
            levels: 4,
            hold: f64::NAN,
        };
        assert_eq!(lab_record(&spec), Err(LabRecordError::Setting("hold")));
        spec.excitation = Excitation::Sine { frequency: 1.0 };
        spec.sample_rate = 1e12;
        assert!(matches!(
            lab_record(&spec),
            Err(LabRecordError::TooLong { .. })
        ));
    }
}

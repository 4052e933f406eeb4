//! `piezo-identify lab-record` and `xy200s-preset`: records and parameter sets
//! written from the simulated stage and the printed tables.

use std::path::{Path, PathBuf};

use clap::Args;

use super::Failure;
use super::arguments::{check_destinations, positive_seconds, seconds};
use super::report::{bouc_wen_parameters, write_json, write_result};

#[derive(Args)]
pub(crate) struct LabRecordArgs {
    /// Sample rate [Hz].
    #[arg(long, default_value_t = 5000.0)]
    pub(crate) rate: f64,
    /// Command range: unipolar 0.5..9.5 V or bipolar -2..8 V.
    #[arg(long, default_value = "unipolar", value_parser = ["unipolar", "bipolar"])]
    pub(crate) drive: String,
    /// Frequency of the sine [Hz], below half the sample rate.
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    pub(crate) frequency: f64,
    /// Sweep the sine's amplitude from 100 % to 20 % and back over this many
    /// seconds (0: a plain sine).
    #[arg(long, default_value_t = 0.0, value_parser = seconds)]
    pub(crate) sweep: f64,
    /// Instead of a sine, a staircase through the command range and back,
    /// each stair held this many seconds.
    #[arg(long, value_parser = positive_seconds, conflicts_with_all = ["sweep", "frequency"])]
    pub(crate) stairs: Option<f64>,
    /// Stairs from the lowest command to the highest (with --stairs).
    #[arg(long, default_value_t = 10, requires = "stairs")]
    pub(crate) levels: usize,
    /// Seconds at rest (0 V) before the step onto the excitation.
    #[arg(long, default_value_t = 2.0, value_parser = seconds)]
    pub(crate) rest: f64,
    /// Seconds of the sine (or staircase) after the step.
    #[arg(long, default_value_t = 8.0, value_parser = seconds)]
    pub(crate) seconds: f64,
    /// Sensor offset [um].
    #[arg(long, default_value_t = -42.7, allow_negative_numbers = true)]
    pub(crate) sensor_offset: f64,
    /// Sensor noise [um RMS].
    #[arg(long, default_value_t = 0.02, allow_negative_numbers = true)]
    pub(crate) noise: f64,
    /// Seed of the sensor noise.
    #[arg(long, default_value_t = 7)]
    pub(crate) noise_seed: u32,
    /// Axis driven and read: y (u1 driven, s1 read) or x (u2 = u3 driven, the
    /// mean of s2 and s3 read).
    #[arg(long, default_value = "y", value_parser = ["x", "y"])]
    pub(crate) axis: String,
    /// The stage: FlexureStage's parameters in their own form
    /// (piezo_models::FlexureStageParams, as piezo-models/presets/flexure_stage.json;
    /// not a set by FMI name), its amplifier as given [default: seed 000's
    /// stage without the return-point memory, piezo-models/presets/flexure_stage_no_memory.json,
    /// with the lab's -30..130 V amplifier]
    #[arg(long)]
    pub(crate) stage: Option<PathBuf>,
    /// The record file to write (comma-separated, with a header).
    #[arg(long)]
    pub(crate) out: PathBuf,
}

#[derive(Args)]
pub(crate) struct Xy200sPresetArgs {
    /// Write the stage parameters (piezo_models::FlexureStageParams) here.
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// Write the conversion of each printed model (fit RMS, scaling) here.
    #[arg(long)]
    pub(crate) report: Option<PathBuf>,
}

/// What a lab record's options must be, named by option, before the stage
/// runs: a NaN or infinite value wrote a record of NaN, a sine at or above
/// half the sample rate an aliased or constant one, and a rate or duration
/// too small a record of a few samples, or of rest alone (exit 0).
fn check_lab_record_options(args: &LabRecordArgs) -> Result<(), String> {
    use piezo_identify::data::MINIMUM_ROWS;
    if !(args.rate.is_finite() && args.rate > 0.0) {
        return Err(format!(
            "--rate {}: give a positive sample rate in Hz",
            args.rate
        ));
    }
    if args.stairs.is_none() {
        let nyquist = args.rate / 2.0;
        if !(args.frequency.is_finite() && args.frequency > 0.0 && args.frequency < nyquist) {
            return Err(format!(
                "--frequency {}: give a frequency above 0 and below half the sample rate \
                 ({nyquist} Hz); at or above it the samples alias",
                args.frequency
            ));
        }
    }
    if !args.sensor_offset.is_finite() {
        return Err(format!(
            "--sensor-offset {}: give a finite offset in um",
            args.sensor_offset
        ));
    }
    if !(args.noise.is_finite() && args.noise >= 0.0) {
        return Err(format!(
            "--noise {}: give a noise of 0 um RMS or more",
            args.noise
        ));
    }
    let excitation_samples = args.seconds * args.rate;
    if excitation_samples.is_nan() || excitation_samples < MINIMUM_ROWS as f64 {
        return Err(format!(
            "--seconds {} at --rate {} Hz makes {} samples of the excitation; a record needs \
             {MINIMUM_ROWS} or more",
            args.seconds,
            args.rate,
            excitation_samples.floor()
        ));
    }
    Ok(())
}

/// FlexureStage's parameters in their own form from `path`, checked: a
/// malformed file is named with its line and column, and a set by FMI name
/// (`dist/presets/FlexureStage.*.json`, which the FMUs take) as such.
fn read_stage_parameters(path: &Path) -> Result<piezo_models::FlexureStageParams, String> {
    let shown = path.display();
    let text = std::fs::read_to_string(path).map_err(|e| format!("--stage {shown}: {e}"))?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let params: piezo_models::FlexureStageParams = serde_json::from_str(text).map_err(|e| {
        let by_fmi_name = serde_json::from_str::<serde_json::Map<String, serde_json::Value>>(text)
            .is_ok_and(|map| {
                map.keys()
                    .any(|k| k.contains('.') || k.contains('[') || k == "L")
            });
        if by_fmi_name {
            format!(
                "--stage {shown} is a parameter set by FMI name (the form the FMUs take); \
                 lab-record runs the stage's model, which takes its parameters in their own form \
                 (piezo-models/presets/flexure_stage.json, MODEL.md section 4), as \
                 flexure-stage-parameters does"
            )
        } else {
            // serde_json ends its message with the place, which leads here.
            let place = format!(" at line {} column {}", e.line(), e.column());
            let message = e.to_string();
            let message = message.strip_suffix(&place).unwrap_or(&message);
            format!("--stage {shown}:{}:{}: {message}", e.line(), e.column())
        }
    })?;
    params
        .validate()
        .map_err(|e| format!("--stage {shown}: {e}"))?;
    Ok(params)
}

pub(crate) fn write_lab_record(args: &LabRecordArgs) -> Result<(), Failure> {
    check_destinations(&[("--out", Some(&args.out))], &[])?;
    check_lab_record_options(args).map_err(Failure::Input)?;
    let stage = match &args.stage {
        Some(path) => Some(read_stage_parameters(path).map_err(Failure::Input)?),
        None => None,
    };
    use piezo_identify::lab_records::{Drive, Excitation, LabRecordSpec, lab_record_on};
    use piezo_identify::plant::RecordAxis;
    let spec = LabRecordSpec {
        sample_rate: args.rate,
        drive: if args.drive == "bipolar" {
            Drive::Bipolar
        } else {
            Drive::Unipolar
        },
        excitation: if let Some(hold) = args.stairs {
            Excitation::Staircase {
                levels: args.levels,
                hold,
            }
        } else if args.sweep > 0.0 {
            Excitation::SweptSine {
                frequency: args.frequency,
                envelope_period: args.sweep,
            }
        } else {
            Excitation::Sine {
                frequency: args.frequency,
            }
        },
        rest_seconds: args.rest,
        excitation_seconds: args.seconds,
        sensor_offset_um: args.sensor_offset,
        noise_rms_um: args.noise,
        noise_seed: args.noise_seed,
    };
    let axis = if args.axis == "x" {
        RecordAxis::X
    } else {
        RecordAxis::Y
    };
    let record = lab_record_on(&spec, stage.as_ref(), axis).map_err(|e| e.to_string())?;
    let mut text = String::from("time_s,command_V,displacement_um\n");
    for (n, (u, y)) in record.input.iter().zip(&record.output).enumerate() {
        text.push_str(&format!("{},{u},{y}\n", n as f64 * record.sample_period));
    }
    write_result(&args.out, text.as_bytes())?;
    say!(
        "{}: {} samples at {} Hz of the {} axis of {} (columns time_s, command_V, \
         displacement_um)",
        args.out.display(),
        record.input.len(),
        args.rate,
        args.axis,
        args.stage
            .as_ref()
            .map_or("the default stage".to_owned(), |p| p.display().to_string())
    );
    Ok(())
}

pub(crate) fn xy200s_preset(args: &Xy200sPresetArgs) -> Result<(), Failure> {
    check_destinations(
        &[
            ("--out", Some(&args.out)),
            ("--report", args.report.as_deref()),
        ],
        &[],
    )?;
    // The printed tables are built in: a failure here is the conversion's.
    let preset =
        piezo_identify::xy200s::xy200s_preset().map_err(|e| Failure::Run(e.to_string()))?;
    for model in &preset.models {
        let p = &model.identified;
        say!(
            "{}: printed model spans {:.3} um on the 2 Hz 0..150 V run; rate-independent fit RMS {:.4} um ({:.3} %); output scaled by {:.4}",
            model.name,
            model.printed_span_um,
            model.rms_um,
            100.0 * model.rms_um / model.printed_span_um,
            model.stroke_scale
        );
        say!("    {}", bouc_wen_parameters(p));
    }
    write_json(&args.out, &preset.stage)?;
    say!("stage parameters written to {}", args.out.display());
    if let Some(report) = &args.report {
        write_json(report, &preset.models)?;
        say!("conversion report written to {}", report.display());
    }
    Ok(())
}

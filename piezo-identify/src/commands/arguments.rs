//! Arguments shared by the subcommands (columns, search, protocol) and the
//! loading of records and plant FMUs.

use std::path::{Path, PathBuf};

use clap::Args;

use piezo_identify::data::{
    ColumnsUsed, Short, UNIFORM_SAMPLING_TOLERANCE, UsedColumn, read_record_with_columns,
};
use piezo_identify::plant::{PlantFmu, read_parameter_set};
use piezo_identify::protocol::{Plan, PlanOptions, ZeroAlignment};
use piezo_identify::segments::{SegmentOptions, Segments};
use piezo_identify::validation::displacement_offset;
use piezo_identify::{Column, FitOptions, ReadOptions, Record, Roles, Sampling};
use result_files::{check_destination, same_file};
use serde::Serialize;

/// Where the record is cut, what is left out of fit and score, and the
/// report file: the same for `inverse-pi` and `bouc-wen`.
#[derive(Args)]
pub(crate) struct ProtocolArgs {
    /// Fit on this fraction of FILE (0 < F < 1) and score the rest, the
    /// models' state carried over from the fit part.
    #[arg(long, allow_negative_numbers = true, value_parser = fraction, conflicts_with = "validate_from")]
    pub(crate) split: Option<f64>,
    /// Fit on FILE before this time [s, counted from its first sample,
    /// whatever its time column starts at] and score the rest (as --split).
    #[arg(long, allow_negative_numbers = true, value_parser = seconds)]
    pub(crate) validate_from: Option<f64>,
    /// Also score on this file (same columns and sampling), the models run
    /// from rest at its first sample; read before the fit.
    #[arg(long, conflicts_with = "plant")]
    pub(crate) validate: Option<PathBuf>,
    /// Seconds at the start of the --validate file not scored [default: the
    /// settling time and the first loading, as at the start of FILE].
    #[arg(long, allow_negative_numbers = true, value_parser = seconds, requires = "validate")]
    pub(crate) validate_warm_up: Option<f64>,
    /// The --validate file's displacement zero: "rest" reads it from its
    /// rest at the start as FILE's is read from FILE's (when both begin at
    /// rest at the same input: a sensor zeroed again between sessions);
    /// "recorded" as written.
    #[arg(long, default_value = "rest", value_parser = ["rest", "recorded"], requires = "validate")]
    pub(crate) validate_zero: String,
    /// Seconds at the start of FILE not fitted [default: the settling time
    /// and the first loading, up to the input's second turning point].
    #[arg(long, allow_negative_numbers = true, value_parser = seconds)]
    pub(crate) warm_up: Option<f64>,
    /// Seconds after each voltage step (and after the start) not fitted nor
    /// scored.
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.1, value_parser = seconds)]
    pub(crate) settle: f64,
    /// Shortest held input that counts as a rest segment [s].
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.5, value_parser = seconds)]
    pub(crate) min_rest: f64,
    /// Fit and score rest segments and steps too (no detection).
    #[arg(long)]
    pub(crate) keep_rest_and_steps: bool,
    /// Write everything (plan, choices, fits, errors) as JSON.
    #[arg(long)]
    pub(crate) report: Option<PathBuf>,
    /// Write FILE's samples as CSV: time, the measured voltage and
    /// displacement, each model's prediction run from the record's start, and
    /// the part each sample is in (fit, scored, left out).
    #[arg(long)]
    pub(crate) predictions: Option<PathBuf>,
}

/// A number of seconds: finite and not negative.
pub(crate) fn seconds(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!(
            "give a number of seconds, 0 or more (got {text:?})"
        )),
    }
}

/// A positive, finite number of seconds.
/// A count of 1 or more (starts, every N-th sample): 0 is refused with the
/// arguments, not after a plant has run for it.
pub(crate) fn at_least_one(text: &str) -> Result<usize, String> {
    at_least::<1>(text)
}

/// A count of `MIN` or more, refused with the arguments as [`at_least_one`].
pub(crate) fn at_least<const MIN: usize>(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(count) if count >= MIN => Ok(count),
        _ => Err(format!("\"{text}\" is not a whole number of {MIN} or more")),
    }
}

/// A `--smooth` half width whose window is wider than the record is refused:
/// its average is of the whole record, and `bouc-wen --smooth 100000` on
/// 8027 samples fitted 35 % errors with exit 0.
pub(crate) fn check_smoothing(half_width: usize, samples: usize) -> Result<(), String> {
    let window = half_width.saturating_mul(2).saturating_add(1);
    if half_width > 0 && window > samples {
        return Err(format!(
            "--smooth {half_width}: a window of {window} samples is wider than the record's \
             {samples}"
        ));
    }
    Ok(())
}

pub(crate) fn positive_seconds(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("give a number of seconds above 0 (got {text:?})")),
    }
}

/// A fraction strictly between 0 and 1.
pub(crate) fn fraction(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v > 0.0 && v < 1.0 => Ok(v),
        _ => Err(format!(
            "give a fraction between 0 and 1, e.g. 0.5 (got {text:?})"
        )),
    }
}

/// "auto" or a value of the parser's kind.
pub(crate) fn auto_or<T>(
    text: &str,
    parse: impl Fn(&str) -> Option<T>,
    what: &str,
) -> Result<Option<T>, String> {
    if text.trim() == "auto" {
        Ok(None)
    } else {
        parse(text.trim())
            .map(Some)
            .ok_or_else(|| format!("give \"auto\" or {what} (got {text:?})"))
    }
}

#[derive(Args, Clone)]
pub(crate) struct ColumnArgs {
    /// Input (command voltage) column: 0-based index or header name [default: the one column in a
    /// voltage unit where the header marks the output by a length unit, else the first column
    /// that is neither a time, a row number, a length nor a given --output]
    #[arg(long)]
    pub(crate) input: Option<String>,
    /// Output (displacement) column: 0-based index or header name [default: the one column in a
    /// length unit, else the first column that is neither a time, a row number nor the input]
    #[arg(long)]
    pub(crate) output: Option<String>,
    /// Sample rate [Hz] (or give --time).
    #[arg(long, conflicts_with = "time")]
    pub(crate) rate: Option<f64>,
    /// Time column [s]: 0-based index or header name (or give --rate; with
    /// neither, the one column whose header name says it is a time).
    #[arg(long)]
    pub(crate) time: Option<String>,
}

impl ColumnArgs {
    pub(crate) fn read_options(&self) -> Result<ReadOptions, String> {
        let sampling = match (&self.time, self.rate) {
            (Some(time), None) => Sampling::TimeColumn(Column::parse(time)),
            (None, Some(rate)) => Sampling::Rate(rate),
            // The file's own time column, if its header names one.
            (None, None) => Sampling::TimeColumn(Column::NamedTime),
            (Some(_), Some(_)) => {
                return Err("give the sampling once: --rate HZ or --time COLUMN".to_owned());
            }
        };
        Ok(ReadOptions {
            input: self.input.as_deref().map(Column::parse),
            output: self.output.as_deref().map(Column::parse),
            sampling,
            roles: Roles::INPUT_OUTPUT,
        })
    }

    /// The columns a `--validate` file is read by: those given, and for each
    /// role left to the default the column `fitted` was read from, by its
    /// header name when it has one, else by its index. Guessed again in the
    /// second file, a role could land on another column (its header in
    /// another order, or no header), and the models would be scored on the
    /// wrong signal.
    fn as_read_from(&self, fitted: &Loaded) -> ColumnArgs {
        let Some(used) = &fitted.columns else {
            return self.clone();
        };
        let same = |given: &Option<String>, column: Option<&UsedColumn>| {
            given
                .clone()
                .or_else(|| column.map(|c| c.name.clone().unwrap_or_else(|| c.index.to_string())))
        };
        ColumnArgs {
            input: same(&self.input, Some(&used.input)),
            output: same(&self.output, Some(&used.output)),
            rate: self.rate,
            time: if self.rate.is_some() {
                None
            } else {
                same(&self.time, used.time.as_ref())
            },
        }
    }
}

#[derive(Args)]
pub(crate) struct SearchArgs {
    /// Random starts of the Nelder-Mead search (seed 000: 30).
    #[arg(long, default_value_t = 30, value_parser = at_least_one)]
    pub(crate) starts: usize,
    /// Seed of the random initial values.
    #[arg(long, default_value_t = 0)]
    pub(crate) seed: u64,
    /// Nelder-Mead iterations per start at most.
    #[arg(long, default_value_t = 2000, value_parser = clap::value_parser!(u64).range(1..))]
    pub(crate) max_iterations: u64,
    /// The search uses every N-th sample (the final linear solve and F use all).
    #[arg(long, value_parser = at_least_one)]
    pub(crate) decimation: Option<usize>,
    /// Seconds at the start of each record that run the models but are not
    /// fitted nor scored (a start-up transient).
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.0, value_parser = seconds)]
    pub(crate) warm_up: f64,
    /// Constant backlash weights (k = 0) instead of seed 000 eq. (4)'s
    /// w_h = k·ẏ + b: for a record whose single frequency and amplitude make
    /// the rate a function of position and direction (k not identifiable).
    #[arg(long)]
    pub(crate) rate_independent: bool,
}

impl SearchArgs {
    pub(crate) fn options(&self, sample_period: f64, default_decimation: usize) -> FitOptions {
        FitOptions {
            starts: self.starts,
            seed: self.seed,
            max_iterations: self.max_iterations,
            decimation: self.decimation.unwrap_or(default_decimation),
            warm_up_samples: (self.warm_up / sample_period).round() as usize,
            rate_dependent: !self.rate_independent,
            ..FitOptions::default()
        }
    }
}

pub(crate) fn resolve_offset(text: &str, y: &[f64], warm_up_samples: usize) -> Result<f64, String> {
    if text == "auto" {
        Ok(displacement_offset(y, warm_up_samples))
    } else {
        text.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("--offset {text}: give a number [µm] or \"auto\""))
    }
}

/// A record file with the columns it was read from.
pub(crate) struct Loaded {
    pub(crate) name: String,
    pub(crate) record: Record,
    pub(crate) columns: Option<ColumnsUsed>,
}

pub(crate) fn load(path: &Path, columns: &ColumnArgs) -> Result<Loaded, String> {
    let (record, used) =
        read_record_with_columns(path, &columns.read_options()?).map_err(|e| e.to_string())?;
    // A column that never changes is no record of a stage: most often the
    // default took an unused channel (a headerless file's column 1 of
    // zeros), and the fit's own complaint ("displacement never exceeds 0")
    // would not say so.
    for (role, option, values, column) in [
        ("output", "--output", &record.output, &used.output),
        ("input", "--input", &record.input, &used.input),
    ] {
        if let Some(&first) = values.first()
            && values.iter().all(|v| *v == first)
        {
            return Err(format!(
                "{}: the {role} ({column}) is {first} in every sample: nothing to fit; name \
                 the {role} column with {option}",
                path.display()
            ));
        }
    }
    Ok(Loaded {
        name: path.display().to_string(),
        record,
        columns: Some(used),
    })
}

/// Loads the `--validate` file of `fitted` by `fitted`'s columns
/// ([`ColumnArgs::as_read_from`]), refusing one sampled at another rate: the
/// rate-dependent weights, the smoothing and the settling times count
/// samples, so they would mean other times there.
pub(crate) fn load_validation(
    path: &Path,
    columns: &ColumnArgs,
    fitted: &Loaded,
) -> Result<Loaded, String> {
    let validation = load(path, &columns.as_read_from(fitted))
        .map_err(|e| format!("{e} (the --validate file is read by the fit file's columns)"))?;
    let (fit_period, period) = (fitted.record.sample_period, validation.record.sample_period);
    if (period - fit_period).abs() > UNIFORM_SAMPLING_TOLERANCE * fit_period {
        return Err(format!(
            "{}: sampled at {} Hz, and {} at {} Hz: the fitted model counts its rate terms, \
             smoothing and settling in samples, so resample the validation file to {} Hz",
            validation.name,
            Short(1.0 / period),
            fitted.name,
            Short(1.0 / fit_period),
            Short(1.0 / fit_period)
        ));
    }
    Ok(validation)
}

/// What a refusal adds when the time column's unit was assumed: the rate
/// that reading gave, since a time in ms read as seconds makes a 20 kHz
/// record a 20 Hz one, whose every sample then looks like a rest.
fn assumed_seconds(loaded: &Loaded) -> String {
    match loaded.columns.as_ref().and_then(|c| c.time_unit.as_ref()) {
        Some(unit) if unit.source.starts_with("assumed") => format!(
            " (the time column was read in seconds, {}: {} Hz; if it is in ms or us, name its \
             unit, `time [ms]`)",
            unit.source,
            Short(1.0 / loaded.record.sample_period)
        ),
        _ => String::new(),
    }
}

impl ProtocolArgs {
    /// [`check_destinations`] for a fit's outputs: its model (`--out`), the
    /// report and the predictions.
    pub(crate) fn check_destinations(
        &self,
        out: Option<&Path>,
        inputs: &[&Path],
    ) -> Result<(), String> {
        check_destinations(
            &[
                ("--out", out),
                ("--report", self.report.as_deref()),
                ("--predictions", self.predictions.as_deref()),
            ],
            inputs,
        )
    }

    pub(crate) fn plan_options(&self, default_warm_up: Option<f64>) -> PlanOptions {
        PlanOptions {
            segments: SegmentOptions {
                settle_seconds: self.settle,
                min_rest_seconds: self.min_rest,
            },
            warm_up_seconds: self.warm_up.or(default_warm_up),
            detect_segments: !self.keep_rest_and_steps,
        }
    }

    /// Refuses a record whose displacement falls as the command rises, for
    /// a model the feedforward inverts (`inverse-pi`, `bouc-wen --monotone`):
    /// PiezoController's feedback takes a displacement that rises with its
    /// command. A coupled displacement may fall (the stage preset's H_XY
    /// has p < 0), and is fitted without this check.
    pub(crate) fn refuse_falling(loaded: &Loaded) -> Result<(), String> {
        let correlation = pearson(&loaded.record.input, &loaded.record.output);
        if correlation < -FALLING_CORRELATION {
            return Err(format!(
                "{}: the displacement falls as the command rises (correlation {correlation:.3}): \
                 the inverse model, and PiezoController's feedback, take a displacement that \
                 rises with the command; a sensor counting the other way is read negated \
                 (multiply the column by -1) and fitted again (a coupled displacement, which \
                 may fall, is fitted by bouc-wen without --monotone)",
                loaded.name
            ));
        }
        Ok(())
    }

    /// The first scored sample (the record's length when nothing is split).
    pub(crate) fn fit_end(&self, record: &Record) -> Result<usize, String> {
        let n = record.input.len();
        let dt = record.sample_period;
        match (self.split, self.validate_from) {
            (Some(fraction), _) => Ok(((fraction * n as f64).round() as usize).clamp(1, n - 1)),
            (None, Some(t)) => {
                let at = (t / dt).round() as usize;
                if at == 0 || at >= n {
                    Err(format!(
                        "--validate-from {t}: the record runs from 0 to {:.3} s; give a time inside it",
                        n as f64 * dt
                    ))
                } else {
                    Ok(at)
                }
            }
            (None, None) => Ok(n),
        }
    }

    /// The plan of `loaded`, with its error named after the file.
    pub(crate) fn plan(
        &self,
        loaded: &Loaded,
        default_warm_up: Option<f64>,
    ) -> Result<Plan, String> {
        let record = &loaded.record;
        Plan::new(
            &record.input,
            record.sample_period,
            self.fit_end(record)?,
            &self.plan_options(default_warm_up),
        )
        .map_err(|e| format!("{}: {e}{}", loaded.name, assumed_seconds(loaded)))
    }

    /// The validation file's rests and steps and its scored samples,
    /// refusing a file with none.
    pub(crate) fn validation_scored(
        &self,
        plan: &Plan,
        validation: &Loaded,
    ) -> Result<(Segments, Vec<bool>), String> {
        let record = &validation.record;
        let warm_up = self
            .validate_warm_up
            .map(|s| (s / record.sample_period).round() as usize);
        let (segments, scored) = plan.validation_scored(
            &record.input,
            record.sample_period,
            warm_up,
            !self.keep_rest_and_steps,
        );
        if !scored.iter().any(|s| *s) {
            return Err(format!(
                "{}: no sample is left to score after its warm-up ({}), rest segments and settling after steps; give a shorter --validate-warm-up",
                validation.name,
                match warm_up {
                    Some(n) => format!("{n} samples"),
                    None => "the settling time and the first loading".to_owned(),
                }
            ));
        }
        Ok((segments, scored))
    }

    /// The validation file's output read from FILE's zero (`--validate-zero`)
    /// and what was done, which it also prints; `stroke` is the fit part's
    /// displacement span, to put the shift in proportion.
    pub(crate) fn validation_output(
        &self,
        plan: &Plan,
        fit: &Loaded,
        validation: &Loaded,
        stroke: f64,
    ) -> (Vec<f64>, ValidationZero) {
        let recorded = validation.record.output.clone();
        if self.validate_zero == "recorded" {
            say!("displacement as recorded (--validate-zero recorded)");
            let zero = ValidationZero {
                mode: "recorded",
                alignment: None,
                not_aligned_because: None,
            };
            return (recorded, zero);
        }
        match plan.zero_alignment(&fit.record, &validation.record) {
            Ok(alignment) => {
                say!(
                    "displacement zero: its rest at {:.4} V (samples {}..{}) reads {:+.6} um from {}'s (samples {}..{}), {:.2} % of the fit part's stroke; subtracted from every sample (--validate-zero recorded keeps it as written)",
                    alignment.rest_input,
                    alignment.validation_rest.start,
                    alignment.validation_rest.end,
                    alignment.shift,
                    fit.name,
                    alignment.fit_rest.start,
                    alignment.fit_rest.end,
                    100.0 * alignment.shift.abs() / stroke,
                );
                let output = alignment.aligned(&validation.record.output);
                let zero = ValidationZero {
                    mode: "rest",
                    alignment: Some(alignment),
                    not_aligned_because: None,
                };
                (output, zero)
            }
            Err(reason) => {
                say!(
                    "displacement as recorded: its zero cannot be compared with {}'s, because {reason}",
                    fit.name
                );
                let zero = ValidationZero {
                    mode: "rest",
                    alignment: None,
                    not_aligned_because: Some(reason.to_string()),
                };
                (recorded, zero)
            }
        }
    }
}

/// Opens a plant FMU, loaded with the parameter set at `parameters` if given.
pub(crate) fn open_plant(path: &Path, parameters: Option<&Path>) -> Result<PlantFmu, String> {
    let plant = PlantFmu::open(path).map_err(|e| e.to_string())?;
    match parameters {
        // A name or value the FMU refuses is the parameter file's fault:
        // named first, then the FMU that refused it.
        Some(set) => plant
            .with_parameters(&read_parameter_set(set)?)
            .map_err(|e| format!("{}: {e}", set.display())),
        None => Ok(plant),
    }
}

/// How a validation file's displacement zero was read, for the report.
#[derive(Serialize)]
pub(crate) struct ValidationZero {
    /// `--validate-zero`.
    pub(crate) mode: &'static str,
    pub(crate) alignment: Option<ZeroAlignment>,
    pub(crate) not_aligned_because: Option<String>,
}

/// A record whose displacement correlates with its command below minus this
/// is a falling one: a piezo's displacement rises with its voltage (r near
/// +1; hysteresis and creep take a few per cent off), so a driven axis that
/// falls is a sensor counting the other way.
const FALLING_CORRELATION: f64 = 0.5;

/// Pearson's correlation of `a` and `b` (0 when either is constant).
fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()) as f64;
    let (mean_a, mean_b) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        let (dx, dy) = (x - mean_a, y - mean_b);
        ab += dx * dy;
        aa += dx * dx;
        bb += dy * dy;
    }
    if aa > 0.0 && bb > 0.0 {
        ab / (aa * bb).sqrt()
    } else {
        0.0
    }
}

/// Refuses, before any work is done, an output that could not be written or
/// would destroy something: `outputs` are (option, path) pairs, `inputs` the
/// files the command reads. A path with no folder to write in, or that is a
/// folder, would otherwise fail only after the fit (minutes, for `stage`);
/// one that is an input file (`--out record.csv`) would overwrite the
/// user's measurement; two options naming one file would keep only the
/// last written.
pub(crate) fn check_destinations(
    outputs: &[(&str, Option<&Path>)],
    inputs: &[&Path],
) -> Result<(), String> {
    let named: Vec<(&str, &Path)> = outputs
        .iter()
        .filter_map(|(option, path)| path.map(|p| (*option, p)))
        .collect();
    for (k, (option, path)) in named.iter().enumerate() {
        check_destination(path).map_err(|e| format!("{option} {}: {e}", path.display()))?;
        for input in inputs {
            if same_file(path, input) {
                return Err(format!(
                    "{option} {}: is {}, which this command reads; writing there would \
                     overwrite it, so give another name",
                    path.display(),
                    input.display()
                ));
            }
        }
        for (other_option, other) in &named[..k] {
            if same_file(path, other) {
                return Err(format!(
                    "{other_option} and {option} both name {}: give each its own file",
                    path.display()
                ));
            }
        }
    }
    Ok(())
}

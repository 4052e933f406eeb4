//! `piezo-identify`: fits seed 000's modified inverse P-I model to a
//! voltage/displacement record, validates it on a second record, and runs the
//! paper's model comparison. All I/O lives here; the library does the math.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Mutex;
use std::time::Instant;

use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use piezo_identify::bouc_wen_fit::{SHAPE_PARAMETERS, default_shape_bounds, wide_shape_bounds};
use piezo_identify::compare::{
    IDENTIFICATION_DURATION, PLANT_SAMPLE_RATE, compare_inverse_models, synthetic_plant_record,
};
use piezo_identify::data::{ColumnsUsed, read_record_with_columns};
use piezo_identify::decoupling::fit_compensation;
use piezo_identify::gapso::{Bounds, GaPsoOptions};
use piezo_identify::plant::{
    ParameterValue, PlantFmu, RecordAxis, read_parameter_set, sine_records,
};
use piezo_identify::protocol::{
    BoucWenProtocolFit, BoucWenSettings, ErrorFigures, ForwardErrors, InversePiErrors,
    InversePiIdentification, InversePiSettings, Plan, PlanOptions, ProgressEvent,
    identify_bouc_wen_protocol, identify_inverse_pi,
};
use piezo_identify::segments::SegmentOptions;
use piezo_identify::stage::{StageConditions, identify_stage};
use piezo_identify::validation::{centred_moving_average, displacement_offset, shifted};
use piezo_identify::{Column, FitOptions, ReadOptions, Record, Sampling, StartResult, read_record};

#[derive(Parser)]
#[command(
    name = "piezo-identify",
    version,
    about = "Identify piezo hysteresis models (seed 000's modified inverse Prandtl-Ishlinskii, seed 001's asymmetric Bouc-Wen) from voltage/displacement records"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fit the proposed modified inverse P-I model (seed 000 eq. 3-5) to a
    /// record, with the classical P-I model and a straight line as
    /// baselines; score all three on the rest of the record (--split,
    /// --validate-from) or on a second file (--validate).
    InversePi(InversePiArgs),
    /// Seed 000's model comparison: F (eq. 7) and evaluation time of the
    /// proposed model and the traditional 10+6 and 10+10 models.
    Compare(CompareArgs),
    /// Seed 000's whole identification on a plant FMU: eq. (6) records and
    /// inverse-model fits of x and y, then single-axis closed-loop runs and
    /// the decoupling compensations (Table 2). Writes a controller preset
    /// (piezo_models::ControllerParams) that PiezoController's start values
    /// come from.
    Stage(StageArgs),
    /// Fit one decoupling compensation D(f) = clamp(dk*f + db, q, p) (seed 000
    /// eq. 11, Table 2) to a record of (driving demand, coupling error).
    Decoupling(DecouplingArgs),
    /// Fit seed 001's asymmetric Bouc-Wen model (eq. 3-4) by GA-PSO on the
    /// RMS of eq. (5), then refine it by Levenberg-Marquardt inside the
    /// search box; from a record (voltage, displacement) or from a plant FMU
    /// driven by seed 001 §5.2's sine, with the classical P-I model and
    /// straight lines as baselines. Also fits the coupling models H_XY,
    /// H_YX: give the coupled displacement as the output (or --read coupled).
    BoucWen(BoucWenArgs),
    /// Build seed 001's XY200S stage as a FlexureStage parameter set from
    /// the printed Tables 1-2 (units and conversion: piezo_identify::xy200s).
    Xy200sPreset(Xy200sPresetArgs),
    /// Write a record taken from the simulated stage (FlexureStage, y
    /// actuator) the way a lab takes one: rest at 0 V, a step onto a sine,
    /// a sensor offset and noise; columns time [s], command [V],
    /// displacement [um].
    LabRecord(LabRecordArgs),
}

#[derive(Args)]
struct LabRecordArgs {
    /// Sample rate [Hz].
    #[arg(long, default_value_t = 5000.0)]
    rate: f64,
    /// Command range: unipolar 0.5..9.5 V or bipolar -2..8 V.
    #[arg(long, default_value = "unipolar", value_parser = ["unipolar", "bipolar"])]
    drive: String,
    /// Frequency of the sine [Hz].
    #[arg(long, default_value_t = 1.0)]
    frequency: f64,
    /// Sweep the sine's amplitude from 100 % to 20 % and back over this many
    /// seconds (0: a plain sine).
    #[arg(long, default_value_t = 0.0, value_parser = seconds)]
    sweep: f64,
    /// Seconds at rest (0 V) before the step onto the sine.
    #[arg(long, default_value_t = 2.0, value_parser = seconds)]
    rest: f64,
    /// Seconds of sine after the step.
    #[arg(long, default_value_t = 8.0, value_parser = seconds)]
    seconds: f64,
    /// Sensor offset [um].
    #[arg(long, default_value_t = -42.7, allow_negative_numbers = true)]
    sensor_offset: f64,
    /// Sensor noise [um RMS].
    #[arg(long, default_value_t = 0.02)]
    noise: f64,
    /// Seed of the sensor noise.
    #[arg(long, default_value_t = 7)]
    noise_seed: u32,
    /// The record file to write (comma-separated, with a header).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Args)]
struct Xy200sPresetArgs {
    /// Write the stage parameters (piezo_models::FlexureStageParams) here.
    #[arg(long)]
    out: PathBuf,
    /// Write the conversion of each printed model (fit RMS, scaling) here.
    #[arg(long)]
    report: Option<PathBuf>,
}

#[derive(Args)]
struct BoucWenArgs {
    /// Identification record (or --plant).
    #[arg(required_unless_present = "plant", conflicts_with = "plant")]
    file: Option<PathBuf>,
    #[command(flatten)]
    columns: ColumnArgs,
    #[command(flatten)]
    protocol: ProtocolArgs,
    /// Drive this plant FMU (FlexureStage's interface) instead of reading a
    /// file: a sine from 0 V to --peak at --frequency on one axis.
    #[arg(long)]
    plant: Option<PathBuf>,
    /// Parameter set the plant is loaded with (JSON by FMI name).
    #[arg(long, requires = "plant")]
    plant_parameters: Option<PathBuf>,
    /// Axis the plant run drives: y (u1) or x (u2 = u3).
    #[arg(long, default_value = "y", value_parser = ["x", "y"])]
    drive: String,
    /// Displacement the plant run fits: the driven axis's (H_XX, H_YY) or
    /// the other axis's (the coupling H_XY, H_YX of eq. 8).
    #[arg(long, default_value = "driven", value_parser = ["driven", "coupled"])]
    read: String,
    /// Frequency of the plant run's sine [Hz] (seed 001 §5.2: 2).
    #[arg(long, default_value_t = 2.0)]
    frequency: f64,
    /// Peak command of the plant run's sine [V] (seed 001 §5.2: 10).
    #[arg(long, default_value_t = 10.0)]
    peak: f64,
    /// Periods of the plant run; the first is the warm-up unless --warm-up.
    #[arg(long, default_value_t = 3.0)]
    periods: f64,
    /// Sample rate of the plant run [Hz].
    #[arg(long, default_value_t = 10_000.0)]
    plant_rate: f64,
    /// Particles of the swarm.
    #[arg(long, default_value_t = 40)]
    population: usize,
    /// GA-PSO generations at most.
    #[arg(long, default_value_t = 150)]
    generations: usize,
    /// Seed of GA-PSO's random stream.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// GA-PSO evaluates every N-th sample (refinement and errors use all);
    /// default: at most about 3000 samples and at least 100 per fastest
    /// cycle for a file, 10 for a plant run.
    #[arg(long)]
    decimation: Option<usize>,
    /// Half width [samples] of a centred moving average of the fitted
    /// displacement (0: none); the errors are always against the measured one.
    #[arg(long, default_value_t = 0)]
    smooth: usize,
    /// Take the output as zero at rest instead of fitting a sensor offset.
    #[arg(long)]
    no_offset: bool,
    /// Accept only models whose every branch rises with the input on the
    /// record: models with an inverse, as feedforward (eq. 6) needs.
    #[arg(long)]
    monotone: bool,
    /// Stop at the GA-PSO optimum, as seed 001 does.
    #[arg(long)]
    no_refine: bool,
    /// Search box of the scaled shape, e.g. "beta=0:10,gamma=-10:10,n=1:3,delta=-2:2"
    /// (u scaled by max|u|, y by its span, A = 1; any subset).
    #[arg(long)]
    bounds: Option<String>,
    /// Start from the wide box (ten times the default in beta, gamma, delta;
    /// n up to 5) before --bounds: for loops unlike a plain piezo's, such as
    /// the XY200S's.
    #[arg(long)]
    wide_bounds: bool,
    /// Write the fitted model (piezo_models::BoucWenParams and the sensor
    /// offset) as JSON.
    #[arg(long)]
    out: Option<PathBuf>,
}

/// Where the record is cut, what is left out of fit and score, and the
/// report file: the same for `inverse-pi` and `bouc-wen`.
#[derive(Args)]
struct ProtocolArgs {
    /// Fit on this fraction of FILE (0 < F < 1) and score the rest, the
    /// models' state carried over from the fit part.
    #[arg(long, allow_negative_numbers = true, value_parser = fraction, conflicts_with = "validate_from")]
    split: Option<f64>,
    /// Fit on FILE before this time [s] and score the rest (as --split).
    #[arg(long, allow_negative_numbers = true, value_parser = seconds)]
    validate_from: Option<f64>,
    /// Also score on this file (same columns and sampling), the models run
    /// from rest at its first sample; read before the fit.
    #[arg(long, conflicts_with = "plant")]
    validate: Option<PathBuf>,
    /// Seconds at the start of the --validate file not scored [default: the
    /// settling time and the first loading, as at the start of FILE].
    #[arg(long, allow_negative_numbers = true, value_parser = seconds, requires = "validate")]
    validate_warm_up: Option<f64>,
    /// Seconds at the start of FILE not fitted [default: the settling time
    /// and the first loading, up to the input's second turning point].
    #[arg(long, allow_negative_numbers = true, value_parser = seconds)]
    warm_up: Option<f64>,
    /// Seconds after each voltage step (and after the start) not fitted nor
    /// scored.
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.1, value_parser = seconds)]
    settle: f64,
    /// Shortest held input that counts as a rest segment [s].
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.5, value_parser = seconds)]
    min_rest: f64,
    /// Fit and score rest segments and steps too (no detection).
    #[arg(long)]
    keep_rest_and_steps: bool,
    /// Write everything (plan, choices, fits, errors) as JSON.
    #[arg(long)]
    report: Option<PathBuf>,
}

/// A number of seconds: finite and not negative.
fn seconds(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!(
            "give a number of seconds, 0 or more (got {text:?})"
        )),
    }
}

/// A fraction strictly between 0 and 1.
fn fraction(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v > 0.0 && v < 1.0 => Ok(v),
        _ => Err(format!(
            "give a fraction between 0 and 1, e.g. 0.5 (got {text:?})"
        )),
    }
}

/// "auto" or a value of the parser's kind.
fn auto_or<T>(
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

#[derive(Args)]
struct StageArgs {
    /// The plant FMU to identify (FMI 2.0 co-simulation, inputs u1..u3 [V],
    /// outputs s1..s3 [um], parameter L [mm]).
    #[arg(long, default_value = "dist/FlexureStage.fmu")]
    plant: PathBuf,
    /// Parameter set the plant is loaded with (JSON by FMI name, as
    /// `flexure-stage-parameters xy200s` writes); default its start values.
    #[arg(long)]
    plant_parameters: Option<PathBuf>,
    #[command(flatten)]
    search: SearchArgs,
    /// Scale of the single-axis runs relative to seed 000's (10 um sines,
    /// x at half of a 12.74 um stroke for the rotation run, 10 um for an
    /// unused cutoff): the stage's strokes over seed 000's.
    #[arg(long, default_value_t = 1.0)]
    scale: f64,
    /// The stage does not rotate (its x actuators move together): no
    /// rotation run, D4 stays zero.
    #[arg(long)]
    no_rotation: bool,
    /// Demands of the held translations, "X,Y" in um: x during the y run, y
    /// during the x run (seed 000 §5: 0,0). A stage whose commands cannot go
    /// below 0 V cancels a coupling only from a held axis above its rest.
    #[arg(long, default_value = "0,0", allow_hyphen_values = true)]
    held: String,
    /// Command range of the controller, "MIN,MAX" in V (seed 000's E-505:
    /// -2,12).
    #[arg(long, default_value = "-2,12", allow_hyphen_values = true)]
    command_range: String,
    /// Factor on the §3.2 PI gains for the single-axis runs (1 for seed
    /// 000's stage; the inverse of the stage's um per volt relative to it).
    #[arg(long, default_value_t = 1.0)]
    gain_scale: f64,
    /// Rounds of decoupling runs: the second refits what the first leaves.
    #[arg(long, default_value_t = 2)]
    rounds: usize,
    /// Write the controller preset (JSON) here.
    #[arg(long)]
    out: PathBuf,
    /// Write everything measured (fits, compensations per round) here as JSON.
    #[arg(long)]
    report: Option<PathBuf>,
}

#[derive(Args)]
struct DecouplingArgs {
    /// Record with a driving-demand column and a coupling-error column.
    file: PathBuf,
    /// Driving demand column (y_d or x_d [um], theta_zd [mdeg]): index or header.
    #[arg(long, default_value = "0")]
    demand: String,
    /// Coupling error column (demand - measurement of the coupled channel) [um].
    #[arg(long, default_value = "1")]
    error: String,
}

#[derive(Args)]
struct ColumnArgs {
    /// Input (command voltage) column: 0-based index or header name.
    #[arg(long, default_value = "0")]
    input: String,
    /// Output (displacement) column: 0-based index or header name.
    #[arg(long, default_value = "1")]
    output: String,
    /// Sample rate [Hz] (or give --time).
    #[arg(long, conflicts_with = "time")]
    rate: Option<f64>,
    /// Time column [s]: 0-based index or header name (or give --rate).
    #[arg(long)]
    time: Option<String>,
}

impl ColumnArgs {
    fn read_options(&self) -> Result<ReadOptions, String> {
        let sampling = match (&self.time, self.rate) {
            (Some(time), None) => Sampling::TimeColumn(Column::parse(time)),
            (None, Some(rate)) => Sampling::Rate(rate),
            _ => return Err("give the sampling: --rate HZ or --time COLUMN".to_owned()),
        };
        Ok(ReadOptions {
            input: Column::parse(&self.input),
            output: Column::parse(&self.output),
            sampling,
        })
    }
}

#[derive(Args)]
struct SearchArgs {
    /// Random starts of the Nelder-Mead search (seed 000: 30).
    #[arg(long, default_value_t = 30)]
    starts: usize,
    /// Seed of the random initial values.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Nelder-Mead iterations per start at most.
    #[arg(long, default_value_t = 2000)]
    max_iterations: u64,
    /// The search uses every N-th sample (the final linear solve and F use all).
    #[arg(long)]
    decimation: Option<usize>,
    /// Seconds at the start of each record that run the models but are not
    /// fitted nor scored (a start-up transient).
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.0, value_parser = seconds)]
    warm_up: f64,
    /// Constant backlash weights (k = 0) instead of seed 000 eq. (4)'s
    /// w_h = k·ẏ + b: for a record whose single frequency and amplitude make
    /// the rate a function of position and direction (k not identifiable).
    #[arg(long)]
    rate_independent: bool,
    /// Half width [samples] of a centred moving average applied to the
    /// displacement of every record before fitting and evaluation (0: none).
    #[arg(long, default_value_t = 0)]
    smooth: usize,
}

impl SearchArgs {
    fn options(&self, sample_period: f64, default_decimation: usize) -> FitOptions {
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

#[derive(Args)]
struct InversePiArgs {
    /// Identification record.
    file: PathBuf,
    #[command(flatten)]
    columns: ColumnArgs,
    #[command(flatten)]
    protocol: ProtocolArgs,
    /// Random starts of the (c, w_s) search (seed 000: 30).
    #[arg(long, default_value_t = 30)]
    starts: usize,
    /// Seed of the random initial values.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Nelder-Mead iterations per start at most.
    #[arg(long, default_value_t = 2000)]
    max_iterations: u64,
    /// Run every start to convergence (seed 000's best of N) instead of
    /// screening them for 60 iterations and running on the best 5.
    #[arg(long)]
    no_screening: bool,
    /// The search uses every N-th sample, or "auto": at most about 3000
    /// samples and at least 100 per fastest cycle.
    #[arg(long, default_value = "auto")]
    decimation: String,
    /// Half width [samples] of a centred moving average of the displacement,
    /// or "auto": chosen by validation inside the fit part among none and
    /// 1/160, 1/80, 1/40 of the fastest cycle.
    #[arg(long, default_value = "auto")]
    smooth: String,
    /// Backlash weights: "rate-dependent" (seed 000 eq. 4), "constant", or
    /// "auto": chosen by validation inside the fit part.
    #[arg(long, default_value = "auto", value_parser = ["auto", "rate-dependent", "constant"])]
    weights: String,
    /// Displacement offset [µm] subtracted from every record, or "auto": the
    /// smallest (smoothed) fitted displacement.
    #[arg(long, default_value = "auto", allow_negative_numbers = true)]
    offset: String,
    /// Write the fitted model (piezo_models::InversePiParams, the offset and
    /// the smoothing it takes) as JSON.
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Args)]
struct CompareArgs {
    /// Record to compare on (or --synthetic).
    #[arg(required_unless_present = "synthetic")]
    file: Option<PathBuf>,
    /// Generate the record: seed 000 eq. (6) driving the simulated stage's y
    /// actuator for 10 s at 10 kHz.
    #[arg(long, conflicts_with = "file")]
    synthetic: bool,
    #[command(flatten)]
    columns: ColumnArgs,
    #[command(flatten)]
    search: SearchArgs,
    /// Displacement offset [µm] for a file, or "auto" (as for inverse-pi).
    /// The synthetic record starts de-energized at 0 and is not shifted.
    #[arg(long, default_value = "auto", allow_negative_numbers = true)]
    offset: String,
    /// Timed passes over the record per model (the median is reported).
    #[arg(long, default_value_t = 31)]
    repetitions: usize,
}

/// Decimation of the synthetic 10 kHz record for the search: 500 Hz, 250
/// samples per period of eq. (6)'s fastest (1 Hz) component.
const SYNTHETIC_DECIMATION: usize = 20;

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::InversePi(args) => inverse_pi(args),
        Command::Compare(args) => compare(args),
        Command::Stage(args) => stage(args),
        Command::Decoupling(args) => decoupling(args),
        Command::BoucWen(args) => bouc_wen(args),
        Command::Xy200sPreset(args) => xy200s_preset(args),
        Command::LabRecord(args) => write_lab_record(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("{message}");
            ExitCode::FAILURE
        }
    }
}

fn read(path: &Path, options: &ReadOptions) -> Result<Record, String> {
    read_record(path, options).map_err(|e| e.to_string())
}

fn resolve_offset(text: &str, y: &[f64], warm_up_samples: usize) -> Result<f64, String> {
    if text == "auto" {
        Ok(displacement_offset(y, warm_up_samples))
    } else {
        text.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("--offset {text}: give a number [µm] or \"auto\""))
    }
}

/// A progress bar on stderr for `total` starts, hidden when stderr is not a
/// terminal; ticked from the rayon workers.
fn progress_bar(total: usize, message: &str) -> ProgressBar {
    let target = if std::io::stderr().is_terminal() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let bar = ProgressBar::with_draw_target(Some(total as u64), target);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} starts, {elapsed}")
            .expect("the template is valid")
            .progress_chars("=> "),
    );
    bar.set_message(message.to_owned());
    bar
}

/// Seconds between progress lines when stderr is not a terminal.
const PROGRESS_INTERVAL_SECONDS: f64 = 2.0;

/// The progress of the identification protocol on stderr: a bar per phase
/// on a terminal, otherwise a line when a phase starts and then at most one
/// every [`PROGRESS_INTERVAL_SECONDS`] (a log, a CI job, a pipe).
struct Reporter {
    terminal: bool,
    started: Instant,
    state: Mutex<ReporterState>,
}

struct ReporterState {
    bar: Option<ProgressBar>,
    phase: String,
    steps: usize,
    done: usize,
    best: f64,
    last_line: Instant,
}

impl Reporter {
    fn new() -> Reporter {
        Reporter {
            terminal: std::io::stderr().is_terminal(),
            started: Instant::now(),
            state: Mutex::new(ReporterState {
                bar: None,
                phase: String::new(),
                steps: 0,
                done: 0,
                best: f64::INFINITY,
                last_line: Instant::now(),
            }),
        }
    }

    fn event(&self, event: ProgressEvent) {
        let mut state = self.state.lock().expect("no panic while held");
        match event {
            ProgressEvent::Phase { name, steps } => {
                if let Some(bar) = state.bar.take() {
                    bar.finish_and_clear();
                }
                state.phase = name.to_owned();
                state.steps = steps;
                state.done = 0;
                state.best = f64::INFINITY;
                if self.terminal {
                    let bar = ProgressBar::with_draw_target(
                        Some(steps as u64),
                        ProgressDrawTarget::stderr(),
                    );
                    bar.set_style(
                        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len}, {elapsed}")
                            .expect("the template is valid")
                            .progress_chars("=> "),
                    );
                    bar.set_message(name.to_owned());
                    state.bar = Some(bar);
                } else {
                    eprintln!(
                        "piezo-identify: {name}: 0/{steps} ({:.1} s)",
                        self.started.elapsed().as_secs_f64()
                    );
                    state.last_line = Instant::now();
                }
            }
            ProgressEvent::Step { best } => {
                state.done += 1;
                state.best = state.best.min(best);
                if let Some(bar) = &state.bar {
                    bar.set_position(state.done as u64);
                    bar.set_message(format!("{}, best {:.4e}", state.phase, state.best));
                } else if state.last_line.elapsed().as_secs_f64() >= PROGRESS_INTERVAL_SECONDS {
                    eprintln!(
                        "piezo-identify: {}: {}/{}, best {:.4e} ({:.1} s)",
                        state.phase,
                        state.done,
                        state.steps,
                        state.best,
                        self.started.elapsed().as_secs_f64()
                    );
                    state.last_line = Instant::now();
                }
            }
        }
    }

    fn finish(&self) {
        if let Some(bar) = self.state.lock().expect("no panic while held").bar.take() {
            bar.finish_and_clear();
        }
    }
}

fn describe(record: &Record, path: &str) -> String {
    format!(
        "{path}: {} samples, {:.2} s at {:.6} Hz",
        record.input.len(),
        record.input.len() as f64 * record.sample_period,
        1.0 / record.sample_period
    )
}

/// "input column 0 \"volts\", output column 4, time column 2, tab-separated,
/// header on line 1".
fn describe_columns(columns: &ColumnsUsed) -> String {
    let mut text = format!("input {}, output {}", columns.input, columns.output);
    if let Some(time) = &columns.time {
        text.push_str(&format!(", time {time}"));
    }
    text.push_str(&format!(", {}-separated", columns.separator.name()));
    match columns.header_line {
        Some(line) => text.push_str(&format!(", header on line {line}")),
        None => text.push_str(", no header"),
    }
    text
}

/// A record file with the columns it was read from.
struct Loaded {
    name: String,
    record: Record,
    columns: Option<ColumnsUsed>,
}

fn load(path: &Path, columns: &ColumnArgs) -> Result<Loaded, String> {
    let (record, used) =
        read_record_with_columns(path, &columns.read_options()?).map_err(|e| e.to_string())?;
    Ok(Loaded {
        name: path.display().to_string(),
        record,
        columns: Some(used),
    })
}

impl ProtocolArgs {
    fn plan_options(&self, default_warm_up: Option<f64>) -> PlanOptions {
        PlanOptions {
            segments: SegmentOptions {
                settle_seconds: self.settle,
                min_rest_seconds: self.min_rest,
            },
            warm_up_seconds: self.warm_up.or(default_warm_up),
            detect_segments: !self.keep_rest_and_steps,
        }
    }

    /// The first scored sample (the record's length when nothing is split).
    fn fit_end(&self, record: &Record) -> Result<usize, String> {
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
    fn plan(&self, loaded: &Loaded, default_warm_up: Option<f64>) -> Result<Plan, String> {
        let record = &loaded.record;
        Plan::new(
            &record.input,
            record.sample_period,
            self.fit_end(record)?,
            &self.plan_options(default_warm_up),
        )
        .map_err(|e| format!("{}: {e}", loaded.name))
    }

    /// The validation file's scored samples, refusing a file with none.
    fn validation_scored(
        &self,
        plan: &Plan,
        validation: &Loaded,
    ) -> Result<(Vec<usize>, Vec<bool>), String> {
        let record = &validation.record;
        let warm_up = self
            .validate_warm_up
            .map(|s| (s / record.sample_period).round() as usize);
        let (segments, scored) =
            plan.validation_scored(&record.input, warm_up, !self.keep_rest_and_steps);
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
        Ok((segments.steps, scored))
    }
}

/// Sample ranges as times, at most six of them.
fn describe_ranges(ranges: &[std::ops::Range<usize>], dt: f64) -> String {
    if ranges.is_empty() {
        return "none".to_owned();
    }
    let mut parts: Vec<String> = ranges
        .iter()
        .take(6)
        .map(|r| format!("{:.3}-{:.3} s", r.start as f64 * dt, r.end as f64 * dt))
        .collect();
    if ranges.len() > 6 {
        parts.push(format!("and {} more", ranges.len() - 6));
    }
    parts.join(", ")
}

fn print_plan(plan: &Plan, name: &str) {
    let dt = plan.sample_period;
    if plan.has_scored_part() {
        println!(
            "fit part: {:.3}-{:.3} s (samples 0..{}); scored part: {:.3}-{:.3} s (samples {}..{}), the models' state carried over from the fit part",
            0.0,
            plan.fit_end as f64 * dt,
            plan.fit_end,
            plan.fit_end as f64 * dt,
            plan.samples as f64 * dt,
            plan.fit_end,
            plan.samples
        );
    } else {
        println!(
            "fit part: the whole of {name} (give --split or --validate-from to score a part of it)"
        );
    }
    let steps: Vec<String> = plan
        .segments
        .steps
        .iter()
        .map(|s| format!("{:.3} s", *s as f64 * dt))
        .collect();
    println!(
        "rest segments: {}; voltage steps: {}",
        describe_ranges(&plan.segments.rests, dt),
        if steps.is_empty() {
            "none".to_owned()
        } else {
            steps.join(", ")
        }
    );
    let fitted = plan.fitted().iter().filter(|f| **f).count();
    println!(
        "left out of the fit (warm-up: settling {:.3} s and first loading; rests; settling after steps): {}; {fitted} of {} samples fitted",
        plan.thresholds.settle_samples as f64 * dt,
        describe_ranges(&plan.fit_excluded, dt),
        plan.fit_end
    );
    if plan.has_scored_part() {
        let scored = plan.scored().iter().filter(|s| **s).count();
        println!(
            "left out of the score (rests, settling after steps): {}; {scored} of {} samples scored",
            describe_ranges(&plan.scored_excluded, dt),
            plan.samples - plan.fit_end
        );
    }
}

/// How far the values at the scored samples reach beyond those at the
/// fitted ones, as a fraction of the fitted span (0 inside).
fn range_excess(values: &[f64], fitted: &[bool], scored: &[bool]) -> f64 {
    let range = |flags: &[bool]| {
        values
            .iter()
            .zip(flags)
            .filter(|(_, f)| **f)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (v, _)| {
                (lo.min(*v), hi.max(*v))
            })
    };
    let (fit_low, fit_high) = range(fitted);
    let (low, high) = range(scored);
    let span = fit_high - fit_low;
    if span.is_nan() || span <= 0.0 || !low.is_finite() {
        return 0.0;
    }
    ((fit_low - low).max(high - fit_high) / span).max(0.0)
}

fn print_extrapolation(what: &str, excess: f64) {
    if excess > 0.01 {
        println!(
            "note: the scored {what} reaches {:.1} % of the fitted span beyond the fitted range; the models extrapolate there",
            100.0 * excess
        );
    }
}

fn inverse_pi(args: &InversePiArgs) -> Result<(), String> {
    let loaded = load(&args.file, &args.columns)?;
    // The validation file is read before the fit: a typo costs nothing.
    let validation = match &args.protocol.validate {
        Some(path) => Some(load(path, &args.columns)?),
        None => None,
    };
    let plan = args.protocol.plan(&loaded, None)?;
    let validation_scored = match &validation {
        Some(v) => Some(args.protocol.validation_scored(&plan, v)?),
        None => None,
    };
    if args.starts == 0 {
        return Err("--starts: give at least 1".to_owned());
    }
    let settings = InversePiSettings {
        starts: args.starts,
        seed: args.seed,
        max_iterations: args.max_iterations,
        screening: if args.no_screening {
            None
        } else {
            InversePiSettings::default().screening
        },
        decimation: auto_or(
            &args.decimation,
            |t| t.parse::<usize>().ok().filter(|m| *m >= 1),
            "a whole number of samples, 1 or more",
        )
        .map_err(|e| format!("--decimation: {e}"))?,
        smoothing: auto_or(
            &args.smooth,
            |t| t.parse::<usize>().ok(),
            "a half width in samples, 0 or more",
        )
        .map_err(|e| format!("--smooth: {e}"))?,
        rate_dependent: match args.weights.as_str() {
            "rate-dependent" => Some(true),
            "constant" => Some(false),
            _ => None,
        },
        offset: auto_or(
            &args.offset,
            |t| t.parse::<f64>().ok().filter(|v| v.is_finite()),
            "a displacement in µm",
        )
        .map_err(|e| format!("--offset: {e}"))?,
    };
    let record = &loaded.record;
    let dt = record.sample_period;
    println!("{}", describe(record, &loaded.name));
    if let Some(columns) = &loaded.columns {
        println!("columns: {}", describe_columns(columns));
    }
    print_plan(&plan, &loaded.name);

    let reporter = Reporter::new();
    let fit = identify_inverse_pi(record, &plan, &settings, &|e| reporter.event(e))
        .map_err(|e| format!("{}: {e}", loaded.name))?;
    reporter.finish();

    print_inverse_pi_choices(&fit, &plan, &settings, dt);
    println!(
        "\nerrors of the voltage each model gives for the measured displacement (RMS, largest; % of the fit part's input span {:.6} V):",
        fit.input_span
    );
    print_inverse_pi_errors("fit part", &fit.fit_errors);
    if let Some(unseen) = &fit.unseen {
        print_inverse_pi_errors("scored part (not seen by the fit)", unseen);
        let y = centred_moving_average(&record.output, fit.smoothing);
        print_extrapolation(
            "displacement",
            range_excess(&y, &pad(&plan.fitted(), plan.samples), &plan.scored()),
        );
    }
    let mut validation_errors = None;
    if let (Some(v), Some((steps, scored))) = (&validation, &validation_scored) {
        println!("\n{}", describe(&v.record, &v.name));
        let errors = fit.errors_on(
            &v.record.output,
            &v.record.input,
            v.record.sample_period,
            steps,
            scored,
        );
        print_inverse_pi_errors("validation file (models from rest at its start)", &errors);
        validation_errors = Some(errors);
    }
    println!("time: {:.2} s", fit.seconds);

    if let Some(out) = &args.out {
        write_json(
            out,
            &serde_json::json!({
                "model": "modified inverse Prandtl-Ishlinskii (seed 000 eq. 3-5): voltage from displacement",
                "params": fit.params,
                "displacement_offset_um": fit.offset,
                "smoothing_half_width_samples": fit.smoothing,
                "sample_period_s": dt,
                "columns": loaded.columns,
            }),
        )?;
        println!("model written to {}", out.display());
    }
    if let Some(path) = &args.protocol.report {
        write_json(
            path,
            &serde_json::json!({
                "record": loaded.name,
                "columns": loaded.columns,
                "plan": plan,
                "settings": settings,
                "identification": fit,
                "validation": validation.as_ref().map(|v| serde_json::json!({
                    "file": v.name,
                    "errors": validation_errors,
                })),
            }),
        )?;
        println!("report written to {}", path.display());
    }
    Ok(())
}

/// `flags` of the fit part, extended with `false` to `len` samples.
fn pad(flags: &[bool], len: usize) -> Vec<bool> {
    let mut padded = flags.to_vec();
    padded.resize(len, false);
    padded
}

fn print_inverse_pi_choices(
    fit: &InversePiIdentification,
    plan: &Plan,
    settings: &InversePiSettings,
    dt: f64,
) {
    let smoothing = |h: usize| {
        if h == 0 {
            "none".to_owned()
        } else {
            format!(
                "{} samples ({:.1} ms)",
                2 * h + 1,
                1e3 * (2 * h + 1) as f64 * dt
            )
        }
    };
    let weights = |rate: bool| if rate { "rate-dependent" } else { "constant" };
    if let Some(cv) = &fit.cross_validation {
        println!(
            "\nvalidation inside the fit part: (c, w_s) searched on its first {} fitted samples (to {:.3} s), every candidate's linear part fitted there and scored on the last {} [V RMS]:",
            cv.train_samples,
            cv.train_end as f64 * dt,
            cv.validation_samples
        );
        println!(
            "  {:<28} {:<16} {:>12}",
            "moving average", "backlash weights", "RMS [V]"
        );
        for c in &cv.proposed {
            println!(
                "  {:<28} {:<16} {:>12.6}",
                smoothing(c.smoothing),
                weights(c.rate_dependent),
                c.validation_rms
            );
        }
        for c in &cv.classical {
            println!(
                "  {:<28} {:<16} {:>12.6}",
                smoothing(c.smoothing),
                "classical P-I",
                c.validation_rms
            );
        }
    }
    let by = |validated: bool| {
        if validated {
            "chosen by that validation"
        } else {
            "given"
        }
    };
    println!(
        "\nproposed model: moving average {} ({}); {} backlash weights ({}{}); classical P-I: moving average {}",
        smoothing(fit.smoothing),
        by(fit.smoothing_validated),
        weights(fit.rate_dependent),
        by(fit.weights_validated),
        if fit.weights_validated {
            ", rate dependence only if it lowers that error by more than 5 %"
        } else {
            ""
        },
        smoothing(fit.classical_smoothing)
    );
    if let Some(cycle) = plan.fastest_cycle {
        println!("fastest cycle of the input: {:.3} s", cycle * dt);
    }
    let polished = fit.starts.iter().filter(|s| s.polished).count();
    println!(
        "search: every {} sample(s), {} starts ({}), seed {}; best start {}, F {:.6e} on the searched samples",
        fit.decimation,
        settings.starts,
        match settings.screening {
            Some(s) => format!(
                "{} iterations each, the best {} run on to convergence",
                s.iterations,
                polished.min(s.kept)
            ),
            None => "each to convergence".to_owned(),
        },
        settings.seed,
        fit.best_start.unwrap_or(0),
        fit.best_start
            .and_then(|b| fit.starts.get(b))
            .map_or(f64::NAN, |s| s.objective)
    );
    println!(
        "displacement offset {:.6} um; c = {:.6} um, u1max = {:.6}; classical P-I offset {:.6} um",
        fit.offset, fit.params.c, fit.params.u1max, fit.classical_offset
    );
}

fn print_figure(name: &str, e: &ErrorFigures, unit: &str) {
    println!(
        "  {name:<16} RMS {:.6} {unit} ({:.3} %), largest {:.6} {unit} ({:.3} %)",
        e.rms, e.rms_percent, e.max_abs, e.max_percent
    );
}

fn print_inverse_pi_errors(part: &str, e: &InversePiErrors) {
    println!("{part}, {} samples:", e.proposed.samples);
    print_figure("proposed", &e.proposed, "V");
    print_figure("classical P-I", &e.classical, "V");
    print_figure("straight line", &e.line, "V");
}

/// One line on the spread of the random starts.
fn print_starts(starts: &[StartResult], max_iterations: u64) {
    let mut objectives: Vec<f64> = starts.iter().map(|s| s.objective).collect();
    objectives.sort_by(f64::total_cmp);
    let mut iterations: Vec<u64> = starts.iter().map(|s| s.iterations).collect();
    iterations.sort_unstable();
    let best = objectives[0];
    println!(
        "  starts: F on the searched samples best {:.6e}, median {:.6e}, worst {:.6e}; {} of {} within 0.1 % of the best; \
         iterations median {} ({} stopped at the cap of {max_iterations})",
        best,
        objectives[objectives.len() / 2],
        objectives[objectives.len() - 1],
        objectives.iter().filter(|f| **f <= best * 1.001).count(),
        starts.len(),
        iterations[iterations.len() / 2],
        iterations.iter().filter(|i| **i >= max_iterations).count()
    );
}

fn compare(args: &CompareArgs) -> Result<(), String> {
    let (record, name, offset, default_decimation) = if args.synthetic {
        let record = synthetic_plant_record(IDENTIFICATION_DURATION, PLANT_SAMPLE_RATE)
            .map_err(|e| format!("stage preset: {e}"))?;
        (
            record,
            "synthetic: seed 000 eq. (6) on FlexureStage y, 10 s at 10 kHz".to_owned(),
            0.0,
            SYNTHETIC_DECIMATION,
        )
    } else {
        let path = args
            .file
            .as_ref()
            .expect("clap requires a file without --synthetic");
        let record = read(path, &args.columns.read_options()?)?;
        let warm_up = (args.search.warm_up / record.sample_period).round() as usize;
        let smoothed = centred_moving_average(&record.output, args.search.smooth);
        let offset = resolve_offset(&args.offset, &smoothed, warm_up)?;
        (record, path.display().to_string(), offset, 1)
    };
    let options = args
        .search
        .options(record.sample_period, default_decimation);
    let y = shifted(
        &centred_moving_average(&record.output, args.search.smooth),
        offset,
    );
    let u = &record.input;
    println!("{}", describe(&record, &name));
    println!(
        "displacement offset {offset:.6} um; search on every {} sample(s) ({:.1} Hz); F on all {} scored samples",
        options.decimation,
        1.0 / (record.sample_period * options.decimation as f64),
        y.len() - options.warm_up_samples
    );
    let bar = progress_bar(3 * options.starts, "fitting three models");
    let tick = |_: &StartResult| bar.inc(1);
    let comparison = compare_inverse_models(
        &y,
        u,
        record.sample_period,
        &options,
        args.repetitions,
        &tick,
    )
    .map_err(|e| format!("{name}: {e}"))?;
    bar.finish_and_clear();

    println!(
        "\nbest of {} random starts each (seed {}); F = sum of squared voltage errors (eq. 7)",
        options.starts, options.seed
    );
    println!(
        "{:<44} {:>6} {:>14} {:>12} {:>12} {:>16}",
        "model", "params", "F [V^2]", "RMS [V]", "max [V]", "eval [ns/sample]"
    );
    for s in &comparison.summaries {
        println!(
            "{:<44} {:>6} {:>14.6e} {:>12.6} {:>12.6} {:>16.2}",
            s.name,
            s.parameter_count,
            s.objective,
            s.rms_volts,
            s.max_abs_volts,
            s.evaluation.median_ns_per_sample
        );
    }
    println!(
        "\nevaluation time: median of {} streaming passes over the record (fastest..slowest):",
        args.repetitions
    );
    for s in &comparison.summaries {
        println!(
            "  {:<44} {:.2}..{:.2} ns/sample",
            s.name, s.evaluation.fastest_ns_per_sample, s.evaluation.slowest_ns_per_sample
        );
    }
    println!("\nrandom starts of each model:");
    let fits = [
        &comparison.proposed.starts,
        &comparison.traditional_six.starts,
        &comparison.traditional_ten.starts,
    ];
    for (s, starts) in comparison.summaries.iter().zip(fits) {
        println!("{}", s.name);
        print_starts(starts, options.max_iterations);
    }
    let p = &comparison.proposed.params;
    println!(
        "\nproposed model: c = {:.6} um, u1max = {:.6} um, ws = {:?}, a = {:?}",
        p.c, p.u1max, p.ws, p.a
    );
    Ok(())
}

/// Decimation of the plant's 10 kHz eq. (6) records for the search (500 Hz).
const STAGE_DECIMATION: usize = 20;

fn stage(args: &StageArgs) -> Result<(), String> {
    if args.search.smooth != 0 {
        return Err(
            "--smooth: the stage's records are simulated and not smoothed; leave it out".to_owned(),
        );
    }
    let plant = open_plant(&args.plant, args.plant_parameters.as_deref())?;
    let options = args
        .search
        .options(piezo_identify::stage::SAMPLE_PERIOD, STAGE_DECIMATION);
    let bar = progress_bar(options.starts, "");
    let step = |message: &str| {
        bar.reset();
        bar.set_message(message.to_owned());
        if bar.is_hidden() {
            eprintln!("{message}");
        }
    };
    let tick = |_: usize| bar.inc(1);
    let range: Vec<f64> = args
        .command_range
        .split(',')
        .map(|v| v.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<Vec<f64>>>()
        .filter(|v| v.len() == 2 && v[0] < v[1])
        .ok_or_else(|| {
            format!(
                "--command-range {}: give MIN,MAX in V with MIN < MAX, e.g. -2,12",
                args.command_range
            )
        })?;
    let held: Vec<f64> = args
        .held
        .split(',')
        .map(|v| v.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<Vec<f64>>>()
        .filter(|v| v.len() == 2)
        .ok_or_else(|| format!("--held {}: give X,Y in um, e.g. 0,0", args.held))?;
    for (name, value) in [("--gain-scale", args.gain_scale), ("--scale", args.scale)] {
        if !(value.is_finite() && value > 0.0) {
            return Err(format!("{name} {value}: give a positive factor"));
        }
    }
    let conditions = StageConditions {
        gain_scale: args.gain_scale,
        command_range: (range[0], range[1]),
        held_um: [held[0], held[1]],
        ..StageConditions::scaled(args.scale, !args.no_rotation)
    };
    let identified = identify_stage(&plant, &options, args.rounds, &conditions, &step, &tick)
        .map_err(|e| format!("{}: {e}", args.plant.display()))?;
    bar.finish_and_clear();
    for (name, fit) in [("x", &identified.x_fit), ("y", &identified.y_fit)] {
        println!(
            "{name} inverse model on eq. (6): F = {:.6e} V^2, RMS {:.6} V, max {:.6} V",
            fit.f, fit.rms_v, fit.max_v
        );
    }
    for (name, rms) in &identified.bouc_wen_fits {
        println!("{name} Bouc-Wen model on seed 001's 2 Hz sine: eq. (5) RMS {rms:.6} um");
    }
    for (round, compensations) in identified.rounds.iter().enumerate() {
        println!("decoupling round {}:", round + 1);
        for (i, c) in compensations.iter().enumerate() {
            println!(
                "  D{}: dk {:+.6}, db {:+.6} um, p {:+.4}, q {:+.4}; coupling span {:.4} um -> residual span {:.4} um (RMS {:.4})",
                i + 1,
                c.dk,
                c.db,
                c.p,
                c.q,
                c.error_span,
                c.residual_span,
                c.residual_rms
            );
        }
    }
    let json = serde_json::to_string_pretty(&identified.controller)
        .map_err(|e| format!("cannot serialise the preset: {e}"))?;
    std::fs::write(&args.out, json + "\n").map_err(|e| format!("{}: {e}", args.out.display()))?;
    println!("controller preset written to {}", args.out.display());
    if let Some(path) = &args.report {
        let json = serde_json::to_string_pretty(&identified)
            .map_err(|e| format!("cannot serialise the report: {e}"))?;
        std::fs::write(path, json + "\n").map_err(|e| format!("{}: {e}", path.display()))?;
        println!("identification report written to {}", path.display());
    }
    Ok(())
}

fn decoupling(args: &DecouplingArgs) -> Result<(), String> {
    let options = ReadOptions {
        input: Column::parse(&args.demand),
        output: Column::parse(&args.error),
        // The fit is static: the sampling does not matter.
        sampling: Sampling::Rate(1.0),
    };
    let record = read(&args.file, &options)?;
    let c = fit_compensation(&record.input, &record.output)
        .map_err(|e| format!("{}: {e}", args.file.display()))?;
    println!(
        "{}: {} pairs; D(f) = clamp({:.6}*f {:+.6}, q = {:.6}, p = {:.6})",
        args.file.display(),
        record.input.len(),
        c.dk,
        c.db,
        c.q,
        c.p
    );
    println!(
        "coupling error span {:.6} um; residual span {:.6} um, RMS {:.6} um",
        c.error_span, c.residual_span, c.residual_rms
    );
    Ok(())
}

/// Parses `name=lo:hi` pairs into `bounds` (the shape of
/// `bouc_wen_fit::SHAPE_PARAMETERS`).
fn parse_shape_bounds(text: &str, bounds: &mut Bounds) -> Result<(), String> {
    for item in text.split(',').map(str::trim).filter(|i| !i.is_empty()) {
        let problem = |why: &str| format!("--bounds {item}: {why}");
        let (name, range) = item
            .split_once('=')
            .ok_or_else(|| problem("write name=lower:upper"))?;
        let index = SHAPE_PARAMETERS
            .iter()
            .position(|p| *p == name.trim())
            .ok_or_else(|| {
                problem(&format!(
                    "the parameters are {}",
                    SHAPE_PARAMETERS.join(", ")
                ))
            })?;
        let (lo, hi) = range
            .split_once(':')
            .ok_or_else(|| problem("write name=lower:upper"))?;
        let number = |t: &str| {
            t.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| problem(&format!("{t:?} is not a finite number")))
        };
        let (lo, hi) = (number(lo)?, number(hi)?);
        if lo >= hi {
            return Err(problem("lower must be below upper"));
        }
        bounds.lower[index] = lo;
        bounds.upper[index] = hi;
    }
    Ok(())
}

/// The identification record of `bouc-wen`: a file or a plant run, and the
/// defaults that differ between them (decimation, warm-up seconds).
fn bouc_wen_record(args: &BoucWenArgs) -> Result<(Loaded, Option<usize>, Option<f64>), String> {
    if let Some(path) = &args.plant {
        // The run starts from a stage never cycled (FlexureStage's
        // `rest_cycle_voltage` = 0): every hysteretic state at h = 0, the
        // state the fitted model starts from. A stage resting after a cycle
        // sits on that cycle's loop, which a model started from h = 0 reaches
        // only after several periods (Bouc-Wen minor loops do not close).
        let plant = open_plant(path, args.plant_parameters.as_deref())?
            .with_parameters(&[("rest_cycle_voltage".to_owned(), ParameterValue::Number(0.0))])
            .map_err(|e| e.to_string())?;
        let axis = if args.drive == "x" {
            RecordAxis::X
        } else {
            RecordAxis::Y
        };
        for (name, value) in [
            ("--frequency", args.frequency),
            ("--peak", args.peak),
            ("--periods", args.periods),
            ("--plant-rate", args.plant_rate),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!("{name} must be positive (got {value})"));
            }
        }
        let (driven, coupled) = sine_records(
            &plant,
            axis,
            args.frequency,
            args.peak,
            args.periods,
            args.plant_rate,
        )
        .map_err(|e| e.to_string())?;
        let record = if args.read == "coupled" {
            coupled
        } else {
            driven
        };
        let name = format!(
            "{} driving {} with a {} Hz sine 0..{} V, reading the {} displacement",
            path.display(),
            args.drive,
            args.frequency,
            args.peak,
            args.read
        );
        // A plant run has no rest and no step and its first period is the
        // warm-up; 1000 samples per period searched at the default rate.
        Ok((
            Loaded {
                name,
                record,
                columns: None,
            },
            Some(10),
            Some(1.0 / args.frequency),
        ))
    } else {
        let path = args.file.as_ref().expect("clap requires a file or --plant");
        Ok((load(path, &args.columns)?, None, None))
    }
}

fn print_forward_errors(part: &str, e: &ForwardErrors, refined: bool, scored_line: bool) {
    println!("{part}, {} samples:", e.bouc_wen.samples);
    if refined {
        print_figure("Bouc-Wen", &e.bouc_wen, "um");
        print_figure("GA-PSO only", &e.gapso, "um");
    } else {
        print_figure("Bouc-Wen", &e.bouc_wen, "um");
    }
    print_figure("classical P-I", &e.classical, "um");
    print_figure("straight line", &e.line, "um");
    if scored_line {
        print_figure("best line here", &e.best_line, "um");
    }
}

fn bouc_wen(args: &BoucWenArgs) -> Result<(), String> {
    let (loaded, default_decimation, default_warm_up) = bouc_wen_record(args)?;
    // The validation file is read before the fit: a typo costs nothing.
    let validation = match &args.protocol.validate {
        Some(path) => Some(load(path, &args.columns)?),
        None => None,
    };
    let plan = args.protocol.plan(&loaded, default_warm_up)?;
    let validation_scored = match &validation {
        Some(v) => Some(args.protocol.validation_scored(&plan, v)?),
        None => None,
    };
    let mut bounds = if args.wide_bounds {
        wide_shape_bounds()
    } else {
        default_shape_bounds()
    };
    if let Some(text) = &args.bounds {
        parse_shape_bounds(text, &mut bounds)?;
    }
    let settings = BoucWenSettings {
        gapso: GaPsoOptions {
            population: args.population,
            generations: args.generations,
            seed: args.seed,
            ..GaPsoOptions::default()
        },
        bounds,
        decimation: args.decimation.or(default_decimation),
        smoothing: args.smooth,
        fit_offset: !args.no_offset,
        monotone: args.monotone,
        refine: !args.no_refine,
    };
    if settings.decimation == Some(0) {
        return Err("--decimation: give a whole number of samples, 1 or more".to_owned());
    }
    let record = &loaded.record;
    let dt = record.sample_period;
    println!("{}", describe(record, &loaded.name));
    if let Some(columns) = &loaded.columns {
        println!("columns: {}", describe_columns(columns));
    }
    print_plan(&plan, &loaded.name);

    let reporter = Reporter::new();
    let fit = identify_bouc_wen_protocol(record, &plan, &settings, &|e| reporter.event(e))
        .map_err(|e| format!("{}: {e}", loaded.name))?;
    reporter.finish();
    print_bouc_wen_fit(&fit, &settings);

    println!(
        "\nerrors of the displacement each model gives for the measured input (RMS, largest; % of the fit part's stroke {:.6} um):",
        fit.stroke
    );
    let refined = fit.identification.refinement_kept;
    print_forward_errors("fit part", &fit.fit_errors, refined, false);
    if let Some(unseen) = &fit.unseen {
        print_forward_errors("scored part (not seen by the fit)", unseen, refined, true);
        print_extrapolation(
            "input",
            range_excess(
                &record.input,
                &pad(&plan.fitted(), plan.samples),
                &plan.scored(),
            ),
        );
    }
    let mut validation_errors = None;
    if let (Some(v), Some((_, scored))) = (&validation, &validation_scored) {
        println!("\n{}", describe(&v.record, &v.name));
        let errors = fit.errors_on(
            &v.record.input,
            &v.record.output,
            v.record.sample_period,
            scored,
        );
        print_forward_errors(
            "validation file (models from rest at its start)",
            &errors,
            refined,
            true,
        );
        validation_errors = Some(errors);
    }
    println!("time: {:.2} s", fit.seconds);

    let best = fit.identification.best();
    if let Some(out) = &args.out {
        write_json(
            out,
            &serde_json::json!({
                "model": "asymmetric Bouc-Wen (seed 001 eq. 3-4): displacement from voltage, plus the sensor offset",
                "params": best.params,
                "sensor_offset_um": best.offset,
                "sample_period_s": dt,
                "columns": loaded.columns,
            }),
        )?;
        println!("model written to {}", out.display());
    }
    if let Some(path) = &args.protocol.report {
        write_json(
            path,
            &serde_json::json!({
                "record": loaded.name,
                "columns": loaded.columns,
                "plan": plan,
                "settings": settings,
                "options": fit.options,
                "identification": fit.identification,
                "classical": fit.classical,
                "line": fit.line,
                "stroke": fit.stroke,
                "fit_errors": fit.fit_errors,
                "unseen": fit.unseen,
                "validation": validation.as_ref().map(|v| serde_json::json!({
                    "file": v.name,
                    "errors": validation_errors,
                })),
                "seconds": fit.seconds,
            }),
        )?;
        println!("report written to {}", path.display());
    }
    Ok(())
}

fn print_bouc_wen_fit(fit: &BoucWenProtocolFit, settings: &BoucWenSettings) {
    let identification = &fit.identification;
    println!(
        "\nGA-PSO: {} particles, {} generations ({} evaluations), seed {}, every {} sample(s): {:.2} s; eq. (5) RMS {:.6} um on the fitted samples",
        settings.gapso.population,
        identification.history.len(),
        identification.gapso_evaluations,
        settings.gapso.seed,
        fit.options.decimation,
        identification.gapso_seconds,
        identification.gapso.rms
    );
    if settings.refine {
        println!(
            "Levenberg-Marquardt inside the search box: {} evaluations, {:.2} s, RMS {} um: {}",
            identification.refinement_evaluations,
            identification.refinement_seconds,
            identification
                .refinement_rms
                .map_or("(no usable result)".to_owned(), |r| format!("{r:.6}")),
            if identification.refinement_kept {
                "kept (lower on the fit part)"
            } else {
                "not kept (no lower on the fit part)"
            }
        );
    }
    let best = identification.best();
    let p = &best.params;
    println!(
        "model: p {:.6e}, q {:+.0}, A {:.6e}, beta {:.6e}, gamma {:.6e}, n {:.4}, delta {:.6e}; sensor offset {:.6} um",
        p.p, p.q, p.a, p.beta, p.gamma, p.n, p.delta, best.offset
    );
}

fn write_lab_record(args: &LabRecordArgs) -> Result<(), String> {
    use piezo_identify::lab_records::{Drive, Excitation, LabRecordSpec, lab_record};
    let spec = LabRecordSpec {
        sample_rate: args.rate,
        drive: if args.drive == "bipolar" {
            Drive::Bipolar
        } else {
            Drive::Unipolar
        },
        excitation: if args.sweep > 0.0 {
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
    let record = lab_record(&spec).map_err(|e| e.to_string())?;
    let mut text = String::from("time_s,command_V,displacement_um\n");
    for (n, (u, y)) in record.input.iter().zip(&record.output).enumerate() {
        text.push_str(&format!("{},{u},{y}\n", n as f64 * record.sample_period));
    }
    std::fs::write(&args.out, text).map_err(|e| format!("{}: {e}", args.out.display()))?;
    println!(
        "{}: {} samples at {} Hz (columns time_s, command_V, displacement_um)",
        args.out.display(),
        record.input.len(),
        args.rate
    );
    Ok(())
}

fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<(), String> {
    let json = serde_json::to_string_pretty(value)
        .map_err(|e| format!("cannot serialise {}: {e}", path.display()))?;
    std::fs::write(path, json + "\n").map_err(|e| format!("{}: {e}", path.display()))
}

fn xy200s_preset(args: &Xy200sPresetArgs) -> Result<(), String> {
    let preset = piezo_identify::xy200s::xy200s_preset().map_err(|e| e.to_string())?;
    for model in &preset.models {
        let p = &model.identified;
        println!(
            "{}: printed model spans {:.3} um on the 2 Hz 0..150 V run; rate-independent fit RMS {:.4} um ({:.3} %); output scaled by {:.4}",
            model.name,
            model.printed_span_um,
            model.rms_um,
            100.0 * model.rms_um / model.printed_span_um,
            model.stroke_scale
        );
        println!(
            "    p {:.6e}, q {:+.0}, A {:.6e}, beta {:.6e}, gamma {:.6e}, n {:.4}, delta {:.6e}",
            p.p, p.q, p.a, p.beta, p.gamma, p.n, p.delta
        );
    }
    write_json(&args.out, &preset.stage)?;
    println!("stage parameters written to {}", args.out.display());
    if let Some(report) = &args.report {
        write_json(report, &preset.models)?;
        println!("conversion report written to {}", report.display());
    }
    Ok(())
}

/// Opens a plant FMU, loaded with the parameter set at `parameters` if given.
fn open_plant(path: &Path, parameters: Option<&Path>) -> Result<PlantFmu, String> {
    let plant = PlantFmu::open(path).map_err(|e| e.to_string())?;
    match parameters {
        Some(set) => plant
            .with_parameters(&read_parameter_set(set)?)
            .map_err(|e| e.to_string()),
        None => Ok(plant),
    }
}

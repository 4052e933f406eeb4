//! `piezo-identify`: fits seed 000's modified inverse P-I model to a
//! voltage/displacement record, validates it on a second record, and runs the
//! paper's model comparison. All I/O lives here; the library does the math.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Mutex;

use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use piezo_identify::bouc_wen_fit::{
    BoucWenFitOptions, BoucWenModelFit, PredictionError, SHAPE_PARAMETERS, default_shape_bounds,
    identify_bouc_wen, predict, prediction_error, wide_shape_bounds,
};
use piezo_identify::compare::{
    IDENTIFICATION_DURATION, PLANT_SAMPLE_RATE, compare_inverse_models, synthetic_plant_record,
};
use piezo_identify::decoupling::fit_compensation;
use piezo_identify::fit::{FitQuality, score};
use piezo_identify::gapso::{Bounds, GaPsoOptions};
use piezo_identify::plant::{PlantFmu, RecordAxis, read_parameter_set, sine_records};
use piezo_identify::stage::{StageConditions, identify_stage};
use piezo_identify::validation::{
    ErrorReport, ScaleReference, centred_moving_average, displacement_offset, shifted,
};
use piezo_identify::{
    ClassicalPi, Column, FitOptions, ReadOptions, Record, Sampling, StartResult, fit_classical_pi,
    fit_modified_inverse_pi_with_progress, read_record,
};
use piezo_models::ModifiedInversePi;

#[derive(Parser)]
#[command(
    name = "piezo-identify",
    version,
    about = "Identify seed 000's modified inverse Prandtl-Ishlinskii model from voltage/displacement data"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fit the proposed modified inverse P-I model (seed 000 eq. 3-5), with the
    /// classical P-I model as a baseline; optionally validate on a second file.
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
    /// RMS of eq. (5), then refine it by Levenberg-Marquardt; from a record
    /// (voltage, displacement) or from a plant FMU driven by seed 001 §5.2's
    /// sine. Also fits the coupling models H_XY, H_YX: give the coupled
    /// displacement as the output (or --read coupled).
    BoucWen(BoucWenArgs),
    /// Build seed 001's XY200S stage as a FlexureStage parameter set from
    /// the printed Tables 1-2 (units and conversion: piezo_identify::xy200s).
    Xy200sPreset(Xy200sPresetArgs),
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
    /// Validation record (same columns and sampling), not used by the fit.
    #[arg(long, conflicts_with = "plant")]
    validate: Option<PathBuf>,
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
    /// default 1 for a file, 10 for a plant run.
    #[arg(long)]
    decimation: Option<usize>,
    /// Seconds at the start that drive the model but are not fitted nor
    /// scored; default 0 for a file, one period for a plant run.
    #[arg(long)]
    warm_up: Option<f64>,
    /// Half width [samples] of a centred moving average applied to the
    /// displacement before fitting and evaluation (0: none).
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
    /// Write the fitted parameters (piezo_models::BoucWenParams) as JSON.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write the whole identification (both fits, offset, history, times,
    /// validation errors) as JSON.
    #[arg(long)]
    report: Option<PathBuf>,
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
    /// Home of the single-axis runs, "X,Y" in um (seed 000's stage: 8,7).
    #[arg(long, default_value = "8,7")]
    home: String,
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
    #[arg(long, default_value_t = 0.0)]
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
    search: SearchArgs,
    /// Displacement offset [µm] subtracted from every record, or "auto": the
    /// smallest displacement of the identification record after the warm-up.
    #[arg(long, default_value = "auto")]
    offset: String,
    /// Validation record (same columns and sampling), not used by the fit.
    #[arg(long)]
    validate: Option<PathBuf>,
    /// Write the fitted parameters (piezo_models::InversePiParams) as JSON.
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
    #[arg(long, default_value = "auto")]
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
    progress_bar_of(total, message, "starts")
}

/// As [`progress_bar`], counting `unit`.
fn progress_bar_of(total: usize, message: &str, unit: &str) -> ProgressBar {
    let target = if std::io::stderr().is_terminal() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    };
    let bar = ProgressBar::with_draw_target(Some(total as u64), target);
    bar.set_style(
        ProgressStyle::with_template(&format!(
            "{{msg}} [{{bar:30}}] {{pos}}/{{len}} {unit}, {{elapsed}}"
        ))
        .expect("the template is valid")
        .progress_chars("=> "),
    );
    bar.set_message(message.to_owned());
    bar
}

fn describe(record: &Record, path: &str) -> String {
    format!(
        "{path}: {} samples, {:.2} s at {:.6} Hz",
        record.input.len(),
        record.input.len() as f64 * record.sample_period,
        1.0 / record.sample_period
    )
}

fn inverse_pi(args: &InversePiArgs) -> Result<(), String> {
    let read_options = args.columns.read_options()?;
    let record = read(&args.file, &read_options)?;
    let options = args.search.options(record.sample_period, 1);
    let smoothed = centred_moving_average(&record.output, args.search.smooth);
    let offset = resolve_offset(&args.offset, &smoothed, options.warm_up_samples)?;
    let y = shifted(&smoothed, offset);
    let u = &record.input;
    let dt = record.sample_period;

    println!("{}", describe(&record, &args.file.display().to_string()));
    println!(
        "displacement: centred moving average over {} samples, then offset {offset:.6} um subtracted; \
         first {} samples ({} s) run the models but are not fitted nor scored",
        2 * args.search.smooth + 1,
        options.warm_up_samples,
        args.search.warm_up
    );
    let bar = progress_bar(options.starts, "proposed model");
    let best_so_far = Mutex::new(f64::INFINITY);
    let tick = |start: &StartResult| {
        let mut best = best_so_far.lock().expect("no panics while held");
        *best = best.min(start.objective);
        bar.set_message(format!("proposed model, best F {:.6e}", *best));
        bar.inc(1);
    };
    let proposed = fit_modified_inverse_pi_with_progress(&y, u, dt, &options, &tick)
        .map_err(|e| format!("{}: {e}", args.file.display()))?;
    bar.finish_and_clear();
    let classical = fit_classical_pi(&y, u, dt, &options)
        .map_err(|e| format!("{}: {e}", args.file.display()))?;

    let reference = ScaleReference::of(u, &y, options.warm_up_samples);
    println!(
        "yardstick (identification record): input span {:.6} V, stroke {:.6} um, mean gain {:.6} um/V",
        reference.input_span,
        reference.stroke,
        reference.mean_gain()
    );
    let p = &proposed.params;
    println!(
        "\nproposed modified inverse P-I (seed 000 eq. 3-5, {} backlash weights), best of {} starts (seed {}, best start {}):",
        if options.rate_dependent {
            "rate-dependent (eq. 4)"
        } else {
            "constant"
        },
        options.starts,
        options.seed,
        proposed.best_start.unwrap_or(0)
    );
    print_starts(&proposed.starts, options.max_iterations);
    println!("  c = {:.9} um, u1max = {:.9} um", p.c, p.u1max);
    println!("  ws = {:?}", p.ws);
    println!("  a  = {:?}", p.a);
    println!("  k  = {:?}", p.k);
    println!("  b  = {:?}", p.b);
    println!(
        "classical P-I (10 backlash on y, constant weights, offset): offset {:.6} V, weights {:?}",
        classical.params.offset, classical.params.weights
    );

    println!(
        "\nidentification record ({} scored samples):",
        proposed.quality.samples
    );
    print_errors("proposed", &proposed.quality, &reference);
    print_errors("classical", &classical.quality, &reference);

    if let Some(path) = &args.validate {
        let validation = read(path, &read_options)?;
        let y_validation = shifted(
            &centred_moving_average(&validation.output, args.search.smooth),
            offset,
        );
        let warm_up = (args.search.warm_up / validation.sample_period).round() as usize;
        println!("\n{}", describe(&validation, &path.display().to_string()));
        println!(
            "validation record (not seen by the fit; same offset; models from the de-energized state; {} scored samples):",
            validation.input.len().saturating_sub(warm_up)
        );
        let proposed_quality = score(
            &mut ModifiedInversePi::new(proposed.params),
            &y_validation,
            &validation.input,
            validation.sample_period,
            warm_up,
        );
        let classical_quality = score(
            &mut ClassicalPi::new(classical.params),
            &y_validation,
            &validation.input,
            validation.sample_period,
            warm_up,
        );
        print_errors("proposed", &proposed_quality, &reference);
        print_errors("classical", &classical_quality, &reference);
        for (name, quality) in [
            ("proposed", &proposed_quality),
            ("classical", &classical_quality),
        ] {
            println!(
                "  {name} max error at t = {:.3} s",
                quality.max_abs_sample as f64 * validation.sample_period
            );
        }
    }

    if let Some(out) = &args.out {
        let json = serde_json::to_string_pretty(&proposed.params)
            .map_err(|e| format!("cannot serialise the parameters: {e}"))?;
        std::fs::write(out, json + "\n").map_err(|e| format!("{}: {e}", out.display()))?;
        println!("\nparameters written to {}", out.display());
    }
    Ok(())
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

fn print_errors(name: &str, quality: &FitQuality, reference: &ScaleReference) {
    let e = ErrorReport::new(quality, reference);
    println!(
        "  {name:<9} F = {:.6e} V^2; voltage error RMS {:.6} V ({:.3} % of input span), max {:.6} V ({:.3} %); \
         equivalent displacement RMS {:.4} um, max {:.4} um (same % of stroke)",
        quality.objective,
        e.rms_volts,
        e.rms_percent,
        e.max_volts,
        e.max_percent,
        e.rms_displacement_um,
        e.max_displacement_um
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
    let home: Vec<f64> = args
        .home
        .split(',')
        .map(|v| v.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect::<Option<Vec<f64>>>()
        .filter(|v| v.len() == 2)
        .ok_or_else(|| format!("--home {}: give X,Y in um, e.g. 8,7", args.home))?;
    if !(args.gain_scale.is_finite() && args.gain_scale > 0.0) {
        return Err(format!(
            "--gain-scale {}: give a positive factor",
            args.gain_scale
        ));
    }
    let conditions = StageConditions {
        home: [home[0], home[1], 0.0],
        gain_scale: args.gain_scale,
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

/// The identification record of `bouc-wen`: a file or a plant run. Returns
/// the record, its name and the default (decimation, warm-up seconds).
fn bouc_wen_record(args: &BoucWenArgs) -> Result<(Record, String, usize, f64), String> {
    if let Some(path) = &args.plant {
        let plant = open_plant(path, args.plant_parameters.as_deref())?;
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
        Ok((record, name, 10, 1.0 / args.frequency))
    } else {
        let path = args.file.as_ref().expect("clap requires a file or --plant");
        let record = read(path, &args.columns.read_options()?)?;
        Ok((record, path.display().to_string(), 1, 0.0))
    }
}

fn print_bouc_wen_fit(name: &str, fit: &BoucWenModelFit) {
    let p = &fit.params;
    println!(
        "  {name:<8} eq. (5) RMS {:.6} um, max |error| {:.6} um, error range {:+.4}..{:+.4} um; offset {:.6} um",
        fit.rms, fit.max_error, fit.error_range.0, fit.error_range.1, fit.offset
    );
    println!(
        "           p {:.6e}, q {:+.0}, A {:.6e}, beta {:.6e}, gamma {:.6e}, n {:.4}, delta {:.6e}",
        p.p, p.q, p.a, p.beta, p.gamma, p.n, p.delta
    );
}

fn print_prediction(name: &str, e: &PredictionError) {
    println!(
        "  {name:<8} error RMS {:.4} um ({:.3} % of stroke {:.3} um), range {:+.4}..{:+.4} um, max |error| {:.3} %",
        e.rms, e.rms_percent, e.stroke, e.min, e.max, e.max_percent
    );
}

fn bouc_wen(args: &BoucWenArgs) -> Result<(), String> {
    let (record, name, default_decimation, default_warm_up) = bouc_wen_record(args)?;
    let dt = record.sample_period;
    let warm_up_seconds = args.warm_up.unwrap_or(default_warm_up);
    let warm_up_samples = (warm_up_seconds / dt).round() as usize;
    let mut bounds = if args.wide_bounds {
        wide_shape_bounds()
    } else {
        default_shape_bounds()
    };
    if let Some(text) = &args.bounds {
        parse_shape_bounds(text, &mut bounds)?;
    }
    let options = BoucWenFitOptions {
        gapso: GaPsoOptions {
            population: args.population,
            generations: args.generations,
            seed: args.seed,
            ..GaPsoOptions::default()
        },
        bounds,
        decimation: args.decimation.unwrap_or(default_decimation),
        warm_up_samples,
        excluded: Vec::new(),
        fit_offset: !args.no_offset,
        monotone: args.monotone,
        refine: !args.no_refine,
        refine_within_bounds: true,
        ..BoucWenFitOptions::default()
    };
    let y = centred_moving_average(&record.output, args.smooth);
    println!("{}", describe(&record, &name));
    println!(
        "GA-PSO: {} particles, at most {} generations, seed {}, every {} sample(s); first {} samples ({} s) not fitted",
        options.gapso.population,
        options.gapso.generations,
        options.gapso.seed,
        options.decimation,
        warm_up_samples,
        warm_up_seconds
    );
    let bar = progress_bar_of(options.gapso.generations, "GA-PSO", "generations");
    let fit = identify_bouc_wen(&record.input, &y, &options, |generation, best| {
        bar.set_position(generation as u64 + 1);
        bar.set_message(format!("GA-PSO, best RMS {best:.4e} um"));
    })
    .map_err(|e| format!("{name}: {e}"))?;
    bar.finish_and_clear();

    println!(
        "\nGA-PSO: {} evaluations in {} generations, {:.2} s",
        fit.gapso_evaluations,
        fit.history.len(),
        fit.gapso_seconds
    );
    print_bouc_wen_fit("GA-PSO", &fit.gapso);
    if let Some(refined) = &fit.refined {
        println!(
            "Levenberg-Marquardt from the GA-PSO optimum: {} evaluations, {:.2} s",
            fit.refinement_evaluations, fit.refinement_seconds
        );
        print_bouc_wen_fit("refined", refined);
    }

    let mut validation_errors = Vec::new();
    if let Some(path) = &args.validate {
        let validation = read(path, &args.columns.read_options()?)?;
        let y_validation = centred_moving_average(&validation.output, args.smooth);
        let warm_up = (warm_up_seconds / validation.sample_period).round() as usize;
        if warm_up >= validation.input.len() {
            return Err(format!("{}: no sample after the warm-up", path.display()));
        }
        println!("\n{}", describe(&validation, &path.display().to_string()));
        println!(
            "validation record (not seen by the fit; models from rest, the identified offset; {} scored samples):",
            validation.input.len() - warm_up
        );
        let mut fits = vec![("GA-PSO", &fit.gapso)];
        if let Some(refined) = &fit.refined {
            fits.push(("refined", refined));
        }
        for (fit_name, model) in fits {
            let predicted = predict(model.params, model.offset, &validation.input);
            let error = prediction_error(&predicted, &y_validation, warm_up);
            print_prediction(fit_name, &error);
            validation_errors.push((fit_name, error));
        }
    }

    if let Some(out) = &args.out {
        let json = serde_json::to_string_pretty(&fit.best().params)
            .map_err(|e| format!("cannot serialise the parameters: {e}"))?;
        std::fs::write(out, json + "\n").map_err(|e| format!("{}: {e}", out.display()))?;
        println!("\nparameters written to {}", out.display());
    }
    if let Some(path) = &args.report {
        let report = serde_json::json!({
            "record": name,
            "options": options,
            "identification": fit,
            "validation": validation_errors
                .iter()
                .map(|(fit_name, e)| serde_json::json!({ "fit": fit_name, "error": e }))
                .collect::<Vec<_>>(),
        });
        let json = serde_json::to_string_pretty(&report)
            .map_err(|e| format!("cannot serialise the report: {e}"))?;
        std::fs::write(path, json + "\n").map_err(|e| format!("{}: {e}", path.display()))?;
        println!("report written to {}", path.display());
    }
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

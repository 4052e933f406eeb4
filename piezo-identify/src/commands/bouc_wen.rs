//! `piezo-identify bouc-wen`: the asymmetric Bouc-Wen model (seed 001 eq. 3-4)
//! by GA-PSO and Levenberg-Marquardt.

use std::path::{Path, PathBuf};

use clap::Args;

use piezo_identify::bouc_wen_fit::{
    MIN_EXPONENT, SHAPE_PARAMETERS, default_shape_bounds, wide_shape_bounds,
};
use piezo_identify::gapso::{Bounds, GaPsoOptions};
use piezo_identify::plant::{ParameterValue, PlantFmu, RecordAxis, sine_records};
use piezo_identify::protocol::{
    BoucWenProtocolFit, BoucWenSettings, ForwardErrors, identify_bouc_wen_protocol,
};

use super::arguments::{ColumnArgs, Loaded, ProtocolArgs, load, load_validation, open_plant};
use super::progress::Reporter;
use super::report::{
    Notes, ResultFiles, bouc_wen_parameters, describe, describe_columns, pad, print_figure,
    print_plan, range_excess, write_json, write_predictions,
};
use super::{Failure, plant_failure, protocol_failure};

#[derive(Args)]
pub(crate) struct BoucWenArgs {
    /// Identification record (or --plant).
    #[arg(required_unless_present = "plant", conflicts_with = "plant")]
    pub(crate) file: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) columns: ColumnArgs,
    #[command(flatten)]
    pub(crate) protocol: ProtocolArgs,
    /// Drive this plant FMU (FlexureStage's interface) instead of reading a
    /// file: a sine from 0 V to --peak at --frequency on one axis.
    #[arg(long)]
    pub(crate) plant: Option<PathBuf>,
    /// Parameter set the plant is loaded with (JSON by FMI name).
    #[arg(long, requires = "plant")]
    pub(crate) plant_parameters: Option<PathBuf>,
    /// Axis the plant run drives: y (u1) or x (u2 = u3).
    #[arg(long, default_value = "y", value_parser = ["x", "y"])]
    pub(crate) drive: String,
    /// Displacement the plant run fits: the driven axis's (H_XX, H_YY) or
    /// the other axis's (the coupling H_XY, H_YX of eq. 8).
    #[arg(long, default_value = "driven", value_parser = ["driven", "coupled"])]
    pub(crate) read: String,
    /// Frequency of the plant run's sine [Hz] (seed 001 §5.2: 2).
    #[arg(long, default_value_t = 2.0)]
    pub(crate) frequency: f64,
    /// Peak command of the plant run's sine [V] (seed 001 §5.2: 10).
    #[arg(long, default_value_t = 10.0)]
    pub(crate) peak: f64,
    /// Periods of the plant run; the first is the warm-up unless --warm-up.
    #[arg(long, default_value_t = 3.0)]
    pub(crate) periods: f64,
    /// Sample rate of the plant run [Hz].
    #[arg(long, default_value_t = 10_000.0)]
    pub(crate) plant_rate: f64,
    /// Particles of the swarm (4 or more: GA-PSO's crossover needs pairs
    /// beside the best).
    #[arg(long, default_value_t = 40, value_parser = super::arguments::at_least::<4>)]
    pub(crate) population: usize,
    /// GA-PSO generations at most.
    #[arg(long, default_value_t = 150, value_parser = super::arguments::at_least_one)]
    pub(crate) generations: usize,
    /// Seed of GA-PSO's random stream.
    #[arg(long, default_value_t = 0)]
    pub(crate) seed: u64,
    /// GA-PSO evaluates every N-th sample (refinement and errors use all);
    /// default: at most about 3000 samples and at least 100 per fastest
    /// cycle for a file, 10 for a plant run.
    #[arg(long)]
    pub(crate) decimation: Option<usize>,
    /// Half width [samples] of a centred moving average of the fitted
    /// displacement (0: none); the errors are always against the measured one.
    #[arg(long, default_value_t = 0)]
    pub(crate) smooth: usize,
    /// Fit no sensor offset: the output is taken as recorded, so it must
    /// read 0 with the stage at rest (de-energized); nothing is subtracted.
    #[arg(long)]
    pub(crate) no_offset: bool,
    /// Accept only models whose every branch rises with the input on the
    /// record: models with an inverse, as feedforward (eq. 6) needs.
    #[arg(long)]
    pub(crate) monotone: bool,
    /// Stop at the GA-PSO optimum, as seed 001 does.
    #[arg(long)]
    pub(crate) no_refine: bool,
    /// Fit and score the model with a return-point memory: its minor loops
    /// close, as FlexureStage's `return_point_memory` runs its stacks (give
    /// the plant that parameter when it runs the fitted model).
    #[arg(long)]
    pub(crate) return_point_memory: bool,
    /// Search box of the scaled shape, e.g. "beta=0:10,gamma=-10:10,n=1:3,delta=-2:2"
    /// (u scaled by max|u|, y by its span, A = 1; any subset).
    #[arg(long)]
    pub(crate) bounds: Option<String>,
    /// Start from the wide box (ten times the default in beta, gamma, delta;
    /// n up to 5) before --bounds: for loops unlike a plain piezo's, such as
    /// the XY200S's.
    #[arg(long)]
    pub(crate) wide_bounds: bool,
    /// Write the fitted model (piezo_models::BoucWenParams and the sensor
    /// offset) as JSON.
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
}

/// Parses `name=lo:hi` pairs into `bounds` (the shape of
/// `bouc_wen_fit::SHAPE_PARAMETERS`).
pub(crate) fn parse_shape_bounds(text: &str, bounds: &mut Bounds) -> Result<(), String> {
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
        // Below 1 the model cannot go (the fit clamps n there), and a box
        // reaching below it reported n = 1 as inside it.
        if SHAPE_PARAMETERS[index] == "n" && lo < MIN_EXPONENT {
            return Err(problem(&format!(
                "n's lower bound must be {MIN_EXPONENT} or more: below 1, |h|^(n-1) is singular at h = 0"
            )));
        }
        bounds.lower[index] = lo;
        bounds.upper[index] = hi;
    }
    Ok(())
}

/// The identification record of `bouc-wen`: a file or a plant run, and the
/// defaults that differ between them (decimation, warm-up seconds).
/// Fewest samples per period of a plant run's sine.
const MIN_PLANT_SAMPLES_PER_PERIOD: f64 = 20.0;
/// Most samples of a plant run: 200 s at the default 10 kHz, 100 times the
/// default run's.
const MAX_PLANT_SAMPLES: usize = 2_000_000;

pub(crate) fn bouc_wen_record(
    args: &BoucWenArgs,
) -> Result<(Loaded, Option<usize>, Option<f64>), Failure> {
    if let Some(path) = &args.plant {
        // The run starts from a stage never cycled (FlexureStage's
        // `rest_cycle_voltage` = 0): every hysteretic state at h = 0, the
        // state the fitted model starts from. A stage resting after a cycle
        // sits on that cycle's loop, which a model started from h = 0 reaches
        // only after several periods (Bouc-Wen minor loops do not close).
        let plant = open_plant(path, args.plant_parameters.as_deref())?
            .with_parameters(&[("rest_cycle_voltage".to_owned(), ParameterValue::Number(0.0))])
            .map_err(plant_failure)?;
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
                return Err(Failure::Input(format!(
                    "{name} must be positive (got {value})"
                )));
            }
        }
        // A peak beyond what the amplifier follows clips the drive into a
        // plateau the fit reads as the stack's (--peak 1000 fitted a
        // saturated record with exit 0).
        if let Some(limit) = amplifier_command_limit(&plant)
            && args.peak > limit.command
        {
            return Err(Failure::Input(format!(
                "--peak {} V is beyond what the plant's amplifier follows: {}; the sine would \
                 be clipped there, and the record would not be the drive it claims",
                args.peak, limit.reason
            )));
        }
        // A sine sampled a few times a period is no loop (the settling after
        // its step then covered the fit part, which the refusal blamed), and
        // --plant-rate 1e7 made 15 million samples whose fit ran for hours.
        let per_period = args.plant_rate / args.frequency;
        if per_period < MIN_PLANT_SAMPLES_PER_PERIOD {
            return Err(Failure::Input(format!(
                "--plant-rate {} Hz samples the {} Hz sine {per_period:.3} times a period; give \
                 {MIN_PLANT_SAMPLES_PER_PERIOD} or more",
                args.plant_rate, args.frequency
            )));
        }
        let samples = (args.periods * per_period).ceil();
        if samples > MAX_PLANT_SAMPLES as f64 {
            return Err(Failure::Input(format!(
                "--periods {} of the {} Hz sine at --plant-rate {} Hz make {samples} samples; \
                 at most {MAX_PLANT_SAMPLES} are fitted (fewer periods or a lower rate)",
                args.periods, args.frequency, args.plant_rate
            )));
        }
        let (driven, coupled) = sine_records(
            &plant,
            axis,
            args.frequency,
            args.peak,
            args.periods,
            args.plant_rate,
        )
        .map_err(plant_failure)?;
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

pub(crate) fn print_forward_errors(
    part: &str,
    e: &ForwardErrors,
    refined: bool,
    scored_line: bool,
) {
    say!("{part}, {} samples:", e.bouc_wen.samples);
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

pub(crate) fn bouc_wen(args: &BoucWenArgs) -> Result<(), Failure> {
    let mut inputs: Vec<&Path> = args.file.iter().map(|p| p.as_path()).collect();
    inputs.extend(args.protocol.validate.as_deref());
    inputs.extend(args.plant.as_deref());
    inputs.extend(args.plant_parameters.as_deref());
    args.protocol
        .check_destinations(args.out.as_deref(), &inputs)?;
    let (loaded, default_decimation, default_warm_up) = bouc_wen_record(args)?;
    super::arguments::check_smoothing(args.smooth, loaded.record.input.len())
        .map_err(Failure::Input)?;
    // The validation file is read before the fit: a typo costs nothing.
    let validation = match &args.protocol.validate {
        Some(path) => Some(load_validation(path, &args.columns, &loaded)?),
        None => None,
    };
    if args.monotone {
        ProtocolArgs::refuse_falling(&loaded)?;
    }
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
        return_point_memory: args.return_point_memory,
    };
    if settings.decimation == Some(0) {
        return Err(Failure::Input(
            "--decimation: give a whole number of samples, 1 or more".to_owned(),
        ));
    }
    let record = &loaded.record;
    let dt = record.sample_period;
    say!("{}", describe(record, &loaded.name));
    if let Some(columns) = &loaded.columns {
        say!("columns: {}", describe_columns(columns));
    }
    print_plan(&plan, &loaded.name);

    let reporter = Reporter::new();
    let fit = identify_bouc_wen_protocol(record, &plan, &settings, &|e| reporter.event(e))
        .map_err(|e| protocol_failure(&loaded.name, e))?;
    reporter.finish();
    let mut notes = Notes::default();
    print_bouc_wen_fit(&fit, &settings, &mut notes);

    say!(
        "\nerrors of the displacement each model gives for the measured input (RMS, largest; % of the fit part's stroke {:.6} um):",
        fit.stroke
    );
    let refined = fit.identification.refinement_kept;
    print_forward_errors("fit part", &fit.fit_errors, refined, false);
    if let Some(unseen) = &fit.unseen {
        print_forward_errors("scored part (not seen by the fit)", unseen, refined, true);
        let fitted = pad(&plan.fitted(), plan.samples);
        notes.extrapolation(
            "input",
            range_excess(&record.input, &fitted, &plan.scored()),
        );
        notes.smaller_loops("input", "V", &record.input, &fitted, &plan.scored());
        notes.faster_cycles(&plan, &record.input, dt, &plan.scored());
    }
    notes.few_turns(&plan, &record.input);
    notes.short_score(&plan);
    notes.implausible_stroke(fit.stroke);
    if args.no_offset {
        // --no-offset takes the displacement as recorded, so the stage must
        // read 0 at rest at 0 V; a record that rests elsewhere was fitted
        // with errors of a quarter of the stroke and only a box note.
        let (low, high) = record
            .input
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                (l.min(v), h.max(v))
            });
        let unpowered = plan.segments.rests.iter().find(|rest| {
            let mean = record.input[(*rest).clone()].iter().sum::<f64>() / rest.len() as f64;
            mean.abs() <= 0.01 * (high - low)
        });
        if let Some(rest) = unpowered {
            let reads = record.output[rest.clone()].iter().sum::<f64>() / rest.len() as f64;
            if reads.abs() > 0.05 * fit.stroke {
                notes.add(format!(
                    "the record rests at 0 V from {:.3} s reading {reads:.6} um, not 0, and \
                     --no-offset takes the displacement as recorded: leave it out to fit the \
                     sensor's offset",
                    rest.start as f64 * dt
                ));
            }
        }
    }
    notes.few_levels(&plan);
    let mut validation_errors = None;
    let mut zero_alignment = None;
    if let (Some(v), Some((_, scored))) = (&validation, &validation_scored) {
        say!("\n{}", describe(&v.record, &v.name));
        if let Some(columns) = &v.columns {
            say!("columns: {}", describe_columns(columns));
        }
        let (output, zero) = args
            .protocol
            .validation_output(&plan, &loaded, v, fit.stroke);
        zero_alignment = Some(zero);
        let errors = fit.errors_on(&v.record.input, &output, v.record.sample_period, scored);
        print_forward_errors(
            "validation file (models from rest at its start)",
            &errors,
            refined,
            true,
        );
        notes.faster_cycles(&plan, &v.record.input, v.record.sample_period, scored);
        validation_errors = Some(errors);
    }
    say!("time: {:.2} s", fit.seconds);

    let mut files = ResultFiles::default();
    if let Some(path) = &args.protocol.predictions {
        let predictions = fit.predictions_on(&record.input, dt);
        let outcome = write_predictions(
            path,
            dt,
            &[
                ("voltage_v", &record.input),
                ("displacement_um", &record.output),
                ("bouc_wen_um", &predictions.bouc_wen),
                ("classical_um", &predictions.classical),
                ("line_um", &predictions.line),
            ],
            &plan,
        );
        files.written("--predictions", "predictions", path, outcome);
    }
    let best = fit.identification.best();
    if let Some(out) = &args.out {
        let outcome = write_json(
            out,
            &serde_json::json!({
                "model": "asymmetric Bouc-Wen (seed 001 eq. 3-4): displacement from voltage, plus the sensor offset",
                "params": best.params,
                "return_point_memory": settings.return_point_memory,
                "sensor_offset_um": best.offset,
                "sample_period_s": dt,
                "columns": loaded.columns,
            }),
        );
        files.written("--out", "model", out, outcome);
    }
    if let Some(path) = &args.protocol.report {
        let outcome = write_json(
            path,
            &serde_json::json!({
                "record": loaded.name,
                "notes": notes.0,
                "columns": loaded.columns,
                "plan": plan,
                "settings": settings,
                "options": fit.options,
                "unusable_searches": fit.unusable_searches,
                "identification": fit.identification,
                "classical": fit.classical,
                "line": fit.line,
                "stroke": fit.stroke,
                "fit_errors": fit.fit_errors,
                "unseen": fit.unseen,
                "validation": validation.as_ref().map(|v| serde_json::json!({
                    "file": v.name,
                    "columns": v.columns,
                    "zero": zero_alignment,
                    "errors": validation_errors,
                })),
                "seconds": fit.seconds,
            }),
        );
        files.written("--report", "report", path, outcome);
    }
    files.finish()
}

pub(crate) fn print_bouc_wen_fit(
    fit: &BoucWenProtocolFit,
    settings: &BoucWenSettings,
    notes: &mut Notes,
) {
    let identification = &fit.identification;
    if settings.return_point_memory {
        say!(
            "\nthe Bouc-Wen model closes its minor loops (return-point memory): fitted, scored and written so; run it so (FlexureStage: return_point_memory = true)"
        );
    }
    for (i, search) in fit.unusable_searches.iter().enumerate() {
        let next = fit
            .unusable_searches
            .get(i + 1)
            .map_or(fit.options.decimation, |s| s.decimation);
        say!(
            "\nthe GA-PSO optimum searched on one sample in {} ({:.2} s) drew a falling branch or diverged between them; searched again on one sample in {next}",
            search.decimation,
            search.seconds
        );
    }
    say!(
        "\nGA-PSO: {} particles, {} generations ({} evaluations), seed {}, every {} sample(s): {:.2} s; eq. (5) RMS {:.6} um on the fitted samples{}",
        settings.gapso.population,
        identification.history.len(),
        identification.gapso_evaluations,
        settings.gapso.seed,
        fit.options.decimation,
        identification.gapso_seconds,
        identification.gapso.rms,
        // The search's cost is against what it fitted; the errors below are
        // against the measured displacement.
        if settings.smoothing > 0 {
            " (against the smoothed displacement)"
        } else {
            ""
        }
    );
    if settings.refine {
        say!(
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
    say!(
        "model: {}; sensor offset {:.6} um",
        bouc_wen_parameters(p),
        best.offset
    );
    let walls = best.on_search_walls(&settings.bounds);
    if !walls.is_empty() {
        // A box as wide as --wide-bounds' already has it: only --bounds
        // reaches farther.
        let wide = wide_shape_bounds();
        let already_wide = (0..SHAPE_PARAMETERS.len()).all(|i| {
            settings.bounds.lower[i] <= wide.lower[i] && settings.bounds.upper[i] >= wide.upper[i]
        });
        notes.add(format!(
            "the fit stopped on the search box's wall ({}, in the scaled shape --bounds \
             takes): a better model may lie beyond it; try {}--bounds past it",
            walls
                .iter()
                .map(|(name, wall)| format!("{name} = {wall}"))
                .collect::<Vec<_>>()
                .join(", "),
            if already_wide {
                ""
            } else {
                "--wide-bounds, or "
            }
        ));
    }
}

/// The largest command the plant's amplifier passes unclipped, and why:
/// clamp(G·clamp(u, input_min, input_max), v_min, v_max) (piezo-models
/// MODEL.md §2) follows u up to min(input_max, v_max/G). `None` for a plant
/// without FlexureStage's amplifier parameters (nothing to check against),
/// or with values it will refuse itself.
struct CommandLimit {
    command: f64,
    reason: String,
}

fn amplifier_command_limit(plant: &PlantFmu) -> Option<CommandLimit> {
    let input_max = plant.start("amplifier.input_max")?;
    let gain = plant.start("amplifier.gain")?;
    let v_max = plant.start("amplifier.v_max")?;
    // Values the plant itself refuses are its to name, when its session starts.
    if !(gain > 0.0 && [input_max, gain, v_max].iter().all(|v| v.is_finite())) {
        return None;
    }
    let by_output = v_max / gain;
    Some(if by_output < input_max {
        CommandLimit {
            command: by_output,
            reason: format!(
                "amplifier.v_max {v_max} V at amplifier.gain {gain} is a command of {by_output} V"
            ),
        }
    } else {
        CommandLimit {
            command: input_max,
            reason: format!("amplifier.input_max is {input_max} V"),
        }
    })
}

//! `piezo-identify stage` and `decoupling`: seed 000's identification of a
//! whole stage and of one decoupling compensation (eq. 11, Table 2).

use std::path::PathBuf;

use clap::Args;

use piezo_identify::data::read_record_with_columns;
use piezo_identify::decoupling::{DecouplingError, fit_compensation};
use piezo_identify::stage::{StageConditions, identify_stage};
use piezo_identify::{Column, ReadOptions, Roles, Sampling};

use super::arguments::{SearchArgs, check_destinations, open_plant};
use super::progress::progress_bar;
use super::report::write_json;
use super::{Failure, stage_failure};

#[derive(Args)]
pub(crate) struct StageArgs {
    /// The plant FMU to identify (FMI 2.0 co-simulation, inputs u1..u3 [V],
    /// outputs s1..s3 [um], parameter L [mm]).
    #[arg(long, default_value = "dist/FlexureStage.fmu")]
    pub(crate) plant: PathBuf,
    /// Parameter set the plant is loaded with (JSON by FMI name, as
    /// `flexure-stage-parameters xy200s` writes); default its start values.
    #[arg(long)]
    pub(crate) plant_parameters: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) search: SearchArgs,
    /// Scale of the single-axis runs relative to seed 000's (10 um sines,
    /// x at half of a 12.74 um stroke for the rotation run, 10 um for an
    /// unused cutoff): the stage's strokes over seed 000's.
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    pub(crate) scale: f64,
    /// The stage does not rotate (its x actuators move together): no
    /// rotation run, D4 stays zero.
    #[arg(long)]
    pub(crate) no_rotation: bool,
    /// Demands of the held translations, "X,Y" in um: x during the y run, y
    /// during the x run (seed 000 §5: 0,0). A stage whose commands cannot go
    /// below 0 V cancels a coupling only from a held axis above its rest.
    #[arg(long, default_value = "0,0", allow_hyphen_values = true)]
    pub(crate) held: String,
    /// Command range of the controller, "MIN,MAX" in V (seed 000's E-505:
    /// -2,12).
    #[arg(long, default_value = "-2,12", allow_hyphen_values = true)]
    pub(crate) command_range: String,
    /// Factor on the §3.2 PI gains for the single-axis runs (1 for seed
    /// 000's stage; the inverse of the stage's um per volt relative to it).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    pub(crate) gain_scale: f64,
    /// Rounds of decoupling runs: each after the first refits what the previous left (the
    /// shipped presets are made with the default).
    #[arg(long, default_value_t = 3, value_parser = super::arguments::at_least_one)]
    pub(crate) rounds: usize,
    /// Write the controller preset (JSON) here, in the Rust form of
    /// piezo-models/presets/; `piezo-controller-parameters FILE SET.json`
    /// (built by `make fmus`) turns it into PiezoController's parameters by
    /// FMI name, as importers take them.
    #[arg(long)]
    pub(crate) out: PathBuf,
    /// Also write the preset with the compensations of the first round alone
    /// (D1..D4 fitted once on runs without decoupling, as seed 000 §4 does),
    /// in the same form as --out.
    #[arg(long)]
    pub(crate) out_fitted_once: Option<PathBuf>,
    /// Write everything measured (fits, compensations per round) here as JSON.
    #[arg(long)]
    pub(crate) report: Option<PathBuf>,
}

#[derive(Args)]
pub(crate) struct DecouplingArgs {
    /// Record with a driving-demand column and a coupling-error column.
    pub(crate) file: PathBuf,
    /// Driving demand column (y_d or x_d [um], theta_zd [urad]): index or header [default: the
    /// first column that is neither the time column nor a given --error]
    #[arg(long)]
    pub(crate) demand: Option<String>,
    /// Coupling error column (demand - measurement of the coupled channel) [um]: index or
    /// header [default: the first column that is neither the time column nor the demand]
    #[arg(long)]
    pub(crate) error: Option<String>,
    /// Time column, if the record has one: skipped by the defaults above (the fit is static, so
    /// the spacing of the samples does not matter)
    #[arg(long)]
    pub(crate) time: Option<String>,
    /// Write the compensation (dk, db, p, q at full precision, the residual and error spans)
    /// as JSON
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
}

/// Decimation of the plant's 10 kHz eq. (6) records for the search (500 Hz).
pub(crate) const STAGE_DECIMATION: usize = 20;

pub(crate) fn stage(args: &StageArgs) -> Result<(), Failure> {
    let mut inputs = vec![args.plant.as_path()];
    inputs.extend(args.plant_parameters.as_deref());
    check_destinations(
        &[
            ("--out", Some(&args.out)),
            ("--out-fitted-once", args.out_fitted_once.as_deref()),
            ("--report", args.report.as_deref()),
        ],
        &inputs,
    )?;
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
            return Err(Failure::Input(format!(
                "{name} {value}: give a positive factor"
            )));
        }
    }
    let conditions = StageConditions {
        gain_scale: args.gain_scale,
        command_range: (range[0], range[1]),
        held_um: [held[0], held[1]],
        ..StageConditions::scaled(args.scale, !args.no_rotation)
    };
    let identified = identify_stage(&plant, &options, args.rounds, &conditions, &step, &tick)
        .map_err(|e| stage_failure(&args.plant, e))?;
    bar.finish_and_clear();
    for (name, fit) in [("x", &identified.x_fit), ("y", &identified.y_fit)] {
        say!(
            "{name} inverse model on eq. (6): F = {:.6e} V^2, RMS {:.6} V, max {:.6} V",
            fit.f,
            fit.rms_v,
            fit.max_v
        );
    }
    for (name, rms) in &identified.bouc_wen_fits {
        say!("{name} Bouc-Wen model on seed 001's 2 Hz sine: eq. (5) RMS {rms:.6} um");
    }
    let memory = &identified.bouc_wen_memory;
    say!(
        "H_XX + H_YY on the 7-3 V minor loops: RMS {:.6} um without a return-point memory, {:.6} um with one: {}",
        memory.rms_without_um,
        memory.rms_with_um,
        if memory.return_point_memory {
            "the Bouc-Wen models close their minor loops"
        } else {
            "no memory"
        }
    );
    for (round, compensations) in identified.rounds.iter().enumerate() {
        say!("decoupling round {}:", round + 1);
        for (i, c) in compensations.iter().enumerate() {
            say!(
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
    write_json(&args.out, &identified.controller)?;
    say!(
        "controller preset written to {} (as PiezoController's parameters by FMI name: \
         piezo-controller-parameters {} SET.json)",
        args.out.display(),
        args.out.display()
    );
    if let Some(path) = &args.out_fitted_once {
        write_json(path, &identified.fitted_once())?;
        say!(
            "the same preset with D1..D4 fitted once (round 1, seed 000 §4's procedure) written \
             to {}",
            path.display()
        );
    }
    if let Some(path) = &args.report {
        write_json(path, &identified)?;
        say!("identification report written to {}", path.display());
    }
    Ok(())
}

pub(crate) fn decoupling(args: &DecouplingArgs) -> Result<(), Failure> {
    check_destinations(&[("--out", args.out.as_deref())], &[args.file.as_path()])?;
    if let (Some(demand), Some(error)) = (&args.demand, &args.error)
        && demand.trim() == error.trim()
    {
        return Err(Failure::Input(format!(
            "--demand and --error both name column {}: give the coupling error's own column",
            demand.trim()
        )));
    }
    let options = ReadOptions {
        input: args.demand.as_deref().map(Column::parse),
        output: args.error.as_deref().map(Column::parse),
        sampling: Sampling::Unspaced {
            time: args.time.as_deref().map(Column::parse),
        },
        roles: Roles {
            input: "demand",
            output: "error",
            // Both lengths: the columns are told apart by their place.
            quantities: None,
        },
    };
    let (record, used) =
        read_record_with_columns(&args.file, &options).map_err(|e| e.to_string())?;
    say!(
        "columns: demand {}, coupling error {}",
        used.input,
        used.output
    );
    let c = fit_compensation(&record.input, &record.output).map_err(|e| {
        let message = format!("{}: {e}", args.file.display());
        match e {
            DecouplingError::Optimizer(_) => Failure::Run(message),
            _ => Failure::Input(message),
        }
    })?;
    say!(
        "{}: {} pairs; D(f) = clamp({:.6}*f {:+.6}, q = {:.6}, p = {:.6})",
        args.file.display(),
        record.input.len(),
        c.dk,
        c.db,
        c.q,
        c.p
    );
    say!(
        "coupling error span {:.6} um; residual span {:.6} um, RMS {:.6} um",
        c.error_span,
        c.residual_span,
        c.residual_rms
    );
    if c.residual_span >= c.error_span {
        // A compensation that leaves the span as wide as it found it has
        // nothing to cancel in these columns: most often the wrong ones.
        say!(
            "note: the compensation does not narrow the coupling error; check that the demand \
             and error columns are the ones meant (--demand, --error)"
        );
    } else if c.residual_span > 0.5 * c.error_span {
        // Seed 000's Table 3 narrows each coupling 4.5-8.5 times; less than
        // half off is a coupling eq. (11) does not describe.
        say!(
            "note: the compensation narrows the coupling error by {:.0} % only, from {:.6} to \
             {:.6} um: the error is not a clamped straight line of the demand (a loop, a curve, \
             noise), which eq. (11) cannot cancel; check the columns too (--demand, --error)",
            100.0 * (1.0 - c.residual_span / c.error_span),
            c.error_span,
            c.residual_span
        );
    }
    if let Some(out) = &args.out {
        // The printed figures are rounded to 6 decimals; the file keeps
        // every digit for `decoupling_params`.
        write_json(
            out,
            &serde_json::json!({
                "compensation": "D(f) = clamp(dk*f + db, q, p), seed 000 eq. (11)",
                "record": args.file.display().to_string(),
                "columns": used,
                "fit": c,
            }),
        )?;
        say!("compensation written to {}", out.display());
    }
    Ok(())
}

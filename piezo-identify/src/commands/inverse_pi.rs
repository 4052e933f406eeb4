//! `piezo-identify inverse-pi`: the modified inverse P-I model (seed 000 eq.
//! 3-5) with its baselines.

use std::path::PathBuf;

use clap::Args;

use piezo_identify::protocol::{
    Candidate, InversePiErrors, InversePiIdentification, InversePiSettings, Plan,
    identify_inverse_pi,
};
use piezo_identify::validation::inverse_model_input;

use super::arguments::{ColumnArgs, ProtocolArgs, auto_or, load, load_validation};
use super::progress::Reporter;
use super::report::{
    Notes, ResultFiles, describe, describe_columns, pad, print_figure, print_plan, range_excess,
    write_json, write_predictions,
};
use super::{Failure, protocol_failure};

#[derive(Args)]
pub(crate) struct InversePiArgs {
    /// Identification record.
    pub(crate) file: PathBuf,
    #[command(flatten)]
    pub(crate) columns: ColumnArgs,
    #[command(flatten)]
    pub(crate) protocol: ProtocolArgs,
    /// Random starts of the (c, w_s) search (seed 000: 30).
    #[arg(long, default_value_t = 30, value_parser = super::arguments::at_least_one)]
    pub(crate) starts: usize,
    /// Seed of the random initial values.
    #[arg(long, default_value_t = 0)]
    pub(crate) seed: u64,
    /// Nelder-Mead iterations per start at most.
    #[arg(long, default_value_t = 2000, value_parser = clap::value_parser!(u64).range(1..))]
    pub(crate) max_iterations: u64,
    /// Run every start to convergence, restarted at its end, instead of
    /// screening them for 60 iterations and running on the best 5 (`compare`
    /// runs seed 000's plain best of N).
    #[arg(long)]
    pub(crate) no_screening: bool,
    /// The search uses every N-th sample, or "auto": at most about 3000
    /// samples and at least 100 per fastest cycle.
    #[arg(long, default_value = "auto")]
    pub(crate) decimation: String,
    /// Half width [samples] of a centred moving average of the displacement,
    /// or "auto": chosen by validation inside the fit part among none and
    /// 1/160, 1/80, 1/40 of the fastest cycle.
    #[arg(long, default_value = "auto")]
    pub(crate) smooth: String,
    /// Backlash weights: "rate-dependent" (seed 000 eq. 4), "constant", or
    /// "auto": chosen by validation inside the fit part.
    #[arg(long, default_value = "auto", value_parser = ["auto", "rate-dependent", "constant"])]
    pub(crate) weights: String,
    /// Displacement offset [µm] subtracted from every record, or "auto": the
    /// smallest (smoothed) fitted displacement.
    #[arg(long, default_value = "auto", allow_negative_numbers = true)]
    pub(crate) offset: String,
    /// Write the fitted model (piezo_models::InversePiParams, the offset and
    /// the smoothing it takes) as JSON.
    #[arg(long)]
    pub(crate) out: Option<PathBuf>,
}

pub(crate) fn inverse_pi(args: &InversePiArgs) -> Result<(), Failure> {
    let mut inputs = vec![args.file.as_path()];
    inputs.extend(args.protocol.validate.as_deref());
    args.protocol
        .check_destinations(args.out.as_deref(), &inputs)?;
    let loaded = load(&args.file, &args.columns)?;
    // The validation file is read before the fit: a typo costs nothing.
    let validation = match &args.protocol.validate {
        Some(path) => Some(load_validation(path, &args.columns, &loaded)?),
        None => None,
    };
    ProtocolArgs::refuse_falling(&loaded)?;
    let plan = args.protocol.plan(&loaded, None)?;
    let validation_scored = match &validation {
        Some(v) => Some(args.protocol.validation_scored(&plan, v)?),
        None => None,
    };
    let settings = InversePiSettings {
        starts: args.starts,
        seed: args.seed,
        max_iterations: args.max_iterations,
        screening: if args.no_screening {
            None
        } else {
            InversePiSettings::default().screening
        },
        restarts: InversePiSettings::default().restarts,
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
    say!("{}", describe(record, &loaded.name));
    if let Some(columns) = &loaded.columns {
        say!("columns: {}", describe_columns(columns));
    }
    print_plan(&plan, &loaded.name);

    let reporter = Reporter::new();
    let fit = identify_inverse_pi(record, &plan, &settings, &|e| reporter.event(e))
        .map_err(|e| protocol_failure(&loaded.name, e))?;
    reporter.finish();

    print_inverse_pi_choices(&fit, &plan, &settings, dt);
    let mut notes = Notes::default();
    say!(
        "\nerrors of the voltage each model gives for the measured displacement (RMS, largest; % of the fit part's input span {:.6} V):",
        fit.input_span
    );
    print_inverse_pi_errors("fit part", &fit.fit_errors);
    if let Some(unseen) = &fit.unseen {
        print_inverse_pi_errors("scored part (not seen by the fit)", unseen);
        let y = inverse_model_input(&record.output, fit.smoothing, plan.steps(&record.input));
        let fitted = pad(&plan.fitted(), plan.samples);
        notes.extrapolation("displacement", range_excess(&y, &fitted, &plan.scored()));
        notes.smaller_loops("displacement", "um", &y, &fitted, &plan.scored());
        notes.faster_cycles(&plan, &record.input, dt, &plan.scored());
    }
    notes.few_turns(&plan, &record.input);
    notes.short_score(&plan);
    notes.implausible_stroke(fit.stroke);
    notes.few_levels(&plan);
    let mut validation_errors = None;
    let mut zero_alignment = None;
    if let (Some(v), Some((segments, scored))) = (&validation, &validation_scored) {
        say!("\n{}", describe(&v.record, &v.name));
        if let Some(columns) = &v.columns {
            say!("columns: {}", describe_columns(columns));
        }
        let (output, zero) = args
            .protocol
            .validation_output(&plan, &loaded, v, fit.stroke);
        zero_alignment = Some(zero);
        let steps = plan.validation_steps(segments, &v.record.input, v.record.sample_period);
        let errors = fit.errors_on(
            &output,
            &v.record.input,
            v.record.sample_period,
            steps,
            scored,
        );
        print_inverse_pi_errors("validation file (models from rest at its start)", &errors);
        notes.faster_cycles(&plan, &v.record.input, v.record.sample_period, scored);
        validation_errors = Some(errors);
    }
    say!("time: {:.2} s", fit.seconds);

    let mut files = ResultFiles::default();
    if let Some(path) = &args.protocol.predictions {
        let predictions = fit.predictions_on(&record.output, dt, plan.steps(&record.input));
        let outcome = write_predictions(
            path,
            dt,
            &[
                ("voltage_v", &record.input),
                ("displacement_um", &record.output),
                ("proposed_v", &predictions.proposed),
                ("classical_v", &predictions.classical),
                ("line_v", &predictions.line),
            ],
            &plan,
        );
        files.written("--predictions", "predictions", path, outcome);
    }
    if let Some(out) = &args.out {
        let outcome = write_json(
            out,
            &serde_json::json!({
                "model": "modified inverse Prandtl-Ishlinskii (seed 000 eq. 3-5): voltage from displacement",
                "params": fit.params,
                "displacement_offset_um": fit.offset,
                "smoothing_half_width_samples": fit.smoothing,
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
                "identification": fit,
                "validation": validation.as_ref().map(|v| serde_json::json!({
                    "file": v.name,
                    "columns": v.columns,
                    "zero": zero_alignment,
                    "errors": validation_errors,
                })),
            }),
        );
        files.written("--report", "report", path, outcome);
    }
    files.finish()
}

pub(crate) fn print_inverse_pi_choices(
    fit: &InversePiIdentification,
    plan: &Plan,
    settings: &InversePiSettings,
    dt: f64,
) {
    let smoothing = |h: usize| {
        if h == 0 {
            "none".to_owned()
        } else {
            // The half width too: it is what --smooth takes, the window is not.
            format!(
                "{} samples, half width {h} ({:.1} ms)",
                2 * h + 1,
                1e3 * (2 * h + 1) as f64 * dt
            )
        }
    };
    let weights = |rate: bool| if rate { "rate-dependent" } else { "constant" };
    if let Some(cv) = &fit.cross_validation {
        let ends: std::collections::BTreeSet<usize> =
            cv.proposed.iter().filter_map(|c| c.start).collect();
        say!(
            "\nvalidation inside the fit part: (c, w_s) searched on its first {} fitted samples (to {:.3} s); with each of that search's {} best distinct ends, every candidate's linear part fitted there and scored on the last {} [V RMS; each candidate's best end shown, --report has all]:",
            cv.train_samples,
            cv.train_end as f64 * dt,
            ends.len(),
            cv.validation_samples
        );
        say!(
            "  {:<36} {:<16} {:>12} {:>6}",
            "moving average",
            "backlash weights",
            "RMS [V]",
            "start"
        );
        // The best end for each (smoothing, weights), in the order tried.
        let mut shown: Vec<&Candidate> = Vec::new();
        for c in &cv.proposed {
            match shown
                .iter_mut()
                .find(|s| s.smoothing == c.smoothing && s.rate_dependent == c.rate_dependent)
            {
                Some(best) if c.validation_rms < best.validation_rms => *best = c,
                Some(_) => {}
                None => shown.push(c),
            }
        }
        for c in shown {
            say!(
                "  {:<36} {:<16} {:>12.6} {:>6}",
                smoothing(c.smoothing),
                weights(c.rate_dependent),
                c.validation_rms,
                c.start.map_or(String::new(), |s| s.to_string())
            );
        }
        for c in &cv.classical {
            say!(
                "  {:<36} {:<16} {:>12.6}",
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
    say!(
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
        say!("fastest cycle of the input: {:.3} s", cycle * dt);
    }
    let polished = fit.starts.iter().filter(|s| s.polished).count();
    say!(
        "search: every {} sample(s), {} starts ({}), seed {}; best start {}, F {:.6e} on the searched samples",
        fit.decimation,
        settings.starts,
        match settings.screening {
            Some(s) => format!(
                "{} iterations each, the best {} run on to convergence, restarted at their end, \
                 {} iterations at most",
                s.iterations.min(settings.max_iterations),
                polished.min(s.kept),
                settings.max_iterations
            ),
            None => format!(
                "each to convergence, restarted at its end, {} iterations at most",
                settings.max_iterations
            ),
        },
        settings.seed,
        fit.best_start.unwrap_or(0),
        fit.best_start
            .and_then(|b| fit.starts.get(b))
            .map_or(f64::NAN, |s| s.objective)
    );
    say!(
        "displacement offset {:.6} um; c = {:.6} um, u1max = {:.6}; classical P-I offset {:.6} um",
        fit.offset,
        fit.params.c,
        fit.params.u1max,
        fit.classical_offset
    );
}

pub(crate) fn print_inverse_pi_errors(part: &str, e: &InversePiErrors) {
    say!("{part}, {} samples:", e.proposed.samples);
    print_figure("proposed", &e.proposed, "V");
    print_figure("classical P-I", &e.classical, "V");
    print_figure("straight line", &e.line, "V");
}

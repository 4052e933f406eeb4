//! `piezo-identify compare`: seed 000's model comparison (F of eq. 7 and
//! evaluation time).

use std::path::PathBuf;

use clap::Args;

use piezo_identify::compare::{
    IDENTIFICATION_DURATION, PLANT_SAMPLE_RATE, compare_inverse_models, synthetic_plant_record,
};
use piezo_identify::validation::{centred_moving_average, shifted};
use piezo_identify::{FitError, StartResult};

use super::Failure;
use super::arguments::{ColumnArgs, SearchArgs, load, resolve_offset};
use super::progress::progress_bar;
use super::report::{describe, print_starts};

#[derive(Args)]
pub(crate) struct CompareArgs {
    /// Record to compare on (or --synthetic).
    #[arg(required_unless_present = "synthetic")]
    pub(crate) file: Option<PathBuf>,
    /// Generate the record: seed 000 eq. (6) driving the simulated stage's y
    /// actuator for 10 s at 10 kHz (its columns, rate and zero are its own:
    /// the options that read a file's are refused with it).
    #[arg(long, conflicts_with_all = ["file", "input", "output", "rate", "time", "offset", "smooth"])]
    pub(crate) synthetic: bool,
    #[command(flatten)]
    pub(crate) columns: ColumnArgs,
    #[command(flatten)]
    pub(crate) search: SearchArgs,
    /// Half width [samples] of a centred moving average applied to the
    /// displacement of the record before fitting and evaluation (0: none).
    #[arg(long, default_value_t = 0)]
    pub(crate) smooth: usize,
    /// Displacement offset [µm] for a file, or "auto" (as for inverse-pi).
    /// The synthetic record starts de-energized at 0 and is not shifted.
    #[arg(long, default_value = "auto", allow_negative_numbers = true)]
    pub(crate) offset: String,
    /// Timed passes over the record per model (the median is reported).
    #[arg(long, default_value_t = 31, value_parser = super::arguments::at_least_one)]
    pub(crate) repetitions: usize,
}

/// Decimation of the synthetic 10 kHz record for the search: 500 Hz, 250
/// samples per period of eq. (6)'s fastest (1 Hz) component.
pub(crate) const SYNTHETIC_DECIMATION: usize = 20;

/// A warm-up that leaves fewer samples than a fit needs is refused: one
/// beyond the record printed an infinite offset and a count wrapped below
/// zero (18446744073709359643 scored samples).
fn check_warm_up(seconds: f64, warm_up: usize, samples: usize) -> Result<(), Failure> {
    let left = samples.saturating_sub(warm_up);
    if left < piezo_identify::data::MINIMUM_ROWS {
        return Err(Failure::Input(format!(
            "--warm-up {seconds} s leaves {left} of the record's {samples} samples to fit; \
             a fit needs {} or more",
            piezo_identify::data::MINIMUM_ROWS
        )));
    }
    Ok(())
}

/// The auto offset is the smallest displacement fitted. When that is the
/// first sample and stands out (more than 1 % of the span below every
/// other), it is most likely a start-up reading, not the stage at rest: on
/// the P-885 record sample 0 reads 3.6 um below the rest and, fitted, made
/// most of two models' F. Said, with the way past it.
fn startup_note(fitted: &[f64], warm_up: usize) -> Option<String> {
    let (&first, rest) = fitted.split_first()?;
    let next = rest.iter().copied().fold(f64::INFINITY, f64::min);
    let top = fitted.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let span = top - first.min(next);
    (first < next && next - first > 0.01 * span).then(|| {
        format!(
            "note: the smallest displacement, which the auto offset takes, is the first sample \
             fitted (sample {warm_up}, {first:.6} um), {:.6} um below any other: a start-up \
             reading? --warm-up leaves it out of the offset and the fits",
            next - first
        )
    })
}

pub(crate) fn compare(args: &CompareArgs) -> Result<(), Failure> {
    let (record, name, offset, default_decimation, startup) = if args.synthetic {
        let record = synthetic_plant_record(IDENTIFICATION_DURATION, PLANT_SAMPLE_RATE)
            .map_err(|e| Failure::Run(format!("stage preset: {e}")))?;
        (
            record,
            "synthetic: seed 000 eq. (6) on FlexureStage y, 10 s at 10 kHz".to_owned(),
            0.0,
            SYNTHETIC_DECIMATION,
            None,
        )
    } else {
        let path = args
            .file
            .as_ref()
            .expect("clap requires a file without --synthetic");
        // Read as the fits read a record: a constant column is refused by name.
        let record = load(path, &args.columns)?.record;
        let warm_up = (args.search.warm_up / record.sample_period).round() as usize;
        check_warm_up(args.search.warm_up, warm_up, record.input.len())?;
        super::arguments::check_smoothing(args.smooth, record.input.len())
            .map_err(Failure::Input)?;
        let smoothed = centred_moving_average(&record.output, args.smooth);
        let offset = resolve_offset(&args.offset, &smoothed, warm_up)?;
        let note = if args.offset == "auto" {
            startup_note(&smoothed[warm_up..], warm_up)
        } else {
            None
        };
        (record, path.display().to_string(), offset, 1, note)
    };
    let options = args
        .search
        .options(record.sample_period, default_decimation);
    check_warm_up(
        args.search.warm_up,
        options.warm_up_samples,
        record.input.len(),
    )?;
    let y = shifted(&centred_moving_average(&record.output, args.smooth), offset);
    let u = &record.input;
    say!("{}", describe(&record, &name));
    say!(
        "displacement offset {offset:.6} um; search on every {} sample(s) ({:.1} Hz); F on all {} scored samples",
        options.decimation,
        1.0 / (record.sample_period * options.decimation as f64),
        y.len() - options.warm_up_samples
    );
    if let Some(note) = startup {
        say!("{note}");
    }
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
    .map_err(|e| {
        let message = format!("{name}: {e}");
        match e {
            FitError::Optimizer(_) => Failure::Run(message),
            _ => Failure::Input(message),
        }
    })?;
    bar.finish_and_clear();

    say!(
        "\nbest of {} random starts each (seed {}); F = sum of squared voltage errors (eq. 7)",
        options.starts,
        options.seed
    );
    say!(
        "{:<44} {:>6} {:>14} {:>12} {:>12} {:>16}",
        "model",
        "params",
        "F [V^2]",
        "RMS [V]",
        "max [V]",
        "eval [ns/sample]"
    );
    for s in &comparison.summaries {
        say!(
            "{:<44} {:>6} {:>14.6e} {:>12.6} {:>12.6} {:>16.2}",
            s.name,
            s.parameter_count,
            s.objective,
            s.rms_volts,
            s.max_abs_volts,
            s.evaluation.median_ns_per_sample
        );
    }
    say!(
        "\nevaluation time: median of {} streaming passes over the record (fastest..slowest):",
        args.repetitions
    );
    for s in &comparison.summaries {
        say!(
            "  {:<44} {:.2}..{:.2} ns/sample",
            s.name,
            s.evaluation.fastest_ns_per_sample,
            s.evaluation.slowest_ns_per_sample
        );
    }
    say!("\nrandom starts of each model:");
    let fits = [
        &comparison.proposed.starts,
        &comparison.traditional_six.starts,
        &comparison.traditional_ten.starts,
    ];
    for (s, starts) in comparison.summaries.iter().zip(fits) {
        say!("{}", s.name);
        print_starts(starts, options.max_iterations);
    }
    let p = &comparison.proposed.params;
    say!(
        "\nproposed model: c = {:.6} um, u1max = {:.6} um, ws = {:?}, a = {:?}",
        p.c,
        p.u1max,
        p.ws,
        p.a
    );
    Ok(())
}

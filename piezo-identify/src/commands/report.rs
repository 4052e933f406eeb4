//! What the subcommands print and write: record and plan descriptions, error
//! figures, JSON.

use std::path::Path;

use piezo_identify::data::ColumnsUsed;
use piezo_identify::protocol::{ErrorFigures, Plan};
use piezo_identify::segments::{fastest_cycle, smaller_loops};
use piezo_identify::{Record, StartResult};

use super::Failure;

pub(crate) fn describe(record: &Record, path: &str) -> String {
    format!(
        "{path}: {} samples, {:.2} s at {:.6} Hz",
        record.input.len(),
        record.input.len() as f64 * record.sample_period,
        1.0 / record.sample_period
    )
}

/// "input column 0 \"volts\", output column 4, time column 2, tab-separated,
/// header on line 1".
pub(crate) fn describe_columns(columns: &ColumnsUsed) -> String {
    let mut text = format!("input {}, output {}", columns.input, columns.output);
    if let Some(time) = &columns.time {
        text.push_str(&format!(", time {time}"));
    }
    text.push_str(&format!(", {}-separated", columns.separator.name()));
    if columns.decimal_comma {
        text.push_str(", decimal comma");
    }
    match columns.header_line {
        Some(line) => text.push_str(&format!(", header on line {line}")),
        None => text.push_str(", no header"),
    }
    if let Some(line) = columns.units_line {
        text.push_str(&format!(", units on line {line}"));
    }
    if let Some(unit) = &columns.time_unit {
        text.push_str(&format!(", time in {} ({})", unit.unit, unit.source));
    }
    if columns.latin1 {
        text.push_str(", read as Latin-1 (not UTF-8)");
    }
    if let Some(last) = columns.labview_header {
        text.push_str(&format!(", LabVIEW measurement headers on lines 1-{last}"));
    }
    if let Some(off) = &columns.rate_disagreement {
        text.push_str(&format!(
            "; note: the time column \"{}\" steps by {} s (its median step, {} Hz), not what \
             --rate says: --rate is used",
            off.column,
            piezo_identify::data::Short(off.step),
            piezo_identify::data::Short(1.0 / off.step)
        ));
    }
    text
}

/// The first six of `items`, then how many more ("none" for none): a
/// staircase of 0.2 s stairs has 200 steps in 40 s.
fn at_most_six(items: impl ExactSizeIterator<Item = String>) -> String {
    let total = items.len();
    if total == 0 {
        return "none".to_owned();
    }
    let mut parts: Vec<String> = items.take(6).collect();
    if total > 6 {
        parts.push(format!("and {} more", total - 6));
    }
    parts.join(", ")
}

/// Sample ranges as times, at most six of them.
pub(crate) fn describe_ranges(ranges: &[std::ops::Range<usize>], dt: f64) -> String {
    at_most_six(
        ranges
            .iter()
            .map(|r| format!("{:.3}-{:.3} s", r.start as f64 * dt, r.end as f64 * dt)),
    )
}

/// Sample indices as times, at most six of them.
pub(crate) fn describe_times(samples: &[usize], dt: f64) -> String {
    at_most_six(samples.iter().map(|s| format!("{:.3} s", *s as f64 * dt)))
}

pub(crate) fn print_plan(plan: &Plan, name: &str) {
    let dt = plan.sample_period;
    if plan.has_scored_part() {
        say!(
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
        say!(
            "fit part: the whole of {name} (give --split or --validate-from to score a part of it)"
        );
    }
    say!(
        "rest segments: {}; voltage steps: {}",
        describe_ranges(&plan.segments.rests, dt),
        describe_times(&plan.segments.steps, dt)
    );
    if !plan.segments.stairs.is_empty() {
        say!(
            "the input is held at {} or more levels: a staircase, whose {} stairs are fitted \
             and scored once settled, not left out as rests",
            piezo_identify::segments::STAIRCASE_LEVELS,
            plan.segments.stairs.len()
        );
    }
    let fitted = plan.fitted().iter().filter(|f| **f).count();
    // The warm-up given replaces the default start (settling and first
    // loading), which the line named even then.
    let warm_up = if plan.warm_up_given {
        format!("{:.3} s", plan.warm_up_samples as f64 * dt)
    } else {
        format!(
            "settling {:.3} s and first loading",
            plan.thresholds.settle_samples as f64 * dt
        )
    };
    say!(
        "left out of the fit (warm-up: {warm_up}; rests; settling after steps): {}; {fitted} of {} samples fitted",
        describe_ranges(&plan.fit_excluded, dt),
        plan.fit_end
    );
    if plan.has_scored_part() {
        let scored = plan.scored().iter().filter(|s| **s).count();
        say!(
            "left out of the score (rests, settling after steps): {}; {scored} of {} samples scored",
            describe_ranges(&plan.scored_excluded, dt),
            plan.samples - plan.fit_end
        );
    }
}

/// How far the values at the scored samples reach beyond those at the
/// fitted ones, as a fraction of the fitted span (0 inside).
pub(crate) fn range_excess(values: &[f64], fitted: &[bool], scored: &[bool]) -> f64 {
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

/// A scored input whose fastest cycle is shorter than the fitted one's by
/// more than this factor gets a note ([`Notes::faster_cycles`]).
pub(crate) const FASTER_CYCLE_RATIO: f64 = 2.0;

/// A staircase of this many levels or fewer over the fitted samples gets a
/// note ([`Notes::few_levels`]).
pub(crate) const MAX_NOTED_LEVELS: usize = 20;

/// An input that turns fewer times than this over the fitted samples gets
/// a note ([`Notes::few_turns`]): some branch of its loop was never fitted.
/// On 16 s of a 0.2 s staircase at 200 Hz split in two, the warm-up (to the
/// first loading's end, 5.7 s) leaves one turn to fit, and the proposed
/// model scored 0.091-0.251 % of the input span by seed 0-5 (classical P-I
/// 1.058 %); on 40 s of it, 0.054-0.060 %.
pub(crate) const MIN_FITTED_TURNS: usize = 2;

/// The notes a fit prints after its errors, kept for `--report` too (a
/// script reading the JSON sees what a reader of the summary sees).
#[derive(Default)]
pub(crate) struct Notes(pub(crate) Vec<String>);

/// Strokes [µm] outside these are noted ([`Notes::implausible_stroke`]):
/// piezo stacks and flexure stages travel from a few tenths of a µm to a
/// few mm; 1 nm and 10 cm are a decade and more beyond either end.
const SMALLEST_PLAUSIBLE_STROKE_UM: f64 = 1e-3;
const LARGEST_PLAUSIBLE_STROKE_UM: f64 = 1e5;

impl Notes {
    /// Prints `note` as "note: …" and keeps it.
    pub(crate) fn add(&mut self, note: String) {
        say!("note: {note}");
        self.0.push(note);
    }

    /// A note when the scored `what` reaches beyond the fitted range by more
    /// than 1 % of its span (`excess`, a fraction of it).
    pub(crate) fn extrapolation(&mut self, what: &str, excess: f64) {
        if excess > 0.01 {
            self.add(format!(
                "the scored {what} reaches {:.1} % of the fitted span beyond the fitted range; the models extrapolate there",
                100.0 * excess
            ));
        }
    }

    /// A note when the input turns fewer than [`MIN_FITTED_TURNS`] times
    /// over the fitted samples (`u` the record's input).
    pub(crate) fn few_turns(&mut self, plan: &Plan, u: &[f64]) {
        let turns = plan.fitted_turns(u);
        if turns < MIN_FITTED_TURNS {
            self.add(format!(
                "the input turns {turns} time(s) over the fitted samples (once the warm-up, rests and settling are left out): no whole loop, up and down, was fitted; a longer record or a larger --split fits one"
            ));
        }
    }

    /// A note when the fit part's stroke (µm) is out of any piezo stage's
    /// scale: a displacement in metres (a last word `_m` is not read as a
    /// unit, since `y_m` is as often "y measured") or in pm or counts.
    pub(crate) fn implausible_stroke(&mut self, stroke: f64) {
        if stroke < SMALLEST_PLAUSIBLE_STROKE_UM {
            self.add(format!(
                "the displacement spans {stroke:.3e} um over the fit part: if it is in metres or millimetres, name its unit (`Displacement [m]`, a units row) and it is read in um"
            ));
        } else if stroke > LARGEST_PLAUSIBLE_STROKE_UM {
            self.add(format!(
                "the displacement spans {stroke:.3e} um over the fit part: if it is in nm, pm or sensor counts, name its unit (`Displacement [nm]`, a units row) or scale it to um"
            ));
        }
    }

    /// A note when the scored part holds fewer samples than one cycle of the
    /// fitted input's fastest ([`Plan::fastest_cycle`]): its error then
    /// scores part of a loop (`--split 0.999` scored 5 samples, 1 % of a
    /// cycle, and said nothing of it).
    pub(crate) fn short_score(&mut self, plan: &Plan) {
        let scored = plan.scored().iter().filter(|s| **s).count();
        if let Some(cycle) = plan.fastest_cycle
            && plan.has_scored_part()
            && (scored as f64) < cycle
        {
            self.add(format!(
                "the scored part holds {scored} samples, less than one cycle of the input ({cycle:.0} samples): its error covers part of a loop; a smaller --split scores more"
            ));
        }
    }

    /// A note when the input is a staircase of few levels over the fitted
    /// samples (at most [`MAX_NOTED_LEVELS`]).
    pub(crate) fn few_levels(&mut self, plan: &Plan) {
        if let Some(levels) = plan.stairs
            && levels <= MAX_NOTED_LEVELS
        {
            self.add(format!(
                "the input stands at {levels} levels over the fitted samples (a staircase): the models are fitted, and a split record scored, at those levels; between them they interpolate"
            ));
        }
    }

    /// A note when the scored input's fastest cycle (`u` sampled every
    /// `sample_period` s, scored where `scored` is set) is shorter than half
    /// the fitted one: rate-dependent behaviour (creep, the backlash
    /// weights' rate terms, Bouc-Wen's loops widening with rate) is then
    /// extrapolated (a 200 Hz chirp scored after 1 Hz loops: Bouc-Wen 2.1
    /// times a straight line's error, with nothing said).
    pub(crate) fn faster_cycles(
        &mut self,
        plan: &Plan,
        u: &[f64],
        sample_period: f64,
        scored: &[bool],
    ) {
        let Some(fitted) = plan.fastest_cycle else {
            return;
        };
        let fitted = fitted * plan.sample_period;
        if let Some(cycle) = fastest_cycle(u, scored, plan.thresholds.span) {
            let cycle = cycle * sample_period;
            if cycle < fitted / FASTER_CYCLE_RATIO {
                self.add(format!(
                    "the scored input cycles faster than the fitted one (fastest cycle {cycle:.4} s, the fit part's {fitted:.4} s): how the stage answers faster cycles was not fitted, and the models extrapolate it"
                ));
            }
        }
    }

    /// A note when the scored `what` runs loops under half the size of the
    /// fitted ones ([`smaller_loops`]).
    pub(crate) fn smaller_loops(
        &mut self,
        what: &str,
        unit: &str,
        values: &[f64],
        fitted: &[bool],
        scored: &[bool],
    ) {
        if let Some((scored_median, fitted_small)) = smaller_loops(values, fitted, scored) {
            self.add(format!(
                "the scored {what} runs smaller loops than the fitted one (median travel between turning points {scored_median:.3} {unit}, the fit part's 10th percentile {fitted_small:.3} {unit}); the models were not fitted on loops that small"
            ));
        }
    }
}

/// `flags` of the fit part, extended with `false` to `len` samples.
pub(crate) fn pad(flags: &[bool], len: usize) -> Vec<bool> {
    let mut padded = flags.to_vec();
    padded.resize(len, false);
    padded
}

/// A Bouc-Wen model's parameters on one line, as the summaries print them.
pub(crate) fn bouc_wen_parameters(p: &piezo_models::BoucWenParams) -> String {
    format!(
        "p {:.6e}, q {:+.0}, A {:.6e}, beta {:.6e}, gamma {:.6e}, n {:.4}, delta {:.6e}",
        p.p, p.q, p.a, p.beta, p.gamma, p.n, p.delta
    )
}

pub(crate) fn print_figure(name: &str, e: &ErrorFigures, unit: &str) {
    say!(
        "  {name:<16} RMS {:.6} {unit} ({:.3} %), largest {:.6} {unit} ({:.3} %)",
        e.rms,
        e.rms_percent,
        e.max_abs,
        e.max_percent
    );
}

/// One line on the spread of the random starts.
pub(crate) fn print_starts(starts: &[StartResult], max_iterations: u64) {
    let mut objectives: Vec<f64> = starts.iter().map(|s| s.objective).collect();
    objectives.sort_by(f64::total_cmp);
    let mut iterations: Vec<u64> = starts.iter().map(|s| s.iterations).collect();
    iterations.sort_unstable();
    let best = objectives[0];
    say!(
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

/// Writes a record's samples as CSV: `time_s`, then each named column, then
/// the part of `plan` each sample is in (`fit`, `scored`, `left out`: the
/// warm-up, rests and the settling after steps).
pub(crate) fn write_predictions(
    path: &Path,
    sample_period: f64,
    columns: &[(&str, &[f64])],
    plan: &Plan,
) -> Result<(), Failure> {
    let fitted = pad(&plan.fitted(), plan.samples);
    let scored = plan.scored();
    let mut text = String::from("time_s");
    for (name, _) in columns {
        text.push(',');
        text.push_str(name);
    }
    text.push_str(",part\n");
    for n in 0..plan.samples {
        text.push_str(&format!("{}", n as f64 * sample_period));
        for (_, values) in columns {
            text.push_str(&format!(",{}", values[n]));
        }
        let part = if fitted[n] {
            "fit"
        } else if scored[n] {
            "scored"
        } else {
            "left out"
        };
        text.push(',');
        text.push_str(part);
        text.push('\n');
    }
    write_result(path, text.as_bytes())
}

/// The result files of one run (`--predictions`, `--out`, `--report`),
/// written one after the other: a file that cannot be written (a full disk)
/// does not keep the others from being written, so the fit is not lost, and
/// the run fails at the end naming each option whose file was not written.
#[derive(Default)]
pub(crate) struct ResultFiles {
    failed: Vec<String>,
}

impl ResultFiles {
    /// Records the outcome of writing `what` for `option` to `path`.
    pub(crate) fn written(
        &mut self,
        option: &str,
        what: &str,
        path: &Path,
        outcome: Result<(), Failure>,
    ) {
        match outcome {
            Ok(()) => say!("{what} written to {}", path.display()),
            Err(failure) => self.failed.push(format!("{option}: {}", failure.message())),
        }
    }

    /// Ok when every file was written.
    pub(crate) fn finish(self) -> Result<(), Failure> {
        if self.failed.is_empty() {
            Ok(())
        } else {
            Err(Failure::Run(format!(
                "the fit ran, but not every result file was written: {}",
                self.failed.join("; ")
            )))
        }
    }
}

/// Writes `value` as JSON; a failure here comes after the work was done
/// (the paths were checked before it), so it is the run's.
pub(crate) fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<(), Failure> {
    let json = serde_json::to_string_pretty(value)
        .map_err(|e| Failure::Run(format!("cannot serialise {}: {e}", path.display())))?;
    write_result(path, (json + "\n").as_bytes())
}

/// Writes a result file whole or not at all (`result_files`: a run stopped
/// while writing leaves no cut file under its name); a failure here comes
/// after the work, so it is the run's.
pub(crate) fn write_result(path: &Path, bytes: &[u8]) -> Result<(), Failure> {
    result_files::write_bytes(path, bytes)
        .map_err(|e| Failure::Run(format!("{}: {e}", path.display())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_lists_of_times_end_with_how_many_more() {
        assert_eq!(describe_times(&[], 0.5), "none");
        assert_eq!(describe_times(&[1, 4], 0.5), "0.500 s, 2.000 s");
        let steps: Vec<usize> = (1..=200).collect();
        assert_eq!(
            describe_times(&steps, 0.2),
            "0.200 s, 0.400 s, 0.600 s, 0.800 s, 1.000 s, 1.200 s, and 194 more"
        );
        assert_eq!(describe_ranges(&[], 0.5), "none");
        let ranges: Vec<std::ops::Range<usize>> = (0..7).map(|k| 2 * k..2 * k + 1).collect();
        assert_eq!(
            describe_ranges(&ranges, 1.0),
            "0.000-1.000 s, 2.000-3.000 s, 4.000-5.000 s, 6.000-7.000 s, 8.000-9.000 s, \
             10.000-11.000 s, and 1 more"
        );
    }
}

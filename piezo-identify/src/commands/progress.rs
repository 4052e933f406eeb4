//! Progress on stderr: a bar on a terminal, sparse lines in a log.

use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use piezo_identify::protocol::ProgressEvent;

/// A progress bar on stderr for `total` starts, hidden when stderr is not a
/// terminal; ticked from the rayon workers.
pub(crate) fn progress_bar(total: usize, message: &str) -> ProgressBar {
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
pub(crate) const PROGRESS_INTERVAL_SECONDS: f64 = 2.0;

/// The progress of the identification protocol on stderr: a bar per phase
/// on a terminal, otherwise a line when a phase starts and then at most one
/// every [`PROGRESS_INTERVAL_SECONDS`] (a log, a CI job, a pipe).
pub(crate) struct Reporter {
    pub(crate) terminal: bool,
    pub(crate) started: Instant,
    pub(crate) state: Mutex<ReporterState>,
}

pub(crate) struct ReporterState {
    pub(crate) bar: Option<ProgressBar>,
    pub(crate) phase: String,
    pub(crate) steps: usize,
    pub(crate) done: usize,
    pub(crate) best: f64,
    pub(crate) last_line: Instant,
}

impl Reporter {
    pub(crate) fn new() -> Reporter {
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

    pub(crate) fn event(&self, event: ProgressEvent) {
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

    pub(crate) fn finish(&self) {
        if let Some(bar) = self.state.lock().expect("no panic while held").bar.take() {
            bar.finish_and_clear();
        }
    }
}

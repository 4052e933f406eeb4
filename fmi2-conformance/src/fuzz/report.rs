//! What a run did ([`FuzzReport`]) and the trail of the last calls a
//! failure prints.

use super::*;
use crate::thousands;

pub(super) const STATUS_NAMES: [&str; 5] = ["OK", "Warning", "Discard", "Error", "Fatal"];

/// What a run did.
#[derive(Clone, Debug, Default)]
pub struct FuzzReport {
    pub model: String,
    pub seed: u64,
    /// Every FMI function call made, checked or not returning a status.
    pub calls: u64,
    /// Statuses returned, OK..Fatal (Fatal is always a failure).
    pub by_status: [u64; 5],
    /// fmi2Instantiate, fmi2FreeInstance, fmi2GetTypesPlatform, fmi2GetVersion.
    pub calls_without_status: u64,
    pub instantiated: u64,
    pub instantiations_refused: u64,
    /// Calls refused because the state does not allow them.
    pub illegal_in_state: u64,
    /// Calls made with NULL, foreign or importer-memory instance pointers.
    pub foreign_instance_calls: u64,
    pub steps_completed: u64,
    pub states_restored: u64,
    pub corrupted_states_refused: u64,
    pub forged_states_accepted: u64,
    /// Calls made on an instance in each state (`State::ALL` order).
    pub calls_in_state: [u64; 7],
    /// Instances made for Model Exchange.
    pub model_exchange_instances: u64,
    /// Model Exchange integrator steps completed.
    pub integrator_steps: u64,
    /// Strings fmi2GetString returned, each checked (a valid C string in
    /// UTF-8, the value set, still the same at the next call on the instance).
    pub strings_read: u64,
    /// String values fmi2SetString accepted.
    pub strings_set: u64,
    /// fmi2SetString calls refused for a NULL or non-UTF-8 element.
    pub bad_strings_refused: u64,
    pub by_function: BTreeMap<&'static str, [u64; 5]>,
    pub elapsed: Duration,
}

impl FuzzReport {
    /// Column of [`FuzzReport::table_cells`] that holds the wall time.
    pub const TIME_CELL: usize = 1;

    /// The run's figures as the fuzz table of docs/robustness.md prints them,
    /// after the run's label: calls, time, crashes, statuses (OK / Warning /
    /// Discard / Error), forged states accepted, and strings read / set /
    /// calls refused for a NULL or non-UTF-8 string ("none to read or set"
    /// for an FMU without String variables).
    pub fn table_cells(&self) -> Vec<String> {
        let [ok, warning, discard, error, _fatal] = self.by_status.map(thousands);
        let strings = if self.strings_read == 0 && self.strings_set == 0 {
            "none to read or set".to_owned()
        } else {
            format!(
                "{} / {} / {}",
                thousands(self.strings_read),
                thousands(self.strings_set),
                thousands(self.bad_strings_refused)
            )
        };
        vec![
            thousands(self.calls),
            format!("{:.2} s", self.elapsed.as_secs_f64()),
            "0".to_owned(), // a crash ends the run before its report
            format!("{ok} / {warning} / {discard} / {error}"),
            thousands(self.forged_states_accepted),
            strings,
        ]
    }
}

impl fmt::Display for FuzzReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let secs = self.elapsed.as_secs_f64();
        writeln!(
            f,
            "fmi fuzz {}: seed {:#x}, {} calls in {:.2} s ({:.0} calls/s), crashes 0",
            self.model,
            self.seed,
            self.calls,
            secs,
            self.calls as f64 / secs.max(1e-9)
        )?;
        write!(f, "  statuses:")?;
        for (name, n) in STATUS_NAMES.iter().zip(self.by_status) {
            write!(f, " {name} {n}")?;
        }
        writeln!(
            f,
            "; no status (instantiate/free/platform/version) {}",
            self.calls_without_status
        )?;
        writeln!(
            f,
            "  instances {} (refused {}), illegal in state {}, foreign instance pointers {}",
            self.instantiated,
            self.instantiations_refused,
            self.illegal_in_state,
            self.foreign_instance_calls
        )?;
        writeln!(
            f,
            "  model-exchange instances {}, integrator steps {}",
            self.model_exchange_instances, self.integrator_steps
        )?;
        writeln!(
            f,
            "  steps completed {}, states restored {}, corrupted states refused {}, forged states accepted {}",
            self.steps_completed,
            self.states_restored,
            self.corrupted_states_refused,
            self.forged_states_accepted
        )?;
        writeln!(
            f,
            "  strings read {}, strings set {}, calls with a NULL or non-UTF-8 string refused {}",
            self.strings_read, self.strings_set, self.bad_strings_refused
        )?;
        write!(f, "  calls in state:")?;
        for (state, n) in State::ALL.iter().zip(self.calls_in_state) {
            write!(f, " {state:?} {n}")?;
        }
        writeln!(f)?;
        for (function, counts) in &self.by_function {
            write!(f, "  {function:<30}")?;
            for (name, n) in STATUS_NAMES.iter().zip(counts) {
                if *n > 0 {
                    write!(f, " {name} {n}")?;
                }
            }
            writeln!(f)?;
        }
        Ok(())
    }
}

#[derive(Clone, Copy)]
pub(super) struct TraceEntry {
    pub(super) call: u64,
    pub(super) function: &'static str,
    pub(super) slot: Option<usize>,
    pub(super) state: Option<State>,
    pub(super) status: Option<sys::fmi2Status>,
}

impl fmt::Display for TraceEntry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "#{} {}", self.call, self.function)?;
        match self.slot {
            Some(slot) => write!(f, " on slot {slot}")?,
            None => write!(f, " on a foreign pointer")?,
        }
        if let Some(state) = self.state {
            write!(f, " in {state:?}")?;
        }
        if let Some(status) = self.status {
            write!(
                f,
                " -> {}",
                STATUS_NAMES
                    .get(status as usize)
                    .copied()
                    .unwrap_or("INVALID")
            )?;
        }
        Ok(())
    }
}

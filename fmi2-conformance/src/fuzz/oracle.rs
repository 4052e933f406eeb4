//! The oracle: its model of each instance (values, times, machine state,
//! and what the fuzzer did to it), the objects it hands the FMU, and the
//! checks common to every call (status, log, other instances silent).

use super::*;

/// The oracle's model of what an instance holds.
#[derive(Clone, Debug)]
pub(super) struct Shadow {
    /// Current value of each settable variable (by index in the description;
    /// Integer and Boolean as f64), `None` where not settable or a String.
    pub(super) values: Vec<Option<f64>>,
    /// Current value of each settable String variable (by index), `None`
    /// elsewhere.
    pub(super) strings: Vec<Option<String>>,
    pub(super) time: f64,
    /// The `startTime` of the last successful `fmi2SetupExperiment`.
    pub(super) start_time: f64,
    /// Its `stopTime`, infinite when it defined none: a co-simulation step
    /// must not end past it.
    pub(super) stop_time: f64,
    /// In an FMU state: the machine state it was taken in and the interface of
    /// its instance (restoring it puts the instance there). In a live
    /// instance: the interface; the machine state is `Live::state`.
    pub(super) machine: State,
    pub(super) interface: Interface,
    /// Model Exchange: continuous states were set to values the fuzzer chose
    /// (not integrated), so the model may refuse to go on from them.
    pub(super) wild_states: bool,
    /// Restored from a forged state: values and time are unknown.
    pub(super) tainted: bool,
    /// A step failed with fmi2Error: the FMU reported that its model could
    /// not compute, and its outputs may be anything until a reset or restore.
    pub(super) failed: bool,
}

pub(super) struct Live {
    pub(super) c: sys::fmi2Component,
    pub(super) sink: Box<LogSink>,
    pub(super) _callbacks: Box<sys::fmi2CallbackFunctions>,
    pub(super) name: String,
    pub(super) has_logger: bool,
    pub(super) state: State,
    pub(super) model: Shadow,
    /// The strings the last `fmi2GetString` on this instance returned, with
    /// their text: the FMU's until the next call on the instance (FMI 2.0.4
    /// §2.1.7), so they must still read the same when that call is made,
    /// calls on other instances in between.
    pub(super) lent: Vec<(sys::fmi2String, String)>,
}

/// An FMU state the fuzzer got from the FMU and has not freed.
pub(super) struct Handle {
    pub(super) ptr: sys::fmi2FMUstate,
    /// The slot whose instance made it: freed before that instance is.
    pub(super) owner: usize,
    pub(super) model: Shadow,
}

pub(super) struct Blob {
    pub(super) bytes: Vec<u8>,
    pub(super) model: Shadow,
}

/// Objects that are not instances of the FMU under test.
pub(super) struct Foreign<'f> {
    pub(super) instance: crate::Instance<'f>,
    pub(super) state: sys::fmi2FMUstate,
    pub(super) bytes: Vec<u8>,
}

/// A pointer passed where an instance is expected that is not one.
#[derive(Clone, Copy, Debug)]
pub(super) enum NotAnInstance {
    Null,
    OwnFmuState,
    ForeignInstance,
    ForeignFmuState,
    ZeroedMemory,
    RandomMemory,
}

impl Fuzzer<'_> {
    pub(super) fn fail(&self, message: String) -> ! {
        let trace: Vec<String> = self.trace.iter().map(|t| t.to_string()).collect();
        panic!(
            "fmi fuzz {} found a problem at call {} (seed {:#x}):\n{message}\nlast calls:\n  {}\n\
             replay: FMI_FUZZ_SEED={:#x} FMI_FUZZ_CALLS={}",
            self.report.model,
            self.report.calls,
            self.report.seed,
            trace.join("\n  "),
            self.report.seed,
            self.report.calls
        );
    }

    /// The strings the last `fmi2GetString` on the instance in `slot` lent
    /// still read what they read then; checked when the next call on the
    /// instance is about to be made, after which they may go.
    pub(super) fn verify_lent_strings(&mut self, slot: usize) {
        let Some(live) = self.slots[slot].as_mut() else {
            return;
        };
        let lent = std::mem::take(&mut live.lent);
        for (pointer, text) in lent {
            // SAFETY: a string this instance's fmi2GetString returned, which
            // the FMU keeps valid until the next call on the instance; that
            // call has not been made yet.
            let now = unsafe { std::ffi::CStr::from_ptr(pointer) };
            if now.to_bytes() != text.as_bytes() {
                self.fail(format!(
                    "a string fmi2GetString returned changed before the next call on its \
                     instance: {text:?} now reads {now:?}"
                ));
            }
        }
    }

    /// Counts a call before it is made (so that the watchdog and a failure
    /// name its number).
    pub(super) fn begin(&mut self, function: &'static str, slot: Option<usize>) {
        if let Some(slot) = slot {
            self.verify_lent_strings(slot);
        }
        self.report.calls += 1;
        self.progress.store(self.report.calls, Ordering::Relaxed);
        let state = slot.and_then(|s| self.slots[s].as_ref()).map(|l| l.state);
        if let Some(state) = state {
            self.report.calls_in_state[State::ALL.iter().position(|s| *s == state).unwrap()] += 1;
        }
        if self.trace.len() == 32 {
            self.trace.pop_front();
        }
        self.trace.push_back(TraceEntry {
            call: self.report.calls,
            function,
            slot,
            state,
            status: None,
        });
    }

    pub(super) fn count_status(&mut self, function: &'static str, status: sys::fmi2Status) {
        if let Some(last) = self.trace.back_mut() {
            last.status = Some(status);
        }
        if status > FATAL {
            self.fail(format!(
                "{function} returned {status}, which is no fmi2Status"
            ));
        }
        self.report.by_status[status as usize] += 1;
        self.report.by_function.entry(function).or_default()[status as usize] += 1;
        if status == FATAL {
            self.fail(format!("{function} returned fmi2Fatal"));
        }
    }

    /// No logger but `except`'s received anything.
    pub(super) fn others_silent(&mut self, except: Option<usize>) {
        for (slot, live) in self.slots.iter().enumerate() {
            if Some(slot) == except {
                continue;
            }
            if let Some(live) = live {
                let log = live.sink.take();
                if !log.is_empty() {
                    self.fail(format!(
                        "slot {slot} ({}) received messages from a call on another instance: {log:#?}",
                        live.name
                    ));
                }
            }
        }
        if let Some(foreign) = &self.foreign {
            let log = foreign.instance.take_log();
            if !log.is_empty() {
                self.fail(format!(
                    "the other FMU's instance received messages from a call on this one: {log:#?}"
                ));
            }
        }
    }

    /// Checks a status-returning call on the instance in `slot`: the status is
    /// one of `allowed`, an error was logged under the function's name (as an
    /// illegal call sequence when `illegal`), no other instance heard of it,
    /// and the instance is in its error state after `fmi2Error`. Returns the
    /// instance's log.
    pub(super) fn check(
        &mut self,
        slot: usize,
        function: &'static str,
        status: sys::fmi2Status,
        allowed: &[sys::fmi2Status],
        illegal: bool,
        arguments: impl FnOnce() -> String,
    ) -> Vec<LogRecord> {
        self.count_status(function, status);
        let live = self.slots[slot].as_ref().expect("a live instance");
        let log = live.sink.take();
        let state = live.state;
        if !allowed.contains(&status) {
            let allowed: Vec<&str> = allowed.iter().map(|s| STATUS_NAMES[*s as usize]).collect();
            self.fail(format!(
                "{function}({}) on {} in state {state:?} returned {}, expected {}{}; log: \
                 {log:#?}\n{}",
                arguments(),
                live.name,
                STATUS_NAMES[status as usize],
                allowed.join(" or "),
                if illegal {
                    " (illegal in this state)"
                } else {
                    ""
                },
                self.describe(slot)
            ));
        }
        for record in &log {
            // The layer turns a panic into fmi2Error with this line: no call
            // sequence, forged FMU states included, may reach one.
            if record.message.contains("internal error (panic)") {
                self.fail(format!("{function} panicked inside the FMU: {record:#?}"));
            }
            let category_known = self.categories.contains(&record.category);
            if record.status > FATAL || !category_known || record.instance_name != live.name {
                self.fail(format!(
                    "{function}: a malformed log record (status, category or instance name): {record:#?}"
                ));
            }
        }
        if status == ERROR && live.has_logger {
            let named = log
                .iter()
                .any(|r| r.status == ERROR && r.message.starts_with(function));
            let reason = !illegal
                || log
                    .iter()
                    .any(|r| r.message.contains("illegal call sequence"));
            if !named || !reason {
                self.fail(format!(
                    "{function}({}) in state {state:?} returned fmi2Error without {}: {log:#?}",
                    arguments(),
                    if named {
                        "saying \"illegal call sequence\""
                    } else {
                        "an error message under the function's name"
                    }
                ));
            }
        }
        if illegal {
            self.report.illegal_in_state += 1;
        }
        self.others_silent(Some(slot));
        if status == ERROR {
            self.slots[slot].as_mut().unwrap().state = State::Error;
        }
        log
    }

    /// The oracle's model of the instance in `slot`: state, time and every
    /// value that differs from its start value (for failure messages).
    pub(super) fn describe(&self, slot: usize) -> String {
        let Some(live) = self.slots[slot].as_ref() else {
            return format!("slot {slot}: empty");
        };
        let changed: Vec<String> = self
            .fmu
            .variables
            .iter()
            .zip(&live.model.values)
            .filter(|(v, value)| {
                value.is_some() && value.map(f64::to_bits) != v.start.map(f64::to_bits)
            })
            .map(|(v, value)| format!("{} = {:e}", v.name, value.unwrap()))
            .chain(
                self.fmu
                    .variables
                    .iter()
                    .zip(&live.model.strings)
                    .filter(|(v, text)| text.is_some() && **text != v.start_string)
                    .map(|(v, text)| format!("{} = {:?}", v.name, text.as_deref().unwrap())),
            )
            .collect();
        format!(
            "slot {slot} ({}): {:?} {:?}, time {:e}, start time {:e}, wild states {}, tainted {}, failed {}, set: {}",
            live.name,
            live.model.interface,
            live.state,
            live.model.time,
            live.model.start_time,
            live.model.wild_states,
            live.model.tainted,
            live.model.failed,
            changed.join(", ")
        )
    }

    pub(super) fn live(&self, slot: usize) -> &Live {
        self.slots[slot].as_ref().expect("a live instance")
    }

    pub(super) fn live_mut(&mut self, slot: usize) -> &mut Live {
        self.slots[slot].as_mut().expect("a live instance")
    }

    /// Whether the instance in `slot` is in a condition where any finite step
    /// must succeed: start parameters, modest inputs, no failed step or forged
    /// state behind it.
    pub(super) fn pristine(&self, slot: usize) -> bool {
        let live = self.live(slot);
        !live.model.tainted
            && !live.model.failed
            && self.fmu.variables.iter().enumerate().all(|(index, v)| {
                let value = live.model.values[index];
                match v.causality {
                    Causality::Parameter => {
                        value.map(f64::to_bits) == v.start.map(f64::to_bits)
                            && live.model.strings[index] == v.start_string
                    }
                    Causality::Input => value.is_none_or(|x| x.abs() <= 1e3),
                    _ => true,
                }
            })
    }
}

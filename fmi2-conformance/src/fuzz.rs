//! A seeded call-sequence fuzzer: random FMI calls with random arguments, on
//! several instances at once, through the C ABI as an importer makes them.
//!
//! Every call is checked against an oracle that keeps its own model of each
//! instance, written from the standard (FMI 2.0.4) and the modelDescription,
//! not from the layer under test:
//!
//! - the interface of the instance (Co-Simulation, or Model Exchange when the
//!   FMU offers it) and its FMI state, moved by every call that returns, and
//!   [`allowed`] (§4.2.4, §3.2.3) to decide whether a call is legal in it;
//!   after `fmi2Error` the instance is in its error state (§2.1.3: "the
//!   simulation cannot be continued with this FMU instance"), which
//!   `fmi2Reset`, `fmi2FreeInstance` and the restore of an FMU state leave;
//! - the value of every parameter and input (start values from the
//!   modelDescription, then what was set), its time and start time; FMU states
//!   and serialized states carry a copy of that model and the machine state
//!   they were taken in, so restoring one restores the oracle's too, state
//!   machine included.
//!
//! The oracle demands: no crash, no abort, no hang (a watchdog aborts a call
//! that runs for a minute); every status is an `fmi2Status` (never Pending or
//! Fatal); a call illegal in the state returns `fmi2Error` and logs
//! "illegal call sequence" under the function's name; a call with an illegal
//! argument returns `fmi2Error` and logs why under the function's name; a legal
//! call with legal arguments succeeds (`fmi2Warning` where the standard's
//! rules call for one, `fmi2Discard` for status kinds a synchronous slave
//! cannot answer); values read back equal the values set; Real values read
//! after success are finite; no message reaches another instance's logger.
//!
//! Where the outcome depends on the model (a parameter set that the model's
//! own validation may refuse, huge inputs a model may not survive), the oracle
//! accepts success or `fmi2Error` with a log line, and nothing else.
//!
//! What the fuzzer never does, because it is the importer's undefined
//! behaviour and no FMU can detect it: pass an instance or FMU state after it
//! was freed (§2.1.5: the pointer is invalid afterwards; the layer poisons its
//! magic number on free, but memory reused by the allocator can hold anything,
//! and a test that relied on it would make valgrind findings meaningless),
//! pass arrays shorter than their length argument, or pass a pointer to less
//! than eight readable bytes as an instance. It does pass NULL, pointers to
//! other objects of the layer (FMU states as instances), the other FMU's live
//! instances and states (a master that mixes up its FMUs), and pointers to
//! importer memory (zeroed or random bytes).

// FMU-state pointers the FMU returned are handed back to it, as an importer does.
#![allow(clippy::not_unsafe_ptr_arg_deref)]

use std::collections::{BTreeMap, VecDeque};
use std::ffi::{CString, c_char, c_void};
use std::fmt;
use std::ptr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use fmi_schema::fmi2::{Causality, Variability};
use fmi_sys::fmi2 as sys;
use rand::{RngExt, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::{DISCARD, ERROR, Fmu, Interface, LogRecord, LogSink, OK, State, WARNING, allowed};

/// The fuzzer's Model Exchange calls.
mod model_exchange;

const FATAL: sys::fmi2Status = sys::fmi2Status_fmi2Fatal;
const STATUS_NAMES: [&str; 5] = ["OK", "Warning", "Discard", "Error", "Fatal"];

/// Instances alive at once (slots the fuzzer fills, frees and refills).
const SLOTS: usize = 4;
/// FMU states and serialized states the fuzzer keeps to pass back.
const MAX_HANDLES: usize = 12;
const MAX_BLOBS: usize = 12;
/// A call that has not returned after this long is a hang.
const HANG_LIMIT: Duration = Duration::from_secs(60);
/// Serialized state layout of fmi2-cosim (fmu_state.rs): magic, version, GUID,
/// payload length; then the payload and a CRC-32 of everything before it.
/// Used only to forge states whose checksum is right and whose payload is not.
const STATE_HEADER_LEN: usize = 8 + 4 + 38 + 8;
const STATE_CRC_LEN: usize = 4;

/// Calls and seed of a run: the defaults of the test, or `FMI_FUZZ_CALLS` and
/// `FMI_FUZZ_SEED` (decimal or 0x-hex, '_' allowed) to run longer by hand or
/// to replay a failure.
#[derive(Clone, Copy, Debug)]
pub struct FuzzConfig {
    pub calls: u64,
    pub seed: u64,
}

impl FuzzConfig {
    pub fn from_env(default_calls: u64, default_seed: u64) -> FuzzConfig {
        fn read(name: &str) -> Option<u64> {
            let text = std::env::var(name).ok()?.replace('_', "");
            let parsed = match text.strip_prefix("0x") {
                Some(hex) => u64::from_str_radix(hex, 16),
                None => text.parse(),
            };
            Some(parsed.unwrap_or_else(|e| panic!("{name}={text:?} is not a number: {e}")))
        }
        FuzzConfig {
            calls: read("FMI_FUZZ_CALLS").unwrap_or(default_calls),
            seed: read("FMI_FUZZ_SEED").unwrap_or(default_seed),
        }
    }
}

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
    pub by_function: BTreeMap<&'static str, [u64; 5]>,
    pub elapsed: Duration,
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

/// The fuzz test of an FMU crate: [`run`] with the budget of [`FuzzConfig::from_env`],
/// the report printed, and the coverage a generator that stopped reaching a
/// state or a function would lose asserted.
pub fn assert_rules_hold(fmu: &Fmu, foreign: &Fmu, default_calls: u64, default_seed: u64) {
    let config = FuzzConfig::from_env(default_calls, default_seed);
    let report = run(fmu, Some(foreign), config);
    println!("{report}");
    assert!(report.calls >= config.calls, "{report}");
    // Every state was visited and every status-returning function called: a
    // generator that stopped reaching a state would pass without testing it.
    let model_exchange = fmu.offers_model_exchange();
    for (state, n) in State::ALL.iter().zip(report.calls_in_state) {
        let reachable = State::CO_SIMULATION.contains(state)
            || (model_exchange && State::MODEL_EXCHANGE.contains(state));
        assert_eq!(n > 0, reachable, "calls in {state:?}\n{report}");
    }
    let functions = 30 + if model_exchange { 10 } else { 0 };
    assert_eq!(report.by_function.len(), functions, "{report}");
    assert!(
        report.steps_completed > 0 && report.states_restored > 0,
        "{report}"
    );
    if model_exchange {
        assert!(
            report.model_exchange_instances > 0 && report.integrator_steps > 0,
            "{report}"
        );
    }
}

/// Runs `config.calls` calls on `fmu`; `foreign`, another FMU built with the
/// same layer, provides instances and states to pass by mistake. Panics with
/// the seed, the call number and the last calls when the oracle objects.
pub fn run(fmu: &Fmu, foreign: Option<&Fmu>, config: FuzzConfig) -> FuzzReport {
    let progress = Arc::new(AtomicU64::new(0));
    let done = Arc::new(AtomicBool::new(false));
    let watchdog = {
        let (progress, done) = (progress.clone(), done.clone());
        let model = fmu.description.model_name.clone();
        let seed = config.seed;
        std::thread::spawn(move || watchdog(progress, done, model, seed))
    };
    let started = Instant::now();
    let mut fuzzer = Fuzzer::new(fmu, foreign, config.seed, progress);
    while fuzzer.report.calls < config.calls {
        fuzzer.step();
    }
    fuzzer.finish();
    fuzzer.report.elapsed = started.elapsed();
    done.store(true, Ordering::Relaxed);
    watchdog.join().expect("the watchdog thread ends");
    std::mem::take(&mut fuzzer.report)
}

/// Aborts the process when no call completes for [`HANG_LIMIT`]: a hang in the
/// FMU would otherwise stall the test suite until CI's time runs out.
fn watchdog(progress: Arc<AtomicU64>, done: Arc<AtomicBool>, model: String, seed: u64) {
    let mut last = (progress.load(Ordering::Relaxed), Instant::now());
    while !done.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(200));
        let now = progress.load(Ordering::Relaxed);
        if now != last.0 {
            last = (now, Instant::now());
        } else if last.1.elapsed() > HANG_LIMIT {
            eprintln!(
                "fmi fuzz {model}: call {now} has not returned after {HANG_LIMIT:?} (a hang); \
                 replay with FMI_FUZZ_SEED={seed:#x} FMI_FUZZ_CALLS={}",
                now + 1
            );
            std::process::abort();
        }
    }
}

/// The oracle's model of what an instance holds.
#[derive(Clone, Debug)]
struct Shadow {
    /// Current value of each settable variable (by index in the description;
    /// Integer and Boolean as f64), `None` where not settable.
    values: Vec<Option<f64>>,
    time: f64,
    /// The `startTime` of the last successful `fmi2SetupExperiment`.
    start_time: f64,
    /// In an FMU state: the machine state it was taken in and the interface of
    /// its instance (restoring it puts the instance there). In a live
    /// instance: the interface; the machine state is `Live::state`.
    machine: State,
    interface: Interface,
    /// Model Exchange: continuous states were set to values the fuzzer chose
    /// (not integrated), so the model may refuse to go on from them.
    wild_states: bool,
    /// Restored from a forged state: values and time are unknown.
    tainted: bool,
    /// A step failed with fmi2Error: the FMU reported that its model could
    /// not compute, and its outputs may be anything until a reset or restore.
    failed: bool,
}

struct Live {
    c: sys::fmi2Component,
    sink: Box<LogSink>,
    _callbacks: Box<sys::fmi2CallbackFunctions>,
    name: String,
    has_logger: bool,
    state: State,
    model: Shadow,
}

/// An FMU state the fuzzer got from the FMU and has not freed.
struct Handle {
    ptr: sys::fmi2FMUstate,
    /// The slot whose instance made it: freed before that instance is.
    owner: usize,
    model: Shadow,
}

struct Blob {
    bytes: Vec<u8>,
    model: Shadow,
}

/// Objects that are not instances of the FMU under test.
struct Foreign<'f> {
    instance: crate::Instance<'f>,
    state: sys::fmi2FMUstate,
    bytes: Vec<u8>,
}

/// A pointer passed where an instance is expected that is not one.
#[derive(Clone, Copy, Debug)]
enum NotAnInstance {
    Null,
    OwnFmuState,
    ForeignInstance,
    ForeignFmuState,
    ZeroedMemory,
    RandomMemory,
}

#[derive(Clone, Copy)]
struct TraceEntry {
    call: u64,
    function: &'static str,
    slot: Option<usize>,
    state: Option<State>,
    status: Option<sys::fmi2Status>,
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

/// Instance-taking functions and their weights in the random choice.
const FUNCTIONS: &[(&str, u32)] = &[
    ("fmi2SetDebugLogging", 3),
    ("fmi2SetupExperiment", 5),
    ("fmi2EnterInitializationMode", 5),
    ("fmi2ExitInitializationMode", 5),
    ("fmi2Terminate", 2),
    ("fmi2Reset", 3),
    ("fmi2GetReal", 10),
    ("fmi2GetInteger", 3),
    ("fmi2GetBoolean", 3),
    ("fmi2GetString", 1),
    ("fmi2SetReal", 12),
    ("fmi2SetInteger", 3),
    ("fmi2SetBoolean", 3),
    ("fmi2SetString", 1),
    ("fmi2GetFMUstate", 5),
    ("fmi2SetFMUstate", 5),
    ("fmi2FreeFMUstate", 3),
    ("fmi2SerializedFMUstateSize", 2),
    ("fmi2SerializeFMUstate", 4),
    ("fmi2DeSerializeFMUstate", 6),
    ("fmi2GetDirectionalDerivative", 1),
    ("fmi2SetRealInputDerivatives", 1),
    ("fmi2GetRealOutputDerivatives", 1),
    ("fmi2DoStep", 16),
    ("fmi2CancelStep", 1),
    ("fmi2GetStatus", 1),
    ("fmi2GetRealStatus", 2),
    ("fmi2GetIntegerStatus", 1),
    ("fmi2GetBooleanStatus", 1),
    ("fmi2GetStringStatus", 1),
    ("fmi2FreeInstance", 1),
];

fn legal(interface: Interface, function: &str, state: State) -> bool {
    function == "fmi2FreeInstance" || allowed(interface, function, state)
}

struct Fuzzer<'a> {
    fmu: &'a Fmu,
    rng: Xoshiro256PlusPlus,
    slots: Vec<Option<Live>>,
    handles: Vec<Handle>,
    blobs: Vec<Blob>,
    foreign: Option<Foreign<'a>>,
    zeroed: Box<[u64; 256]>,
    random: Box<[u64; 256]>,
    report: FuzzReport,
    trace: VecDeque<TraceEntry>,
    progress: Arc<AtomicU64>,
    instances_made: u64,
    /// Variable index of each value reference.
    by_vr: BTreeMap<u32, usize>,
    /// Value references by type name ("Real", ...).
    by_kind: BTreeMap<&'static str, Vec<u32>>,
    settable_by_kind: BTreeMap<&'static str, Vec<u32>>,
    real_outputs: Vec<u32>,
    real_inputs: Vec<u32>,
    unknown_vrs: Vec<u32>,
    categories: Vec<String>,
    fresh: Shadow,
}

impl<'a> Fuzzer<'a> {
    fn new(fmu: &'a Fmu, foreign: Option<&'a Fmu>, seed: u64, progress: Arc<AtomicU64>) -> Self {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let mut by_vr = BTreeMap::new();
        let mut by_kind: BTreeMap<&'static str, Vec<u32>> = BTreeMap::new();
        let mut settable_by_kind: BTreeMap<&'static str, Vec<u32>> = BTreeMap::new();
        let mut values = Vec::new();
        for (index, v) in fmu.variables.iter().enumerate() {
            by_vr.insert(v.vr, index);
            by_kind.entry(v.kind).or_default().push(v.vr);
            let settable = matches!(v.causality, Causality::Parameter | Causality::Input);
            if settable {
                settable_by_kind.entry(v.kind).or_default().push(v.vr);
            }
            values.push(if settable { v.start } else { None });
        }
        let real_outputs = fmu
            .with_causality(Causality::Output)
            .filter(|v| v.kind == "Real")
            .map(|v| v.vr)
            .collect();
        let real_inputs = fmu
            .with_causality(Causality::Input)
            .filter(|v| v.kind == "Real")
            .map(|v| v.vr)
            .collect();
        let max_vr = fmu.variables.iter().map(|v| v.vr).max().unwrap_or(0);
        let unknown_vrs = vec![max_vr + 1, max_vr + 1000, u32::MAX, u32::MAX - 1, 1 << 31];
        let categories = fmu
            .description
            .log_categories
            .as_ref()
            .map(|c| c.categories.iter().map(|c| c.name.clone()).collect())
            .unwrap_or_default();
        let foreign = foreign.map(|other| {
            let mut instance = other.instantiate("foreign", false);
            instance.initialize();
            assert_eq!(instance.do_step(1e-4), OK, "the foreign FMU steps");
            let (status, state) = instance.get_state();
            assert_eq!(status, OK, "the foreign FMU gives a state");
            let (status, bytes) = instance.serialize(state);
            assert_eq!(status, OK, "the foreign FMU serializes its state");
            instance.take_log();
            Foreign {
                instance,
                state,
                bytes,
            }
        });
        let mut random = Box::new([0u64; 256]);
        for word in random.iter_mut() {
            *word = rng.random();
        }
        Fuzzer {
            fmu,
            rng,
            slots: (0..SLOTS).map(|_| None).collect(),
            handles: Vec::new(),
            blobs: Vec::new(),
            foreign,
            zeroed: Box::new([0u64; 256]),
            random,
            report: FuzzReport {
                model: fmu.description.model_name.clone(),
                seed,
                ..FuzzReport::default()
            },
            trace: VecDeque::with_capacity(32),
            progress,
            instances_made: 0,
            by_vr,
            by_kind,
            settable_by_kind,
            real_outputs,
            real_inputs,
            unknown_vrs,
            categories,
            fresh: Shadow {
                values,
                time: 0.0,
                start_time: 0.0,
                machine: State::Instantiated,
                interface: Interface::CoSimulation,
                wild_states: false,
                tainted: false,
                failed: false,
            },
        }
    }

    // ----- bookkeeping and the checks common to every call -----

    fn fail(&self, message: String) -> ! {
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

    /// Counts a call before it is made (so that the watchdog and a failure
    /// name its number).
    fn begin(&mut self, function: &'static str, slot: Option<usize>) {
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

    fn count_status(&mut self, function: &'static str, status: sys::fmi2Status) {
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
    fn others_silent(&mut self, except: Option<usize>) {
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
    fn check(
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
    fn describe(&self, slot: usize) -> String {
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

    fn live(&self, slot: usize) -> &Live {
        self.slots[slot].as_ref().expect("a live instance")
    }

    fn live_mut(&mut self, slot: usize) -> &mut Live {
        self.slots[slot].as_mut().expect("a live instance")
    }

    // ----- random choices -----

    fn chance(&mut self, p: f64) -> bool {
        self.rng.random_bool(p)
    }

    fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[self.rng.random_range(0..items.len())]
    }

    fn pick_function(&mut self, interface: Interface, state: State) -> &'static str {
        let only_legal = self.chance(0.75);
        let candidates: Vec<(&'static str, u32)> = self
            .functions()
            .filter(|(f, _)| !only_legal || legal(interface, f, state))
            .collect();
        let total: u32 = candidates.iter().map(|(_, w)| w).sum();
        let mut x = self.rng.random_range(0..total);
        for (function, weight) in candidates {
            if x < weight {
                return function;
            }
            x -= weight;
        }
        unreachable!("the weights sum to the total")
    }

    /// A Real value for variable `index`: mostly plausible, often hostile.
    fn real_value(&mut self, index: usize, current: Option<f64>) -> f64 {
        let start = self.fmu.variables[index].start.unwrap_or(0.0);
        match self.rng.random_range(0..100) {
            0..22 => current.unwrap_or(start),
            22..34 => start,
            34..48 => start * self.rng.random_range(0.5..2.0),
            48..60 => self.rng.random_range(-10.0..10.0),
            60..64 => self.pick(&[0.0, -0.0]),
            64..70 => self.pick(&[1e15, -1e15, 1e300, -1e300, f64::MAX, f64::MIN]),
            70..74 => self.pick(&[5e-324, -5e-324, f64::MIN_POSITIVE / 2.0, f64::MIN_POSITIVE]),
            74..79 => f64::from_bits(0x7ff8_0000_0000_0000 | self.rng.random_range(0..1u64 << 51)),
            79..84 => self.pick(&[f64::INFINITY, f64::NEG_INFINITY]),
            84..90 => f64::from_bits(self.rng.random()),
            _ => -start.abs() - self.rng.random_range(0.0..10.0),
        }
    }

    fn integer_value(&mut self, index: usize, current: Option<f64>) -> i32 {
        let start = self.fmu.variables[index].start.unwrap_or(0.0) as i32;
        match self.rng.random_range(0..10) {
            0..3 => current.map_or(start, |v| v as i32),
            3..5 => start,
            5 => self.pick(&[0, 1, 2, 3, -1]),
            6 => self.pick(&[i32::MIN, i32::MAX]),
            _ => self.rng.random(),
        }
    }

    fn boolean_value(&mut self, current: Option<f64>) -> sys::fmi2Boolean {
        match self.rng.random_range(0..10) {
            0..4 => current.map_or(0, |v| v as sys::fmi2Boolean),
            4..6 => 0,
            6..8 => 1,
            // Not fmi2True but true in C.
            _ => self.pick(&[2, -1, i32::MAX]),
        }
    }

    /// Value references for a call on type `kind`.
    fn vrs(&mut self, kind: &'static str, settable: bool) -> Vec<u32> {
        let n = match self.rng.random_range(0..20) {
            0..2 => 0,
            2..10 => 1,
            10..18 => self.rng.random_range(2..=8),
            _ => self.rng.random_range(9..=64),
        };
        let preferred = if settable {
            self.settable_by_kind.get(kind)
        } else {
            self.by_kind.get(kind)
        }
        .cloned()
        .unwrap_or_default();
        let everything: Vec<u32> = self.by_vr.keys().copied().collect();
        (0..n)
            .map(|_| match self.rng.random_range(0..100) {
                0..80 if !preferred.is_empty() => self.pick(&preferred),
                80..92 => self.pick(&everything),
                92..97 => {
                    let unknown = self.unknown_vrs.clone();
                    self.pick(&unknown)
                }
                _ => self.rng.random(),
            })
            .collect()
    }

    /// Which variable each vr names if all name a variable of `kind`;
    /// `Err(reason)` when the FMU must refuse.
    fn resolve(&self, vrs: &[u32], kind: &str) -> Result<Vec<usize>, String> {
        vrs.iter()
            .map(|vr| match self.by_vr.get(vr) {
                None => Err(format!("unknown value reference {vr}")),
                Some(i) if self.fmu.variables[*i].kind != kind => Err(format!(
                    "value reference {vr} is {}, not {kind}",
                    self.fmu.variables[*i].kind
                )),
                Some(i) => Ok(*i),
            })
            .collect()
    }

    /// A pointer that is not an instance of the FMU under test.
    fn not_an_instance(&mut self) -> (NotAnInstance, *mut c_void) {
        loop {
            let kind = self.pick(&[
                NotAnInstance::Null,
                NotAnInstance::OwnFmuState,
                NotAnInstance::ForeignInstance,
                NotAnInstance::ForeignFmuState,
                NotAnInstance::ZeroedMemory,
                NotAnInstance::RandomMemory,
            ]);
            let pointer = match kind {
                NotAnInstance::Null => ptr::null_mut(),
                NotAnInstance::OwnFmuState if !self.handles.is_empty() => {
                    self.handles[self.rng.random_range(0..self.handles.len())].ptr
                }
                NotAnInstance::ForeignInstance if self.foreign.is_some() => {
                    self.foreign.as_ref().unwrap().instance.c
                }
                NotAnInstance::ForeignFmuState if self.foreign.is_some() => {
                    self.foreign.as_ref().unwrap().state
                }
                NotAnInstance::ZeroedMemory => self.zeroed.as_mut_ptr().cast(),
                NotAnInstance::RandomMemory => self.random.as_mut_ptr().cast(),
                _ => continue,
            };
            return (kind, pointer);
        }
    }

    /// An FMU-state argument: one of ours (`Some(index)`) or something else.
    fn state_argument(&mut self, own: f64) -> (Option<usize>, sys::fmi2FMUstate) {
        if !self.handles.is_empty() && self.chance(own) {
            let index = self.rng.random_range(0..self.handles.len());
            return (Some(index), self.handles[index].ptr);
        }
        let pointer = match self.rng.random_range(0..4) {
            0 => ptr::null_mut(),
            // An instance where a state belongs.
            1 => self
                .slots
                .iter()
                .flatten()
                .next()
                .map_or(ptr::null_mut(), |l| l.c),
            2 => self.foreign.as_ref().map_or(ptr::null_mut(), |f| f.state),
            _ => self.zeroed.as_mut_ptr().cast(),
        };
        (None, pointer)
    }

    // ----- the random walk -----

    fn step(&mut self) {
        let slot = self.rng.random_range(0..SLOTS);
        if self.slots[slot].is_none() {
            self.instantiate(slot);
            return;
        }
        match self.rng.random_range(0..1000) {
            0..30 => return self.call_on_foreign_pointer(),
            30..45 => return self.burst(slot),
            45..48 => return self.platform_and_version(),
            _ => {}
        }
        let (state, interface) = (self.live(slot).state, self.live(slot).model.interface);
        let function = self.pick_function(interface, state);
        self.call(slot, function, false);
    }

    /// The functions this FMU's binary exports, with their weights: the Model
    /// Exchange ones only when it offers Model Exchange.
    fn functions(&self) -> impl Iterator<Item = (&'static str, u32)> + use<> {
        let model_exchange = self.fmu.offers_model_exchange();
        FUNCTIONS.iter().copied().chain(
            model_exchange::FUNCTIONS
                .iter()
                .copied()
                .filter(move |_| model_exchange),
        )
    }

    /// Whether `function` is legal on the instance in `slot` now.
    fn legal_now(&self, slot: usize, function: &str) -> bool {
        let live = self.live(slot);
        legal(live.model.interface, function, live.state)
    }

    fn call(&mut self, slot: usize, function: &'static str, benign: bool) {
        match function {
            "fmi2SetDebugLogging" => self.set_debug_logging(slot, benign),
            "fmi2SetupExperiment" => self.setup_experiment(slot, benign),
            "fmi2EnterInitializationMode" => self.simple(slot, function),
            "fmi2ExitInitializationMode" => self.exit_initialization_mode(slot),
            "fmi2Terminate" | "fmi2Reset" | "fmi2CancelStep" => self.simple(slot, function),
            "fmi2GetReal" | "fmi2GetInteger" | "fmi2GetBoolean" | "fmi2GetString" => {
                self.get(slot, function, benign)
            }
            "fmi2SetReal" | "fmi2SetInteger" | "fmi2SetBoolean" | "fmi2SetString" => {
                self.set(slot, function, benign)
            }
            "fmi2GetFMUstate" => self.get_fmu_state(slot, benign),
            "fmi2SetFMUstate" => self.set_fmu_state(slot, benign),
            "fmi2FreeFMUstate" => self.free_fmu_state(slot, benign),
            "fmi2SerializedFMUstateSize" => self.serialized_size(slot, benign),
            "fmi2SerializeFMUstate" => self.serialize(slot, benign),
            "fmi2DeSerializeFMUstate" => self.deserialize(slot, benign),
            "fmi2GetDirectionalDerivative"
            | "fmi2SetRealInputDerivatives"
            | "fmi2GetRealOutputDerivatives" => self.not_offered(slot, function),
            "fmi2DoStep" => self.do_step(slot, benign),
            "fmi2GetStatus"
            | "fmi2GetRealStatus"
            | "fmi2GetIntegerStatus"
            | "fmi2GetBooleanStatus"
            | "fmi2GetStringStatus" => self.status_query(slot, function, benign),
            "fmi2FreeInstance" => self.free_instance(slot),
            other => self.call_model_exchange(slot, other, benign),
        }
    }

    /// A run of legal calls that drives the instance to StepComplete and steps
    /// it many times with plausible inputs: random walks alone rarely get deep.
    fn burst(&mut self, slot: usize) {
        if self.live(slot).model.interface == Interface::ModelExchange {
            return self.burst_model_exchange(slot);
        }
        let path: &[&'static str] = match self.live(slot).state {
            State::Instantiated => &[
                "fmi2SetupExperiment",
                "fmi2EnterInitializationMode",
                "fmi2ExitInitializationMode",
            ],
            State::InitializationMode => &["fmi2ExitInitializationMode"],
            State::StepComplete => &[],
            State::Terminated | State::Error => &[
                "fmi2Reset",
                "fmi2SetupExperiment",
                "fmi2EnterInitializationMode",
                "fmi2ExitInitializationMode",
            ],
            State::EventMode | State::ContinuousTimeMode => {
                unreachable!("a co-simulation instance")
            }
        };
        for function in path {
            self.call(slot, function, true);
            if self.live(slot).state == State::Error {
                return;
            }
        }
        let steps = self.rng.random_range(10..200);
        let terminate = self.chance(0.3);
        for _ in 0..steps {
            if self.live(slot).state != State::StepComplete {
                return;
            }
            match self.rng.random_range(0..10) {
                0..3 => self.set(slot, "fmi2SetReal", true),
                3 => self.get(slot, "fmi2GetReal", true),
                4 if self.chance(0.1) => self.get_fmu_state(slot, true),
                4 if self.chance(0.1) => self.set_fmu_state(slot, true),
                _ => self.do_step(slot, true),
            }
        }
        // Some runs end as a master ends them, and the calls that follow meet
        // a terminated instance.
        if terminate && self.live(slot).state == State::StepComplete {
            self.simple(slot, "fmi2Terminate");
        }
    }

    fn platform_and_version(&mut self) {
        let b = &self.fmu.binding;
        self.begin("fmi2GetTypesPlatform", None);
        self.report.calls_without_status += 1;
        let platform = unsafe { std::ffi::CStr::from_ptr(b.fmi2GetTypesPlatform()) };
        self.begin("fmi2GetVersion", None);
        self.report.calls_without_status += 1;
        let version = unsafe { std::ffi::CStr::from_ptr(b.fmi2GetVersion()) };
        if platform.to_bytes() != b"default" || version.to_bytes() != b"2.0" {
            self.fail(format!("platform {platform:?}, version {version:?}"));
        }
    }

    // ----- instance lifetime -----

    fn instantiate(&mut self, slot: usize) {
        self.instances_made += 1;
        let name = match self.rng.random_range(0..100) {
            0..85 => format!("fuzz{slot}-{}", self.instances_made),
            85..90 => "%s%d%n%%".to_owned(),
            90..93 => "x".repeat(3000),
            93..95 => "µ-инстанс".to_owned(),
            _ => String::new(),
        };
        let null_name = self.chance(0.04);
        let fmu_type = match self.rng.random_range(0..20) {
            0..8 => sys::fmi2Type_fmi2ModelExchange,
            8 => self.rng.random_range(2..1000),
            _ => sys::fmi2Type_fmi2CoSimulation,
        };
        let interface = if fmu_type == sys::fmi2Type_fmi2ModelExchange {
            Interface::ModelExchange
        } else {
            Interface::CoSimulation
        };
        let own_guid = self.fmu.guid.clone();
        let guid = match self.rng.random_range(0..40) {
            0 => None,
            1 => Some(own_guid.to_uppercase()),
            2 => Some(own_guid.trim_matches(|c| c == '{' || c == '}').to_owned()),
            3 => Some("{00000000-0000-0000-0000-000000000000}".to_owned()),
            4 => Some(String::new()),
            _ => Some(own_guid.clone()),
        };
        let location = match self.rng.random_range(0..20) {
            0..12 => None,
            12..15 => Some("file:///tmp/fuzz%20dir/resources"),
            15 => Some("http://example.org/resources"),
            16 => Some("not a uri"),
            17 => Some("file:"),
            18 => Some(""),
            _ => Some("file://localhost/tmp/%ZZ"),
        };
        let (null_functions, has_logger) = match self.rng.random_range(0..40) {
            0 => (true, false),
            1 => (false, false),
            _ => (false, true),
        };
        let logging_on = self.rng.random_range(0..3) as sys::fmi2Boolean;
        let visible = self.rng.random_range(0..2) as sys::fmi2Boolean;

        let sink = Box::new(LogSink::default());
        let mut callbacks = Box::new(crate::callbacks_for(&sink));
        if !has_logger {
            callbacks.logger = None;
        }
        let name_c = CString::new(name.clone()).expect("no NUL in names");
        let guid_c = guid.as_ref().map(|g| CString::new(g.as_str()).unwrap());
        let location_c = location.map(|l| CString::new(l).unwrap());
        self.begin("fmi2Instantiate", Some(slot));
        self.report.calls_without_status += 1;
        let c = unsafe {
            self.fmu.binding.fmi2Instantiate(
                if null_name {
                    ptr::null()
                } else {
                    name_c.as_ptr()
                },
                fmu_type,
                guid_c.as_ref().map_or(ptr::null(), |g| g.as_ptr()),
                location_c.as_ref().map_or(ptr::null(), |l| l.as_ptr()),
                if null_functions {
                    ptr::null()
                } else {
                    &*callbacks
                },
                visible,
                logging_on,
            )
        };
        let type_offered = fmu_type == sys::fmi2Type_fmi2CoSimulation
            || (fmu_type == sys::fmi2Type_fmi2ModelExchange && self.fmu.offers_model_exchange());
        let acceptable = !null_name
            && !null_functions
            && type_offered
            && guid.as_deref() == Some(own_guid.as_str());
        let log = sink.take();
        self.others_silent(None);
        let describe = || {
            format!(
                "name {:?}, type {fmu_type}, GUID {guid:?}, location {location:?}, functions {}, logger {}",
                (!null_name).then_some(&name),
                !null_functions,
                has_logger
            )
        };
        if c.is_null() {
            if acceptable {
                self.fail(format!(
                    "fmi2Instantiate refused legal arguments ({}): {log:#?}",
                    describe()
                ));
            }
            if has_logger && !log.iter().any(|r| r.status == ERROR) {
                self.fail(format!(
                    "fmi2Instantiate refused ({}) without an error message: {log:#?}",
                    describe()
                ));
            }
            self.report.instantiations_refused += 1;
            return;
        }
        if !acceptable {
            self.fail(format!("fmi2Instantiate accepted {}", describe()));
        }
        self.report.instantiated += 1;
        if interface == Interface::ModelExchange {
            self.report.model_exchange_instances += 1;
        }
        let mut model = self.fresh.clone();
        model.interface = interface;
        self.slots[slot] = Some(Live {
            c,
            sink,
            _callbacks: callbacks,
            name,
            has_logger,
            state: State::Instantiated,
            model,
        });
    }

    fn free_instance(&mut self, slot: usize) {
        // The states the instance made are freed with it (FMI 2.0.4 §2.1.5:
        // fmi2FreeInstance frees all memory the FMU interface allocated), so a
        // careful importer frees them first or never uses them again; the
        // fuzzer does either.
        let owned: Vec<usize> = (0..self.handles.len())
            .filter(|i| self.handles[*i].owner == slot)
            .collect();
        let free_first = self.chance(0.5);
        for index in owned.into_iter().rev() {
            if free_first {
                self.free_handle(slot, index);
            } else {
                self.handles.swap_remove(index);
            }
        }
        let live = self.slots[slot].take().expect("a live instance");
        self.begin("fmi2FreeInstance", Some(slot));
        self.report.calls_without_status += 1;
        unsafe { self.fmu.binding.fmi2FreeInstance(live.c) };
        // Messages sent while freeing (call tracing) belong to the instance.
        for record in live.sink.take() {
            if record.status >= ERROR {
                self.fail(format!("fmi2FreeInstance logged an error: {record:#?}"));
            }
        }
        self.others_silent(None);
    }

    /// Frees our handle `index` through the instance in `slot`, checked.
    fn free_handle(&mut self, slot: usize, index: usize) {
        let mut pointer = self.handles[index].ptr;
        self.begin("fmi2FreeFMUstate", Some(slot));
        let status = unsafe {
            self.fmu
                .binding
                .fmi2FreeFMUstate(self.live(slot).c, &mut pointer)
        };
        self.check(slot, "fmi2FreeFMUstate", status, &[OK], false, || {
            "one of its own states".to_owned()
        });
        if !pointer.is_null() {
            self.fail("fmi2FreeFMUstate returned OK but left *FMUstate non-NULL".to_owned());
        }
        self.handles.swap_remove(index);
    }

    /// Frees everything, checked, and verifies that the other FMU's instance
    /// still works after the calls aimed at it by mistake.
    fn finish(&mut self) {
        for slot in 0..SLOTS {
            if self.slots[slot].is_some() {
                self.free_instance(slot);
            }
        }
        if !self.handles.is_empty() {
            self.fail(format!(
                "{} FMU states outlived their instances",
                self.handles.len()
            ));
        }
        if let Some(mut foreign) = self.foreign.take() {
            let log = foreign.instance.take_log();
            if !log.is_empty() {
                self.fail(format!(
                    "the other FMU's instance heard of this one's calls: {log:#?}"
                ));
            }
            if foreign.instance.do_step(1e-4) != OK {
                self.fail(format!(
                    "the other FMU's instance no longer steps: {:#?}",
                    foreign.instance.take_log()
                ));
            }
            if foreign.instance.free_state(&mut foreign.state) != OK {
                self.fail("the other FMU's state could not be freed".to_owned());
            }
        }
    }

    // ----- calls on things that are not instances -----

    fn call_on_foreign_pointer(&mut self) {
        let (kind, c) = self.not_an_instance();
        let functions: Vec<(&'static str, u32)> = self.functions().collect();
        let function = self.pick(&functions).0;
        self.report.foreign_instance_calls += 1;
        self.begin(function, None);
        let b = &self.fmu.binding;
        let mut reals = [0.0f64; 4];
        let mut ints = [0i32; 4];
        let mut strings: [sys::fmi2String; 4] = [ptr::null(); 4];
        let vrs = [0u32; 4];
        let mut size = 0usize;
        let mut bytes = [0u8; 64];
        let mut state_slot: sys::fmi2FMUstate = ptr::null_mut();
        let mut status_value = OK;
        let status = unsafe {
            match function {
                "fmi2SetDebugLogging" => b.fmi2SetDebugLogging(c, 1, 0, ptr::null()),
                "fmi2SetupExperiment" => b.fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0),
                "fmi2EnterInitializationMode" => b.fmi2EnterInitializationMode(c),
                "fmi2ExitInitializationMode" => b.fmi2ExitInitializationMode(c),
                "fmi2Terminate" => b.fmi2Terminate(c),
                "fmi2Reset" => b.fmi2Reset(c),
                "fmi2GetReal" => b.fmi2GetReal(c, vrs.as_ptr(), 1, reals.as_mut_ptr()),
                "fmi2GetInteger" => b.fmi2GetInteger(c, vrs.as_ptr(), 1, ints.as_mut_ptr()),
                "fmi2GetBoolean" => b.fmi2GetBoolean(c, vrs.as_ptr(), 1, ints.as_mut_ptr()),
                "fmi2GetString" => b.fmi2GetString(c, vrs.as_ptr(), 1, strings.as_mut_ptr()),
                "fmi2SetReal" => b.fmi2SetReal(c, vrs.as_ptr(), 1, reals.as_ptr()),
                "fmi2SetInteger" => b.fmi2SetInteger(c, vrs.as_ptr(), 1, ints.as_ptr()),
                "fmi2SetBoolean" => b.fmi2SetBoolean(c, vrs.as_ptr(), 1, ints.as_ptr()),
                "fmi2SetString" => b.fmi2SetString(c, vrs.as_ptr(), 1, strings.as_ptr()),
                "fmi2GetFMUstate" => b.fmi2GetFMUstate(c, &mut state_slot),
                "fmi2SetFMUstate" => {
                    let (_, state) = self.state_argument(0.5);
                    b.fmi2SetFMUstate(c, state)
                }
                "fmi2FreeFMUstate" => {
                    let (_, state) = self.state_argument(0.5);
                    let mut state = state;
                    b.fmi2FreeFMUstate(c, &mut state)
                }
                "fmi2SerializedFMUstateSize" => {
                    let (_, state) = self.state_argument(0.5);
                    b.fmi2SerializedFMUstateSize(c, state, &mut size)
                }
                "fmi2SerializeFMUstate" => {
                    let (_, state) = self.state_argument(0.5);
                    b.fmi2SerializeFMUstate(c, state, bytes.as_mut_ptr().cast(), bytes.len())
                }
                "fmi2DeSerializeFMUstate" => {
                    let source = self
                        .blobs
                        .first()
                        .map_or(&bytes[..], |blob| &blob.bytes[..]);
                    b.fmi2DeSerializeFMUstate(
                        c,
                        source.as_ptr().cast(),
                        source.len(),
                        &mut state_slot,
                    )
                }
                "fmi2GetDirectionalDerivative" => b.fmi2GetDirectionalDerivative(
                    c,
                    vrs.as_ptr(),
                    1,
                    vrs.as_ptr(),
                    1,
                    reals.as_ptr(),
                    reals.as_mut_ptr(),
                ),
                "fmi2SetRealInputDerivatives" => {
                    b.fmi2SetRealInputDerivatives(c, vrs.as_ptr(), 1, ints.as_ptr(), reals.as_ptr())
                }
                "fmi2GetRealOutputDerivatives" => b.fmi2GetRealOutputDerivatives(
                    c,
                    vrs.as_ptr(),
                    1,
                    ints.as_ptr(),
                    reals.as_mut_ptr(),
                ),
                "fmi2DoStep" => b.fmi2DoStep(c, 0.0, 1e-4, 0),
                "fmi2CancelStep" => b.fmi2CancelStep(c),
                "fmi2GetStatus" => {
                    b.fmi2GetStatus(c, sys::fmi2StatusKind_fmi2DoStepStatus, &mut status_value)
                }
                "fmi2GetRealStatus" => b.fmi2GetRealStatus(
                    c,
                    sys::fmi2StatusKind_fmi2LastSuccessfulTime,
                    reals.as_mut_ptr(),
                ),
                "fmi2GetIntegerStatus" => b.fmi2GetIntegerStatus(
                    c,
                    sys::fmi2StatusKind_fmi2DoStepStatus,
                    ints.as_mut_ptr(),
                ),
                "fmi2GetBooleanStatus" => {
                    b.fmi2GetBooleanStatus(c, sys::fmi2StatusKind_fmi2Terminated, ints.as_mut_ptr())
                }
                "fmi2GetStringStatus" => b.fmi2GetStringStatus(
                    c,
                    sys::fmi2StatusKind_fmi2PendingStatus,
                    strings.as_mut_ptr(),
                ),
                "fmi2FreeInstance" => {
                    b.fmi2FreeInstance(c);
                    self.report.calls_without_status += 1;
                    self.others_silent(None);
                    self.check_foreign_alive(kind);
                    return;
                }
                other => model_exchange::call_on_pointer(b, other, c),
            }
        };
        self.count_status(function, status);
        if status != ERROR {
            self.fail(format!(
                "{function} on {kind:?} ({c:?}) returned {}, expected fmi2Error",
                STATUS_NAMES[status as usize]
            ));
        }
        if !state_slot.is_null() {
            self.fail(format!("{function} on {kind:?} returned an FMU state"));
        }
        self.others_silent(None);
        self.check_foreign_alive(kind);
    }

    /// After a call aimed at the other FMU's instance or state by mistake, that
    /// instance still works and its state is still a state.
    fn check_foreign_alive(&mut self, kind: NotAnInstance) {
        if !matches!(
            kind,
            NotAnInstance::ForeignInstance | NotAnInstance::ForeignFmuState
        ) {
            return;
        }
        let Some(foreign) = self.foreign.as_mut() else {
            return;
        };
        let stepped = foreign.instance.do_step(1e-4);
        let restored = foreign.instance.set_state(foreign.state);
        let log = foreign.instance.take_log();
        foreign.instance.time = {
            let mut time = 0.0;
            unsafe {
                foreign.instance.fmu.binding.fmi2GetRealStatus(
                    foreign.instance.c,
                    sys::fmi2StatusKind_fmi2LastSuccessfulTime,
                    &mut time,
                )
            };
            time
        };
        if stepped != OK || restored != OK {
            self.fail(format!(
                "a call on the other FMU's {kind:?} through this FMU broke it (doStep {stepped}, \
                 setFMUstate {restored}): {log:#?}"
            ));
        }
    }

    // ----- the functions -----

    /// Functions without arguments: Enter, Terminate, Reset, CancelStep.
    fn simple(&mut self, slot: usize, function: &'static str) {
        let is_legal = self.legal_now(slot, function);
        let c = self.live(slot).c;
        let b = &self.fmu.binding;
        self.begin(function, Some(slot));
        let status = unsafe {
            match function {
                "fmi2EnterInitializationMode" => b.fmi2EnterInitializationMode(c),
                "fmi2Terminate" => b.fmi2Terminate(c),
                "fmi2Reset" => b.fmi2Reset(c),
                "fmi2CancelStep" => b.fmi2CancelStep(c),
                other => unreachable!("{other} is not simple"),
            }
        };
        let allowed = if is_legal { [OK] } else { [ERROR] };
        self.check(slot, function, status, &allowed, !is_legal, String::new);
        if status != OK {
            return;
        }
        let fresh = self.fresh.clone();
        let live = self.live_mut(slot);
        match function {
            "fmi2EnterInitializationMode" => live.state = State::InitializationMode,
            "fmi2Terminate" => live.state = State::Terminated,
            "fmi2Reset" => {
                live.state = State::Instantiated;
                live.model = Shadow {
                    interface: live.model.interface,
                    ..fresh
                };
            }
            _ => unreachable!("fmi2CancelStep is never legal here"),
        }
    }

    fn setup_experiment(&mut self, slot: usize, benign: bool) {
        let start = if benign {
            self.pick(&[0.0, 0.0, 0.0, 1.5, -2.0, 1e3])
        } else {
            match self.rng.random_range(0..20) {
                0..12 => 0.0,
                12..15 => self.rng.random_range(-1e3..1e3),
                15 => self.pick(&[1e300, -1e300, 1e15]),
                16 => f64::NAN,
                17 => self.pick(&[f64::INFINITY, f64::NEG_INFINITY]),
                18 => 5e-324,
                _ => f64::from_bits(self.rng.random()),
            }
        };
        let stop_defined = !benign && self.chance(0.3);
        let stop = match self.rng.random_range(0..6) {
            0 | 1 => start + self.rng.random_range(0.0..10.0),
            2 => start - 1.0,
            3 => f64::NAN,
            4 => f64::INFINITY,
            _ => f64::NEG_INFINITY,
        };
        let tolerance_defined = self.rng.random_range(0..2);
        let tolerance = self.pick(&[1e-6, 0.0, -1.0, f64::NAN]);
        let is_legal = self.legal_now(slot, "fmi2SetupExperiment");
        let valid = start.is_finite() && (!stop_defined || (!stop.is_nan() && stop >= start));
        self.begin("fmi2SetupExperiment", Some(slot));
        let status = unsafe {
            self.fmu.binding.fmi2SetupExperiment(
                self.live(slot).c,
                tolerance_defined,
                tolerance,
                start,
                stop_defined as sys::fmi2Boolean,
                stop,
            )
        };
        let allowed = if is_legal && valid { [OK] } else { [ERROR] };
        self.check(
            slot,
            "fmi2SetupExperiment",
            status,
            &allowed,
            !is_legal,
            || format!("startTime {start}, stopTimeDefined {stop_defined}, stopTime {stop}"),
        );
        if status == OK {
            let live = self.live_mut(slot);
            live.model.start_time = start;
            live.model.time = start;
        }
    }

    fn exit_initialization_mode(&mut self, slot: usize) {
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, "fmi2ExitInitializationMode");
        // A parameter outside its declared range must be refused; other
        // changed parameters are for the model to judge.
        let mut out_of_range = None;
        let mut changed = self.live(slot).model.tainted;
        for (index, v) in self.fmu.variables.iter().enumerate() {
            if v.causality != Causality::Parameter {
                continue;
            }
            let value = self.live(slot).model.values[index];
            if value.map(f64::to_bits) != v.start.map(f64::to_bits) {
                changed = true;
            }
            if let Some(value) = value
                && (v.min.is_some_and(|min| value < min) || v.max.is_some_and(|max| value > max))
            {
                out_of_range = Some(format!(
                    "{} = {value} outside [{:?}, {:?}]",
                    v.name, v.min, v.max
                ));
            }
        }
        let allowed: &[sys::fmi2Status] =
            if !is_legal || (out_of_range.is_some() && !self.live(slot).model.tainted) {
                &[ERROR]
            } else if changed {
                &[OK, ERROR]
            } else {
                &[OK]
            };
        self.begin("fmi2ExitInitializationMode", Some(slot));
        let status = unsafe { self.fmu.binding.fmi2ExitInitializationMode(c) };
        self.check(
            slot,
            "fmi2ExitInitializationMode",
            status,
            allowed,
            !is_legal,
            || {
                out_of_range
                    .clone()
                    .unwrap_or_else(|| format!("parameters changed: {changed}"))
            },
        );
        if status == OK {
            let live = self.live_mut(slot);
            live.state = match live.model.interface {
                Interface::CoSimulation => State::StepComplete,
                Interface::ModelExchange => State::EventMode,
            };
            // The model is built anew from its parameters.
            live.model.failed = false;
            live.model.wild_states = false;
            live.model.time = live.model.start_time;
        }
    }

    fn set_debug_logging(&mut self, slot: usize, benign: bool) {
        let mut names: Vec<CString> = Vec::new();
        let count = self.rng.random_range(0..5);
        let mut unknown = false;
        for _ in 0..count {
            let name = match self.rng.random_range(0..10) {
                0..6 if !self.categories.is_empty() => {
                    let i = self.rng.random_range(0..self.categories.len());
                    self.categories[i].clone().into_bytes()
                }
                6 => b"logAll".to_vec(),
                _ if benign => b"logAll".to_vec(),
                7 => {
                    unknown = true;
                    self.pick(&[&b""[..], b"logNothing", b"%s%s%n%d", b"\xff\xfe"])
                        .to_vec()
                }
                8 => {
                    unknown = true;
                    vec![b'%'; 2000]
                }
                _ => {
                    unknown = true;
                    b"LOGALL".to_vec()
                }
            };
            names.push(CString::new(name).unwrap());
        }
        let mut pointers: Vec<*const c_char> = names.iter().map(|n| n.as_ptr()).collect();
        let null_entry = !benign && !pointers.is_empty() && self.chance(0.05);
        if null_entry {
            let i = self.rng.random_range(0..pointers.len());
            pointers[i] = ptr::null();
        }
        let null_array = !benign && self.chance(0.04);
        let n = if null_array {
            self.rng.random_range(1..4)
        } else {
            pointers.len()
        };
        let logging_on = self.pick(&[0, 1, 1, 2]);
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, "fmi2SetDebugLogging");
        let allowed = if !is_legal || null_array || null_entry {
            [ERROR]
        } else if unknown {
            [WARNING]
        } else {
            [OK]
        };
        self.begin("fmi2SetDebugLogging", Some(slot));
        let status = unsafe {
            self.fmu.binding.fmi2SetDebugLogging(
                c,
                logging_on,
                n,
                if null_array || (n == 0 && self.rng.random_bool(0.5)) {
                    ptr::null()
                } else {
                    pointers.as_ptr()
                },
            )
        };
        self.check(slot, "fmi2SetDebugLogging", status, &allowed, !is_legal, || {
            format!("loggingOn {logging_on}, {n} categories {names:?}, NULL array {null_array}, NULL entry {null_entry}")
        });
    }

    fn get(&mut self, slot: usize, function: &'static str, benign: bool) {
        let kind = match function {
            "fmi2GetReal" => "Real",
            "fmi2GetInteger" => "Integer",
            "fmi2GetBoolean" => "Boolean",
            _ => "String",
        };
        let vrs = if benign && kind == "Real" {
            self.real_outputs.clone()
        } else {
            self.vrs(kind, false)
        };
        let null_vr = !benign && !vrs.is_empty() && self.chance(0.04);
        let null_values = !benign && !vrs.is_empty() && self.chance(0.04);
        // NULL arrays may come with any length: nothing may be read.
        let n = if (null_vr || null_values) && self.chance(0.2) {
            self.pick(&[usize::MAX, 1 << 40, 100_000])
        } else {
            vrs.len()
        };
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, function);
        let resolved = self.resolve(&vrs, kind);
        let valid = n == 0 || (!null_vr && !null_values && resolved.is_ok());
        let vr_ptr = if null_vr { ptr::null() } else { vrs.as_ptr() };
        let len = vrs.len().max(1);
        let mut reals = vec![f64::NAN; len];
        let mut ints = vec![i32::MIN; len];
        let mut strings: Vec<sys::fmi2String> = vec![ptr::null(); len];
        let b = &self.fmu.binding;
        self.begin(function, Some(slot));
        let status = unsafe {
            match kind {
                "Real" => b.fmi2GetReal(
                    c,
                    vr_ptr,
                    n,
                    if null_values {
                        ptr::null_mut()
                    } else {
                        reals.as_mut_ptr()
                    },
                ),
                "Integer" => b.fmi2GetInteger(
                    c,
                    vr_ptr,
                    n,
                    if null_values {
                        ptr::null_mut()
                    } else {
                        ints.as_mut_ptr()
                    },
                ),
                "Boolean" => b.fmi2GetBoolean(
                    c,
                    vr_ptr,
                    n,
                    if null_values {
                        ptr::null_mut()
                    } else {
                        ints.as_mut_ptr()
                    },
                ),
                _ => b.fmi2GetString(
                    c,
                    vr_ptr,
                    n,
                    if null_values {
                        ptr::null_mut()
                    } else {
                        strings.as_mut_ptr()
                    },
                ),
            }
        };
        // A state derivative is computed when read: from states or
        // parameters the fuzzer chose it may overflow, which the layer refuses
        // as fmi2GetDerivatives does.
        let reads_derivative = resolved
            .as_ref()
            .is_ok_and(|indices| indices.iter().any(|i| self.fmu.is_derivative(*i)));
        let allowed: &[sys::fmi2Status] = if !is_legal || !valid {
            &[ERROR]
        } else if reads_derivative && !self.pristine_model_exchange(slot) {
            &[OK, ERROR]
        } else {
            &[OK]
        };
        self.check(slot, function, status, allowed, !is_legal, || {
            format!(
                "vr {vrs:?} (n {n}, NULL vr {null_vr}, NULL values {null_values}): {:?}",
                resolved.as_ref().err()
            )
        });
        if status != OK || n == 0 {
            return;
        }
        let live = self.live(slot);
        let tainted = live.model.tainted;
        let unreliable = tainted || live.model.failed || live.model.wild_states;
        for (i, index) in resolved.expect("valid").into_iter().enumerate() {
            let var = &self.fmu.variables[index];
            let expected = live.model.values[index];
            let problem = match kind {
                // The layer never hands out a non-finite derivative.
                "Real"
                    if (!unreliable || self.fmu.is_derivative(index)) && !reals[i].is_finite() =>
                {
                    Some(format!("{} is {}", var.name, reals[i]))
                }
                "Real"
                    if !tainted && expected.is_some_and(|e| e.to_bits() != reals[i].to_bits()) =>
                {
                    Some(format!(
                        "{} reads {} but {} was set",
                        var.name,
                        reals[i],
                        expected.unwrap()
                    ))
                }
                "Boolean" if ints[i] != 0 && ints[i] != 1 => Some(format!(
                    "{} reads {} (neither fmi2False nor fmi2True)",
                    var.name, ints[i]
                )),
                "Integer" | "Boolean"
                    if !tainted && expected.is_some_and(|e| e != f64::from(ints[i])) =>
                {
                    Some(format!(
                        "{} reads {} but {} was set",
                        var.name,
                        ints[i],
                        expected.unwrap()
                    ))
                }
                _ => None,
            };
            if let Some(problem) = problem {
                self.fail(format!(
                    "{function} returned fmi2OK with a wrong value: {problem}\n{}",
                    self.describe(slot)
                ));
            }
        }
    }

    fn set(&mut self, slot: usize, function: &'static str, benign: bool) {
        let kind = match function {
            "fmi2SetReal" => "Real",
            "fmi2SetInteger" => "Integer",
            "fmi2SetBoolean" => "Boolean",
            _ => "String",
        };
        let vrs = if benign {
            let inputs = self.real_inputs.clone();
            let k = self.rng.random_range(1..=inputs.len().max(1));
            inputs.into_iter().take(k).collect()
        } else {
            self.vrs(kind, true)
        };
        let null_vr = !benign && !vrs.is_empty() && self.chance(0.04);
        let null_values = !benign && !vrs.is_empty() && self.chance(0.04);
        let n = if (null_vr || null_values) && self.chance(0.2) {
            self.pick(&[usize::MAX, 1 << 40, 100_000])
        } else {
            vrs.len()
        };
        let resolved = self.resolve(&vrs, kind);
        // One value per vr, drawn for the variable it names when it names one.
        let mut reals = Vec::with_capacity(vrs.len().max(1));
        let mut ints = Vec::with_capacity(vrs.len().max(1));
        for vr in &vrs {
            let index = self.by_vr.get(vr).copied();
            let current = index.and_then(|i| self.live(slot).model.values[i]);
            if benign {
                reals.push(self.rng.random_range(-1.0..11.0));
                ints.push(0);
                continue;
            }
            reals.push(match index {
                Some(i) => self.real_value(i, current),
                None => self.rng.random_range(-10.0..10.0),
            });
            ints.push(match (kind, index) {
                ("Boolean", _) => self.boolean_value(current),
                (_, Some(i)) => self.integer_value(i, current),
                _ => self.rng.random(),
            });
        }
        reals.push(0.0);
        ints.push(0);
        let strings: Vec<sys::fmi2String> = vec![c"text".as_ptr(); vrs.len().max(1)];

        // What the standard and the modelDescription say of each value.
        let is_legal = self.legal_now(slot, function);
        let live = self.live(slot);
        let state = live.state;
        let mut refusal: Option<String> = None;
        let mut warning_certain = false;
        let mut ambiguous = false;
        if n > 0 && (null_vr || null_values) {
            refusal = Some("a NULL array".to_owned());
        } else if let Err(reason) = &resolved {
            refusal = Some(reason.clone());
        } else if let Ok(indices) = &resolved {
            for (i, index) in indices.iter().enumerate() {
                let var = &self.fmu.variables[*index];
                let value = match kind {
                    "Real" => reals[i],
                    "Boolean" => f64::from(u8::from(ints[i] != 0)),
                    _ => f64::from(ints[i]),
                };
                if !value.is_finite() {
                    refusal = Some(format!("{} = {value}", var.name));
                    break;
                }
                let settable = matches!(var.causality, Causality::Parameter | Causality::Input);
                if !settable {
                    refusal = Some(format!("{} has causality {:?}", var.name, var.causality));
                    break;
                }
                if state == State::ContinuousTimeMode
                    && !(var.causality == Causality::Input
                        && var.variability.is_none_or(|v| v == Variability::Continuous))
                {
                    // FMI 2.0.4 §3.2.3: between events only continuous inputs.
                    refusal = Some(format!("{} set in continuous-time mode", var.name));
                    break;
                }
                if matches!(state, State::StepComplete | State::EventMode)
                    && var.causality == Causality::Parameter
                    && var.variability != Some(Variability::Tunable)
                {
                    // A fixed parameter after initialization: the same value
                    // again is harmless (a warning), a new one is refused.
                    match live.model.values[*index] {
                        Some(current) if !live.model.tainted => {
                            if current == value {
                                warning_certain = true;
                            } else {
                                refusal = Some(format!(
                                    "fixed parameter {} changed after initialization",
                                    var.name
                                ));
                                break;
                            }
                        }
                        _ => ambiguous = true,
                    }
                }
            }
        }
        let allowed: &[sys::fmi2Status] = if !is_legal || refusal.is_some() {
            &[ERROR]
        } else if ambiguous {
            &[OK, WARNING, ERROR]
        } else if warning_certain {
            &[WARNING]
        } else {
            &[OK]
        };
        let vr_ptr = if null_vr { ptr::null() } else { vrs.as_ptr() };
        let b = &self.fmu.binding;
        let c = live.c;
        self.begin(function, Some(slot));
        let status = unsafe {
            match kind {
                "Real" => b.fmi2SetReal(
                    c,
                    vr_ptr,
                    n,
                    if null_values {
                        ptr::null()
                    } else {
                        reals.as_ptr()
                    },
                ),
                "Integer" => b.fmi2SetInteger(
                    c,
                    vr_ptr,
                    n,
                    if null_values {
                        ptr::null()
                    } else {
                        ints.as_ptr()
                    },
                ),
                "Boolean" => b.fmi2SetBoolean(
                    c,
                    vr_ptr,
                    n,
                    if null_values {
                        ptr::null()
                    } else {
                        ints.as_ptr()
                    },
                ),
                _ => b.fmi2SetString(
                    c,
                    vr_ptr,
                    n,
                    if null_values {
                        ptr::null()
                    } else {
                        strings.as_ptr()
                    },
                ),
            }
        };
        self.check(slot, function, status, allowed, !is_legal, || {
            format!(
                "vr {vrs:?} (n {n}, NULL vr {null_vr}, NULL values {null_values}), values {:?}: {refusal:?}",
                if kind == "Real" { format!("{reals:?}") } else { format!("{ints:?}") }
            )
        });
        if (status == OK || status == WARNING) && n > 0 {
            let indices = resolved.expect("accepted");
            let live = self.live_mut(slot);
            for (i, index) in indices.into_iter().enumerate() {
                let value = match kind {
                    "Real" => reals[i],
                    "Boolean" => f64::from(u8::from(ints[i] != 0)),
                    _ => f64::from(ints[i]),
                };
                live.model.values[index] = Some(value);
            }
        }
    }

    /// Whether the instance in `slot` is in a condition where any finite step
    /// must succeed: start parameters, modest inputs, no failed step or forged
    /// state behind it.
    fn pristine(&self, slot: usize) -> bool {
        let live = self.live(slot);
        !live.model.tainted
            && !live.model.failed
            && self.fmu.variables.iter().enumerate().all(|(index, v)| {
                let value = live.model.values[index];
                match v.causality {
                    Causality::Parameter => value.map(f64::to_bits) == v.start.map(f64::to_bits),
                    Causality::Input => value.is_none_or(|x| x.abs() <= 1e3),
                    _ => true,
                }
            })
    }

    fn do_step(&mut self, slot: usize, benign: bool) {
        let time = self.live(slot).model.time;
        let h = if benign {
            self.pick(&[1e-4, 1e-4, 1e-4, 5e-5, 1e-3, 2.5e-4])
        } else {
            match self.rng.random_range(0..100) {
                0..55 => 1e-4,
                55..70 => 10f64.powf(self.rng.random_range(-9.0..-1.0)),
                70..74 => self.pick(&[0.0, -0.0]),
                74..78 => -10f64.powf(self.rng.random_range(-9.0..3.0)),
                78..81 => f64::NAN,
                81..84 => self.pick(&[f64::INFINITY, f64::NEG_INFINITY]),
                84..90 => self.pick(&[1.0, 1e3, 1e6]),
                90..93 => self.pick(&[1e300, f64::MAX]),
                93..95 => 5e-324,
                _ => f64::from_bits(self.rng.random()),
            }
        };
        // The layer's tolerance for a communication point that misses the
        // FMU's time by rounding is documented as 1e-9 relative (at least
        // 1e-9 absolute), at most half a step. Points well inside must be
        // accepted, points well outside refused; the band between is left open.
        let tolerance = (1e-9 * time.abs().max(1.0)).min(0.5 * h.abs());
        let t = if benign {
            time
        } else {
            match self.rng.random_range(0..100) {
                0..72 => time,
                72..80 => time + self.pick(&[0.3, -0.3]) * tolerance,
                80..88 => {
                    time + self.pick(&[1.0, -1.0])
                        * (4.0 * tolerance + 10f64.powf(self.rng.random_range(-6.0..3.0)))
                }
                88..92 => f64::NAN,
                92..96 => self.pick(&[f64::INFINITY, f64::NEG_INFINITY]),
                _ => f64::from_bits(self.rng.random()),
            }
        };
        let no_prior = self.rng.random_range(0..2);
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, "fmi2DoStep");
        let miss = (t - time).abs();
        let tainted = self.live(slot).model.tainted;
        // A step must be positive and finite, start at a finite point and end
        // at one: an end time that overflows leaves no time to continue from.
        let arguments_valid = h.is_finite() && h > 0.0 && t.is_finite() && (t + h).is_finite();
        let allowed: &[sys::fmi2Status] =
            if !is_legal || !arguments_valid || (!tainted && miss > 2.0 * tolerance) {
                &[ERROR]
            } else if tainted || miss > 0.5 * tolerance {
                &[OK, WARNING, ERROR]
            } else if self.pristine(slot) && (1e-9..=1.0).contains(&h) {
                // Steps from a nanosecond (the resolution of integer-nanosecond
                // masters) to a second must work with start parameters and modest
                // inputs. Outside, a model may fail with a message (the
                // controller's rate terms divide by h: a subnormal step overflows).
                &[OK, WARNING]
            } else {
                &[OK, WARNING, ERROR]
            };
        self.begin("fmi2DoStep", Some(slot));
        let status = unsafe { self.fmu.binding.fmi2DoStep(c, t, h, no_prior) };
        self.check(slot, "fmi2DoStep", status, allowed, !is_legal, || {
            format!("currentCommunicationPoint {t} (FMU time {time}), communicationStepSize {h}")
        });
        if status == ERROR && is_legal && allowed.contains(&OK) {
            self.live_mut(slot).model.failed = true;
        }
        if status == OK || status == WARNING {
            self.report.steps_completed += 1;
            self.live_mut(slot).model.time = t + h;
            // The outputs after a successful step are finite.
            self.get(slot, "fmi2GetReal", true);
        }
    }

    fn not_offered(&mut self, slot: usize, function: &'static str) {
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, function);
        let vrs = [0u32; 2];
        let mut reals = [0.0f64; 2];
        let orders = [1i32; 2];
        let n = self.rng.random_range(0..3);
        let b = &self.fmu.binding;
        self.begin(function, Some(slot));
        let status = unsafe {
            match function {
                "fmi2GetDirectionalDerivative" => b.fmi2GetDirectionalDerivative(
                    c,
                    vrs.as_ptr(),
                    n,
                    vrs.as_ptr(),
                    n,
                    reals.as_ptr(),
                    reals.as_mut_ptr(),
                ),
                "fmi2SetRealInputDerivatives" => b.fmi2SetRealInputDerivatives(
                    c,
                    vrs.as_ptr(),
                    n,
                    orders.as_ptr(),
                    reals.as_ptr(),
                ),
                _ => b.fmi2GetRealOutputDerivatives(
                    c,
                    vrs.as_ptr(),
                    n,
                    orders.as_ptr(),
                    reals.as_mut_ptr(),
                ),
            }
        };
        // modelDescription declares none of the three capabilities.
        let log = self.check(slot, function, status, &[ERROR], !is_legal, String::new);
        if is_legal
            && self.live(slot).has_logger
            && !log.iter().any(|r| r.message.contains("not offered"))
        {
            self.fail(format!(
                "{function} refused without saying it is not offered: {log:#?}"
            ));
        }
    }

    fn status_query(&mut self, slot: usize, function: &'static str, benign: bool) {
        let kind: sys::fmi2StatusKind = if benign || self.chance(0.85) {
            self.rng.random_range(0..4)
        } else {
            self.pick(&[4, 1000, u32::MAX])
        };
        let null_value = !benign && self.chance(0.05);
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, function);
        let mut real = f64::NAN;
        let mut int = i32::MIN;
        let mut status_value = u32::MAX;
        let mut string: sys::fmi2String = ptr::null();
        let b = &self.fmu.binding;
        self.begin(function, Some(slot));
        let status = unsafe {
            match function {
                "fmi2GetStatus" => b.fmi2GetStatus(
                    c,
                    kind,
                    if null_value {
                        ptr::null_mut()
                    } else {
                        &mut status_value
                    },
                ),
                "fmi2GetRealStatus" => b.fmi2GetRealStatus(
                    c,
                    kind,
                    if null_value {
                        ptr::null_mut()
                    } else {
                        &mut real
                    },
                ),
                "fmi2GetIntegerStatus" => b.fmi2GetIntegerStatus(
                    c,
                    kind,
                    if null_value {
                        ptr::null_mut()
                    } else {
                        &mut int
                    },
                ),
                "fmi2GetBooleanStatus" => b.fmi2GetBooleanStatus(
                    c,
                    kind,
                    if null_value {
                        ptr::null_mut()
                    } else {
                        &mut int
                    },
                ),
                _ => b.fmi2GetStringStatus(
                    c,
                    kind,
                    if null_value {
                        ptr::null_mut()
                    } else {
                        &mut string
                    },
                ),
            }
        };
        // A synchronous slave answers the last successful time and whether it
        // wants to terminate; the other kinds are not available: fmi2Discard.
        let answerable = matches!(
            (function, kind),
            (
                "fmi2GetRealStatus",
                sys::fmi2StatusKind_fmi2LastSuccessfulTime
            ) | ("fmi2GetBooleanStatus", sys::fmi2StatusKind_fmi2Terminated)
        );
        let allowed = if !is_legal || null_value {
            [ERROR]
        } else if answerable {
            [OK]
        } else {
            [DISCARD]
        };
        self.check(slot, function, status, &allowed, !is_legal, || {
            format!("kind {kind}, NULL value {null_value}")
        });
        if status == OK {
            let live = self.live(slot);
            let wrong = match function {
                "fmi2GetRealStatus" => {
                    !live.model.tainted && real.to_bits() != live.model.time.to_bits()
                }
                _ => int != 0,
            };
            if wrong {
                self.fail(format!(
                    "{function}({kind}) answered {real} / {int}; the FMU's time is {}",
                    live.model.time
                ));
            }
        }
    }

    // ----- FMU states -----

    fn get_fmu_state(&mut self, slot: usize, benign: bool) {
        enum Target {
            Fresh,
            Reuse(usize),
            Null,
            Foreign,
        }
        let target = match self.rng.random_range(0..20) {
            _ if self.handles.len() >= MAX_HANDLES => {
                Target::Reuse(self.rng.random_range(0..self.handles.len()))
            }
            0..13 => Target::Fresh,
            13..16 if !self.handles.is_empty() => {
                Target::Reuse(self.rng.random_range(0..self.handles.len()))
            }
            16 if !benign => Target::Null,
            17..19 if !benign => Target::Foreign,
            _ => Target::Fresh,
        };
        let mut state_slot: sys::fmi2FMUstate = match target {
            Target::Reuse(i) => self.handles[i].ptr,
            Target::Foreign => self.state_argument(0.0).1,
            _ => ptr::null_mut(),
        };
        let before = state_slot;
        let valid = match target {
            Target::Fresh | Target::Reuse(_) => true,
            // NULL is the fresh case: only a non-NULL foreign pointer is wrong.
            Target::Foreign => before.is_null(),
            Target::Null => false,
        };
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, "fmi2GetFMUstate");
        self.begin("fmi2GetFMUstate", Some(slot));
        let status = unsafe {
            self.fmu.binding.fmi2GetFMUstate(
                c,
                if matches!(target, Target::Null) {
                    ptr::null_mut()
                } else {
                    &mut state_slot
                },
            )
        };
        let allowed = if is_legal && valid { [OK] } else { [ERROR] };
        self.check(slot, "fmi2GetFMUstate", status, &allowed, !is_legal, || {
            format!("*FMUstate {before:?}")
        });
        if status != OK {
            if state_slot != before {
                self.fail("fmi2GetFMUstate failed but changed *FMUstate".to_owned());
            }
            return;
        }
        let mut model = self.live(slot).model.clone();
        model.machine = self.live(slot).state;
        match target {
            Target::Reuse(i) => {
                if state_slot != before {
                    self.fail("fmi2GetFMUstate did not reuse the state it was given".to_owned());
                }
                self.handles[i].model = model;
            }
            _ => {
                if state_slot.is_null() {
                    self.fail("fmi2GetFMUstate returned OK and no state".to_owned());
                }
                self.handles.push(Handle {
                    ptr: state_slot,
                    owner: slot,
                    model,
                });
            }
        }
    }

    /// `fmi2SetFMUstate`: a state of this FMU restores the values and the
    /// machine state it was taken in, from whatever state the instance is in
    /// (error state included); a state of the other interface is refused.
    fn set_fmu_state(&mut self, slot: usize, benign: bool) {
        let (own, state) = self.state_argument(if benign { 1.0 } else { 0.85 });
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, "fmi2SetFMUstate");
        let interface = self.live(slot).model.interface;
        let same_interface = own.is_some_and(|i| self.handles[i].model.interface == interface);
        // A forged state may claim anything, its interface and machine state
        // included.
        let forged = own.is_some_and(|i| self.handles[i].model.tainted);
        let allowed: &[sys::fmi2Status] = if !is_legal || own.is_none() {
            &[ERROR]
        } else if forged {
            &[OK, ERROR]
        } else if same_interface {
            &[OK]
        } else {
            &[ERROR]
        };
        self.begin("fmi2SetFMUstate", Some(slot));
        let status = unsafe { self.fmu.binding.fmi2SetFMUstate(c, state) };
        let log = self.check(slot, "fmi2SetFMUstate", status, allowed, !is_legal, || {
            format!("own state {own:?}, same interface {same_interface}, forged {forged}")
        });
        if status != OK && is_legal && own.is_some() && !forged && !same_interface {
            let live = self.live(slot);
            if live.has_logger && !log.iter().any(|r| r.message.contains("interface")) {
                self.fail(format!(
                    "a state of the other interface refused without saying so: {log:#?}"
                ));
            }
        }
        if status == OK {
            self.report.states_restored += 1;
            let model = self.handles[own.expect("only own states restore")]
                .model
                .clone();
            let live = self.live_mut(slot);
            live.state = model.machine;
            // The interface is the instance's: a forged state may claim the
            // other one and still be accepted.
            let interface = live.model.interface;
            live.model = model;
            live.model.interface = interface;
            if forged {
                // The machine state a forged state put the instance in is
                // unknown: a reset brings it back to a known one.
                self.simple(slot, "fmi2Reset");
            }
        }
    }

    fn free_fmu_state(&mut self, slot: usize, benign: bool) {
        let choice = if benign {
            0
        } else {
            self.rng.random_range(0..10)
        };
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, "fmi2FreeFMUstate");
        match choice {
            0..6 if !self.handles.is_empty() => {
                let index = self.rng.random_range(0..self.handles.len());
                if is_legal {
                    return self.free_handle(slot, index);
                }
                let mut pointer = self.handles[index].ptr;
                self.begin("fmi2FreeFMUstate", Some(slot));
                let status = unsafe { self.fmu.binding.fmi2FreeFMUstate(c, &mut pointer) };
                self.check(
                    slot,
                    "fmi2FreeFMUstate",
                    status,
                    &[ERROR],
                    true,
                    String::new,
                );
            }
            6 => {
                let mut null_state: sys::fmi2FMUstate = ptr::null_mut();
                self.begin("fmi2FreeFMUstate", Some(slot));
                let status = unsafe { self.fmu.binding.fmi2FreeFMUstate(c, &mut null_state) };
                let allowed = if is_legal { [OK] } else { [ERROR] };
                self.check(
                    slot,
                    "fmi2FreeFMUstate",
                    status,
                    &allowed,
                    !is_legal,
                    || "*FMUstate NULL".to_owned(),
                );
            }
            7 => {
                self.begin("fmi2FreeFMUstate", Some(slot));
                let status = unsafe { self.fmu.binding.fmi2FreeFMUstate(c, ptr::null_mut()) };
                self.check(
                    slot,
                    "fmi2FreeFMUstate",
                    status,
                    &[ERROR],
                    !is_legal,
                    || "FMUstate NULL".to_owned(),
                );
            }
            _ => {
                let (_, mut foreign) = self.state_argument(0.0);
                let before = foreign;
                self.begin("fmi2FreeFMUstate", Some(slot));
                let status = unsafe { self.fmu.binding.fmi2FreeFMUstate(c, &mut foreign) };
                let allowed = if is_legal && before.is_null() {
                    [OK]
                } else {
                    [ERROR]
                };
                self.check(
                    slot,
                    "fmi2FreeFMUstate",
                    status,
                    &allowed,
                    !is_legal,
                    || format!("*FMUstate {before:?}, not a state of this FMU"),
                );
                if foreign != before {
                    self.fail("fmi2FreeFMUstate changed a pointer it refused".to_owned());
                }
            }
        }
    }

    fn serialized_size(&mut self, slot: usize, benign: bool) {
        let (own, state) = self.state_argument(if benign { 1.0 } else { 0.85 });
        let null_size = !benign && self.chance(0.05);
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, "fmi2SerializedFMUstateSize");
        let mut size = usize::MAX;
        self.begin("fmi2SerializedFMUstateSize", Some(slot));
        let status = unsafe {
            self.fmu.binding.fmi2SerializedFMUstateSize(
                c,
                state,
                if null_size {
                    ptr::null_mut()
                } else {
                    &mut size
                },
            )
        };
        let allowed = if is_legal && own.is_some() && !null_size {
            [OK]
        } else {
            [ERROR]
        };
        self.check(
            slot,
            "fmi2SerializedFMUstateSize",
            status,
            &allowed,
            !is_legal,
            || format!("own state {own:?}, NULL size {null_size}"),
        );
        if status == OK && (size == 0 || size == usize::MAX) {
            self.fail(format!("fmi2SerializedFMUstateSize answered {size}"));
        }
    }

    /// fmi2SerializedFMUstateSize, then fmi2SerializeFMUstate with that size
    /// or a wrong one.
    fn serialize(&mut self, slot: usize, benign: bool) {
        let (own, state) = self.state_argument(if benign { 1.0 } else { 0.9 });
        let c = self.live(slot).c;
        let state_legal = self.legal_now(slot, "fmi2SerializeFMUstate");
        let mut needed = 0usize;
        if own.is_some() && state_legal {
            self.begin("fmi2SerializedFMUstateSize", Some(slot));
            let status = unsafe {
                self.fmu
                    .binding
                    .fmi2SerializedFMUstateSize(c, state, &mut needed)
            };
            self.check(
                slot,
                "fmi2SerializedFMUstateSize",
                status,
                &[OK],
                false,
                String::new,
            );
        } else {
            needed = self.rng.random_range(0..256);
        }
        let size = match self.rng.random_range(0..20) {
            _ if benign => needed,
            0 => needed.saturating_sub(1),
            1 => needed + 1,
            2 => 0,
            _ => needed,
        };
        let null_buffer = !benign && self.chance(0.04);
        let mut buffer = vec![0u8; size.max(1)];
        self.begin("fmi2SerializeFMUstate", Some(slot));
        let status = unsafe {
            self.fmu.binding.fmi2SerializeFMUstate(
                c,
                state,
                if null_buffer {
                    ptr::null_mut()
                } else {
                    buffer.as_mut_ptr().cast()
                },
                size,
            )
        };
        let valid = own.is_some() && size == needed && !null_buffer;
        let allowed = if state_legal && valid { [OK] } else { [ERROR] };
        self.check(
            slot,
            "fmi2SerializeFMUstate",
            status,
            &allowed,
            !state_legal,
            || format!("own state {own:?}, size {size} of {needed}, NULL buffer {null_buffer}"),
        );
        if status == OK {
            buffer.truncate(size);
            let blob = Blob {
                bytes: buffer,
                model: self.handles[own.expect("own")].model.clone(),
            };
            if self.blobs.len() >= MAX_BLOBS {
                let i = self.rng.random_range(0..self.blobs.len());
                self.blobs[i] = blob;
            } else {
                self.blobs.push(blob);
            }
        }
    }

    /// Bytes that differ from a serialized state in a way a CRC-32 always
    /// detects (a burst of at most 32 bits), or in length, or entirely.
    fn corrupt(&mut self, bytes: &[u8]) -> Vec<u8> {
        let mut out = bytes.to_vec();
        match self.rng.random_range(0..7) {
            0 if !out.is_empty() => {
                let i = self.rng.random_range(0..out.len());
                out[i] ^= 1 << self.rng.random_range(0..8);
            }
            1 if out.len() >= 4 => {
                let i = self.rng.random_range(0..out.len() - 3);
                let mask: u32 = self.rng.random_range(1..=u32::MAX);
                for (k, m) in mask.to_le_bytes().iter().enumerate() {
                    out[i + k] ^= m;
                }
            }
            2 if !out.is_empty() => out.truncate(self.rng.random_range(0..out.len())),
            3 => {
                let extra = self.rng.random_range(1..17);
                out.extend((0..extra).map(|_| self.rng.random::<u8>()));
            }
            4 => out.clear(),
            _ => {
                let n = self.rng.random_range(0..300);
                out = (0..n).map(|_| self.rng.random::<u8>()).collect();
            }
        }
        out
    }

    /// A serialized state whose payload has flipped bits and whose checksum
    /// was recomputed: well-formed bytes with garbage values.
    fn forge(&mut self, bytes: &[u8]) -> Vec<u8> {
        let mut out = bytes.to_vec();
        let payload = STATE_HEADER_LEN..out.len() - STATE_CRC_LEN;
        for _ in 0..self.rng.random_range(1..=8) {
            let i = self.rng.random_range(payload.clone());
            out[i] ^= 1 << self.rng.random_range(0..8);
        }
        let crc = crc32fast::hash(&out[..payload.end]);
        out[payload.end..].copy_from_slice(&crc.to_le_bytes());
        out
    }

    fn deserialize(&mut self, slot: usize, benign: bool) {
        #[derive(Debug, PartialEq)]
        enum Source {
            Intact(usize),
            Corrupted,
            Foreign,
            Forged(usize),
            NullWithSize,
            NullEmpty,
        }
        let choice = if benign {
            0
        } else {
            self.rng.random_range(0..100)
        };
        let (source, bytes) = match choice {
            0..45 if !self.blobs.is_empty() => {
                let i = self.rng.random_range(0..self.blobs.len());
                (Source::Intact(i), self.blobs[i].bytes.clone())
            }
            45..80 if !self.blobs.is_empty() => {
                let i = self.rng.random_range(0..self.blobs.len());
                let original = self.blobs[i].bytes.clone();
                (Source::Corrupted, self.corrupt(&original))
            }
            80..88 if self.foreign.is_some() => (
                Source::Foreign,
                self.foreign.as_ref().unwrap().bytes.clone(),
            ),
            88..94 if !self.blobs.is_empty() => {
                let i = self.rng.random_range(0..self.blobs.len());
                let original = self.blobs[i].bytes.clone();
                if original.len() <= STATE_HEADER_LEN + STATE_CRC_LEN {
                    self.fail(format!(
                        "a serialized state of {} bytes has no payload",
                        original.len()
                    ));
                }
                (Source::Forged(i), self.forge(&original))
            }
            94..97 => (Source::NullWithSize, Vec::new()),
            97..100 => (Source::NullEmpty, Vec::new()),
            _ => {
                let n = self.rng.random_range(0..200);
                (
                    Source::Corrupted,
                    (0..n).map(|_| self.rng.random::<u8>()).collect(),
                )
            }
        };
        enum Out {
            Fresh,
            Reuse(usize),
            Null,
            Foreign,
        }
        let out = match self.rng.random_range(0..20) {
            _ if self.handles.len() >= MAX_HANDLES => {
                Out::Reuse(self.rng.random_range(0..self.handles.len()))
            }
            _ if benign => Out::Fresh,
            0..15 => Out::Fresh,
            15..17 if !self.handles.is_empty() => {
                Out::Reuse(self.rng.random_range(0..self.handles.len()))
            }
            17 => Out::Null,
            18 => Out::Foreign,
            _ => Out::Fresh,
        };
        let mut state_slot: sys::fmi2FMUstate = match out {
            Out::Reuse(i) => self.handles[i].ptr,
            Out::Foreign => self.state_argument(0.0).1,
            _ => ptr::null_mut(),
        };
        let before = state_slot;
        let out_valid = match out {
            Out::Fresh | Out::Reuse(_) => true,
            Out::Foreign => before.is_null(),
            Out::Null => false,
        };
        let (data, size): (*const sys::fmi2Byte, usize) = match source {
            Source::NullWithSize => (ptr::null(), self.rng.random_range(1..1000)),
            Source::NullEmpty => (ptr::null(), 0),
            _ => (bytes.as_ptr().cast(), bytes.len()),
        };
        let c = self.live(slot).c;
        let is_legal = self.legal_now(slot, "fmi2DeSerializeFMUstate");
        let allowed: &[sys::fmi2Status] = if !is_legal || !out_valid {
            &[ERROR]
        } else {
            match source {
                Source::Intact(_) => &[OK],
                Source::Forged(_) => &[OK, ERROR],
                _ => &[ERROR],
            }
        };
        self.begin("fmi2DeSerializeFMUstate", Some(slot));
        let status = unsafe {
            self.fmu.binding.fmi2DeSerializeFMUstate(
                c,
                data,
                size,
                if matches!(out, Out::Null) {
                    ptr::null_mut()
                } else {
                    &mut state_slot
                },
            )
        };
        let log = self.check(
            slot,
            "fmi2DeSerializeFMUstate",
            status,
            allowed,
            !is_legal,
            || format!("{source:?}, {size} bytes, *FMUstate {before:?}"),
        );
        if status != OK {
            if state_slot != before {
                self.fail("fmi2DeSerializeFMUstate failed but changed *FMUstate".to_owned());
            }
            let corrupted = matches!(
                source,
                Source::Corrupted | Source::Foreign | Source::Forged(_)
            );
            if is_legal && out_valid && corrupted {
                self.report.corrupted_states_refused += 1;
                if self.live(slot).has_logger && !log.iter().any(|r| r.message.contains("refused"))
                {
                    self.fail(format!(
                        "corrupted bytes refused without saying so: {log:#?}"
                    ));
                }
            }
            return;
        }
        let mut model = match source {
            Source::Intact(i) | Source::Forged(i) => self.blobs[i].model.clone(),
            _ => unreachable!("only intact or forged bytes are accepted"),
        };
        if matches!(source, Source::Forged(_)) {
            self.report.forged_states_accepted += 1;
            model.tainted = true;
        }
        match out {
            Out::Reuse(i) => {
                if state_slot != before {
                    self.fail(
                        "fmi2DeSerializeFMUstate did not reuse the state it was given".to_owned(),
                    );
                }
                self.handles[i].model = model;
            }
            _ => {
                if state_slot.is_null() {
                    self.fail("fmi2DeSerializeFMUstate returned OK and no state".to_owned());
                }
                self.handles.push(Handle {
                    ptr: state_slot,
                    owner: slot,
                    model,
                });
            }
        }
    }
}

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

// The call vocabulary (an enum per family of FMI functions).
mod function;
// Random choices: functions, values, value references, pointers, bytes.
mod generator;
// The oracle's model of each instance and the checks every call gets.
mod oracle;
// The fuzzer's state, the random walk, bursts, instance lifetimes.
mod runner;
// What a run did, and the trail a failure prints.
mod report;
// The calls themselves, by family.
mod calls;
mod fmu_states;
mod foreign;
mod model_exchange;

use function::*;
use oracle::*;
pub use report::FuzzReport;
use report::*;
use runner::*;

const FATAL: sys::fmi2Status = sys::fmi2Status_fmi2Fatal;

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

/// The fuzz test of an FMU crate: [`run`] with the budget of [`FuzzConfig::from_env`],
/// the report printed, and the coverage a generator that stopped reaching a
/// state or a function would lose asserted. Returns the report.
pub fn assert_rules_hold(
    fmu: &Fmu,
    foreign: &Fmu,
    default_calls: u64,
    default_seed: u64,
) -> FuzzReport {
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
    report
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

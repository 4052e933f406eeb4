//! Runs an FMU binary through many complete instance lifetimes, as a master
//! that simulates, restores and restarts does, to find memory that is not
//! given back: under valgrind (every byte) and natively (resident memory).
//!
//! ```text
//! fmi-cycles <library.so> <modelDescription.xml> <cycles> [checkpoint ...]
//! ```
//!
//! One cycle: fmi2Instantiate, fmi2SetupExperiment, enter and exit
//! initialization, an input set, five fmi2DoStep, fmi2GetFMUstate,
//! fmi2SerializedFMUstateSize, fmi2SerializeFMUstate, fmi2DeSerializeFMUstate,
//! fmi2SetFMUstate, fmi2FreeFMUstate of both states, a step after the restore,
//! a third fmi2GetFMUstate left for fmi2FreeInstance to free, fmi2Terminate,
//! fmi2FreeInstance; every status is checked. After each
//! checkpoint (a cycle count) it prints `cycles N VmRSS R kB VmHWM H kB` from
//! /proc/self/status.

use std::path::Path;
use std::process::ExitCode;

use fmi2_conformance::{Fmu, FmuUnderTest, OK};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 4 {
        eprintln!(
            "usage: fmi-cycles <library.so> <modelDescription.xml> <cycles> [checkpoint ...]"
        );
        return ExitCode::from(2);
    }
    let description = match std::fs::read_to_string(&args[2]) {
        Ok(text) => text,
        Err(e) => {
            eprintln!("{}: {e}", args[2]);
            return ExitCode::from(2);
        }
    };
    let numbers: Result<Vec<u64>, _> = args[3..].iter().map(|a| a.parse::<u64>()).collect();
    let Ok(numbers) = numbers else {
        eprintln!("cycles and checkpoints are numbers: {:?}", &args[3..]);
        return ExitCode::from(2);
    };
    let (cycles, checkpoints) = (numbers[0], &numbers[1..]);
    let fmu = match Fmu::try_load(Path::new(&args[1]), &description) {
        Ok(fmu) => fmu,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    let input = fmu.real_input().vr;
    for cycle in 1..=cycles {
        if let Err(problem) = one_lifetime(&fmu, input, cycle) {
            eprintln!("cycle {cycle}: {problem}");
            return ExitCode::FAILURE;
        }
        if checkpoints.contains(&cycle) {
            let (rss, hwm) = resident_kib();
            println!("cycles {cycle} VmRSS {rss} kB VmHWM {hwm} kB");
        }
    }
    println!("completed {cycles} cycles");
    ExitCode::SUCCESS
}

fn expect(what: &str, status: u32) -> Result<(), String> {
    if status == OK {
        Ok(())
    } else {
        Err(format!("{what} returned status {status}"))
    }
}

fn one_lifetime(fmu: &Fmu, input: u32, cycle: u64) -> Result<(), String> {
    let mut instance = fmu
        .try_instantiate(&format!("cycle{cycle}"), &fmu.guid, None, false)
        .map_err(|log| format!("fmi2Instantiate refused: {log:?}"))?;
    expect("fmi2SetupExperiment", instance.setup(0.0))?;
    expect("fmi2EnterInitializationMode", instance.enter_init())?;
    expect(
        "fmi2SetReal",
        instance.set_real(&[input], &[0.01 * (cycle % 7) as f64]),
    )?;
    expect("fmi2ExitInitializationMode", instance.exit_init())?;
    for _ in 0..5 {
        expect("fmi2DoStep", instance.do_step(1e-4))?;
    }
    let (status, mut state) = instance.get_state();
    expect("fmi2GetFMUstate", status)?;
    let (status, bytes) = instance.serialize(state);
    expect("fmi2SerializeFMUstate", status)?;
    let (status, mut restored) = instance.deserialize(&bytes);
    expect("fmi2DeSerializeFMUstate", status)?;
    expect("fmi2DoStep", instance.do_step(1e-4))?;
    expect("fmi2SetFMUstate", instance.set_state(restored))?;
    instance.time -= 1e-4;
    expect("fmi2DoStep", instance.do_step(1e-4))?;
    expect("fmi2FreeFMUstate", instance.free_state(&mut restored))?;
    expect("fmi2FreeFMUstate", instance.free_state(&mut state))?;
    // A state the importer leaves to fmi2FreeInstance (which frees all the
    // instance's memory, FMI 2.0.4 §2.1.5).
    let (status, _left) = instance.get_state();
    expect("fmi2GetFMUstate", status)?;
    expect("fmi2Terminate", instance.terminate())?;
    let log = instance.take_log();
    if log.iter().any(|r| r.status != OK) {
        return Err(format!("unexpected warnings or errors: {log:?}"));
    }
    drop(instance); // fmi2FreeInstance
    Ok(())
}

/// VmRSS and VmHWM of this process in KiB (0 where /proc is unavailable).
fn resident_kib() -> (u64, u64) {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let field = |name: &str| {
        status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|rest| rest.split_whitespace().next())
            .and_then(|n| n.parse().ok())
            .unwrap_or(0)
    };
    (field("VmRSS:"), field("VmHWM:"))
}

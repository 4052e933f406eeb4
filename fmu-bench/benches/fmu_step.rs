//! Cost of one 100 µs sample of the two FMUs through the FMI 2.0 C ABI (the
//! release cdylibs, dlopen'ed as an importer does) beside the same models
//! called directly in Rust. README.md beside this crate says what each
//! benchmark measures; report.py turns the results into the project's table.
//!
//! Every benchmark keeps its model or instance alive from one criterion sample
//! to the next and pre-rolls one period of its signal before timing, so the
//! timed steps are those of a long simulation in steady state, not the
//! start-up transient from rest (whose first plant steps, a jump of the
//! amplifier from 0 V, are cut into hundreds of pieces).

use std::hint::black_box;
use std::path::PathBuf;

use criterion::Criterion;
use fmu_bench::paired::{self, Block};
use fmu_bench::{
    AbiLoop, ControllerSignal, DirectLoop, PlantSignal, SIGNAL_HZ, STEP, abi_controller, abi_plant,
    controller_step, direct_controller, direct_plant, load_controller, load_plant, plant_step,
};

/// One period of the 1 Hz signals at 10 kHz.
const PRE_ROLL: usize = (1.0 / (SIGNAL_HZ * STEP)) as usize;

fn controller(c: &mut Criterion) {
    let fmu = load_controller();
    let mut group = c.benchmark_group("controller");

    let mut direct = direct_controller();
    let mut signal = ControllerSignal::new(STEP);
    for _ in 0..PRE_ROLL {
        controller_step(&mut direct, &signal.sample(), STEP);
    }
    group.bench_function("direct_step", |b| {
        b.iter(|| controller_step(&mut direct, black_box(&signal.sample()), STEP))
    });

    // The setter alone, on an instance that stays at one communication point:
    // subtracted from set + doStep by report.py to give doStep alone (timing
    // doStep by itself would need a clock read per call, which costs a
    // quarter of what is measured).
    let abi = abi_controller(&fmu);
    let mut signal = ControllerSignal::new(STEP);
    group.bench_function("abi_set_inputs", |b| {
        b.iter(|| abi.set_inputs(black_box(&signal.sample())))
    });
    drop(abi);

    let mut abi = abi_controller(&fmu);
    let mut signal = ControllerSignal::new(STEP);
    for _ in 0..PRE_ROLL {
        abi.set_inputs(&signal.sample());
        abi.do_step(STEP);
    }
    group.bench_function("abi_set_doStep", |b| {
        b.iter(|| {
            abi.set_inputs(black_box(&signal.sample()));
            abi.do_step(STEP);
        })
    });
    // Continues the same instance: what an importer does at every sample.
    group.bench_function("abi_set_doStep_get", |b| {
        b.iter(|| {
            abi.set_inputs(black_box(&signal.sample()));
            abi.do_step(STEP);
            abi.get_outputs()
        })
    });
    group.finish();
}

fn plant(c: &mut Criterion) {
    let fmu = load_plant();
    let mut group = c.benchmark_group("plant");

    let mut direct = direct_plant();
    let mut signal = PlantSignal::new(STEP);
    for _ in 0..PRE_ROLL {
        plant_step(&mut direct, signal.sample(), STEP);
    }
    group.bench_function("direct_step", |b| {
        b.iter(|| plant_step(&mut direct, black_box(signal.sample()), STEP))
    });

    let abi = abi_plant(&fmu);
    let mut signal = PlantSignal::new(STEP);
    group.bench_function("abi_set_inputs", |b| {
        b.iter(|| abi.set_inputs(black_box(&signal.sample())))
    });
    drop(abi);

    let mut abi = abi_plant(&fmu);
    let mut signal = PlantSignal::new(STEP);
    for _ in 0..PRE_ROLL {
        abi.set_inputs(&signal.sample());
        abi.do_step(STEP);
    }
    group.bench_function("abi_set_doStep", |b| {
        b.iter(|| {
            abi.set_inputs(black_box(&signal.sample()));
            abi.do_step(STEP);
        })
    });
    group.bench_function("abi_set_doStep_get", |b| {
        b.iter(|| {
            abi.set_inputs(black_box(&signal.sample()));
            abi.do_step(STEP);
            abi.get_outputs()
        })
    });
    group.finish();
}

fn closed_loop(c: &mut Criterion) {
    let controller_fmu = load_controller();
    let plant_fmu = load_plant();
    let mut group = c.benchmark_group("closed_loop");

    let mut direct = DirectLoop::new(STEP);
    for _ in 0..PRE_ROLL {
        direct.step(STEP);
    }
    group.bench_function("direct", |b| b.iter(|| direct.step(black_box(STEP))));

    let mut abi = AbiLoop::new(&controller_fmu, &plant_fmu, STEP);
    for _ in 0..PRE_ROLL {
        abi.step(STEP);
    }
    group.bench_function("abi", |b| b.iter(|| abi.step(black_box(STEP))));
    group.finish();
}

/// Samples per block of the interleaved timing: 0.1 to 1 ms of work, short
/// against the machine's drifts and long against the two clock reads.
const BLOCK: usize = 1000;

/// `[q1, median, q3]` as JSON.
fn triple(q: [f64; 3]) -> String {
    format!("[{:.4}, {:.4}, {:.4}]", q[0], q[1], q[2])
}

/// Interleaved timing of one FMU's workloads: the direct call, the setter
/// alone, set + doStep and set + doStep + get, each on its own model or
/// instance (pre-rolled one period). Returns its JSON object.
fn paired_fmu(mut workloads: [Block<'_>; 4], rounds: usize) -> String {
    for w in workloads.iter_mut() {
        w(PRE_ROLL);
    }
    let mut times = paired::interleave(&mut workloads, BLOCK, rounds);
    let overhead = |f: fn(&[f64]) -> f64| triple(paired::ratio_quartiles(&times, f));
    let do_step = overhead(|t| (t[2] - t[1]) / t[0] - 1.0);
    let set_do_step = overhead(|t| t[2] / t[0] - 1.0);
    let cycle = overhead(|t| t[3] / t[0] - 1.0);
    let do_step_ns = triple(paired::ratio_quartiles(&times, |t| t[2] - t[1]));
    let ns: Vec<String> = times
        .iter_mut()
        .map(|t| triple(paired::quartiles(t)))
        .collect();
    format!(
        "{{\"rounds\": {rounds}, \"block\": {BLOCK}, \
         \"ns\": {{\"direct_step\": {}, \"abi_set_inputs\": {}, \"abi_set_doStep\": {}, \
         \"abi_set_doStep_get\": {}, \"abi_doStep\": {do_step_ns}}}, \
         \"overhead\": {{\"abi_doStep\": {do_step}, \"abi_set_doStep\": {set_do_step}, \
         \"abi_set_doStep_get\": {cycle}}}}}",
        ns[0], ns[1], ns[2], ns[3]
    )
}

/// The FMI overhead ratios measured by interleaving (see `fmu_bench::paired`),
/// as JSON for report.py.
fn paired_overheads() -> String {
    let controller_fmu = load_controller();
    let plant_fmu = load_plant();

    let controller = {
        let mut direct = direct_controller();
        let mut direct_signal = ControllerSignal::new(STEP);
        let set_only = abi_controller(&controller_fmu);
        let mut set_signal = ControllerSignal::new(STEP);
        let mut stepped = abi_controller(&controller_fmu);
        let mut stepped_signal = ControllerSignal::new(STEP);
        let mut cycled = abi_controller(&controller_fmu);
        let mut cycled_signal = ControllerSignal::new(STEP);
        paired_fmu(
            [
                &mut |n| {
                    for _ in 0..n {
                        black_box(controller_step(
                            &mut direct,
                            black_box(&direct_signal.sample()),
                            STEP,
                        ));
                    }
                },
                &mut |n| {
                    for _ in 0..n {
                        set_only.set_inputs(black_box(&set_signal.sample()));
                    }
                },
                &mut |n| {
                    for _ in 0..n {
                        stepped.set_inputs(black_box(&stepped_signal.sample()));
                        stepped.do_step(STEP);
                    }
                },
                &mut |n| {
                    for _ in 0..n {
                        cycled.set_inputs(black_box(&cycled_signal.sample()));
                        cycled.do_step(STEP);
                        black_box(cycled.get_outputs());
                    }
                },
            ],
            2000,
        )
    };

    let plant = {
        let mut direct = direct_plant();
        let mut direct_signal = PlantSignal::new(STEP);
        let set_only = abi_plant(&plant_fmu);
        let mut set_signal = PlantSignal::new(STEP);
        let mut stepped = abi_plant(&plant_fmu);
        let mut stepped_signal = PlantSignal::new(STEP);
        let mut cycled = abi_plant(&plant_fmu);
        let mut cycled_signal = PlantSignal::new(STEP);
        paired_fmu(
            [
                &mut |n| {
                    for _ in 0..n {
                        black_box(plant_step(
                            &mut direct,
                            black_box(direct_signal.sample()),
                            STEP,
                        ));
                    }
                },
                &mut |n| {
                    for _ in 0..n {
                        set_only.set_inputs(black_box(&set_signal.sample()));
                    }
                },
                &mut |n| {
                    for _ in 0..n {
                        stepped.set_inputs(black_box(&stepped_signal.sample()));
                        stepped.do_step(STEP);
                    }
                },
                &mut |n| {
                    for _ in 0..n {
                        cycled.set_inputs(black_box(&cycled_signal.sample()));
                        cycled.do_step(STEP);
                        black_box(cycled.get_outputs());
                    }
                },
            ],
            1000,
        )
    };

    let closed_loop = {
        let mut direct = DirectLoop::new(STEP);
        let mut abi = AbiLoop::new(&controller_fmu, &plant_fmu, STEP);
        let mut workloads: [Block<'_>; 2] = [
            &mut |n| {
                for _ in 0..n {
                    black_box(direct.step(black_box(STEP)));
                }
            },
            &mut |n| {
                for _ in 0..n {
                    black_box(abi.step(black_box(STEP)));
                }
            },
        ];
        for w in workloads.iter_mut() {
            w(PRE_ROLL);
        }
        let rounds = 1000;
        let mut times = paired::interleave(&mut workloads, BLOCK, rounds);
        let overhead = triple(paired::ratio_quartiles(&times, |t| t[1] / t[0] - 1.0));
        let ns: Vec<String> = times
            .iter_mut()
            .map(|t| triple(paired::quartiles(t)))
            .collect();
        format!(
            "{{\"rounds\": {rounds}, \"block\": {BLOCK}, \
             \"ns\": {{\"direct\": {}, \"abi\": {}}}, \"overhead\": {{\"abi\": {overhead}}}}}",
            ns[0], ns[1]
        )
    };

    format!(
        "{{\n  \"controller\": {controller},\n  \"plant\": {plant},\n  \
         \"closed_loop\": {closed_loop}\n}}\n"
    )
}

/// CPU time counters, to say how busy the machine was while the benchmarks
/// ran: timings on a shared machine are only as good as the share of a core
/// they got.
#[derive(Clone, Copy)]
struct CpuTimes {
    /// All cores together, in USER_HZ ticks (/proc/stat).
    total: u64,
    idle: u64,
    steal: u64,
    /// This process (/proc/self/stat utime + stime), in the same ticks.
    own: u64,
}

impl CpuTimes {
    /// None where /proc is not Linux's.
    fn now() -> Option<CpuTimes> {
        let stat = std::fs::read_to_string("/proc/stat").ok()?;
        let fields: Vec<u64> = stat
            .lines()
            .next()?
            .split_whitespace()
            .skip(1)
            .map(|f| f.parse().ok())
            .collect::<Option<_>>()?;
        // user nice system idle iowait irq softirq steal [guest guest_nice],
        // where guest time is already counted in user.
        let total = fields.iter().take(8).sum();
        let idle = fields.get(3)? + fields.get(4)?;
        let steal = *fields.get(7)?;
        let own_stat = std::fs::read_to_string("/proc/self/stat").ok()?;
        // Fields after the parenthesised command name; utime, stime are 14, 15.
        let after_name = &own_stat[own_stat.rfind(')')? + 2..];
        let own_fields: Vec<&str> = after_name.split_whitespace().collect();
        let own =
            own_fields.get(11)?.parse::<u64>().ok()? + own_fields.get(12)?.parse::<u64>().ok()?;
        Some(CpuTimes {
            total,
            idle,
            steal,
            own,
        })
    }
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_default()
}

/// target/criterion, where criterion writes its estimates: the directory of
/// the running binary is target/<profile>/deps.
fn criterion_dir() -> Option<PathBuf> {
    if let Some(home) = std::env::var_os("CRITERION_HOME") {
        return Some(home.into());
    }
    if let Some(target) = std::env::var_os("CARGO_TARGET_DIR") {
        return Some(PathBuf::from(target).join("criterion"));
    }
    let exe = std::env::current_exe().ok()?;
    Some(exe.ancestors().nth(3)?.join("criterion"))
}

/// Writes how loaded the machine was during this run beside criterion's
/// results, for report.py.
fn record_machine_load(before: Option<CpuTimes>, load_before: &str, elapsed_s: f64) {
    let (Some(before), Some(after), Some(dir)) = (before, CpuTimes::now(), criterion_dir()) else {
        return;
    };
    let total = after.total.saturating_sub(before.total).max(1) as f64;
    let busy = total - after.idle.saturating_sub(before.idle) as f64;
    let own = after.own.saturating_sub(before.own) as f64;
    let steal = after.steal.saturating_sub(before.steal) as f64;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let json = format!(
        "{{\n  \"cores\": {cores},\n  \"elapsed_s\": {elapsed_s:.1},\n  \
         \"loadavg_before\": \"{load_before}\",\n  \"loadavg_after\": \"{}\",\n  \
         \"machine_busy_fraction\": {:.3},\n  \"bench_fraction\": {:.3},\n  \
         \"others_fraction\": {:.3},\n  \"steal_fraction\": {:.3}\n}}\n",
        load_average(),
        busy / total,
        own / total,
        ((busy - own) / total).max(0.0),
        steal / total,
    );
    if std::fs::create_dir_all(&dir).is_ok() {
        let _ = std::fs::write(dir.join("fmu-bench-machine.json"), json);
    }
}

fn main() {
    let before = CpuTimes::now();
    let load_before = load_average();
    let started = std::time::Instant::now();
    let mut criterion = Criterion::default().configure_from_args();
    controller(&mut criterion);
    plant(&mut criterion);
    closed_loop(&mut criterion);
    criterion.final_summary();
    // Only in a real benchmark run: `cargo test --benches` runs each
    // benchmark once as a test, passes no --bench, and must not overwrite the
    // figures of the last real run.
    if std::env::args().any(|a| a == "--bench") {
        let json = paired_overheads();
        if let Some(dir) = criterion_dir()
            && std::fs::create_dir_all(&dir).is_ok()
        {
            let _ = std::fs::write(dir.join("fmu-bench-paired.json"), json);
        }
        record_machine_load(before, &load_before, started.elapsed().as_secs_f64());
    }
}

//! A small driver for profilers (callgrind, perf): runs one of the benchmarks'
//! workloads for a given number of 100 µs samples after a one-period pre-roll.
//! Profiling two sample counts and subtracting gives the cost of one sample
//! without the set-up (dlopen, instantiation, pre-roll); README.md shows how.
//!
//! cargo build --release --example drive -p fmu-bench
//! target/release/examples/drive <workload> <samples>
//!
//! workloads: controller-direct, controller-abi, plant-direct, plant-abi,
//! loop-direct, loop-abi (the abi ones do set inputs + doStep + get outputs).

use std::hint::black_box;

use fmu_bench::{
    AbiLoop, ControllerSignal, DirectLoop, PlantSignal, SIGNAL_HZ, STEP, abi_controller, abi_plant,
    controller_step, direct_controller, direct_plant, load_controller, load_plant, plant_step,
};

const PRE_ROLL: usize = (1.0 / (SIGNAL_HZ * STEP)) as usize;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(workload), Some(samples)) = (args.get(1), args.get(2)) else {
        eprintln!("usage: drive <workload> <samples>");
        std::process::exit(2);
    };
    let samples: usize = samples.parse().expect("samples is a count");
    // Each workload runs its pre-roll and then `samples` more samples of the
    // same loop, so that only the sample count differs between two runs.
    let total = PRE_ROLL + samples;
    match workload.as_str() {
        "controller-direct" => {
            let mut controller = direct_controller();
            let mut signal = ControllerSignal::new(STEP);
            for _ in 0..total {
                black_box(controller_step(
                    &mut controller,
                    black_box(&signal.sample()),
                    STEP,
                ));
            }
        }
        "controller-abi" => {
            let fmu = load_controller();
            let mut abi = abi_controller(&fmu);
            let mut signal = ControllerSignal::new(STEP);
            for _ in 0..total {
                abi.set_inputs(black_box(&signal.sample()));
                abi.do_step(STEP);
                black_box(abi.get_outputs());
            }
        }
        "plant-direct" => {
            let mut plant = direct_plant();
            let mut signal = PlantSignal::new(STEP);
            for _ in 0..total {
                black_box(plant_step(&mut plant, black_box(signal.sample()), STEP));
            }
        }
        "plant-abi" => {
            let fmu = load_plant();
            let mut abi = abi_plant(&fmu);
            let mut signal = PlantSignal::new(STEP);
            for _ in 0..total {
                abi.set_inputs(black_box(&signal.sample()));
                abi.do_step(STEP);
                black_box(abi.get_outputs());
            }
        }
        "loop-direct" => {
            let mut direct = DirectLoop::new(STEP);
            for _ in 0..total {
                black_box(direct.step(black_box(STEP)));
            }
        }
        "loop-abi" => {
            let controller = load_controller();
            let plant = load_plant();
            let mut abi = AbiLoop::new(&controller, &plant, STEP);
            for _ in 0..total {
                black_box(abi.step(black_box(STEP)));
            }
        }
        other => {
            eprintln!("unknown workload {other}");
            std::process::exit(2);
        }
    }
}

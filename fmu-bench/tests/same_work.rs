//! The ABI side and the direct side of each benchmark do the same work: from
//! the same inputs they produce bit-identical outputs, sample after sample.
//! Otherwise the FMI overhead the benchmarks report would compare different
//! computations (another parameter set, a switch left off, a skipped step).
//!
//! Loads the release cdylibs: run after `cargo build --release -p fmu-plant
//! -p fmu-controller`, as `cargo test --release -p fmu-bench`.

use fmu_bench::{
    AbiLoop, ControllerSignal, DirectLoop, PlantSignal, STEP, Y_AMPLITUDE_UM, Y_MEAN_UM,
    abi_controller, abi_plant, controller_step, direct_controller, direct_plant, load_controller,
    load_plant, plant_step,
};

/// Two seconds of 10 kHz samples: two periods of every signal.
const SAMPLES: usize = 20_000;

#[test]
fn controller_abi_and_direct_agree() {
    let fmu = load_controller();
    let mut abi = abi_controller(&fmu);
    let mut direct = direct_controller();
    let mut signal = ControllerSignal::new(STEP);
    for k in 0..SAMPLES {
        let inputs = signal.sample();
        abi.set_inputs(&inputs);
        abi.do_step(STEP);
        let from_abi = abi.get_outputs();
        let from_direct = controller_step(&mut direct, &inputs, STEP);
        assert_eq!(from_abi, from_direct, "sample {k}, inputs {inputs:?}");
    }
}

#[test]
fn plant_abi_and_direct_agree() {
    let fmu = load_plant();
    let mut abi = abi_plant(&fmu);
    let mut direct = direct_plant();
    let mut signal = PlantSignal::new(STEP);
    for k in 0..SAMPLES {
        let commands = signal.sample();
        abi.set_inputs(&commands);
        abi.do_step(STEP);
        let from_abi = abi.get_outputs();
        let from_direct = plant_step(&mut direct, commands, STEP);
        assert_eq!(from_abi, from_direct, "sample {k}, commands {commands:?}");
    }
}

#[test]
fn closed_loops_agree_and_close() {
    let controller = load_controller();
    let plant = load_plant();
    let mut abi = AbiLoop::new(&controller, &plant, STEP);
    let mut direct = DirectLoop::new(STEP);
    let mut signal = ControllerSignal::new(STEP);
    let (mut sum_s1, mut sum_squared_error, mut n) = (0.0, 0.0, 0.0);
    for k in 0..SAMPLES {
        let from_abi = abi.step(STEP);
        let from_direct = direct.step(STEP);
        assert_eq!(from_abi, from_direct, "sample {k}");
        let y_ref = signal.sample()[1];
        if k >= SAMPLES / 2 {
            sum_s1 += from_abi[0];
            sum_squared_error += (from_abi[0] - y_ref).powi(2);
            n += 1.0;
        }
    }
    // The loop really closes (the sensors reach the controller and the
    // commands the plant): over the second period the integrators hold the
    // mean of y on the reference's, and y follows the sine, its error well
    // below the sine's own RMS of 5/√2 µm. How well it tracks is the demo's
    // business, not this check's.
    let mean = sum_s1 / n;
    let rms_error = (sum_squared_error / n).sqrt();
    assert!((mean - Y_MEAN_UM).abs() < 0.05, "mean of y {mean} µm");
    assert!(
        rms_error < 0.5 * Y_AMPLITUDE_UM / 2f64.sqrt(),
        "y does not follow its reference: RMS error {rms_error} µm"
    );
}

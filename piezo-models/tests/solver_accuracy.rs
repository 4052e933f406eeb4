//! The step integration: independent of the communication step, of the input
//! rate (hysteresis), and converged in `solver.max_voltage_step`.

use piezo_models::fingerprint::{branches, interpolate};
use piezo_models::{FlexureStage, FlexureStageParams};
use std::f64::consts::TAU;

/// 1 Hz raised-cosine commands on the three channels, a third of a period apart.
fn sine_commands(t: f64, frequency: f64) -> [f64; 3] {
    [0.0, 1.0, 2.0].map(|k| 5.0 * (1.0 - (TAU * (frequency * t + k / 3.0)).cos()))
}

/// A stage driven for 0.3 s (3000 steps of 100 µs) by the three-phase sine, so
/// that the hysteresis, creep and modes are all away from rest.
fn busy_stage() -> FlexureStage {
    let mut stage = FlexureStage::new(FlexureStageParams::default()).unwrap();
    for k in 1..=3000 {
        stage.step(sine_commands(k as f64 * 1e-4, 1.0), 1e-4);
    }
    stage
}

fn max_output_difference(a: &FlexureStage, b: &FlexureStage) -> f64 {
    let (pa, pb) = (a.pose(), b.pose());
    let l_um = a.params().sensor_spacing_mm * 1e3;
    let mut worst = (pa.x_um - pb.x_um)
        .abs()
        .max((pa.y_um - pb.y_um).abs())
        .max((pa.theta_rad - pb.theta_rad).abs() * l_um);
    for (sa, sb) in a.sensors().iter().zip(b.sensors()) {
        worst = worst.max((sa - sb).abs());
    }
    worst
}

/// Commands held from a non-trivial state: one step of H and ten steps of H/10
/// agree to 1e-6 µm on every output (pose with θ·L, sensors) and to 1e-9 V on
/// the voltages, for H = 1 ms and a non-round H = 0.7316 ms. The linear parts
/// are exact; only the hysteresis chord (O(ΔV²), ΔV ≤ 0.05 V) differs between
/// the two piece layouts.
#[test]
fn one_step_equals_ten_steps() {
    for h in [1e-3, 7.316e-4] {
        for commands in [[2.0, 7.0, 3.0], [9.5, 0.5, 6.0]] {
            let mut one = busy_stage();
            let mut ten = one.clone();
            one.step(commands, h);
            for _ in 0..10 {
                ten.step(commands, h / 10.0);
            }
            let difference = max_output_difference(&one, &ten);
            println!("H = {h}: commands {commands:?}: max output difference {difference:.3e} µm");
            assert!(difference < 1e-6);
            for (va, vb) in one
                .amplifier_voltages()
                .iter()
                .zip(ten.amplifier_voltages())
            {
                assert!((va - vb).abs() < 1e-9);
            }
        }
    }
}

/// Convergence in the piece size: a 1 s run of the three-phase 1 Hz full-range
/// sine at 10 kHz with max_voltage_step 0.05 V and 0.025 V differs by less than
/// 1e-4 µm (0.1 nm) on every output at every step.
#[test]
fn halving_the_voltage_step_changes_outputs_by_less_than_a_tenth_of_a_nanometre() {
    let coarse_params = FlexureStageParams::default();
    let mut fine_params = coarse_params.clone();
    fine_params.solver.max_voltage_step *= 0.5;
    let mut coarse = FlexureStage::new(coarse_params).unwrap();
    let mut fine = FlexureStage::new(fine_params).unwrap();
    let mut worst = 0.0f64;
    for k in 1..=10_000 {
        let commands = sine_commands(k as f64 * 1e-4, 1.0);
        coarse.step(commands, 1e-4);
        fine.step(commands, 1e-4);
        worst = worst.max(max_output_difference(&coarse, &fine));
    }
    println!("max output difference, 0.05 V vs 0.025 V: {worst:.3e} µm");
    assert!(worst < 1e-4);
}

/// Rate independence of the hysteresis through the whole stage: y versus the
/// PZT1 voltage over the second cycle of 5·(1 − cos 2πft) on all three
/// channels, at f = 1 Hz and f = 0.1 Hz (10 kHz steps), creep switched off
/// (creep is rate dependent by nature). The loops agree within 1e-3 µm at
/// every voltage 2, 3, …, 98 V on both branches. Plotting against the actual
/// voltage removes the amplifier lag; what is left is the modes' quasi-static
/// lag 2ζ/ω·ẏ ≈ 3e-4 µm at 1 Hz.
#[test]
fn ten_times_slower_sweep_gives_the_same_loop() {
    let mut params = FlexureStageParams::default();
    for actuator in &mut params.actuators {
        actuator.creep_gain = 0.0;
    }
    let loop_at = |frequency: f64| {
        let mut stage = FlexureStage::new(params.clone()).unwrap();
        let period = 1.0 / frequency;
        let steps = (2.0 * period / 1e-4).round() as usize;
        let (mut voltage, mut y) = (Vec::new(), Vec::new());
        for k in 1..=steps {
            let t = k as f64 * 1e-4;
            let u = 5.0 * (1.0 - (TAU * frequency * t).cos());
            stage.step([u; 3], 1e-4);
            if t >= period - 1e-9 {
                voltage.push(stage.amplifier_voltages()[0]);
                y.push(stage.pose().y_um);
            }
        }
        branches(&voltage, &y)
    };
    let (fast_up, fast_down) = loop_at(1.0);
    let (slow_up, slow_down) = loop_at(0.1);
    let mut worst = 0.0f64;
    for v in (2..=98).map(f64::from) {
        worst = worst.max((interpolate(&fast_up, v) - interpolate(&slow_up, v)).abs());
        worst = worst.max((interpolate(&fast_down, v) - interpolate(&slow_down, v)).abs());
    }
    println!("1 Hz vs 0.1 Hz loop, max difference: {worst:.3e} µm");
    assert!(worst < 1e-3);
}

/// A step far longer than every time constant costs at most a full-range
/// voltage swing of pieces and lands on the settled state: the same state as
/// reached by a 60 s hold split into 600 steps.
#[test]
fn a_very_long_step_settles_exactly() {
    let mut long = busy_stage();
    let mut split = long.clone();
    long.step([8.0, 1.0, 4.0], 1e6);
    for _ in 0..600 {
        split.step([8.0, 1.0, 4.0], 0.1);
    }
    assert!(max_output_difference(&long, &split) < 1e-6);
}

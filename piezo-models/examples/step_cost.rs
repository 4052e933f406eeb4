//! Cost of `FlexureStage::step` with the default parameters.
//!
//! Usage: `cargo run --release -p piezo-models --example step_cost`
//!
//! Times 100 000 steps of 100 µs (10 s of simulated time at seed 000's 10 kHz)
//! in three situations: all commands held (the cached single-piece path), a
//! three-phase 1 Hz full-range sine on the three channels (one piece per step,
//! since the voltage moves ≤ 0.031 V per step), and the same sine with sensor
//! noise on. A fourth run shows the other end: full-range command jumps every
//! 10 ms, each jump integrated in ≈ 100 V / 0.05 V = 2000 pieces.

use piezo_models::{FlexureStage, FlexureStageParams};
use std::f64::consts::TAU;
use std::hint::black_box;
use std::time::Instant;

const STEPS: usize = 100_000;
const H: f64 = 1e-4;

fn time(name: &str, params: FlexureStageParams, demand: impl Fn(usize) -> [f64; 3]) {
    let mut stage = FlexureStage::new(params).expect("valid parameters");
    let mut commands: Vec<[f64; 3]> = (1..=STEPS).map(&demand).collect();
    commands = black_box(commands);
    let start = Instant::now();
    let mut finite = true;
    for c in &commands {
        finite &= stage.step(*c, H).fault.is_none();
        black_box(stage.sensors());
    }
    let elapsed = start.elapsed();
    assert!(finite);
    println!(
        "{name}: {:.0} ns/step ({STEPS} steps of {} µs in {:.1} ms)",
        elapsed.as_nanos() as f64 / STEPS as f64,
        H * 1e6,
        elapsed.as_secs_f64() * 1e3
    );
}

fn main() {
    let sine = |k: usize| {
        let t = k as f64 * H;
        [0.0, 1.0, 2.0].map(|p| 5.0 * (1.0 - (TAU * (t + p / 3.0)).cos()))
    };
    time("held commands", FlexureStageParams::default(), |_| {
        [3.0, 5.0, 5.0]
    });
    time("1 Hz full-range sine", FlexureStageParams::default(), sine);
    let mut noisy = FlexureStageParams::default();
    noisy.noise.enabled = true;
    time("1 Hz full-range sine, noise on", noisy, sine);
    time(
        "full-range jumps every 10 ms",
        FlexureStageParams::default(),
        |k| {
            if (k / 100) % 2 == 0 {
                [0.0; 3]
            } else {
                [10.0; 3]
            }
        },
    );
}

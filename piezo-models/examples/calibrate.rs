//! Calibrates the FlexureStage preset to the stage of seed 000.
//!
//! Starting from `presets/flexure_stage_no_memory.json` (the stage as first
//! calibrated), it keeps every loop *shape*
//! (A, β, γ, n, δ of each Bouc-Wen model, the modes, amplifier and creep) and
//! solves for the output scales and the sensor spacing that reproduce the
//! figures of seed 000, using the measurement procedures of
//! `piezo_models::fingerprint`:
//!
//! 1. PZT1 scale ← y stroke 12.22 µm (seed 000 §2);
//! 2. PZT2 scale, PZT3 scale and L ← x stroke 12.74 µm and rotation range
//!    0.0103° anticlockwise / 0.0088° clockwise (seed 000 §2);
//! 3. scales of x_from_pzt1, rot_from_pzt1, y_from_pzt2, y_from_pzt3 ← the
//!    coupling spans of seed 000 Table 3 (2.2065, 2.7435, 1.2482, 1.6784 µm);
//! 4. the modes ← seed 000 §3.2's PI gains, which were tuned by
//!    Ziegler-Nichols (kp = 0.45·K_u, ki = 0.54·K_u/T_u): translation kp 0.05,
//!    ki 50 give K_u = 0.111 V/µm and T_u = 1.2 ms, rotation kp 0.06 gives
//!    K_u = 0.133 V/µm. The x and y frequencies and damping ratios are solved
//!    for (K_u, T_u), the θ damping ratio for K_u (its frequency is the 790 Hz
//!    of §2; the rotation's ki 70 would need T_u = 1.03 ms, which a 790 Hz
//!    mode cannot give, so it is reported, not fitted).
//!
//! A scale multiplies p and q of a Bouc-Wen model together, which scales its
//! output exactly (for any n) and keeps its shape. The steps are independent
//! in this order: the coupling models are at rest in steps 1-2 (their driving
//! voltages are 0 there), and the x home used in step 3 depends only on step 2.
//! The results are rounded to 6 significant digits and measured again.
//!
//! Usage: `cargo run --release -p piezo-models --example calibrate [-- --write]`
//! (`--write` replaces the preset file; otherwise the JSON is printed):
//! without options it writes `presets/flexure_stage_no_memory.json`.
//! `--memory` calibrates the same stage with its stacks' return-point memory
//! on and writes `presets/flexure_stage_memory.json` (MODEL.md §6: the
//! memory flattens the small loops the Ziegler-Nichols figures are taken
//! on, so the modes move). `--memory --moving` takes the Ziegler-Nichols
//! figures while the stage moves instead
//! (`fingerprint::ultimate_gain_while_moving`: on branches, not on a held
//! point's small loops) and writes `presets/flexure_stage.json`, the default.

use piezo_models::fingerprint::{self, Axis, Fingerprints, LoopAxis};
use piezo_models::{BoucWenParams, FlexureStageParams};

/// A figure of seed 000 this calibration solves for
/// (`piezo_models::fingerprint::TARGETS`, where each is written once).
fn paper(key: &str) -> f64 {
    fingerprint::target(key).paper
}

fn scaled(bw: BoucWenParams, factor: f64) -> BoucWenParams {
    BoucWenParams {
        p: bw.p * factor,
        q: bw.q * factor,
        ..bw
    }
}

/// Newton's method on relative multipliers (start 1) with a forward-difference
/// Jacobian; stops when every residual is below `tolerance`.
fn solve<const N: usize>(
    name: &str,
    residual: impl Fn(&[f64; N]) -> [f64; N],
    tolerance: f64,
) -> [f64; N] {
    let mut x = [1.0; N];
    let mut r = residual(&x);
    for iteration in 0..20 {
        let worst = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        eprintln!("{name}: iteration {iteration}, multipliers {x:?}, worst residual {worst:.3e}");
        if worst < tolerance {
            return x;
        }
        let mut jacobian = [[0.0; N]; N];
        for j in 0..N {
            let step = 1e-4 * x[j].abs().max(1e-3);
            let mut xj = x;
            xj[j] += step;
            let rj = residual(&xj);
            for i in 0..N {
                jacobian[i][j] = (rj[i] - r[i]) / step;
            }
        }
        let dx = gauss(jacobian, r.map(|v| -v));
        for j in 0..N {
            x[j] += dx[j];
        }
        r = residual(&x);
    }
    panic!("{name}: Newton did not converge");
}

/// Solves A·x = b by Gaussian elimination with partial pivoting.
fn gauss<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> [f64; N] {
    for col in 0..N {
        let pivot = (col..N)
            .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
            .unwrap();
        a.swap(col, pivot);
        b.swap(col, pivot);
        let pivot_row = a[col];
        for row in col + 1..N {
            let f = a[row][col] / pivot_row[col];
            for (x, p) in a[row][col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= f * p;
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; N];
    for row in (0..N).rev() {
        let tail: f64 = (row + 1..N).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - tail) / a[row][row];
    }
    x
}

fn round6(v: f64) -> f64 {
    if v == 0.0 {
        return 0.0;
    }
    let digits = 5 - v.abs().log10().floor() as i32;
    let factor = 10f64.powi(digits);
    (v * factor).round() / factor
}

fn round_model(bw: &mut BoucWenParams) {
    bw.p = round6(bw.p);
    bw.q = round6(bw.q);
}

fn calibrate(base: &FlexureStageParams, ultimate_gain: UltimateGainProbe) -> FlexureStageParams {
    // 1. PZT1 from the y stroke.
    let [s1] = solve(
        "PZT1",
        |m| {
            let mut p = base.clone();
            p.actuators[0].hysteresis = scaled(base.actuators[0].hysteresis, m[0]);
            [fingerprint::stroke(&p, Axis::Y) / paper("stroke_y") - 1.0]
        },
        1e-7,
    );
    let mut params = base.clone();
    params.actuators[0].hysteresis = scaled(base.actuators[0].hysteresis, s1);

    // 2. PZT2, PZT3 and L from the x stroke and the rotation range.
    let with_x_pair = |m: &[f64; 3]| {
        let mut p = params.clone();
        p.actuators[1].hysteresis = scaled(params.actuators[1].hysteresis, m[0]);
        p.actuators[2].hysteresis = scaled(params.actuators[2].hysteresis, m[1]);
        p.sensor_spacing_mm = params.sensor_spacing_mm * m[2];
        p
    };
    let x_pair = solve(
        "x pair and L",
        |m| {
            let p = with_x_pair(m);
            let u_home = fingerprint::x_home_command(&p);
            let (acw, cw) = fingerprint::rotation_range_deg(&p, u_home);
            [
                fingerprint::stroke(&p, Axis::X) / paper("stroke_x") - 1.0,
                acw / paper("rotation_anticlockwise") - 1.0,
                cw / paper("rotation_clockwise") - 1.0,
            ]
        },
        1e-7,
    );
    params = with_x_pair(&x_pair);
    params.sensor_spacing_mm = round6(params.sensor_spacing_mm);
    for act in &mut params.actuators {
        round_model(&mut act.hysteresis);
    }

    // 3. Coupling scales from the Table 3 spans.
    let u_home = fingerprint::x_home_command(&params);
    let with_couplings = |m: &[f64; 4]| {
        let mut p = params.clone();
        let c = &mut p.coupling;
        c.x_from_pzt1 = scaled(params.coupling.x_from_pzt1, m[0]);
        c.rot_from_pzt1 = scaled(params.coupling.rot_from_pzt1, m[1]);
        c.y_from_pzt2 = scaled(params.coupling.y_from_pzt2, m[2]);
        c.y_from_pzt3 = scaled(params.coupling.y_from_pzt3, m[3]);
        p
    };
    let couplings = solve(
        "couplings",
        |m| {
            let c = fingerprint::coupling_sweeps(&with_couplings(m), u_home);
            [
                c.s2_from_y.span_um / paper("s2_from_y") - 1.0,
                c.s3_from_y.span_um / paper("s3_from_y") - 1.0,
                c.y_from_x.span_um / paper("y_from_x") - 1.0,
                c.y_from_rotation.span_um / paper("y_from_rotation") - 1.0,
            ]
        },
        1e-6,
    );
    params = with_couplings(&couplings);
    let c = &mut params.coupling;
    for bw in [
        &mut c.x_from_pzt1,
        &mut c.rot_from_pzt1,
        &mut c.y_from_pzt2,
        &mut c.y_from_pzt3,
    ] {
        round_model(bw);
    }

    // 4. Modes from the Ziegler-Nichols figures of the §3.2 gains.
    calibrate_modes(&mut params, ultimate_gain);
    params
}

/// How the Ziegler-Nichols ultimate gain is measured: at a held point
/// (`fingerprint::ultimate_gain`, the default) or while the stage moves
/// (`fingerprint::ultimate_gain_while_moving`, `--moving`).
type UltimateGainProbe = fn(&FlexureStageParams, f64, LoopAxis) -> fingerprint::UltimateGain;

/// Fixed-point iteration on the two near-proportionalities of the sampled
/// loop: K_u ∝ ζ (the resonant peak's height is ∝ 1/ζ) and T_u ∝ 1/f. The
/// targets are the K_u and T_u that Ziegler-Nichols maps to seed 000's gains.
fn calibrate_modes(params: &mut FlexureStageParams, ultimate_gain: UltimateGainProbe) {
    let u_home = fingerprint::x_home_command(params);
    let ku_translation = paper("ultimate_gain_x");
    let tu_translation = paper("ultimate_period_x");
    let ku_rotation = paper("ultimate_gain_theta");
    for iteration in 0..30 {
        let mut worst = 0.0f64;
        for axis in LoopAxis::ALL {
            let ku = ultimate_gain(params, u_home, axis);
            let mode = match axis {
                LoopAxis::X => &mut params.modes.x,
                LoopAxis::Y => &mut params.modes.y,
                LoopAxis::Theta => &mut params.modes.theta,
            };
            let (ku_target, tu_target) = match axis {
                LoopAxis::Theta => (ku_rotation, None),
                _ => (ku_translation, Some(tu_translation)),
            };
            worst = worst.max((ku.gain / ku_target - 1.0).abs());
            mode.damping_ratio *= ku_target / ku.gain;
            if let Some(tu_target) = tu_target {
                worst = worst.max((ku.period / tu_target - 1.0).abs());
                mode.frequency_hz *= ku.period / tu_target;
            }
            eprintln!(
                "modes: iteration {iteration}, {axis:?}: K_u {:.5} V/µm, T_u {:.4} ms -> f {:.2} Hz, ζ {:.5}",
                ku.gain,
                ku.period * 1e3,
                mode.frequency_hz,
                mode.damping_ratio
            );
        }
        if worst < 2e-3 {
            break;
        }
    }
    for mode in [
        &mut params.modes.x,
        &mut params.modes.y,
        &mut params.modes.theta,
    ] {
        mode.frequency_hz = round6(mode.frequency_hz);
        mode.damping_ratio = round6(mode.damping_ratio);
    }
}

/// The measured figures beside their targets (`Fingerprints::checks`, the
/// same rows `plant-fingerprints` reports for the FMU), with the θ mode's
/// resonance beside the frequency the calibration gave it.
fn report(f: &Fingerprints, params: &FlexureStageParams) {
    println!("| fingerprint | target | measured | deviation | within |");
    println!("|---|---|---|---|---|");
    for check in f.checks() {
        let target = check.paper.map_or_else(
            || check.rule.clone(),
            |p| format!("{p:.6} ({})", check.rule),
        );
        let deviation = check
            .relative_error
            .map_or_else(String::new, |e| format!("{:+.3} %", 100.0 * e));
        println!(
            "| {} [{}] | {target} | {:.6} | {deviation} | {} |",
            check.name, check.unit, check.measured, check.within
        );
    }
    println!(
        "| θ resonance against the mode's {:.2} Hz | | {:.2} Hz | {:+.3} % | |",
        params.modes.theta.frequency_hz,
        f.theta_resonance_hz,
        100.0 * (f.theta_resonance_hz / params.modes.theta.frequency_hz - 1.0)
    );
    let c = &f.couplings;
    println!();
    println!("x home command u_home = {:.6} V", f.x_home_command);
    println!(
        "sweep amplitudes: y {:.6} V, x {:.6} V, rotation ±{:.6} V",
        c.y_sweep_amplitude, c.x_sweep_amplitude, c.rotation_sweep_amplitude
    );
    let [.., theta] = f.ultimate_gains;
    println!(
        "ultimate period θ: {:.4} ms (not fitted: §3.2's ki 70 would need 1.03 ms)",
        theta.period * 1e3
    );
}

fn main() {
    let write = std::env::args().any(|a| a == "--write");
    let memory = std::env::args().any(|a| a == "--memory");
    let moving = std::env::args().any(|a| a == "--moving");
    // Every preset is calibrated from the stage without the memory, as each
    // was first made.
    let base = FlexureStageParams {
        return_point_memory: memory,
        ..FlexureStageParams::without_memory()
    };
    let probe: UltimateGainProbe = if moving {
        |p, u, a| fingerprint::ultimate_gain_while_moving(p, u, a)
    } else {
        |p, u, a| fingerprint::ultimate_gain(p, u, a)
    };
    let params = calibrate(&base, probe);
    params.validate().expect("calibrated parameters are valid");
    let reading = if moving {
        fingerprint::ZieglerNicholsReading::WhileMoving
    } else {
        fingerprint::ZieglerNicholsReading::Held
    };
    report(&fingerprint::measure_with(&params, reading), &params);
    let json = serde_json::to_string_pretty(&params).expect("parameters serialise") + "\n";
    if write {
        let path = match (memory, moving) {
            (true, true) => concat!(env!("CARGO_MANIFEST_DIR"), "/presets/flexure_stage.json"),
            (true, false) => concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/presets/flexure_stage_memory.json"
            ),
            (false, false) => concat!(
                env!("CARGO_MANIFEST_DIR"),
                "/presets/flexure_stage_no_memory.json"
            ),
            (false, true) => {
                eprintln!(
                    "no preset is calibrated --moving without --memory: printed, not written"
                );
                println!("{json}");
                return;
            }
        };
        std::fs::write(path, json).expect("preset written");
        eprintln!("wrote {path}");
    } else {
        println!("{json}");
    }
}

//! The default parameters reproduce the stage of seed 000 (§2 and Table 3),
//! and so do the other presets of seed 000's stage.
//!
//! Every test measures its figure in simulation with the procedures of
//! `piezo_models::fingerprint`, prints it (run with `--nocapture` to see) and
//! asserts the tolerance. Common to all procedures: a fresh stage from rest,
//! noise off (the default), commands held over steps of 100 µs (10 kHz), the
//! command of step k being the demand at the end of the step, t = k·100 µs;
//! readings from the sensors after each step: x = (s2 + s3)/2, y = s1,
//! θ = (s2 − s3)/L. Commands are in volts before the amplifier (gain 10).
//!
//! x home: u_home is the u2 = u3 command whose linear ramp from rest over 1 s
//! (u1 = 0) ends at x = (x stroke)/2, solved to 1e-9 µm in x (u_home ≈ 5.0966 V).

use piezo_models::FlexureStageParams;
use piezo_models::fingerprint::{self, Axis};

fn relative_error(measured: f64, target: f64) -> f64 {
    (measured / target - 1.0).abs()
}

/// Asserts `measured` is within the tolerance of `fingerprint::TARGETS`'s
/// row `key` (where seed 000's figures are written once) and prints both.
fn check(key: &str, measured: f64) {
    let target = fingerprint::target(key);
    println!(
        "{}: {measured:.6} {} (seed 000 {} {}, ±{:.0} %)",
        target.name,
        target.unit,
        target.paper,
        target.unit,
        100.0 * target.relative_tolerance
    );
    assert!(
        relative_error(measured, target.paper) <= target.relative_tolerance,
        "{}: {measured} against {}",
        target.name,
        target.paper
    );
}

/// Quasi-static x stroke, target 12.74 µm ± 5 % (seed 000 §2). From rest,
/// u2 = u3 ramp linearly 0 → 10 V over 1 s (10 000 steps), u1 = 0; the stroke
/// is x after the last step.
#[test]
fn x_stroke_at_full_command() {
    let stroke = fingerprint::stroke(&FlexureStageParams::default(), Axis::X);
    check("stroke_x", stroke);
}

/// Quasi-static y stroke, target 12.22 µm ± 5 % (seed 000 §2). From rest, u1
/// ramps linearly 0 → 10 V over 1 s, u2 = u3 = 0; the stroke is y after the
/// last step.
#[test]
fn y_stroke_at_full_command() {
    let stroke = fingerprint::stroke(&FlexureStageParams::default(), Axis::Y);
    check("stroke_y", stroke);
}

/// Rotation range, targets 0.0103° anticlockwise and 0.0088° clockwise, ± 10 %
/// (seed 000 §2). From rest, four linear ramps of 1 s each: to the x home
/// (0, u_home, u_home); to (0, 10, 0), read θ⁺; back to (0, u_home, u_home);
/// to (0, 0, 10), read θ⁻. θ is measured from the orientation at rest;
/// anticlockwise = θ⁺ (> 0), clockwise = −θ⁻.
#[test]
fn rotation_range_from_x_home() {
    let params = FlexureStageParams::default();
    let u_home = fingerprint::x_home_command(&params);
    let (anticlockwise, clockwise) = fingerprint::rotation_range_deg(&params, u_home);
    println!("x home command: {u_home:.6} V");
    assert!(anticlockwise > 0.0 && clockwise > 0.0);
    check("rotation_anticlockwise", anticlockwise);
    check("rotation_clockwise", clockwise);
}

/// θ resonance, target 790 Hz ± 2 % (seed 000 §2). At the x home (ramp 1 s),
/// hold 0.5 s, then hold (0, u_home + 0.1, u_home − 0.1) while θ is sampled
/// every 10 µs (steps of 10 µs) for 0.25 s; the resonance is the frequency of
/// the largest |DFT(θ − mean θ)|, scanned from 300 to 2000 Hz every 0.5 Hz.
#[test]
fn theta_resonance_is_the_spectral_peak_of_a_rotation_step() {
    let params = FlexureStageParams::default();
    let u_home = fingerprint::x_home_command(&params);
    let peak = fingerprint::theta_resonance_hz(&params, u_home);
    check("theta_resonance", peak);
}

/// Open-loop major loops (u1 → y; u2 = u3 → x): from rest, the driven
/// command(s) follow 5·(1 − cos 2πt) V for 2 s (0 → 10 → 0 V at 1 Hz), the
/// others 0; the loop is the axis reading versus the command over the second
/// cycle, t ∈ [1, 2] s. Width w(u) = descending − ascending branch, by linear
/// interpolation at 19 commands 0.5, 1.0, …, 9.5 V. Required: max |w| between
/// 8 % and 15 % of the loop's span (max − min of the reading), and asymmetry
/// max_d |w(5 + d) − w(5 − d)| / max |w| > 0.1 (not point-symmetric).
#[test]
fn major_loops_are_asymmetric_with_a_realistic_width() {
    let params = FlexureStageParams::default();
    for (name, axis) in [("x", Axis::X), ("y", Axis::Y)] {
        let shape = fingerprint::major_loop(&params, axis);
        println!(
            "{name} major loop: span {:.4} µm, max width {:.4} µm ({:.2} % of span), asymmetry {:.3}",
            shape.span_um,
            shape.max_width_um,
            100.0 * shape.width_ratio,
            shape.asymmetry
        );
        let (low, high) = fingerprint::LOOP_WIDTH_RANGE;
        assert!((low..=high).contains(&shape.width_ratio), "{name}");
        assert!(shape.asymmetry > fingerprint::LOOP_ASYMMETRY_MIN, "{name}");
    }
}

/// Cross-axis coupling spans without decoupling (seed 000 Table 3), each ± 15 %,
/// and each coupling a hysteresis loop (width ≥ 5 % of its span). Sweeps at
/// 1 Hz, the amplitude solved so that the driven axis spans 10 µm (or θ spans
/// 2 × 9.2e-3°) over the measured cycle; the other actuators at home:
/// - y sweep: ramp to the x home (1 s), then u1 = a(1 − cos 2πt)/2 for 2 s,
///   u2 = u3 = u_home; measured t ∈ [1, 2] s; spans of s2 (2.2065 µm) and s3
///   (2.7435 µm); loops s2, s3 versus u1;
/// - x sweep: from rest, u2 = u3 = a(1 − cos 2πt)/2 for 2 s, u1 = 0; measured
///   t ∈ [1, 2] s; span of y (1.2482 µm); loop y versus u2;
/// - rotation sweep: ramp to the x home, then u2 = u_home + D sin 2πt,
///   u3 = u_home − D sin 2πt for 2.75 s, u1 = 0; measured t ∈ [1.75, 2.75] s;
///   span of y (1.6784 µm); loop y versus D sin 2πt.
#[test]
fn coupling_spans_match_table_3_and_are_hysteretic() {
    let params = FlexureStageParams::default();
    let u_home = fingerprint::x_home_command(&params);
    let c = fingerprint::coupling_sweeps(&params, u_home);
    println!(
        "sweep amplitudes: y a = {:.6} V, x a = {:.6} V, rotation D = {:.6} V",
        c.y_sweep_amplitude, c.x_sweep_amplitude, c.rotation_sweep_amplitude
    );
    for (name, coupling) in [
        ("s2_from_y", c.s2_from_y),
        ("s3_from_y", c.s3_from_y),
        ("y_from_x", c.y_from_x),
        ("y_from_rotation", c.y_from_rotation),
    ] {
        check(name, coupling.span_um);
        println!(
            "{name}: loop width {:.2} % of span",
            100.0 * coupling.width_ratio
        );
        assert!(
            coupling.width_ratio >= fingerprint::COUPLING_LOOP_WIDTH_MIN,
            "{name}"
        );
    }
}

/// Ziegler-Nichols ultimate gains, the loop-dynamics fingerprint: seed 000
/// §3.2 tuned its PI gains by Ziegler-Nichols (kp = 0.45·K_u, ki = 1.2·kp/T_u),
/// so translation kp 0.05, ki 50 mean K_u = 0.111 V/µm and T_u = 1.2 ms, and
/// rotation kp 0.06 means K_u = 0.133 V/µm; ± 10 %. Procedure: at the loop
/// operating point (ramp to (5 V, u_home, u_home) over 1 s, hold 0.5 s), a
/// proportional loop with one sample of compute delay follows a 0.05 µm
/// reference step; K_u is the gain at which the oscillation neither grows nor
/// decays (see `fingerprint::ultimate_gain`). The paper's gains then have a
/// gain margin of 1/0.45 ≈ 2.2 on this plant, as on the paper's stage. Read
/// at this held point on the preset calibrated so (`3dof_no_memory`); the
/// default is calibrated to the reading on the moving stage (below).
#[test]
fn ziegler_nichols_ultimate_gains_match_the_papers_pi_gains() {
    use piezo_models::fingerprint::LoopAxis;
    let params = FlexureStageParams::without_memory();
    let u_home = fingerprint::x_home_command(&params);
    for (axis, gain_key, period_key) in [
        (LoopAxis::X, "ultimate_gain_x", Some("ultimate_period_x")),
        (LoopAxis::Y, "ultimate_gain_y", Some("ultimate_period_y")),
        (LoopAxis::Theta, "ultimate_gain_theta", None),
    ] {
        let ku = fingerprint::ultimate_gain(&params, u_home, axis);
        let (kp, ki) = ku.ziegler_nichols_pi();
        println!(
            "{axis:?}: K_u {:.5} V/µm, T_u {:.4} ms -> Ziegler-Nichols kp {kp:.4}, ki {ki:.1}",
            ku.gain,
            ku.period * 1e3
        );
        check(gain_key, ku.gain);
        if let Some(period_key) = period_key {
            check(period_key, ku.period);
        }
    }
}

/// MODEL.md §6 and docs/seed000.md ("Calibrated with the memory"): the
/// Ziegler-Nichols test oscillates on a held stack's minor loops, which
/// close along a flatter path with the return-point memory, so the
/// ultimate gain x of the preset's modes rises by 44 %
/// (0.1111 → 0.1601 V/µm), far outside the fingerprint's 10 %: the preset's
/// modes are calibrated for the stage without the memory. Deterministic; the
/// band is the printed 44 % to its last digit.
#[test]
fn the_return_point_memory_moves_the_ziegler_nichols_gain_by_44_percent() {
    use piezo_models::fingerprint::LoopAxis;
    let without = FlexureStageParams::without_memory();
    let with = FlexureStageParams {
        return_point_memory: true,
        ..FlexureStageParams::without_memory()
    };
    let gain = |params: &FlexureStageParams| {
        let u_home = fingerprint::x_home_command(params);
        fingerprint::ultimate_gain(params, u_home, LoopAxis::X).gain
    };
    let (k_without, k_with) = (gain(&without), gain(&with));
    let rise = k_with / k_without - 1.0;
    println!(
        "ultimate gain x: {k_without:.4} V/um without the memory, {k_with:.4} with (+{:.1} %)",
        100.0 * rise
    );
    assert!(
        (0.435..0.445).contains(&rise),
        "{k_without} -> {k_with}: +{rise}"
    );
}

/// The preset calibrated with the return-point memory
/// (`FlexureStageParams::with_closed_minor_loops`, `examples/calibrate.rs --
/// --memory`) reproduces every fingerprint of seed 000 as the default does:
/// what moved to keep them is the modes (MODEL.md §5).
#[test]
fn the_memory_preset_holds_every_fingerprint() {
    let params = FlexureStageParams::with_closed_minor_loops();
    assert!(params.return_point_memory);
    let checks =
        fingerprint::measure_with(&params, fingerprint::ZieglerNicholsReading::Held).checks();
    for check in &checks {
        println!(
            "{}: {:.6} {} ({})",
            check.name, check.measured, check.unit, check.within
        );
    }
    let failing: Vec<_> = checks
        .iter()
        .filter(|c| !c.within)
        .map(|c| &c.name)
        .collect();
    assert!(failing.is_empty(), "{failing:?}");
}

/// The loop on a moving stage (`fingerprint::ultimate_gain_while_moving`)
/// has a lower ultimate gain than at a held point, since a branch is steeper
/// than a held point's small loops: on the default preset 0.0835 against
/// 0.1111 V/µm (x; y 0.0845, θ 0.1098 against 0.1333), with the memory and its
/// own modes (`3dof_memory`) 0.0580 (y 0.0597, θ 0.0756), which leaves the
/// paper's kp = 0.05 a gain margin of 1.16 while tracking (docs/seed000.md,
/// "Why Fig. 7 is a draw there"). Deterministic; bands of ±1 % about the
/// printed figures.
#[test]
fn a_moving_stage_has_a_lower_ultimate_gain_than_a_held_one() {
    use piezo_models::fingerprint::LoopAxis;
    for (name, params, moving) in [
        (
            "3dof_no_memory",
            FlexureStageParams::without_memory(),
            [0.0835, 0.0845, 0.1098],
        ),
        (
            "3dof_memory",
            FlexureStageParams::with_closed_minor_loops(),
            [0.0580, 0.0597, 0.0756],
        ),
    ] {
        let u_home = fingerprint::x_home_command(&params);
        for (axis, expected) in LoopAxis::ALL.into_iter().zip(moving) {
            let held = fingerprint::ultimate_gain(&params, u_home, axis).gain;
            let while_moving = fingerprint::ultimate_gain_while_moving(&params, u_home, axis).gain;
            println!("{name} {axis:?}: K_u held {held:.4}, while moving {while_moving:.4} V/um");
            assert!(
                (while_moving / expected - 1.0).abs() < 0.01,
                "{name} {axis:?}: {while_moving} against {expected}"
            );
            assert!(while_moving < 0.9 * held, "{name} {axis:?}");
        }
    }
}

/// The default preset, calibrated with the memory and Ziegler-Nichols taken
/// on the moving stage (`examples/calibrate.rs -- --memory --moving`), holds
/// every fingerprint of seed 000 as `fingerprint::measure` reads them: the
/// Ziegler-Nichols figures of the loop while moving within the same
/// tolerances as the held ones of the other presets (K_u 0.1111 V/µm x and
/// y, 0.1333 θ, ±10 %; T_u 1.2 ms x and y, ±10 %).
#[test]
fn the_default_holds_every_fingerprint_with_ziegler_nichols_on_the_moving_stage() {
    let params = FlexureStageParams::default();
    assert!(params.return_point_memory);
    let fingerprints = fingerprint::measure(&params);
    assert_eq!(
        fingerprints.ziegler_nichols,
        fingerprint::ZieglerNicholsReading::WhileMoving
    );
    let checks = fingerprints.checks();
    for check in &checks {
        println!(
            "{}: {:.6} {} ({})",
            check.name, check.measured, check.unit, check.within
        );
    }
    let failing: Vec<_> = checks
        .iter()
        .filter(|c| !c.within)
        .map(|c| &c.name)
        .collect();
    assert!(failing.is_empty(), "{failing:?}");
}

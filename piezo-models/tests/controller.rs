//! Seed 000's sampled controller (eq. 3-5, 10-12): each part checked against
//! the law it implements, independently of the others.

use piezo_models::decoupling::decouple;
use piezo_models::{ControllerParams, ModifiedInversePi, PiGains, PiezoController};

const DT: f64 = 1e-4;

fn params() -> ControllerParams {
    ControllerParams::paper()
}

fn feedback_only(mut p: ControllerParams) -> ControllerParams {
    p.feedforward = false;
    p.decoupling = false;
    p
}

#[test]
fn feedforward_alone_is_the_inverse_model_of_each_channel() {
    let mut p = params();
    p.feedback_x = false;
    p.feedback_y = false;
    p.feedback_theta = false;
    let half_l_um = 0.5 * p.sensor_spacing_mm * 1e3;
    let mut controller = PiezoController::new(p.clone()).unwrap();
    let mut y_model = ModifiedInversePi::new(p.y_model);
    let mut pzt2 = ModifiedInversePi::new(p.x_model);
    let mut pzt3 = ModifiedInversePi::new(p.x_model);
    // Steps of changing size, as a master that aligns to events or output
    // points makes: eq. (4)'s rate is the backward difference over the time
    // since the previous sample, that sample's dt, not this one's.
    let steps = [DT, 3.0 * DT, DT, 1e-6, DT - 1e-6, 2.0 * DT];
    let mut previous: Option<([f64; 3], f64)> = None;
    let mut t: f64 = 0.0;
    for n in 0..2000 {
        let dt = steps[n % steps.len()];
        let (x_ref, y_ref) = (6.0 + 2.0 * (7.0 * t).sin(), 6.0 + 5.0 * (3.0 * t).sin());
        let theta_ref = 4e-5 * (5.0 * t).cos();
        let out = controller.step(x_ref, y_ref, theta_ref, [0.0; 3], dt);
        t += dt;
        let inputs = [
            y_ref,
            x_ref + theta_ref * half_l_um,
            x_ref - theta_ref * half_l_um,
        ];
        let (prev, since) = previous.unwrap_or((inputs, dt));
        previous = Some((inputs, dt));
        let expected = [
            y_model.evaluate(inputs[0], (inputs[0] - prev[0]) / since),
            pzt2.evaluate(inputs[1], (inputs[1] - prev[1]) / since),
            pzt3.evaluate(inputs[2], (inputs[2] - prev[2]) / since),
        ];
        for (c, expected) in expected.into_iter().enumerate() {
            assert_eq!(out.feedforward[c], expected, "channel {c}, sample {n}");
            assert_eq!(out.feedback[c], 0.0);
            assert_eq!(out.u[c], expected.clamp(p.command_min, p.command_max));
        }
        assert_eq!(out.decoupled.x_r2, inputs[1]);
        assert_eq!(out.decoupled.y_rx, y_ref);
    }
}

#[test]
fn pi_law_follows_eq_10_with_the_channel_mapping_of_section_3_2() {
    let p = feedback_only(params());
    let (kt, kr) = (p.translation_gains, p.rotation_gains);
    let half_l_um = 0.5 * p.sensor_spacing_mm * 1e3;
    let mut controller = PiezoController::new(p).unwrap();
    // Constant errors: y 0.4 µm, x 0.3 µm, theta 2e-6 rad about x = 5 µm.
    let (e_y, e_x, e_theta) = (0.4, 0.3, 2e-6);
    let x_ref = 5.0;
    // s2 − s3 = −e_theta·L so that theta_ref − (s2 − s3)/L = e_theta with theta_ref = 0.
    let s2 = x_ref - e_x - e_theta * half_l_um;
    let s3 = x_ref - e_x + e_theta * half_l_um;
    let sensors = [3.0 - e_y, s2, s3];
    for n in 1..=50 {
        let out = controller.step(x_ref, 3.0, 0.0, sensors, DT);
        let integral_time = n as f64 * DT;
        let v = |g: PiGains, e: f64| g.kp * e + g.ki * e * integral_time;
        let v_y = v(kt, e_y);
        let v_x = v(kt, e_x);
        let v_theta = v(kr, e_theta * half_l_um);
        let tol = 1e-12;
        assert!((out.e_y - e_y).abs() < tol && (out.e_x - e_x).abs() < tol);
        assert!((out.e_theta - e_theta).abs() < 1e-15);
        assert!(
            (out.feedback[0] - v_y).abs() < tol,
            "{n}: {:?}",
            out.feedback
        );
        assert!((out.feedback[1] - (v_x + v_theta)).abs() < tol);
        assert!((out.feedback[2] - (v_x - v_theta)).abs() < tol);
        assert_eq!(out.u, out.feedback, "inside the command range");
    }
}

#[test]
fn integrators_hold_while_their_channel_is_limited() {
    let mut p = feedback_only(params());
    p.feedback_x = false;
    p.feedback_theta = false;
    let ki = p.translation_gains.ki;
    let limit = p.command_max;
    let mut controller = PiezoController::new(p).unwrap();
    // A 20 µm error asks for more than 12 V within 13 ms (ki·e·t = 12 V at t = 12 ms).
    let mut limited_at = None;
    for n in 0..400 {
        let out = controller.step(0.0, 20.0, 0.0, [0.0; 3], DT);
        if out.u[0] == limit && limited_at.is_none() {
            limited_at = Some(n);
        }
    }
    let limited_at = limited_at.expect("the command reaches its limit");
    assert!(limited_at < 140, "limited after {limited_at} samples");
    let held = controller.output().feedback[0];
    assert!(
        (limit..=limit + ki * 20.0 * DT + 1e-9).contains(&held),
        "the integrator stops within one increment past the limit: fb = {held}"
    );
    // When the error reverses, the command leaves the limit at once: no
    // stored windup to unwind.
    let out = controller.step(0.0, 20.0, 0.0, [21.0, 0.0, 0.0], DT);
    assert!(out.u[0] < limit, "u1 = {}", out.u[0]);
}

#[test]
fn switching_feedback_off_empties_the_integrator() {
    let p = feedback_only(params());
    let mut controller = PiezoController::new(p).unwrap();
    for _ in 0..100 {
        controller.step(0.0, 1.0, 0.0, [0.0; 3], DT);
    }
    assert!(controller.output().feedback[0] > 0.0);
    controller.set_tuning(|p| p.feedback_y = false);
    controller.set_tuning(|p| p.feedback_y = true);
    let out = controller.step(0.0, 1.0, 0.0, [1.0, 0.0, 0.0], DT);
    assert_eq!(out.feedback[0], 0.0, "no error, no stored integral");
}

#[test]
fn decoupling_feeds_the_compensated_references_to_the_models() {
    let mut p = params();
    p.decoupling = true;
    p.feedback_x = false;
    p.feedback_y = false;
    p.feedback_theta = false;
    let half_l_um = 0.5 * p.sensor_spacing_mm * 1e3;
    let mut controller = PiezoController::new(p.clone()).unwrap();
    let mut y_model = ModifiedInversePi::new(p.y_model);
    let mut pzt2 = ModifiedInversePi::new(p.x_model);
    let (x_ref, y_ref, theta_ref) = (6.0, 8.0, 3e-5);
    let (x_d2, x_d3) = (x_ref + theta_ref * half_l_um, x_ref - theta_ref * half_l_um);
    let expected = decouple(&p.decoupling_params, x_d2, x_d3, y_ref, p.sensor_spacing_mm);
    let out = controller.step(x_ref, y_ref, theta_ref, [0.0; 3], DT);
    assert_eq!(out.decoupled, expected);
    assert!(expected.x_r2 != x_d2, "the paper's D1 acts at y = 8 µm");
    assert_eq!(
        out.feedforward[0],
        y_model.evaluate(expected.y_r(y_ref), 0.0)
    );
    assert_eq!(out.feedforward[1], pzt2.evaluate(expected.x_r2, 0.0));
}

#[test]
fn the_state_round_trips_through_serde() {
    let mut controller = PiezoController::new(params()).unwrap();
    for n in 0..300 {
        let y = 6.0 + 3.0 * (n as f64 * 0.01).sin();
        controller.step(6.0, y, 0.0, [0.1, 6.0, 6.0], DT);
    }
    let json = serde_json::to_string(&controller).unwrap();
    let mut restored: PiezoController = serde_json::from_str(&json).unwrap();
    assert_eq!(restored, controller);
    let a = controller.step(6.0, 7.0, 0.0, [7.2, 6.1, 5.9], DT);
    let b = restored.step(6.0, 7.0, 0.0, [7.2, 6.1, 5.9], DT);
    assert_eq!(a, b);
}

#[test]
fn invalid_parameters_are_named() {
    // A lower cutoff above the upper one (Table 2's misprinted q_1 = 10
    // beside p_1 = 2.05) would make D1 a constant.
    let mut p = params();
    p.decoupling_params.q[0] = 10.0;
    let e = PiezoController::new(p).unwrap_err();
    assert_eq!(
        (e.parameter.as_str(), e.value),
        ("decoupling_params.q[0]", 10.0)
    );
    assert!(
        e.allowed
            .starts_with("at most the upper cutoff p of the same compensation, 2.05")
    );
    let mut p = params();
    p.decoupling_params.q[0] = p.decoupling_params.p[0];
    assert!(
        PiezoController::new(p).is_ok(),
        "q = p is a constant D by choice"
    );
    let mut p = params();
    p.rotation_gains.ki = -1.0;
    let e = PiezoController::new(p).unwrap_err();
    assert_eq!(e.parameter, "rotation_gains.ki");
    let mut p = params();
    p.sensor_spacing_mm = 0.0;
    assert_eq!(
        PiezoController::new(p).unwrap_err().parameter,
        "sensor_spacing_mm"
    );
    let mut p = params();
    p.y_model.c = -0.5;
    assert_eq!(PiezoController::new(p).unwrap_err().parameter, "y_model.c");
}

#[test]
fn the_stage_preset_is_an_identified_controller_and_the_default() {
    let stage = ControllerParams::stage();
    stage
        .validate()
        .expect("the shipped stage preset validates");
    assert_eq!(
        ControllerParams::default(),
        stage,
        "FMU start values = stage"
    );
    // It is the paper's controller structure with this plant's identified
    // numbers: every switch on, the §3.2 gains, and fitted models that differ
    // from Table 1's.
    let paper = ControllerParams::paper();
    assert!(stage.feedforward && stage.decoupling);
    assert!(stage.feedback_x && stage.feedback_y && stage.feedback_theta);
    assert_eq!(stage.translation_gains, paper.translation_gains);
    assert_eq!(stage.rotation_gains, paper.rotation_gains);
    assert_eq!(stage.sensor_spacing_mm, paper.sensor_spacing_mm);
    assert_ne!(stage.y_model, paper.y_model);
    // Every compensation was fitted to a coupling of ~1-3 um over its
    // sweep (D1-D3: 10 um of demand; D4: eq. (16)'s ±9.2e-3 deg, 321 urad):
    // a slope that moves it by well over 0.1 um across that sweep.
    let sweeps = [10.0, 10.0, 10.0, 2.0 * 9.2e-3_f64.to_radians() * 1e6];
    for (i, (dk, sweep)) in stage.decoupling_params.dk.iter().zip(sweeps).enumerate() {
        assert!(dk.abs() * sweep > 0.1, "D{} slope {dk} over {sweep}", i + 1);
    }
}

/// Seed 001's path inside the sampled controller: with `hysteresis_model`
/// Bouc-Wen the feedforward is the exact inverse of eq. (6) of each channel
/// (its model's output at the commands equals the references), and with the
/// model-based law the references are the demands minus the coupling
/// models' outputs at the commands applied so far.
#[test]
fn inverse_bouc_wen_feedforward_and_model_based_decoupling_follow_their_models() {
    use piezo_models::{AsymmetricBoucWen, DecouplingModel, HysteresisModel};
    let mut p = ControllerParams::stage();
    p.feedback_x = false;
    p.feedback_y = false;
    p.feedback_theta = false;
    p.decoupling = true;
    p.hysteresis_model = HysteresisModel::BoucWen;
    p.decoupling_model = DecouplingModel::ModelBased;
    // The memory-free models (the memory's identity: inverse_bouc_wen's tests).
    p.bouc_wen.return_point_memory = false;
    let half_l_um = 0.5 * p.sensor_spacing_mm * 1e3;
    let mut controller = PiezoController::new(p.clone()).unwrap();
    // The controller's models start where its plant's stacks rest: at the
    // 0 V end of their exercised loop.
    let at_rest = |params| AsymmetricBoucWen::at_exercised_rest(params, p.bouc_wen.rest_cycle);
    let mut forward = [p.bouc_wen.y, p.bouc_wen.x, p.bouc_wen.x].map(at_rest);
    let mut x_from_y = at_rest(p.bouc_wen.x_from_y);
    let mut y_from_x = at_rest(p.bouc_wen.y_from_x);
    for n in 0..5000 {
        let t = n as f64 * DT;
        let (x_ref, y_ref) = (6.0 + 2.0 * (7.0 * t).sin(), 6.0 + 5.0 * (3.0 * t).sin());
        let theta_ref = 4e-5 * (5.0 * t).cos();
        let out = controller.step(x_ref, y_ref, theta_ref, [0.0; 3], DT);
        let references = [
            y_ref - y_from_x.output(),
            x_ref + theta_ref * half_l_um - x_from_y.output(),
            x_ref - theta_ref * half_l_um - x_from_y.output(),
        ];
        assert!(
            (out.decoupled.y_rx - references[0]).abs() < 1e-12,
            "sample {n}"
        );
        assert!(
            (out.decoupled.x_r2 - references[1]).abs() < 1e-12,
            "sample {n}"
        );
        for c in 0..3 {
            assert_eq!(out.u[c], out.feedforward[c], "no feedback, no limiting");
            forward[c].advance_to(out.u[c], 0.01);
            assert!(
                (forward[c].output() - references[c]).abs() < 1e-9,
                "channel {c}, sample {n}: {} vs {}",
                forward[c].output(),
                references[c]
            );
        }
        x_from_y.advance_to(out.u[0], 0.01);
        y_from_x.advance_to(0.5 * (out.u[1] + out.u[2]), 0.01);
    }
}

/// `ControllerOutput::is_finite` sums the sample before testing it: finite
/// values whose sum overflows are still finite, and one infinite or NaN value
/// anywhere in the sample is found.
#[test]
fn a_sample_is_finite_exactly_when_each_value_is() {
    use piezo_models::piezo_controller::ControllerOutput;
    let mut sample = ControllerOutput::default();
    assert!(sample.is_finite());
    // f64::MAX + f64::MAX overflows to +inf; the values themselves are finite.
    sample.u = [f64::MAX, f64::MAX, -f64::MAX];
    sample.feedback = [f64::MAX, 0.0, 0.0];
    assert!(sample.is_finite());
    for index in 0..ControllerOutput::NAMES.len() {
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let mut sample = ControllerOutput::default();
            set_value(&mut sample, index, bad);
            assert_eq!(sample.values()[index].to_bits(), bad.to_bits());
            assert!(
                !sample.is_finite(),
                "{} = {bad}",
                ControllerOutput::NAMES[index]
            );
        }
    }
}

/// Writes value `index` of [`ControllerOutput::values`] order.
fn set_value(sample: &mut piezo_models::piezo_controller::ControllerOutput, index: usize, v: f64) {
    let d = &mut sample.decoupled;
    let slot = match index {
        0..=2 => &mut sample.u[index],
        3..=5 => &mut sample.feedforward[index - 3],
        6..=8 => &mut sample.feedback[index - 6],
        9 => &mut sample.e_x,
        10 => &mut sample.e_y,
        11 => &mut sample.e_theta,
        12 => &mut d.x_r2,
        13 => &mut d.x_r3,
        14 => &mut d.y_rx,
        _ => &mut d.y_rtheta,
    };
    *slot = v;
}

/// Before its first sample, and after a reset, the controller commands 0 V
/// as far as the command range lets it: inside the range, always.
#[test]
fn the_commands_before_the_first_sample_are_inside_the_range() {
    for (min, max, rest) in [(-2.0, 12.0, 0.0), (1.0, 10.0, 1.0), (-10.0, -1.0, -1.0)] {
        let mut p = params();
        p.command_min = min;
        p.command_max = max;
        let mut controller = PiezoController::new(p).unwrap();
        assert_eq!(controller.output().u, [rest; 3], "{min}..{max}");
        controller.step(1.0, 2.0, 0.0, [0.0; 3], DT);
        controller.reset();
        assert_eq!(
            controller.output().u,
            [rest; 3],
            "{min}..{max} after a reset"
        );
    }
}

/// Sensors that read `offsets` where the references count from (a stage
/// whose models were fitted on raw readings) give the PI laws no error once
/// the offsets are given, and the offsets as errors when they are not: the
/// feedback would pull the stage to the sensors' 0 against the feedforward.
#[test]
fn sensor_offsets_give_the_feedback_the_references_zero() {
    let offsets = [23.4, -96.2, -95.1];
    let half_l_um = 0.5 * params().sensor_spacing_mm * 1e3;
    let (x_ref, y_ref, theta_ref) = (3.0, 5.0, 2e-5);
    let sensors = [
        offsets[0] + y_ref,
        offsets[1] + x_ref + theta_ref * half_l_um,
        offsets[2] + x_ref - theta_ref * half_l_um,
    ];
    let mut with = feedback_only(params());
    with.sensor_offsets = offsets;
    let mut controller = PiezoController::new(with).unwrap();
    for _ in 0..100 {
        let out = controller.step(x_ref, y_ref, theta_ref, sensors, DT);
        assert!(out.e_x.abs() < 1e-12 && out.e_y.abs() < 1e-12, "{out:?}");
        assert!(out.e_theta.abs() < 1e-15, "{out:?}");
        assert!(out.feedback.iter().all(|u| u.abs() < 1e-9), "{out:?}");
    }
    let mut without = PiezoController::new(feedback_only(params())).unwrap();
    let out = without.step(x_ref, y_ref, theta_ref, sensors, DT);
    assert!((out.e_y + offsets[0]).abs() < 1e-12, "{out:?}");
    assert!(
        (out.e_x + 0.5 * (offsets[1] + offsets[2])).abs() < 1e-12,
        "{out:?}"
    );
    let mut bad = params();
    bad.sensor_offsets[2] = f64::NAN;
    assert!(PiezoController::new(bad).is_err());
}

//! Seed 001's model-based decoupling (eq. 7-16) on both stages: y follows a
//! 2 Hz, 2 µm-amplitude sine (seed 001 §5.3) through the inverse Bouc-Wen
//! feedforward while x is held, feedforward only, no feedback; the x
//! displacement the y motion causes shrinks when the coupling estimate is
//! subtracted from x's reference.
//!
//! The controller's models here are the plant's own (converted to command
//! volts through the amplifier gain), starting, like the plant's, at the rest
//! of their working loop, so the test isolates the law from the
//! identification: what remains is the amplifier's lag, the modes and the
//! one-sample delay of the estimate. x is held at a home above 0 V
//! and the commands stay in 0..10 V, where every stage of the project works.

use piezo_models::{
    BoucWenFeedforward, BoucWenModels, BoucWenParams, CouplingEstimator, FlexureStage,
    FlexureStageParams,
};

const STEP: f64 = 1e-4;
const MAX_DU: f64 = 1e-3;

/// The plant's models in command volts. The y-from-x coupling is the sum of
/// the pair's two models (same shape, so the sum is one Bouc-Wen model with
/// p and q added).
fn oracle_models(params: &FlexureStageParams) -> BoucWenModels {
    let g = params.amplifier.gain;
    let c = &params.coupling;
    let y_from_x = BoucWenParams {
        p: c.y_from_pzt2.p + c.y_from_pzt3.p,
        q: c.y_from_pzt2.q + c.y_from_pzt3.q,
        ..c.y_from_pzt2
    };
    assert_eq!(
        BoucWenParams {
            p: 0.0,
            q: 0.0,
            ..c.y_from_pzt2
        },
        BoucWenParams {
            p: 0.0,
            q: 0.0,
            ..c.y_from_pzt3
        },
        "the pair's coupling models share one shape"
    );
    BoucWenModels {
        x: params.actuators[1].hysteresis.with_input_scale(g),
        y: params.actuators[0].hysteresis.with_input_scale(g),
        x_from_y: c.x_from_pzt1.with_input_scale(g),
        y_from_x: y_from_x.with_input_scale(g),
        // The plant's stacks rest on their loop to rest_cycle_voltage: the
        // same loop in command volts.
        rest_cycle: params.rest_cycle_voltage / g,
        // And close their minor loops as the stacks do.
        return_point_memory: params.return_point_memory,
    }
}

/// Span of x over the last of three periods of the y sine (x held at
/// `x_home`, y around `y_home`), and the RMS of y's tracking error there.
fn coupling_run(
    params: &FlexureStageParams,
    decouple: bool,
    x_home: f64,
    y_home: f64,
) -> (f64, f64) {
    let models = oracle_models(params);
    let mut stage = FlexureStage::new(params.clone()).unwrap();
    let mut feedforward = BoucWenFeedforward::new(&models, MAX_DU);
    let mut estimator = CouplingEstimator::new(&models, MAX_DU);
    let (mut lo, mut hi, mut square, mut count) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0);
    // One second ramps both axes to their homes, then three periods of 2 Hz.
    let samples = 25_000;
    for i in 0..samples {
        let t = i as f64 * STEP;
        let ramp = (t / 1.0).min(1.0);
        let sine = if t > 1.0 {
            2.0 * (2.0 * std::f64::consts::PI * 2.0 * (t - 1.0)).sin()
        } else {
            0.0
        };
        let (x_ref, y_ref) = (ramp * x_home, ramp * y_home + sine);
        let estimate = estimator.estimate();
        let (x_r, y_r) = if decouple {
            (x_ref - estimate.x_from_y, y_ref - estimate.y_from_x)
        } else {
            (x_ref, y_ref)
        };
        let commands = feedforward
            .commands([y_r, x_r, x_r])
            .map(|u| u.clamp(0.0, 10.0));
        feedforward.commit(commands);
        estimator.commit(commands);
        stage.step(commands, STEP);
        if t >= 2.0 {
            let pose = stage.pose();
            lo = lo.min(pose.x_um);
            hi = hi.max(pose.x_um);
            square += (pose.y_um - y_ref).powi(2);
            count += 1;
        }
    }
    (hi - lo, (square / count as f64).sqrt())
}

/// On the stage whose minor loops close, the exact models must close theirs
/// too: without the memory the same law takes 75 % off (0.24 um left), short
/// of the 90 % below.
#[test]
fn model_based_decoupling_shrinks_the_coupling_on_both_stages() {
    for (name, params, x_home, y_home) in [
        (
            "FlexureStage (seed 000, without the memory: 3dof_no_memory)",
            FlexureStageParams::without_memory(),
            8.0,
            7.0,
        ),
        (
            "XY200S (seed 001)",
            FlexureStageParams::xy200s(),
            20.0,
            20.0,
        ),
        (
            "FlexureStage (seed 000, its minor loops closed: the default; the models with the memory)",
            FlexureStageParams::default(),
            8.0,
            7.0,
        ),
    ] {
        let (without, _) = coupling_run(&params, false, x_home, y_home);
        let (with, y_rms) = coupling_run(&params, true, x_home, y_home);
        let reduction = 100.0 * (1.0 - with / without);
        println!(
            "{name}: x coupling span {without:.4} um without, {with:.4} um with decoupling ({reduction:.1} % less; seed 001: 73 %); y tracking RMS {y_rms:.4} um"
        );
        // Seed 001 reached 73 %; with exact models the law must do far
        // better, bounded by the lag of the amplifier and the modes.
        assert!(reduction > 90.0, "{name}: {reduction} %");
        // With both couplings cancelled, the feedforward alone tracks y to a
        // small fraction of its 4 um swing (seed 000's stage also creeps,
        // which no feedforward model here knows).
        assert!(y_rms < 0.05, "{name}: y RMS {y_rms}");
    }
}

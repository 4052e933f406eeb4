//! Rebuilding a stage and a controller from a state that comes from outside
//! (`piezo_models::restore`): only the parameters and the dynamic state are
//! taken from it, so forged derived values change nothing, forged parameters
//! are refused by name, and a non-finite dynamic variable is named.

use piezo_models::{
    ControllerParams, DecouplingModel, FlexureStage, FlexureStageParams, HysteresisModel,
    PiezoController,
};
use serde_json::{Value, json};

const DT: f64 = 1e-4;

/// Commands [V] of a slow, unequal sine on the three channels at step `k`.
fn commands(k: usize) -> [f64; 3] {
    let phase = k as f64 * DT * std::f64::consts::TAU * 50.0;
    [
        5.0 + 4.0 * phase.sin(),
        5.0 + 3.0 * (phase + 1.0).sin(),
        4.0 - 2.0 * (phase + 2.0).sin(),
    ]
}

fn stage_params() -> FlexureStageParams {
    let mut params = FlexureStageParams::default();
    // The noise generator is part of the dynamic state: carried over, so
    // the rebuilt stage draws the same samples.
    params.noise.enabled = true;
    params
}

/// A stage 200 steps into a sine.
fn running_stage() -> FlexureStage {
    let mut stage = FlexureStage::new(stage_params()).unwrap();
    for k in 0..200 {
        assert!(stage.step(commands(k), DT).fault.is_none());
    }
    stage
}

/// Sets `value` at the JSON `path` (object keys, or array indices as
/// numbers) of `state`.
fn set(state: &mut Value, path: &[&str], value: Value) {
    let mut node = state;
    for key in path {
        node = match key.parse::<usize>() {
            Ok(index) => &mut node[index],
            Err(_) => &mut node[*key],
        };
    }
    assert!(!node.is_null(), "no {path:?} in the serialized model");
    *node = value;
}

/// Steps `a` and `b` side by side for 200 steps; every step's sensors agree
/// bit for bit, and so do the whole stages at the end (caches included).
fn assert_steps_alike(mut a: FlexureStage, mut b: FlexureStage) {
    for k in 200..400 {
        a.step(commands(k), DT);
        b.step(commands(k), DT);
        assert_eq!(a.sensors(), b.sensors(), "step {k}");
    }
    assert_eq!(a, b);
}

#[test]
fn a_rebuilt_stage_steps_as_the_original_whatever_its_derived_values_said() {
    let original = running_stage();
    let mut state = serde_json::to_value(&original).unwrap();
    // Values derived from the parameters at construction, each forged: the
    // amplifier's copy of its limits crossed (a clamp with min > max
    // panics), the time constant, the sensor spacing, a mode's frequency,
    // the piece cache's values, an exercised rest and a Bouc-Wen model's copy of its
    // parameters.
    set(&mut state, &["amplifier", "params", "v_min"], json!(500.0));
    set(&mut state, &["tau"], json!(1.0));
    set(&mut state, &["spacing_um"], json!(1.0));
    set(&mut state, &["modes", "0", "omega"], json!(3.0));
    set(
        &mut state,
        &["piece", "decays"],
        json!([0.5, 0.5, 0.5, 0.5]),
    );
    set(
        &mut state,
        &["actuators", "1", "rest", "offset"],
        json!(7.0),
    );
    set(&mut state, &["couplings", "2", "params", "q"], json!(-40.0));
    let forged: FlexureStage = serde_json::from_value(state).unwrap();
    assert_ne!(forged, original);

    let rebuilt = forged.rebuilt().unwrap();
    assert_eq!(rebuilt.unreachable_state(), None);
    // The same value, caches included: a state taken from it serializes to
    // the original's bytes.
    assert_eq!(rebuilt, original);
    assert_steps_alike(original, rebuilt);
}

#[test]
fn a_stage_rebuilt_untouched_is_the_same_stage() {
    let original = running_stage();
    let rebuilt = original.rebuilt().unwrap();
    assert_eq!(rebuilt, original);
    assert_steps_alike(original, rebuilt);
    // Before its first step too (nothing cached yet).
    let fresh = FlexureStage::new(stage_params()).unwrap();
    assert_eq!(fresh.rebuilt().unwrap(), fresh);
}

#[test]
fn a_stage_whose_parameters_were_forged_is_not_rebuilt() {
    let mut state = serde_json::to_value(running_stage()).unwrap();
    set(&mut state, &["params", "amplifier", "v_min"], json!(500.0));
    let forged: FlexureStage = serde_json::from_value(state).unwrap();
    let error = forged.rebuilt().unwrap_err();
    assert!(error.parameter.contains("v_m"), "{error}");
}

#[test]
fn a_non_finite_dynamic_variable_of_a_stage_is_named() {
    let mut stage = running_stage();
    assert_eq!(stage.unreachable_state(), None);
    let names = piezo_models::flexure_stage::ode::STATES;
    for (i, name) in names.iter().enumerate() {
        let mut x = stage.continuous_states();
        x[i] = f64::NAN;
        let mut broken = stage.clone();
        broken.set_continuous_states(&x);
        let unreachable = broken
            .unreachable_state()
            .expect("a NaN state is unreachable");
        assert_eq!(unreachable.variable, *name);
        assert!(unreachable.value.is_nan());
    }
    // A finite state far beyond the co-simulation divergence bounds is one
    // a Model Exchange integrator may set: not refused here.
    let mut x = stage.continuous_states();
    x[13] = 1e9;
    stage.set_continuous_states(&x);
    assert_eq!(stage.unreachable_state(), None);
}

fn controller_params() -> ControllerParams {
    ControllerParams {
        hysteresis_model: HysteresisModel::BoucWen,
        decoupling_model: DecouplingModel::ModelBased,
        ..ControllerParams::default()
    }
}

/// References x [µm], y [µm], theta [rad] and sensors [µm] at sample `k`.
fn sample(k: usize) -> ([f64; 3], [f64; 3]) {
    let phase = k as f64 * DT * std::f64::consts::TAU * 20.0;
    (
        [
            5.0 + 4.0 * phase.sin(),
            4.0 + 3.0 * phase.cos(),
            1e-5 * phase.sin(),
        ],
        [
            4.0 + 3.0 * phase.cos(),
            5.0 + 3.9 * phase.sin(),
            5.1 + 4.1 * phase.sin(),
        ],
    )
}

fn run(controller: &mut PiezoController, samples: std::ops::Range<usize>) -> Vec<[f64; 3]> {
    samples
        .map(|k| {
            let ([x, y, theta], sensors) = sample(k);
            controller.step(x, y, theta, sensors, DT).u
        })
        .collect()
}

#[test]
fn a_rebuilt_controller_steps_as_the_original_whatever_its_derived_values_said() {
    for (hysteresis_model, decoupling_model) in [
        (HysteresisModel::BoucWen, DecouplingModel::ModelBased),
        (
            HysteresisModel::ModifiedPi,
            DecouplingModel::PiecewiseLinear,
        ),
    ] {
        let mut original = PiezoController::new(ControllerParams {
            hysteresis_model,
            decoupling_model,
            ..controller_params()
        })
        .unwrap();
        run(&mut original, 0..200);
        // PI gains changed while running are carried over.
        original.set_tuning(|p| p.translation_gains.kp *= 1.5);
        let mut state = serde_json::to_value(&original).unwrap();
        // Thresholds derived from the inverse P-I parameters, an inverse
        // Bouc-Wen model's rest, copy of its parameters and substep, and a
        // coupling model's rest.
        set(
            &mut state,
            &["models", "0", "backlash_thresholds", "0"],
            json!(1e3),
        );
        set(
            &mut state,
            &["models", "2", "dead_zone_thresholds", "1"],
            json!(-7.0),
        );
        set(
            &mut state,
            &["bouc_wen", "inverses", "0", "model", "rest", "offset"],
            json!(5.0),
        );
        set(
            &mut state,
            &["bouc_wen", "inverses", "1", "model", "params", "p"],
            json!(0.0),
        );
        set(
            &mut state,
            &["bouc_wen", "inverses", "2", "max_du"],
            json!(10.0),
        );
        set(
            &mut state,
            &["coupling", "y_from_x", "rest", "h"],
            json!(3.0),
        );
        let forged: PiezoController = serde_json::from_value(state).unwrap();
        assert_ne!(forged, original);

        let mut rebuilt = forged.rebuilt().unwrap();
        assert_eq!(rebuilt.unreachable_state(), None);
        assert_eq!(rebuilt, original);
        assert_eq!(
            run(&mut rebuilt, 200..400),
            run(&mut original, 200..400),
            "{hysteresis_model:?} / {decoupling_model:?}"
        );
        assert_eq!(rebuilt, original);
    }
}

#[test]
fn a_controller_whose_fixed_parameters_were_forged_is_not_rebuilt() {
    let mut controller = PiezoController::new(controller_params()).unwrap();
    run(&mut controller, 0..10);
    let mut state = serde_json::to_value(&controller).unwrap();
    set(&mut state, &["params", "bouc_wen", "x", "n"], json!(0.1));
    let forged: PiezoController = serde_json::from_value(state).unwrap();
    let error = forged.rebuilt().unwrap_err();
    assert_eq!(error.parameter, "bouc_wen.x.n", "{error}");
}

#[test]
fn an_unreachable_dynamic_variable_of_a_controller_is_named() {
    let mut controller = PiezoController::new(controller_params()).unwrap();
    run(&mut controller, 0..10);
    assert_eq!(controller.unreachable_state(), None);

    let mut state = serde_json::to_value(&controller).unwrap();
    set(&mut state, &["limited", "1"], json!(7));
    let forged: PiezoController = serde_json::from_value(state).unwrap();
    let unreachable = forged.rebuilt().unwrap().unreachable_state().unwrap();
    assert_eq!(
        (unreachable.variable, unreachable.value),
        ("limit flag of a channel", 7.0)
    );

    // A step too long for the integrators (as an importer may ask)
    // overflows them, and the state goes non-finite from there on.
    let ([x, y, theta], sensors) = sample(10);
    controller.step(x, y, theta, sensors, f64::MAX);
    let unreachable = controller.rebuilt().unwrap().unreachable_state().unwrap();
    assert!(!unreachable.value.is_finite(), "{unreachable}");
}

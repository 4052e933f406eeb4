//! `FlexureStage::step` and `PiezoController::step` allocate nothing (they run
//! inside an FMU's doStep).
//!
//! The workspace's counting allocator counts the allocations of the test
//! thread only, so the harness's own threads do not disturb the count.

use counting_allocator::{CountingAllocator, allocations_of};
use piezo_models::{
    ControllerParams, DecouplingModel, FlexureStage, FlexureStageParams, HysteresisModel,
    PiezoController,
};
use std::f64::consts::TAU;

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// 10 000 steps with noise on, a full-range sine, varying step lengths (fresh
/// caches, many pieces) and a clipped command: zero allocations.
#[test]
fn step_allocates_nothing() {
    let mut params = FlexureStageParams::default();
    params.noise.enabled = true;
    let mut stage = FlexureStage::new(params).unwrap();
    let mut finite = true;

    let allocations = allocations_of(|| {
        for k in 1..=10_000 {
            let t = k as f64 * 1e-4;
            let u = 5.0 * (1.0 - (TAU * t).cos());
            let h = if k % 1000 == 0 { 2.5e-3 } else { 1e-4 };
            let commands = if k % 777 == 0 {
                [12.0, -1.0, u]
            } else {
                [u, 10.0 - u, u]
            };
            finite &= stage.step(commands, h).fault.is_none();
            std::hint::black_box(stage.sensors());
        }
    });

    assert!(finite);
    assert_eq!(allocations, 0, "step allocated {allocations} times");
}

/// With the return-point memory (the tracking parameter set): 10 000 steps
/// that turn every channel at each sample (dither on a sine), and the Model
/// Exchange calls an importer makes between and at events (states set,
/// derivatives, switching functions, the memory's event update): zero
/// allocations.
#[test]
fn the_memory_allocates_nothing_in_either_interface() {
    let mut stage = FlexureStage::new(FlexureStageParams::default()).unwrap();
    let mut finite = true;
    let mut checksum = 0.0;
    let allocations = allocations_of(|| {
        for k in 1..=10_000 {
            let t = k as f64 * 1e-4;
            let dither = if k % 2 == 0 { 0.02 } else { -0.02 };
            let u = 5.0 * (1.0 - (TAU * t).cos()) + dither;
            let commands = [u, 10.0 - u, u];
            finite &= stage.step(commands, 1e-4).fault.is_none();
            let mut x = stage.continuous_states();
            x[0] += 1e-3;
            stage.set_continuous_states(&x);
            checksum += stage.derivatives(commands)[3];
            checksum += stage.switching_functions(commands)[7];
            stage.settle_memories(commands);
        }
    });
    assert!(finite && checksum.is_finite());
    assert_eq!(allocations, 0, "the memory allocated {allocations} times");
}

/// 10 000 controller samples with every part on (feedforward, decoupling,
/// three PI loops), limited commands and varying sample periods: zero
/// allocations.
#[test]
fn controller_step_allocates_nothing() {
    let params = ControllerParams {
        decoupling: true,
        ..ControllerParams::default()
    };
    let mut controller = PiezoController::new(params).unwrap();
    let mut total = 0.0;

    let allocations = allocations_of(|| {
        for k in 1..=10_000 {
            let t = k as f64 * 1e-4;
            let dt = if k % 1000 == 0 { 2.5e-4 } else { 1e-4 };
            let y_ref = 6.0 + 5.0 * (TAU * t).sin();
            let sensors = if k % 777 == 0 {
                [30.0, -5.0, 40.0]
            } else {
                [y_ref - 0.1, 6.0, 6.1]
            };
            let out = controller.step(6.0, y_ref, 1e-5 * (TAU * t).cos(), sensors, dt);
            total += out.u[0] + out.u[1] + out.u[2];
        }
    });

    assert!(total.is_finite());
    assert_eq!(
        allocations, 0,
        "the controller allocated {allocations} times"
    );
}

/// Seed 001's method with the Bouc-Wen models' return-point memory: the
/// inverse's Newton trials copy nothing (a copy of a memory would allocate),
/// on a demand that turns at every sample (dither on a sine): zero
/// allocations.
#[test]
fn the_bouc_wen_controller_with_its_memory_allocates_nothing() {
    let mut params = ControllerParams {
        decoupling: true,
        hysteresis_model: HysteresisModel::BoucWen,
        decoupling_model: DecouplingModel::ModelBased,
        ..ControllerParams::default()
    };
    params.bouc_wen.return_point_memory = true;
    let mut controller = PiezoController::new(params).unwrap();
    let mut total = 0.0;
    let allocations = allocations_of(|| {
        for k in 1..=10_000 {
            let t = k as f64 * 1e-4;
            let dither = if k % 2 == 0 { 0.01 } else { -0.01 };
            let y_ref = 6.0 + 5.0 * (TAU * t).sin() + dither;
            let out = controller.step(6.0 + dither, y_ref, 0.0, [y_ref, 6.0, 6.1], 1e-4);
            total += out.u[0] + out.u[1] + out.u[2];
        }
    });
    assert!(total.is_finite());
    assert_eq!(
        allocations, 0,
        "the controller allocated {allocations} times"
    );
}

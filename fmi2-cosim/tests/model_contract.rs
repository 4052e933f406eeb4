//! The model contract seen through the C entry points: how each
//! [`StepOutcome`] maps onto fmi2DoStep's status, the time, the state machine
//! and the status queries (FMI 2.0.4 §4.2.2, §4.2.4), and how an FMU state
//! from outside (deserialized bytes with a valid checksum but made-up values)
//! is checked before it can replace an instance's values.

mod common;

use std::ptr;

use common::{DISCARD, ERROR, OK};
use fmi2_cosim::abi;
use fmi2_cosim::fmi_sys::fmi2 as sys;
use fmi2_cosim::{
    BaseUnit, CoSimModel, Context, DefaultExperiment, FmiState, ModelError, ModelInfo, StepOutcome,
    UnitDefinition, Variability, Variable,
};
use serde::{Deserialize, Serialize};

/// `y' = u`; `z = gain_twice · y`, where `gain_twice` is derived from the
/// parameter `gain` (a cache the model rebuilds on restore). `mode` selects
/// how the next step ends.
#[derive(Clone, Serialize, Deserialize)]
struct Stepper {
    u: f64,
    y: f64,
    gain: f64,
    mode: i32,
    /// 2 · gain, computed at initialization and on restore, never set.
    gain_twice: f64,
}

/// Values of `mode`.
const COMPLETE: i32 = 0;
const DISCARD_HALFWAY: i32 = 1;
const TERMINATE_HALFWAY: i32 = 2;
const DISCARD_BEFORE_THE_STEP: i32 = 3;
const DISCARD_AT_THE_END: i32 = 4;

/// Beyond this |y| the model's own invariant is broken.
const Y_LIMIT: f64 = 1e6;

static VARIABLES: &[Variable<Stepper>] = &[
    Variable::real_input("u", "input", "1", |m| m.u, |m, v| m.u = v),
    Variable::real_output("y", "integral of u", "1", |m| m.y),
    Variable::real_output("z", "2 gain y", "1", |m| m.gain_twice * m.y),
    Variable::real_parameter(
        "gain",
        "gain of z",
        "1",
        Variability::Fixed,
        |m: &Stepper| m.gain,
        |m, v| m.gain = v,
    )
    .range(Some(0.0), Some(10.0)),
    Variable::integer_parameter(
        "mode",
        "how the next step ends",
        Variability::Tunable,
        |m: &Stepper| m.mode,
        |m, v| m.mode = v,
    )
    .integer_range(Some(0), Some(4)),
];

impl CoSimModel for Stepper {
    const INFO: ModelInfo = ModelInfo {
        model_identifier: "Stepper",
        model_name: "Stepper",
        description: "ends its steps as told",
        author: "tests",
        version: "0",
        license: "MIT",
        default_experiment: DefaultExperiment {
            start_time: 0.0,
            stop_time: 1.0,
            step_size: 0.1,
        },
    };
    const UNITS: &'static [UnitDefinition] = &[UnitDefinition {
        name: "1",
        base: BaseUnit::NONE,
        display_units: &[],
    }];

    fn variables() -> &'static [Variable<Self>] {
        VARIABLES
    }

    fn new() -> Self {
        Stepper {
            u: 0.0,
            y: 0.0,
            gain: 1.0,
            mode: COMPLETE,
            gain_twice: 2.0,
        }
    }

    fn exit_initialization_mode(&mut self, _: &mut Context<'_>, _: f64) -> Result<(), ModelError> {
        self.gain_twice = 2.0 * self.gain;
        Ok(())
    }

    fn do_step(&mut self, _: &mut Context<'_>, t: f64, h: f64) -> Result<StepOutcome, ModelError> {
        let half = |m: &mut Stepper| {
            m.y += m.u * h / 2.0;
            t + h / 2.0
        };
        Ok(match self.mode {
            DISCARD_HALFWAY => StepOutcome::Discarded {
                last_successful_time: half(self),
            },
            TERMINATE_HALFWAY => StepOutcome::Terminate {
                last_successful_time: half(self),
            },
            DISCARD_BEFORE_THE_STEP => StepOutcome::Discarded {
                last_successful_time: t - h,
            },
            DISCARD_AT_THE_END => StepOutcome::Discarded {
                last_successful_time: t + h,
            },
            _ => {
                self.y += self.u * h;
                StepOutcome::Completed
            }
        })
    }

    fn validate_restored(&mut self, _: &mut Context<'_>, _: FmiState) -> Result<(), ModelError> {
        if self.y.abs() > Y_LIMIT {
            return Err(ModelError(format!("y = {} is beyond {Y_LIMIT}", self.y)));
        }
        self.gain_twice = 2.0 * self.gain;
        Ok(())
    }
}

const U: u32 = 0;
const Y: u32 = 1;
const Z: u32 = 2;
const GAIN: u32 = 3;
const MODE: u32 = 4;

type Slave = common::Slave<Stepper>;

impl common::Slave<Stepper> {
    /// Initialized at t = 0 with gain 1.25 and input 2.
    fn initialized() -> Slave {
        let slave = Slave::instantiate();
        assert_eq!(slave.set_real(GAIN, 1.25), OK);
        assert_eq!(slave.set_real(U, 2.0), OK);
        slave.setup_and_enter(0.0);
        assert_eq!(slave.exit_initialization(), OK);
        slave
    }

    fn set_mode(&self, mode: i32) -> sys::fmi2Status {
        self.set_integer(MODE, mode)
    }
}

/// `bytes` with the one occurrence, in the payload, of the f64 `from`
/// replaced by `to`, and the checksum recomputed.
fn forge(bytes: &[u8], from: f64, to: f64) -> Vec<u8> {
    common::forge(bytes, &from.to_le_bytes(), &to.to_le_bytes())
}

#[test]
fn a_discarded_step_stops_at_the_last_successful_time_in_step_failed() {
    let slave = Slave::initialized();
    assert_eq!(slave.step(0.0, 0.1), OK);
    let saved = slave.get_state();
    assert_eq!(slave.set_mode(DISCARD_HALFWAY), OK);
    assert_eq!(slave.step(0.1, 0.1), DISCARD);
    // The slave stands where the model stopped, and says so.
    let (status, time) = slave.last_successful_time();
    assert_eq!(status, OK);
    assert!((time - 0.15).abs() < 1e-15, "{time}");
    assert_eq!(slave.terminated(), (OK, 0));
    assert!((slave.real(Y) - 0.3).abs() < 1e-12);
    // fmi2DoStepStatus is for asynchronous steps only.
    let mut step_status = OK;
    // SAFETY: `step_status` is valid for a write.
    let status = unsafe {
        abi::get_status::<Stepper>(
            slave.0,
            sys::fmi2StatusKind_fmi2DoStepStatus,
            &mut step_status,
        )
    };
    assert_eq!(status, DISCARD);
    // The importer goes back to the saved state and retries with a shorter
    // step.
    assert_eq!(slave.set_state(saved), OK);
    assert_eq!(slave.last_successful_time(), (OK, 0.1));
    assert_eq!(slave.set_mode(COMPLETE), OK);
    assert_eq!(slave.step(0.1, 0.05), OK);
    assert_eq!(slave.last_successful_time(), (OK, 0.15000000000000002));
    assert!((slave.real(Y) - 0.3).abs() < 1e-12);
}

#[test]
fn step_failed_refuses_inputs() {
    let slave = Slave::initialized();
    assert_eq!(slave.set_mode(DISCARD_HALFWAY), OK);
    assert_eq!(slave.step(0.0, 0.1), DISCARD);
    assert_eq!(slave.set_real(U, 1.0), ERROR);
}

#[test]
fn a_step_is_refused_after_a_discard_and_terminate_is_allowed() {
    let slave = Slave::initialized();
    assert_eq!(slave.set_mode(DISCARD_HALFWAY), OK);
    assert_eq!(slave.step(0.0, 0.1), DISCARD);
    assert_eq!(slave.terminate(), OK);
    let slave = Slave::initialized();
    assert_eq!(slave.set_mode(DISCARD_HALFWAY), OK);
    assert_eq!(slave.step(0.0, 0.1), DISCARD);
    // fmi2DoStep is not allowed in stepFailed: an illegal call, fmi2Error.
    assert_eq!(slave.step(0.05, 0.1), ERROR);
}

#[test]
fn a_terminate_request_is_a_discard_with_fmi2_terminated_true() {
    let slave = Slave::initialized();
    assert_eq!(slave.set_mode(TERMINATE_HALFWAY), OK);
    assert_eq!(slave.step(0.0, 0.2), DISCARD);
    assert_eq!(slave.terminated(), (OK, 1));
    assert_eq!(slave.last_successful_time(), (OK, 0.1));
    // The flag survives an FMU state round trip through bytes, and a
    // state in stepFailed restores into stepFailed.
    let state = slave.get_state();
    let bytes = slave.serialize(state);
    let other = Slave::initialized();
    assert_eq!(other.terminated(), (OK, 0));
    let (status, copy) = other.deserialize(&bytes);
    assert_eq!(status, OK);
    assert_eq!(other.set_state(copy), OK);
    assert_eq!(other.terminated(), (OK, 1));
    assert_eq!(other.last_successful_time(), (OK, 0.1));
    assert_eq!(other.step(0.1, 0.1), ERROR, "stepFailed allows no step");
    assert_eq!(slave.terminate(), OK);
    // fmi2Reset clears the request.
    // SAFETY: `other.0` is live.
    let status = unsafe { abi::reset::<Stepper>(other.0) };
    assert_eq!(status, OK);
    let other = Slave::initialized();
    assert_eq!(other.terminated(), (OK, 0));
}

/// fmi2DeSerializeFMUstate's FMUstate is output only (FMI 2.0.4 §2.1.8), so
/// an importer may hand it an uninitialized variable: the layer writes a new
/// state there without reading what it held (an unmapped address here, which
/// a read would crash on), reuses a state this instance made, and leaves a
/// state of another instance to that instance.
#[test]
fn deserialize_writes_its_state_over_whatever_the_variable_held() {
    let slave = Slave::initialized();
    assert_eq!(slave.step(0.0, 0.1), OK);
    let bytes = slave.serialize(slave.get_state());
    let deserialize = |slave: &Slave, slot: &mut sys::fmi2FMUstate| {
        // SAFETY: `bytes` is a live slice and `slot` a live variable; what
        // it holds is the importer's business.
        unsafe {
            abi::deserialize_fmu_state::<Stepper>(slave.0, bytes.as_ptr().cast(), bytes.len(), slot)
        }
    };
    let mut slot: sys::fmi2FMUstate = ptr::without_provenance_mut(8);
    assert_eq!(deserialize(&slave, &mut slot), OK);
    assert_ne!(slot, ptr::without_provenance_mut(8));
    assert_eq!(slave.step(0.1, 0.1), OK);
    assert_eq!(slave.set_state(slot), OK, "the new state restores");
    let restored = slot;
    assert_eq!(deserialize(&slave, &mut slot), OK);
    assert_eq!(slot, restored, "a state of this instance is reused");
    let other = Slave::initialized();
    let mut others = other.get_state();
    let kept = others;
    assert_eq!(deserialize(&slave, &mut others), OK);
    assert_ne!(
        others, kept,
        "a state of another instance is not overwritten"
    );
    assert_eq!(other.set_state(kept), OK);
}

#[test]
fn a_last_successful_time_outside_the_step_is_a_model_error() {
    for mode in [DISCARD_BEFORE_THE_STEP, DISCARD_AT_THE_END] {
        let slave = Slave::initialized();
        assert_eq!(slave.set_mode(mode), OK);
        assert_eq!(slave.step(0.0, 0.1), ERROR, "mode {mode}");
        // The error state: status queries and steps are refused.
        assert_eq!(slave.last_successful_time().0, ERROR);
    }
}

#[test]
fn a_forged_parameter_out_of_its_range_is_refused_and_the_instance_keeps_working() {
    let slave = Slave::initialized();
    assert_eq!(slave.step(0.0, 0.1), OK);
    let state = slave.get_state();
    let bytes = slave.serialize(state);
    // Intact bytes restore.
    assert_eq!(slave.deserialize(&bytes).0, OK);
    for (from, to, what) in [
        (1.25, 20.0, "gain above its range"),
        (1.25, -1.0, "gain below its range"),
        (1.25, f64::NAN, "gain NaN"),
        (0.2, f64::NAN, "y NaN"),
        (0.2, f64::INFINITY, "y infinite"),
        (0.2, 1e9, "y beyond the model's own limit"),
    ] {
        let forged = forge(&bytes, from, to);
        let (status, forged_state) = slave.deserialize(&forged);
        assert_eq!(status, ERROR, "{what}");
        assert!(forged_state.is_null(), "{what}: no state made");
        // The refusal put the instance in its error state (fmi2Error) with
        // its values untouched; restoring a state of its own recovers it.
        assert!((slave.real(Y) - 0.2).abs() < 1e-12, "{what}");
        assert_eq!(slave.set_state(state), OK, "{what}");
        assert_eq!(slave.last_successful_time(), (OK, 0.1), "{what}");
    }
    assert_eq!(slave.step(0.1, 0.1), OK);
    assert!((slave.real(Y) - 0.4).abs() < 1e-12);
    assert!((slave.real(Z) - 2.5 * 0.4).abs() < 1e-12);
}

#[test]
fn a_forged_cache_is_rebuilt_from_the_parameters() {
    let slave = Slave::initialized();
    assert_eq!(slave.step(0.0, 0.1), OK);
    let bytes = slave.serialize(slave.get_state());
    // gain_twice = 2.5 replaced by 7: still finite, and no variable of the
    // table; the model derives it again from gain.
    let forged = forge(&bytes, 2.5, 7.0);
    let other = Slave::initialized();
    let (status, state) = other.deserialize(&forged);
    assert_eq!(status, OK);
    assert_eq!(other.set_state(state), OK);
    assert!((other.real(Z) - 2.5 * 0.2).abs() < 1e-12);
}

/// Before initialization the importer may still be setting parameters: a
/// state taken then may hold one outside its range, and restores;
/// fmi2ExitInitializationMode refuses it as it would have.
#[test]
fn ranges_are_not_enforced_on_a_state_taken_before_initialization() {
    let slave = Slave::instantiate();
    assert_eq!(slave.set_real(GAIN, 20.0), OK);
    let bytes = slave.serialize(slave.get_state());
    let other = Slave::instantiate();
    let (status, state) = other.deserialize(&bytes);
    assert_eq!(status, OK);
    assert_eq!(other.set_state(state), OK);
    // SAFETY: `other.0` is live.
    unsafe {
        assert_eq!(abi::enter_initialization_mode::<Stepper>(other.0), OK);
        assert_eq!(abi::exit_initialization_mode::<Stepper>(other.0), ERROR);
    }
}

/// The gate turns (pointer, length) into a slice only when it can be one: a
/// misaligned array is refused with fmi2Error instead of being read.
#[test]
fn a_misaligned_array_is_refused_at_the_gate() {
    let slave = Slave::initialized();
    let storage = [0u64; 3];
    // One byte into an 8-aligned buffer: misaligned for u32 and f64.
    let misaligned = storage.as_ptr().cast::<u8>().wrapping_add(1);
    let mut value = 0.0;
    // SAFETY: the layer checks the alignment before it reads `vr`, and
    // refuses; `value` is a local.
    let status =
        unsafe { abi::get_real::<Stepper>(slave.0, misaligned.cast::<u32>(), 1, &mut value) };
    assert_eq!(status, ERROR);
    // Refused without a read: the instance is in its error state, values
    // intact, and recovers through a reset.
    assert!((slave.real(Y) - 0.0).abs() < 1e-15);
    // SAFETY: `slave.0` is live.
    let status = unsafe { abi::reset::<Stepper>(slave.0) };
    assert_eq!(status, OK);
}

/// A tunable parameter is checked against its declared range when it is set
/// while running (nothing checks it later): a value outside is refused and
/// changes nothing, one inside is taken, and a state holding it restores.
#[test]
fn a_tunable_parameter_is_held_in_its_range_while_running() {
    let slave = Slave::initialized();
    assert_eq!(slave.set_mode(7), ERROR);
    assert_eq!(slave.step(0.0, 0.1), ERROR, "the refusal is an error");
    let slave = Slave::initialized();
    assert_eq!(slave.set_mode(DISCARD_HALFWAY), OK);
    assert_eq!(slave.step(0.0, 0.1), DISCARD);
    let bytes = slave.serialize(slave.get_state());
    let other = Slave::initialized();
    let (status, state) = other.deserialize(&bytes);
    assert_eq!(status, OK);
    assert_eq!(other.set_state(state), OK);
    assert_eq!(other.last_successful_time(), (OK, 0.05));
}

/// The call that carries a loop's inputs between steps takes a short path
/// (`Instance::set_values`): what it accepts and refuses is the full rule's.
/// Several inputs in one call are taken (the last of one reference wins);
/// a call with one value that is not a valid input value (NaN, an output,
/// an unknown reference, a fixed parameter) is refused whole and leaves the
/// input as it was.
#[test]
fn inputs_between_steps_are_taken_whole_or_refused_whole() {
    let set = |slave: &Slave, vrs: &[u32], values: &[f64]| {
        // SAFETY: both arrays hold `vrs.len()` elements.
        unsafe { abi::set_real::<Stepper>(slave.0, vrs.as_ptr(), vrs.len(), values.as_ptr()) }
    };
    let slave = Slave::initialized();
    assert_eq!(slave.step(0.0, 0.1), OK);
    assert_eq!(set(&slave, &[U, U], &[3.0, 4.0]), OK);
    assert_eq!(slave.real(U), 4.0);
    assert_eq!(slave.step(0.1, 0.1), OK);
    assert!(
        (slave.real(Y) - (0.2 + 0.4)).abs() < 1e-12,
        "{}",
        slave.real(Y)
    );
    for (vrs, values) in [
        (&[U, U][..], &[5.0, f64::NAN][..]),
        (&[U, Y], &[5.0, 1.0]),
        (&[U, 99], &[5.0, 1.0]),
        (&[U, GAIN], &[5.0, 2.0]),
    ] {
        let slave = Slave::initialized();
        assert_eq!(slave.step(0.0, 0.1), OK);
        assert_eq!(set(&slave, vrs, values), ERROR, "{vrs:?}");
        assert_eq!(slave.real(U), 2.0, "{vrs:?}: the input is unchanged");
    }
}

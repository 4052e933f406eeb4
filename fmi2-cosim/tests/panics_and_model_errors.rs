//! A model that panics or fails on demand, driven through the generic C entry
//! points: no panic crosses the C boundary, and a failing model puts the
//! instance in its error state until fmi2Reset.

mod common;

use common::{ERROR, OK, Slave};
use fmi2_cosim::fmi_sys::fmi2 as sys;
use fmi2_cosim::{
    BaseUnit, CoSimModel, Context, DefaultExperiment, ModelError, ModelInfo, StepOutcome,
    UnitDefinition, Variability, Variable,
};
use serde::{Deserialize, Serialize};

#[derive(Clone, Serialize, Deserialize)]
struct Faulty {
    input: f64,
    output: f64,
    /// 1: panic in doStep; 2: fail in doStep; 3: fail at initialization.
    mode: i32,
}

static VARIABLES: &[Variable<Faulty>] = &[
    Variable::real_input("u", "input", "1", |m| m.input, |m, v| m.input = v),
    Variable::real_output("y", "output", "1", |m| m.output),
    Variable::integer_parameter(
        "mode",
        "fault to inject",
        Variability::Tunable,
        |m| m.mode,
        |m, v| m.mode = v,
    ),
    Variable::independent("time", "the simulation time", "s"),
];

impl CoSimModel for Faulty {
    const INFO: ModelInfo = ModelInfo {
        model_identifier: "Faulty",
        model_name: "Faulty",
        description: "fails on demand",
        author: "tests",
        version: "0",
        license: "MIT",
        default_experiment: DefaultExperiment {
            start_time: 0.0,
            stop_time: 1.0,
            step_size: 0.1,
        },
    };
    const UNITS: &'static [UnitDefinition] = &[
        UnitDefinition {
            name: "1",
            base: BaseUnit::NONE,
            display_units: &[],
        },
        UnitDefinition {
            name: "s",
            base: BaseUnit {
                s: 1,
                ..BaseUnit::NONE
            },
            display_units: &[],
        },
    ];

    fn variables() -> &'static [Variable<Self>] {
        VARIABLES
    }

    fn new() -> Self {
        Faulty {
            input: 0.0,
            output: 0.0,
            mode: 0,
        }
    }

    fn exit_initialization_mode(&mut self, _: &mut Context<'_>, _: f64) -> Result<(), ModelError> {
        if self.mode == 3 {
            return Err(ModelError("refusing to initialize".into()));
        }
        Ok(())
    }

    fn do_step(&mut self, _: &mut Context<'_>, _: f64, h: f64) -> Result<StepOutcome, ModelError> {
        match self.mode {
            1 => panic!("model bug"),
            2 => Err(ModelError("diverged".into())),
            _ => {
                self.output += self.input * h;
                Ok(StepOutcome::Completed)
            }
        }
    }
}

/// An instance of `Faulty` behaving as `mode` says (see `Faulty::mode`).
fn instance(mode: i32) -> Slave<Faulty> {
    let inst = Slave::instantiate();
    assert_eq!(inst.set_integer(2, mode), OK);
    inst
}

/// fmi2SetupExperiment, fmi2EnterInitializationMode, and the status of
/// fmi2ExitInitializationMode.
fn initialize(inst: &Slave<Faulty>) -> sys::fmi2Status {
    inst.setup_and_enter(0.0);
    inst.exit_initialization()
}

#[test]
fn a_panic_in_the_model_returns_error_instead_of_unwinding_into_c() {
    let inst = instance(1);
    assert_eq!(initialize(&inst), OK);
    assert_eq!(inst.step(0.0, 0.1), ERROR);
    // The instance is in its error state: stepping stays refused...
    assert_eq!(inst.step(0.0, 0.1), ERROR);
    // ...getters still answer, and fmi2Reset recovers.
    let (status, _) = inst.get_real(1);
    assert_eq!(status, OK);
    assert_eq!(inst.reset(), OK);
    assert_eq!(initialize(&inst), OK);
    assert_eq!(inst.step(0.0, 0.1), OK);
}

/// A step that fails, by a panic or an error, leaves the instance at the
/// time it started from (the layer advances the time before the model's
/// step and puts it back when the step does not complete).
#[test]
fn a_failed_step_leaves_the_time_where_the_step_started() {
    for mode in [1, 2] {
        let inst = instance(0);
        assert_eq!(initialize(&inst), OK);
        for k in 0..3 {
            assert_eq!(inst.step(k as f64 * 0.1, 0.1), OK);
        }
        let start = 3.0 * 0.1;
        assert_eq!(inst.get_real(3), (OK, start), "mode {mode}");
        assert_eq!(inst.set_integer(2, mode), OK);
        assert_eq!(inst.step(start, 0.1), ERROR, "mode {mode}");
        assert_eq!(inst.get_real(3), (OK, start), "mode {mode}");
    }
}

#[test]
fn a_failing_step_enters_the_error_state() {
    let inst = instance(2);
    assert_eq!(initialize(&inst), OK);
    assert_eq!(inst.step(0.0, 0.1), ERROR);
    assert_eq!(inst.terminate(), ERROR);
}

#[test]
fn a_refused_initialization_enters_the_error_state() {
    let inst = instance(3);
    assert_eq!(initialize(&inst), ERROR);
    assert_eq!(inst.step(0.0, 0.1), ERROR);
    assert_eq!(inst.reset(), OK);
}

#[test]
fn a_healthy_model_integrates() {
    let inst = instance(0);
    assert_eq!(inst.set_real(0, 2.0), OK);
    assert_eq!(initialize(&inst), OK);
    for k in 0..10 {
        assert_eq!(inst.step(k as f64 * 0.1, 0.1), OK);
    }
    let (status, y) = inst.get_real(1);
    assert_eq!(status, OK);
    assert!((y - 2.0).abs() < 1e-12, "y = {y}");
}

/// Sets up an experiment from `start` (to `stop`, if given) and initializes.
fn initialize_from(inst: &Slave<Faulty>, start: f64, stop: Option<f64>) {
    // SAFETY: `inst.0` is a live instance of Faulty.
    unsafe {
        assert_eq!(
            fmi2_cosim::abi::setup_experiment::<Faulty>(
                inst.0,
                0,
                0.0,
                start,
                stop.is_some() as i32,
                stop.unwrap_or(0.0),
            ),
            OK
        );
        assert_eq!(
            fmi2_cosim::abi::enter_initialization_mode::<Faulty>(inst.0),
            OK
        );
    }
    assert_eq!(inst.exit_initialization(), OK);
}

/// A co-simulation step past the stopTime fmi2SetupExperiment defined is
/// refused with fmi2Error (FMI 2.0.4 §2.1.6); communication points summed
/// step by step, which round past it, reach it; fmi2Reset forgets it.
#[test]
fn a_step_past_the_defined_stop_time_is_an_error() {
    let setup = |inst: &Slave<Faulty>, stop: Option<f64>| initialize_from(inst, 0.0, stop);
    let inst = instance(0);
    setup(&inst, Some(0.3));
    // Three steps of 0.1 sum to 0.30000000000000004, past 0.3 by rounding
    // only: each is taken.
    let mut t = 0.0;
    for _ in 0..3 {
        assert_eq!(inst.step(t, 0.1), OK, "t = {t}");
        t += 0.1;
    }
    assert!(t > 0.3, "the sum rounds past the stop: {t}");
    assert_eq!(inst.step(t, 0.1), ERROR, "a step past stopTime");
    assert_eq!(inst.reset(), OK);
    setup(&inst, None);
    for k in 0..20 {
        assert_eq!(inst.step(k as f64 * 0.1, 0.1), OK);
    }
    assert_eq!(inst.reset(), OK);
    setup(&inst, Some(0.05));
    assert_eq!(inst.step(0.0, 0.1), ERROR, "a first step past stopTime");
}

/// A state carries no stop time: a run continued from a finished run's
/// state, in another instance or in the same one set up again, steps up to
/// its own stopTime, or without one when it defined none.
#[test]
fn a_restored_state_keeps_the_receiving_instances_stop_time() {
    let setup = initialize_from;
    let first = instance(0);
    setup(&first, 0.0, Some(0.2));
    assert_eq!(first.step(0.0, 0.1), OK);
    assert_eq!(first.step(0.1, 0.1), OK);
    let finished = first.get_state();
    let bytes = first.serialize(finished);
    for stop in [Some(0.4), None] {
        let next = instance(0);
        setup(&next, 0.2, stop);
        let (status, state) = next.deserialize(&bytes);
        assert_eq!(status, OK);
        assert_eq!(next.set_state(state), OK);
        assert_eq!(next.step(0.2, 0.1), OK, "stop {stop:?}");
        assert_eq!(next.step(0.3, 0.1), OK, "stop {stop:?}");
        let past = next.step(0.4, 0.1);
        assert_eq!(
            past,
            if stop.is_some() { ERROR } else { OK },
            "stop {stop:?}"
        );
    }
    // Its own earlier state does not bring an instance's earlier stop back.
    assert_eq!(first.reset(), OK);
    setup(&first, 0.2, Some(0.4));
    assert_eq!(first.set_state(finished), OK);
    assert_eq!(
        first.step(0.2, 0.1),
        OK,
        "within the stop set up after the state was taken"
    );
}

//! A model that panics or fails on demand, driven through the generic C entry
//! points: no panic crosses the C boundary, and a failing model puts the
//! instance in its error state until fmi2Reset.

use std::ffi::CString;
use std::ptr;

use fmi2_cosim::abi;
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
    const UNITS: &'static [UnitDefinition] = &[UnitDefinition {
        name: "1",
        base: BaseUnit::NONE,
        display_units: &[],
    }];

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

const OK: sys::fmi2Status = sys::fmi2Status_fmi2OK;
const ERROR: sys::fmi2Status = sys::fmi2Status_fmi2Error;

struct Instance(sys::fmi2Component);

impl Instance {
    fn new(mode: i32) -> Instance {
        let callbacks = sys::fmi2CallbackFunctions {
            logger: None,
            allocateMemory: None,
            freeMemory: None,
            stepFinished: None,
            componentEnvironment: ptr::null_mut(),
        };
        let guid = CString::new(fmi2_cosim::model_description::guid::<Faulty>().unwrap()).unwrap();
        // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
        // freed; the other pointers are to locals that outlive the call, with the lengths
        // passed.
        let c = unsafe {
            abi::instantiate::<Faulty>(
                c"faulty".as_ptr(),
                sys::fmi2Type_fmi2CoSimulation,
                guid.as_ptr(),
                ptr::null(),
                &callbacks,
                0,
                0,
            )
        };
        assert!(!c.is_null());
        let instance = Instance(c);
        // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
        // freed; the other pointers are to locals that outlive the call, with the lengths
        // passed.
        assert_eq!(unsafe { abi::set_integer::<Faulty>(c, &2, 1, &mode) }, OK);
        instance
    }

    fn initialize(&self) -> sys::fmi2Status {
        // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
        // freed; the other pointers are to locals that outlive the call, with the lengths
        // passed.
        unsafe {
            assert_eq!(
                abi::setup_experiment::<Faulty>(self.0, 0, 0.0, 0.0, 0, 0.0),
                OK
            );
            assert_eq!(abi::enter_initialization_mode::<Faulty>(self.0), OK);
            abi::exit_initialization_mode::<Faulty>(self.0)
        }
    }

    fn step(&self, t: f64) -> sys::fmi2Status {
        // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
        // freed; the other pointers are to locals that outlive the call, with the lengths
        // passed.
        unsafe { abi::do_step::<Faulty>(self.0, t, 0.1, 1) }
    }
}

impl Drop for Instance {
    fn drop(&mut self) {
        // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
        // freed; the other pointers are to locals that outlive the call, with the lengths
        // passed.
        unsafe { abi::free_instance::<Faulty>(self.0) };
    }
}

#[test]
fn a_panic_in_the_model_returns_error_instead_of_unwinding_into_c() {
    let inst = Instance::new(1);
    assert_eq!(inst.initialize(), OK);
    assert_eq!(inst.step(0.0), ERROR);
    // The instance is in its error state: stepping stays refused...
    assert_eq!(inst.step(0.0), ERROR);
    // ...getters still answer, and fmi2Reset recovers.
    let mut y = f64::NAN;
    // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
    // freed; the other pointers are to locals that outlive the call, with the lengths passed.
    let status = unsafe { abi::get_real::<Faulty>(inst.0, &1, 1, &mut y) };
    assert_eq!(status, OK);
    // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
    // freed; the other pointers are to locals that outlive the call, with the lengths passed.
    assert_eq!(unsafe { abi::reset::<Faulty>(inst.0) }, OK);
    assert_eq!(inst.initialize(), OK);
    assert_eq!(inst.step(0.0), OK);
}

#[test]
fn a_failing_step_enters_the_error_state() {
    let inst = Instance::new(2);
    assert_eq!(inst.initialize(), OK);
    assert_eq!(inst.step(0.0), ERROR);
    // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
    // freed; the other pointers are to locals that outlive the call, with the lengths passed.
    assert_eq!(unsafe { abi::terminate::<Faulty>(inst.0) }, ERROR);
}

#[test]
fn a_refused_initialization_enters_the_error_state() {
    let inst = Instance::new(3);
    assert_eq!(inst.initialize(), ERROR);
    assert_eq!(inst.step(0.0), ERROR);
    // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
    // freed; the other pointers are to locals that outlive the call, with the lengths passed.
    assert_eq!(unsafe { abi::reset::<Faulty>(inst.0) }, OK);
}

#[test]
fn a_healthy_model_integrates() {
    let inst = Instance::new(0);
    // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
    // freed; the other pointers are to locals that outlive the call, with the lengths passed.
    assert_eq!(unsafe { abi::set_real::<Faulty>(inst.0, &0, 1, &2.0) }, OK);
    assert_eq!(inst.initialize(), OK);
    for k in 0..10 {
        assert_eq!(inst.step(k as f64 * 0.1), OK);
    }
    let mut y = 0.0;
    // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
    // freed; the other pointers are to locals that outlive the call, with the lengths passed.
    let status = unsafe { abi::get_real::<Faulty>(inst.0, &1, 1, &mut y) };
    assert_eq!(status, OK);
    assert!((y - 2.0).abs() < 1e-12, "y = {y}");
}

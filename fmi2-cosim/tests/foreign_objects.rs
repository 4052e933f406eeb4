//! Two models built with this layer in one process, as two FMUs loaded by one
//! importer: an instance or FMU state of one, passed to the other's entry
//! points by mistake, is refused and left untouched. Both models have the same
//! memory layout, so only the model-specific magic number tells them apart.
//! The same integrator model, which survives any step size, also shows the
//! layer's own refusal of a step that ends beyond the largest time, and that
//! fmi2FreeInstance frees the FMU states the importer left to it.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::ffi::CString;
use std::ptr;

use fmi2_cosim::abi;
use fmi2_cosim::fmi_sys::fmi2 as sys;
use fmi2_cosim::{
    BaseUnit, CoSimModel, Context, DefaultExperiment, ModelError, ModelInfo, StepOutcome,
    UnitDefinition, Variable,
};
use serde::{Deserialize, Serialize};

/// Counts the heap bytes each thread holds, so that a test can see what a
/// sequence of calls leaves allocated (tests run in parallel threads).
struct CountingAllocator;

thread_local! {
    static LIVE_BYTES: Cell<isize> = const { Cell::new(0) };
}

// SAFETY: allocation is delegated unchanged to `System`; the counting has no effect on the
// memory returned.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: `layout` comes from the caller of `alloc`, under GlobalAlloc's contract,
        // passed on unchanged.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            let _ = LIVE_BYTES.try_with(|n| n.set(n.get() + layout.size() as isize));
        }
        p
    }

    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        // SAFETY: `p` was allocated by `System` with `layout` (every allocation goes through
        // `alloc` above).
        unsafe { System.dealloc(p, layout) };
        let _ = LIVE_BYTES.try_with(|n| n.set(n.get() - layout.size() as isize));
    }
}

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

const OK: sys::fmi2Status = sys::fmi2Status_fmi2OK;
const ERROR: sys::fmi2Status = sys::fmi2Status_fmi2Error;

const UNITS: &[UnitDefinition] = &[UnitDefinition {
    name: "1",
    base: BaseUnit::NONE,
    display_units: &[],
}];

/// A model `y' = u` under the identifier `$id`.
macro_rules! integrator_model {
    ($model:ident, $id:literal) => {
        #[derive(Clone, Serialize, Deserialize)]
        struct $model {
            u: f64,
            y: f64,
        }

        impl CoSimModel for $model {
            const INFO: ModelInfo = ModelInfo {
                model_identifier: $id,
                model_name: $id,
                description: "integrator",
                author: "tests",
                version: "0",
                license: "MIT",
                default_experiment: DefaultExperiment {
                    start_time: 0.0,
                    stop_time: 1.0,
                    step_size: 0.1,
                },
            };
            const UNITS: &'static [UnitDefinition] = UNITS;

            fn variables() -> &'static [Variable<Self>] {
                static VARIABLES: [Variable<$model>; 2] = [
                    Variable::real_input("u", "input", "1", |m| m.u, |m, v| m.u = v),
                    Variable::real_output("y", "output", "1", |m| m.y),
                ];
                &VARIABLES
            }

            fn new() -> Self {
                $model { u: 0.0, y: 0.0 }
            }

            fn exit_initialization_mode(
                &mut self,
                _: &mut Context<'_>,
                _: f64,
            ) -> Result<(), ModelError> {
                Ok(())
            }

            fn do_step(
                &mut self,
                _: &mut Context<'_>,
                _: f64,
                h: f64,
            ) -> Result<StepOutcome, ModelError> {
                self.y += self.u * h;
                Ok(StepOutcome::Completed)
            }
        }
    };
}

integrator_model!(Left, "Left");
integrator_model!(Right, "Right");

/// An initialized instance of `M` with input `u`.
fn instance<M: CoSimModel>(u: f64) -> sys::fmi2Component {
    let callbacks = sys::fmi2CallbackFunctions {
        logger: None,
        allocateMemory: None,
        freeMemory: None,
        stepFinished: None,
        componentEnvironment: ptr::null_mut(),
    };
    let guid = CString::new(fmi2_cosim::model_description::guid::<M>().unwrap()).unwrap();
    // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
    // freed; the other pointers are to locals that outlive the call, with the lengths passed.
    unsafe {
        let c = abi::instantiate::<M>(
            c"instance".as_ptr(),
            sys::fmi2Type_fmi2CoSimulation,
            guid.as_ptr(),
            ptr::null(),
            &callbacks,
            0,
            0,
        );
        assert!(!c.is_null());
        assert_eq!(abi::set_real::<M>(c, &0, 1, &u), OK);
        assert_eq!(abi::setup_experiment::<M>(c, 0, 0.0, 0.0, 0, 0.0), OK);
        assert_eq!(abi::enter_initialization_mode::<M>(c), OK);
        assert_eq!(abi::exit_initialization_mode::<M>(c), OK);
        c
    }
}

fn output<M: CoSimModel>(c: sys::fmi2Component) -> f64 {
    let mut y = f64::NAN;
    // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
    // freed; the other pointers are to locals that outlive the call, with the lengths passed.
    assert_eq!(unsafe { abi::get_real::<M>(c, &1, 1, &mut y) }, OK);
    y
}

#[test]
fn another_models_instance_is_refused_and_left_untouched() {
    let left = instance::<Left>(1.0);
    let right = instance::<Right>(2.0);
    // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
    // freed; the other pointers are to locals that outlive the call, with the lengths passed.
    unsafe {
        // Every kind of access through Left's entry points.
        assert_eq!(abi::set_real::<Left>(right, &0, 1, &5.0), ERROR);
        let mut y = 0.0;
        assert_eq!(abi::get_real::<Left>(right, &1, 1, &mut y), ERROR);
        assert_eq!(abi::do_step::<Left>(right, 0.0, 0.1, 1), ERROR);
        assert_eq!(abi::terminate::<Left>(right), ERROR);
        assert_eq!(abi::reset::<Left>(right), ERROR);
        abi::free_instance::<Left>(right);
        // Right is still itself: its input, its state machine, its memory.
        assert_eq!(abi::do_step::<Right>(right, 0.0, 0.1, 1), OK);
        assert_eq!(output::<Right>(right), 2.0 * 0.1);
        assert_eq!(abi::do_step::<Left>(left, 0.0, 0.1, 1), OK);
        assert_eq!(output::<Left>(left), 0.1);
        abi::free_instance::<Right>(right);
        abi::free_instance::<Left>(left);
    }
}

#[test]
fn another_models_fmu_state_is_refused_and_left_untouched() {
    let left = instance::<Left>(1.0);
    let right = instance::<Right>(2.0);
    // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
    // freed; the other pointers are to locals that outlive the call, with the lengths passed.
    unsafe {
        let mut right_state: sys::fmi2FMUstate = ptr::null_mut();
        assert_eq!(abi::get_fmu_state::<Right>(right, &mut right_state), OK);
        assert_eq!(abi::set_fmu_state::<Left>(left, right_state), ERROR);
        assert_eq!(abi::reset::<Left>(left), OK);
        let mut size = 0;
        assert_eq!(
            abi::serialized_fmu_state_size::<Left>(left, right_state, &mut size),
            ERROR
        );
        assert_eq!(abi::reset::<Left>(left), OK);
        // Taking a state into Right's state would overwrite it as Left's.
        let mut slot = right_state;
        assert_eq!(abi::get_fmu_state::<Left>(left, &mut slot), ERROR);
        assert_eq!(slot, right_state);
        assert_eq!(abi::reset::<Left>(left), OK);
        // Freeing it through Left would free it with Left's layout.
        assert_eq!(abi::free_fmu_state::<Left>(left, &mut slot), ERROR);
        assert_eq!(slot, right_state, "a refused free changed the pointer");
        // Right's state still restores Right.
        assert_eq!(abi::do_step::<Right>(right, 0.0, 0.1, 1), OK);
        assert_eq!(abi::set_fmu_state::<Right>(right, right_state), OK);
        assert_eq!(output::<Right>(right), 0.0);
        assert_eq!(abi::free_fmu_state::<Right>(right, &mut right_state), OK);
        abi::free_instance::<Right>(right);
        abi::free_instance::<Left>(left);
    }
}

/// fmi2Instantiate checks the GUID from a per-process cache: each model gets
/// its own, equal to a fresh computation.
#[test]
fn cached_guids_are_per_model() {
    use fmi2_cosim::model_description::{cached_guid, guid};
    for _ in 0..2 {
        assert_eq!(cached_guid(&Left::new()).unwrap(), guid::<Left>().unwrap());
        assert_eq!(
            cached_guid(&Right::new()).unwrap(),
            guid::<Right>().unwrap()
        );
    }
    assert_ne!(guid::<Left>().unwrap(), guid::<Right>().unwrap());
}

/// A step whose end time overflows is refused: the FMU's time would become
/// infinite and no communication point could follow it.
#[test]
fn a_step_ending_beyond_the_largest_time_is_refused() {
    let callbacks = sys::fmi2CallbackFunctions {
        logger: None,
        allocateMemory: None,
        freeMemory: None,
        stepFinished: None,
        componentEnvironment: ptr::null_mut(),
    };
    let guid = CString::new(fmi2_cosim::model_description::guid::<Left>().unwrap()).unwrap();
    // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
    // freed; the other pointers are to locals that outlive the call, with the lengths passed.
    unsafe {
        let c = abi::instantiate::<Left>(
            c"late".as_ptr(),
            sys::fmi2Type_fmi2CoSimulation,
            guid.as_ptr(),
            ptr::null(),
            &callbacks,
            0,
            0,
        );
        assert_eq!(abi::setup_experiment::<Left>(c, 0, 0.0, 1e300, 0, 0.0), OK);
        assert_eq!(abi::enter_initialization_mode::<Left>(c), OK);
        assert_eq!(abi::exit_initialization_mode::<Left>(c), OK);
        assert_eq!(abi::do_step::<Left>(c, 1e300, f64::MAX, 1), ERROR);
        let mut time = f64::NAN;
        assert_eq!(
            abi::get_real_status::<Left>(c, sys::fmi2StatusKind_fmi2LastSuccessfulTime, &mut time),
            ERROR,
            "the instance is in its error state"
        );
        assert_eq!(abi::reset::<Left>(c), OK);
        abi::free_instance::<Left>(c);
    }
}

/// FMU states the importer did not free are freed with the instance that made
/// them (FMI 2.0.4 §2.1.5), also when another instance freed some of them or
/// restored them; none is freed twice.
#[test]
fn free_instance_frees_the_fmu_states_left_to_it() {
    let live = || LIVE_BYTES.with(Cell::get);
    // The first instantiation fills the process-wide GUID table.
    // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
    // freed; the other pointers are to locals that outlive the call, with the lengths passed.
    unsafe { abi::free_instance::<Left>(instance::<Left>(1.0)) };
    let before = live();
    // SAFETY: the instance pointer comes from `abi::instantiate` and is live until it is
    // freed; the other pointers are to locals that outlive the call, with the lengths passed.
    unsafe {
        let first = instance::<Left>(1.0);
        let second = instance::<Left>(2.0);
        let mut states = [ptr::null_mut(); 4];
        for state in &mut states {
            assert_eq!(abi::get_fmu_state::<Left>(first, state), OK);
        }
        let mut size = 0;
        assert_eq!(
            abi::serialized_fmu_state_size::<Left>(first, states[1], &mut size),
            OK
        );
        // One freed by its maker, one by the other instance, one restored
        // into the other instance; two left to fmi2FreeInstance.
        assert_eq!(abi::free_fmu_state::<Left>(first, &mut states[0]), OK);
        assert_eq!(abi::free_fmu_state::<Left>(second, &mut states[2]), OK);
        assert_eq!(abi::set_fmu_state::<Left>(second, states[3]), OK);
        let mut own = ptr::null_mut();
        assert_eq!(abi::get_fmu_state::<Left>(second, &mut own), OK);
        abi::free_instance::<Left>(first);
        abi::free_instance::<Left>(second);
    }
    assert_eq!(
        live(),
        before,
        "heap bytes left after freeing both instances"
    );
}

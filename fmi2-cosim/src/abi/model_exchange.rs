//! The FMI 2.0 Model Exchange entry points, generic over a model that
//! implements [`ModelExchange`]. Each one goes through the same gate as the
//! common and co-simulation functions (`super::call`: instance identity, state
//! machine and interface, panic barrier, error state) and refuses a NULL array
//! with a non-zero length or a length that is not the model's.

use fmi_sys::fmi2 as sys;

use std::mem::MaybeUninit;

use super::{call, slice_in, slice_out, value_out};
use crate::Instance;
use crate::model_exchange::ModelExchange;
use crate::status::{FmiFunction, Status};

/// An output vector of the importer, zeroed so that the model can be handed
/// a plain `&mut [f64]` (what it does not write reads as 0, never as
/// uninitialized memory).
fn zeroed(out: &mut [MaybeUninit<f64>]) -> &mut [f64] {
    for x in out.iter_mut() {
        x.write(0.0);
    }
    // SAFETY: every element was just written; `MaybeUninit<f64>` has the
    // layout of `f64`, so the slice is one of initialized `f64`s with the
    // same length and lifetime.
    unsafe { &mut *(out as *mut [MaybeUninit<f64>] as *mut [f64]) }
}

fn to_c(b: bool) -> sys::fmi2Boolean {
    if b {
        sys::fmi2True as _
    } else {
        sys::fmi2False as _
    }
}

/// # Safety
/// `c` as for every FMI function.
pub unsafe fn enter_event_mode<M: ModelExchange>(c: sys::fmi2Component) -> sys::fmi2Status {
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe {
        call::<M, _, _>(
            c,
            FmiFunction::EnterEventMode,
            |_| Ok(()),
            |inst| inst.enter_event_mode(),
        )
    }
}

/// # Safety
/// Arguments as `fmi2NewDiscreteStates`.
pub unsafe fn new_discrete_states<M: ModelExchange>(
    c: sys::fmi2Component,
    event_info: *mut sys::fmi2EventInfo,
) -> sys::fmi2Status {
    let function = FmiFunction::NewDiscreteStates;
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `event_info` is the importer's output struct when non-NULL
        // (this function's contract).
        let out = match unsafe { value_out(inst, function, event_info, "fmi2eventInfo") } {
            Ok(out) => out,
            Err(status) => return status,
        };
        match inst.new_discrete_states() {
            Ok(info) => {
                let update = info.update;
                out.write(sys::fmi2EventInfo {
                    newDiscreteStatesNeeded: to_c(info.new_discrete_states_needed),
                    terminateSimulation: to_c(update.terminate_simulation),
                    nominalsOfContinuousStatesChanged: to_c(update.nominals_changed),
                    valuesOfContinuousStatesChanged: to_c(update.values_changed),
                    nextEventTimeDefined: to_c(update.next_event_time.is_some()),
                    nextEventTime: update.next_event_time.unwrap_or(0.0),
                });
                Status::Ok
            }
            Err(status) => status,
        }
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe {
        call::<M, _, _>(
            c,
            function,
            |f| write!(f, "fmi2eventInfo = {event_info:?}"),
            body,
        )
    }
}

/// # Safety
/// `c` as for every FMI function.
pub unsafe fn enter_continuous_time_mode<M: ModelExchange>(
    c: sys::fmi2Component,
) -> sys::fmi2Status {
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe {
        call::<M, _, _>(
            c,
            FmiFunction::EnterContinuousTimeMode,
            |_| Ok(()),
            |inst| inst.enter_continuous_time_mode(),
        )
    }
}

/// # Safety
/// Arguments as `fmi2CompletedIntegratorStep`.
pub unsafe fn completed_integrator_step<M: ModelExchange>(
    c: sys::fmi2Component,
    _no_set_fmu_state_prior_to_current_point: sys::fmi2Boolean,
    enter_event_mode: *mut sys::fmi2Boolean,
    terminate_simulation: *mut sys::fmi2Boolean,
) -> sys::fmi2Status {
    let function = FmiFunction::CompletedIntegratorStep;
    let body = |inst: &mut Instance<M>| {
        // SAFETY: both are the importer's output variables when non-NULL
        // (this function's contract).
        let flags = unsafe {
            (
                value_out(inst, function, enter_event_mode, "enterEventMode"),
                value_out(inst, function, terminate_simulation, "terminateSimulation"),
            )
        };
        let (enter_event_mode, terminate_simulation) = match flags {
            (Ok(enter), Ok(terminate)) => (enter, terminate),
            (Err(status), _) | (_, Err(status)) => return status,
        };
        let status = inst.completed_integrator_step();
        if status <= Status::Warning {
            // No step events: the model has nothing to do between steps
            // that an event would serve.
            enter_event_mode.write(sys::fmi2False as _);
            terminate_simulation.write(sys::fmi2False as _);
        }
        status
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, function, |_| Ok(()), body) }
}

/// # Safety
/// `c` as for every FMI function.
pub unsafe fn set_time<M: ModelExchange>(
    c: sys::fmi2Component,
    time: sys::fmi2Real,
) -> sys::fmi2Status {
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe {
        call::<M, _, _>(
            c,
            FmiFunction::SetTime,
            |f| write!(f, "time = {time}"),
            |inst| inst.set_time(time),
        )
    }
}

/// # Safety
/// Arguments as `fmi2SetContinuousStates`.
pub unsafe fn set_continuous_states<M: ModelExchange>(
    c: sys::fmi2Component,
    x: *const sys::fmi2Real,
    nx: usize,
) -> sys::fmi2Status {
    let function = FmiFunction::SetContinuousStates;
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `x` points to `nx` values when non-NULL (this function's
        // contract).
        match unsafe { slice_in(inst, function, x, nx, "x") } {
            Ok(states) => inst.set_continuous_states(states),
            Err(status) => status,
        }
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, function, |f| write!(f, "nx = {nx}"), body) }
}

/// # Safety
/// Arguments as `fmi2GetContinuousStates`.
pub unsafe fn get_continuous_states<M: ModelExchange>(
    c: sys::fmi2Component,
    x: *mut sys::fmi2Real,
    nx: usize,
) -> sys::fmi2Status {
    let function = FmiFunction::GetContinuousStates;
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `x` points to `nx` writable values when non-NULL (this
        // function's contract).
        match unsafe { slice_out(inst, function, x, nx, "x") } {
            Ok(out) => inst.get_continuous_states(zeroed(out)),
            Err(status) => status,
        }
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, function, |f| write!(f, "nx = {nx}"), body) }
}

/// # Safety
/// Arguments as `fmi2GetDerivatives`.
pub unsafe fn get_derivatives<M: ModelExchange>(
    c: sys::fmi2Component,
    derivatives: *mut sys::fmi2Real,
    nx: usize,
) -> sys::fmi2Status {
    let function = FmiFunction::GetDerivatives;
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `derivatives` points to `nx` writable values when non-NULL (this
        // function's contract).
        match unsafe { slice_out(inst, function, derivatives, nx, "derivatives") } {
            Ok(out) => inst.get_derivatives(zeroed(out)),
            Err(status) => status,
        }
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, function, |f| write!(f, "nx = {nx}"), body) }
}

/// # Safety
/// Arguments as `fmi2GetEventIndicators`.
pub unsafe fn get_event_indicators<M: ModelExchange>(
    c: sys::fmi2Component,
    indicators: *mut sys::fmi2Real,
    ni: usize,
) -> sys::fmi2Status {
    let function = FmiFunction::GetEventIndicators;
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `indicators` points to `ni` writable values when non-NULL (this
        // function's contract).
        match unsafe { slice_out(inst, function, indicators, ni, "eventIndicators") } {
            Ok(out) => inst.get_event_indicators(zeroed(out)),
            Err(status) => status,
        }
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, function, |f| write!(f, "ni = {ni}"), body) }
}

/// # Safety
/// Arguments as `fmi2GetNominalsOfContinuousStates`.
pub unsafe fn get_nominals_of_continuous_states<M: ModelExchange>(
    c: sys::fmi2Component,
    nominals: *mut sys::fmi2Real,
    nx: usize,
) -> sys::fmi2Status {
    let function = FmiFunction::GetNominalsOfContinuousStates;
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `nominals` points to `nx` writable values when non-NULL (this
        // function's contract).
        match unsafe { slice_out(inst, function, nominals, nx, "x_nominal") } {
            Ok(out) => inst.get_nominals(zeroed(out)),
            Err(status) => status,
        }
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, function, |f| write!(f, "nx = {nx}"), body) }
}

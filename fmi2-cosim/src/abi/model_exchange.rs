//! The FMI 2.0 Model Exchange entry points, generic over a model that
//! implements [`ModelExchange`]. Each one goes through the same gate as the
//! common and co-simulation functions (`super::call`: instance identity, state
//! machine and interface, panic barrier, error state) and refuses a NULL array
//! with a non-zero length or a length that is not the model's.

use fmi_sys::fmi2 as sys;

use super::call;
use crate::model_exchange::ModelExchange;
use crate::status::{FmiFunction, Status};

/// The array argument of a vector call as a slice; refuses NULL when `n > 0`.
///
/// # Safety
/// When non-NULL, `values` must point to `n` elements.
unsafe fn vector<'a, T>(
    inst: &crate::Instance<impl ModelExchange>,
    function: FmiFunction,
    values: *mut T,
    n: usize,
    name: &str,
) -> Result<&'a mut [T], Status> {
    if n == 0 {
        return Ok(&mut []);
    }
    if values.is_null() {
        return Err(inst.error(
            function,
            format_args!("{name}[] is NULL but its length is {n}"),
        ));
    }
    Ok(unsafe { std::slice::from_raw_parts_mut(values, n) })
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
    unsafe {
        call::<M, _, _>(
            c,
            function,
            |f| write!(f, "fmi2eventInfo = {event_info:?}"),
            |inst| {
                if event_info.is_null() {
                    return inst.error(function, format_args!("fmi2eventInfo is NULL"));
                }
                match inst.new_discrete_states() {
                    Ok(info) => {
                        let update = info.update;
                        *event_info = sys::fmi2EventInfo {
                            newDiscreteStatesNeeded: to_c(info.new_discrete_states_needed),
                            terminateSimulation: to_c(update.terminate_simulation),
                            nominalsOfContinuousStatesChanged: to_c(update.nominals_changed),
                            valuesOfContinuousStatesChanged: to_c(update.values_changed),
                            nextEventTimeDefined: to_c(update.next_event_time.is_some()),
                            nextEventTime: update.next_event_time.unwrap_or(0.0),
                        };
                        Status::Ok
                    }
                    Err(status) => status,
                }
            },
        )
    }
}

/// # Safety
/// `c` as for every FMI function.
pub unsafe fn enter_continuous_time_mode<M: ModelExchange>(
    c: sys::fmi2Component,
) -> sys::fmi2Status {
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
    unsafe {
        call::<M, _, _>(
            c,
            function,
            |_| Ok(()),
            |inst| {
                if enter_event_mode.is_null() || terminate_simulation.is_null() {
                    return inst.error(
                        function,
                        format_args!("enterEventMode or terminateSimulation is NULL"),
                    );
                }
                let status = inst.completed_integrator_step();
                if status <= Status::Warning {
                    // No step events: the model has nothing to do between steps
                    // that an event would serve.
                    *enter_event_mode = sys::fmi2False as _;
                    *terminate_simulation = sys::fmi2False as _;
                }
                status
            },
        )
    }
}

/// # Safety
/// `c` as for every FMI function.
pub unsafe fn set_time<M: ModelExchange>(
    c: sys::fmi2Component,
    time: sys::fmi2Real,
) -> sys::fmi2Status {
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
    unsafe {
        call::<M, _, _>(
            c,
            function,
            |f| write!(f, "nx = {nx}"),
            |inst| match vector(inst, function, x.cast_mut(), nx, "x") {
                Ok(states) => inst.set_continuous_states(states),
                Err(status) => status,
            },
        )
    }
}

/// # Safety
/// Arguments as `fmi2GetContinuousStates`.
pub unsafe fn get_continuous_states<M: ModelExchange>(
    c: sys::fmi2Component,
    x: *mut sys::fmi2Real,
    nx: usize,
) -> sys::fmi2Status {
    let function = FmiFunction::GetContinuousStates;
    unsafe {
        call::<M, _, _>(
            c,
            function,
            |f| write!(f, "nx = {nx}"),
            |inst| match vector(inst, function, x, nx, "x") {
                Ok(states) => inst.get_continuous_states(states),
                Err(status) => status,
            },
        )
    }
}

/// # Safety
/// Arguments as `fmi2GetDerivatives`.
pub unsafe fn get_derivatives<M: ModelExchange>(
    c: sys::fmi2Component,
    derivatives: *mut sys::fmi2Real,
    nx: usize,
) -> sys::fmi2Status {
    let function = FmiFunction::GetDerivatives;
    unsafe {
        call::<M, _, _>(
            c,
            function,
            |f| write!(f, "nx = {nx}"),
            |inst| match vector(inst, function, derivatives, nx, "derivatives") {
                Ok(out) => inst.get_derivatives(out),
                Err(status) => status,
            },
        )
    }
}

/// # Safety
/// Arguments as `fmi2GetEventIndicators`.
pub unsafe fn get_event_indicators<M: ModelExchange>(
    c: sys::fmi2Component,
    indicators: *mut sys::fmi2Real,
    ni: usize,
) -> sys::fmi2Status {
    let function = FmiFunction::GetEventIndicators;
    unsafe {
        call::<M, _, _>(
            c,
            function,
            |f| write!(f, "ni = {ni}"),
            |inst| match vector(inst, function, indicators, ni, "eventIndicators") {
                Ok(out) => inst.get_event_indicators(out),
                Err(status) => status,
            },
        )
    }
}

/// # Safety
/// Arguments as `fmi2GetNominalsOfContinuousStates`.
pub unsafe fn get_nominals_of_continuous_states<M: ModelExchange>(
    c: sys::fmi2Component,
    nominals: *mut sys::fmi2Real,
    nx: usize,
) -> sys::fmi2Status {
    let function = FmiFunction::GetNominalsOfContinuousStates;
    unsafe {
        call::<M, _, _>(
            c,
            function,
            |f| write!(f, "nx = {nx}"),
            |inst| match vector(inst, function, nominals, nx, "x_nominal") {
                Ok(out) => inst.get_nominals(out),
                Err(status) => status,
            },
        )
    }
}

//! The FMI 2.0 C entry points, generic over the model. [`export_fmi2!`](crate::export_fmi2)
//! exports them under their standard names.
//!
//! Every entry point: checks its pointers (an instance pointer is checked for
//! NULL and for this layer's magic number), checks the state machine, logs a
//! refusal with the function's name and the reason, catches any panic so that
//! none crosses the C boundary, and moves the instance to its error state after
//! `fmi2Error`. With `n == 0`, array pointers may be NULL.
//!
//! This is the gate: the pointers of a call become references and slices
//! here ([`slice_in`], [`slice_out`], [`value_out`], checked for NULL,
//! alignment and size with `fmi2Error` and a log line when they fail), and
//! everything past it (`Instance`, the model) is safe Rust. Every `unsafe`
//! block says, in its `SAFETY` comment, which part of the caller's contract
//! (the FMI 2.0 standard's rules for the arguments, repeated in each
//! function's `# Safety`) or which check makes it sound.

use std::ffi::{CStr, CString, c_char};
use std::fmt;
use std::mem::MaybeUninit;
use std::panic::{self, AssertUnwindSafe};
use std::ptr;

use fmi_sys::fmi2 as sys;

use crate::fmu_state::{self, Snapshot};
use crate::instance::{FmiValue, Instance, Magic, SetValue, StringArg};
use crate::logging::{LogCategory, Logger};
use crate::model::CoSimModel;
use crate::model_description;
use crate::resources;
use crate::status::{FmiFunction, Interface, Status};

pub mod model_exchange;

const ERROR: sys::fmi2Status = sys::fmi2Status_fmi2Error;

fn panic_message(payload: &(dyn std::any::Any + Send)) -> &str {
    if let Some(s) = payload.downcast_ref::<&str>() {
        s
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s
    } else {
        "unknown panic"
    }
}

/// The instance behind `c`, if it is one of ours.
///
/// # Safety
/// `c` must be NULL or point to at least eight readable bytes; a pointer
/// returned by `fmi2Instantiate` that was freed is not allowed. A NULL pointer,
/// a pointer to another object of this layer (such as an FMU state), and an
/// instance or state of another model built with this layer (another FMU in
/// the same process) are recognised by their magic number and refused.
unsafe fn instance<'a, M: CoSimModel>(c: sys::fmi2Component) -> Option<&'a mut Instance<M>> {
    if c.is_null() {
        return None;
    }
    // SAFETY: every object this layer hands out (instances and FMU states) is
    // repr(C) with a u64 magic number first, so reading the first eight bytes
    // stays inside the allocation whichever of them `c` is (the caller
    // guarantees eight readable bytes); read_unaligned makes no claim on the
    // alignment of a pointer that may not be ours.
    let magic = unsafe { ptr::read_unaligned(c as *const u64) };
    if magic != Magic::<M>::INSTANCE {
        return None;
    }
    // SAFETY: the magic number is that of a live `Instance<M>` made by
    // `instantiate` (Box, so aligned and initialized); `fmi2FreeInstance`
    // poisons it before the memory is released. The FMI standard forbids
    // calling into one instance from two threads at once, so the reference
    // is the only one while the call runs.
    Some(unsafe { &mut *(c as *mut Instance<M>) })
}

/// Runs `body` on the instance if `function` is legal in its state. With
/// `logFmiCalls` on, the call is traced with `arguments`, which writes them;
/// it only runs then, so that tracing costs nothing while it is off (not even
/// the stores of building a `fmt::Arguments`).
///
/// # Safety
/// As for [`instance`].
unsafe fn call<M, A, F>(
    c: sys::fmi2Component,
    function: FmiFunction,
    arguments: A,
    body: F,
) -> sys::fmi2Status
where
    M: CoSimModel,
    A: Fn(&mut fmt::Formatter<'_>) -> fmt::Result,
    F: FnOnce(&mut Instance<M>) -> Status,
{
    // SAFETY: `c` is NULL or points to eight readable bytes (this function's
    // contract, the caller's from the FMI standard).
    let Some(inst) = (unsafe { instance::<M>(c) }) else {
        return ERROR;
    };
    trace(inst, function, arguments);
    if !function.allowed(inst.env.interface, inst.state) {
        refuse_sequence(inst, function);
        return ERROR;
    }
    // The status is turned into the instance's state and the C value inside
    // the guarded call, where the compiler sees which status the body
    // returned: a step that returns fmi2OK pays no test for the error state.
    let outcome = panic::catch_unwind(AssertUnwindSafe(|| {
        let status = body(&mut *inst);
        inst.enter_error_state(status);
        status.to_raw()
    }));
    outcome.unwrap_or_else(|payload| {
        inst.env.logger.error(
            function.name(),
            format_args!("internal error (panic): {}", panic_message(&*payload)),
        );
        inst.enter_error_state(Status::Error);
        ERROR
    })
}

/// Logs why `function` is not allowed now and moves the instance to its error
/// state. Kept out of line: the check that leads here is on every call's path.
#[cold]
#[inline(never)]
fn refuse_sequence<M: CoSimModel>(inst: &mut Instance<M>, function: FmiFunction) {
    match function.interface() {
        Some(own) if own != inst.env.interface => inst.env.logger.error(
            function.name(),
            format_args!(
                "illegal call sequence: a {} function, and this instance was instantiated \
                 for {}",
                own.name(),
                inst.env.interface.name()
            ),
        ),
        _ => inst.env.logger.error(
            function.name(),
            format_args!(
                "illegal call sequence: not allowed in state {}",
                inst.state.name()
            ),
        ),
    }
    inst.enter_error_state(Status::Error);
}

/// A C string argument as `&str` (lossy on invalid UTF-8).
///
/// # Safety
/// `s` must be NULL or a NUL-terminated string.
unsafe fn string_arg<'a>(s: *const c_char) -> Option<std::borrow::Cow<'a, str>> {
    if s.is_null() {
        return None;
    }
    // SAFETY: non-NULL, and NUL-terminated by this function's contract.
    Some(unsafe { CStr::from_ptr(s) }.to_string_lossy())
}

/// An input array argument (`values`, `n`) as a slice: empty when `n == 0`
/// (the pointer may then be NULL); refuses, with `fmi2Error` and a log line
/// naming `name`, a NULL or misaligned pointer or an impossible length.
///
/// # Safety
/// When non-NULL, `values` must point to `n` initialized elements, valid for
/// `'a` and not written meanwhile.
pub(crate) unsafe fn slice_in<'a, T>(
    inst: &Instance<impl CoSimModel>,
    function: FmiFunction,
    values: *const T,
    n: usize,
    name: &str,
) -> Result<&'a [T], Status> {
    if n == 0 {
        return Ok(&[]);
    }
    check_array(inst, function, values, n, name)?;
    // SAFETY: `values` is non-NULL and aligned, and `n` elements of `T` fit
    // in `isize` (all checked above); the caller guarantees that it points to
    // `n` initialized elements that nothing writes while the call runs (the
    // FMI standard: the array has `n` elements).
    Ok(unsafe { std::slice::from_raw_parts(values, n) })
}

/// An output array argument (`values`, `n`) as a slice of possibly
/// uninitialized elements (the importer's buffer may be fresh memory),
/// checked as by [`slice_in`].
///
/// # Safety
/// When non-NULL, `values` must point to `n` elements writable for `'a`, that
/// nothing else reads or writes meanwhile.
pub(crate) unsafe fn slice_out<'a, T>(
    inst: &Instance<impl CoSimModel>,
    function: FmiFunction,
    values: *mut T,
    n: usize,
    name: &str,
) -> Result<&'a mut [MaybeUninit<T>], Status> {
    if n == 0 {
        return Ok(&mut []);
    }
    check_array(inst, function, values.cast_const(), n, name)?;
    // SAFETY: as in `slice_in` (non-NULL, aligned, size checked); the caller
    // guarantees the elements writable and not aliased (the FMI standard: the
    // importer's output buffer of `n` elements). `MaybeUninit` makes no claim
    // on what the buffer holds before it is written.
    Ok(unsafe { std::slice::from_raw_parts_mut(values.cast::<MaybeUninit<T>>(), n) })
}

/// Refuses, with a log line, an array pointer that cannot be made a slice of
/// `n > 0` elements: NULL, misaligned, or too long for the address space.
fn check_array<T>(
    inst: &Instance<impl CoSimModel>,
    function: FmiFunction,
    values: *const T,
    n: usize,
    name: &str,
) -> Result<(), Status> {
    if values.is_null() {
        return Err(inst.error(
            function,
            format_args!("{name}[] is NULL but its length is {n}"),
        ));
    }
    if !values.is_aligned() {
        return Err(inst.error(
            function,
            format_args!(
                "{name}[] at {values:?} is not aligned for its element type ({} bytes)",
                std::mem::align_of::<T>()
            ),
        ));
    }
    if n > isize::MAX as usize / std::mem::size_of::<T>().max(1) {
        return Err(inst.error(
            function,
            format_args!("{name}[] cannot have {n} elements (larger than the address space)"),
        ));
    }
    Ok(())
}

/// A pointer to one output value, possibly uninitialized, as a reference;
/// refuses NULL and misaligned pointers with a log line naming `name`.
///
/// # Safety
/// When non-NULL, `value` must be valid for writes of a `T` for `'a`, and not
/// aliased meanwhile.
pub(crate) unsafe fn value_out<'a, T>(
    inst: &Instance<impl CoSimModel>,
    function: FmiFunction,
    value: *mut T,
    name: &str,
) -> Result<&'a mut MaybeUninit<T>, Status> {
    if value.is_null() {
        return Err(inst.error(function, format_args!("{name} is NULL")));
    }
    check_array(inst, function, value.cast_const(), 1, name)?;
    // SAFETY: non-NULL and aligned (checked); valid for writes and unaliased
    // by this function's contract (the FMI standard: the importer's output
    // variable); `MaybeUninit` claims nothing of its current contents.
    Ok(unsafe { &mut *value.cast::<MaybeUninit<T>>() })
}

/// A pointer to one in-out value (read, then maybe written) as a reference;
/// refuses NULL and misaligned pointers with a log line naming `name`.
///
/// # Safety
/// When non-NULL, `value` must point to an initialized `T` valid for reads
/// and writes for `'a`, and not aliased meanwhile.
unsafe fn value_in_out<'a, T>(
    inst: &Instance<impl CoSimModel>,
    function: FmiFunction,
    value: *mut T,
    name: &str,
) -> Result<&'a mut T, Status> {
    if value.is_null() {
        return Err(inst.error(function, format_args!("{name} is NULL")));
    }
    check_array(inst, function, value.cast_const(), 1, name)?;
    // SAFETY: non-NULL and aligned (checked); initialized, valid and
    // unaliased by this function's contract (the FMI standard: the
    // importer's `fmi2FMUstate` variable).
    Ok(unsafe { &mut *value })
}

/// The arguments of a traced call, written only when the trace is.
struct Arguments<A>(A);

impl<A: Fn(&mut fmt::Formatter<'_>) -> fmt::Result> fmt::Display for Arguments<A> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        (self.0)(f)
    }
}

/// Traces a call as `fmi2X: (arguments)` when `logFmiCalls` is on.
#[inline]
fn trace<M, A>(inst: &Instance<M>, function: FmiFunction, arguments: A)
where
    M: CoSimModel,
    A: Fn(&mut fmt::Formatter<'_>) -> fmt::Result,
{
    if inst.env.logger.is_enabled(LogCategory::FmiCalls) {
        inst.env.logger.log_in(
            function.name(),
            Status::Ok,
            LogCategory::FmiCalls,
            format_args!("({})", Arguments(arguments)),
        );
    }
}

pub extern "C" fn get_types_platform() -> *const c_char {
    c"default".as_ptr()
}

pub extern "C" fn get_version() -> *const c_char {
    c"2.0".as_ptr()
}

/// # Safety
/// Arguments as `fmi2Instantiate` of the FMI 2.0 standard.
pub unsafe fn instantiate<M: CoSimModel>(
    instance_name: sys::fmi2String,
    fmu_type: sys::fmi2Type,
    fmu_guid: sys::fmi2String,
    fmu_resource_location: sys::fmi2String,
    functions: *const sys::fmi2CallbackFunctions,
    _visible: sys::fmi2Boolean,
    logging_on: sys::fmi2Boolean,
) -> sys::fmi2Component {
    let outcome = panic::catch_unwind(|| {
        // SAFETY: the arguments are this function's, under the same contract.
        unsafe {
            instantiate_checked::<M>(
                instance_name,
                fmu_type,
                fmu_guid,
                fmu_resource_location,
                functions,
                logging_on,
            )
        }
    });
    outcome.unwrap_or(ptr::null_mut())
}

/// # Safety
/// As [`instantiate`].
unsafe fn instantiate_checked<M: CoSimModel>(
    instance_name: sys::fmi2String,
    fmu_type: sys::fmi2Type,
    fmu_guid: sys::fmi2String,
    fmu_resource_location: sys::fmi2String,
    functions: *const sys::fmi2CallbackFunctions,
    logging_on: sys::fmi2Boolean,
) -> sys::fmi2Component {
    const NAME: &str = "fmi2Instantiate";
    if functions.is_null() {
        // Without callbacks there is no logger to say why.
        return ptr::null_mut();
    }
    if !functions.is_aligned() {
        return ptr::null_mut();
    }
    // SAFETY: non-NULL and aligned (checked); the importer passes its
    // callback struct, initialized (FMI 2.0.4 §2.1.5). Copied: the importer
    // may free it after the call.
    let callbacks = unsafe { *functions };
    // SAFETY: NULL or a NUL-terminated string (the standard's `fmi2String`).
    let name = unsafe { string_arg(instance_name) };
    let logger_name = CString::new(name.as_deref().unwrap_or("(NULL)").replace('\0', "?"))
        .expect("NUL bytes replaced");
    let logger = Logger::new(
        callbacks.logger,
        callbacks.componentEnvironment,
        logger_name,
        logging_on != 0,
    );
    if name.is_none() {
        logger.error(NAME, format_args!("instanceName is NULL"));
        return ptr::null_mut();
    }
    let interface = match fmu_type {
        sys::fmi2Type_fmi2CoSimulation => Interface::CoSimulation,
        sys::fmi2Type_fmi2ModelExchange if M::MODEL_EXCHANGE.is_some() => Interface::ModelExchange,
        sys::fmi2Type_fmi2ModelExchange => {
            logger.error(
                NAME,
                format_args!(
                    "{} implements FMI 2.0 co-simulation only (modelDescription has no \
                     <ModelExchange>); fmuType fmi2ModelExchange was requested",
                    M::INFO.model_identifier
                ),
            );
            return ptr::null_mut();
        }
        other => {
            logger.error(
                NAME,
                format_args!(
                    "fmuType {other} is neither fmi2ModelExchange (0) nor fmi2CoSimulation (1)"
                ),
            );
            return ptr::null_mut();
        }
    };
    // The instance's model, built before the GUID check: the GUID's start
    // values are read from it (one construction, not two).
    let model = M::new();
    let guid = match model_description::cached_guid(&model) {
        Ok(guid) => guid,
        Err(e) => {
            logger.error(
                NAME,
                format_args!("the model's variable table is inconsistent: {e}"),
            );
            return ptr::null_mut();
        }
    };
    // SAFETY: as for `instance_name`.
    match unsafe { string_arg(fmu_guid) } {
        None => {
            logger.error(NAME, format_args!("fmuGUID is NULL (expected {guid})"));
            return ptr::null_mut();
        }
        Some(given) if given != guid => {
            logger.error(
                NAME,
                format_args!(
                    "fmuGUID {given} does not match this binary's GUID {guid}: the \
                     modelDescription.xml and the binary come from different builds"
                ),
            );
            return ptr::null_mut();
        }
        Some(_) => {}
    }
    // SAFETY: as for `instance_name`.
    let location = unsafe { string_arg(fmu_resource_location) };
    let resource_dir = match resources::resource_dir(location.as_deref()) {
        Ok(dir) => dir,
        Err(reason) => {
            logger.warning(NAME, format_args!("{reason}; continuing without resources"));
            None
        }
    };
    let instance = Instance::new(logger, interface, resource_dir, guid, model);
    if instance.env.logger.is_enabled(LogCategory::FmiCalls) {
        instance.env.logger.log_in(
            NAME,
            Status::Ok,
            LogCategory::FmiCalls,
            format_args!(
                "(instanceName = {:?}, fmuType = {fmu_type}, fmuResourceLocation = {:?}, \
                 loggingOn = {logging_on})",
                name.as_deref().unwrap_or_default(),
                location.as_deref()
            ),
        );
    }
    instance.env.logger.log_in(
        NAME,
        Status::Ok,
        LogCategory::Events,
        format_args!(
            "instantiated {} for {}",
            M::INFO.model_identifier,
            interface.name()
        ),
    );
    Box::into_raw(Box::new(instance)).cast()
}

/// # Safety
/// `c` as for every FMI function.
pub unsafe fn free_instance<M: CoSimModel>(c: sys::fmi2Component) {
    // SAFETY: `c` as for every FMI function (this function's contract).
    let Some(inst) = (unsafe { instance::<M>(c) }) else {
        return;
    };
    trace(inst, FmiFunction::FreeInstance, |_| Ok(()));
    // The FMU states it made that the importer did not free.
    for state in std::mem::take(&mut inst.fmu_states) {
        // SAFETY: `fmu_states` holds only live snapshots of `M` this
        // instance made; `fmi2FreeFMUstate` removes a state from it before
        // freeing it, so none is freed twice.
        unsafe { free_snapshot::<M>(state) };
    }
    // Poison the magic so that a second free of the same pointer is refused
    // as long as the memory has not been reused.
    inst.magic = 0;
    // SAFETY: `c` is a live `Instance<M>` (its magic number said so) that
    // `instantiate` made with `Box::into_raw`; `inst` is not used after this.
    let boxed = unsafe { Box::from_raw(c as *mut Instance<M>) };
    let _ = panic::catch_unwind(AssertUnwindSafe(move || drop(boxed)));
}

/// # Safety
/// Arguments as `fmi2SetDebugLogging`.
pub unsafe fn set_debug_logging<M: CoSimModel>(
    c: sys::fmi2Component,
    logging_on: sys::fmi2Boolean,
    n_categories: usize,
    categories: *const sys::fmi2String,
) -> sys::fmi2Status {
    let function = FmiFunction::SetDebugLogging;
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `categories` points to `n_categories` strings when
        // non-NULL (the standard's contract, this function's).
        let raw = match unsafe { slice_in(inst, function, categories, n_categories, "categories") }
        {
            Ok(raw) => raw,
            Err(status) => return status,
        };
        if raw.iter().any(|p| p.is_null()) {
            return inst.error(function, format_args!("a category name is NULL"));
        }
        let names: Vec<std::borrow::Cow<'_, str>> = raw
            .iter()
            // SAFETY: each is non-NULL (checked) and NUL-terminated (the
            // standard's `fmi2String`).
            .map(|p| unsafe { string_arg(*p) }.expect("checked"))
            .collect();
        let names: Vec<&str> = names.iter().map(|n| n.as_ref()).collect();
        inst.set_debug_logging(logging_on != 0, &names)
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe {
        call::<M, _, _>(
            c,
            function,
            |f| write!(f, "loggingOn = {logging_on}, nCategories = {n_categories}"),
            body,
        )
    }
}

/// # Safety
/// Arguments as `fmi2SetupExperiment`.
pub unsafe fn setup_experiment<M: CoSimModel>(
    c: sys::fmi2Component,
    _tolerance_defined: sys::fmi2Boolean,
    _tolerance: sys::fmi2Real,
    start_time: sys::fmi2Real,
    stop_time_defined: sys::fmi2Boolean,
    stop_time: sys::fmi2Real,
) -> sys::fmi2Status {
    // The tolerance is not used: the models integrate their linear parts exactly
    // and bound the rest by their own solver parameters.
    // SAFETY: `c` as for every FMI function (this function's contract); the
    // other arguments are values.
    unsafe {
        call::<M, _, _>(
            c,
            FmiFunction::SetupExperiment,
            |f| {
                write!(
                    f,
                    "startTime = {start_time}, stopTimeDefined = {stop_time_defined}, stopTime = {stop_time}"
                )
            },
            |inst| inst.setup_experiment(start_time, (stop_time_defined != 0).then_some(stop_time)),
        )
    }
}

/// # Safety
/// `c` as for every FMI function.
pub unsafe fn enter_initialization_mode<M: CoSimModel>(c: sys::fmi2Component) -> sys::fmi2Status {
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe {
        call::<M, _, _>(
            c,
            FmiFunction::EnterInitializationMode,
            |_| Ok(()),
            |i| i.enter_initialization_mode(),
        )
    }
}

/// # Safety
/// `c` as for every FMI function.
pub unsafe fn exit_initialization_mode<M: CoSimModel>(c: sys::fmi2Component) -> sys::fmi2Status {
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe {
        call::<M, _, _>(
            c,
            FmiFunction::ExitInitializationMode,
            |_| Ok(()),
            |i| i.exit_initialization_mode(),
        )
    }
}

/// # Safety
/// `c` as for every FMI function.
pub unsafe fn terminate<M: CoSimModel>(c: sys::fmi2Component) -> sys::fmi2Status {
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, FmiFunction::Terminate, |_| Ok(()), |i| i.terminate()) }
}

/// # Safety
/// `c` as for every FMI function.
pub unsafe fn reset<M: CoSimModel>(c: sys::fmi2Component) -> sys::fmi2Status {
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, FmiFunction::Reset, |_| Ok(()), |i| i.reset()) }
}

/// # Safety
/// Arguments as `fmi2GetReal` and friends; `values` points to `nvr` elements of
/// the C type that `to_c` produces.
unsafe fn get<M: CoSimModel, T: FmiValue, C>(
    c: sys::fmi2Component,
    function: FmiFunction,
    vr: *const sys::fmi2ValueReference,
    nvr: usize,
    values: *mut C,
    to_c: fn(T) -> C,
) -> sys::fmi2Status {
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `vr` points to `nvr` value references when non-NULL (this
        // function's contract, the standard's for fmi2GetXXX).
        let vrs = match unsafe { slice_in(inst, function, vr, nvr, "vr") } {
            Ok(vrs) => vrs,
            Err(status) => return status,
        };
        // SAFETY: `values` points to `nvr` writable elements when non-NULL
        // (as above).
        let out = match unsafe { slice_out(inst, function, values, nvr, "value") } {
            Ok(out) => out,
            Err(status) => return status,
        };
        inst.get_values(function, vrs, |i, value: T| {
            out[i].write(to_c(value));
        })
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, function, |f| write!(f, "nvr = {nvr}"), body) }
}

/// # Safety
/// Arguments as `fmi2SetReal` and friends; `values` points to `nvr` elements of
/// the C type, each of which `from_c` may read under its own contract.
unsafe fn set<M: CoSimModel, T: SetValue, C: Copy>(
    c: sys::fmi2Component,
    function: FmiFunction,
    vr: *const sys::fmi2ValueReference,
    nvr: usize,
    values: *const C,
    from_c: unsafe fn(C) -> T,
) -> sys::fmi2Status {
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `vr` points to `nvr` value references when non-NULL (this
        // function's contract, the standard's for fmi2SetXXX).
        let vrs = match unsafe { slice_in(inst, function, vr, nvr, "vr") } {
            Ok(vrs) => vrs,
            Err(status) => return status,
        };
        // SAFETY: `values` points to `nvr` values when non-NULL (as above).
        let raw = match unsafe { slice_in(inst, function, values, nvr, "value") } {
            Ok(raw) => raw,
            Err(status) => return status,
        };
        inst.set_values(function, vrs, |i| {
            // SAFETY: `raw[i]` is an element of the importer's array, which
            // meets `from_c`'s contract (this function's).
            unsafe { from_c(raw[i]) }
        })
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, function, |f| write!(f, "nvr = {nvr}"), body) }
}

fn bool_to_c(b: bool) -> sys::fmi2Boolean {
    b as sys::fmi2Boolean
}

fn bool_from_c(b: sys::fmi2Boolean) -> bool {
    b != 0
}

/// # Safety
/// Arguments as `fmi2GetReal`.
pub unsafe fn get_real<M: CoSimModel>(
    c: sys::fmi2Component,
    vr: *const sys::fmi2ValueReference,
    nvr: usize,
    value: *mut sys::fmi2Real,
) -> sys::fmi2Status {
    // SAFETY: the arguments are this function's, under the same contract.
    unsafe { get::<M, f64, _>(c, FmiFunction::GetReal, vr, nvr, value, |v| v) }
}

/// # Safety
/// Arguments as `fmi2GetInteger`.
pub unsafe fn get_integer<M: CoSimModel>(
    c: sys::fmi2Component,
    vr: *const sys::fmi2ValueReference,
    nvr: usize,
    value: *mut sys::fmi2Integer,
) -> sys::fmi2Status {
    // SAFETY: the arguments are this function's, under the same contract.
    unsafe { get::<M, i32, _>(c, FmiFunction::GetInteger, vr, nvr, value, |v| v) }
}

/// # Safety
/// Arguments as `fmi2GetBoolean`.
pub unsafe fn get_boolean<M: CoSimModel>(
    c: sys::fmi2Component,
    vr: *const sys::fmi2ValueReference,
    nvr: usize,
    value: *mut sys::fmi2Boolean,
) -> sys::fmi2Status {
    // SAFETY: the arguments are this function's, under the same contract.
    unsafe { get::<M, bool, _>(c, FmiFunction::GetBoolean, vr, nvr, value, bool_to_c) }
}

/// # Safety
/// Arguments as `fmi2GetString`.
pub unsafe fn get_string<M: CoSimModel>(
    c: sys::fmi2Component,
    vr: *const sys::fmi2ValueReference,
    nvr: usize,
    value: *mut sys::fmi2String,
) -> sys::fmi2Status {
    let function = FmiFunction::GetString;
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `vr` points to `nvr` value references when non-NULL (this
        // function's contract, the standard's for fmi2GetString).
        let vrs = match unsafe { slice_in(inst, function, vr, nvr, "vr") } {
            Ok(vrs) => vrs,
            Err(status) => return status,
        };
        // SAFETY: `value` points to `nvr` writable pointers when non-NULL
        // (as above).
        let out = match unsafe { slice_out(inst, function, value, nvr, "value") } {
            Ok(out) => out,
            Err(status) => return status,
        };
        let status = inst.get_strings(function, vrs);
        if status == Status::Ok {
            // The instance owns the strings until its next fmi2GetString
            // or fmi2FreeInstance (FMI 2.0.4 §2.1.7).
            for (out, text) in out.iter_mut().zip(&inst.strings) {
                out.write(text.as_ptr());
            }
        }
        status
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, function, |f| write!(f, "nvr = {nvr}"), body) }
}

/// One element of `fmi2SetString`'s `value[]` as text, or why it is none.
///
/// # Safety
/// `text` must be NULL or point to a NUL-terminated string that nothing
/// writes while the call runs; the text returned borrows that string, and
/// must not be kept past the call (the model's setter copies it).
unsafe fn string_value<'a>(text: sys::fmi2String) -> StringArg<'a> {
    if text.is_null() {
        return StringArg::Null;
    }
    // SAFETY: non-NULL, and NUL-terminated and unchanging during the call by
    // this function's contract (the standard's `fmi2String`).
    let bytes = unsafe { CStr::from_ptr(text) };
    match bytes.to_str() {
        Ok(text) => StringArg::Text(text),
        Err(_) => StringArg::NotUtf8,
    }
}

/// # Safety
/// Arguments as `fmi2SetReal`.
pub unsafe fn set_real<M: CoSimModel>(
    c: sys::fmi2Component,
    vr: *const sys::fmi2ValueReference,
    nvr: usize,
    value: *const sys::fmi2Real,
) -> sys::fmi2Status {
    // SAFETY: the arguments are this function's, under the same contract.
    unsafe { set::<M, f64, _>(c, FmiFunction::SetReal, vr, nvr, value, |v| v) }
}

/// # Safety
/// Arguments as `fmi2SetInteger`.
pub unsafe fn set_integer<M: CoSimModel>(
    c: sys::fmi2Component,
    vr: *const sys::fmi2ValueReference,
    nvr: usize,
    value: *const sys::fmi2Integer,
) -> sys::fmi2Status {
    // SAFETY: the arguments are this function's, under the same contract.
    unsafe { set::<M, i32, _>(c, FmiFunction::SetInteger, vr, nvr, value, |v| v) }
}

/// # Safety
/// Arguments as `fmi2SetBoolean`.
pub unsafe fn set_boolean<M: CoSimModel>(
    c: sys::fmi2Component,
    vr: *const sys::fmi2ValueReference,
    nvr: usize,
    value: *const sys::fmi2Boolean,
) -> sys::fmi2Status {
    // SAFETY: the arguments are this function's, under the same contract.
    unsafe { set::<M, bool, _>(c, FmiFunction::SetBoolean, vr, nvr, value, bool_from_c) }
}

/// `fmi2SetString`: each string is checked (not NULL, UTF-8) with the rest
/// of the call's values before any is stored, and the model keeps a copy.
///
/// # Safety
/// Arguments as `fmi2SetString`: `value` points to `nvr` strings, each NULL
/// or NUL-terminated.
pub unsafe fn set_string<M: CoSimModel>(
    c: sys::fmi2Component,
    vr: *const sys::fmi2ValueReference,
    nvr: usize,
    value: *const sys::fmi2String,
) -> sys::fmi2Status {
    // SAFETY: the arguments are this function's, under the same contract;
    // each element `set` hands `string_value` is a NULL or NUL-terminated
    // string, as `string_value` requires.
    unsafe { set::<M, _, _>(c, FmiFunction::SetString, vr, nvr, value, string_value) }
}

/// The snapshot behind an `fmi2FMUstate`, if it is one of ours.
///
/// # Safety
/// `state` must be NULL or point to at least eight readable bytes; a state
/// that was freed is not allowed. Instances, and states of another model built
/// with this layer, are recognised by their magic number and refused.
unsafe fn snapshot<'a, M: CoSimModel>(state: sys::fmi2FMUstate) -> Option<&'a mut Snapshot<M>> {
    if state.is_null() {
        return None;
    }
    // SAFETY: as in `instance`: the magic number is the first field of
    // every object this layer hands out, and the caller guarantees eight
    // readable bytes.
    let magic = unsafe { ptr::read_unaligned(state as *const u64) };
    if magic != Magic::<M>::SNAPSHOT {
        return None;
    }
    // SAFETY: the magic number is that of a live `Snapshot<M>` made by
    // `store_snapshot` (Box: aligned, initialized); `free_snapshot` poisons
    // it before the memory is released. Calls on one instance are never
    // concurrent (FMI standard), so the reference is the only one.
    Some(unsafe { &mut *(state as *mut Snapshot<M>) })
}

/// Frees a snapshot of this layer, poisoning its magic number first.
///
/// # Safety
/// `state` must be a live snapshot of model `M` made by this layer.
unsafe fn free_snapshot<M: CoSimModel>(state: sys::fmi2FMUstate) {
    let snapshot = state as *mut Snapshot<M>;
    // SAFETY: a live snapshot made by `Box::into_raw` in `store_snapshot`
    // (this function's contract); nothing uses it after this.
    let mut boxed = unsafe { Box::from_raw(snapshot) };
    boxed.magic = 0;
    drop(boxed);
}

/// What [`store_snapshot`] may read of the `*FMUstate` it is given.
#[derive(Clone, Copy, PartialEq)]
enum Slot {
    /// `fmi2GetFMUstate`: *FMUstate is NULL or a state the importer got from
    /// this FMU and has not freed (FMI 2.0.4 §2.1.8), which is reused.
    InOut,
    /// `fmi2DeSerializeFMUstate`: FMUstate is output only (§2.1.8: it
    /// "returns FMUstate"), so the importer may pass an uninitialized
    /// variable. Only a state that this instance made and lists is reused;
    /// anything else is overwritten with a new state without being read.
    Out,
}

/// Stores `data` in `*slot`, reusing the snapshot already there if there is
/// one ([`Slot`] says which), else in a new one.
fn store_snapshot<M: CoSimModel>(
    inst: &mut Instance<M>,
    function: FmiFunction,
    slot: &mut sys::fmi2FMUstate,
    slot_kind: Slot,
    data: fmu_state::SnapshotData<M>,
) -> Status {
    let current = *slot;
    if current.is_null() || (slot_kind == Slot::Out && !inst.fmu_states.contains(&current)) {
        let owner: *mut Instance<M> = inst;
        let boxed = Box::new(Snapshot::new(data, owner.cast()));
        let state: sys::fmi2FMUstate = Box::into_raw(boxed).cast();
        inst.fmu_states.push(state);
        *slot = state;
        return Status::Ok;
    }
    // SAFETY: `*slot` is non-NULL: with `Slot::Out` a live snapshot this
    // instance lists; with `Slot::InOut` a state the importer got from this
    // FMU and has not freed, or the importer broke the standard (FMI 2.0.4
    // §2.1.8: *FMUstate is NULL or a state of this FMU); any of our objects
    // has the eight readable bytes the magic check needs.
    match unsafe { snapshot::<M>(current) } {
        Some(existing) => {
            existing.data = data;
            existing.encoded = None;
            Status::Ok
        }
        None => inst.error(
            function,
            format_args!("*FMUstate is neither NULL nor a state of this FMU"),
        ),
    }
}

/// # Safety
/// Arguments as `fmi2GetFMUstate`.
pub unsafe fn get_fmu_state<M: CoSimModel>(
    c: sys::fmi2Component,
    state: *mut sys::fmi2FMUstate,
) -> sys::fmi2Status {
    let function = FmiFunction::GetFmuState;
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `state` is the importer's initialized `fmi2FMUstate`
        // variable when non-NULL (this function's contract).
        let slot = match unsafe { value_in_out(inst, function, state, "FMUstate") } {
            Ok(slot) => slot,
            Err(status) => return status,
        };
        let data = inst.snapshot();
        store_snapshot(inst, function, slot, Slot::InOut, data)
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, function, |f| write!(f, "FMUstate = {state:?}"), body) }
}

/// # Safety
/// Arguments as `fmi2SetFMUstate`.
pub unsafe fn set_fmu_state<M: CoSimModel>(
    c: sys::fmi2Component,
    state: sys::fmi2FMUstate,
) -> sys::fmi2Status {
    let function = FmiFunction::SetFmuState;
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `state` is NULL or a state of this FMU not yet freed (this
        // function's contract); any of our objects has eight readable bytes.
        match unsafe { snapshot::<M>(state) } {
            Some(snapshot) => inst.restore(function, &snapshot.data),
            None => inst.error(
                function,
                format_args!("FMUstate is NULL or not a state of this FMU"),
            ),
        }
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, function, |f| write!(f, "FMUstate = {state:?}"), body) }
}

/// # Safety
/// Arguments as `fmi2FreeFMUstate`.
pub unsafe fn free_fmu_state<M: CoSimModel>(
    c: sys::fmi2Component,
    state: *mut sys::fmi2FMUstate,
) -> sys::fmi2Status {
    let function = FmiFunction::FreeFmuState;
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `state` is the importer's initialized `fmi2FMUstate`
        // variable when non-NULL (this function's contract).
        let slot = match unsafe { value_in_out(inst, function, state, "FMUstate") } {
            Ok(slot) => slot,
            Err(status) => return status,
        };
        let current = *slot;
        if current.is_null() {
            return Status::Ok;
        }
        // SAFETY: `current` is non-NULL and a state of this FMU not yet
        // freed, or refused by its magic number (this function's contract).
        let Some(snapshot) = (unsafe { snapshot::<M>(current) }) else {
            return inst.error(
                function,
                format_args!("*FMUstate is not a state of this FMU"),
            );
        };
        // The instance that made it (maybe another one than this: states of
        // one instance may be used with another) no longer has to free it.
        let owner = snapshot.owner as *mut Instance<M>;
        if ptr::eq(owner, &*inst) {
            inst.fmu_states.retain(|s| *s != current);
        // SAFETY: a snapshot's owner is the instance that made it; an owner
        // freed since is refused by its poisoned magic number, as long as
        // the memory was not reused (the standard forbids using a state of a
        // freed instance).
        } else if let Some(owner) = unsafe { instance::<M>(owner.cast()) } {
            owner.fmu_states.retain(|s| *s != current);
        }
        // SAFETY: `current` is a live snapshot of `M` (its magic number) and
        // no instance lists it any more, so it is freed once.
        unsafe { free_snapshot::<M>(current) };
        *slot = ptr::null_mut();
        Status::Ok
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, function, |f| write!(f, "FMUstate = {state:?}"), body) }
}

/// The encoded bytes of a snapshot, computed once.
fn encoded<'a, M: CoSimModel>(
    inst: &Instance<M>,
    function: FmiFunction,
    snapshot: &'a mut Snapshot<M>,
) -> Result<&'a [u8], Status> {
    if snapshot.encoded.is_none() {
        match fmu_state::encode(&snapshot.data, &inst.guid) {
            Ok(bytes) => snapshot.encoded = Some(bytes),
            Err(e) => return Err(inst.error(function, format_args!("{e}"))),
        }
    }
    Ok(snapshot.encoded.as_deref().expect("just encoded"))
}

/// # Safety
/// Arguments as `fmi2SerializedFMUstateSize`.
pub unsafe fn serialized_fmu_state_size<M: CoSimModel>(
    c: sys::fmi2Component,
    state: sys::fmi2FMUstate,
    size: *mut usize,
) -> sys::fmi2Status {
    let function = FmiFunction::SerializedFmuStateSize;
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `size` is the importer's output variable when non-NULL
        // (this function's contract).
        let size = match unsafe { value_out(inst, function, size, "size") } {
            Ok(size) => size,
            Err(status) => return status,
        };
        // SAFETY: `state` is NULL or a state of this FMU not yet freed, or
        // refused by its magic number (this function's contract).
        let Some(snapshot) = (unsafe { snapshot::<M>(state) }) else {
            return inst.error(
                function,
                format_args!("FMUstate is NULL or not a state of this FMU"),
            );
        };
        match encoded(inst, function, snapshot) {
            Ok(bytes) => {
                size.write(bytes.len());
                Status::Ok
            }
            Err(status) => status,
        }
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, function, |f| write!(f, "FMUstate = {state:?}"), body) }
}

/// # Safety
/// Arguments as `fmi2SerializeFMUstate`.
pub unsafe fn serialize_fmu_state<M: CoSimModel>(
    c: sys::fmi2Component,
    state: sys::fmi2FMUstate,
    serialized: *mut sys::fmi2Byte,
    size: usize,
) -> sys::fmi2Status {
    let function = FmiFunction::SerializeFmuState;
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `state` is NULL or a state of this FMU not yet freed, or
        // refused by its magic number (this function's contract).
        let Some(snapshot) = (unsafe { snapshot::<M>(state) }) else {
            return inst.error(
                function,
                format_args!("FMUstate is NULL or not a state of this FMU"),
            );
        };
        let bytes = match encoded(inst, function, snapshot) {
            Ok(bytes) => bytes,
            Err(status) => return status,
        };
        if size != bytes.len() {
            return inst.error(
                function,
                format_args!(
                    "size is {size} but the state needs {} bytes (ask fmi2SerializedFMUstateSize)",
                    bytes.len()
                ),
            );
        }
        if serialized.is_null() {
            return inst.error(function, format_args!("serializedState is NULL"));
        }
        // SAFETY: `serialized` points to `size` writable bytes (this
        // function's contract); bytes have no alignment.
        let out = match unsafe {
            slice_out(
                inst,
                function,
                serialized.cast::<u8>(),
                size,
                "serializedState",
            )
        } {
            Ok(out) => out,
            Err(status) => return status,
        };
        for (out, byte) in out.iter_mut().zip(bytes) {
            out.write(*byte);
        }
        Status::Ok
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe {
        call::<M, _, _>(
            c,
            function,
            |f| write!(f, "FMUstate = {state:?}, size = {size}"),
            body,
        )
    }
}

/// # Safety
/// Arguments as `fmi2DeSerializeFMUstate`.
pub unsafe fn deserialize_fmu_state<M: CoSimModel>(
    c: sys::fmi2Component,
    serialized: *const sys::fmi2Byte,
    size: usize,
    state: *mut sys::fmi2FMUstate,
) -> sys::fmi2Status {
    let function = FmiFunction::DeSerializeFmuState;
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `state` is the importer's `fmi2FMUstate` variable when
        // non-NULL (this function's contract); its value may be anything,
        // and `store_snapshot` reads through it only if this instance made it.
        let slot = match unsafe { value_in_out(inst, function, state, "FMUstate") } {
            Ok(slot) => slot,
            Err(status) => return status,
        };
        // SAFETY: `serialized` points to `size` bytes when non-NULL (this
        // function's contract).
        let bytes = match unsafe {
            slice_in(
                inst,
                function,
                serialized.cast::<u8>(),
                size,
                "serializedState",
            )
        } {
            Ok(bytes) => bytes,
            Err(status) => return status,
        };
        match fmu_state::decode::<M>(bytes, &inst.guid) {
            Ok(mut data) => match inst.validate_foreign_state(function, &mut data) {
                Ok(()) => store_snapshot(inst, function, slot, Slot::Out, data),
                Err(status) => status,
            },
            Err(reason) => inst.error(function, format_args!("refused: {reason}")),
        }
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, function, |f| write!(f, "size = {size}"), body) }
}

/// An optional capability this layer does not offer: `fmi2Error` with the
/// reason, after the usual state check.
///
/// # Safety
/// `c` as for every FMI function.
unsafe fn not_offered<M: CoSimModel>(
    c: sys::fmi2Component,
    function: FmiFunction,
    capability: &'static str,
) -> sys::fmi2Status {
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe {
        call::<M, _, _>(
            c,
            function,
            |_| Ok(()),
            |inst| {
                inst.error(
                    function,
                    format_args!(
                        "not offered by this FMU (modelDescription declares {capability})"
                    ),
                )
            },
        )
    }
}

/// # Safety
/// `c` as for every FMI function; the other arguments are not read.
pub unsafe fn get_directional_derivative<M: CoSimModel>(c: sys::fmi2Component) -> sys::fmi2Status {
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe {
        not_offered::<M>(
            c,
            FmiFunction::GetDirectionalDerivative,
            "providesDirectionalDerivative=\"false\"",
        )
    }
}

/// # Safety
/// `c` as for every FMI function; the other arguments are not read.
pub unsafe fn set_real_input_derivatives<M: CoSimModel>(c: sys::fmi2Component) -> sys::fmi2Status {
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe {
        not_offered::<M>(
            c,
            FmiFunction::SetRealInputDerivatives,
            "canInterpolateInputs=\"false\"",
        )
    }
}

/// # Safety
/// `c` as for every FMI function; the other arguments are not read.
pub unsafe fn get_real_output_derivatives<M: CoSimModel>(c: sys::fmi2Component) -> sys::fmi2Status {
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe {
        not_offered::<M>(
            c,
            FmiFunction::GetRealOutputDerivatives,
            "maxOutputDerivativeOrder=\"0\"",
        )
    }
}

/// # Safety
/// `c` as for every FMI function. Only legal while an asynchronous step is in
/// progress, which never happens here, so the state check refuses it.
pub unsafe fn cancel_step<M: CoSimModel>(c: sys::fmi2Component) -> sys::fmi2Status {
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe {
        not_offered::<M>(
            c,
            FmiFunction::CancelStep,
            "canRunAsynchronuously=\"false\"",
        )
    }
}

/// # Safety
/// Arguments as `fmi2DoStep`.
pub unsafe fn do_step<M: CoSimModel>(
    c: sys::fmi2Component,
    current_communication_point: sys::fmi2Real,
    communication_step_size: sys::fmi2Real,
    _no_set_fmu_state_prior_to_current_point: sys::fmi2Boolean,
) -> sys::fmi2Status {
    let function = FmiFunction::DoStep;
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe {
        call::<M, _, _>(
            c,
            function,
            // By value: the arguments stay in registers unless tracing is on.
            move |f| {
                write!(
                    f,
                    "currentCommunicationPoint = {current_communication_point}, communicationStepSize = {communication_step_size}"
                )
            },
            |inst| inst.do_step(current_communication_point, communication_step_size),
        )
    }
}

/// A status query. Steps are never asynchronous, so only the last successful
/// time and the terminated flag are available; other kinds answer
/// `fmi2Discard`, as the standard prescribes for an unavailable status.
///
/// # Safety
/// `value` must be NULL or valid for a write of `T`.
unsafe fn status_query<M: CoSimModel, T>(
    c: sys::fmi2Component,
    function: FmiFunction,
    kind: sys::fmi2StatusKind,
    value: *mut T,
    answer: impl FnOnce(&Instance<M>, sys::fmi2StatusKind) -> Option<T>,
) -> sys::fmi2Status {
    let body = |inst: &mut Instance<M>| {
        // SAFETY: `value` is the importer's output variable when non-NULL
        // (this function's contract).
        let value = match unsafe { value_out(inst, function, value, "value") } {
            Ok(value) => value,
            Err(status) => return status,
        };
        match answer(inst, kind) {
            Some(v) => {
                value.write(v);
                Status::Ok
            }
            None => {
                inst.env.logger.log_in(
                    function.name(),
                    Status::Discard,
                    LogCategory::StatusDiscard,
                    format_args!(
                        "status kind {kind} is not available here: this FMU never runs \
                         asynchronous steps"
                    ),
                );
                Status::Discard
            }
        }
    };
    // SAFETY: `c` as for every FMI function (this function's contract).
    unsafe { call::<M, _, _>(c, function, |f| write!(f, "status kind {kind}"), body) }
}

/// # Safety
/// Arguments as `fmi2GetStatus`.
pub unsafe fn get_status<M: CoSimModel>(
    c: sys::fmi2Component,
    kind: sys::fmi2StatusKind,
    value: *mut sys::fmi2Status,
) -> sys::fmi2Status {
    // SAFETY: the arguments are this function's, under the same contract.
    unsafe { status_query::<M, _>(c, FmiFunction::GetStatus, kind, value, |_, _| None) }
}

/// # Safety
/// Arguments as `fmi2GetRealStatus`.
pub unsafe fn get_real_status<M: CoSimModel>(
    c: sys::fmi2Component,
    kind: sys::fmi2StatusKind,
    value: *mut sys::fmi2Real,
) -> sys::fmi2Status {
    // SAFETY: the arguments are this function's, under the same contract.
    unsafe {
        status_query::<M, _>(c, FmiFunction::GetRealStatus, kind, value, |inst, kind| {
            (kind == sys::fmi2StatusKind_fmi2LastSuccessfulTime).then_some(inst.time)
        })
    }
}

/// # Safety
/// Arguments as `fmi2GetIntegerStatus`.
pub unsafe fn get_integer_status<M: CoSimModel>(
    c: sys::fmi2Component,
    kind: sys::fmi2StatusKind,
    value: *mut sys::fmi2Integer,
) -> sys::fmi2Status {
    // SAFETY: the arguments are this function's, under the same contract.
    unsafe { status_query::<M, _>(c, FmiFunction::GetIntegerStatus, kind, value, |_, _| None) }
}

/// # Safety
/// Arguments as `fmi2GetBooleanStatus`.
pub unsafe fn get_boolean_status<M: CoSimModel>(
    c: sys::fmi2Component,
    kind: sys::fmi2StatusKind,
    value: *mut sys::fmi2Boolean,
) -> sys::fmi2Status {
    // SAFETY: the arguments are this function's, under the same contract.
    unsafe {
        status_query::<M, _>(
            c,
            FmiFunction::GetBooleanStatus,
            kind,
            value,
            |inst, kind| {
                // Whether the model asked, in a discarded step, to end the
                // simulation.
                (kind == sys::fmi2StatusKind_fmi2Terminated)
                    .then_some(inst.terminate_requested as sys::fmi2Boolean)
            },
        )
    }
}

/// # Safety
/// Arguments as `fmi2GetStringStatus`.
pub unsafe fn get_string_status<M: CoSimModel>(
    c: sys::fmi2Component,
    kind: sys::fmi2StatusKind,
    value: *mut sys::fmi2String,
) -> sys::fmi2Status {
    // SAFETY: the arguments are this function's, under the same contract.
    unsafe { status_query::<M, _>(c, FmiFunction::GetStringStatus, kind, value, |_, _| None) }
}

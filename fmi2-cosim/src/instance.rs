//! One FMU instance: the state machine and the rules of every FMI call, in safe
//! Rust. `abi` turns C pointers into the slices these methods take; the model
//! only sees validated calls in legal states.

use std::cell::{Ref, RefCell};
use std::ffi::CString;
use std::fmt;
use std::ops::Deref;
use std::path::PathBuf;

use crate::fmu_state::SnapshotData;
use crate::logging::{LogCategory, Logger};
use crate::model::{CoSimModel, Context, Environment, StepOutcome};
use crate::model_description::format_real;
use crate::status::{FmiFunction, FmiState, Interface, Status};
use crate::variables::{Causality, Value, Variability, Variable};

/// Marks a live instance allocated by this layer (checked before use), before
/// it is made model-specific by [`Magic`].
const INSTANCE_MAGIC: u64 = 0x5453_4e49_3249_4d46;
/// The same for FMU states (`fmu_state::Snapshot`).
const SNAPSHOT_MAGIC: u64 = 0x5453_5332_494d_4646;

/// FNV-1a of `bytes`, continuing from `hash`.
const fn fnv1a(mut hash: u64, bytes: &[u8]) -> u64 {
    let mut i = 0;
    while i < bytes.len() {
        hash ^= bytes[i] as u64;
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
        i += 1;
    }
    hash
}

/// The magic numbers of model `M`'s instances and FMU states. They differ
/// between models (identifier, version and memory layout are hashed in) so
/// that an importer that passes another FMU's instance or state to this
/// binary, both built with this layer, is refused instead of having its
/// object read and written as one of `M`'s.
pub(crate) struct Magic<M>(std::marker::PhantomData<M>);

impl<M: CoSimModel> Magic<M> {
    const TAG: u64 = {
        let info = M::INFO;
        let mut hash = fnv1a(0xcbf2_9ce4_8422_2325, info.model_identifier.as_bytes());
        hash = fnv1a(hash, info.version.as_bytes());
        hash = fnv1a(hash, &(std::mem::size_of::<M>() as u64).to_le_bytes());
        fnv1a(hash, &(std::mem::align_of::<M>() as u64).to_le_bytes())
    };
    /// Never 0, the value a freed object is poisoned with.
    pub(crate) const INSTANCE: u64 = match INSTANCE_MAGIC ^ Self::TAG {
        0 => INSTANCE_MAGIC,
        magic => magic,
    };
    pub(crate) const SNAPSHOT: u64 = match SNAPSHOT_MAGIC ^ Self::TAG {
        0 => SNAPSHOT_MAGIC,
        magic => magic,
    };
}

/// Share of a step by which it may end past stopTime (rounding of summed
/// communication points, not a step more).
const STOP_TIME_SLACK: f64 = 1e-3;

/// `repr(C)` with the magic number first, so that a pointer can be recognised
/// by reading its first eight bytes before it is used as an instance.
#[repr(C)]
pub struct Instance<M: CoSimModel> {
    pub(crate) magic: u64,
    pub(crate) state: FmiState,
    /// The logger, resources folder and interface, which the model reaches
    /// through its [`Context`].
    pub(crate) env: Environment,
    /// The time the instance stands at: after a discarded step, the last
    /// successful time (`fmi2LastSuccessfulTime`).
    pub(crate) time: f64,
    pub(crate) start_time: f64,
    /// The end fmi2SetupExperiment defined (infinite when it defined none):
    /// a co-simulation step must not end past it (FMI 2.0.4 §2.1.6).
    pub(crate) stop_time: f64,
    /// The model asked to end the simulation in its last step
    /// (`fmi2GetBooleanStatus(fmi2Terminated)`).
    pub(crate) terminate_requested: bool,
    pub(crate) model: M,
    pub(crate) guid: String,
    /// FMU states this instance made and the importer has not freed:
    /// `fmi2FreeInstance` frees them (FMI 2.0.4 §2.1.5: it frees all memory
    /// the FMU interface allocated for the instance).
    pub(crate) fmu_states: Vec<*mut std::ffi::c_void>,
    /// The strings the last `fmi2GetString` handed out: the FMU owns them,
    /// and they stay valid until the next `fmi2GetString` on this instance
    /// refills the buffer, or the instance is freed (FMI 2.0.4 §2.1.7 asks
    /// for them to last until the next call of any FMI function on it).
    pub(crate) strings: Vec<CString>,
    /// In Initialization Mode, the model as `fmi2ExitInitializationMode`
    /// would build it from the values set so far: what the getters read there,
    /// since an InitialUnknown is a function of the knowns set (the FMI 2.0
    /// schema's `InitialUnknowns`), not of the start values. Built by the
    /// first getter that needs it, dropped by every change of a value, time
    /// or state.
    pub(crate) preview: RefCell<Option<M>>,
}

/// The model a getter reads: the instance's own, or in Initialization Mode
/// its preview ([`Instance::readable`]).
pub(crate) enum Readable<'a, M> {
    Own(&'a M),
    Preview(Ref<'a, M>),
}

impl<M> Deref for Readable<'_, M> {
    type Target = M;
    fn deref(&self) -> &M {
        match self {
            Readable::Own(model) => model,
            Readable::Preview(model) => model,
        }
    }
}

/// What a setter does with one value after validation.
#[derive(Clone, Copy, PartialEq, Eq)]
enum SetAction {
    Apply,
    /// A fixed parameter written again after initialization with the value it
    /// already has: accepted with a warning.
    KeepSameValue,
}

/// A value type served by fmi2GetXXX and fmi2SetXXX by value (Real,
/// Integer, Boolean; Strings are lent and copied, see [`StringArg`]).
pub(crate) trait FmiValue: Copy + PartialOrd + fmt::Display {
    const TYPE_NAME: &'static str;
    /// What the importer may pass, said when a value is refused.
    const ACCEPTED: &'static str = "";
    fn getter<M>(value: &Value<M>) -> Option<fn(&M) -> Self>;
    fn setter<M>(value: &Value<M>) -> Option<fn(&mut M, Self)>;
    /// The independent variable's value at `time`, for the type it has
    /// (Real).
    fn time(time: f64) -> Option<Self> {
        let _ = time;
        None
    }
    /// Why the value cannot be stored, if it cannot.
    fn invalid(self) -> Option<&'static str> {
        None
    }
    /// The declared `(min, max)` of a variable of this type.
    fn range<M>(value: &Value<M>) -> (Option<Self>, Option<Self>) {
        let _ = value;
        (None, None)
    }
}

impl FmiValue for f64 {
    const TYPE_NAME: &'static str = "Real";
    const ACCEPTED: &'static str = "only finite values are accepted";
    fn getter<M>(value: &Value<M>) -> Option<fn(&M) -> f64> {
        match value {
            Value::Real(r) => Some(r.get),
            _ => None,
        }
    }
    fn setter<M>(value: &Value<M>) -> Option<fn(&mut M, f64)> {
        match value {
            Value::Real(r) => r.set,
            _ => None,
        }
    }
    fn range<M>(value: &Value<M>) -> (Option<f64>, Option<f64>) {
        match value {
            Value::Real(r) => (r.min, r.max),
            _ => (None, None),
        }
    }
    fn time(time: f64) -> Option<f64> {
        Some(time)
    }
    /// One test for the finite value every set call passes; which of NaN
    /// and infinity it is, only when it is one.
    #[inline]
    fn invalid(self) -> Option<&'static str> {
        if self.is_finite() {
            None
        } else {
            Some(non_finite(self))
        }
    }
}

#[cold]
#[inline(never)]
fn non_finite(value: f64) -> &'static str {
    if value.is_nan() { "NaN" } else { "infinite" }
}

impl FmiValue for i32 {
    const TYPE_NAME: &'static str = "Integer";
    fn getter<M>(value: &Value<M>) -> Option<fn(&M) -> i32> {
        match value {
            Value::Integer(i) => Some(i.get),
            _ => None,
        }
    }
    fn setter<M>(value: &Value<M>) -> Option<fn(&mut M, i32)> {
        match value {
            Value::Integer(i) => i.set,
            _ => None,
        }
    }
    fn range<M>(value: &Value<M>) -> (Option<i32>, Option<i32>) {
        match value {
            Value::Integer(i) => (i.min, i.max),
            _ => (None, None),
        }
    }
}

impl FmiValue for bool {
    const TYPE_NAME: &'static str = "Boolean";
    fn getter<M>(value: &Value<M>) -> Option<fn(&M) -> bool> {
        match value {
            Value::Boolean(b) => Some(b.get),
            _ => None,
        }
    }
    fn setter<M>(value: &Value<M>) -> Option<fn(&mut M, bool)> {
        match value {
            Value::Boolean(b) => b.set,
            _ => None,
        }
    }
}

/// One element of `fmi2SetString`'s `value[]`, as the gate read it: the
/// importer's text, or why it is not one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum StringArg<'a> {
    Text(&'a str),
    Null,
    /// Not UTF-8 (the text of a String variable and of modelDescription is).
    NotUtf8,
}

impl fmt::Display for StringArg<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StringArg::Text(text) => write!(f, "{text:?}"),
            StringArg::Null => f.write_str("NULL"),
            StringArg::NotUtf8 => f.write_str("(bytes that are not UTF-8)"),
        }
    }
}

/// What the rules of `fmi2SetXXX` need of a value: its type, whether it can
/// be stored, how it compares with the variable's current value, and how to
/// store it.
pub(crate) trait SetValue: Copy + fmt::Display {
    const TYPE_NAME: &'static str;
    const ACCEPTED: &'static str;
    fn invalid(self) -> Option<&'static str>;
    /// The variable's current value, written out, when it is not `self`.
    fn differs<M>(self, value: &Value<M>, model: &M) -> Option<String>;
    /// Stores `self` through the variable's setter (there is one: checked).
    fn write<M>(self, value: &Value<M>, model: &mut M);
    /// Whether `self` is a valid value of the variable's type and the
    /// variable has a setter.
    #[inline]
    fn accepted_by<M>(self, value: &Value<M>) -> bool {
        self.invalid().is_none() && Self::has_setter(value)
    }
    /// Whether the variable is of this type and has a setter.
    fn has_setter<M>(value: &Value<M>) -> bool;
    /// The variable's declared range, written out, when `self` is outside it.
    fn out_of_range<M>(self, value: &Value<M>) -> Option<String>;
}

impl<T: FmiValue> SetValue for T {
    const TYPE_NAME: &'static str = T::TYPE_NAME;
    const ACCEPTED: &'static str = T::ACCEPTED;
    fn invalid(self) -> Option<&'static str> {
        FmiValue::invalid(self)
    }
    fn differs<M>(self, value: &Value<M>, model: &M) -> Option<String> {
        let current = T::getter(value)?(model);
        (current != self).then(|| current.to_string())
    }
    fn write<M>(self, value: &Value<M>, model: &mut M) {
        let set = T::setter(value).expect("checked by check_set");
        set(model, self);
    }
    #[inline]
    fn has_setter<M>(value: &Value<M>) -> bool {
        T::setter(value).is_some()
    }
    fn out_of_range<M>(self, value: &Value<M>) -> Option<String> {
        let (min, max) = T::range(value);
        let outside = min.is_some_and(|min| self < min) || max.is_some_and(|max| self > max);
        let bound = |b: Option<T>, inf: &str| b.map_or_else(|| inf.to_owned(), |b| b.to_string());
        outside.then(|| format!("[{}, {}]", bound(min, "-inf"), bound(max, "inf")))
    }
}

impl SetValue for StringArg<'_> {
    const TYPE_NAME: &'static str = "String";
    const ACCEPTED: &'static str =
        "a String value must point to a NUL-terminated UTF-8 string, which the FMU copies";
    fn invalid(self) -> Option<&'static str> {
        match self {
            StringArg::Text(_) => None,
            StringArg::Null => Some("a NULL pointer"),
            StringArg::NotUtf8 => Some("not valid UTF-8"),
        }
    }
    fn differs<M>(self, value: &Value<M>, model: &M) -> Option<String> {
        let (Value::String(s), StringArg::Text(text)) = (value, self) else {
            return Some("(not a String)".to_owned());
        };
        let current = (s.get)(model);
        (current != text).then(|| format!("{current:?}"))
    }
    fn write<M>(self, value: &Value<M>, model: &mut M) {
        let (Value::String(s), StringArg::Text(text)) = (value, self) else {
            unreachable!("checked by check_set");
        };
        let set = s.set.expect("checked by check_set");
        set(model, text);
    }
    fn has_setter<M>(value: &Value<M>) -> bool {
        matches!(value, Value::String(s) if s.set.is_some())
    }
    fn out_of_range<M>(self, _: &Value<M>) -> Option<String> {
        None
    }
}

impl<M: CoSimModel> Instance<M> {
    pub(crate) fn new(
        logger: Logger,
        interface: Interface,
        resource_dir: Option<PathBuf>,
        guid: String,
        model: M,
    ) -> Self {
        Instance {
            magic: Magic::<M>::INSTANCE,
            state: FmiState::Instantiated,
            env: Environment {
                logger,
                resource_dir,
                interface,
            },
            time: 0.0,
            start_time: 0.0,
            stop_time: f64::INFINITY,
            terminate_requested: false,
            model,
            guid,
            fmu_states: Vec::new(),
            strings: Vec::new(),
            preview: RefCell::new(None),
        }
    }

    /// The model the getters read, and the status of that reading: in
    /// Initialization Mode, when `computed()` (a value the model calculates is
    /// read), [`Instance::preview`], built when missing; else the instance's
    /// own. Values set so far that no initialization takes (the importer may
    /// be half way through setting them) cannot be computed: the getter
    /// then reads the instance's own model, whose calculated values are the
    /// start values', with `fmi2Warning` and the reason;
    /// `fmi2ExitInitializationMode` refuses them if they stay.
    pub(crate) fn readable(
        &self,
        function: FmiFunction,
        computed: impl FnOnce() -> bool,
    ) -> (Readable<'_, M>, Status) {
        // Asked only in Initialization Mode: between steps a getter pays one
        // compare.
        if self.state != FmiState::InitializationMode || !computed() {
            return (Readable::Own(&self.model), Status::Ok);
        }
        if self.preview.borrow().is_none() {
            let mut candidate = self.model.clone();
            let refused = match M::variables()
                .iter()
                .find_map(|var| parameter_out_of_range(var, &candidate))
            {
                Some(message) => Some(message),
                None => {
                    let mut ctx = Context {
                        env: &self.env,
                        function,
                    };
                    candidate
                        .exit_initialization_mode(&mut ctx, self.start_time)
                        .err()
                        .map(|e| e.to_string())
                }
            };
            if let Some(reason) = refused {
                self.env.logger.warning(
                    function.name(),
                    format_args!(
                        "the initial values cannot be computed from the values set so far \
                         ({reason}): the calculated values read are the start values'; \
                         fmi2ExitInitializationMode refuses these values if they stay"
                    ),
                );
                return (Readable::Own(&self.model), Status::Warning);
            }
            *self.preview.borrow_mut() = Some(candidate);
        }
        let preview = Ref::map(self.preview.borrow(), |p| p.as_ref().expect("built above"));
        (Readable::Preview(preview), Status::Ok)
    }

    /// Drops the preview: a value, the time or the state changed.
    pub(crate) fn forget_preview(&mut self) {
        *self.preview.get_mut() = None;
    }

    pub fn state(&self) -> FmiState {
        self.state
    }

    pub fn interface(&self) -> Interface {
        self.env.interface
    }

    /// Whether the instance is past initialization and simulating: the
    /// states in which fixed parameters are frozen.
    fn simulating(&self) -> bool {
        matches!(
            self.state,
            FmiState::StepComplete | FmiState::EventMode | FmiState::ContinuousTimeMode
        )
    }

    pub fn model(&self) -> &M {
        &self.model
    }

    /// The time the instance stands at; after a discarded step, the last
    /// successful time.
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Whether the model asked to end the simulation (answer of
    /// `fmi2GetBooleanStatus(fmi2Terminated)`).
    pub fn terminate_requested(&self) -> bool {
        self.terminate_requested
    }

    pub(crate) fn error(&self, function: FmiFunction, args: fmt::Arguments<'_>) -> Status {
        self.env.logger.error(function.name(), args);
        Status::Error
    }

    fn event(&self, function: FmiFunction, args: fmt::Arguments<'_>) {
        self.env
            .logger
            .log_in(function.name(), Status::Ok, LogCategory::Events, args);
    }

    /// After `fmi2Error` the instance accepts only what the error state allows
    /// (FMI 2.0.4 §2.1.3): getters, state handling, `fmi2Reset`, freeing.
    #[inline]
    pub(crate) fn enter_error_state(&mut self, status: Status) {
        // One compare on every call's way out; the states change only on
        // the rare error.
        if status >= Status::Error {
            self.enter_error_state_for(status);
        }
    }

    #[cold]
    #[inline(never)]
    fn enter_error_state_for(&mut self, status: Status) {
        match status {
            Status::Fatal => self.state = FmiState::Fatal,
            Status::Error if self.state != FmiState::Fatal => self.state = FmiState::Error,
            _ => {}
        }
    }

    fn variable(&self, function: FmiFunction, vr: u32) -> Result<&'static Variable<M>, Status> {
        M::variables().get(vr as usize).ok_or_else(|| {
            self.error(
                function,
                format_args!(
                    "unknown value reference {vr} (this FMU has value references 0..{})",
                    M::variables().len().saturating_sub(1)
                ),
            )
        })
    }

    pub(crate) fn set_debug_logging(&mut self, logging_on: bool, categories: &[&str]) -> Status {
        let function = FmiFunction::SetDebugLogging;
        if categories.is_empty() {
            self.env.logger.set_all(logging_on);
            return Status::Ok;
        }
        let mut status = Status::Ok;
        for name in categories {
            if *name == LogCategory::ALL_NAME {
                self.env.logger.set_all(logging_on);
            } else if let Some(category) = LogCategory::from_name(name) {
                self.env.logger.set(category, logging_on);
            } else {
                self.env.logger.warning(
                    function.name(),
                    format_args!(
                        "unknown log category {name:?} ignored (known: logEvents, logStatusWarning, \
                         logStatusDiscard, logStatusError, logStatusFatal, logFmiCalls, logAll)"
                    ),
                );
                status = Status::Warning;
            }
        }
        status
    }

    pub(crate) fn setup_experiment(&mut self, start_time: f64, stop_time: Option<f64>) -> Status {
        let function = FmiFunction::SetupExperiment;
        if !start_time.is_finite() {
            return self.error(
                function,
                format_args!("startTime must be finite (got {start_time})"),
            );
        }
        if let Some(stop) = stop_time
            && (stop.is_nan() || stop < start_time)
        {
            return self.error(
                function,
                format_args!("stopTime {stop} is before startTime {start_time}"),
            );
        }
        self.start_time = start_time;
        self.stop_time = stop_time.unwrap_or(f64::INFINITY);
        self.time = start_time;
        self.forget_preview();
        Status::Ok
    }

    pub(crate) fn enter_initialization_mode(&mut self) -> Status {
        self.forget_preview();
        self.state = FmiState::InitializationMode;
        self.event(
            FmiFunction::EnterInitializationMode,
            format_args!("entered initialization mode"),
        );
        Status::Ok
    }

    /// Checks every parameter against its declared range, then lets the model
    /// validate the rest and build its initial state.
    pub(crate) fn exit_initialization_mode(&mut self) -> Status {
        let function = FmiFunction::ExitInitializationMode;
        self.forget_preview();
        let mut violations = 0;
        for var in M::variables() {
            if let Some(message) = parameter_out_of_range(var, &self.model) {
                self.env
                    .logger
                    .error(function.name(), format_args!("{message}"));
                violations += 1;
            }
        }
        if violations > 0 {
            return Status::Error;
        }
        let mut ctx = Context {
            env: &self.env,
            function,
        };
        if let Err(e) = self
            .model
            .exit_initialization_mode(&mut ctx, self.start_time)
        {
            return self.error(function, format_args!("{e}"));
        }
        self.time = self.start_time;
        self.state = match self.env.interface {
            Interface::CoSimulation => FmiState::StepComplete,
            Interface::ModelExchange => FmiState::EventMode,
        };
        self.event(
            function,
            format_args!("initialized at t = {}", self.start_time),
        );
        Status::Ok
    }

    pub(crate) fn terminate(&mut self) -> Status {
        self.state = FmiState::Terminated;
        self.event(
            FmiFunction::Terminate,
            format_args!("terminated at t = {}", self.time),
        );
        Status::Ok
    }

    /// Back to the state after `fmi2Instantiate`, start values included; the
    /// importer's logging choices are kept.
    pub(crate) fn reset(&mut self) -> Status {
        self.forget_preview();
        self.model = M::new();
        self.state = FmiState::Instantiated;
        self.time = 0.0;
        self.start_time = 0.0;
        self.stop_time = f64::INFINITY;
        self.terminate_requested = false;
        self.event(FmiFunction::Reset, format_args!("reset to start values"));
        Status::Ok
    }

    /// Refuses value reference `vr` of `var` for a call on another type.
    fn wrong_type(
        &self,
        function: FmiFunction,
        vr: u32,
        var: &Variable<M>,
        wanted: &str,
    ) -> Status {
        self.error(
            function,
            format_args!(
                "value reference {vr} ({}) is a {} variable, not {wanted}",
                var.name,
                var.value.type_name(),
            ),
        )
    }

    /// Reads `vrs` and hands the i-th value to `store(i, value)`. The
    /// independent variable reads the instance's time. A state derivative
    /// that is not finite is refused as `fmi2GetDerivatives` refuses it: the
    /// importer sets the states and parameters of Model Exchange, and the
    /// rates of some may overflow.
    pub(crate) fn get_values<T: FmiValue>(
        &self,
        function: FmiFunction,
        vrs: &[u32],
        mut store: impl FnMut(usize, T),
    ) -> Status {
        let (model, status) = self.readable(function, || reads_calculated::<M>(vrs));
        for (i, vr) in vrs.iter().enumerate() {
            let var = match self.variable(function, *vr) {
                Ok(var) => var,
                Err(status) => return status,
            };
            let value = match (T::getter(&var.value), &var.value) {
                (Some(get), _) => get(&model),
                (None, Value::Time(_)) => match T::time(self.time) {
                    Some(time) => time,
                    None => return self.wrong_type(function, *vr, var, T::TYPE_NAME),
                },
                (None, _) => return self.wrong_type(function, *vr, var, T::TYPE_NAME),
            };
            // Folds away in a model without Model Exchange (no derivatives).
            if M::MODEL_EXCHANGE.is_some()
                && var.derivative_of.is_some()
                && let Some(reason) = value.invalid()
            {
                return self.error(
                    function,
                    format_args!(
                        "at t = {}: {} is {reason}; the states or inputs are outside the \
                         model's domain",
                        self.time, var.name
                    ),
                );
            }
            store(i, value);
        }
        status
    }

    /// Reads the String variables `vrs` into the instance's buffer of C
    /// strings ([`Instance::strings`], refilled: the strings of the previous
    /// call are released). A model value that holds a NUL byte cannot be a
    /// C string and is refused.
    pub(crate) fn get_strings(&mut self, function: FmiFunction, vrs: &[u32]) -> Status {
        let mut strings = std::mem::take(&mut self.strings);
        strings.clear();
        let (model, status) = self.readable(function, || reads_calculated::<M>(vrs));
        for vr in vrs {
            let var = match self.variable(function, *vr) {
                Ok(var) => var,
                Err(status) => return status,
            };
            let Value::String(s) = &var.value else {
                return self.wrong_type(function, *vr, var, "String");
            };
            match CString::new((s.get)(&model)) {
                Ok(text) => strings.push(text),
                Err(e) => {
                    return self.error(
                        function,
                        format_args!(
                            "value reference {vr} ({}) holds a NUL byte at offset {}, which a C \
                             string cannot carry (a fault of the model)",
                            var.name,
                            e.nul_position()
                        ),
                    );
                }
            }
        }
        drop(model);
        self.strings = strings;
        status
    }

    /// Whether `var` (value reference `vr`) may receive `value` now. Errors
    /// are logged here.
    fn check_set<T: SetValue>(
        &self,
        function: FmiFunction,
        vr: u32,
        var: &Variable<M>,
        value: T,
    ) -> Result<SetAction, Status> {
        if var.value.type_name() != T::TYPE_NAME {
            return Err(self.wrong_type(function, vr, var, T::TYPE_NAME));
        }
        if let Some(reason) = value.invalid() {
            return Err(self.error(
                function,
                format_args!(
                    "value reference {vr} ({}): the value is {reason}; {}",
                    var.name,
                    T::ACCEPTED
                ),
            ));
        }
        if !var.is_settable() {
            let why = match (var.causality, var.variability) {
                (Causality::Independent, _) => {
                    "it is the independent variable, the FMU's time, which fmi2SetupExperiment \
                     and fmi2DoStep move (fmi2SetTime in Model Exchange)"
                }
                (_, Variability::Constant) => "it is a constant",
                _ => "",
            };
            return Err(self.error(
                function,
                format_args!(
                    "value reference {vr} ({}) cannot be set: its causality is {}{}{why}",
                    var.name,
                    var.causality.as_str(),
                    if why.is_empty() { "" } else { "; " },
                ),
            ));
        }
        match self.state {
            FmiState::Instantiated | FmiState::InitializationMode => Ok(SetAction::Apply),
            // FMI 2.0.4 §3.2.3: between events only continuous inputs move.
            FmiState::ContinuousTimeMode => {
                if var.causality == Causality::Input && var.variability == Variability::Continuous {
                    Ok(SetAction::Apply)
                } else {
                    Err(self.error(
                        function,
                        format_args!(
                            "{} cannot be set in continuous-time mode (only continuous inputs \
                             can); set it in event mode",
                            var.name
                        ),
                    ))
                }
            }
            FmiState::StepComplete | FmiState::EventMode => {
                match (var.causality, var.variability) {
                    (Causality::Input, _) => Ok(SetAction::Apply),
                    // Nothing checks a tunable parameter after this call
                    // (initialization checked the others), so its declared
                    // range is checked here.
                    (Causality::Parameter, Variability::Tunable) => {
                        if let Some(range) = value.out_of_range(&var.value) {
                            Err(self.error(
                                function,
                                format_args!(
                                    "tunable parameter {} = {value} is outside its allowed \
                                     range {range}; it keeps its value, and the instance is in \
                                     the error state (fmi2Reset, or fmi2SetFMUstate of a saved \
                                     state, continues)",
                                    var.name
                                ),
                            ))
                        } else {
                            Ok(SetAction::Apply)
                        }
                    }
                    (Causality::Parameter, Variability::Fixed) => {
                        match value.differs(&var.value, &self.model) {
                            None => Ok(SetAction::KeepSameValue),
                            Some(current) => Err(self.error(
                                function,
                                format_args!(
                                    "{} is a fixed parameter: it cannot change after \
                                     initialization (it is {current}, {value} was requested); \
                                     use fmi2Reset",
                                    var.name
                                ),
                            )),
                        }
                    }
                    _ => Err(self.error(
                        function,
                        format_args!("{} cannot be set after initialization", var.name),
                    )),
                }
            }
            other => Err(self.error(
                function,
                format_args!("values cannot be set in state {}", other.name()),
            )),
        }
    }

    /// Whether the call is what an importer makes at every communication
    /// point, which [`Instance::check_set`] accepts: between steps (or events,
    /// or in continuous-time mode a continuous one), every value a valid
    /// value of an input of type `T`. One light pass over the values, so
    /// that the call that carries a loop's inputs pays for no more; any other
    /// call takes the full checks, which also say why a value is refused.
    #[inline]
    fn inputs_between_steps<T: SetValue>(
        &self,
        vrs: &[u32],
        value_at: &impl Fn(usize) -> T,
    ) -> bool {
        let continuous_only = match self.state {
            FmiState::StepComplete | FmiState::EventMode => false,
            FmiState::ContinuousTimeMode => true,
            _ => return false,
        };
        vrs.iter().enumerate().all(|(i, vr)| {
            M::variables().get(*vr as usize).is_some_and(|var| {
                var.causality == Causality::Input
                    && (!continuous_only || var.variability == Variability::Continuous)
                    && value_at(i).accepted_by(&var.value)
            })
        })
    }

    /// Validates every value (the i-th read by `value_at(i)`) first and applies
    /// them only if all are valid, so a refused call changes nothing.
    pub(crate) fn set_values<T: SetValue>(
        &mut self,
        function: FmiFunction,
        vrs: &[u32],
        value_at: impl Fn(usize) -> T,
    ) -> Status {
        // Between steps no preview exists: the fast path leaves it alone.
        if self.inputs_between_steps::<T>(vrs, &value_at) {
            for (i, vr) in vrs.iter().enumerate() {
                value_at(i).write(&M::variables()[*vr as usize].value, &mut self.model);
            }
            return Status::Ok;
        }
        self.forget_preview();
        let mut status = Status::Ok;
        for (i, vr) in vrs.iter().enumerate() {
            let value = value_at(i);
            let var = match self.variable(function, *vr) {
                Ok(var) => var,
                Err(status) => return status,
            };
            match self.check_set(function, *vr, var, value) {
                Ok(SetAction::Apply) => {}
                Ok(SetAction::KeepSameValue) => {
                    self.env.logger.warning(
                        function.name(),
                        format_args!(
                            "fixed parameter {} was written again after initialization with its \
                             current value {value}; accepted, nothing changes",
                            var.name
                        ),
                    );
                    status = Status::Warning;
                }
                Err(status) => return status,
            }
        }
        for (i, vr) in vrs.iter().enumerate() {
            let var = &M::variables()[*vr as usize];
            if self.simulating()
                && var.causality == Causality::Parameter
                && var.variability == Variability::Fixed
            {
                continue;
            }
            value_at(i).write(&var.value, &mut self.model);
        }
        status
    }

    #[inline]
    pub(crate) fn do_step(&mut self, current_time: f64, step_size: f64) -> Status {
        let function = FmiFunction::DoStep;
        let end = current_time + step_size;
        // The step is positive and finite, starts at the FMU's time (most
        // importers pass it exactly) and ends at a finite point (the next
        // communication point: no step could follow an infinite one). One
        // test of all of it on the way; the reason is worked out only when it
        // fails. The FMU's time is always finite (setupExperiment and a
        // restored state refuse any other, and every step ends at a finite
        // point), so a start equal to it is finite, and a positive step from
        // it ends above -inf: `end < inf` is all that is left of the end's
        // finiteness. A NaN fails every compare.
        // A step may end past stopTime by rounding only (below).
        let sound = (step_size > 0.0)
            & (end < f64::INFINITY)
            & (current_time == self.time)
            & (end <= self.stop_time);
        if !sound && let Err(status) = self.check_step(current_time, step_size) {
            return status;
        }
        // The time moves to the end before the model's step, so that the end
        // need not be kept across it; a step that does not complete (an
        // error, a discard, a panic) puts back the FMU's own time on the way
        // (not the communication point, which may miss it by rounding).
        let before = self.time;
        self.time = end;
        let rewind = Rewind {
            time: &mut self.time,
            start: before,
        };
        let mut ctx = Context {
            env: &self.env,
            function,
        };
        match self.model.do_step(&mut ctx, current_time, step_size) {
            Ok(StepOutcome::Completed) => {
                std::mem::forget(rewind);
                Status::Ok
            }
            Ok(StepOutcome::CompletedWithWarning) => {
                std::mem::forget(rewind);
                Status::Warning
            }
            Ok(StepOutcome::Discarded {
                last_successful_time,
            }) => {
                drop(rewind);
                self.discard(current_time, end, last_successful_time, false)
            }
            Ok(StepOutcome::Terminate {
                last_successful_time,
            }) => {
                drop(rewind);
                self.discard(current_time, end, last_successful_time, true)
            }
            // fmi2Error: the gate puts the instance in its error state.
            Err(e) => {
                drop(rewind);
                self.error(function, format_args!("at t = {current_time}: {e}"))
            }
        }
    }

    /// A step the model did not complete (FMI 2.0.4 §4.2.2, §4.2.4): the
    /// slave stands at the last successful time in `stepFailed`, and says
    /// whether it wants the simulation to end. A last successful time
    /// outside the step is a bug of the model: `fmi2Error`.
    #[cold]
    #[inline(never)]
    fn discard(
        &mut self,
        current_time: f64,
        end: f64,
        last_successful_time: f64,
        terminate: bool,
    ) -> Status {
        let function = FmiFunction::DoStep;
        // A discarded step ends before its end; a terminating one may end at it.
        let inside = current_time <= last_successful_time
            && (last_successful_time < end || (terminate && last_successful_time == end));
        if !inside {
            return self.error(
                function,
                format_args!(
                    "the model stopped the step from {current_time} to {end} at \
                     {last_successful_time}, outside the step"
                ),
            );
        }
        self.time = last_successful_time;
        self.state = FmiState::StepFailed;
        self.terminate_requested = terminate;
        self.env.logger.log_in(
            function.name(),
            Status::Discard,
            LogCategory::StatusDiscard,
            format_args!(
                "the step from {current_time} to {end} stopped at {last_successful_time}{}; \
                 fmi2LastSuccessfulTime is {last_successful_time}",
                if terminate {
                    ": the model asks to end the simulation (fmi2Terminated)"
                } else {
                    "; restore an FMU state to retry (a shorter step), or terminate"
                }
            ),
        );
        Status::Discard
    }

    /// Why the step of `step_size` from `current_time` cannot be made, if it
    /// cannot. Importers that keep time in integer nanoseconds (libcosim) or
    /// sum steps in floating point land a rounding error away from the FMU's
    /// time: a point within 1e-9 relative (at least 1e-9 absolute, at most
    /// half the step) of it is accepted, anything further refused.
    #[cold]
    #[inline(never)]
    fn check_step(&self, current_time: f64, step_size: f64) -> Result<(), Status> {
        let function = FmiFunction::DoStep;
        if !(step_size > 0.0 && step_size < f64::INFINITY) {
            return Err(self.error(
                function,
                format_args!("communicationStepSize must be positive and finite (got {step_size})"),
            ));
        }
        if !current_time.is_finite() {
            return Err(self.error(
                function,
                format_args!("currentCommunicationPoint must be finite (got {current_time})"),
            ));
        }
        if !(current_time + step_size).is_finite() {
            return Err(self.error(
                function,
                format_args!(
                    "the step from {current_time} by {step_size} ends beyond the largest \
                     representable time"
                ),
            ));
        }
        let tolerance = (1e-9 * current_time.abs().max(1.0)).min(0.5 * step_size);
        if (current_time - self.time).abs() > tolerance {
            return Err(self.error(
                function,
                format_args!(
                    "currentCommunicationPoint {current_time} does not continue from the FMU's time {} \
                     (tolerance {tolerance:e}); to go back, restore a state with fmi2SetFMUstate",
                    self.time
                ),
            ));
        }
        // Communication points summed step by step round: a step that ends
        // within 0.1 % of its size past stopTime is taken (its end stands).
        let end = current_time + step_size;
        if end > self.stop_time + STOP_TIME_SLACK * step_size {
            return Err(self.error(
                function,
                format_args!(
                    "the step from {current_time} to {end} ends past stopTime {} \
                     (fmi2SetupExperiment defined it); set up a later stopTime, or none",
                    self.stop_time
                ),
            ));
        }
        Ok(())
    }

    pub(crate) fn snapshot(&self) -> SnapshotData<M> {
        SnapshotData {
            model: self.model.clone(),
            time: self.time,
            start_time: self.start_time,
            stop_time: self.stop_time,
            interface: self.env.interface,
            state: self.state,
            terminate_requested: self.terminate_requested,
        }
    }

    /// Checks an FMU state that comes from outside (deserialized bytes: a
    /// valid checksum says they were written on purpose, not that they are a
    /// state this FMU can be in) before it can replace the instance's values,
    /// and lets the model rebuild what it derives from its parameters. The
    /// layer checks what its own calls guarantee of every live instance: a
    /// finite time (the independent variable's value), a machine state an
    /// instance of that interface is saved in, every Real of the variable
    /// table finite (state derivatives aside: `fmi2GetReal` refuses a
    /// non-finite one itself; and in the error state, which a diverged step
    /// may have left), no NUL byte in a String parameter or input, every
    /// constant at its start value, and, past initialization, every
    /// parameter in its declared range. Then the model's own hook
    /// ([`CoSimModel::validate_restored`]). The reason of a refusal is logged
    /// and returned.
    pub(crate) fn validate_foreign_state(
        &self,
        function: FmiFunction,
        data: &mut SnapshotData<M>,
    ) -> Result<(), Status> {
        let refuse =
            |reason: fmt::Arguments<'_>| self.error(function, format_args!("refused: {reason}"));
        if !(data.time.is_finite() && data.start_time.is_finite()) {
            return Err(refuse(format_args!(
                "the state's time {} (start time {}) is not finite",
                data.time, data.start_time
            )));
        }
        // A NaN stop time is refused too.
        if data.stop_time.is_nan() || data.stop_time < data.start_time {
            return Err(refuse(format_args!(
                "the state's stop time {} is before its start time {}",
                data.stop_time, data.start_time
            )));
        }
        if !can_be_saved_in(data.interface, data.state) {
            return Err(refuse(format_args!(
                "the state claims the machine state {}, which a {} instance is never saved in",
                data.state.name(),
                data.interface.name()
            )));
        }
        if data.terminate_requested && data.state != FmiState::StepFailed {
            return Err(refuse(format_args!(
                "the state says the model asked to terminate, which only a discarded step \
                 does, but its machine state is {}",
                data.state.name()
            )));
        }
        if data.state != FmiState::Error {
            // A derivative is not evaluated at all: it is computed from the
            // model's parameters and derived values, which only the model's
            // hook below rebuilds, and may not even be computable from
            // forged ones.
            for var in M::variables()
                .iter()
                .filter(|var| var.derivative_of.is_none())
            {
                let Some(get) = f64::getter(&var.value) else {
                    continue;
                };
                let value = get(&data.model);
                if !value.is_finite() {
                    return Err(refuse(format_args!(
                        "the state holds {} = {value}, and only finite values are held by an \
                         instance in {}",
                        var.name,
                        data.state.name()
                    )));
                }
            }
        }
        // A String parameter or input never holds a NUL byte: fmi2SetString
        // cannot pass one (and fmi2GetString could not hand it out).
        if let Some((var, at)) = M::variables().iter().find_map(|var| match &var.value {
            Value::String(s) if var.is_settable() => {
                (s.get)(&data.model).find('\0').map(|at| (var, at))
            }
            _ => None,
        }) {
            return Err(refuse(format_args!(
                "the state holds a NUL byte at offset {at} of the String {}, which no \
                 fmi2SetString can put there",
                var.name
            )));
        }
        // A constant holds its start value in every state (only models with
        // constants pay for the start-up model built to compare).
        let mut constants = M::variables()
            .iter()
            .filter(|var| var.variability == Variability::Constant)
            .peekable();
        if constants.peek().is_some() {
            let start = M::new();
            if let Some(var) = constants.find(|var| !same_value(var, &data.model, &start)) {
                return Err(refuse(format_args!(
                    "the state changes the constant {}, which holds its start value in every \
                     state",
                    var.name
                )));
            }
        }
        // Tunable ones too: fmi2SetReal refuses a value outside the range
        // while the model runs.
        if data.state.initialized()
            && let Some(reason) = M::variables()
                .iter()
                .find_map(|var| parameter_out_of_range(var, &data.model))
        {
            return Err(refuse(format_args!(
                "{reason}, and the state was taken after initialization ({})",
                data.state.name()
            )));
        }
        let mut ctx = Context {
            env: &self.env,
            function,
        };
        data.model
            .validate_restored(&mut ctx, data.state)
            .map_err(|e| refuse(format_args!("{e}")))
    }

    /// Restores what a snapshot holds: the model, the time and the state
    /// machine, and before initialization the experiment's start and stop
    /// times (after it, the instance keeps its own). The instance continues as the one the
    /// snapshot was taken from, from the state it was in then, whatever its
    /// own state now (FMI 2.0.4 §2.1.8 allows `fmi2SetFMUstate` in every state
    /// but the fatal one; after `fmi2Error` this is how an importer recovers,
    /// §2.1.3). Refused: a snapshot of the other interface, or one claiming a
    /// state no instance of this interface can be saved in (forged bytes).
    pub(crate) fn restore(&mut self, function: FmiFunction, data: &SnapshotData<M>) -> Status {
        if data.interface != self.env.interface {
            return self.error(
                function,
                format_args!(
                    "the state was taken from a {} instance and this instance is {}; \
                     restore it into an instance of the same interface",
                    data.interface.name(),
                    self.env.interface.name()
                ),
            );
        }
        if !can_be_saved_in(self.env.interface, data.state) {
            return self.error(
                function,
                format_args!(
                    "the state claims the machine state {}, which a {} instance is never \
                     saved in",
                    data.state.name(),
                    self.env.interface.name()
                ),
            );
        }
        self.forget_preview();
        self.model = data.model.clone();
        // A state taken after initialization continues in this instance's
        // experiment: its start and stop times stay this instance's, what the
        // importer said of this run (fmi2SetupExperiment, FMI 2.0.4 §2.1.6);
        // a run continued from a finished one's state (fmpy's fmu_state,
        // fmusim's --initial-fmu-state-file) would otherwise be refused at
        // its first step, past the old run's stop. A state taken before
        // initialization holds an experiment still being set up, which an
        // importer cannot set again once in Initialization Mode: it brings
        // its own.
        self.time = data.time;
        if matches!(
            data.state,
            FmiState::Instantiated | FmiState::InitializationMode
        ) {
            self.start_time = data.start_time;
            self.stop_time = data.stop_time;
        }
        self.state = data.state;
        self.terminate_requested = data.terminate_requested;
        self.event(
            function,
            format_args!(
                "state restored at t = {}, in {}",
                data.time,
                data.state.name()
            ),
        );
        Status::Ok
    }
}

/// Puts an instance's time back to the start of a step when dropped: what
/// a step that does not complete leaves (a completed step forgets it).
struct Rewind<'a> {
    time: &'a mut f64,
    start: f64,
}

impl Drop for Rewind<'_> {
    fn drop(&mut self) {
        *self.time = self.start;
    }
}

/// The states `fmi2GetFMUstate` can be called in (every live state) that an
/// instance of `interface` can reach.
fn can_be_saved_in(interface: Interface, state: FmiState) -> bool {
    let other = match interface {
        Interface::CoSimulation => Interface::ModelExchange,
        Interface::ModelExchange => Interface::CoSimulation,
    };
    state != FmiState::Fatal && !other.own_states().contains(state)
}

/// Whether `vrs` name a value the model calculates: not a parameter, an
/// input, the time or a constant, which read as set (or declared).
fn reads_calculated<M: CoSimModel>(vrs: &[u32]) -> bool {
    vrs.iter().any(|vr| {
        M::variables().get(*vr as usize).is_some_and(|var| {
            !matches!(
                var.causality,
                Causality::Parameter | Causality::Input | Causality::Independent
            ) && var.variability != Variability::Constant
        })
    })
}

/// A declared bound as an interval writes it, and whether that end is open:
/// the round value `outside` next to it (the double beyond the bound) when
/// the bound is the nearest double inside an open end, since FMI's bounds are
/// inclusive, else the bound itself.
fn interval_end(bound: f64, outside: f64) -> (bool, String) {
    let (bound_text, outside_text) = (format_real(bound), format_real(outside));
    if outside_text.len() < bound_text.len() {
        (true, outside_text)
    } else {
        (false, bound_text)
    }
}

/// The double beyond a declared bound, the way `next` steps: 0 beyond the
/// smallest normal double, which an open end at 0 declares (the subnormals
/// between them are out of range to C's `strtod`).
fn beyond(bound: f64, next: fn(f64) -> f64) -> f64 {
    if bound.abs() == f64::MIN_POSITIVE {
        0.0
    } else {
        next(bound)
    }
}

/// A declared minimum as the lower end of an interval: `(0` or `[1e-4`.
fn lower_end(min: f64) -> String {
    let (open, text) = interval_end(min, beyond(min, f64::next_down));
    format!("{}{text}", if open { '(' } else { '[' })
}

/// A declared maximum as the upper end of an interval: `1)` or `10]`.
fn upper_end(max: f64) -> String {
    let (open, text) = interval_end(max, beyond(max, f64::next_up));
    format!("{text}{}", if open { ')' } else { ']' })
}

/// Why the parameter `var` of `model` is outside its declared range, if it
/// is a parameter and is outside (a NaN is outside every range).
fn parameter_out_of_range<M>(var: &Variable<M>, model: &M) -> Option<String> {
    if var.causality != Causality::Parameter {
        return None;
    }
    let bound = |b: Option<String>, inf: &str| b.unwrap_or_else(|| inf.to_owned());
    match &var.value {
        Value::Real(r) => {
            let value = (r.get)(model);
            let below = r.min.is_some_and(|min| value.is_nan() || value < min);
            let above = r.max.is_some_and(|max| value.is_nan() || value > max);
            // An open end at 0 is declared as the smallest normal double, so
            // a subnormal value of the right sign is refused though it lies
            // inside "(0, ...": say why, or the message contradicts itself.
            let subnormal = |bound: Option<f64>, which: &str| {
                let inside_the_open_end = match bound {
                    Some(min) if min == f64::MIN_POSITIVE => value > 0.0,
                    Some(max) if max == -f64::MIN_POSITIVE => value < 0.0,
                    _ => false,
                };
                (inside_the_open_end && value.abs() < f64::MIN_POSITIVE).then(|| {
                    format!(
                        " (a subnormal double: the range ends at the smallest normal double, \
                         {}, as the declared {which} says)",
                        format_real(bound.unwrap_or_default())
                    )
                })
            };
            (below || above).then(|| {
                let note = if below {
                    subnormal(r.min, "min")
                } else {
                    subnormal(r.max, "max")
                };
                format!(
                    "parameter {} = {} is outside its allowed range {}, {}{}",
                    var.name,
                    // Not Display: it writes every digit of 1e-300.
                    format_real(value),
                    r.min.map_or("[-inf".to_owned(), lower_end),
                    r.max.map_or("inf]".to_owned(), upper_end),
                    note.unwrap_or_default()
                )
            })
        }
        Value::Integer(i) => {
            let value = (i.get)(model);
            let below = i.min.is_some_and(|min| value < min);
            let above = i.max.is_some_and(|max| value > max);
            (below || above).then(|| {
                format!(
                    "parameter {} = {value} is outside its allowed range [{}, {}]",
                    var.name,
                    bound(i.min.map(|v| v.to_string()), "-inf"),
                    bound(i.max.map(|v| v.to_string()), "inf")
                )
            })
        }
        Value::Boolean(_) | Value::String(_) | Value::Time(_) => None,
    }
}

/// Whether variable `var` has the same value in `a` and `b` (Reals by their
/// bits, so that a NaN equals itself; the time is not the model's).
fn same_value<M>(var: &Variable<M>, a: &M, b: &M) -> bool {
    match &var.value {
        Value::Real(r) => (r.get)(a).to_bits() == (r.get)(b).to_bits(),
        Value::Integer(i) => (i.get)(a) == (i.get)(b),
        Value::Boolean(v) => (v.get)(a) == (v.get)(b),
        Value::String(s) => (s.get)(a) == (s.get)(b),
        Value::Time(_) => true,
    }
}

//! The importer side of FMI 2.0 co-simulation and Model Exchange: what every
//! tool that loads an FMU binary needs, and nothing that judges the FMU.
//!
//! `dlopen` of the built library with every symbol resolved through the
//! official typedefs of `fmi2FunctionTypes.h` (fmi-sys's bindgen output, so a
//! signature drift is a type error here), the modelDescription parsed with
//! fmi-schema, an instance handle that frees itself, and a logger that formats
//! messages the way printf-style importers do. [`archive`] opens a `.fmu`
//! (or its unpacked folder) and finds this platform's binary;
//! [`model_exchange`] adds the Model Exchange calls, instantiation for Model
//! Exchange and a fixed-step integrator that drives an instance.
//!
//! The conformance harness (`fmi2-conformance`), the identification command
//! (`piezo-identify`), the benchmarks (`fmu-bench`) and the co-simulation
//! master (`piezo-cosim`) stand on this crate; the checks live in the harness.

// An importer hands FMU-state pointers that the FMU gave it back to the FMU;
// validating them is the FMU's job.
#![allow(clippy::not_unsafe_ptr_arg_deref)]

use std::ffi::{CStr, CString, c_char, c_void};
use std::path::{Path, PathBuf};
use std::ptr;
use std::sync::Mutex;

use fmi_schema::fmi2::{Fmi2ModelDescription, ScalarVariableElement};
use fmi_schema::traits::FmiModelDescription;
use fmi_sys::fmi2 as sys;
use fmi_sys::fmi2::Fmi2Binding;

pub mod archive;
mod cdylib;
pub mod model_exchange;
pub mod parameter_set;

pub use cdylib::{cdylib_path, cdylib_sources};

pub use archive::{FmuArchive, OpenError};
/// The variable attributes an importer sorts by (fmi-schema's types).
pub use fmi_schema::fmi2::{Causality, Variability};

pub const OK: sys::fmi2Status = sys::fmi2Status_fmi2OK;
pub const WARNING: sys::fmi2Status = sys::fmi2Status_fmi2Warning;
pub const DISCARD: sys::fmi2Status = sys::fmi2Status_fmi2Discard;
pub const ERROR: sys::fmi2Status = sys::fmi2Status_fmi2Error;
pub const FATAL: sys::fmi2Status = sys::fmi2Status_fmi2Fatal;

/// One message the FMU sent to the logger, after printf-style formatting.
#[derive(Clone, Debug, PartialEq)]
pub struct LogRecord {
    pub instance_name: String,
    pub status: sys::fmi2Status,
    pub category: String,
    pub message: String,
}

/// Where the log messages of one instance go (its `componentEnvironment`).
#[derive(Default)]
pub struct LogSink {
    records: Mutex<Vec<LogRecord>>,
}

unsafe extern "C" {
    /// The variadic logger in c/logger_shim.c, with the exact parameter types of
    /// `fmi2CallbackLogger`.
    fn fmi2_import_logger(
        environment: sys::fmi2ComponentEnvironment,
        instance_name: sys::fmi2String,
        status: sys::fmi2Status,
        category: sys::fmi2String,
        message: sys::fmi2String,
        ...
    );
}

fn lossy(s: *const c_char) -> String {
    if s.is_null() {
        "(NULL)".to_owned()
    } else {
        // SAFETY: non-NULL (checked above) and NUL-terminated: the FMU and the C logger shim
        // pass C strings (`fmi2String`).
        unsafe { CStr::from_ptr(s) }.to_string_lossy().into_owned()
    }
}

/// Called by the C shim with the formatted message.
#[unsafe(no_mangle)]
extern "C" fn fmi2_import_record(
    environment: *mut c_void,
    instance_name: *const c_char,
    status: sys::fmi2Status,
    category: *const c_char,
    message: *const c_char,
) {
    if environment.is_null() {
        return;
    }
    // SAFETY: the environment is the boxed `LogSink` that `callbacks_for` passed as
    // `componentEnvironment`; the `Instance` owns that box and frees the FMU instance (the
    // only caller of the logger) before it; `LogSink` is shared through a Mutex.
    let sink = unsafe { &*(environment as *const LogSink) };
    let record = LogRecord {
        instance_name: lossy(instance_name),
        status,
        category: lossy(category),
        message: lossy(message),
    };
    sink.records
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push(record);
}

/// The importer-side description of a variable.
#[derive(Clone, Debug)]
pub struct VariableInfo {
    pub name: String,
    pub vr: u32,
    pub causality: Causality,
    pub variability: Option<Variability>,
    pub kind: &'static str,
    pub start: Option<f64>,
    /// The start value of a String variable (fmi-schema keeps none).
    pub start_string: Option<String>,
    /// The declared range (`min`, `max` of the Real or Integer element).
    pub min: Option<f64>,
    pub max: Option<f64>,
    /// The `unit` of the Real element (`um`, `rad`), if it gives one.
    pub unit: Option<String>,
}

/// A loaded FMU binary and its modelDescription.
pub struct Fmu {
    pub binding: Fmi2Binding,
    pub library_path: PathBuf,
    pub guid: String,
    pub description: Fmi2ModelDescription,
    pub variables: Vec<VariableInfo>,
}

impl Fmu {
    /// Loads `library` (dlopen) and parses `model_description` with fmi-schema;
    /// panics with the reason (for tests).
    pub fn load(library: &Path, model_description: &str) -> Fmu {
        Fmu::try_load(library, model_description).unwrap_or_else(|e| panic!("{e}"))
    }

    /// Like [`Fmu::load`], with the reason as an error (for tools).
    pub fn try_load(library: &Path, model_description: &str) -> Result<Fmu, String> {
        // SAFETY: loading runs the library's initializers; an FMI 2.0 binary has none with
        // preconditions, and the binding resolves each function with the standard's signature
        // (fmi-sys).
        let binding = unsafe { Fmi2Binding::new(library) }
            .map_err(|e| format!("cannot load {}: {e}", library.display()))?;
        let description = Fmi2ModelDescription::deserialize(model_description)
            .map_err(|e| format!("modelDescription does not parse with fmi-schema: {e}"))?;
        // fmi-schema does not parse min/max, nor a String's start; they are
        // read here, in document order.
        let extras = type_attributes(model_description)?;
        if extras.len() != description.model_variables.variables.len() {
            return Err(format!(
                "{} ScalarVariables parsed but {} type elements read",
                description.model_variables.variables.len(),
                extras.len()
            ));
        }
        let variables = description
            .model_variables
            .variables
            .iter()
            .zip(extras)
            .map(|(v, extra)| {
                let (kind, start) = match &v.elem {
                    ScalarVariableElement::Real(r) => ("Real", r.start),
                    ScalarVariableElement::Integer(i) => ("Integer", i.start.map(f64::from)),
                    ScalarVariableElement::Boolean(b) => {
                        ("Boolean", b.start.map(|b| if b { 1.0 } else { 0.0 }))
                    }
                    ScalarVariableElement::String => ("String", None),
                    ScalarVariableElement::Enumeration => ("Enumeration", None),
                };
                VariableInfo {
                    name: v.name.clone(),
                    vr: v.value_reference,
                    causality: v.causality.clone(),
                    variability: v.variability,
                    kind,
                    start,
                    start_string: extra.string_start,
                    min: extra.min,
                    max: extra.max,
                    unit: extra.unit,
                }
            })
            .collect();
        Ok(Fmu {
            binding,
            library_path: library.to_owned(),
            guid: description.guid.clone(),
            description,
            variables,
        })
    }

    /// The variable called `name`, if there is one.
    pub fn find(&self, name: &str) -> Option<&VariableInfo> {
        self.variables.iter().find(|v| v.name == name)
    }

    pub fn variable(&self, name: &str) -> &VariableInfo {
        self.variables
            .iter()
            .find(|v| v.name == name)
            .unwrap_or_else(|| panic!("no variable {name} in modelDescription"))
    }

    pub fn with_causality(&self, causality: Causality) -> impl Iterator<Item = &VariableInfo> {
        self.variables
            .iter()
            .filter(move |v| v.causality == causality)
    }

    /// Instantiates with a fresh log sink.
    pub fn instantiate(&self, name: &str, logging_on: bool) -> Instance<'_> {
        self.try_instantiate(name, &self.guid, None, logging_on)
            .unwrap_or_else(|log| panic!("fmi2Instantiate returned NULL: {log:#?}"))
    }

    /// Instantiates with the given GUID and resource location; `Err` carries
    /// the log when the FMU refused.
    pub fn try_instantiate(
        &self,
        name: &str,
        guid: &str,
        resource_location: Option<&str>,
        logging_on: bool,
    ) -> Result<Instance<'_>, Vec<LogRecord>> {
        self.try_instantiate_as(
            Interface::CoSimulation,
            name,
            guid,
            resource_location,
            logging_on,
        )
    }

    /// [`Fmu::try_instantiate`] for either interface.
    pub fn try_instantiate_as(
        &self,
        interface: Interface,
        name: &str,
        guid: &str,
        resource_location: Option<&str>,
        logging_on: bool,
    ) -> Result<Instance<'_>, Vec<LogRecord>> {
        let sink = Box::new(LogSink::default());
        let callbacks = Box::new(callbacks_for(&sink));
        let name_c = CString::new(name).expect("no NUL");
        let guid_c = CString::new(guid).expect("no NUL");
        let location_c = resource_location.map(|l| CString::new(l).expect("no NUL"));
        // SAFETY: every string is a CString alive for the call; the callbacks are boxed and
        // kept by the returned `Instance`, so they outlive the FMU instance as the standard
        // requires.
        let c = unsafe {
            self.binding.fmi2Instantiate(
                name_c.as_ptr(),
                interface.fmu_type(),
                guid_c.as_ptr(),
                location_c.as_ref().map_or(ptr::null(), |l| l.as_ptr()),
                &*callbacks,
                0,
                logging_on as sys::fmi2Boolean,
            )
        };
        if c.is_null() {
            return Err(sink.take());
        }
        Ok(Instance {
            fmu: self,
            c,
            sink,
            _callbacks: callbacks,
            time: 0.0,
            interface,
        })
    }
}

/// What fmi-schema does not read of a ScalarVariable's type element.
#[derive(Clone, Debug, Default, PartialEq)]
struct TypeAttributes {
    /// The declared range (`min`, `max` of a Real or Integer).
    min: Option<f64>,
    max: Option<f64>,
    /// The `start` of a String.
    string_start: Option<String>,
    /// The `unit` of a Real.
    unit: Option<String>,
}

/// The start value of every ScalarVariable's `<String>` element (`None` for
/// other types and for a String without one), in document order: what an
/// importer reads, XML escapes resolved.
pub fn string_starts(model_description: &str) -> Result<Vec<Option<String>>, String> {
    Ok(type_attributes(model_description)?
        .into_iter()
        .map(|a| a.string_start)
        .collect())
}

/// The attributes of the type element (Real, Integer, ...) of every
/// ScalarVariable that fmi-schema leaves out, in document order.
fn type_attributes(model_description: &str) -> Result<Vec<TypeAttributes>, String> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::Reader::from_str(model_description);
    let mut found = Vec::new();
    let mut in_variable = false;
    loop {
        let event = reader
            .read_event()
            .map_err(|e| format!("modelDescription is not XML: {e}"))?;
        match event {
            Event::Start(e) if e.name().as_ref() == "ScalarVariable" => in_variable = true,
            Event::End(e) if e.name().as_ref() == "ScalarVariable" => in_variable = false,
            Event::Start(e) | Event::Empty(e)
                if in_variable
                    && matches!(
                        e.name().as_ref(),
                        "Real" | "Integer" | "Boolean" | "String" | "Enumeration"
                    ) =>
            {
                let is_string = e.name().as_ref() == "String";
                let mut attributes = TypeAttributes::default();
                for attribute in e.attributes() {
                    let attribute =
                        attribute.map_err(|e| format!("bad attribute in modelDescription: {e}"))?;
                    let value = attribute
                        .normalized_value(quick_xml::XmlVersion::Implicit1_0)
                        .map_err(|e| format!("bad attribute value in modelDescription: {e}"))?;
                    let slot = match attribute.key.as_ref() {
                        "start" if is_string => {
                            attributes.string_start = Some(value.into_owned());
                            continue;
                        }
                        "unit" => {
                            attributes.unit = Some(value.into_owned());
                            continue;
                        }
                        "min" => &mut attributes.min,
                        "max" => &mut attributes.max,
                        _ => continue,
                    };
                    *slot = Some(
                        value
                            .parse::<f64>()
                            .map_err(|e| format!("range attribute {value:?}: {e}"))?,
                    );
                }
                found.push(attributes);
            }
            Event::Eof => break,
            _ => {}
        }
    }
    Ok(found)
}

/// Callbacks whose logger writes into `sink`.
pub fn callbacks_for(sink: &LogSink) -> sys::fmi2CallbackFunctions {
    sys::fmi2CallbackFunctions {
        logger: Some(fmi2_import_logger),
        allocateMemory: None,
        freeMemory: None,
        stepFinished: None,
        componentEnvironment: sink as *const LogSink as *mut c_void,
    }
}

impl LogSink {
    pub fn take(&self) -> Vec<LogRecord> {
        std::mem::take(&mut *self.records.lock().unwrap_or_else(|e| e.into_inner()))
    }
}

/// A live instance; freed on drop.
pub struct Instance<'a> {
    pub fmu: &'a Fmu,
    pub c: sys::fmi2Component,
    sink: Box<LogSink>,
    _callbacks: Box<sys::fmi2CallbackFunctions>,
    /// The communication point the next [`Instance::do_step`] starts from
    /// (Model Exchange: the time the integrator has reached).
    pub time: f64,
    /// The interface it was instantiated for.
    pub interface: Interface,
}

/// The interface an instance is instantiated for (`fmuType`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interface {
    ModelExchange,
    CoSimulation,
}

impl Interface {
    pub fn fmu_type(self) -> sys::fmi2Type {
        match self {
            Interface::ModelExchange => sys::fmi2Type_fmi2ModelExchange,
            Interface::CoSimulation => sys::fmi2Type_fmi2CoSimulation,
        }
    }
}

impl Instance<'_> {
    fn b(&self) -> &Fmi2Binding {
        &self.fmu.binding
    }

    /// Messages logged since the last call.
    pub fn take_log(&self) -> Vec<LogRecord> {
        self.sink.take()
    }

    pub fn setup(&mut self, start: f64) -> sys::fmi2Status {
        self.time = start;
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // every pointer is to a local, or a slice of the length passed, valid for the call
        // (the standard's signatures, through fmi-sys).
        unsafe { self.b().fmi2SetupExperiment(self.c, 0, 0.0, start, 0, 0.0) }
    }

    pub fn enter_init(&self) -> sys::fmi2Status {
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // every pointer is to a local, or a slice of the length passed, valid for the call
        // (the standard's signatures, through fmi-sys).
        unsafe { self.b().fmi2EnterInitializationMode(self.c) }
    }

    pub fn exit_init(&self) -> sys::fmi2Status {
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // every pointer is to a local, or a slice of the length passed, valid for the call
        // (the standard's signatures, through fmi-sys).
        unsafe { self.b().fmi2ExitInitializationMode(self.c) }
    }

    /// setupExperiment(0), enter and exit initialization; panics unless OK.
    pub fn initialize(&mut self) {
        assert_eq!(
            self.setup(0.0),
            OK,
            "fmi2SetupExperiment: {:#?}",
            self.take_log()
        );
        assert_eq!(
            self.enter_init(),
            OK,
            "fmi2EnterInitializationMode: {:#?}",
            self.take_log()
        );
        assert_eq!(
            self.exit_init(),
            OK,
            "fmi2ExitInitializationMode: {:#?}",
            self.take_log()
        );
    }

    pub fn terminate(&self) -> sys::fmi2Status {
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // every pointer is to a local, or a slice of the length passed, valid for the call
        // (the standard's signatures, through fmi-sys).
        unsafe { self.b().fmi2Terminate(self.c) }
    }

    pub fn reset(&mut self) -> sys::fmi2Status {
        self.time = 0.0;
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // every pointer is to a local, or a slice of the length passed, valid for the call
        // (the standard's signatures, through fmi-sys).
        unsafe { self.b().fmi2Reset(self.c) }
    }

    pub fn set_real(&self, vrs: &[u32], values: &[f64]) -> sys::fmi2Status {
        assert_eq!(vrs.len(), values.len());
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // every pointer is to a local, or a slice of the length passed, valid for the call
        // (the standard's signatures, through fmi-sys).
        unsafe {
            self.b()
                .fmi2SetReal(self.c, vrs.as_ptr(), vrs.len(), values.as_ptr())
        }
    }

    pub fn set_integer(&self, vrs: &[u32], values: &[i32]) -> sys::fmi2Status {
        assert_eq!(vrs.len(), values.len());
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // every pointer is to a local, or a slice of the length passed, valid for the call
        // (the standard's signatures, through fmi-sys).
        unsafe {
            self.b()
                .fmi2SetInteger(self.c, vrs.as_ptr(), vrs.len(), values.as_ptr())
        }
    }

    pub fn set_boolean(&self, vrs: &[u32], values: &[bool]) -> sys::fmi2Status {
        assert_eq!(vrs.len(), values.len());
        let values: Vec<sys::fmi2Boolean> = values.iter().map(|b| i32::from(*b)).collect();
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // every pointer is to a local, or a slice of the length passed, valid for the call
        // (the standard's signatures, through fmi-sys).
        unsafe {
            self.b()
                .fmi2SetBoolean(self.c, vrs.as_ptr(), vrs.len(), values.as_ptr())
        }
    }

    pub fn get_real(&self, vrs: &[u32]) -> (sys::fmi2Status, Vec<f64>) {
        let mut values = vec![f64::NAN; vrs.len()];
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // every pointer is to a local, or a slice of the length passed, valid for the call
        // (the standard's signatures, through fmi-sys).
        let status = unsafe {
            self.b()
                .fmi2GetReal(self.c, vrs.as_ptr(), vrs.len(), values.as_mut_ptr())
        };
        (status, values)
    }

    /// fmi2GetReal into a buffer the caller owns: allocates nothing, for a
    /// master's step loop.
    pub fn get_real_into(&self, vrs: &[u32], values: &mut [f64]) -> sys::fmi2Status {
        assert_eq!(vrs.len(), values.len());
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // every pointer is to a local, or a slice of the length passed, valid for the call
        // (the standard's signatures, through fmi-sys).
        unsafe {
            self.b()
                .fmi2GetReal(self.c, vrs.as_ptr(), vrs.len(), values.as_mut_ptr())
        }
    }

    pub fn get_real_one(&self, vr: u32) -> f64 {
        let (status, values) = self.get_real(&[vr]);
        assert_eq!(status, OK, "fmi2GetReal({vr}): {:#?}", self.take_log());
        values[0]
    }

    pub fn do_step(&mut self, h: f64) -> sys::fmi2Status {
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // every pointer is to a local, or a slice of the length passed, valid for the call
        // (the standard's signatures, through fmi-sys).
        let status = unsafe { self.b().fmi2DoStep(self.c, self.time, h, 1) };
        if status <= WARNING {
            self.time += h;
        }
        status
    }

    pub fn do_step_at(&self, t: f64, h: f64) -> sys::fmi2Status {
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // every pointer is to a local, or a slice of the length passed, valid for the call
        // (the standard's signatures, through fmi-sys).
        unsafe { self.b().fmi2DoStep(self.c, t, h, 1) }
    }

    /// Values of every Real output, in modelDescription order.
    pub fn outputs(&self) -> Vec<f64> {
        let vrs: Vec<u32> = self
            .fmu
            .with_causality(Causality::Output)
            .filter(|v| v.kind == "Real")
            .map(|v| v.vr)
            .collect();
        let (status, values) = self.get_real(&vrs);
        assert_eq!(status, OK, "fmi2GetReal(outputs): {:#?}", self.take_log());
        values
    }

    pub fn get_state(&self) -> (sys::fmi2Status, sys::fmi2FMUstate) {
        let mut state: sys::fmi2FMUstate = ptr::null_mut();
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // every pointer is to a local, or a slice of the length passed, valid for the call
        // (the standard's signatures, through fmi-sys).
        let status = unsafe { self.b().fmi2GetFMUstate(self.c, &mut state) };
        (status, state)
    }

    pub fn set_state(&self, state: sys::fmi2FMUstate) -> sys::fmi2Status {
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // `state` is handed back to the FMU as the caller got it, for the FMU to check (the
        // crate's header); the other pointers are to locals valid for the call.
        unsafe { self.b().fmi2SetFMUstate(self.c, state) }
    }

    pub fn free_state(&self, state: &mut sys::fmi2FMUstate) -> sys::fmi2Status {
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // `state` is handed back to the FMU as the caller got it, for the FMU to check (the
        // crate's header); the other pointers are to locals valid for the call.
        unsafe { self.b().fmi2FreeFMUstate(self.c, state) }
    }

    pub fn serialize(&self, state: sys::fmi2FMUstate) -> (sys::fmi2Status, Vec<u8>) {
        let mut size = 0usize;
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // `state` is handed back to the FMU as the caller got it, for the FMU to check (the
        // crate's header); the other pointers are to locals valid for the call.
        let status = unsafe {
            self.b()
                .fmi2SerializedFMUstateSize(self.c, state, &mut size)
        };
        if status != OK {
            return (status, Vec::new());
        }
        let mut bytes = vec![0u8; size];
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // `state` is handed back to the FMU as the caller got it, for the FMU to check (the
        // crate's header); the other pointers are to locals valid for the call.
        let status = unsafe {
            self.b()
                .fmi2SerializeFMUstate(self.c, state, bytes.as_mut_ptr().cast(), size)
        };
        (status, bytes)
    }

    pub fn deserialize(&self, bytes: &[u8]) -> (sys::fmi2Status, sys::fmi2FMUstate) {
        let mut state: sys::fmi2FMUstate = ptr::null_mut();
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // every pointer is to a local, or a slice of the length passed, valid for the call
        // (the standard's signatures, through fmi-sys).
        let status = unsafe {
            self.b()
                .fmi2DeSerializeFMUstate(self.c, bytes.as_ptr().cast(), bytes.len(), &mut state)
        };
        (status, state)
    }

    pub fn set_debug_logging(&self, on: bool, categories: &[&str]) -> sys::fmi2Status {
        let owned: Vec<CString> = categories
            .iter()
            .map(|c| CString::new(*c).unwrap())
            .collect();
        let pointers: Vec<*const c_char> = owned.iter().map(|c| c.as_ptr()).collect();
        // SAFETY: `self.c` is the live instance this `Instance` owns (freed only on drop);
        // every pointer is to a local, or a slice of the length passed, valid for the call
        // (the standard's signatures, through fmi-sys).
        unsafe {
            self.b().fmi2SetDebugLogging(
                self.c,
                on as sys::fmi2Boolean,
                pointers.len(),
                if pointers.is_empty() {
                    ptr::null()
                } else {
                    pointers.as_ptr()
                },
            )
        }
    }
}

impl Drop for Instance<'_> {
    fn drop(&mut self) {
        // SAFETY: `self.c` is live and freed once, here; nothing uses it after.
        unsafe { self.fmu.binding.fmi2FreeInstance(self.c) };
    }
}

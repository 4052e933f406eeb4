//! The conformance checks. Each drives fresh instances through the C ABI and
//! panics with the reason when the FMU misbehaves.

use std::ffi::{CStr, c_char};
use std::ptr;

use fmi_schema::fmi2::{Causality, Initial, Variability};
use fmi_sys::fmi2 as sys;

use crate::model_exchange::MODEL_EXCHANGE_FUNCTIONS;
use crate::{
    DISCARD, DriveTo, ERROR, Fmu, FmuUnderTest, Instance, Interface, InterfaceStates, OK, State,
    VariableInfo, WARNING, allowed,
};

mod model_exchange;
mod restore;
mod variable_kinds;

pub use model_exchange::*;
pub use restore::*;
pub use variable_kinds::*;

fn has_message(log: &[crate::LogRecord], needle: &str) -> bool {
    log.iter().any(|r| r.message.contains(needle))
}

fn assert_logged(log: &[crate::LogRecord], function: &str, needle: &str) {
    assert!(
        log.iter()
            .any(|r| r.message.starts_with(function) && r.message.contains(needle)),
        "expected a message from {function} containing {needle:?}, got {log:#?}"
    );
}

/// Every FMI 2.0 common and co-simulation function resolves (the binding
/// types each symbol with the official typedef), the Model Exchange ones too
/// when modelDescription offers Model Exchange, and the dynamic symbol table
/// holds nothing else.
pub fn exports_every_function_and_nothing_else(fmu: &Fmu) {
    let b = &fmu.binding;
    let resolved = [
        ("fmi2GetTypesPlatform", b.fmi2GetTypesPlatform.is_ok()),
        ("fmi2GetVersion", b.fmi2GetVersion.is_ok()),
        ("fmi2SetDebugLogging", b.fmi2SetDebugLogging.is_ok()),
        ("fmi2Instantiate", b.fmi2Instantiate.is_ok()),
        ("fmi2FreeInstance", b.fmi2FreeInstance.is_ok()),
        ("fmi2SetupExperiment", b.fmi2SetupExperiment.is_ok()),
        (
            "fmi2EnterInitializationMode",
            b.fmi2EnterInitializationMode.is_ok(),
        ),
        (
            "fmi2ExitInitializationMode",
            b.fmi2ExitInitializationMode.is_ok(),
        ),
        ("fmi2Terminate", b.fmi2Terminate.is_ok()),
        ("fmi2Reset", b.fmi2Reset.is_ok()),
        ("fmi2GetReal", b.fmi2GetReal.is_ok()),
        ("fmi2GetInteger", b.fmi2GetInteger.is_ok()),
        ("fmi2GetBoolean", b.fmi2GetBoolean.is_ok()),
        ("fmi2GetString", b.fmi2GetString.is_ok()),
        ("fmi2SetReal", b.fmi2SetReal.is_ok()),
        ("fmi2SetInteger", b.fmi2SetInteger.is_ok()),
        ("fmi2SetBoolean", b.fmi2SetBoolean.is_ok()),
        ("fmi2SetString", b.fmi2SetString.is_ok()),
        ("fmi2GetFMUstate", b.fmi2GetFMUstate.is_ok()),
        ("fmi2SetFMUstate", b.fmi2SetFMUstate.is_ok()),
        ("fmi2FreeFMUstate", b.fmi2FreeFMUstate.is_ok()),
        (
            "fmi2SerializedFMUstateSize",
            b.fmi2SerializedFMUstateSize.is_ok(),
        ),
        ("fmi2SerializeFMUstate", b.fmi2SerializeFMUstate.is_ok()),
        ("fmi2DeSerializeFMUstate", b.fmi2DeSerializeFMUstate.is_ok()),
        (
            "fmi2GetDirectionalDerivative",
            b.fmi2GetDirectionalDerivative.is_ok(),
        ),
        (
            "fmi2SetRealInputDerivatives",
            b.fmi2SetRealInputDerivatives.is_ok(),
        ),
        (
            "fmi2GetRealOutputDerivatives",
            b.fmi2GetRealOutputDerivatives.is_ok(),
        ),
        ("fmi2DoStep", b.fmi2DoStep.is_ok()),
        ("fmi2CancelStep", b.fmi2CancelStep.is_ok()),
        ("fmi2GetStatus", b.fmi2GetStatus.is_ok()),
        ("fmi2GetRealStatus", b.fmi2GetRealStatus.is_ok()),
        ("fmi2GetIntegerStatus", b.fmi2GetIntegerStatus.is_ok()),
        ("fmi2GetBooleanStatus", b.fmi2GetBooleanStatus.is_ok()),
        ("fmi2GetStringStatus", b.fmi2GetStringStatus.is_ok()),
    ];
    let model_exchange = [
        ("fmi2EnterEventMode", b.fmi2EnterEventMode.is_ok()),
        ("fmi2NewDiscreteStates", b.fmi2NewDiscreteStates.is_ok()),
        (
            "fmi2EnterContinuousTimeMode",
            b.fmi2EnterContinuousTimeMode.is_ok(),
        ),
        (
            "fmi2CompletedIntegratorStep",
            b.fmi2CompletedIntegratorStep.is_ok(),
        ),
        ("fmi2SetTime", b.fmi2SetTime.is_ok()),
        ("fmi2SetContinuousStates", b.fmi2SetContinuousStates.is_ok()),
        ("fmi2GetDerivatives", b.fmi2GetDerivatives.is_ok()),
        ("fmi2GetEventIndicators", b.fmi2GetEventIndicators.is_ok()),
        ("fmi2GetContinuousStates", b.fmi2GetContinuousStates.is_ok()),
        (
            "fmi2GetNominalsOfContinuousStates",
            b.fmi2GetNominalsOfContinuousStates.is_ok(),
        ),
    ];
    let resolved: Vec<(&str, bool)> = if fmu.offers_model_exchange() {
        resolved.iter().chain(&model_exchange).copied().collect()
    } else {
        resolved.to_vec()
    };
    let missing: Vec<&str> = resolved
        .iter()
        .filter(|(_, ok)| !ok)
        .map(|(n, _)| *n)
        .collect();
    assert!(missing.is_empty(), "unresolved FMI functions: {missing:?}");

    let data = std::fs::read(&fmu.library_path).expect("the library is readable");
    let file = object::File::parse(&*data).expect("the library is an object file");
    use object::{Object, ObjectSymbol};
    let exported: Vec<String> = file
        .dynamic_symbols()
        .filter(|s| s.is_definition() && s.is_global())
        .filter_map(|s| s.name().ok().map(str::to_owned))
        .collect();
    let foreign: Vec<&String> = exported.iter().filter(|n| !n.starts_with("fmi2")).collect();
    assert!(
        foreign.is_empty(),
        "the binary exports non-FMI symbols {foreign:?}: add them to fmi2-cosim/linker/fmi2-exports.map"
    );
    let mut names: Vec<&str> = resolved.iter().map(|(n, _)| *n).collect();
    names.sort_unstable();
    let mut exported_sorted: Vec<&str> = exported.iter().map(String::as_str).collect();
    exported_sorted.sort_unstable();
    assert_eq!(
        exported_sorted, names,
        "exported fmi2 symbols differ from the standard's set"
    );
}

pub fn reports_platform_and_version(fmu: &Fmu) {
    // SAFETY: the function takes no argument and returns a static NUL-terminated string (FMI
    // 2.0.4 §2.1.4), which the binding keeps loaded.
    let platform = unsafe { CStr::from_ptr(fmu.binding.fmi2GetTypesPlatform()) };
    // SAFETY: the function takes no argument and returns a static NUL-terminated string (FMI
    // 2.0.4 §2.1.4), which the binding keeps loaded.
    let version = unsafe { CStr::from_ptr(fmu.binding.fmi2GetVersion()) };
    assert_eq!(platform.to_str().unwrap(), "default");
    assert_eq!(version.to_str().unwrap(), "2.0");
}

/// modelDescription declares what the layer promises the importers.
pub fn model_description_declares_capabilities(fmu: &Fmu) {
    let md = &fmu.description;
    assert_eq!(md.fmi_version, "2.0");
    let cs = md.co_simulation.as_ref().expect("a CoSimulation element");
    if let Some(me) = &md.model_exchange {
        // One binary serves both interfaces.
        assert_eq!(me.model_identifier, cs.model_identifier);
        assert_eq!(me.can_get_and_set_fmu_state, Some(true));
        assert_eq!(me.can_serialize_fmu_state, Some(true));
        assert_eq!(me.can_be_instantiated_only_once_per_process, Some(false));
        assert_eq!(me.provides_directional_derivative, Some(false));
        assert!(fmu.number_of_states() > 0, "Model Exchange without states");
    } else {
        assert_eq!(fmu.number_of_states(), 0, "states without Model Exchange");
    }
    assert_eq!(cs.can_handle_variable_communication_step_size, Some(true));
    assert_eq!(cs.can_get_and_set_fmu_state, Some(true));
    assert_eq!(cs.can_serialize_fmu_state, Some(true));
    assert_eq!(cs.can_be_instantiated_only_once_per_process, Some(false));
    assert_eq!(cs.provides_directional_derivative, Some(false));
    assert_eq!(cs.can_interpolate_inputs, Some(false));
    assert_eq!(cs.max_output_derivative_order, Some(0));
    assert_eq!(cs.can_run_asynchronuously, Some(false));
    let categories = md
        .log_categories
        .as_ref()
        .expect("LogCategories")
        .categories
        .len();
    assert!(categories >= 6, "log categories declared: {categories}");
    // At most one independent variable: a continuous Real without start
    // value or initial (FMI 2.0.4 §2.2.7).
    let independent: Vec<(&VariableInfo, &fmi_schema::fmi2::ScalarVariable)> = fmu
        .variables
        .iter()
        .zip(&md.model_variables.variables)
        .filter(|(v, _)| v.causality == Causality::Independent)
        .collect();
    assert!(
        independent.len() <= 1,
        "independent variables {independent:?}"
    );
    for (time, declared) in independent {
        assert_eq!(time.kind, "Real", "{}", time.name);
        assert!(
            time.variability
                .is_none_or(|v| v == Variability::Continuous),
            "{}",
            time.name
        );
        assert!(time.start.is_none(), "{} has a start value", time.name);
        assert!(declared.initial.is_none(), "{} has an initial", time.name);
    }
    let exact = |v: &fmi_schema::fmi2::ScalarVariable| {
        v.initial == Some(Initial::Exact)
            || (v.initial.is_none() && v.variability == Some(Variability::Constant))
    };
    // Every constant is an exact output or local with a start value.
    for (v, info) in md.model_variables.variables.iter().zip(&fmu.variables) {
        if v.variability == Some(Variability::Constant) {
            assert!(
                matches!(v.causality, Causality::Output | Causality::Local) && exact(v),
                "{}: a constant is an exact output or local",
                v.name
            );
            assert!(
                info.start.is_some() || info.start_string.is_some(),
                "{}: a constant declares its value",
                v.name
            );
        }
    }
    // Every output appears in Outputs; those computed at initialization (not
    // exact, as a constant is) in InitialUnknowns.
    let outputs: Vec<u32> = md
        .model_variables
        .variables
        .iter()
        .enumerate()
        .filter(|(_, v)| v.causality == Causality::Output)
        .map(|(i, _)| i as u32 + 1)
        .collect();
    let listed: Vec<u32> = md
        .model_structure
        .outputs
        .unknowns
        .iter()
        .map(|u| u.index)
        .collect();
    assert_eq!(listed, outputs, "ModelStructure/Outputs");
    // InitialUnknowns: the outputs that are not exact, the calculated
    // parameters, and the states and state derivatives (FMI 2.0.4 §2.2.8;
    // here all of them are calculated), in index order.
    let mut expected: Vec<u32> = outputs
        .iter()
        .copied()
        .filter(|index| !exact(&md.model_variables.variables[*index as usize - 1]))
        .collect();
    expected.extend(
        md.model_variables
            .variables
            .iter()
            .enumerate()
            .filter(|(_, v)| v.causality == Causality::CalculatedParameter)
            .map(|(i, _)| i as u32 + 1),
    );
    for unknown in &md.model_structure.derivatives.unknowns {
        expected.push(unknown.index);
        expected.push(crate::model_exchange::state_of(fmu, unknown.index));
    }
    expected.sort_unstable();
    expected.dedup();
    let initial: Vec<u32> = md
        .model_structure
        .initial_unknowns
        .unknowns
        .iter()
        .map(|u| u.index)
        .collect();
    assert_eq!(initial, expected, "ModelStructure/InitialUnknowns");
}

/// Outputs whose ModelStructure dependencies exclude an input do not move when
/// that input changes without a step (no undeclared direct feedthrough).
pub fn declared_dependencies_hold(fmu: &Fmu) {
    let xml_inputs: Vec<(usize, u32)> = fmu
        .variables
        .iter()
        .enumerate()
        .filter(|(_, v)| v.causality == Causality::Input && v.kind == "Real")
        .map(|(i, v)| (i + 1, v.vr))
        .collect();
    let mut inst = fmu.instantiate("dependencies", false);
    inst.initialize();
    for _ in 0..10 {
        assert_eq!(inst.do_step(1e-4), OK);
    }
    for unknown in &fmu.description.model_structure.outputs.unknowns {
        let output = &fmu.variables[unknown.index as usize - 1];
        if output.kind != "Real" {
            continue;
        }
        let before = inst.get_real_one(output.vr);
        for (index, vr) in &xml_inputs {
            if unknown.dependencies.contains(&(*index as u32)) {
                continue;
            }
            let old = inst.get_real_one(*vr);
            assert_eq!(inst.set_real(&[*vr], &[old + 1.0]), OK);
            let after = inst.get_real_one(output.vr);
            assert_eq!(
                before.to_bits(),
                after.to_bits(),
                "{} changed when input vr {vr} changed without a step, but its dependencies \
                 ({:?}) do not list it",
                output.name,
                unknown.dependencies
            );
            assert_eq!(inst.set_real(&[*vr], &[old]), OK);
        }
    }
}

pub fn instantiate_refuses_bad_arguments(fmu: &Fmu) {
    // Wrong GUID: refused, and the message says why.
    let log = fmu
        .try_instantiate(
            "wrong-guid",
            "{00000000-0000-0000-0000-000000000000}",
            None,
            false,
        )
        .err()
        .expect("a wrong GUID must be refused");
    assert!(has_message(&log, "GUID"), "{log:#?}");

    let b = &fmu.binding;
    let sink = crate::LogSink::default();
    let callbacks = crate::callbacks_for(&sink);
    let guid = std::ffi::CString::new(fmu.guid.clone()).unwrap();
    let name = c"probe";
    let instantiate = |name: *const c_char,
                       fmu_type: sys::fmi2Type,
                       guid: *const c_char,
                       functions: *const sys::fmi2CallbackFunctions| {
        // SAFETY: each pointer is NULL (the arguments under test) or points
        // to a NUL-terminated string or to callbacks that outlive the call;
        // the sink the callbacks log to outlives the instances.
        unsafe { b.fmi2Instantiate(name, fmu_type, guid, ptr::null(), functions, 0, 0) }
    };
    // NULL GUID.
    let c = instantiate(
        name.as_ptr(),
        sys::fmi2Type_fmi2CoSimulation,
        ptr::null(),
        &callbacks,
    );
    assert!(c.is_null(), "NULL GUID accepted");
    assert!(has_message(&sink.take(), "fmuGUID"));
    // Model exchange, where it is not offered; an fmuType that is neither.
    let c = instantiate(
        name.as_ptr(),
        sys::fmi2Type_fmi2ModelExchange,
        guid.as_ptr(),
        &callbacks,
    );
    if fmu.offers_model_exchange() {
        assert!(!c.is_null(), "model exchange refused: {:#?}", sink.take());
        // SAFETY: `c` is the instance just made, freed once.
        unsafe { b.fmi2FreeInstance(c) };
        sink.take();
    } else {
        assert!(c.is_null(), "model exchange accepted");
        assert!(has_message(&sink.take(), "co-simulation only"));
    }
    let c = instantiate(name.as_ptr(), 2, guid.as_ptr(), &callbacks);
    assert!(c.is_null(), "fmuType 2 accepted");
    assert!(has_message(&sink.take(), "fmuType"));
    // NULL instance name.
    let c = instantiate(
        ptr::null(),
        sys::fmi2Type_fmi2CoSimulation,
        guid.as_ptr(),
        &callbacks,
    );
    assert!(c.is_null(), "NULL instanceName accepted");
    assert!(has_message(&sink.take(), "instanceName"));
    // NULL callbacks: nothing to log with, but no crash.
    let c = instantiate(
        name.as_ptr(),
        sys::fmi2Type_fmi2CoSimulation,
        guid.as_ptr(),
        ptr::null(),
    );
    assert!(c.is_null(), "NULL functions accepted");
}

pub fn resource_locations_in_every_spelling(fmu: &Fmu) {
    for location in [
        None,
        Some("file:///tmp/some%20dir/resources"),
        Some("file:/tmp/resources"),
        Some("file://localhost/tmp/resources"),
    ] {
        let mut inst = fmu
            .try_instantiate("resources", &fmu.guid, location, false)
            .unwrap_or_else(|log| panic!("{location:?} refused: {log:#?}"));
        inst.initialize();
        assert_eq!(inst.do_step(1e-4), OK);
    }
    // Not a file URI: accepted, with a warning.
    let inst = fmu
        .try_instantiate("resources", &fmu.guid, Some("http://example.org/x"), false)
        .unwrap_or_else(|log| panic!("refused: {log:#?}"));
    assert!(has_message(&inst.take_log(), "not a file: URI"));
}

/// Calls `function` on `inst` with valid arguments; returns its status.
fn probe(inst: &mut Instance<'_>, function: &str) -> sys::fmi2Status {
    let fmu = inst.fmu;
    let b = &fmu.binding;
    let c = inst.c;
    let real_vr = fmu.real_input().vr;
    let mut real = [0.0f64];
    let mut int = [0i32];
    let mut boolean = [0i32];
    let mut string: [*const c_char; 1] = [ptr::null()];
    let real_input = real_vr;
    // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the ones
    // under test, which the layer must refuse without touching them, and every other pointer is
    // to a local that outlives the call with at least the length passed.
    unsafe {
        match function {
            "fmi2SetDebugLogging" => b.fmi2SetDebugLogging(c, 1, 0, ptr::null()),
            "fmi2SetupExperiment" => b.fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0),
            "fmi2EnterInitializationMode" => b.fmi2EnterInitializationMode(c),
            "fmi2ExitInitializationMode" => b.fmi2ExitInitializationMode(c),
            "fmi2Terminate" => b.fmi2Terminate(c),
            "fmi2Reset" => b.fmi2Reset(c),
            "fmi2GetReal" => b.fmi2GetReal(c, &real_vr, 1, real.as_mut_ptr()),
            "fmi2GetInteger" => b.fmi2GetInteger(c, ptr::null(), 0, int.as_mut_ptr()),
            "fmi2GetBoolean" => b.fmi2GetBoolean(c, ptr::null(), 0, boolean.as_mut_ptr()),
            "fmi2GetString" => b.fmi2GetString(c, ptr::null(), 0, string.as_mut_ptr()),
            "fmi2SetReal" => b.fmi2SetReal(c, &real_input, 1, [1.0].as_ptr()),
            "fmi2SetInteger" => b.fmi2SetInteger(c, ptr::null(), 0, int.as_ptr()),
            "fmi2SetBoolean" => b.fmi2SetBoolean(c, ptr::null(), 0, boolean.as_ptr()),
            "fmi2SetString" => b.fmi2SetString(c, ptr::null(), 0, string.as_ptr()),
            "fmi2GetFMUstate" | "fmi2FreeFMUstate" => {
                let mut state = ptr::null_mut();
                let status = b.fmi2GetFMUstate(c, &mut state);
                if function == "fmi2GetFMUstate" {
                    if !state.is_null() {
                        b.fmi2FreeFMUstate(c, &mut state);
                    }
                    status
                } else {
                    b.fmi2FreeFMUstate(c, &mut state)
                }
            }
            "fmi2SetFMUstate" => {
                let mut state = ptr::null_mut();
                b.fmi2GetFMUstate(c, &mut state);
                let status = b.fmi2SetFMUstate(c, state);
                b.fmi2FreeFMUstate(c, &mut state);
                status
            }
            "fmi2SerializedFMUstateSize" | "fmi2SerializeFMUstate" | "fmi2DeSerializeFMUstate" => {
                let mut state = ptr::null_mut();
                b.fmi2GetFMUstate(c, &mut state);
                let mut size = 0usize;
                let status = b.fmi2SerializedFMUstateSize(c, state, &mut size);
                let status = if function == "fmi2SerializedFMUstateSize" {
                    status
                } else {
                    let mut bytes = vec![0u8; size];
                    let serialized =
                        b.fmi2SerializeFMUstate(c, state, bytes.as_mut_ptr().cast(), size);
                    if function == "fmi2SerializeFMUstate" {
                        serialized
                    } else {
                        let mut restored = ptr::null_mut();
                        let s = b.fmi2DeSerializeFMUstate(
                            c,
                            bytes.as_ptr().cast(),
                            size,
                            &mut restored,
                        );
                        if !restored.is_null() {
                            b.fmi2FreeFMUstate(c, &mut restored);
                        }
                        s
                    }
                };
                if !state.is_null() {
                    b.fmi2FreeFMUstate(c, &mut state);
                }
                status
            }
            "fmi2GetDirectionalDerivative" => b.fmi2GetDirectionalDerivative(
                c,
                ptr::null(),
                0,
                ptr::null(),
                0,
                ptr::null(),
                ptr::null_mut(),
            ),
            "fmi2SetRealInputDerivatives" => {
                b.fmi2SetRealInputDerivatives(c, ptr::null(), 0, ptr::null(), ptr::null())
            }
            "fmi2GetRealOutputDerivatives" => {
                b.fmi2GetRealOutputDerivatives(c, ptr::null(), 0, ptr::null(), ptr::null_mut())
            }
            "fmi2DoStep" => b.fmi2DoStep(c, inst.time, 1e-4, 1),
            "fmi2CancelStep" => b.fmi2CancelStep(c),
            "fmi2GetStatus" => {
                let mut s = OK;
                b.fmi2GetStatus(c, sys::fmi2StatusKind_fmi2DoStepStatus, &mut s)
            }
            "fmi2GetRealStatus" => b.fmi2GetRealStatus(
                c,
                sys::fmi2StatusKind_fmi2LastSuccessfulTime,
                real.as_mut_ptr(),
            ),
            "fmi2GetIntegerStatus" => {
                b.fmi2GetIntegerStatus(c, sys::fmi2StatusKind_fmi2DoStepStatus, int.as_mut_ptr())
            }
            "fmi2GetBooleanStatus" => {
                b.fmi2GetBooleanStatus(c, sys::fmi2StatusKind_fmi2Terminated, boolean.as_mut_ptr())
            }
            "fmi2GetStringStatus" => b.fmi2GetStringStatus(
                c,
                sys::fmi2StatusKind_fmi2PendingStatus,
                string.as_mut_ptr(),
            ),
            other => model_exchange::probe(inst, other),
        }
    }
}

/// The co-simulation and common functions that take an instance, from the
/// layer's one list of FMI functions, with `fmi2FreeInstance` last: it ends
/// the instance.
fn instance_functions() -> impl Iterator<Item = &'static str> {
    fmi2_cosim::functions::EXPORTED_FUNCTIONS
        .iter()
        .copied()
        .filter(|name| {
            *name != "fmi2FreeInstance"
                && fmi2_cosim::functions::by_name(name).is_some_and(|f| f.state_checked.is_some())
        })
        .chain(["fmi2FreeInstance"])
}

/// Functions that are legal in a state but not offered by this kind of FMU:
/// refused with "not offered" instead of "illegal call sequence".
const NOT_OFFERED: [&str; 3] = [
    "fmi2GetDirectionalDerivative",
    "fmi2SetRealInputDerivatives",
    "fmi2GetRealOutputDerivatives",
];

/// Status kinds that a synchronous slave cannot answer: fmi2Discard.
const DISCARDED_QUERIES: [&str; 3] = [
    "fmi2GetStatus",
    "fmi2GetIntegerStatus",
    "fmi2GetStringStatus",
];

/// A call that is legal in `state` and not in the error state, to see whether
/// an instance went there; `None` where the standard has none (a terminated
/// model-exchange instance allows the same calls as one in error).
fn legal_except_in_error(interface: Interface, state: State) -> Option<&'static str> {
    match state {
        State::Instantiated => Some("fmi2SetupExperiment"),
        State::InitializationMode => Some("fmi2ExitInitializationMode"),
        State::StepComplete => Some("fmi2DoStep"),
        State::EventMode => Some("fmi2EnterContinuousTimeMode"),
        State::ContinuousTimeMode => Some("fmi2SetTime"),
        State::Terminated if interface == Interface::CoSimulation => Some("fmi2GetRealStatus"),
        State::Terminated | State::Error => None,
    }
}

/// The interfaces modelDescription offers.
pub(crate) fn interfaces(fmu: &Fmu) -> Vec<Interface> {
    let mut interfaces = vec![Interface::CoSimulation];
    if fmu.offers_model_exchange() {
        interfaces.push(Interface::ModelExchange);
    }
    interfaces
}

/// Every function in every reachable state of every interface the FMU
/// offers: legal calls succeed (or are refused as not offered), illegal ones
/// (a function of the other interface among them) return fmi2Error, name the
/// function and the reason, and leave the instance in its error state.
pub fn state_machine_allows_exactly_the_standard_calls(fmu: &Fmu) {
    let mut failures = Vec::new();
    let model_exchange: &[&str] = if fmu.offers_model_exchange() {
        &MODEL_EXCHANGE_FUNCTIONS
    } else {
        &[]
    };
    for interface in interfaces(fmu) {
        for &state in interface.states() {
            for function in instance_functions()
                .chain(model_exchange.iter().copied())
                .filter(|f| *f != "fmi2FreeInstance")
            {
                let mut inst = fmu.instantiate_for(interface, "state-machine");
                inst.drive_to(state);
                let status = probe(&mut inst, function);
                let log = inst.take_log();
                let legal = allowed(interface, function, state);
                let outcome = if !legal {
                    if status != ERROR {
                        Some(format!("illegal but returned {status}"))
                    } else if !log.iter().any(|r| {
                        r.message.starts_with(function)
                            && r.message.contains("illegal call sequence")
                    }) {
                        Some(format!(
                            "refused without naming the function and the reason: {log:?}"
                        ))
                    } else if let Some(witness) = legal_except_in_error(interface, state)
                        && probe(&mut inst, witness) != ERROR
                    {
                        // Legal in the state it was in, illegal in the error state.
                        Some(format!(
                            "the instance did not enter its error state ({witness} succeeded)"
                        ))
                    } else {
                        None
                    }
                } else if NOT_OFFERED.contains(&function) {
                    (status != ERROR || !has_message(&log, "not offered"))
                        .then(|| format!("not-offered capability answered {status}: {log:?}"))
                } else if DISCARDED_QUERIES.contains(&function) {
                    (status != DISCARD)
                        .then(|| format!("expected fmi2Discard, got {status}: {log:?}"))
                } else {
                    (status != OK).then(|| format!("legal call returned {status}: {log:?}"))
                };
                if let Some(problem) = outcome {
                    failures.push(format!("{function} in {interface:?} {state:?}: {problem}"));
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "state machine violations:\n{}",
        failures.join("\n")
    );
}

/// fmi2FreeInstance works in every state, including the error state, and a
/// NULL instance is ignored.
pub fn free_instance_in_every_state(fmu: &Fmu) {
    for interface in interfaces(fmu) {
        for &state in interface.states() {
            let mut inst = fmu.instantiate_for(interface, "free");
            inst.drive_to(state);
            drop(inst);
        }
    }
    // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the ones
    // under test, which the layer must refuse without touching them, and every other pointer is
    // to a local that outlives the call with at least the length passed.
    unsafe { fmu.binding.fmi2FreeInstance(ptr::null_mut()) };
}

/// A NULL instance and a pointer that is not an instance (an FMU state) are
/// refused without a crash.
pub fn foreign_instance_pointers_are_refused(fmu: &Fmu) {
    let mut inst = fmu.instantiate("foreign", false);
    inst.initialize();
    let (status, mut state) = inst.get_state();
    assert_eq!(status, OK);
    let b = &fmu.binding;
    // SAFETY: NULL and a live FMU state of this FMU where an instance belongs:
    // what the layer must recognize as not an instance (FMI 2.0.4 §2.1.5
    // leaves it to the FMU); the state's memory is live and larger than the
    // eight bytes the layer reads to tell.
    let statuses = unsafe {
        [
            b.fmi2DoStep(ptr::null_mut(), 0.0, 1e-4, 1),
            b.fmi2DoStep(state, 0.0, 1e-4, 1),
            b.fmi2Terminate(state),
        ]
    };
    assert_eq!(statuses, [ERROR; 3]);
    assert_eq!(inst.free_state(&mut state), OK);
    assert!(state.is_null(), "fmi2FreeFMUstate sets *FMUstate to NULL");
    // The instance itself is untouched by the refused calls.
    assert_eq!(inst.do_step(1e-4), OK);
}

pub fn unknown_value_references_are_refused(fmu: &Fmu) {
    let mut inst = fmu.instantiate("unknown-vr", false);
    inst.initialize();
    let unknown = fmu.unknown_vr();
    let (status, _) = inst.get_real(&[unknown]);
    assert_eq!(status, ERROR);
    assert_logged(&inst.take_log(), "fmi2GetReal", "unknown value reference");
    assert_eq!(inst.reset(), OK);
    assert_eq!(inst.set_real(&[unknown], &[1.0]), ERROR);
    assert_logged(&inst.take_log(), "fmi2SetReal", "unknown value reference");
}

pub fn type_mismatch_is_refused(fmu: &Fmu) {
    let mut inst = fmu.instantiate("type-mismatch", false);
    inst.initialize();
    let real = fmu.real_input().vr;
    let mut value = 0i32;
    // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the ones
    // under test, which the layer must refuse without touching them, and every other pointer is
    // to a local that outlives the call with at least the length passed.
    let status = unsafe { fmu.binding.fmi2GetInteger(inst.c, &real, 1, &mut value) };
    assert_eq!(status, ERROR);
    assert_logged(&inst.take_log(), "fmi2GetInteger", "not Integer");
}

/// NULL arrays with n > 0 are refused; with n == 0 the call is a no-op.
pub fn null_arrays(fmu: &Fmu) {
    let b = &fmu.binding;
    let vr = fmu.real_input().vr;
    let mut inst = fmu.instantiate("null-arrays", false);
    inst.initialize();
    // SAFETY: `inst.c` is a live instance; NULL arrays of length 0 are valid
    // arguments (nothing is read or written).
    let statuses = unsafe {
        [
            b.fmi2GetReal(inst.c, ptr::null(), 0, ptr::null_mut()),
            b.fmi2SetReal(inst.c, ptr::null(), 0, ptr::null()),
            b.fmi2GetBoolean(inst.c, ptr::null(), 0, ptr::null_mut()),
            b.fmi2SetDebugLogging(inst.c, 1, 0, ptr::null()),
        ]
    };
    assert_eq!(statuses, [OK; 4]);
    // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the ones
    // under test, which the layer must refuse without touching them, and every other pointer is
    // to a local that outlives the call with at least the length passed.
    let status = unsafe { b.fmi2GetReal(inst.c, ptr::null(), 1, [0.0].as_mut_ptr()) };
    assert_eq!(status, ERROR, "vr[] NULL with nvr = 1 accepted");
    assert_logged(&inst.take_log(), "fmi2GetReal", "vr[] is NULL");
    let mut inst = fmu.instantiate("null-arrays", false);
    inst.initialize();
    assert_eq!(
        // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the
        // ones under test, which the layer must refuse without touching them, and every other
        // pointer is to a local that outlives the call with at least the length passed.
        unsafe { b.fmi2GetReal(inst.c, &vr, 1, ptr::null_mut()) },
        ERROR
    );
    assert_logged(&inst.take_log(), "fmi2GetReal", "value[] is NULL");
    let mut inst = fmu.instantiate("null-arrays", false);
    inst.initialize();
    // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the ones
    // under test, which the layer must refuse without touching them, and every other pointer is
    // to a local that outlives the call with at least the length passed.
    assert_eq!(unsafe { b.fmi2SetReal(inst.c, &vr, 1, ptr::null()) }, ERROR);
    let mut inst = fmu.instantiate("null-arrays", false);
    inst.initialize();
    assert_eq!(
        // SAFETY: `inst.c` is a live instance and `state` a local pointer it writes.
        unsafe { b.fmi2SetDebugLogging(inst.c, 1, 2, ptr::null()) },
        ERROR
    );
    let mut inst = fmu.instantiate("null-arrays", false);
    inst.initialize();
    // SAFETY: `inst.c` is a live instance and `state` a local pointer it writes.
    assert_eq!(unsafe { b.fmi2GetFMUstate(inst.c, ptr::null_mut()) }, ERROR);
    let mut inst = fmu.instantiate("null-arrays", false);
    inst.initialize();
    // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the ones
    // under test, which the layer must refuse without touching them, and every other pointer is
    // to a local that outlives the call with at least the length passed.
    assert_eq!(unsafe { b.fmi2SetFMUstate(inst.c, ptr::null_mut()) }, ERROR);
    let mut inst = fmu.instantiate("null-arrays", false);
    inst.initialize();
    assert_eq!(
        // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the
        // ones under test, which the layer must refuse without touching them, and every other
        // pointer is to a local that outlives the call with at least the length passed.
        unsafe {
            b.fmi2GetRealStatus(
                inst.c,
                sys::fmi2StatusKind_fmi2LastSuccessfulTime,
                ptr::null_mut(),
            )
        },
        ERROR
    );
}

/// A refused set changes nothing: all values are checked before any is stored.
pub fn non_finite_and_partial_sets_change_nothing(fmu: &Fmu) {
    let vr = fmu.real_input().vr;
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut inst = fmu.instantiate("non-finite", false);
        inst.initialize();
        assert_eq!(inst.set_real(&[vr], &[2.5]), OK);
        assert_eq!(inst.set_real(&[vr], &[bad]), ERROR, "{bad} accepted");
        assert_logged(&inst.take_log(), "fmi2SetReal", "only finite values");
        assert_eq!(inst.get_real_one(vr), 2.5, "a refused value was stored");
    }
    let mut inst = fmu.instantiate("partial", false);
    inst.initialize();
    assert_eq!(inst.set_real(&[vr], &[1.5]), OK);
    assert_eq!(inst.set_real(&[vr, fmu.unknown_vr()], &[3.0, 1.0]), ERROR);
    assert_eq!(
        inst.get_real_one(vr),
        1.5,
        "part of a refused call was applied"
    );
}

/// Fixed parameters: settable before initialization; after it, the same value
/// again is a warning and a different value an error naming the parameter.
pub fn fixed_parameters_after_initialization(fmu: &Fmu) {
    let parameter = fmu.fixed_real_parameter();
    let start = parameter.start.expect("parameters have start values");
    let mut inst = fmu.instantiate("fixed", false);
    assert_eq!(
        inst.set_real(&[parameter.vr], &[start]),
        OK,
        "settable while instantiated"
    );
    assert_eq!(inst.setup(0.0), OK);
    assert_eq!(inst.enter_init(), OK);
    assert_eq!(
        inst.set_real(&[parameter.vr], &[start]),
        OK,
        "settable in initialization mode"
    );
    assert_eq!(inst.exit_init(), OK);
    inst.take_log();
    assert_eq!(inst.set_real(&[parameter.vr], &[start]), WARNING);
    assert_logged(&inst.take_log(), "fmi2SetReal", &parameter.name);
    assert_eq!(
        inst.do_step(1e-4),
        OK,
        "the warning leaves the instance usable"
    );
    let changed = if start == 0.0 { 1.0 } else { start * 1.5 };
    assert_eq!(inst.set_real(&[parameter.vr], &[changed]), ERROR);
    let log = inst.take_log();
    assert_logged(&log, "fmi2SetReal", &parameter.name);
    assert_logged(&log, "fmi2SetReal", "fixed parameter");
    assert_eq!(inst.get_real_one(parameter.vr), start);
    assert_eq!(
        inst.do_step(1e-4),
        ERROR,
        "the instance is in its error state"
    );
    assert_eq!(inst.reset(), OK, "fmi2Reset leaves the error state");
    inst.initialize();
    assert_eq!(inst.do_step(1e-4), OK);
}

/// Tunable parameters while running: a value inside the declared range is
/// taken, one outside it is an error naming the parameter and changes
/// nothing (nothing checks the value later, as initialization checks the
/// others). Every tunable Real parameter with a declared bound is tried.
pub fn tunable_parameters_hold_their_ranges(fmu: &Fmu) {
    let tunables = fmu.variables.iter().filter(|v| {
        v.causality == Causality::Parameter
            && v.variability == Some(Variability::Tunable)
            && v.kind == "Real"
            && (v.min.is_some() || v.max.is_some())
    });
    for parameter in tunables {
        let start = parameter.start.expect("parameters have start values");
        let (inside, outside) = match (parameter.min, parameter.max) {
            (_, Some(max)) => (max, max + 1.0 + max.abs()),
            (Some(min), None) => (min, min - 1.0 - min.abs()),
            (None, None) => unreachable!("filtered above"),
        };
        let mut inst = fmu.instantiate("tunable", false);
        inst.initialize();
        assert_eq!(inst.do_step(1e-4), OK);
        assert_eq!(
            inst.set_real(&[parameter.vr], &[inside]),
            OK,
            "{} = {inside} (its bound) refused: {:#?}",
            parameter.name,
            inst.take_log()
        );
        assert_eq!(inst.set_real(&[parameter.vr], &[start]), OK);
        inst.take_log();
        assert_eq!(
            inst.set_real(&[parameter.vr], &[outside]),
            ERROR,
            "{} = {outside} accepted while running",
            parameter.name
        );
        let log = inst.take_log();
        assert_logged(&log, "fmi2SetReal", &parameter.name);
        assert_logged(&log, "fmi2SetReal", "allowed range");
        assert_eq!(inst.get_real_one(parameter.vr), start);
        assert_eq!(inst.reset(), OK, "fmi2Reset leaves the error state");
    }
}

pub fn step_sizes_must_be_positive_and_finite(fmu: &Fmu) {
    for bad in [0.0, -1e-4, f64::NAN, f64::INFINITY] {
        let mut inst = fmu.instantiate("step-size", false);
        inst.initialize();
        assert_eq!(inst.do_step(bad), ERROR, "step {bad} accepted");
        assert_logged(&inst.take_log(), "fmi2DoStep", "communicationStepSize");
    }
    // A huge step is legal and bounded in work.
    let mut inst = fmu.instantiate("huge-step", false);
    inst.initialize();
    let vr = fmu.real_input().vr;
    assert_eq!(inst.set_real(&[vr], &[5.0]), OK);
    assert_eq!(inst.do_step(1e6), OK, "{:#?}", inst.take_log());
    assert!(inst.outputs().iter().all(|v| v.is_finite()));
}

/// The communication point must continue from the FMU's time, up to rounding.
pub fn communication_points_must_continue(fmu: &Fmu) {
    let mut inst = fmu.instantiate("points", false);
    inst.initialize();
    // A point off by rounding (integer-nanosecond masters): accepted.
    let mut t = 0.0;
    for k in 1..=1000u64 {
        let next = (k * 100_000) as f64 * 1e-9;
        assert_eq!(inst.do_step_at(t, next - t), OK, "step {k}");
        t = next;
    }
    // Variable step sizes.
    for h in [1e-4, 3.7e-5, 2.5e-4] {
        assert_eq!(inst.do_step_at(t, h), OK);
        t += h;
    }
    // A skipped step: refused, with the times in the message.
    assert_eq!(inst.do_step_at(t + 1e-4, 1e-4), ERROR);
    assert_logged(&inst.take_log(), "fmi2DoStep", "does not continue");
}

/// FMU state: restoring and stepping again reproduces the outputs bit for bit,
/// in memory and through the serialized bytes.
pub fn fmu_state_restores_bit_for_bit(fmu: &Fmu) {
    let vr = fmu.real_input().vr;
    let mut inst = fmu.instantiate("state", false);
    inst.initialize();
    assert_eq!(inst.set_real(&[vr], &[4.0]), OK);
    for _ in 0..200 {
        assert_eq!(inst.do_step(1e-4), OK);
    }
    let (status, mut state) = inst.get_state();
    assert_eq!(status, OK);
    let (status, bytes) = inst.serialize(state);
    assert_eq!(status, OK);
    let t0 = inst.time;
    let run = |inst: &mut Instance<'_>| -> Vec<u64> {
        let mut trace = Vec::new();
        for k in 0..300 {
            assert_eq!(inst.set_real(&[vr], &[4.0 + (k as f64 * 0.01).sin()]), OK);
            assert_eq!(inst.do_step(1e-4), OK);
            trace.extend(inst.outputs().iter().map(|v| v.to_bits()));
        }
        trace
    };
    let first = run(&mut inst);
    assert_eq!(inst.set_state(state), OK);
    inst.time = t0;
    assert_eq!(
        run(&mut inst),
        first,
        "fmi2SetFMUstate did not reproduce the run"
    );
    // Another instance, from the bytes.
    let mut other = fmu.instantiate("state-copy", false);
    other.initialize();
    let (status, mut restored) = other.deserialize(&bytes);
    assert_eq!(status, OK, "{:#?}", other.take_log());
    assert_eq!(other.set_state(restored), OK);
    other.time = t0;
    assert_eq!(
        run(&mut other),
        first,
        "the deserialized state did not reproduce the run"
    );
    // Getting a state into an existing one reuses it.
    assert_eq!(
        // SAFETY: `inst.c` is a live instance and `state` a local pointer it writes.
        unsafe { fmu.binding.fmi2GetFMUstate(inst.c, &mut state) },
        OK
    );
    assert_eq!(inst.free_state(&mut state), OK);
    assert_eq!(other.free_state(&mut restored), OK);
    let mut null_state = ptr::null_mut();
    assert_eq!(
        inst.free_state(&mut null_state),
        OK,
        "freeing a NULL state is a no-op"
    );
}

pub fn corrupted_states_are_refused(fmu: &Fmu) {
    let mut inst = fmu.instantiate("corrupt", false);
    inst.initialize();
    let (_, mut state) = inst.get_state();
    let (status, bytes) = inst.serialize(state);
    assert_eq!(status, OK);
    assert_eq!(inst.free_state(&mut state), OK);
    let mut cases: Vec<(String, Vec<u8>)> = vec![
        ("empty".into(), Vec::new()),
        ("truncated".into(), bytes[..bytes.len() - 1].to_vec()),
        ("header only".into(), bytes[..20].to_vec()),
    ];
    for i in [0, 10, 40, bytes.len() / 2, bytes.len() - 1] {
        let mut flipped = bytes.clone();
        flipped[i] ^= 0x20;
        cases.push((format!("byte {i} flipped"), flipped));
    }
    for (name, case) in cases {
        let mut inst = fmu.instantiate("corrupt", false);
        inst.initialize();
        let (status, state) = inst.deserialize(&case);
        assert_eq!(status, ERROR, "{name} accepted");
        assert!(state.is_null(), "{name}: a state was returned");
        assert_logged(&inst.take_log(), "fmi2DeSerializeFMUstate", "refused");
    }
    // Sound bytes (a valid CRC, so written on purpose) that carry a value
    // fmi2SetReal refuses: an input set to a value whose bytes occur once in
    // the state, overwritten with NaN.
    let marker = 1_234.567_890_123_f64;
    let mut inst = fmu.instantiate("forged", false);
    inst.initialize();
    assert_eq!(inst.set_real(&[fmu.real_input().vr], &[marker]), OK);
    let (_, mut state) = inst.get_state();
    let (status, mut forged) = inst.serialize(state);
    assert_eq!(status, OK);
    assert_eq!(inst.free_state(&mut state), OK);
    let needle = marker.to_le_bytes();
    let places: Vec<usize> = forged
        .windows(needle.len())
        .enumerate()
        .filter(|(_, w)| *w == needle)
        .map(|(i, _)| i)
        .collect();
    assert_eq!(places.len(), 1, "the input's bytes occur once in the state");
    forged[places[0]..places[0] + 8].copy_from_slice(&f64::NAN.to_le_bytes());
    let body = forged.len() - 4;
    let crc = crc32fast::hash(&forged[..body]);
    forged[body..].copy_from_slice(&crc.to_le_bytes());
    let (status, restored) = inst.deserialize(&forged);
    assert_eq!(status, ERROR, "a state holding a NaN input accepted");
    assert!(restored.is_null());
    assert_logged(&inst.take_log(), "fmi2DeSerializeFMUstate", "only finite");
    // The wrong buffer size in fmi2SerializeFMUstate is refused.
    let mut inst = fmu.instantiate("corrupt", false);
    inst.initialize();
    let (_, mut state) = inst.get_state();
    let mut buffer = vec![0u8; bytes.len() - 1];
    // SAFETY: `inst.c` is a live instance, `state` one of its states, and `buffer` holds
    // `buffer.len()` bytes (one too few, the case under test).
    let status = unsafe {
        fmu.binding
            .fmi2SerializeFMUstate(inst.c, state, buffer.as_mut_ptr().cast(), buffer.len())
    };
    assert_eq!(status, ERROR);
    assert_logged(&inst.take_log(), "fmi2SerializeFMUstate", "size");
    let _ = inst.free_state(&mut state);
}

pub fn status_queries(fmu: &Fmu) {
    let b = &fmu.binding;
    let mut inst = fmu.instantiate("status", false);
    inst.initialize();
    for _ in 0..5 {
        assert_eq!(inst.do_step(1e-4), OK);
    }
    let mut time = 0.0;
    assert_eq!(
        // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the
        // ones under test, which the layer must refuse without touching them, and every other
        // pointer is to a local that outlives the call with at least the length passed.
        unsafe {
            b.fmi2GetRealStatus(
                inst.c,
                sys::fmi2StatusKind_fmi2LastSuccessfulTime,
                &mut time,
            )
        },
        OK
    );
    assert!((time - 5e-4).abs() < 1e-15, "last successful time {time}");
    let mut terminated = 1;
    assert_eq!(
        // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the
        // ones under test, which the layer must refuse without touching them, and every other
        // pointer is to a local that outlives the call with at least the length passed.
        unsafe {
            b.fmi2GetBooleanStatus(inst.c, sys::fmi2StatusKind_fmi2Terminated, &mut terminated)
        },
        OK
    );
    assert_eq!(terminated, 0);
    let mut status = OK;
    assert_eq!(
        // SAFETY: `inst.c` (or `c`) is a live instance of this FMU; the NULL arguments are the
        // ones under test, which the layer must refuse without touching them, and every other
        // pointer is to a local that outlives the call with at least the length passed.
        unsafe { b.fmi2GetStatus(inst.c, sys::fmi2StatusKind_fmi2DoStepStatus, &mut status) },
        DISCARD
    );
    assert_eq!(
        inst.do_step(1e-4),
        OK,
        "fmi2Discard leaves the instance usable"
    );
}

/// fmi2Reset returns to the start values and the instantiated state.
pub fn reset_restores_start_values(fmu: &Fmu) {
    let parameter = fmu.fixed_real_parameter();
    let start = parameter.start.unwrap();
    let input = fmu.real_input();
    let mut inst = fmu.instantiate("reset", false);
    assert_eq!(inst.set_real(&[parameter.vr], &[start * 1.01 + 1e-3]), OK);
    inst.initialize();
    assert_eq!(inst.set_real(&[input.vr], &[3.0]), OK);
    assert_eq!(inst.do_step(1e-3), OK);
    let before = inst.outputs();
    assert_eq!(inst.reset(), OK);
    assert_eq!(inst.setup(0.0), OK);
    assert_eq!(inst.enter_init(), OK);
    assert_eq!(
        inst.get_real_one(parameter.vr),
        start,
        "parameter back at its start value"
    );
    assert_eq!(
        inst.get_real_one(input.vr),
        input.start.unwrap_or(0.0),
        "input back at its start"
    );
    assert_eq!(inst.exit_init(), OK);
    assert_ne!(
        before,
        inst.outputs(),
        "the stepped state was not discarded"
    );
}

/// Logging: errors always arrive; other categories obey fmi2SetDebugLogging;
/// messages survive printf-style formatting ('%' doubled by the FMU).
pub fn logging_follows_debug_logging(fmu: &Fmu) {
    let mut inst = fmu.instantiate("logging", false);
    inst.initialize();
    inst.take_log();
    assert_eq!(inst.do_step(1e-4), OK);
    assert!(
        !inst.take_log().iter().any(|r| r.category == "logFmiCalls"),
        "call tracing is off by default"
    );
    assert_eq!(inst.set_debug_logging(true, &["logFmiCalls"]), OK);
    assert_eq!(inst.do_step(1e-4), OK);
    let log = inst.take_log();
    assert!(
        log.iter()
            .any(|r| r.category == "logFmiCalls" && r.message.starts_with("fmi2DoStep")),
        "no trace of fmi2DoStep with logFmiCalls on: {log:#?}"
    );
    // Every call is traced, not only the data calls.
    let (_, mut state) = inst.get_state();
    assert_eq!(inst.set_state(state), OK);
    assert_eq!(inst.free_state(&mut state), OK);
    assert_eq!(inst.terminate(), OK);
    assert_eq!(inst.reset(), OK);
    inst.initialize();
    let traced: Vec<String> = inst
        .take_log()
        .into_iter()
        .filter(|r| r.category == "logFmiCalls")
        .map(|r| r.message)
        .collect();
    for function in [
        "fmi2GetFMUstate",
        "fmi2SetFMUstate",
        "fmi2FreeFMUstate",
        "fmi2Terminate",
        "fmi2Reset",
        "fmi2SetupExperiment",
        "fmi2EnterInitializationMode",
        "fmi2ExitInitializationMode",
    ] {
        assert!(
            traced.iter().any(|m| m.starts_with(function)),
            "{function} was not traced with logFmiCalls on: {traced:#?}"
        );
    }
    assert_eq!(inst.set_debug_logging(false, &[]), OK);
    // That call itself was traced while tracing was still on.
    inst.take_log();
    assert_eq!(inst.do_step(1e-4), OK);
    assert!(
        inst.take_log().is_empty(),
        "messages with every category off"
    );
    // Errors are delivered even so.
    assert_eq!(inst.do_step(-1.0), ERROR);
    assert!(
        !inst.take_log().is_empty(),
        "an error was not logged with categories off"
    );

    // A '%' in a message reaches a printf-style importer intact.
    let inst = fmu.instantiate("percent", false);
    let name = "log%s%d%%Unknown";
    assert_eq!(inst.set_debug_logging(true, &[name]), WARNING);
    let log = inst.take_log();
    assert!(
        log.iter().any(|r| r.message.contains(name)),
        "the category name with '%' did not survive printf formatting: {log:#?}"
    );
    // Every record carries the instance name.
    assert!(log.iter().all(|r| r.instance_name == "percent"));
}

/// Many instances live in one process and do not influence each other.
pub fn instances_are_independent(fmu: &Fmu) {
    let vr = fmu.real_input().vr;
    let mut alone = fmu.instantiate("alone", false);
    alone.initialize();
    assert_eq!(alone.set_real(&[vr], &[6.0]), OK);
    let mut reference = Vec::new();
    for _ in 0..100 {
        assert_eq!(alone.do_step(1e-4), OK);
        reference.push(alone.outputs());
    }
    drop(alone);
    let mut a = fmu.instantiate("a", false);
    let mut b = fmu.instantiate("b", false);
    a.initialize();
    b.initialize();
    assert_eq!(a.set_real(&[vr], &[6.0]), OK);
    assert_eq!(b.set_real(&[vr], &[1.0]), OK);
    for expected in &reference {
        assert_eq!(a.do_step(1e-4), OK);
        assert_eq!(b.do_step(1e-4), OK);
        assert_eq!(
            &a.outputs(),
            expected,
            "instance b changed instance a's results"
        );
    }
}

/// N instances stepped at once in N threads give bit-identical outputs to
/// the same instances stepped one after another in one thread: the binary
/// keeps no mutable state outside its instances, and nothing in a step
/// depends on the thread or on timing.
pub fn instances_step_identically_in_threads(fmu: &Fmu) {
    const INSTANCES: usize = 4;
    const STEPS: usize = 2000;
    let vr = fmu.real_input().vr;
    let run = |k: usize| -> Vec<Vec<u64>> {
        let mut instance = fmu.instantiate(&format!("thread{k}"), false);
        instance.initialize();
        (0..STEPS)
            .map(|n| {
                let value = 1.0 + k as f64 + (n as f64 * 0.01).sin();
                assert_eq!(instance.set_real(&[vr], &[value]), OK);
                assert_eq!(instance.do_step(1e-4), OK);
                instance.outputs().iter().map(|v| v.to_bits()).collect()
            })
            .collect()
    };
    let serial: Vec<_> = (0..INSTANCES).map(run).collect();
    let parallel: Vec<_> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..INSTANCES)
            .map(|k| scope.spawn(move || run(k)))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("a stepping thread panicked"))
            .collect()
    });
    for (k, (a, b)) in serial.iter().zip(&parallel).enumerate() {
        assert!(
            a == b,
            "instance {k}: threaded results differ from serial ones"
        );
    }
}

//! String variables, the independent variable and constants: what an
//! importer may rely on for each (FMI 2.0.4 §2.1.7 for `fmi2GetString` and
//! `fmi2SetString`, §2.2.7 for causality, variability, `initial` and start
//! values).
//!
//! [`string_values_round_trip`] runs on every FMU (one without String
//! variables must refuse every value reference of the String functions as
//! another type); the others are for FMUs that declare what they check,
//! listed by `conformance_tests!(fmu, strings_time_constants)`.

use std::ffi::c_char;
use std::ptr;

use fmi_schema::fmi2::{Causality, Variability};

use super::assert_logged;
use crate::{
    ERROR, Fmu, FmuUnderTest, GetDiscrete, Instance, OK, StringValues, VariableInfo, WARNING,
};

/// Texts an importer passes: empty, markup and quotes, characters outside
/// ASCII (two, three and four bytes in UTF-8), and a long one.
fn sample_texts() -> Vec<String> {
    vec![
        String::new(),
        "plain".to_owned(),
        "<tag attr=\"1\"> & 'quote'\ttab\nnewline".to_owned(),
        "µ ✓ 𝄞".to_owned(),
        "long text ".repeat(1000),
    ]
}

/// Not UTF-8, each NUL-terminated: a lone continuation byte, an overlong
/// encoding of NUL, an encoded surrogate, a sequence cut short.
const NOT_UTF8: [&[u8]; 4] = [b"\x80\0", b"\xc0\x80\0", b"\xed\xa0\x80\0", b"ab\xe2\x82\0"];

fn string_variables(fmu: &Fmu) -> Vec<&VariableInfo> {
    fmu.variables
        .iter()
        .filter(|v| v.kind == "String")
        .collect()
}

/// Whether fmi2SetXXX may write `v` at some point: a parameter or input that
/// is not a constant.
fn settable(v: &VariableInfo) -> bool {
    matches!(v.causality, Causality::Parameter | Causality::Input)
        && v.variability != Some(Variability::Constant)
}

/// Every String variable reads its declared start value before
/// initialization; what is set is read back exactly (the FMU copies the
/// importer's text), through initialization, after it (inputs and tunable
/// parameters; a fixed parameter written again with its value is a
/// warning, with another value an error), in an FMU state and its bytes,
/// and `fmi2Reset` brings back the start values. An FMU without String
/// variables refuses the String functions as a type mismatch.
pub fn string_values_round_trip(fmu: &Fmu) {
    let strings = string_variables(fmu);
    if strings.is_empty() {
        let real = fmu.real_input().vr;
        let mut inst = fmu.instantiate("no-strings", false);
        inst.initialize();
        assert_eq!(inst.get_string(&[real]).0, ERROR);
        assert_logged(&inst.take_log(), "fmi2GetString", "not String");
        assert_eq!(inst.reset(), OK);
        assert_eq!(inst.set_string(&[real], &["text"]), ERROR);
        assert_logged(&inst.take_log(), "fmi2SetString", "not String");
        return;
    }
    let vrs: Vec<u32> = strings.iter().map(|v| v.vr).collect();
    let writable: Vec<u32> = strings
        .iter()
        .filter(|v| settable(v))
        .map(|v| v.vr)
        .collect();
    let mut inst = fmu.instantiate("strings", false);
    assert_eq!(inst.setup(0.0), OK);
    assert_eq!(inst.enter_init(), OK);
    let (status, texts) = inst.get_string(&vrs);
    assert_eq!(status, OK, "{:#?}", inst.take_log());
    for (v, text) in strings.iter().zip(&texts) {
        if let Some(start) = &v.start_string {
            assert_eq!(text, start, "{} before any set", v.name);
        }
    }
    for text in sample_texts() {
        let values = vec![text.as_str(); writable.len()];
        assert_eq!(inst.set_string(&writable, &values), OK, "{text:?}");
        let (status, read) = inst.get_string(&writable);
        assert_eq!(status, OK);
        assert!(read.iter().all(|r| *r == text), "{text:?} read as {read:?}");
    }
    // The same value reference twice in one call: two strings, both right.
    if let Some(&vr) = writable.first() {
        assert_eq!(inst.set_string(&[vr], &["twice"]), OK);
        assert_eq!(
            inst.get_string(&[vr, vr]),
            (OK, vec!["twice".to_owned(); 2])
        );
    }
    assert_eq!(inst.exit_init(), OK, "{:#?}", inst.take_log());
    for v in strings.iter().filter(|v| settable(v)) {
        let current = inst.get_string(&[v.vr]).1.remove(0);
        if v.causality == Causality::Parameter && v.variability != Some(Variability::Tunable) {
            inst.take_log();
            assert_eq!(inst.set_string(&[v.vr], &[&current]), WARNING, "{}", v.name);
            assert_logged(&inst.take_log(), "fmi2SetString", &v.name);
        } else {
            assert_eq!(
                inst.set_string(&[v.vr], &["while running"]),
                OK,
                "{}",
                v.name
            );
            assert_eq!(inst.get_string(&[v.vr]).1, ["while running"], "{}", v.name);
        }
    }
    assert_eq!(inst.do_step(1e-4), OK);
    // An FMU state carries the strings, in memory and in its bytes.
    let (_, before) = inst.get_string(&vrs);
    let (status, mut state) = inst.get_state();
    assert_eq!(status, OK);
    let (status, bytes) = inst.serialize(state);
    assert_eq!(status, OK);
    let inputs: Vec<&VariableInfo> = strings
        .iter()
        .filter(|v| v.causality == Causality::Input)
        .copied()
        .collect();
    for v in &inputs {
        assert_eq!(inst.set_string(&[v.vr], &["changed"]), OK);
    }
    assert_eq!(inst.set_state(state), OK);
    assert_eq!(
        inst.get_string(&vrs),
        (OK, before.clone()),
        "after fmi2SetFMUstate"
    );
    assert_eq!(inst.free_state(&mut state), OK);
    let mut other = fmu.instantiate("strings-copy", false);
    other.initialize();
    let (status, mut copy) = other.deserialize(&bytes);
    assert_eq!(status, OK, "{:#?}", other.take_log());
    assert_eq!(other.set_state(copy), OK);
    assert_eq!(other.get_string(&vrs), (OK, before), "from the bytes");
    assert_eq!(other.free_state(&mut copy), OK);
    // fmi2Reset: the start values again.
    assert_eq!(inst.reset(), OK);
    assert_eq!(inst.setup(0.0), OK);
    assert_eq!(inst.enter_init(), OK);
    let (_, texts) = inst.get_string(&vrs);
    for (v, text) in strings.iter().zip(&texts) {
        if let Some(start) = &v.start_string {
            assert_eq!(text, start, "{} after fmi2Reset", v.name);
        }
    }
}

/// `fmi2SetString` with a NULL element or bytes that are not UTF-8 returns
/// `fmi2Error`, logs the value reference and the reason, and stores nothing
/// (a valid element before the bad one included); a NULL `value[]` is
/// refused too. For an FMU with a settable String variable.
pub fn string_arguments_are_checked(fmu: &Fmu) {
    let v = string_variables(fmu)
        .into_iter()
        .find(|v| settable(v))
        .expect("the FMU has a settable String variable");
    let good = c"lost";
    let null: &[u8] = &[];
    for bad in NOT_UTF8.iter().chain([&null]) {
        // In initialization mode every parameter and input may be set, and
        // getters answer there and in the error state.
        let mut inst = fmu.instantiate("bad-strings", false);
        assert_eq!(inst.setup(0.0), OK);
        assert_eq!(inst.enter_init(), OK);
        assert_eq!(inst.set_string(&[v.vr], &["kept"]), OK);
        let pointer: *const c_char = if bad.is_empty() {
            ptr::null()
        } else {
            bad.as_ptr().cast()
        };
        // SAFETY: the elements are a C string literal and NULL or a
        // NUL-terminated byte string, all alive for the call.
        let status = unsafe { inst.set_string_raw(&[v.vr, v.vr], &[good.as_ptr(), pointer]) };
        assert_eq!(status, ERROR, "{bad:?} accepted");
        let log = inst.take_log();
        assert_logged(&log, "fmi2SetString", &format!("value reference {}", v.vr));
        assert_logged(
            &log,
            "fmi2SetString",
            if bad.is_empty() { "NULL" } else { "UTF-8" },
        );
        assert_eq!(
            inst.get_string(&[v.vr]),
            (OK, vec!["kept".to_owned()]),
            "{bad:?}: part of a refused call was stored"
        );
    }
    let inst = fmu.instantiate("null-values", false);
    // SAFETY: `inst.c` is live; a NULL value array with nvr = 1 is the case
    // under test, which the FMU must refuse before reading it.
    let status = unsafe {
        fmu.binding
            .fmi2SetString(inst.c, &v.vr, 1, ptr::null::<*const c_char>())
    };
    assert_eq!(status, ERROR);
    assert_logged(&inst.take_log(), "fmi2SetString", "value[] is NULL");
}

/// Sets `v` through the setter of its type with a plausible value (its start
/// value where it has one).
fn set_typed(inst: &Instance<'_>, v: &VariableInfo) -> (&'static str, fmi_sys::fmi2::fmi2Status) {
    let start = v.start.unwrap_or(0.0);
    match v.kind {
        "Real" => ("fmi2SetReal", inst.set_real(&[v.vr], &[start])),
        "Integer" => ("fmi2SetInteger", inst.set_integer(&[v.vr], &[start as i32])),
        "Boolean" => ("fmi2SetBoolean", inst.set_boolean(&[v.vr], &[start != 0.0])),
        "String" => (
            "fmi2SetString",
            inst.set_string(&[v.vr], &[v.start_string.as_deref().unwrap_or("")]),
        ),
        other => panic!("{}: no setter for {other}", v.name),
    }
}

/// Only parameters and inputs are settable: every output, local, calculated
/// parameter, constant and the independent variable is refused by the setter
/// of its type, before and after initialization, with a message naming it
/// and why.
pub fn only_parameters_and_inputs_are_settable(fmu: &Fmu) {
    let refused: Vec<&VariableInfo> = fmu.variables.iter().filter(|v| !settable(v)).collect();
    assert!(!refused.is_empty(), "every FMU has an output");
    let mut inst = fmu.instantiate("not-settable", false);
    for initialized in [false, true] {
        for v in &refused {
            assert_eq!(inst.reset(), OK);
            if initialized {
                inst.initialize();
            }
            let (function, status) = set_typed(&inst, v);
            assert_eq!(status, ERROR, "{} ({:?}) accepted", v.name, v.causality);
            let log = inst.take_log();
            assert_logged(&log, function, &v.name);
            let reason = match (&v.causality, v.variability) {
                (Causality::Independent, _) => "independent variable",
                (_, Some(Variability::Constant)) => "constant",
                _ => "causality is",
            };
            assert_logged(&log, function, reason);
        }
    }
}

/// The independent variable's value is the time: the start time from
/// initialization on, the end of each completed step, the time of a restored
/// FMU state; `fmi2SetReal` refuses it with the reason. (How it is declared,
/// FMI 2.0.4 §2.2.7, is checked for every FMU by
/// [`model_description_declares_capabilities`](super::model_description_declares_capabilities).)
pub fn independent_variable_is_the_time(fmu: &Fmu) {
    let time = fmu
        .with_causality(Causality::Independent)
        .next()
        .expect("the FMU declares an independent variable");
    let mut inst = fmu.instantiate("time", false);
    assert_eq!(inst.setup(1.25), OK);
    assert_eq!(inst.enter_init(), OK);
    assert_eq!(inst.get_real_one(time.vr), 1.25);
    assert_eq!(inst.exit_init(), OK);
    assert_eq!(inst.get_real_one(time.vr), 1.25);
    assert_eq!(inst.do_step(0.25), OK);
    assert_eq!(inst.get_real_one(time.vr), 1.5);
    let (_, mut state) = inst.get_state();
    assert_eq!(inst.do_step(0.25), OK);
    assert_eq!(inst.get_real_one(time.vr), 1.75);
    assert_eq!(inst.set_state(state), OK);
    assert_eq!(inst.get_real_one(time.vr), 1.5);
    assert_eq!(inst.free_state(&mut state), OK);
    assert_eq!(inst.set_real(&[time.vr], &[2.0]), ERROR);
    assert_logged(&inst.take_log(), "fmi2SetReal", "independent variable");
    assert_eq!(
        inst.get_real_one(time.vr),
        1.5,
        "the refused set changed the time"
    );
}

/// Every constant reads the start value it declares in every state an
/// importer can read it in: initialization, after steps, after termination,
/// after a reset. (That it is exact and declares a start value, FMI 2.0.4
/// §2.2.7, is checked for every FMU by
/// [`model_description_declares_capabilities`](super::model_description_declares_capabilities).)
pub fn constants_hold_their_start_values(fmu: &Fmu) {
    let constants: Vec<&VariableInfo> = fmu
        .variables
        .iter()
        .filter(|v| v.variability == Some(Variability::Constant))
        .collect();
    assert!(!constants.is_empty(), "the FMU declares a constant");
    let read_all = |inst: &Instance<'_>, when: &str| {
        for v in &constants {
            let matches = match v.kind {
                "Real" => inst.get_real(&[v.vr]) == (OK, vec![v.start.unwrap()]),
                "Integer" => inst.get_integer(&[v.vr]) == (OK, vec![v.start.unwrap() as i32]),
                "Boolean" => inst.get_boolean(&[v.vr]) == (OK, vec![v.start.unwrap() as i32]),
                "String" => inst.get_string(&[v.vr]) == (OK, vec![v.start_string.clone().unwrap()]),
                other => panic!("{}: no getter for {other}", v.name),
            };
            assert!(matches, "{} differs from its start value {when}", v.name);
        }
    };
    let mut inst = fmu.instantiate("constants", false);
    assert_eq!(inst.setup(0.0), OK);
    assert_eq!(inst.enter_init(), OK);
    read_all(&inst, "in initialization mode");
    assert_eq!(inst.exit_init(), OK);
    for _ in 0..10 {
        assert_eq!(inst.do_step(1e-3), OK);
    }
    read_all(&inst, "after steps");
    assert_eq!(inst.terminate(), OK);
    read_all(&inst, "after fmi2Terminate");
    assert_eq!(inst.reset(), OK);
    inst.initialize();
    read_all(&inst, "after fmi2Reset");
}

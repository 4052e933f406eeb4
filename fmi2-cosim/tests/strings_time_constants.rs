//! String variables, the independent variable and constants, through the C
//! entry points: what modelDescription declares for them (FMI 2.0.4 §2.2.7,
//! §2.2.8), `fmi2GetString`/`fmi2SetString` (strings owned by the FMU,
//! arguments copied, NULL and non-UTF-8 refused without changing anything),
//! the time as a variable, constants that no call changes, and FMU states
//! that carry strings and are refused when forged.

use std::ffi::{CStr, CString, c_char};
use std::ptr;

mod common;

use common::{ERROR, OK, WARNING, forge};
use fmi2_cosim::abi;
use fmi2_cosim::fmi_sys::fmi2 as sys;
use fmi2_cosim::model_description::model_description;
use fmi2_cosim::{
    BaseUnit, CoSimModel, Context, DefaultExperiment, ModelError, ModelInfo, StepOutcome,
    UnitDefinition, Variability, Variable, units,
};
use serde::{Deserialize, Serialize};

/// A label, a line of text fed through, and a revision number that is a
/// constant the model keeps in its own value (so a forged state can change it).
#[derive(Clone, Serialize, Deserialize)]
struct Labels {
    label: String,
    line: String,
    revision: i32,
}

/// A start value that XML must escape: markup characters, quotes, a tab and
/// a character outside ASCII.
const LABEL_START: &str = "pump <1> & \"two\"\tend µ";
const GRAVITY: f64 = 9.806_65;
/// Distinctive, so that its encoding occurs once in a serialized state.
const REVISION: i32 = 20_250_401;

static VARIABLES: &[Variable<Labels>] = &[
    Variable::string_parameter(
        "label",
        "a fixed String parameter",
        Variability::Fixed,
        |m: &Labels| &m.label,
        |m, v| m.label = v.to_owned(),
    ),
    Variable::string_input(
        "line",
        "a String input",
        |m: &Labels| &m.line,
        |m, v| m.line = v.to_owned(),
    ),
    Variable::string_output("echo", "line, fed through", |m: &Labels| &m.line)
        .depends_on(&["line"])
        .initially_depends_on(&["line"]),
    Variable::independent("time", "the simulation time", "s"),
    Variable::real_output("gravity", "a Real constant", "1", |_| GRAVITY).constant(),
    Variable {
        name: "revision",
        description: "an Integer constant the model keeps",
        causality: fmi2_cosim::Causality::Local,
        variability: Variability::Constant,
        value: fmi2_cosim::variables::Value::Integer(fmi2_cosim::variables::IntegerVariable {
            get: |m: &Labels| m.revision,
            set: None,
            min: None,
            max: None,
        }),
        output_dependencies: &[],
        initial_dependencies: Some(&[]),
        derivative_of: None,
        model_path: None,
    },
    Variable {
        name: "broken",
        description: "a String local whose model value holds a NUL byte",
        causality: fmi2_cosim::Causality::Local,
        variability: Variability::Discrete,
        value: fmi2_cosim::variables::Value::String(fmi2_cosim::variables::StringVariable {
            get: |_: &Labels| "before\0after",
            set: None,
        }),
        output_dependencies: &[],
        initial_dependencies: Some(&[]),
        derivative_of: None,
        model_path: None,
    },
];

const ONE: UnitDefinition = UnitDefinition {
    name: "1",
    base: BaseUnit::NONE,
    display_units: &[],
};

impl CoSimModel for Labels {
    const INFO: ModelInfo = ModelInfo {
        model_identifier: "Labels",
        model_name: "Labels",
        description: "strings, the time and constants",
        author: "tests",
        version: "0",
        license: "MIT",
        default_experiment: DefaultExperiment {
            start_time: 0.0,
            stop_time: 1.0,
            step_size: 0.1,
        },
    };
    const UNITS: &'static [UnitDefinition] = &[units::SECOND, ONE];

    fn variables() -> &'static [Variable<Self>] {
        VARIABLES
    }

    fn new() -> Self {
        Labels {
            label: LABEL_START.to_owned(),
            line: String::new(),
            revision: REVISION,
        }
    }

    fn exit_initialization_mode(&mut self, _: &mut Context<'_>, _: f64) -> Result<(), ModelError> {
        Ok(())
    }

    fn do_step(&mut self, _: &mut Context<'_>, _: f64, _: f64) -> Result<StepOutcome, ModelError> {
        Ok(StepOutcome::Completed)
    }
}

const LABEL: u32 = 0;
const LINE: u32 = 1;
const ECHO: u32 = 2;
const TIME: u32 = 3;
const GRAVITY_VR: u32 = 4;
const REVISION_VR: u32 = 5;
const BROKEN: u32 = 6;

type Slave = common::Slave<Labels>;

impl common::Slave<Labels> {
    fn initialized(start: f64) -> Slave {
        let slave = Slave::instantiate();
        slave.setup_and_enter(start);
        assert_eq!(slave.exit_initialization(), OK);
        slave
    }

    /// fmi2GetString of `vrs`: the status and the pointers the FMU returned.
    fn get_raw(&self, vrs: &[u32]) -> (sys::fmi2Status, Vec<sys::fmi2String>) {
        let mut out = vec![ptr::null(); vrs.len()];
        // SAFETY: both arrays hold `vrs.len()` elements.
        let status =
            unsafe { abi::get_string::<Labels>(self.0, vrs.as_ptr(), vrs.len(), out.as_mut_ptr()) };
        (status, out)
    }

    /// The texts of `vrs`, read at once (before any other call).
    fn get(&self, vrs: &[u32]) -> Vec<String> {
        let (status, out) = self.get_raw(vrs);
        assert_eq!(status, OK);
        out.iter()
            .map(|p| {
                assert!(!p.is_null());
                // SAFETY: a string the FMU returned and owns until the next
                // call on this instance; none was made since.
                unsafe { CStr::from_ptr(*p) }.to_str().unwrap().to_owned()
            })
            .collect()
    }

    fn get_one(&self, vr: u32) -> String {
        self.get(&[vr]).remove(0)
    }

    /// fmi2SetString with raw element pointers (NULL or NUL-terminated).
    fn set_raw(&self, vrs: &[u32], values: &[*const c_char]) -> sys::fmi2Status {
        assert_eq!(vrs.len(), values.len());
        // SAFETY: both arrays hold `vrs.len()` elements; each element is NULL
        // or a NUL-terminated string alive for the call.
        unsafe { abi::set_string::<Labels>(self.0, vrs.as_ptr(), vrs.len(), values.as_ptr()) }
    }

    fn set(&self, vrs: &[u32], texts: &[&str]) -> sys::fmi2Status {
        let owned: Vec<CString> = texts.iter().map(|t| CString::new(*t).unwrap()).collect();
        let pointers: Vec<*const c_char> = owned.iter().map(|c| c.as_ptr()).collect();
        self.set_raw(vrs, &pointers)
    }
}

/// The `<ScalarVariable>` element of `name` in `xml`, up to its end tag.
fn scalar_variable<'a>(xml: &'a str, name: &str) -> &'a str {
    let start = xml
        .find(&format!("<ScalarVariable name=\"{name}\""))
        .unwrap_or_else(|| panic!("no ScalarVariable {name}"));
    let end = start + xml[start..].find("</ScalarVariable>").unwrap();
    &xml[start..end]
}

/// The `start` attribute of the `<String>` element of `name`, read back as
/// an XML reader reads it (escapes resolved).
fn string_start(xml: &str, name: &str) -> Option<String> {
    use quick_xml::events::Event;
    let element = scalar_variable(xml, name);
    let mut reader = quick_xml::Reader::from_str(element);
    loop {
        match reader.read_event().unwrap() {
            Event::Empty(e) if e.name().as_ref() == "String" => {
                return e
                    .attributes()
                    .map(|a| a.unwrap())
                    .find(|a| a.key.as_ref() == "start")
                    .map(|a| {
                        a.normalized_value(quick_xml::XmlVersion::Implicit1_0)
                            .unwrap()
                            .into_owned()
                    });
            }
            Event::Eof => panic!("{name} has no String element"),
            _ => {}
        }
    }
}

#[test]
fn the_description_declares_strings_the_time_and_constants() {
    let xml = model_description::<Labels>().unwrap();
    assert_eq!(string_start(&xml, "label").as_deref(), Some(LABEL_START));
    assert_eq!(string_start(&xml, "line").as_deref(), Some(""));
    assert_eq!(string_start(&xml, "echo"), None);
    let line = scalar_variable(&xml, "line");
    assert!(
        line.contains("causality=\"input\" variability=\"discrete\""),
        "{line}"
    );
    // The independent variable: continuous Real, no start, no initial.
    let time = scalar_variable(&xml, "time");
    assert!(
        time.contains("causality=\"independent\" variability=\"continuous\">"),
        "{time}"
    );
    assert!(time.contains("<Real unit=\"s\"/>"), "{time}");
    // Constants: exact, with their value as start value.
    let gravity = scalar_variable(&xml, "gravity");
    assert!(
        gravity.contains("causality=\"output\" variability=\"constant\" initial=\"exact\""),
        "{gravity}"
    );
    assert!(gravity.contains("start=\"9.80665\""), "{gravity}");
    let revision = scalar_variable(&xml, "revision");
    assert!(
        revision.contains("variability=\"constant\" initial=\"exact\""),
        "{revision}"
    );
    assert!(
        revision.contains("<Integer start=\"20250401\"/>"),
        "{revision}"
    );
    // Outputs lists both outputs (indices 3 and 5); InitialUnknowns only the
    // one computed at initialization: a constant is known from its start.
    let structure = &xml[xml.find("<ModelStructure>").unwrap()..];
    let initial = &structure[structure.find("<InitialUnknowns>").unwrap()..];
    let outputs = &structure[..structure.find("<InitialUnknowns>").unwrap()];
    assert!(
        outputs.contains("<Unknown index=\"3\" dependencies=\"2\"/>"),
        "{outputs}"
    );
    assert!(
        outputs.contains("<Unknown index=\"5\" dependencies=\"\"/>"),
        "{outputs}"
    );
    assert!(
        initial.contains("<Unknown index=\"3\" dependencies=\"2\"/>"),
        "{initial}"
    );
    assert!(!initial.contains("index=\"5\""), "{initial}");
}

/// A model whose String start value XML 1.0 cannot carry.
#[derive(Clone, Serialize, Deserialize)]
struct Bell(String);

impl CoSimModel for Bell {
    const INFO: ModelInfo = Labels::INFO;
    const UNITS: &'static [UnitDefinition] = &[];

    fn variables() -> &'static [Variable<Self>] {
        static TABLE: &[Variable<Bell>] = &[Variable::string_parameter(
            "bell",
            "",
            Variability::Tunable,
            |m: &Bell| &m.0,
            |m, v| m.0 = v.to_owned(),
        )];
        TABLE
    }

    fn new() -> Self {
        Bell("ring\u{7}".to_owned())
    }

    fn exit_initialization_mode(&mut self, _: &mut Context<'_>, _: f64) -> Result<(), ModelError> {
        Ok(())
    }

    fn do_step(&mut self, _: &mut Context<'_>, _: f64, _: f64) -> Result<StepOutcome, ModelError> {
        Ok(StepOutcome::Completed)
    }
}

#[test]
fn a_start_value_xml_cannot_carry_is_refused_with_the_reason() {
    let err = model_description::<Bell>().unwrap_err();
    assert!(err.contains("bell") && err.contains("U+0007"), "{err}");
}

#[test]
fn strings_round_trip_and_the_output_follows_its_input_at_once() {
    let slave = Slave::instantiate();
    slave.setup_and_enter(0.0);
    assert_eq!(slave.get(&[LABEL, LINE, ECHO]), [LABEL_START, "", ""]);
    for text in ["plain", "", "ünïcödé ✓ 𝄞", &"long ".repeat(2000)] {
        assert_eq!(slave.set(&[LINE], &[text]), OK);
        assert_eq!(slave.get(&[LINE, ECHO]), [text, text]);
    }
    assert_eq!(slave.set(&[LABEL, LINE], &["left", "right"]), OK);
    assert_eq!(slave.exit_initialization(), OK);
    assert_eq!(slave.get(&[ECHO, LABEL, LINE]), ["right", "left", "right"]);
    assert_eq!(slave.step(0.0, 0.1), OK);
    assert_eq!(slave.set(&[LINE], &["after a step"]), OK);
    assert_eq!(slave.get_one(ECHO), "after a step");
    // The same variable twice in one call: two strings, both right.
    let (status, pointers) = slave.get_raw(&[ECHO, ECHO]);
    assert_eq!(status, OK);
    for p in pointers {
        // SAFETY: returned by the call just made; no call since.
        assert_eq!(unsafe { CStr::from_ptr(p) }.to_str(), Ok("after a step"));
    }
    // fmi2Reset brings back the start values.
    assert_eq!(slave.reset(), OK);
    slave.setup_and_enter(0.0);
    assert_eq!(slave.get(&[LABEL, LINE]), [LABEL_START, ""]);
}

#[test]
fn the_argument_is_copied() {
    let slave = Slave::initialized(0.0);
    let mut buffer = CString::new("first").unwrap().into_bytes_with_nul();
    assert_eq!(slave.set_raw(&[LINE], &[buffer.as_ptr().cast()]), OK);
    buffer[..5].copy_from_slice(b"XXXXX");
    assert_eq!(slave.get_one(LINE), "first");
}

#[test]
fn null_and_non_utf8_strings_are_refused_and_change_nothing() {
    let invalid: [&[u8]; 4] = [
        b"\xff\xfe\0",
        b"\xc0\x80\0",
        b"\xed\xa0\x80\0",
        b"ok\xe2\x82\0",
    ];
    let null: &[u8] = &[];
    for bad in invalid.iter().chain([&null]) {
        let slave = Slave::initialized(0.0);
        assert_eq!(slave.set(&[LINE], &["kept"]), OK);
        let pointer = if bad.is_empty() {
            ptr::null()
        } else {
            bad.as_ptr().cast()
        };
        // A good value before the bad one is not stored either.
        let good = CString::new("lost").unwrap();
        assert_eq!(
            slave.set_raw(&[LINE, LINE], &[good.as_ptr(), pointer]),
            ERROR,
            "{bad:?}"
        );
        // The error state still answers getters.
        assert_eq!(slave.get(&[LINE, ECHO]), ["kept", "kept"], "{bad:?}");
    }
}

#[test]
fn outputs_constants_and_the_time_are_never_set() {
    let refused = |set: &dyn Fn(&Slave) -> sys::fmi2Status| {
        let slave = Slave::instantiate();
        assert_eq!(set(&slave), ERROR);
        let slave = Slave::initialized(0.0);
        assert_eq!(set(&slave), ERROR);
    };
    refused(&|s| s.set(&[ECHO], &["x"]));
    refused(&|s| s.set(&[BROKEN], &["x"]));
    refused(&|s| s.set_real(TIME, 1.0));
    refused(&|s| s.set_real(GRAVITY_VR, GRAVITY));
    refused(&|s| s.set_integer(REVISION_VR, REVISION));
    // Type mismatches, both ways.
    refused(&|s| s.set(&[TIME], &["1.0"]));
    refused(&|s| s.set_real(LINE, 1.0));
    let slave = Slave::initialized(0.0);
    assert_eq!(slave.get_raw(&[GRAVITY_VR]).0, ERROR);
}

#[test]
fn a_fixed_string_parameter_is_frozen_after_initialization() {
    let slave = Slave::initialized(0.0);
    assert_eq!(slave.set(&[LABEL], &[LABEL_START]), WARNING);
    assert_eq!(slave.set(&[LABEL], &["changed"]), ERROR);
    assert_eq!(slave.get_one(LABEL), LABEL_START);
}

#[test]
fn the_independent_variable_reads_the_time() {
    let slave = Slave::instantiate();
    slave.setup_and_enter(2.5);
    assert_eq!(slave.get_real(TIME), (OK, 2.5));
    assert_eq!(slave.exit_initialization(), OK);
    assert_eq!(slave.get_real(TIME), (OK, 2.5));
    assert_eq!(slave.step(2.5, 0.25), OK);
    assert_eq!(slave.get_real(TIME), (OK, 2.75));
    let saved = slave.get_state();
    assert_eq!(slave.step(2.75, 0.25), OK);
    assert_eq!(slave.get_real(TIME), (OK, 3.0));
    assert_eq!(slave.set_state(saved), OK);
    assert_eq!(slave.get_real(TIME), (OK, 2.75));
    // Integer reads of a Real are refused, the time included.
    assert_eq!(slave.get_integer(TIME).0, ERROR);
}

#[test]
fn constants_hold_their_value_in_every_state() {
    let slave = Slave::instantiate();
    slave.setup_and_enter(0.0);
    assert_eq!(slave.get_real(GRAVITY_VR), (OK, GRAVITY));
    assert_eq!(slave.get_integer(REVISION_VR), (OK, REVISION));
    assert_eq!(slave.exit_initialization(), OK);
    assert_eq!(slave.step(0.0, 0.5), OK);
    assert_eq!(slave.get_real(GRAVITY_VR), (OK, GRAVITY));
    assert_eq!(slave.get_integer(REVISION_VR), (OK, REVISION));
}

#[test]
fn a_model_string_with_a_nul_byte_is_refused() {
    let slave = Slave::initialized(0.0);
    assert_eq!(slave.get_raw(&[LINE, BROKEN]).0, ERROR);
}

#[test]
fn fmu_states_carry_strings_and_forged_ones_are_refused() {
    let slave = Slave::initialized(0.0);
    assert_eq!(slave.set(&[LINE], &["saved line"]), OK);
    let state = slave.get_state();
    let bytes = slave.serialize(state);
    assert_eq!(slave.set(&[LINE], &["later"]), OK);
    assert_eq!(slave.set_state(state), OK);
    assert_eq!(slave.get(&[LINE, ECHO]), ["saved line", "saved line"]);
    // Through the bytes, into another instance.
    let other = Slave::initialized(0.0);
    let (status, copy) = other.deserialize(&bytes);
    assert_eq!(status, OK);
    assert_eq!(other.set_state(copy), OK);
    assert_eq!(other.get_one(ECHO), "saved line");
    // A NUL byte in a String, which no fmi2SetString can put there.
    let forged = forge(&bytes, b"saved line", b"saved\0line");
    let (status, refused) = other.deserialize(&forged);
    assert_eq!((status, refused.is_null()), (ERROR, true));
    // A constant the model keeps, changed.
    let other = Slave::initialized(0.0);
    let forged = forge(&bytes, &varint(REVISION), &varint(REVISION + 2));
    let (status, refused) = other.deserialize(&forged);
    assert_eq!((status, refused.is_null()), (ERROR, true));
    // The untouched bytes still restore (in the error state too).
    let (status, copy) = other.deserialize(&bytes);
    assert_eq!((status, copy.is_null()), (OK, false));
    assert_eq!(other.set_state(copy), OK);
    assert_eq!(other.get_integer(REVISION_VR), (OK, REVISION));
}

/// postcard's encoding of an `i32`: zigzag, then LEB128.
fn varint(n: i32) -> Vec<u8> {
    let mut zigzag = ((n << 1) ^ (n >> 31)) as u32;
    let mut out = Vec::new();
    loop {
        let byte = (zigzag & 0x7f) as u8;
        zigzag >>= 7;
        if zigzag == 0 {
            out.push(byte);
            return out;
        }
        out.push(byte | 0x80);
    }
}

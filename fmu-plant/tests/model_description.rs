//! modelDescription.xml: the committed copy matches a fresh generation, and the
//! generated file agrees with the variable table the binary serves.

use fmi_schema::fmi2::{Causality, Fmi2ModelDescription, ScalarVariableElement};
use fmi_schema::traits::FmiModelDescription;
use fmi2_cosim::CoSimModel;
use fmi2_cosim::model_description::{guid, model_description};
use fmi2_cosim::variables::{Causality as TableCausality, Value};
use fmu_plant::FlexureStageFmu;

fn generated() -> String {
    model_description::<FlexureStageFmu>().expect("the description renders")
}

#[test]
fn committed_model_description_is_current() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../modelDescription/FlexureStage.xml"
    );
    let committed = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{path}: {e}; run `make model-descriptions`"));
    assert!(
        committed == generated(),
        "modelDescription/FlexureStage.xml differs from the variable table; run `make model-descriptions` \
         and commit the result"
    );
}

#[test]
fn guid_is_deterministic_and_tracks_the_interface() {
    let first = guid::<FlexureStageFmu>().unwrap();
    assert_eq!(first, guid::<FlexureStageFmu>().unwrap());
    assert_eq!(first.len(), 38);
    assert!(generated().contains(&format!("guid=\"{first}\"")));
}

#[test]
fn parsed_description_matches_the_table() {
    let md = Fmi2ModelDescription::deserialize(&generated()).expect("fmi-schema parses it");
    let table = FlexureStageFmu::variables();
    assert_eq!(md.model_variables.variables.len(), table.len());
    let model = FlexureStageFmu::new();
    for (vr, (parsed, var)) in md.model_variables.variables.iter().zip(table).enumerate() {
        assert_eq!(parsed.name, var.name);
        assert_eq!(parsed.value_reference as usize, vr, "{}", var.name);
        let causality = match var.causality {
            TableCausality::Parameter => Causality::Parameter,
            TableCausality::CalculatedParameter => Causality::CalculatedParameter,
            TableCausality::Input => Causality::Input,
            TableCausality::Output => Causality::Output,
            TableCausality::Local => Causality::Local,
        };
        assert_eq!(parsed.causality, causality, "{}", var.name);
        match (&parsed.elem, &var.value) {
            (ScalarVariableElement::Real(r), Value::Real(v)) => {
                if var.has_start() {
                    assert_eq!(r.start, Some((v.get)(&model)), "start of {}", var.name);
                } else {
                    assert_eq!(r.start, None, "{} has no start", var.name);
                }
            }
            (ScalarVariableElement::Integer(i), Value::Integer(v)) => {
                assert_eq!(i.start, Some((v.get)(&model)), "start of {}", var.name);
            }
            (ScalarVariableElement::Boolean(b), Value::Boolean(v)) => {
                assert_eq!(b.start, Some((v.get)(&model)), "start of {}", var.name);
            }
            (parsed, _) => panic!("{}: type {parsed:?} differs from the table", var.name),
        }
    }
}

#[test]
fn ports_have_flat_names_and_units() {
    // A '.' in a port name becomes a bus in Simulink.
    let xml = generated();
    for (name, unit) in [
        ("u1", "V"),
        ("u2", "V"),
        ("u3", "V"),
        ("s1", "um"),
        ("s2", "um"),
        ("s3", "um"),
        ("x", "um"),
        ("y", "um"),
        ("theta_z", "rad"),
    ] {
        let var = FlexureStageFmu::variables()
            .iter()
            .find(|v| v.name == name)
            .unwrap_or_else(|| panic!("port {name} missing"));
        let Value::Real(r) = &var.value else {
            panic!("{name} is Real")
        };
        assert_eq!(r.unit, Some(unit), "{name}");
    }
    for var in FlexureStageFmu::variables() {
        if matches!(
            var.causality,
            TableCausality::Input | TableCausality::Output
        ) {
            assert!(
                !var.name.contains('.') && !var.name.contains('['),
                "port {} is not flat",
                var.name
            );
        }
    }
    assert!(
        xml.contains("displayUnit=\"deg\""),
        "theta_z shows in degrees"
    );
}

#[test]
fn every_parameter_maps_to_its_preset_path() {
    // The model's own validation messages name preset paths; each must map to
    // an FMI parameter, which the table records as model_path.
    for var in FlexureStageFmu::variables() {
        if var.causality == TableCausality::Parameter {
            let path = var
                .model_path
                .unwrap_or_else(|| panic!("{} has no model path", var.name));
            assert!(
                !path.contains(' '),
                "{}: model path {path:?} has spaces",
                var.name
            );
        }
    }
}

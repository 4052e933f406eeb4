//! modelDescription.xml: the committed copy matches a fresh generation, and the
//! generated file agrees with the variable table the binary serves.

use fmi_schema::fmi2::Fmi2ModelDescription;
use fmi_schema::traits::FmiModelDescription;
use fmi2_cosim::model_description::model_description;
use fmu_controller::PiezoControllerFmu;

fmi2_conformance::table_tests!(
    PiezoControllerFmu,
    concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../modelDescription/PiezoController.xml"
    )
);

fn xml() -> String {
    model_description::<PiezoControllerFmu>().expect("the description renders")
}

fn parsed() -> Fmi2ModelDescription {
    Fmi2ModelDescription::deserialize(&xml()).expect("fmi-schema parses it")
}

#[test]
fn ports_have_the_units_users_wire() {
    fmi2_conformance::table::ports_have_units::<PiezoControllerFmu>(&[
        ("x_ref", "um"),
        ("y_ref", "um"),
        ("theta_ref", "rad"),
        ("s1", "um"),
        ("s2", "um"),
        ("s3", "um"),
        ("u1", "V"),
        ("u2", "V"),
        ("u3", "V"),
        ("e_x", "um"),
        ("e_y", "um"),
        ("e_theta", "rad"),
        ("x_r2", "um"),
        ("x_r3", "um"),
        ("y_rx", "um"),
        ("y_rtheta", "um"),
    ]);
}

#[test]
fn model_parameters_have_structured_names() {
    // The names the documentation promises users.
    let md = parsed();
    let names: Vec<&str> = md
        .model_variables
        .variables
        .iter()
        .map(|v| v.name.as_str())
        .collect();
    let has = |name: String| assert!(names.contains(&name.as_str()), "{name} is missing");
    for axis in ["x", "y"] {
        for i in 1..=10 {
            has(format!("{axis}.k[{i}]"));
            has(format!("{axis}.b[{i}]"));
        }
        for j in 1..=6 {
            has(format!("{axis}.ws[{j}]"));
        }
        for i in 1..=4 {
            has(format!("{axis}.a[{i}]"));
        }
        has(format!("{axis}.c"));
        has(format!("{axis}.u1max"));
    }
    for field in ["dk", "db", "p", "q"] {
        for i in 1..=4 {
            has(format!("compensation.{field}[{i}]"));
        }
    }
    for name in [
        "feedforward",
        "decoupling",
        "feedback_x",
        "feedback_y",
        "feedback_theta",
        "translation.kp",
        "translation.ki",
        "rotation.kp",
        "rotation.ki",
        "L",
    ] {
        has(name.to_owned());
    }
    assert_eq!(
        md.variable_naming_convention.as_deref(),
        Some("structured"),
        "names carry indices"
    );
}

#[test]
fn outputs_have_no_direct_feedthrough() {
    // The controller samples its inputs at the start of a step and its outputs
    // hold from the end: an importer must see no algebraic loop through it. An
    // absent `dependencies` attribute would mean "depends on everything", so
    // the attribute must be present and empty (fmi-schema cannot tell the two
    // apart, hence the text).
    assert_eq!(parsed().model_structure.outputs.unknowns.len(), 16);
    let text = xml();
    let outputs = &text[text.find("<Outputs>").unwrap()..text.find("</Outputs>").unwrap()];
    let unknowns: Vec<&str> = outputs.split("<Unknown ").skip(1).collect();
    assert_eq!(unknowns.len(), 16);
    for unknown in unknowns {
        assert!(
            unknown.contains("dependencies=\"\""),
            "an output declares feedthrough or omits its dependencies: <Unknown {unknown}"
        );
    }
}

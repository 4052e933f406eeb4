//! The generated modelDescription agrees with the variable table, the table
//! keeps its released value references, and it holds what the fixture
//! promises: a variable of every type, causality and variability the layer
//! serves.

use fmi2_cosim::CoSimModel;
use fmi2_cosim::variables::Value;
use fmi2_cosim::{Causality, Variability};
use fmu_fixture::Feedthrough;

#[test]
fn guid_is_deterministic_and_tracks_the_interface() {
    fmi2_conformance::table::guid_is_deterministic::<Feedthrough>();
}

#[test]
fn parsed_description_matches_the_table() {
    fmi2_conformance::table::parsed_description_matches_the_table::<Feedthrough>();
}

#[test]
fn ports_have_flat_names() {
    fmi2_conformance::table::ports_have_flat_names::<Feedthrough>();
}

#[test]
fn every_parameter_has_a_model_path() {
    fmi2_conformance::table::every_parameter_has_a_model_path::<Feedthrough>();
}

#[test]
fn value_references_are_append_only() {
    fmi2_conformance::table::value_references_are_append_only(
        Feedthrough::variables(),
        include_str!("../valueReferences.txt"),
    );
}

#[test]
fn the_table_covers_what_the_layer_serves() {
    let table = Feedthrough::variables();
    for kind in ["Real", "Integer", "Boolean", "String"] {
        for causality in [Causality::Parameter, Causality::Input, Causality::Output] {
            assert!(
                table
                    .iter()
                    .any(|v| v.value.type_name() == kind && v.causality == causality),
                "no {kind} {causality:?}"
            );
        }
    }
    for (causality, variability) in [
        (Causality::Parameter, Variability::Fixed),
        (Causality::Parameter, Variability::Tunable),
        (Causality::CalculatedParameter, Variability::Fixed),
        (Causality::Input, Variability::Continuous),
        (Causality::Input, Variability::Discrete),
        (Causality::Output, Variability::Constant),
        (Causality::Output, Variability::Continuous),
        (Causality::Output, Variability::Discrete),
        (Causality::Local, Variability::Continuous),
        (Causality::Local, Variability::Discrete),
        (Causality::Independent, Variability::Continuous),
    ] {
        assert!(
            table
                .iter()
                .any(|v| v.causality == causality && v.variability == variability),
            "no {causality:?} {variability:?}"
        );
    }
    let time = table
        .iter()
        .find(|v| v.causality == Causality::Independent)
        .expect("the independent variable");
    assert!(matches!(time.value, Value::Time(_)));
    // Every output but the constant is an input fed through, declared as
    // direct feedthrough.
    for output in table
        .iter()
        .filter(|v| v.causality == Causality::Output && v.variability != Variability::Constant)
    {
        let [input] = output.output_dependencies else {
            panic!("{} depends on one input", output.name)
        };
        let input = table.iter().find(|v| v.name == *input).expect("declared");
        assert_eq!(input.causality, Causality::Input);
        assert_eq!(input.value.type_name(), output.value.type_name());
        assert_eq!(input.variability, output.variability, "{}", output.name);
    }
}

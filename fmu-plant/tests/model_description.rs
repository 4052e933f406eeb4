//! modelDescription.xml: the committed copy matches a fresh generation, and the
//! generated file agrees with the variable table the binary serves.

use fmi2_cosim::model_description::model_description;
use fmu_plant::FlexureStageFmu;

fmi2_conformance::table_tests!(
    FlexureStageFmu,
    concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../modelDescription/FlexureStage.xml"
    )
);

#[test]
fn ports_have_the_units_users_wire() {
    fmi2_conformance::table::ports_have_units::<FlexureStageFmu>(&[
        ("u1", "V"),
        ("u2", "V"),
        ("u3", "V"),
        ("s1", "um"),
        ("s2", "um"),
        ("s3", "um"),
        ("x", "um"),
        ("y", "um"),
        ("theta_z", "rad"),
    ]);
    let xml = model_description::<FlexureStageFmu>().expect("the description renders");
    assert!(
        xml.contains("displayUnit=\"deg\""),
        "theta_z shows in degrees"
    );
}

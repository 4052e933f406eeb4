//! The variable table against what it must keep: the released value
//! references (append-only, `valueReferences.txt`) and the parameter ranges
//! piezo-models declares (the model refuses what the table says is out of
//! range, and an open end is stated in the description).

use fmi2_cosim::CoSimModel;
use fmu_plant::FlexureStageFmu;
use piezo_models::FlexureStageParams;

#[test]
fn value_references_are_append_only() {
    fmi2_conformance::table::value_references_are_append_only(
        FlexureStageFmu::variables(),
        include_str!("../valueReferences.txt"),
    );
}

#[test]
fn declared_ranges_agree_with_the_model() {
    piezo_fmu_tables::check_declared_ranges(
        FlexureStageFmu::variables(),
        || FlexureStageFmu::with_params(FlexureStageParams::default()).unwrap(),
        |m| m.params().validate(),
        // T > 10 amplifier time constants, which the bandwidth sets.
        &[".creep_time"],
    );
}

/// `flexure-stage-parameters` given its own output (a set by FMI name, as
/// `dist/presets/` holds) says what the file is and what the tool takes.
#[test]
fn a_set_by_fmi_name_is_named_as_such() {
    fmi2_conformance::table::a_set_by_fmi_name_is_named_as_such(
        env!("CARGO_BIN_EXE_flexure-stage-parameters"),
        "3dof",
        "FlexureStage",
        "3dof, 3dof_memory, 3dof_no_memory, xy200s or a FlexureStageParams JSON file",
    );
}

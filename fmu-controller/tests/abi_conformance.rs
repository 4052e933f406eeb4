//! The PiezoController binary, driven through the C ABI as an importer drives
//! it (dlopen, official typedefs, printf-style logger): every state-machine and
//! argument rule of the FMI layer.

use fmu_controller::PiezoControllerFmu;

fmi2_conformance::conformance_tests!(
    fmi2_conformance::cdylib_path(
        "fmu_controller",
        std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/..")),
        &["fmu-controller/src", "fmi2-cosim/src", "fmi2-cosim/linker", "piezo-models/src", "piezo-models/presets"],
    ),
    fmi2_cosim::model_description::model_description::<PiezoControllerFmu>()
        .expect("the description renders");
    exports_every_function_and_nothing_else,
    reports_platform_and_version,
    model_description_declares_capabilities,
    declared_dependencies_hold,
    instantiate_refuses_bad_arguments,
    resource_locations_in_every_spelling,
    state_machine_allows_exactly_the_standard_calls,
    free_instance_in_every_state,
    foreign_instance_pointers_are_refused,
    unknown_value_references_are_refused,
    type_mismatch_is_refused,
    null_arrays,
    non_finite_and_partial_sets_change_nothing,
    fixed_parameters_after_initialization,
    calculated_variables_are_not_settable,
    step_sizes_must_be_positive_and_finite,
    communication_points_must_continue,
    fmu_state_restores_bit_for_bit,
    corrupted_states_are_refused,
    fmu_state_restores_every_machine_state,
    status_queries,
    reset_restores_start_values,
    logging_follows_debug_logging,
    instances_are_independent,
    instances_step_identically_in_threads,
);

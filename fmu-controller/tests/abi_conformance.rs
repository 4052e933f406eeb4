//! The PiezoController binary, driven through the C ABI as an importer drives
//! it (dlopen, official typedefs, printf-style logger): every state-machine and
//! argument rule of the FMI layer.

#[path = "../../tests/docs_figures.rs"]
mod docs_figures;

use fmi2_conformance::Interface;
use fmi2_conformance::checks::RestoreCases;

fmi2_conformance::conformance_tests!(
    fmi2_conformance::workspace::load::<fmu_controller::PiezoControllerFmu>("fmu-controller"),
    restore_cases => restore_cases_are_documented
);

/// docs/fmi.md ("FMU state: restart and recovery") prints how many restores
/// the check makes per FMU in Co-Simulation, the one interface this FMU
/// offers: the count of the run itself must be the printed one.
fn restore_cases_are_documented(cases: &[RestoreCases]) {
    let [run] = cases else {
        panic!("restores in one interface expected: {cases:?}")
    };
    assert_eq!(run.interface, Interface::CoSimulation);
    docs_figures::assert_count_documented(
        "fmi.md",
        "That is",
        "cases per FMU for Co-Simulation",
        &run.to_string(),
    );
}

//! The FlexureStage binary, driven through the C ABI as an importer drives it
//! (dlopen, official typedefs, printf-style logger): every state-machine and
//! argument rule of the FMI layer, for Co-Simulation and Model Exchange.

#[path = "../../tests/docs_figures.rs"]
mod docs_figures;

use fmi2_conformance::Interface;
use fmi2_conformance::checks::RestoreCases;

fmi2_conformance::conformance_tests!(
    fmi2_conformance::workspace::load::<fmu_plant::FlexureStageFmu>("fmu-plant"),
    model_exchange,
    restore_cases => restore_cases_are_documented
);

/// docs/fmi.md ("FMU state: restart and recovery") prints how many restores
/// the check makes in each interface: the count of the run itself must be
/// the printed one.
fn restore_cases_are_documented(cases: &[RestoreCases]) {
    let printed = [
        (
            Interface::CoSimulation,
            "That is",
            "cases per FMU for Co-Simulation",
        ),
        (
            Interface::ModelExchange,
            "Co-Simulation and",
            "for FlexureStage's Model Exchange",
        ),
    ];
    for (interface, before, after) in printed {
        let run = cases
            .iter()
            .find(|case| case.interface == interface)
            .unwrap_or_else(|| panic!("no {interface:?} restores were run: {cases:?}"));
        docs_figures::assert_count_documented("fmi.md", before, after, &run.to_string());
    }
}

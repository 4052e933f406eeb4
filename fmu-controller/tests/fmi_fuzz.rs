//! The call-sequence fuzzer (fmi2_conformance::fuzz) on the PiezoController
//! binary, with the FlexureStage binary as the other FMU whose instances
//! and states it passes by mistake. `FMI_FUZZ_CALLS` and `FMI_FUZZ_SEED` run it
//! longer or replay a failure; `-- --nocapture` shows the figures.

#[path = "../../tests/docs_figures.rs"]
mod docs_figures;

use fmi2_conformance::{fuzz, workspace};
use fmu_controller::PiezoControllerFmu;

/// Calls in the normal suite: about 7 s in release on the 2-core build
/// machine, enough for every function in every state many times over (the
/// report's per-state and per-function counts show it).
const CALLS: u64 = 1_000_000;
const SEED: u64 = 0x5eed_0002;

#[test]
fn random_call_sequences_keep_every_rule() {
    let fmu = workspace::load::<PiezoControllerFmu>("fmu-controller");
    let other = workspace::load_committed("fmu-plant", "FlexureStage");
    let report = fuzz::assert_rules_hold(&fmu, &other, CALLS, SEED);
    let config = fuzz::FuzzConfig::from_env(CALLS, SEED);
    if (config.calls, config.seed) == (CALLS, SEED) {
        // docs/robustness.md prints this run's counts (the time varies).
        let row = docs_figures::row(
            &format!("`make test`, PiezoController, seed {SEED:#x}"),
            report.table_cells(),
            &[fuzz::FuzzReport::TIME_CELL],
        );
        docs_figures::assert_documented("robustness.md", "## Call-sequence fuzzing", 1, &[row]);
    }
}

//! The call-sequence fuzzer (fmi2_conformance::fuzz) on the FlexureStage
//! binary, with the PiezoController binary as the other FMU whose instances
//! and states it passes by mistake. `FMI_FUZZ_CALLS` and `FMI_FUZZ_SEED` run it
//! longer or replay a failure; `-- --nocapture` shows the figures.

#[path = "../../tests/docs_figures.rs"]
mod docs_figures;

use fmi2_conformance::{fuzz, workspace};
use fmu_plant::FlexureStageFmu;

/// Calls in the normal suite: about 7 s in release on the 2-core build
/// machine, enough for every function in every state many times over (the
/// report's per-state and per-function counts show it).
const CALLS: u64 = 200_000;
const SEED: u64 = 0x5eed_0001;

#[test]
fn random_call_sequences_keep_every_rule() {
    let fmu = workspace::load::<FlexureStageFmu>("fmu-plant");
    let other = workspace::load_committed("fmu-controller", "PiezoController");
    let report = fuzz::assert_rules_hold(&fmu, &other, CALLS, SEED);
    let config = fuzz::FuzzConfig::from_env(CALLS, SEED);
    if (config.calls, config.seed) == (CALLS, SEED) {
        // docs/robustness.md prints this run's counts (the time varies).
        let row = docs_figures::row(
            &format!("`make test`, FlexureStage, seed {SEED:#x}"),
            report.table_cells(),
            &[fuzz::FuzzReport::TIME_CELL],
        );
        docs_figures::assert_documented("robustness.md", "## Call-sequence fuzzing", 1, &[row]);
    }
}

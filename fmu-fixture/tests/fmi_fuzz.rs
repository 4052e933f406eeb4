//! The call-sequence fuzzer (fmi2_conformance::fuzz) on the Feedthrough
//! fixture, with the PiezoController binary as the other FMU whose instances
//! and states it passes by mistake. `FMI_FUZZ_CALLS` and `FMI_FUZZ_SEED` run it
//! longer or replay a failure; `-- --nocapture` shows the figures.

#[path = "../../tests/docs_figures.rs"]
mod docs_figures;

use fmi2_conformance::{fuzz, workspace};
use fmu_fixture::Feedthrough;

/// Calls in the normal suite: the fixture's model costs next to nothing, so
/// the budget buys coverage of the layer (every function in every state, the
/// report's counts show it) in a few seconds of release time.
const CALLS: u64 = 300_000;
const SEED: u64 = 0x5eed_0003;

#[test]
fn random_call_sequences_keep_every_rule() {
    let fmu = workspace::load::<Feedthrough>("fmu-fixture");
    let other = workspace::load_committed("fmu-controller", "PiezoController");
    let report = fuzz::assert_rules_hold(&fmu, &other, CALLS, SEED);
    let config = fuzz::FuzzConfig::from_env(CALLS, SEED);
    if (config.calls, config.seed) == (CALLS, SEED) {
        // docs/robustness.md prints this run's counts (the time varies).
        let row = docs_figures::row(
            &format!("`make test`, Feedthrough, seed {SEED:#x}"),
            report.table_cells(),
            &[fuzz::FuzzReport::TIME_CELL],
        );
        docs_figures::assert_documented("robustness.md", "## Call-sequence fuzzing", 1, &[row]);
    }
}

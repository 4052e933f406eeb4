//! The call-sequence fuzzer (fmi2_conformance::fuzz) on the PiezoController
//! binary, with the FlexureStage binary as the other FMU whose instances
//! and states it passes by mistake. `FMI_FUZZ_CALLS` and `FMI_FUZZ_SEED` run it
//! longer or replay a failure; `-- --nocapture` shows the figures.

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
    fuzz::assert_rules_hold(&fmu, &other, CALLS, SEED);
}

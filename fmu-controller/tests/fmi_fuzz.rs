//! The call-sequence fuzzer (fmi2_conformance::fuzz) on the PiezoController
//! binary, with the FlexureStage binary as the other FMU whose instances
//! and states it passes by mistake. `FMI_FUZZ_CALLS` and `FMI_FUZZ_SEED` run it
//! longer or replay a failure; `-- --nocapture` shows the figures.

use std::path::Path;

use fmi2_conformance::Fmu;
use fmi2_conformance::fuzz;
use fmu_controller::PiezoControllerFmu;

/// Calls in the normal suite: about 7 s in release on the 2-core build
/// machine, enough for every function in every state many times over (the
/// report's per-state and per-function counts show it).
const CALLS: u64 = 1_000_000;
const SEED: u64 = 0x5eed_0002;

#[test]
fn random_call_sequences_keep_every_rule() {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let fmu = Fmu::load(
        &fmi2_conformance::cdylib_path(
            "fmu_controller",
            root,
            &[
                "fmu-controller/src",
                "fmi2-cosim/src",
                "fmi2-cosim/linker",
                "piezo-models/src",
                "piezo-models/presets",
            ],
        ),
        &fmi2_cosim::model_description::model_description::<PiezoControllerFmu>()
            .expect("the description renders"),
    );
    // The other FMU's description as committed (its own tests keep it current).
    let other = Fmu::load(
        &fmi2_conformance::cdylib_path(
            "fmu_plant",
            root,
            &[
                "fmu-plant/src",
                "fmi2-cosim/src",
                "fmi2-cosim/linker",
                "piezo-models/src",
                "piezo-models/presets",
            ],
        ),
        &std::fs::read_to_string(root.join("modelDescription/FlexureStage.xml"))
            .expect("the committed FlexureStage description"),
    );
    fuzz::assert_rules_hold(&fmu, &other, CALLS, SEED);
}

//! The call-sequence fuzzer (fmi2_conformance::fuzz) on the FlexureStage
//! binary, with the PiezoController binary as the other FMU whose instances
//! and states it passes by mistake. `FMI_FUZZ_CALLS` and `FMI_FUZZ_SEED` run it
//! longer or replay a failure; `-- --nocapture` shows the figures.

use std::path::Path;

use fmi2_conformance::Fmu;
use fmi2_conformance::fuzz;
use fmu_plant::FlexureStageFmu;

/// Calls in the normal suite: about 7 s in release on the 2-core build
/// machine, enough for every function in every state many times over (the
/// report's per-state and per-function counts show it).
const CALLS: u64 = 200_000;
const SEED: u64 = 0x5eed_0001;

#[test]
fn random_call_sequences_keep_every_rule() {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let fmu = Fmu::load(
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
        &fmi2_cosim::model_description::model_description::<FlexureStageFmu>()
            .expect("the description renders"),
    );
    // The other FMU's description as committed (its own tests keep it current).
    let other = Fmu::load(
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
        &std::fs::read_to_string(root.join("modelDescription/PiezoController.xml"))
            .expect("the committed PiezoController description"),
    );
    fuzz::assert_rules_hold(&fmu, &other, CALLS, SEED);
}

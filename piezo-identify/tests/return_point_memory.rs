//! `bouc-wen --return-point-memory` on the real P-885 records: fitted on
//! the identification record (a 1 Hz sine of one amplitude) and run on the
//! validation record (1 Hz, the amplitude ramping up and down), the model
//! whose minor loops close predicts the unseen record better than seed
//! 001's eq. (3) as integrated, and better than the classical P-I model
//! (docs/identification.md, "Return-point memory on the P-885 records").

use std::path::{Path, PathBuf};
use std::process::Command;

fn p885(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/piezo-p885")
        .join(file)
}

/// The defaults of `bouc-wen` on Model_Vi_Do.dat, validated on
/// Test_Vi_Do_Di.dat, with `extra`; the report's validation errors [um RMS]
/// of the Bouc-Wen and classical P-I models, and what `--out` wrote.
fn validation_rms(extra: &[&str]) -> (f64, f64, serde_json::Value) {
    let dir = tempfile::tempdir().unwrap();
    let report = dir.path().join("report.json");
    let model = dir.path().join("model.json");
    let fit = p885("Model_Vi_Do.dat");
    let validate = p885("Test_Vi_Do_Di.dat");
    let output = Command::new(env!("CARGO_BIN_EXE_piezo-identify"))
        .args([
            "bouc-wen",
            fit.to_str().unwrap(),
            "--input",
            "0",
            "--output",
            "4",
            "--rate",
            "200",
            "--validate",
            validate.to_str().unwrap(),
            "--report",
            report.to_str().unwrap(),
            "--out",
            model.to_str().unwrap(),
        ])
        .args(extra)
        .output()
        .expect("the binary runs");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let read = |path: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
    };
    let errors = &read(&report)["validation"]["errors"];
    let rms = |model: &str| errors[model]["rms"].as_f64().unwrap();
    (rms("bouc_wen"), rms("classical"), read(&model))
}

/// Measured at the commit that added the option: 1.184 um without the
/// memory, 0.831 um with it, 1.047 um for the classical P-I model. The
/// bounds leave the memory's gain room to shrink by half before failing
/// (0.831 is 0.70 of 1.184; the bound is 0.85) and keep it under the
/// classical P-I model, which it beats by 21 %.
#[test]
fn the_memory_predicts_the_unseen_p885_record_better() {
    let (without, classical, written_without) = validation_rms(&[]);
    let (with, classical_again, written_with) = validation_rms(&["--return-point-memory"]);
    assert_eq!(
        classical, classical_again,
        "the baseline does not depend on the option"
    );
    assert!(
        with <= 0.85 * without,
        "with memory {with} um, without {without} um"
    );
    assert!(
        with < classical,
        "with memory {with} um, classical P-I {classical} um"
    );
    // The written model says how it must be run.
    assert_eq!(written_without["return_point_memory"], false);
    assert_eq!(written_with["return_point_memory"], true);
}

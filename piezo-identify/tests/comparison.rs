//! (e) Seed 000's model comparison on the simulated stage: the proposed model
//! (10 backlash + 6 dead-zone + cubic) reaches a lower F (eq. 7) than the
//! traditional 10 + 6 and 10 + 10 models on the same eq. (6) record.
//!
//! Test budget: the search runs at 200 Hz (every 50th sample of the 10 kHz
//! record, 2000 samples) with 8 starts per model instead of the CLI's 500 Hz
//! and 30 starts; F is still reported on the full 10 kHz record. README gives
//! the figures of the full protocol (`piezo-identify compare --synthetic`).

use piezo_identify::FitOptions;
use piezo_identify::compare::{
    IDENTIFICATION_DURATION, PLANT_SAMPLE_RATE, compare_inverse_models, synthetic_plant_record,
};

#[test]
fn proposed_model_has_the_lowest_objective_on_the_plant() {
    let record = synthetic_plant_record(IDENTIFICATION_DURATION, PLANT_SAMPLE_RATE).unwrap();
    assert_eq!(record.output.len(), 100_000);
    let stroke = record
        .output
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    // The stage preset is calibrated to seed 000's 12.22 µm y stroke at 100 V,
    // which eq. (6) reaches (it is clipped at 10 V): a sanity check of the data.
    assert!((11.5..13.0).contains(&stroke), "y stroke {stroke} um");

    let options = FitOptions {
        starts: 8,
        seed: 0,
        decimation: 50,
        ..FitOptions::default()
    };
    let comparison = compare_inverse_models(
        &record.output,
        &record.input,
        record.sample_period,
        &options,
        5,
        &|_| {},
    )
    .unwrap();
    for s in &comparison.summaries {
        println!(
            "{:<44} {} parameters: F = {:.4} V^2 on 100000 samples (RMS {:.5} V, max {:.4} V), {:.1} ns/sample",
            s.name,
            s.parameter_count,
            s.objective,
            s.rms_volts,
            s.max_abs_volts,
            s.evaluation.median_ns_per_sample
        );
    }
    let [proposed, six, ten] = &comparison.summaries;
    assert_eq!(proposed.parameter_count, ten.parameter_count);
    assert!(
        proposed.objective < six.objective,
        "proposed F {} vs 10+6 F {}",
        proposed.objective,
        six.objective
    );
    assert!(
        proposed.objective < ten.objective,
        "proposed F {} vs 10+10 F {}",
        proposed.objective,
        ten.objective
    );
}

//! The default identification's speed target: a default inverse-pi fit of a
//! 50,000-sample record in 10 s or less on the project's 2-core machine.
//!
//! The record is the one a lab takes (`lab_records`): 2 s at rest, then a
//! 1 Hz sine of 0.5..9.5 V for 8 s, sampled at 5 kHz, sensor offset and
//! noise. The fit is everything `piezo-identify inverse-pi FILE` does with
//! its defaults on the whole record: rest/step detection, the validation
//! search and linear candidates inside the fit part, the final search, the
//! classical P-I baseline and every error.
//!
//! `cargo bench -p piezo-identify --bench identification`

use criterion::{Criterion, criterion_group, criterion_main};
use piezo_identify::lab_records::{Drive, Excitation, LabRecordSpec, lab_record};
use piezo_identify::protocol::{InversePiSettings, Plan, PlanOptions, identify_inverse_pi};

fn default_inverse_pi_fit(c: &mut Criterion) {
    let record = lab_record(&LabRecordSpec::new(
        5000.0,
        Drive::Unipolar,
        Excitation::Sine { frequency: 1.0 },
        8.0,
    ))
    .expect("the lab record is valid");
    assert_eq!(record.input.len(), 50_000);
    let mut group = c.benchmark_group("identification");
    group.sample_size(10);
    group.bench_function("default inverse-pi fit, 50000 samples", |b| {
        b.iter(|| {
            let plan = Plan::new(
                &record.input,
                record.sample_period,
                record.input.len(),
                &PlanOptions::default(),
            )
            .expect("the record has an excitation");
            identify_inverse_pi(&record, &plan, &InversePiSettings::default(), &|_| {})
                .expect("the record fits")
        })
    });
    group.finish();
}

criterion_group!(benches, default_inverse_pi_fit);
criterion_main!(benches);

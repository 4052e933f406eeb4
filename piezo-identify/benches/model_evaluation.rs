//! Evaluation time of one sample of each inverse model of seed 000's
//! comparison (the response time of Fig. 4): the proposed model
//! (`piezo_models::ModifiedInversePi`, the controller's evaluator) and the
//! traditional 10 + 6 and 10 + 10 models, each fitted on the synthetic plant
//! record (a quick fit: the time of one evaluation does not depend on how well
//! the parameters fit, only on their being typical), then stepped sample by
//! sample along that record.
//!
//! `cargo bench -p piezo-identify --bench model_evaluation`

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use piezo_identify::compare::{
    IDENTIFICATION_DURATION, PLANT_SAMPLE_RATE, compare_inverse_models, synthetic_plant_record,
};
use piezo_identify::{FitOptions, InverseHysteresis, TraditionalInversePi};
use piezo_models::ModifiedInversePi;
use piezo_models::inverse_pi::backward_rates;

/// Steps the model through the record one sample per iteration, wrapping
/// around (the memories then carry on from the end, which is as typical a
/// state as any).
fn bench_model<M: InverseHysteresis>(
    c: &mut Criterion,
    name: &str,
    mut model: M,
    y: &[f64],
    rates: &[f64],
) {
    let mut n = 0;
    c.bench_function(name, |b| {
        b.iter(|| {
            let u = model.evaluate(black_box(y[n]), black_box(rates[n]));
            n = if n + 1 == y.len() { 0 } else { n + 1 };
            u
        })
    });
}

fn model_evaluation(c: &mut Criterion) {
    let record = synthetic_plant_record(IDENTIFICATION_DURATION, PLANT_SAMPLE_RATE)
        .expect("the default stage preset is valid");
    let options = FitOptions {
        starts: 2,
        max_iterations: 200,
        decimation: 50,
        ..FitOptions::default()
    };
    let comparison = compare_inverse_models(
        &record.output,
        &record.input,
        record.sample_period,
        &options,
        1,
        &|_| {},
    )
    .expect("the synthetic record fits");
    let rates = backward_rates(&record.output, record.sample_period);
    let y = &record.output;
    bench_model(
        c,
        "proposed 10 backlash + 6 dead-zone + cubic (ModifiedInversePi)",
        ModifiedInversePi::new(comparison.proposed.params),
        y,
        &rates,
    );
    bench_model(
        c,
        "traditional 10 backlash + 6 dead-zone",
        TraditionalInversePi::new(comparison.traditional_six.params),
        y,
        &rates,
    );
    bench_model(
        c,
        "traditional 10 backlash + 10 dead-zone",
        TraditionalInversePi::new(comparison.traditional_ten.params),
        y,
        &rates,
    );
}

criterion_group!(benches, model_evaluation);
criterion_main!(benches);

//! The rivals' streaming evaluation allocates nothing per sample, like
//! `piezo_models::ModifiedInversePi` (whose own test lives in piezo-models):
//! their evaluation time is compared with it (Fig. 4), so it must be the same
//! kind of code.
//!
//! The workspace's counting allocator counts the allocations of the test
//! thread only, so the harness's own threads do not disturb the count.

use counting_allocator::{CountingAllocator, allocations_of};

use piezo_identify::models::{TEN_DEAD_ZONE_PATTERN, dead_zone_pattern};
use piezo_identify::{
    ClassicalPi, ClassicalPiParams, InverseHysteresis, TraditionalInversePi,
    TraditionalInversePiParams,
};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

fn run<M: InverseHysteresis>(model: &mut M) -> f64 {
    let mut sum = 0.0;
    let mut previous = 0.0;
    for n in 0..5000 {
        let y = 6.0 - 5.5 * (n as f64 * 0.01).cos();
        sum += model.evaluate(y, (y - previous) * 100.0);
        previous = y;
    }
    model.reset();
    sum
}

#[test]
fn rival_models_evaluate_without_allocating() {
    let mut six = TraditionalInversePi::new(TraditionalInversePiParams::<6> {
        k: [1e-3; 10],
        b: [0.1; 10],
        ws: dead_zone_pattern::<6>().map(|p| 1.0 - 0.05 * p),
        c: 0.9,
        u1max: 8.0,
    });
    let mut ten = TraditionalInversePi::new(TraditionalInversePiParams::<10> {
        k: [1e-3; 10],
        b: [0.1; 10],
        ws: TEN_DEAD_ZONE_PATTERN.map(|p| 1.0 - 0.05 * p),
        c: 0.9,
        u1max: 8.0,
    });
    let mut classical = ClassicalPi::new(ClassicalPiParams {
        weights: [0.1; 10],
        thresholds: ClassicalPiParams::evenly_spaced_thresholds(11.0),
        offset: 0.2,
    });
    let mut sums = [0.0; 3];
    let count = allocations_of(|| {
        sums = [run(&mut six), run(&mut ten), run(&mut classical)];
    });
    assert_eq!(count, 0);
    assert!(sums.iter().all(|s| s.is_finite() && *s != 0.0), "{sums:?}");
}

//! The rivals' streaming evaluation allocates nothing per sample, like
//! `piezo_models::ModifiedInversePi` (whose own test lives in piezo-models):
//! their evaluation time is compared with it (Fig. 4), so it must be the same
//! kind of code.
//!
//! A counting global allocator counts the allocations of the test thread only
//! while counting is switched on, so the harness's own threads do not disturb
//! the count.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use piezo_identify::models::{TEN_DEAD_ZONE_PATTERN, dead_zone_pattern};
use piezo_identify::{
    ClassicalPi, ClassicalPiParams, InverseHysteresis, TraditionalInversePi,
    TraditionalInversePiParams,
};

struct CountingAllocator;

thread_local! {
    static COUNTING: Cell<bool> = const { Cell::new(false) };
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn note_allocation() {
    // try_with: the thread-locals may be gone while a thread shuts down.
    let _ = COUNTING.try_with(|counting| {
        if counting.get() {
            let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
        }
    });
}

// SAFETY: every call is passed on unchanged to `System`, which upholds
// GlobalAlloc's contract; the counting touches no memory it hands out.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        // SAFETY: the caller's `layout`, under GlobalAlloc's contract.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        // SAFETY: the caller's `layout`, under GlobalAlloc's contract.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_allocation();
        // SAFETY: `ptr` was allocated by `System` with `layout` (every
        // allocation goes through this allocator); the caller's `new_size`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` was allocated by `System` with `layout` (as above).
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// Allocations made by `f` on this thread.
fn allocations_of(f: impl FnOnce()) -> u64 {
    ALLOCATIONS.with(|n| n.set(0));
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    ALLOCATIONS.with(|n| n.get())
}

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

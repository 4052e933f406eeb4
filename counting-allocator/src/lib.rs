//! A global allocator for tests that proves a hot path allocates nothing.
//!
//! It forwards to the system allocator and counts the allocations (alloc,
//! alloc_zeroed, realloc) of the calling thread while counting is switched on
//! for that thread, so the test harness's own threads do not disturb the
//! count. A test binary installs it once:
//!
//! ```
//! use counting_allocator::{CountingAllocator, allocations_of};
//!
//! #[global_allocator]
//! static ALLOCATOR: CountingAllocator = CountingAllocator;
//!
//! fn main() {
//!     let mut samples = [0.0f64; 64];
//!     let n = allocations_of(|| samples.iter_mut().for_each(|s| *s += 1.0));
//!     assert_eq!(n, 0);
//!     assert_eq!(allocations_of(|| drop(vec![1u8])), 1);
//! }
//! ```
//!
//! Without the `#[global_allocator]` line nothing is counted and
//! [`allocations_of`] returns 0 whatever `f` does, so each test binary that
//! uses it must install it (a test of this crate checks the count).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

/// The system allocator, counting the allocations of threads that switched
/// counting on.
pub struct CountingAllocator;

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

// SAFETY: every method forwards its arguments unchanged to `System`, which
// upholds the `GlobalAlloc` contract; the counting touches only const-initialized
// thread-locals (no allocation, so no re-entry).
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        // SAFETY: the caller's obligations for `alloc` are passed on as they are.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note_allocation();
        // SAFETY: as for `alloc`.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note_allocation();
        // SAFETY: `ptr` came from this allocator, that is from `System`.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` came from this allocator, that is from `System`.
        unsafe { System.dealloc(ptr, layout) }
    }
}

/// The allocations `f` makes on this thread (0 unless [`CountingAllocator`]
/// is the binary's global allocator).
pub fn allocations_of(f: impl FnOnce()) -> u64 {
    ALLOCATIONS.with(|n| n.set(0));
    COUNTING.with(|c| c.set(true));
    f();
    COUNTING.with(|c| c.set(false));
    ALLOCATIONS.with(Cell::get)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[global_allocator]
    static ALLOCATOR: CountingAllocator = CountingAllocator;

    #[test]
    fn counts_the_allocations_of_the_closure_only() {
        let outside: Vec<u8> = (0..16).collect();
        let mut sum = 0;
        let n = allocations_of(|| {
            let a: Vec<u64> = std::hint::black_box(vec![0; 4]);
            let mut b: Vec<u8> = Vec::with_capacity(1);
            b.extend([1, 2]); // grows: a realloc
            sum = a.len() + b.len();
        });
        assert_eq!(sum, 6);
        assert_eq!(n, 3);
        let n = allocations_of(|| {
            std::hint::black_box(outside.len());
        });
        assert_eq!(n, 0);
    }

    #[test]
    fn another_threads_allocations_are_not_counted() {
        // Spawning allocates on this thread (the thread's handle); the
        // spawned thread's own vectors are not counted here.
        let spawn_only = allocations_of(|| {
            std::thread::spawn(|| 0usize).join().unwrap();
        });
        let with_work = allocations_of(|| {
            std::thread::spawn(|| (0..100).map(|k| vec![0u8; k + 1].len()).sum::<usize>())
                .join()
                .unwrap();
        });
        assert_eq!(with_work, spawn_only);
    }
}

//! # hrc-adapt-tests: shared test helpers, and the home of cross-crate tests
//!
//! This library holds only helpers that the crates' own tests share: locating the data bundled
//! in the repository's `data/` folder and its `config/` folder, and a counting allocator. Each
//! crate's own tests live in that crate (`<crate>/tests/`); cross-crate closed-loop tests belong
//! in `tests/tests/`: `closed_loop.rs` wires `adapt::Controller` through `safety::Supervisor` to
//! `SimRobot` as the trial runtime does. Whole-trial tests are still unit tests of the root
//! package's library (`hrc_adapt::trial`; ARCHITECTURE.md, "Where the tests live").

use std::path::PathBuf;

/// The repository's bundled `data/` folder (real recordings with their licences beside them).
pub fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("data")
}

/// The repository's `config/` folder (shipped calibration and configuration files).
pub fn config_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join("config")
}

/// A counting global allocator for the "allocates nothing" tests of the real-time paths.
///
/// Install it in a test binary and count what a closure allocates on the calling thread:
/// ```
/// use hrc_adapt_tests::alloc_count::{CountingAllocator, allocations_in};
///
/// #[global_allocator]
/// static GLOBAL: CountingAllocator = CountingAllocator;
///
/// let mut v: Vec<u32> = Vec::with_capacity(4);
/// assert_eq!(allocations_in(|| v.push(1)).1, 0);
/// assert_eq!(allocations_in(|| v.extend([2, 3, 4, 5])).1, 1); // grows: one reallocation
/// ```
///
/// Only allocations (and reallocations) made by the thread that runs the closure are counted,
/// so the test harness's other threads don't interfere; frees are not counted.
pub mod alloc_count {
    use std::alloc::{GlobalAlloc, Layout, System};
    use std::cell::Cell;

    /// The system allocator, counting the allocations of threads inside [`allocations_in`].
    #[derive(Debug)]
    pub struct CountingAllocator;

    thread_local! {
        static COUNTING: Cell<bool> = const { Cell::new(false) };
        static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
    }

    fn note() {
        // `try_with`: thread-locals may already be gone while a thread shuts down.
        if COUNTING.try_with(Cell::get).unwrap_or(false) {
            let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
        }
    }

    // SAFETY: every method forwards to `System` with the caller's arguments unchanged; the
    // counting touches only const-initialised thread-locals and never allocates.
    unsafe impl GlobalAlloc for CountingAllocator {
        unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
            note();
            unsafe { System.alloc(layout) }
        }
        unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
            note();
            unsafe { System.alloc_zeroed(layout) }
        }
        unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
            note();
            unsafe { System.realloc(ptr, layout, new_size) }
        }
        unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
            unsafe { System.dealloc(ptr, layout) }
        }
    }

    /// Run `f` and return its result with the number of allocations it made on this thread.
    /// Counts only when [`CountingAllocator`] is the binary's global allocator.
    pub fn allocations_in<R>(f: impl FnOnce() -> R) -> (R, u64) {
        let before = ALLOCATIONS.with(Cell::get);
        COUNTING.with(|c| c.set(true));
        let r = f();
        COUNTING.with(|c| c.set(false));
        (r, ALLOCATIONS.with(Cell::get) - before)
    }
}

//! The per-slice loop of a HAS march does not allocate: a march to plane 2N makes exactly as many
//! heap allocations as a march to plane N (the fixed ones: copy of the source, FFT workspace, one
//! reservation for the recorded window).
//!
//! A counting `#[global_allocator]` counts every thread's allocations, so this file holds a single
//! test (libtest runs the tests of one binary concurrently). The marches run inside the rayon
//! pool: called from outside it, every parallel operation is injected into rayon's global queue,
//! whose lock-free list allocates one block per 63 injected jobs; that cost belongs to rayon, not
//! to the loop, and does not happen when the caller is a worker (the batch path, and any caller
//! that wraps its work in `install`).

use has_core::physics::grid::Grid;
use has_core::physics::medium::{Material, Medium};
use has_core::physics::propagation::{HasOptions, HasPlan, RecordSpec, Window};
use has_core::Complex64 as C64;
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        System.alloc(layout)
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        System.alloc_zeroed(layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        System.realloc(ptr, layout, new_size)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations made while running `f`, and its result.
fn count<T>(f: impl FnOnce() -> T) -> (usize, T) {
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    let out = f();
    (ALLOCATIONS.load(Ordering::SeqCst) - before, out)
}

/// Only a 4 x 4 window on plane `last` is kept, so recording reserves once and never grows.
fn window_on(last: usize, n: usize) -> RecordSpec {
    let c = n / 2;
    RecordSpec { window: Some(Window { planes: last..last + 1, rows: c - 2..c + 2, cols: c - 2..c + 2 }), ..Default::default() }
}

#[test]
fn per_slice_loop_does_not_allocate() {
    const N: usize = 24;
    let n = 48;
    let f = 1e6;
    let dx = 1.5e3 / f / 4.0;
    let grid = Grid::new(n, n, dx, dx, 2 * N + 1, dx, 0.0).unwrap();
    let water = Material::new("water", 1500.0, 1000.0, 0.5).unwrap();
    let medium = Medium::homogeneous(water);
    // A disc of uniform pressure, radius n/6 samples.
    let r = (n / 6) as f64;
    let source: Vec<C64> = (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as f64 - (n / 2) as f64, (i / n) as f64 - (n / 2) as f64);
            if x * x + y * y <= r * r {
                C64::new(1.0, 0.0)
            } else {
                C64::new(0.0, 0.0)
            }
        })
        .collect();
    let (plan, _) = HasPlan::build(&grid, &medium, f, &source, &HasOptions::default(), &RecordSpec::default()).unwrap();

    // A dedicated pool of 2 workers, so the parallel paths run (4 FFT chunks) on any machine.
    let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
    // Warm once (lazy initialisation in the pool and its thread-locals), then count: the fewest
    // of 5 runs, as rayon's own bookkeeping (a work-stealing deque growing, a worker waking) now
    // and then adds an allocation or two to a run, and only ever adds (a CI run once saw 13
    // against 11).
    let counted = |run: &(dyn Fn() + Sync)| {
        pool.install(run);
        (0..5).map(|_| count(|| pool.install(run)).0).min().unwrap_or(0)
    };

    // Single field, FFT rows spread over the pool (`propagate`).
    let single = |last: usize| {
        let spec = window_on(last, n);
        let rec = plan.propagate(&source, &spec).unwrap();
        assert_eq!(rec.window.len(), 16);
        (counted(&|| drop(plan.propagate(&source, &spec).unwrap())), rec.window)
    };
    let (a_n, w_n) = single(N);
    let (a_2n, w_2n) = single(2 * N);
    assert!(w_n != w_2n, "the two marches should end on different planes");
    assert!(a_n > 0, "the counting allocator saw no allocation at all");
    assert_eq!(a_n, a_2n, "march to plane {N}: {a_n} allocations; to plane {}: {a_2n}", 2 * N);

    // Batch of sources (one sequential march per rayon task): same property.
    let sources = vec![source.clone(), source.iter().map(|v| v * C64::new(0.0, 1.0)).collect()];
    let batch = |last: usize| {
        let spec = window_on(last, n);
        counted(&|| drop(plan.propagate_batch(&sources, &spec).unwrap()))
    };
    let (b_n, b_2n) = (batch(N), batch(2 * N));
    assert!(b_n > 0);
    assert_eq!(b_n, b_2n, "batch march to plane {N}: {b_n} allocations; to plane {}: {b_2n}", 2 * N);
}

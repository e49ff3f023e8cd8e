//! Criterion benchmarks of the HAS core on the embedded default scenario, the paper's phantom
//! experiment (180 x 180 x 188 grid, 1024 elements in 16 groups, MR window around the focal slab).
//!
//! Run with `cargo bench -p has-bench` (a few minutes on 2 cores); filter with
//! `cargo bench -p has-bench -- group_fields`. Targets (BENCHMARKS.md): one HAS run to the focal
//! slab ≤ 0.5 s, 16 group fields in one batch ≤ 3 s; estimation (the paper's 16 groups): one cost evaluation
//! for 16 groups ≤ 20 µs, `build_model` + Nelder–Mead (≤ 8000 evaluations) ≤ 5 s, 20-start
//! L-BFGS ≤ 5 s.
//!
//! Besides the targets, a few breakdown benches (`breakdown/*`) split a run into its parts
//! (source rasterisation, one 2-D FFT pair with and without the rayon pool, a single-field march
//! to the last plane) so a regression can be located without a profiler.

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use has_core::control::Control;
use has_core::inverse::cost::{build_model, Measurement, Model, Objective};
use has_core::inverse::element::build_element_model;
use has_core::inverse::estimate::{condense, Estimator};
use has_core::physics::aberration::SkullScreen;
use has_core::physics::fft::{each_pair, Fft2};
use has_core::physics::propagation::RecordSpec;
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use has_core::Complex64 as C64;
use std::hint::black_box;
use std::time::Duration;

/// Per-group source planes: steering phasors on the elements of group `g`, zero elsewhere.
fn group_sources(sim: &Simulation) -> Vec<Vec<C64>> {
    sim.group_sources(&sim.groups, &[]).expect("group sources")
}

fn pseudo_random_field(n: usize) -> Vec<C64> {
    let mut s = 0x2545_f491_4f6c_dd1du64;
    let mut rnd = || {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    (0..n).map(|_| C64::new(rnd(), rnd())).collect()
}

fn bench_build(c: &mut Criterion) {
    let scenario = Scenario::default();
    let mut g = c.benchmark_group("build");
    g.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(5));
    // Resolve, choose the grid, steer, rasterise the source, build the MR sampler and march the
    // reference beam once to fix every slab's mean wavenumber.
    g.bench_function("simulation_new_default", |b| b.iter(|| Simulation::new(black_box(&scenario)).unwrap()));
    g.finish();
}

fn bench_single_run(c: &mut Criterion) {
    let sim = Simulation::new(&Scenario::default()).unwrap();
    let source = sim.source_field(&[]).unwrap();
    let spec = RecordSpec { window: Some(sim.sampler().unwrap().window.clone()), ..Default::default() };
    let mut g = c.benchmark_group("single_run");
    g.sample_size(20).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(5));
    // Target: ≤ 0.5 s. Source plane + march to the end of the MR slab + force image.
    g.bench_function("arfi_image_default", |b| b.iter(|| sim.arfi_image(black_box(&[])).unwrap()));
    // The march alone (source already on plane 0).
    g.bench_function("propagate_to_focal_slab", |b| b.iter(|| sim.plan.propagate(black_box(&source), &spec).unwrap()));
    // The same march started on a rayon worker: the parallel operations of each step (8 per step)
    // are then pushed to the worker's own deque instead of the pool's global queue, with no
    // cross-thread wake-up of the caller.
    g.bench_function("propagate_to_focal_slab_in_pool", |b| {
        b.iter(|| rayon::scope(|_| sim.plan.propagate(black_box(&source), &spec).unwrap()))
    });
    // `arfi field`'s march (the focal plane and the axis), alone and as `Simulation::field` runs it
    // with the box around the target and the focal metrics from it, then with the plane's and the
    // axis's peaks. Target: the metrics add at most 10 %.
    let g0 = &sim.grid;
    let plane = RecordSpec { planes: vec![g0.plane_index(sim.focus[2])], axis: true, axis_slope: sim.axis_slope(), ..Default::default() };
    g.bench_function("field_march_only", |b| b.iter(|| sim.plan.propagate(black_box(&source), &plane).unwrap()));
    g.bench_function("field_with_focal_metrics", |b| b.iter(|| sim.field(black_box(&[]), None).unwrap()));
    g.bench_function("field_with_metrics_and_plane_axis_peaks", |b| b.iter(|| sim.field(black_box(&[]), None).unwrap().focus(sim.focus)));
    g.finish();
}

fn bench_group_fields(c: &mut Criterion) {
    let sim = Simulation::new(&Scenario::default()).unwrap();
    let mut g = c.benchmark_group("group_fields");
    g.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(10));
    // Target: ≤ 3 s. 16 per-group source planes plus one batch march (one field per rayon task).
    g.bench_function("16_groups_sources_and_batch", |b| {
        b.iter(|| {
            let sources = group_sources(&sim);
            sim.record_window(black_box(&sources)).unwrap()
        })
    });
    let sources = group_sources(&sim);
    assert_eq!(sources.len(), 16);
    g.bench_function("16_groups_batch_only", |b| b.iter(|| sim.record_window(black_box(&sources)).unwrap()));
    g.finish();
}

fn bench_fft(c: &mut Criterion) {
    let (nx, ny) = (180, 180);
    let fft = Fft2::new(nx, ny);
    let input = pseudo_random_field(nx * ny);
    let mut g = c.benchmark_group("fft2_180x180");
    g.sample_size(50).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
    for parallel in [false, true] {
        let mut ws = fft.workspace(parallel);
        let name = if parallel { "forward_inverse_parallel" } else { "forward_inverse_serial" };
        // A fresh copy per iteration (PerIteration: the allocator hands back the block just freed,
        // so the data are as warm in cache as in the march, where one buffer is reused).
        g.bench_function(name, |b| {
            b.iter_batched_ref(
                || input.clone(),
                |field| {
                    fft.forward(field, &mut ws);
                    fft.inverse(&mut ws, field);
                },
                BatchSize::PerIteration,
            )
        });
    }
    g.finish();
}

fn bench_breakdown(c: &mut Criterion) {
    let sim = Simulation::new(&Scenario::default()).unwrap();
    let drive: Vec<C64> = sim.steering.iter().map(|&p| C64::from_polar(1.0, p)).collect();
    let source = sim.source_field(&[]).unwrap();
    let mut g = c.benchmark_group("breakdown");
    g.sample_size(20).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
    // Rasterised source plane of all 1024 elements.
    g.bench_function("source_field_all_elements", |b| b.iter(|| sim.source.field(black_box(&drive)).unwrap()));
    // Window samples → MR image (force, slab average, broadening, pixel sampling).
    let rec = sim.record_window(std::slice::from_ref(&source)).unwrap().remove(0);
    g.bench_function("force_image", |b| b.iter(|| sim.sampler().unwrap().force_image(black_box(&rec.window)).unwrap()));
    // Whole-grid march (all nz planes, on-axis samples only) for the per-step cost.
    let to_end = RecordSpec { axis: true, ..Default::default() };
    g.bench_function("propagate_all_planes", |b| b.iter(|| sim.plan.propagate(black_box(&source), &to_end).unwrap()));
    // One element-wise complex multiply of a slice (one of the three per step).
    let screen = pseudo_random_field(sim.grid.lateral_len());
    for parallel in [false, true] {
        let name = if parallel { "multiply_parallel" } else { "multiply_serial" };
        g.bench_function(name, |b| {
            b.iter_batched_ref(|| source.clone(), |f| each_pair(parallel, f, black_box(&screen), |x, y| *x *= y), BatchSize::PerIteration)
        });
    }
    g.finish();
}

/// The estimation workload of the targets: one noisy (0.02 rad) MR-ARFI image of the default scenario
/// with a skull-like aberration (`SkullScreen::default()`, seed 1) condensed to the 16 groups.
fn aberrated_measurement(sim: &Simulation) -> Vec<Measurement> {
    let positions = sim.transducer.reference_points();
    let truth = condense(&SkullScreen::default().phases(&positions, 1).unwrap(), &sim.groups).unwrap();
    vec![Measurement { image: sim.noisy_arfi_image(&truth, 0.02, 1).unwrap(), known: vec![] }]
}

/// The cost model as `arfi estimate` builds it (scenario mask fraction, 3-pixel margin).
fn model(sim: &Simulation, measurements: &[Measurement]) -> Model {
    build_model(sim, measurements, sim.mask_fraction, 3).unwrap()
}

/// One HAS slab step: FFT, propagator, inverse FFT, screen ([`Fft2::filter`] as the march calls
/// it), the unit of every march; on 180 x 180 (the paper's phantom) and 540 x 540 (a 650 kHz
/// hemisphere through a head).
fn bench_has_step(c: &mut Criterion) {
    for n in [180, 256, 360, 540] {
        let fft = Fft2::new(n, n);
        let input = pseudo_random_field(n * n);
        let propagator = pseudo_random_field(n * n);
        let screen = pseudo_random_field(n * n);
        let mut g = c.benchmark_group(format!("has_step_{n}x{n}"));
        g.sample_size(if n > 200 { 20 } else { 50 }).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
        for parallel in [false, true] {
            let mut ws = fft.workspace(parallel);
            let name = if parallel { "filter_parallel" } else { "filter_serial" };
            g.bench_function(name, |b| {
                b.iter_batched_ref(
                    || input.clone(),
                    |field| fft.filter(field, &mut ws, None, &propagator, Some(&screen)),
                    BatchSize::PerIteration,
                )
            });
        }
        g.finish();
    }
}

/// Cost and cost + gradient for 1024 groups (one per element): the field-basis model of
/// `arfi estimate --groups 1024` (its build, one march per element into a basis of about 750 MB, is not timed).
fn bench_estimation_1024(c: &mut Criterion) {
    let sim = Simulation::new(&Scenario::default()).unwrap();
    let meas = aberrated_measurement(&sim);
    let m = build_element_model(&sim, &meas, sim.mask_fraction, 0, Control::default()).unwrap();
    let x: Vec<f64> = (0..sim.transducer.elements.len()).map(|e| 0.3 * (e as f64).sin()).collect();
    let mut g = c.benchmark_group("estimation_1024");
    g.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(8));
    g.bench_function("cost_1024_elements", |b| b.iter(|| m.cost.cost(black_box(&x))));
    g.bench_function("cost_and_gradient_1024_elements", |b| b.iter(|| m.cost.cost_and_gradient(black_box(&x))));
    // The clinical case: the focus and three defocused acquisitions (+5, -5, +10 mm).
    let mut four = meas.clone();
    for dz in [5e-3, -5e-3, 10e-3] {
        four.push(Measurement { image: meas[0].image.clone(), known: sim.focus_shift_phases([0.0, 0.0, dz]).unwrap() });
    }
    let m4 = build_element_model(&sim, &four, sim.mask_fraction, 0, Control::default()).unwrap();
    g.bench_function("cost_and_gradient_1024_elements_4_images", |b| b.iter(|| m4.cost.cost_and_gradient(black_box(&x))));
    g.finish();
}

fn bench_estimation(c: &mut Criterion) {
    let sim = Simulation::new(&Scenario::default()).unwrap();
    assert_eq!(sim.n_groups, 16);
    let meas = aberrated_measurement(&sim);
    let m = model(&sim, &meas);
    let x: Vec<f64> = (0..16).map(|g| 0.3 * (g as f64).sin()).collect();

    let mut g = c.benchmark_group("estimation");
    g.sample_size(100).warm_up_time(Duration::from_millis(500)).measurement_time(Duration::from_secs(3));
    // Target: ≤ 20 µs. One evaluation of the hybrid cost (paper Eq. 4) for 16 groups: a Hermitian
    // form per masked pixel of the precomputed kernels.
    g.bench_function("cost_16_groups", |b| b.iter(|| m.cost.cost(black_box(&x))));
    // The cost with its analytic gradient (what each L-BFGS step evaluates).
    g.bench_function("cost_and_gradient_16_groups", |b| b.iter(|| m.cost.cost_and_gradient(black_box(&x))));

    g.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(12));
    // Basis precomputation: masks, 16 group source planes, one batched march of the 16 group
    // fields to the MR slab, and the per-pixel kernels.
    g.bench_function("build_model_16_groups", |b| b.iter(|| model(&sim, black_box(&meas))));
    // Target: ≤ 5 s. The paper-scale estimation end to end: basis precomputation, then the
    // paper's estimator (restarted Nelder–Mead from zero, at most 8000 evaluations).
    g.measurement_time(Duration::from_secs(15));
    g.bench_function("nelder_mead_end_to_end", |b| {
        b.iter(|| Estimator::nelder_mead().run(&model(&sim, black_box(&meas)).cost, Control::default()).unwrap())
    });
    g.measurement_time(Duration::from_secs(5));
    // The Nelder–Mead search alone on the prebuilt model.
    g.bench_function("nelder_mead_run", |b| b.iter(|| Estimator::nelder_mead().run(black_box(&m.cost), Control::default()).unwrap()));
    // Target: ≤ 5 s. Multi-start L-BFGS with the analytic gradient (20 starts + 20 second-round
    // starts, at most 40000 evaluations).
    g.bench_function("lbfgs_run", |b| b.iter(|| Estimator::lbfgs().run(black_box(&m.cost), Control::default()).unwrap()));
    g.finish();
}

criterion_group!(
    benches,
    bench_build,
    bench_single_run,
    bench_group_fields,
    bench_fft,
    bench_has_step,
    bench_breakdown,
    bench_estimation,
    bench_estimation_1024
);
criterion_main!(benches);

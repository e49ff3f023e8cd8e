//! Per-element estimation on the field basis (`--groups` = number of elements), on a
//! 256-element version of the default array (8 x 8 per quadrant) to keep the marches short.

use crate::common;
use has_core::control::Control;
use has_core::inverse::cost::{build_model, Measurement, Objective};
use has_core::inverse::element::nuisance::Nuisance;
use has_core::inverse::element::{build_element_model, BasisCache};
use has_core::inverse::estimate::{condense, Estimator};
use has_core::physics::aberration::SkullScreen;
use has_core::simulation::Simulation;
use ndarray::Array2;
use std::sync::Arc;

fn peak(img: &Array2<f64>) -> f64 {
    img.iter().copied().fold(f64::MIN, f64::max)
}

/// Element-level skull aberration plus images with known random group phases (noise-free).
fn study(sim: &Simulation, images: u64) -> (Vec<f64>, Vec<Measurement>) {
    let positions = sim.transducer.reference_points();
    let truth = SkullScreen::default().phases(&positions, 1).unwrap();
    let mut m = vec![Measurement { image: sim.arfi_image(&truth).unwrap(), known: vec![] }];
    for k in 1..images {
        let d = SkullScreen { correlation_length: 1.0, peak_to_peak: 0.0, jitter: 1.5 }
            .phases(&vec![[0.0; 3]; sim.n_groups], 1000 + k)
            .unwrap();
        let total: Vec<f64> = truth.iter().zip(sim.element_phases(&d).unwrap()).map(|(t, x)| t + x).collect();
        m.push(Measurement { image: sim.arfi_image(&total).unwrap(), known: d });
    }
    (truth, m)
}

#[test]
fn element_basis_images_gradient_and_estimate() {
    let sim = common::small_array();
    let n = sim.n_elements();
    assert_eq!(n, 256);
    let (truth, ms) = study(&sim, 4);
    let model = build_element_model(&sim, &ms, sim.mask_fraction, 0, Control::default()).unwrap();
    let basis = &model.cost.basis;

    // The basis is marched on a grid 1.5 x coarser (3λ/8: the phantom and water reverberate
    // nowhere), and reproduces that grid's direct HAS image: the fields are marched and stored in
    // single precision (a few 1e-6 of the peak in the field, about twice that in |p|²: see
    // `single_precision_march_matches_the_double_precision_one`); 2e-5 leaves room.
    let coarse = common::basis_model(&sim);
    assert!((coarse.grid.dx / sim.grid.dx - 1.5).abs() < 0.01, "basis spacing {} m", coarse.grid.dx);
    let p = &basis.sampler.pixels;
    let box_of = |img: &Array2<f64>| img.slice(ndarray::s![p[0].clone(), p[1].clone()]).to_owned();
    let max_diff = |a: &Array2<f64>, b: &Array2<f64>| (a - b).iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    let from_basis = basis.image(&truth).unwrap();
    let err = max_diff(&from_basis, &box_of(&coarse.arfi_image(&truth).unwrap()));
    assert!(err < 2e-5 * peak(&from_basis), "basis image error {err:e}");
    // Against the simulation's own λ/4 grid: the discretisation (1.5 % of the peak; 0.8 % at
    // 1.25 x coarser, so the λ/4 grid's own error is of that order). 2 % of the peak,
    // under the 3 % that 0.02 rad of noise is on this 0.6 rad focus.
    let direct = sim.arfi_image(&truth).unwrap();
    let err = max_diff(&from_basis, &box_of(&direct));
    assert!(err < 0.02 * peak(&direct), "coarser basis against the simulation's grid: {err:e}");

    assert_gradient(&model.cost);

    // Element amplitudes (a prediction's transmission) weight the basis as they weight the march.
    let amplitudes: Vec<f64> = (0..n).map(|e| 0.2 + 0.8 * ((e * 37) % 11) as f64 / 10.0).collect();
    let weighted = sim.with_element_amplitudes(&amplitudes).unwrap();
    let direct_weighted = common::basis_model(&weighted).arfi_image(&truth).unwrap();
    let basis_weighted = build_element_model(&weighted, &ms, sim.mask_fraction, 0, Control::default()).unwrap().cost.basis;
    let q = &basis_weighted.sampler.pixels;
    let err = (&basis_weighted.image(&truth).unwrap() - &direct_weighted.slice(ndarray::s![q[0].clone(), q[1].clone()]))
        .iter()
        .fold(0.0_f64, |m, x| m.max(x.abs()));
    assert!(err < 2e-5 * peak(&direct_weighted), "weighted basis image error {err:e}");
    assert!(peak(&direct_weighted) < 0.9 * peak(&direct), "the amplitudes (mean 0.6) must weaken the image");

    // Estimation: the 16-group estimate, expanded to elements, warm-starts L-BFGS on all 256
    // phases. Required: better than the best any 16-group correction of this kind (the circular
    // mean of the truth per group) can do, by 0.05 of the ideal focus. Here that correction barely
    // lifts the aberrated focus (about 0.69 to 0.71), and the per-element estimate reaches about
    // 0.78 within its 300 evaluations.
    let ideal = peak(&sim.arfi_image(&[]).unwrap());
    let recovered = |est: &[f64]| {
        let c: Vec<f64> = truth.iter().zip(sim.element_phases(est).unwrap()).map(|(t, e)| t - e).collect();
        peak(&sim.arfi_image(&c).unwrap()) / ideal
    };
    let groups = build_model(&sim, &ms, sim.mask_fraction, 3).unwrap();
    let g16 = Estimator::lbfgs().run(&groups.cost, Control::default()).unwrap();
    let start = sim.element_phases(&g16.phases).unwrap();
    let e = Estimator::lbfgs()
        .with_starts(1)
        .unwrap()
        .with_max_evaluations(300)
        .unwrap()
        .with_start(start)
        .unwrap()
        .run(&model.cost, Control::default())
        .unwrap();
    let best16 = recovered(&condense(&truth, &sim.groups).unwrap());
    let per_element = recovered(&e.phases);
    println!("aberrated {:.3}, best 16-group {best16:.3}, per-element {per_element:.3}, cost {:.2e}", recovered(&vec![0.0; n]), e.cost);
    assert_eq!(e.phases.len(), n);
    assert!(per_element > best16 + 0.05, "per-element {per_element:.3} vs best 16-group {best16:.3}");
}

#[test]
fn a_basis_cache_reuses_the_basis_for_the_same_pixel_box_only() {
    // The basis depends on the simulation and the pixel box: the same images give the same box
    // and the kept basis (the same allocation); another box is built anew.
    let sim = common::small_array();
    let (_, ms) = study(&sim, 2);
    let cache = BasisCache::default();
    let a = cache.element_model(&sim, &ms, sim.mask_fraction, 0, &Nuisance::default(), Control::default()).unwrap();
    let b = cache.element_model(&sim, &ms, sim.mask_fraction, 0, &Nuisance::default(), Control::default()).unwrap();
    assert!(Arc::ptr_eq(&a.cost.basis, &b.cost.basis));
    let c = cache.element_model(&sim, &ms, sim.mask_fraction, 2, &Nuisance::default(), Control::default()).unwrap();
    assert!(!Arc::ptr_eq(&a.cost.basis, &c.cost.basis) && c.cost.basis.sampler.pixels != a.cost.basis.sampler.pixels);
}

/// With the amplitude scale and per-image background planes projected out and another view
/// (W, shift) on the wide window: the adjoint gradient still matches central differences
/// (variable projection: at the least-squares optimum the linear parameters' own change does not
/// enter), and the fitted linear nuisance recovers what was added to the images exactly
/// (noise-free: to 1e-6 of the added values, single-precision basis).
#[test]
fn element_gradient_with_nuisance_projected_out() {
    let sim = common::small_array();
    // Images of the basis's own model (its grid): the linear fit is then exact.
    let (truth, mut ms) = study(&common::basis_model(&sim), 2);
    let coords = |k: usize, i: usize| sim.mr.pixel_center(k, i) * 1e3;
    let added = [[0.03, 2e-4, -1e-4], [-0.02, 0.0, 3e-4]];
    for (m, b) in ms.iter_mut().zip(&added) {
        m.image *= 0.9;
        for ((i, j), x) in m.image.indexed_iter_mut() {
            *x += b[0] + b[1] * coords(0, i) + b[2] * coords(1, j);
        }
    }
    let nuisance = Nuisance::parse(&["all"]).unwrap();
    let model = BasisCache::default().element_model(&sim, &ms, sim.mask_fraction, 0, &nuisance, Control::default()).unwrap();
    let linear = model.cost.linear_at(&truth);
    assert!((linear.scale - 0.9).abs() < 1e-5, "scale {}", linear.scale);
    for (fit, b) in linear.background.iter().zip(&added) {
        assert!(fit.iter().zip(b).all(|(f, b)| (f - b).abs() < 1e-6), "background {fit:?} vs {b:?}");
    }
    let cost = model.cost.with_view([3.1e-3; 2], [0.4e-3, -0.3e-3]).unwrap();
    assert_gradient(&cost);
}

/// The adjoint gradient against central differences at a fixed pseudo-random point of 256
/// phases (h = 0.01 rad: truncation ~h² ≈ 1e-4 relative, above the single-precision rounding of
/// the cost); tolerance 1 % of the largest component.
fn assert_gradient(cost: &dyn Objective) {
    let x: Vec<f64> = (0..cost.n_phases()).map(|e| 0.3 * ((e * 7919 % 101) as f64 / 101.0 - 0.5)).collect();
    let (_, g) = cost.cost_and_gradient(&x);
    let scale = g.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    for e in [0, 37, 128, 200, 255] {
        let h = 1e-2;
        let (mut a, mut b) = (x.clone(), x.clone());
        a[e] += h;
        b[e] -= h;
        let fd = (cost.cost(&a) - cost.cost(&b)) / (2.0 * h);
        assert!((fd - g[e]).abs() < 1e-2 * scale, "element {e}: analytic {} numeric {fd}", g[e]);
    }
}

/// The basis's grid is coarser only where that holds the images (`basis_grid`): at 550 kHz 1.5 x
/// (3/8 of the wavelength), at 220 kHz none (3/8 of the 7 mm wavelength would be nearly two
/// 1.4 mm MR pixels), and none through a bone plate, which reverberates.
#[test]
fn the_basis_grid_is_coarser_only_where_it_holds_the_images() {
    use has_core::inverse::element::basis_grid;
    use has_core::scenario::Scenario;
    let sim = |text: &str| Simulation::new(&Scenario::from_toml(text, None).unwrap()).unwrap();
    let phantom = sim("[transducer]\nelements_per_side = 2\n");
    let g = basis_grid(&phantom).unwrap().expect("a coarser grid through the phantom");
    assert!((g.dx / phantom.grid.dx - 1.5).abs() < 0.01, "{} vs {}", g.dx, phantom.grid.dx);
    assert!(basis_grid(&sim("frequency_hz = 220000.0\n[transducer]\nelements_per_side = 2\n")).unwrap().is_none());
    let plate = "frequency_hz = 500000.0\n[transducer]\nkind = \"bowl\"\nradius_of_curvature_mm = 40.0\n\
                 aperture_diameter_mm = 30.0\n[focus]\nposition_mm = [0.0, 0.0, 40.0]\n[grid]\nspacing_mm = 0.5\n\
                 z_max_mm = 50.0\n[arfi]\namplitude_rad_m3_per_n = 1.0\n[medium]\nbackground = \"water\"\n[[material]]\n\
                 name = \"water\"\nsound_speed_m_s = 1500.0\ndensity_kg_m3 = 1000.0\n[[material]]\nname = \"bone\"\n\
                 sound_speed_m_s = 2800.0\ndensity_kg_m3 = 1850.0\nattenuation_db_cm_mhz = 4.0\n[[region]]\n\
                 material = \"bone\"\nshape = \"slab\"\nz_min_mm = 20.0\nz_max_mm = 26.0\n";
    let bone = sim(plate);
    assert!(bone.plan.reverberation().is_some());
    assert!(basis_grid(&bone).unwrap().is_none());
}

//! CT volumes in the medium: a bone plate read from a CT NIfTI against the same plate given as a
//! region, and what a CT the scenario cannot use is told.
//!
//! Run with `cargo test --release -p has-core --test suite ct:: -- --nocapture` to see the numbers.

use has_core::nifti;
use has_core::physics::ct::HuConversion;
use has_core::scenario::Scenario;
use has_core::simulation::Simulation;
use has_core::HasError;
use std::path::PathBuf;

/// HU of the plate: ψ = 0.4 in the porosity model (2340 m/s, 1720 kg/m³, 51.3 dB/cm/MHz).
const PLATE_HU: f64 = 1200.0;

/// A fresh folder for one test's files.
fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("arfi-ct-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The default planar array and focus, water, and the grid spacing fixed so both media march on
/// the same grid.
const BASE: &str = "[grid]\nspacing_mm = 0.68\nstep_mm = 0.68\n";

/// A scenario: `head` (e.g. a `[grid]`), water, and a slab of bone from `lo` to `hi` (m) whose
/// material is the porosity model's conversion of [`PLATE_HU`].
fn plate_as_region(head: &str, lo: f64, hi: f64) -> Scenario {
    let p = HuConversion::named("aubry2003").unwrap().properties(PLATE_HU, 1e6).unwrap();
    let a0 = p.attenuation / (100.0 * has_core::physics::medium::NP_PER_DB);
    let text = format!(
        "{head}[[material]]\nname = \"water\"\nsound_speed_m_s = 1500\ndensity_kg_m3 = 1000\n\
         [[material]]\nname = \"bone\"\nsound_speed_m_s = {}\ndensity_kg_m3 = {}\nattenuation_db_cm_mhz = {a0}\n\
         [[region]]\nmaterial = \"bone\"\nshape = \"slab\"\nz_min_mm = {}\nz_max_mm = {}\n",
        p.sound_speed,
        p.density,
        lo * 1e3,
        hi * 1e3
    );
    Scenario::from_toml(&text, None).unwrap()
}

/// A CT of `nk` slices of `dz` (m) from `z_first` (centre of slice 0, transducer frame, m), three
/// 60 mm voxels wide in x and y (covering ±90 mm), holding `hu(z)`; the patient frame is the
/// transducer frame (identity transform), so the NIfTI's RAS x and y are the frame's negated.
fn layered_ct(nk: usize, dz: f64, z_first: f64, hu: impl Fn(f64) -> f64) -> Vec<u8> {
    let values: Vec<f32> = (0..nk).flat_map(|k| std::iter::repeat(hu(z_first + k as f64 * dz) as f32).take(9)).collect();
    // RAS x = -60·i + 60 mm puts the voxel centres at LPS x = 60·i - 60 = -60, 0, 60 mm.
    let affine = [[-60.0, 0.0, 0.0, 60.0], [0.0, -60.0, 0.0, 60.0], [0.0, 0.0, dz * 1e3, z_first * 1e3]];
    nifti::encode([nk, 3, 3], &values, affine)
}

#[test]
fn a_plate_read_from_a_ct_gives_the_field_of_the_same_plate_as_a_region() {
    let water = Simulation::new(&Scenario::from_toml(BASE, None).unwrap()).unwrap();
    let g = water.grid.clone();
    // The plate fills the steps from plane a to plane b (whole cells), 4 steps = 2.7 mm thick.
    let (a, b) = (g.plane_index(0.030), g.plane_index(0.030) + 4);
    let with_region = Simulation::new(&plate_as_region(BASE, g.z(a), g.z(b))).unwrap();
    // The CT: one slice per step, centred on the steps' midpoints, from 5 steps before the plate to
    // beyond the focus; air (coupling) around the plate.
    let z_first = g.z(a - 5) + 0.5 * g.dz;
    let nk = ((0.095 - z_first) / g.dz) as usize;
    let (lo, hi) = (g.z(a), g.z(b));
    let dir = scratch("plate");
    std::fs::write(dir.join("plate.nii"), layered_ct(nk, g.dz, z_first, |z| if z > lo && z < hi { PLATE_HU } else { -1000.0 })).unwrap();
    let ct = format!("{BASE}[ct]\nfile = \"plate.nii\"\nconversion = \"aubry2003\"\n");
    let with_ct = Simulation::new(&Scenario::from_toml(&ct, Some(&dir)).unwrap()).unwrap();
    assert_eq!(with_ct.grid, g);

    let (fr, fc) = (with_region.field(&[], None).unwrap(), with_ct.field(&[], None).unwrap());
    let peak = fr.pressure.iter().map(|v| v.norm()).fold(0.0, f64::max);
    let worst = fr.pressure.iter().zip(fc.pressure.iter()).map(|(r, c)| (r - c).norm()).fold(0.0, f64::max) / peak;
    let water_peak = water.field(&[], None).unwrap().pressure.iter().map(|v| v.norm()).fold(0.0, f64::max);
    println!(
        "plate of {PLATE_HU} HU, {:.2} mm: focal peak {:.3} of water's; CT vs region: worst |Δp| {worst:.2e} of the peak",
        (hi - lo) * 1e3,
        peak / water_peak
    );
    // The plate matters (it costs over 30 % of the focal pressure) ...
    assert!(peak < 0.7 * water_peak);
    // ... and the CT gives the region's field: the plate's faces lie on grid planes, so every cell
    // and every steering ray sees the same material either way (the fields agree to rounding). The
    // bound allows for the affine's single precision (it moves the voxel faces by ~1e-9 m) should
    // a steering sample land on a face.
    assert!(worst < 1e-4, "worst {worst}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn a_ct_the_scenario_cannot_use_is_named_with_what_is_wrong() {
    let dir = scratch("bad");
    let g = Simulation::new(&Scenario::from_toml(BASE, None).unwrap()).unwrap().grid;
    let good = |z: f64| if (0.03..0.033).contains(&z) { PLATE_HU } else { -1000.0 };
    let write = |name: &str, bytes: Vec<u8>| std::fs::write(dir.join(name), bytes).unwrap();
    write("good.nii", layered_ct(100, g.dz, 0.02, good));
    // Cut off inside the plate: the beam enters the CT in bone.
    write("cut.nii", layered_ct(100, g.dz, 0.031, good));
    // Ends before the focus (85 mm). The hot and NaN voxels start at slice k = 45 (z = 50.6 mm):
    // errors give a voxel as (i, j, k), not as a flat index.
    write("short.nii", layered_ct(40, g.dz, 0.02, good));
    write("hot.nii", layered_ct(100, g.dz, 0.02, |z| if z > 0.05 { 4100.0 } else { 0.0 }));
    write("nan.nii", layered_ct(100, g.dz, 0.02, |z| if z > 0.05 { f64::NAN } else { 0.0 }));
    let resolve = |ct: &str| Scenario::from_toml(&format!("{BASE}[ct]\n{ct}\n"), Some(&dir)).unwrap().resolve().map(|_| ()).unwrap_err();
    let cases: [(&str, &[&str]); 8] = [
        ("file = \"good.nii\"\nconversion = \"hounsfield\"", &["ct.conversion", "aubry2003"]),
        ("file = \"missing.nii\"", &["missing.nii", "no such file", "the [ct] file of scenario"]),
        ("file = \"cut.nii\"", &["cut.nii", "beam path", "bone"]),
        ("file = \"short.nii\"", &["short.nii", "focus"]),
        ("file = \"hot.nii\"", &["hot.nii", "4100", "voxel (0, 0, 45) (i, j, k)"]),
        ("file = \"nan.nii\"", &["nan.nii", "NaN", "voxel (0, 0, 45) (i, j, k)"]),
        (
            "file = \"good.nii\"\npatient_to_transducer_mm = [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]",
            &["patient_to_transducer_mm", "rigid"],
        ),
        ("file = \"good.nii\"\nconversion = \"schneider-mast\"\nhu_max = 1800", &["ct.hu_max", "porosity"]),
    ];
    for (ct, want) in cases {
        let e = resolve(ct).to_string();
        assert!(want.iter().all(|w| e.contains(w)), "{ct}: {e}");
    }
    assert!(matches!(resolve("file = \"missing.nii\""), HasError::FileNotFound { .. }));
    assert!(Scenario::from_toml(&format!("{BASE}[ct]\nfile = \"good.nii\"\n"), Some(&dir)).unwrap().resolve().is_ok());
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn a_plate_thinner_than_its_cells_keeps_its_delay_wherever_it_lies_on_the_grid() {
    // A plate of 9 quarter-steps on a CT of quarter-step voxels, moved by quarter steps across the
    // grid, against the same plate as a region marched with quarter steps (its faces on planes:
    // exact layering). Each coarse cell averages its slowness, so the focal phase follows the
    // plate's true thickness rather than the whole steps it touches; a region on the coarse grid
    // rounds the plate to 2 or 3 steps, a jump of (k_bone - k_water)·dz = 0.56 rad.
    let g = Simulation::new(&Scenario::from_toml(BASE, None).unwrap()).unwrap().grid;
    let dz = g.dz / 4.0;
    let z_first = g.z(g.plane_index(0.025)) + 0.5 * dz;
    let nk = ((0.095 - z_first) / dz) as usize;
    let dir = scratch("thin");
    let centre = |sim: &Simulation| {
        let f = sim.field(&[], None).unwrap();
        f.pressure[[f.y.len() / 2, f.x.len() / 2]]
    };
    let region = |grid: &str, lo: f64, hi: f64| centre(&Simulation::new(&plate_as_region(grid, lo, hi)).unwrap());
    let fine = format!("[grid]\nspacing_mm = {}\nstep_mm = {}\n", g.dx * 1e3, dz * 1e3);
    let (mut ct_worst, mut coarse_worst, mut amplitude_worst) = (0.0f64, 0.0f64, 0.0f64);
    for shift in 0..4 {
        let (lo, hi) = (z_first + (20 + shift) as f64 * dz - 0.5 * dz, z_first + (29 + shift) as f64 * dz - 0.5 * dz);
        let name = format!("thin{shift}.nii");
        std::fs::write(dir.join(&name), layered_ct(nk, dz, z_first, |z| if z > lo && z < hi { PLATE_HU } else { -1000.0 })).unwrap();
        let ct = centre(&Simulation::new(&Scenario::from_toml(&format!("{BASE}[ct]\nfile = \"{name}\"\n"), Some(&dir)).unwrap()).unwrap());
        let (exact, coarse) = (region(&fine, lo + 1e-9, hi - 1e-9), region(BASE, lo, hi));
        println!(
            "shift {shift}: CT {:.3} ∠{:.3} | region coarse {:.3} ∠{:.3} | fine region {:.3} ∠{:.3}",
            ct.norm() / exact.norm(),
            (ct / exact).arg(),
            coarse.norm() / exact.norm(),
            (coarse / exact).arg(),
            exact.norm(),
            exact.arg()
        );
        ct_worst = ct_worst.max((ct / exact).arg().abs());
        coarse_worst = coarse_worst.max((coarse / exact).arg().abs());
        amplitude_worst = amplitude_worst.max((ct.norm() / exact.norm() - 1.0).abs());
    }
    // The CT's phase stays within about 0.12 rad of the exact layering at every shift, the coarse
    // region's rounding (a step set in [grid], so its faces are not all on planes) up to 0.9 rad
    // off. The cells at the faces take the impedance at their centre: sharp faces at the nearest
    // planes, so the plate reflects as one of 2 or 3 whole steps would, 0-8 % below the exact
    // focal pressure (averaged impedances would grade the faces: 10-18 % above it). Bounds: phase
    // 0.15 rad and below a third of the rounding's error; amplitude 12 %.
    assert!(ct_worst < 0.15 && ct_worst < coarse_worst / 3.0, "{ct_worst} {coarse_worst}");
    assert!(amplitude_worst < 0.12, "{amplitude_worst}");
    std::fs::remove_dir_all(dir).ok();
}

//! The transposed march against the march itself: the dot-product test of an adjoint,
//! `Σ w · (M·s) = Σ (Mᵀ·w) · s` for random sources `s` and weights `w`, on media that exercise
//! every part of the march (reverberation round trips, reflections towards the source, material
//! pairs on part of a plane, per-pixel interfaces of a voxel map, the normal-incidence model) and
//! on a plane before, inside and beyond the reverberating layer. The two sides share no code
//! path beyond the plan's operators, so a transposed factor in the wrong order or a wave left out
//! shows at once; what remains is rounding (tolerance 1e-10 of `Σ |w|·|M·s|`; seen ~1e-15).

use has_core::nifti::Volume;
use has_core::physics::ct::{BoneShear, CtMedium, HuConversion};
use has_core::physics::grid::Grid;
use has_core::physics::medium::{Material, Medium, Region, Shape, VoxelMap};
use has_core::physics::propagation::{HasOptions, HasPlan, InterfaceModel, RecordSpec};
use has_core::Complex64 as C64;

const F: f64 = 500e3;

/// Deterministic pseudo-random numbers in [-0.5, 0.5).
fn lcg(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed;
    move || {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }
}

/// 48 x 40 pixels (unequal, so a transposed layout shows), 0.5 mm, 60 planes from z = 2 mm.
fn grid() -> Grid {
    Grid::new(48, 40, 0.5e-3, 0.5e-3, 60, 0.5e-3, 2e-3).unwrap()
}

/// Water with a bone plate (8–14 mm) holding a slower cylinder off the axis, and soft tissue
/// beyond it from 20 mm.
fn plate() -> Medium {
    let m = |n, c, r, a| Material::new(n, c, r, a).unwrap();
    Medium {
        materials: vec![
            m("water", 1500.0, 1000.0, 0.0),
            m("bone", 2800.0, 1850.0, 10.0),
            m("diploe", 2300.0, 1700.0, 20.0),
            m("tissue", 1560.0, 1050.0, 1.0),
        ],
        background: 0,
        regions: vec![
            Region { material: 1, shape: Shape::Slab { z_min: 8e-3, z_max: 14e-3 } },
            Region { material: 2, shape: Shape::Cylinder { radius: 4e-3, z_min: 9.5e-3, z_max: 12.5e-3, center: [2e-3, -1e-3] } },
            Region { material: 3, shape: Shape::Slab { z_min: 20e-3, z_max: 40e-3 } },
        ],
        voxels: None,
        ct: None,
    }
}

/// Water with a box of random voxels (more material pairs per plane than the spectral model
/// takes: per-pixel interfaces).
fn voxels() -> Medium {
    let mut rnd = lcg(7);
    let shape = [8, 10, 12];
    let n = shape.iter().product();
    let mut medium = Medium::homogeneous(Material::new("water", 1500.0, 1000.0, 0.0).unwrap());
    medium.voxels = Some(VoxelMap {
        origin: [-3e-3, -2.5e-3, 10e-3],
        spacing: [0.5e-3; 3],
        shape,
        sound_speed: (0..n).map(|_| 1900.0 + 1600.0 * rnd()).collect(),
        density: (0..n).map(|_| 1500.0 + 800.0 * rnd()).collect(),
        attenuation_db_cm_mhz: (0..n).map(|_| 5.0 + 8.0 * rnd()).collect(),
        attenuation_power: 1.0,
    });
    medium
}

/// Water with a bone plate 4 mm thick turned 20° about y, as a voxel map of 0.25 mm (its cells
/// average the slowness): a planar wall oblique to the planes, whose treads take the wall's
/// filters and reverberate.
fn tilted() -> Medium {
    // (nz, ny, nx)
    let (spacing, shape) = (0.25e-3, [120, 96, 112]);
    let n: usize = shape.iter().product();
    let t = 20f64.to_radians();
    let origin = [-14e-3, -12e-3, 4e-3];
    let bone = |i: usize| {
        let (x, z) = (origin[0] + (i % shape[2]) as f64 * spacing, origin[2] + (i / (shape[2] * shape[1])) as f64 * spacing);
        (0.0..4e-3).contains(&(x * t.sin() + (z - 12e-3) * t.cos()))
    };
    let mut medium = Medium::homogeneous(Material::new("water", 1500.0, 1000.0, 0.0).unwrap());
    medium.voxels = Some(VoxelMap {
        origin,
        spacing: [spacing; 3],
        shape,
        sound_speed: (0..n).map(|i| if bone(i) { 2800.0 } else { 1500.0 }).collect(),
        density: (0..n).map(|i| if bone(i) { 1850.0 } else { 1000.0 }).collect(),
        attenuation_db_cm_mhz: (0..n).map(|i| if bone(i) { 8.0 } else { 0.0 }).collect(),
        attenuation_power: 1.0,
    });
    medium
}

/// The plate of [`tilted`] as solid bone (shear 1500 m/s) read from a CT of 0.25 mm voxels: its
/// oblique walls convert between P and SV waves (`oblique_shear.rs`).
fn tilted_solid_ct() -> Medium {
    // (nk, nj, ni), the NIfTI's RAS x and y the frame's negated (identity transform).
    let (spacing, shape) = (0.25e-3, [120, 96, 112]);
    let t = 20f64.to_radians();
    let origin = [-14e-3, -12e-3, 4e-3];
    let values: Vec<f32> = (0..shape.iter().product())
        .map(|f: usize| {
            let (x, z) = (origin[0] + (f % shape[2]) as f64 * spacing, origin[2] + (f / (shape[2] * shape[1])) as f64 * spacing);
            if (0.0..4e-3).contains(&(x * t.sin() + (z - 12e-3) * t.cos())) {
                2000.0
            } else {
                -1000.0
            }
        })
        .collect();
    let mm = |v: f64| v * 1e3;
    let affine =
        [[-mm(spacing), 0.0, 0.0, -mm(origin[0])], [0.0, -mm(spacing), 0.0, -mm(origin[1])], [0.0, 0.0, mm(spacing), mm(origin[2])]];
    let identity = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];
    let mut conversion = HuConversion::named("aubry2003").unwrap();
    conversion.bone_shear = BoneShear { sound_speed: 1500.0, attenuation_db_cm_mhz: 8.0 };
    let ct = CtMedium::new(Volume { shape, values, affine }, identity, conversion, "tilted plate").unwrap();
    let mut medium = Medium::homogeneous(Material::new("water", 1500.0, 1000.0, 0.0).unwrap());
    medium.ct = Some(std::sync::Arc::new(ct));
    medium
}

/// A Gaussian beam converging towards (1, 0.5, 20) mm: the reference that fixes the plan.
fn reference(g: &Grid) -> Vec<C64> {
    let k = 2.0 * std::f64::consts::PI * F / 1500.0;
    (0..g.lateral_len())
        .map(|i| {
            let (x, y) = (g.x(i % g.nx) - 1e-3, g.y(i / g.nx) - 0.5e-3);
            let r2 = x * x + y * y;
            C64::from_polar((-r2 / (6e-3f64).powi(2)).exp(), -k * (r2 + 0.018f64.powi(2)).sqrt())
        })
        .collect()
}

fn dot_test(name: &str, medium: &Medium, interfaces: InterfaceModel, planes: &[usize]) {
    let g = grid();
    let options = HasOptions { interfaces, ..HasOptions::default() };
    let (plan, _) = HasPlan::build(&g, medium, F, &reference(&g), &options, &RecordSpec::default()).unwrap();
    let mut rnd = lcg(11);
    let source: Vec<C64> = (0..g.lateral_len()).map(|_| C64::new(rnd(), rnd())).collect();
    for &plane in planes {
        for reflections in [false, true] {
            let weights: Vec<C64> = (0..g.lateral_len()).map(|_| C64::new(rnd(), rnd())).collect();
            let spec = RecordSpec { planes: vec![plane], reflections, ..RecordSpec::default() };
            let field = plan.propagate(&source, &spec).unwrap().planes.remove(0);
            let lhs: C64 = weights.iter().zip(&field).map(|(w, p)| w * p).sum();
            let scale: f64 = weights.iter().zip(&field).map(|(w, p)| w.norm() * p.norm()).sum();
            let m = plan.transposed(plane, &weights, reflections).unwrap();
            let rhs: C64 = m.iter().zip(&source).map(|(m, s)| m * s).sum();
            let err = (lhs - rhs).norm() / scale;
            eprintln!("[{name}] plane {plane}, reflections {reflections}: relative error {err:.1e} (tolerance 1e-10)");
            assert!(err < 1e-10, "{name}, plane {plane}, reflections {reflections}: {lhs} vs {rhs}");
        }
    }
}

#[test]
fn transposed_march_passes_the_dot_product_test_through_a_reverberating_plate() {
    let g = grid();
    let options = HasOptions::default();
    let (plan, _) = HasPlan::build(&g, &plate(), F, &reference(&g), &options, &RecordSpec::default()).unwrap();
    let (first, last, trips) = plan.reverberation().expect("the plate reverberates");
    assert!(trips >= 2, "{trips} round trips: the test needs several");
    // Planes: before the plate, inside it, on its last interface, just beyond it, on the
    // tissue's interface (z = 20 mm, the top of the reflections' backward sweep) and in the
    // tissue.
    let inside = (first + last) / 2;
    dot_test("plate, angular", &plate(), InterfaceModel::Angular, &[3, inside, last, last + 2, 36, 50]);
}

/// The plate with solid bone and diploë (shear 1500 and 1100 m/s): the march carries the SV
/// field, its faces convert (fluid-solid on the whole plane, solid-solid on the cylinder's ends,
/// pairs on part of the plane) and the transposed march transposes both fields.
#[test]
fn transposed_march_passes_the_dot_product_test_through_a_solid_plate() {
    let mut solid = plate();
    for (m, cs) in [(1, 1500.0), (2, 1100.0)] {
        solid.materials[m].shear_sound_speed = cs;
        solid.materials[m].shear_attenuation_db_cm_mhz = 20.0;
    }
    let g = grid();
    let (plan, _) = HasPlan::build(&g, &solid, F, &reference(&g), &HasOptions::default(), &RecordSpec::default()).unwrap();
    let (first, last, trips) = plan.reverberation().expect("the plate reverberates");
    assert!(plan.carries_shear() && plan.elastic_interfaces() == 4, "{} elastic interfaces", plan.elastic_interfaces());
    assert!(trips >= 2, "{trips} round trips: the test needs several");
    dot_test("solid plate", &solid, InterfaceModel::Angular, &[3, (first + last) / 2, last, last + 2, 36, 50]);
}

#[test]
fn transposed_march_passes_the_dot_product_test_with_normal_incidence_and_voxels() {
    dot_test("plate, normal incidence", &plate(), InterfaceModel::NormalIncidence, &[20, 50]);
    // The voxels' per-pixel interfaces reverberate: their reflected waves are kept on their own
    // pixels alone (sparse), which the transposed march, keeping whole planes, checks.
    let g = grid();
    let (plan, _) = HasPlan::build(&g, &voxels(), F, &reference(&g), &HasOptions::default(), &RecordSpec::default()).unwrap();
    let (first, last, trips) = plan.reverberation().expect("the voxels reverberate");
    eprintln!("voxels: reverberation {first}..{last}, {trips} round trips");
    assert!(trips >= 1, "no round trip through the voxels");
    dot_test("voxels, angular", &voxels(), InterfaceModel::Angular, &[14, (first + last) / 2, 40]);
    dot_test("water", &Medium::homogeneous(Material::new("water", 1500.0, 1000.0, 0.0).unwrap()), InterfaceModel::Angular, &[0, 59]);
}

#[test]
fn transposed_march_passes_the_dot_product_test_through_an_oblique_wall() {
    let g = grid();
    let (plan, _) = HasPlan::build(&g, &tilted(), F, &reference(&g), &HasOptions::default(), &RecordSpec::default()).unwrap();
    let walls = plan.oblique_walls();
    eprintln!("tilted plate: {walls} interfaces with oblique walls, reverberation {:?}", plan.reverberation());
    assert!(walls >= 5, "{walls} interfaces with oblique walls: the test needs them");
    assert!(plan.split_steps() >= 5, "{} steps with two reference media: the test needs them", plan.split_steps());
    dot_test("tilted plate", &tilted(), InterfaceModel::Angular, &[10, 24, 30, 50]);
}

/// The tilted plate as a solid read from a CT: the march carries the SV field, the walls'
/// treads convert (with reflected SV waves kept for the round trips) and the transposed march
/// transposes both fields there.
#[test]
fn transposed_march_passes_the_dot_product_test_through_an_oblique_solid_wall() {
    let g = grid();
    let medium = tilted_solid_ct();
    let (plan, _) = HasPlan::build(&g, &medium, F, &reference(&g), &HasOptions::default(), &RecordSpec::default()).unwrap();
    let (walls, converting) = (plan.oblique_walls(), plan.elastic_interfaces());
    eprintln!(
        "tilted solid plate: {walls} interfaces with oblique walls, {converting} converting, reverberation {:?}",
        plan.reverberation()
    );
    assert!(plan.carries_shear() && converting >= 5, "{converting} converting interfaces: the test needs them");
    assert!(plan.continues_shear(), "the walls' SV wave must be continued beside the solid: the test needs it");
    assert!(plan.reverberation().is_some_and(|r| r.2 >= 1), "the plate must reverberate");
    dot_test("tilted solid plate", &medium, InterfaceModel::Angular, &[10, 24, 30, 50]);
}

#[test]
fn transposed_march_refuses_bad_input() {
    let g = grid();
    let water = Medium::homogeneous(Material::new("water", 1500.0, 1000.0, 0.0).unwrap());
    let (plan, _) = HasPlan::build(&g, &water, F, &reference(&g), &HasOptions::default(), &RecordSpec::default()).unwrap();
    let w = vec![C64::new(1.0, 0.0); g.lateral_len()];
    assert!(plan.transposed(60, &w, false).unwrap_err().to_string().contains("plane"));
    assert!(plan.transposed(5, &w[1..], false).unwrap_err().to_string().contains("weights"));
    let mut bad = w.clone();
    bad[3] = C64::new(f64::NAN, 0.0);
    assert!(plan.transposed(5, &bad, false).unwrap_err().to_string().contains("weights"));
}

/// A 64-element bowl (R 50 mm) at 500 kHz focused through a bone plate with an off-axis slower
/// inclusion and soft tissue beyond, with reflections towards the source.
fn bowl_through_plate() -> has_core::Simulation {
    let text = "frequency_hz = 500000.0\n\
        [transducer]\nkind = \"bowl\"\nradius_of_curvature_mm = 50.0\naperture_diameter_mm = 40.0\nelements = 64\n\
        [focus]\nposition_mm = [2.0, -1.0, 50.0]\n\
        [[material]]\nname = \"water\"\nsound_speed_m_s = 1500.0\ndensity_kg_m3 = 1000.0\n\
        [[material]]\nname = \"bone\"\nsound_speed_m_s = 2800.0\ndensity_kg_m3 = 1850.0\nattenuation_db_cm_mhz = 10.0\n\
        [[material]]\nname = \"diploe\"\nsound_speed_m_s = 2300.0\ndensity_kg_m3 = 1700.0\nattenuation_db_cm_mhz = 20.0\n\
        [[material]]\nname = \"tissue\"\nsound_speed_m_s = 1560.0\ndensity_kg_m3 = 1050.0\nattenuation_db_cm_mhz = 1.0\n\
        [medium]\nbackground = \"water\"\n\
        [[region]]\nmaterial = \"bone\"\nshape = \"slab\"\nz_min_mm = 30.0\nz_max_mm = 35.0\n\
        [[region]]\nmaterial = \"diploe\"\nshape = \"cylinder\"\nradius_mm = 6.0\ncenter_mm = [4.0, 0.0]\nz_min_mm = 31.0\nz_max_mm = 34.0\n\
        [[region]]\nmaterial = \"tissue\"\nshape = \"slab\"\nz_min_mm = 40.0\nz_max_mm = 70.0\n\
        [grid]\nreflections = true\n";
    has_core::Simulation::new(&has_core::Scenario::from_toml(text, None).unwrap()).unwrap()
}

#[test]
fn element_responses_equal_one_march_per_element_and_add_up_to_the_array() {
    // The naive reference: each element's source plane marched alone, its pressure read at the
    // target pixel. And the whole steered array's field at the focus, marched as `field` does,
    // against Σ_e h_e·exp(i·steering_e). Tolerance 1e-5 of the largest response: the Rayleigh
    // projections of the two sides sum in single precision (~1e-6, see rayleigh.rs).
    let sim = bowl_through_plate();
    assert!(sim.propagation().reverberation.is_some(), "the plate reverberates");
    let g = &sim.grid;
    // On grid points, where the march's own field is the reference (between them the responses
    // are interpolated: tested against direct sums in `tests/suite/hemisphere.rs`).
    let grid_point = |p: [f64; 3]| g.nearest(p).map(|[i, j, n]| [g.x(i), g.y(j), g.z(n)]).unwrap();
    for target in [grid_point(sim.focus), grid_point([sim.focus[0] + 3e-3, sim.focus[1], sim.focus[2] - 6e-3])] {
        let h = sim.element_responses(target).unwrap();
        let plane = g.plane_index(target[2]);
        let index = |v: f64, d: f64, n: usize| ((v / d).round() as i64 + (n / 2) as i64) as usize;
        let pixel = index(target[1], g.dy, g.ny) * g.nx + index(target[0], g.dx, g.nx);
        let peak = h.iter().map(|v| v.norm()).fold(0.0, f64::max);
        let spec = RecordSpec { planes: vec![plane], reflections: true, ..RecordSpec::default() };
        for e in [0, 21, 63] {
            let mut drive = vec![C64::new(0.0, 0.0); h.len()];
            drive[e] = C64::new(1.0, 0.0);
            let marched = sim.plan.propagate(&sim.source.field(&drive).unwrap(), &spec).unwrap().planes[0][pixel];
            let err = (marched - h[e]).norm() / peak;
            eprintln!(
                "[element {e}, target {:.0?} mm] |h| {:.4e} Pa, error {err:.1e} of the largest (tolerance 1e-5)",
                target.map(|v| v * 1e3),
                h[e].norm()
            );
            assert!(err < 1e-5, "element {e}: marched {marched}, reciprocal {}", h[e]);
        }
        let array = sim.plan.propagate(&sim.source_field(&[]).unwrap(), &spec).unwrap().planes[0][pixel];
        let sum: C64 = h.iter().zip(&sim.steering).map(|(h, s)| h * C64::from_polar(1.0, *s)).sum();
        let err = (array - sum).norm() / array.norm();
        eprintln!("[array] marched {:.4e} Pa, sum of responses {:.4e} Pa, error {err:.1e} (tolerance 1e-5)", array.norm(), sum.norm());
        assert!(err < 1e-5, "array: marched {array}, summed {sum}");
        // Element amplitudes (e.g. a prediction's transmission) weight the responses.
        let amplitudes: Vec<f64> = (0..h.len()).map(|e| 0.2 + 0.8 * ((e * 37) % 11) as f64 / 10.0).collect();
        let weighted = sim.with_element_amplitudes(&amplitudes).unwrap();
        let array = weighted.plan.propagate(&weighted.source_field(&[]).unwrap(), &spec).unwrap().planes[0][pixel];
        let sum: C64 = h.iter().zip(&sim.steering).zip(&amplitudes).map(|((h, s), a)| h * C64::from_polar(*a, *s)).sum();
        let err = (array - sum).norm() / array.norm();
        eprintln!(
            "[amplitudes] marched {:.4e} Pa, weighted sum of responses {:.4e} Pa, error {err:.1e} (tolerance 1e-5)",
            array.norm(),
            sum.norm()
        );
        assert!(err < 1e-5, "amplitudes: marched {array}, summed {sum}");
    }
    for (bad, named) in
        [(vec![1.0; 3], "has 3 values"), (vec![-1.0; sim.n_elements()], "non-negative"), (vec![0.0; sim.n_elements()], "not all zero")]
    {
        let err = sim.with_element_amplitudes(&bad).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(err.contains("amplitudes") && err.contains(named), "{err}");
    }
    let outside = sim.element_responses([0.5, 0.0, 0.05]).unwrap_err().to_string();
    assert!(outside.contains("target") && outside.contains("outside the grid"), "{outside}");
}

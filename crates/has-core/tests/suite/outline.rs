//! A scenario's outline (what it fixes before a simulation is built) against the simulation
//! built from it: the same elements, groups, MR geometry and rules for phases and images.

use has_core::{Scenario, Simulation};

#[test]
fn the_default_scenarios_outline_is_its_simulations() {
    let scenario = Scenario::default();
    let outline = scenario.outline().unwrap();
    let sim = Simulation::new(&scenario).unwrap();
    assert_eq!(outline.n_elements(), sim.n_elements());
    assert_eq!(outline.default_groups(), &sim.groups[..]);
    assert_eq!(outline.mr().affine_mm(), sim.mr.affine_mm());
    let per_group: Vec<f64> = (0..sim.n_groups).map(|g| g as f64 * 0.1).collect();
    assert_eq!(outline.element_phases("p", &per_group, None).unwrap(), sim.element_phases(&per_group).unwrap());
    let e = outline.element_phases("--correction", &[0.0; 5], None).unwrap_err().to_string();
    assert!(e.starts_with("--correction: has 5 values; expected"), "{e}");
    let m = sim.mr.matrix;
    assert!(outline.mr().check_file("--image a.nii", m, &sim.mr.affine_mm()).is_ok());
    let mut moved = sim.mr.affine_mm();
    moved[2][3] += 0.5;
    let e = outline.mr().check_file("--image a.nii", m, &moved).unwrap_err().to_string();
    assert!(e.starts_with("--image a.nii: its affine does not match"), "{e}");
    let e = outline.mr().check_file("--image a.nii", [m[0] + 1, m[1]], &sim.mr.affine_mm()).unwrap_err().to_string();
    assert!(e.contains("the scenario's MR matrix is"), "{e}");
}

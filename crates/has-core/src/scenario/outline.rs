//! What a scenario fixes before a simulation is built (the array's elements and default groups,
//! the focus, the MR image geometry): enough to check a user's phases and images against it in
//! milliseconds, before a build that through a head takes tens of seconds and gigabytes. The
//! checks are the simulation's own rules ([`crate::simulation::grouping`],
//! [`MrGeometry::check_file`]), not copies of them.

use super::Scenario;
use crate::error::{HasError, Result};
use crate::physics::mr::MrGeometry;
use crate::simulation::grouping;

/// A scenario's array, focus and MR geometry, read without its CT or grid.
#[derive(Debug, Clone)]
pub struct Outline {
    n_elements: usize,
    default_groups: Vec<usize>,
    focus: [f64; 3],
    mr: MrGeometry,
}

impl Scenario {
    /// The scenario's [`Outline`]: its transducer and `[mr]` section checked, nothing built.
    pub fn outline(&self) -> Result<Outline> {
        let transducer = self.transducer_si()?;
        let focus = self.focus.position_mm.map(|v| v * 1e-3);
        if focus.iter().any(|v| !v.is_finite()) {
            return Err(HasError::invalid("focus.position_mm", format!("must be finite, got {:?}", self.focus.position_mm)));
        }
        Ok(Outline { n_elements: transducer.elements.len(), default_groups: transducer.default_groups(), focus, mr: self.mr_geometry()? })
    }
}

impl Outline {
    /// Number of elements of the array.
    pub fn n_elements(&self) -> usize {
        self.n_elements
    }

    /// The array's default element → group map (the paper's 16 groups on its quadrant array).
    pub fn default_groups(&self) -> &[usize] {
        &self.default_groups
    }

    /// The steering target, m (transducer frame).
    pub fn focus(&self) -> [f64; 3] {
        self.focus
    }

    /// The MR image geometry.
    pub fn mr(&self) -> &MrGeometry {
        &self.mr
    }

    /// The element → group map a simulation of this scenario has with `groups` contiguous
    /// groups ([`grouping::contiguous`]), or its default groups (`None`).
    pub fn groups(&self, groups: Option<usize>) -> Result<Vec<usize>> {
        match groups {
            Some(g) => grouping::contiguous(self.n_elements, g),
            None => Ok(self.default_groups.clone()),
        }
    }

    /// Phases added to the steering (per element or per group of [`Outline::groups`]) as one per
    /// element, as [`crate::simulation::Simulation::element_phases`] will take them; an error
    /// naming `name` otherwise.
    pub fn element_phases(&self, name: &str, phases: &[f64], groups: Option<usize>) -> Result<Vec<f64>> {
        let g = self.groups(groups)?;
        let n_groups = grouping::check_groups(&g, self.n_elements)?;
        grouping::per_element(name, phases, &g, n_groups)
    }

    /// An image's known phases as one per element, as the estimators will take them (per
    /// element, per group or per default group; [`grouping::known_per_element`]).
    pub fn known_per_element(&self, name: &str, known: &[f64], groups: Option<usize>) -> Result<Vec<f64>> {
        let g = self.groups(groups)?;
        let n_groups = grouping::check_groups(&g, self.n_elements)?;
        grouping::known_per_element(name, known, &g, n_groups, &self.default_groups)
    }

    /// A prior's predicted phases as the estimate takes them: a per-element estimate (one group
    /// per element) per element, per group or per default group, as an image's known phases; a
    /// group estimate per element or per group. An error naming `name` otherwise.
    pub fn check_prior(&self, name: &str, prior: &[f64], groups: Option<usize>) -> Result<()> {
        let g = self.groups(groups)?;
        let n_groups = grouping::check_groups(&g, self.n_elements)?;
        if n_groups == self.n_elements {
            grouping::known_per_element(name, prior, &g, n_groups, &self.default_groups)?;
        } else {
            grouping::per_element(name, prior, &g, n_groups)?;
        }
        Ok(())
    }

    /// Per-element values (e.g. transmissions), one per element of the array; an error naming
    /// `name` otherwise.
    pub fn check_per_element(&self, name: &str, len: usize) -> Result<()> {
        if len != self.n_elements {
            return Err(HasError::invalid(name, format!("has {len} values for {} elements", self.n_elements)));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_scenarios_outline_is_its_simulations() {
        let scenario = Scenario::default();
        let outline = scenario.outline().unwrap();
        let sim = crate::simulation::Simulation::new(&scenario).unwrap();
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
}

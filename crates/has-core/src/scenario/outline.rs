//! What a scenario fixes before a simulation is built (the array's elements and default groups,
//! the focus, the MR image geometry): enough to check a user's phases and images against it in
//! milliseconds, before a build that through a head takes tens of seconds and gigabytes. The
//! checks are the simulation's own rules ([`crate::grouping`],
//! [`MrGeometry::check_file`]), not copies of them.

use super::Scenario;
use crate::error::{HasError, Result};
use crate::grouping;
use crate::physics::mr::MrGeometry;

/// A scenario's array, focus and MR geometry, read without its CT or grid.
#[derive(Debug, Clone)]
pub struct Outline {
    name: String,
    frequency: f64,
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
        Ok(Outline {
            name: self.name.clone(),
            frequency: self.frequency_hz,
            n_elements: transducer.elements.len(),
            default_groups: transducer.default_groups(),
            focus,
            mr: self.mr_geometry()?,
        })
    }
}

impl Outline {
    /// The scenario's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The drive frequency, Hz.
    pub fn frequency(&self) -> f64 {
        self.frequency
    }

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

    /// [`Outline::groups`] and their count.
    fn grouped(&self, groups: Option<usize>) -> Result<(Vec<usize>, usize)> {
        let g = self.groups(groups)?;
        let n = grouping::count(&g);
        Ok((g, n))
    }

    /// Phases added to the steering (per element or per group of [`Outline::groups`]) as one per
    /// element, as [`crate::simulation::Simulation::element_phases`] will take them; an error
    /// naming `name` otherwise.
    pub fn element_phases(&self, name: &str, phases: &[f64], groups: Option<usize>) -> Result<Vec<f64>> {
        let (g, n_groups) = self.grouped(groups)?;
        grouping::per_element(name, phases, &g, n_groups)
    }

    /// An image's known phases as one per element, as the estimators will take them (per
    /// element, per group or per default group; [`grouping::known_per_element`]).
    pub fn known_per_element(&self, name: &str, known: &[f64], groups: Option<usize>) -> Result<Vec<f64>> {
        let (g, n_groups) = self.grouped(groups)?;
        grouping::known_per_element(name, known, &g, n_groups, &self.default_groups)
    }

    /// A prior's predicted phases as the estimate will take them ([`grouping::prior_layout`]:
    /// a per-element estimate per element or per default group, a group estimate per element or
    /// per group); finite. An error naming `name` otherwise.
    pub fn check_prior(&self, name: &str, prior: &[f64], groups: Option<usize>) -> Result<()> {
        let (g, n_groups) = self.grouped(groups)?;
        crate::error::require_finite(name, prior)?;
        grouping::prior_layout(name, prior.len(), &g, n_groups, &self.default_groups).map(|_| ())
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

//! A simulation carried to another grid: the same device, driven the same way, through the same
//! medium and imaged the same way, discretised anew (e.g. coarser, for the many marches of an
//! element basis).

use super::Simulation;
use crate::error::Result;
use crate::physics::grid::Grid;
use crate::physics::mr::MrSampler;
use crate::physics::propagation::{HasPlan, RecordSpec};
use std::sync::Arc;

impl Simulation {
    /// The same simulation on `grid` (its plane 0 the source plane, as this grid's): medium,
    /// array, steering, element amplitudes, groups, interface and screen models, the MR geometry
    /// with its broadening and shift, and the ARFI amplitude (a property of the tissue and the
    /// sequence, rad·m³/N, the same on any grid) are kept; the source is projected onto the new
    /// grid and the HAS plan built there (one march of the steered beam).
    pub fn on_grid(&self, grid: Grid) -> Result<Self> {
        self.medium.check_on_grid(&grid)?;
        let source = self.source.on_grid(&self.transducer, &grid)?;
        let drive: Vec<_> = (0..self.n_elements()).map(|e| self.drive(e, 0.0)).collect();
        let steered_source = source.field(&drive)?;
        let spec = RecordSpec { reflections: self.reflections, ..RecordSpec::default() };
        let (plan, _) = HasPlan::build(&grid, &self.medium, self.frequency, &steered_source, &self.plan.options, &spec)?;
        let sampler = self.sampler.as_ref().map_err(Clone::clone).and_then(|old| {
            MrSampler::new(&grid, &self.medium, self.frequency, &old.geometry, old.broadening)?
                .with_view([old.broadening.width; 2], old.shift)
        });
        Ok(Simulation {
            name: self.name.clone(),
            frequency: self.frequency,
            grid,
            medium: self.medium.clone(),
            steering_medium: self.steering_medium.clone(),
            transducer: self.transducer.clone(),
            focus: self.focus,
            steering: self.steering.clone(),
            element_amplitudes: Arc::clone(&self.element_amplitudes),
            groups: self.groups.clone(),
            n_groups: self.n_groups,
            source,
            steered_source: Arc::new(steered_source),
            plan,
            mr: self.mr.clone(),
            sampler,
            amplitude: self.amplitude.clone(),
            mask_fraction: self.mask_fraction,
            focal_search_radius: self.focal_search_radius,
            noise: self.noise,
            reflections: self.reflections,
        })
    }
}

//! A simulation carried to another grid: the same device, driven the same way, through the same
//! medium and imaged the same way, discretised anew (e.g. coarser, for the many marches of an
//! element basis).

use super::Simulation;
use crate::error::Result;
use crate::physics::grid::Grid;
use crate::physics::propagation::{HasPlan, RecordSpec};
use std::sync::Arc;

impl Simulation {
    /// The same simulation on `grid` (its plane 0 the source plane, as this grid's): medium,
    /// array, steering, element amplitudes, groups, interface and screen models, the MR geometry
    /// with its broadening and shift, and the ARFI amplitude (a property of the tissue and the
    /// sequence, rad·m³/N, the same on any grid) are kept; the source model is carried to the new
    /// grid (its sums Fourier-resampled where the grid has the same period, else the array
    /// projected anew: [`crate::physics::source::SourceModel::on_grid`]) and the HAS plan built
    /// there (one march of the steered beam).
    pub fn on_grid(&self, grid: Grid) -> Result<Self> {
        self.medium.check_on_grid(&grid)?;
        let source = self.source.on_grid(&self.transducer, &grid)?;
        let spec = RecordSpec { reflections: self.reflections, ..RecordSpec::default() };
        let drives = self.steered_drives();
        let (plan, _, steered_source) =
            HasPlan::build_with_reference(&grid, &self.medium, self.frequency, || source.field(&drives), &self.plan.options, &spec)?;
        let sampler = self.sampler_on(&grid, &self.medium);
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

#[cfg(test)]
mod tests {
    use crate::scenario::Scenario;
    use crate::simulation::Simulation;

    /// Carried to its own grid, a simulation gives the same image to rounding (the same plan
    /// built again: 1e-12 of the peak); carried to a coarser one it keeps its device and
    /// calibration, and the ideal image's peak stays within 2 % (discretisation).
    #[test]
    fn a_simulation_on_its_own_grid_gives_the_same_images() {
        let sim = Simulation::new(&Scenario::from_toml("[transducer]\nelements_per_side = 4\n", None).unwrap()).unwrap();
        let phases: Vec<f64> = (0..sim.n_elements()).map(|e| 0.4 * ((e * 7) % 5) as f64 - 0.8).collect();
        let a = sim.arfi_image(&phases).unwrap();
        let peak = a.iter().fold(0.0_f64, |m, v| m.max(*v));
        let same = sim.on_grid(sim.grid.clone()).unwrap().arfi_image(&phases).unwrap();
        let err = (&same - &a).iter().fold(0.0_f64, |m, v| m.max(v.abs()));
        assert!(err < 1e-12 * peak, "{err:e}");
        let g = crate::simulation::coarser_grid(&sim.grid, sim.focus[2], 1.5 * sim.grid.dx).unwrap();
        let coarse = sim.on_grid(g).unwrap();
        assert_eq!((coarse.steering.clone(), coarse.amplitude().unwrap()), (sim.steering.clone(), sim.amplitude().unwrap()));
        let ideal = |s: &Simulation| s.arfi_image(&[]).unwrap().iter().fold(0.0_f64, |m, v| m.max(*v));
        assert!((ideal(&coarse) / ideal(&sim) - 1.0).abs() < 0.02, "{} vs {}", ideal(&coarse), ideal(&sim));
    }
}

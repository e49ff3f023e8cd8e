//! The beam on an x–z section: the pressure of one or more drives on the plane y = y₀ through
//! the beam, every grid plane from the source plane to the last, with the sound speed the march
//! used there (a skull slice with the beam through it).

use crate::error::{HasError, Result};
use crate::simulation::{section_spec, Simulation};
use ndarray::{Array2, Array3};
use num_complex::Complex64 as C64;

/// Pressure and sound speed on the grid's x–z plane nearest y = `y`.
#[derive(Debug, Clone)]
pub struct Section {
    /// y of the section (m): the grid row nearest the one asked for.
    pub y: f64,
    /// x of each column (m).
    pub x: Vec<f64>,
    /// z of each row (m): every grid plane, from the source plane on.
    pub z: Vec<f64>,
    /// Sound speed (m/s) of the slab each plane was reached through, `(nz, nx)` (the source
    /// plane's row: the medium before it).
    pub sound_speed: Array2<f64>,
    /// Complex pressure amplitude (Pa), `(drives, nz, nx)`, drives in the order given.
    pub pressure: Array3<C64>,
}

impl Simulation {
    /// The x–z section nearest y = `y` (m; `None`: the focus's) of the beam driven with each of
    /// `added` (phases added to the steering, per element or per group; an empty vector: none),
    /// marched in one batch, reflections as the simulation adds them.
    ///
    /// ```
    /// use has_core::{Scenario, Simulation};
    /// let sim = Simulation::new(&Scenario::default())?;
    /// let s = sim.section(&[vec![]], None)?;
    /// let axis = s.x.len() / 2; // the column x = 0
    /// let peak = (0..s.z.len()).max_by(|&a, &b| s.pressure[[0, a, axis]].norm().total_cmp(&s.pressure[[0, b, axis]].norm())).unwrap();
    /// assert!((s.z[peak] - 0.085).abs() < 0.01); // the focus, 85 mm from the array
    /// # Ok::<(), has_core::HasError>(())
    /// ```
    pub fn section(&self, added: &[Vec<f64>], y: Option<f64>) -> Result<Section> {
        let g = &self.grid;
        let (row, spec) = section_spec(g, y.unwrap_or(self.focus[1]), self.reflections)?;
        if added.is_empty() {
            return Err(HasError::invalid("phases", "needs at least one drive"));
        }
        let sources = self.source_fields(added)?;
        let recordings = self.plan.propagate_batch(&sources, &spec)?;
        let pressure = Array3::from_shape_vec((added.len(), g.nz, g.nx), recordings.into_iter().flat_map(|rec| rec.window).collect())
            .map_err(|e| HasError::invalid("section", e.to_string()))?;
        let sound_speed = Array2::from_shape_fn((g.nz, g.nx), |(n, i)| self.plan.slab_properties(n).sound_speed[row * g.nx + i]);
        Ok(Section { y: g.y(row), x: (0..g.nx).map(|i| g.x(i)).collect(), z: (0..g.nz).map(|n| g.z(n)).collect(), sound_speed, pressure })
    }
}

#[cfg(test)]
mod tests {
    use crate::{Scenario, Simulation};

    /// The section is the field's own planes: its row through the focal plane equals that row of
    /// `Simulation::field` (the same march, recorded differently: equal to rounding), for two
    /// drives in one batch.
    #[test]
    fn section_rows_are_the_field_planes() {
        let sim = Simulation::new(&Scenario::default()).unwrap();
        let aberration: Vec<f64> = (0..sim.n_groups).map(|g| 0.4 * g as f64 - 3.0).collect();
        let s = sim.section(&[vec![], aberration.clone()], Some(0.0)).unwrap();
        let n = sim.grid.plane_index(sim.focus[2]);
        let j = sim.grid.ny / 2;
        for (k, added) in [vec![], aberration].iter().enumerate() {
            let f = sim.field(added, None).unwrap();
            let peak = f.pressure.iter().map(|p| p.norm()).fold(0.0, f64::max);
            for i in 0..sim.grid.nx {
                assert!((s.pressure[[k, n, i]] - f.pressure[[j, i]]).norm() <= 1e-9 * peak);
            }
        }
        assert_eq!(s.y, 0.0);
        assert!(sim.section(&[], None).is_err());
        assert!(sim.section(&[vec![]], Some(1.0)).is_err());
    }
}

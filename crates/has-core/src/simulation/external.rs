//! A field computed by another engine (a full-wave solver) on this simulation's grid, given the
//! same reading as the march's own: the focal metrics, the hottest place of each tissue and the
//! volume outputs come from one code path whichever engine made the pressure.

use super::{Field, FieldVolume, Simulation};
use crate::error::{HasError, Result};
use crate::physics::propagation::Window;
use ndarray::Array2;
use num_complex::Complex64 as C64;

/// Pressure computed elsewhere on [`Simulation::grid`]: what [`Simulation::field_from_volume`]
/// reads.
#[derive(Debug, Clone)]
pub struct ExternalField {
    /// Complex pressure amplitude (Pa) on the plane `z`, `(ny, nx)`.
    pub plane: Array2<C64>,
    /// z of that plane, m: a grid plane (the nearest one is taken within half a step).
    pub z: f64,
    /// Complex pressure amplitude (Pa) on the beam's axis, one per grid plane, at
    /// `x = axis_slope[0]·z`, `y = axis_slope[1]·z` ([`Simulation::axis_slope`]).
    pub axis: Vec<C64>,
    /// `|p|` (Pa) on every grid sample, row-major (plane, row, column).
    pub magnitude: Vec<f32>,
}

impl Simulation {
    /// The [`Field`] of pressure computed elsewhere on this grid: its focal metrics about the
    /// focus and the hottest place of each tissue found in `magnitude` exactly as for a march
    /// ([`Simulation::field_with_volume`]). Sizes that do not match the grid, a plane off the
    /// grid or a value that is not finite are refused naming the array.
    pub fn field_from_volume(&self, external: ExternalField) -> Result<Field> {
        let g = &self.grid;
        let ExternalField { plane, z, axis, magnitude } = external;
        if plane.dim() != (g.ny, g.nx) {
            return Err(HasError::invalid("plane", format!("must be {} x {} (ny, nx), got {:?}", g.ny, g.nx, plane.dim())));
        }
        if axis.len() != g.nz {
            return Err(HasError::invalid("axis", format!("must hold one value per grid plane ({}), got {}", g.nz, axis.len())));
        }
        let whole = Window::whole(g);
        if magnitude.len() != whole.len() {
            return Err(HasError::invalid(
                "magnitude",
                format!("must hold {} x {} x {} values, got {}", g.nz, g.ny, g.nx, magnitude.len()),
            ));
        }
        if !z.is_finite() || z < g.z0 - 0.5 * g.dz || z > g.z(g.nz - 1) + 0.5 * g.dz {
            return Err(HasError::invalid("z_mm", format!("must lie within the grid, {:.1} to {:.1} mm", g.z0 * 1e3, g.z(g.nz - 1) * 1e3)));
        }
        if plane.iter().chain(&axis).any(|p| !(p.re.is_finite() && p.im.is_finite())) {
            return Err(HasError::invalid("plane", "the plane and the axis must be finite"));
        }
        if magnitude.iter().any(|v| !v.is_finite() || *v < 0.0) {
            return Err(HasError::invalid("magnitude", "must be finite and non-negative"));
        }
        let metrics = match self.focal_search(self.focus) {
            Some(search) => search.metrics(self, |window| Ok(whole.extract(&magnitude, window)))?,
            None => None,
        };
        let volume = FieldVolume { hottest: self.hottest_by_tissue(&magnitude), magnitude };
        Ok(self.assemble_field(plane, g.plane_index(z), axis, metrics, Some(volume)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Scenario;

    /// The march's own field read back through `field_from_volume` gives the same metrics and
    /// hottest places (the code path is shared, so equality is exact).
    #[test]
    fn a_marched_volume_read_back_gives_the_same_field() {
        let sim = Simulation::new(&Scenario::default()).unwrap();
        let f = sim.field_with_volume(&[], None).unwrap();
        let v = f.volume.clone().unwrap();
        let back = sim
            .field_from_volume(ExternalField {
                plane: f.pressure.clone(),
                z: f.z,
                axis: f.axis_pressure.clone(),
                magnitude: v.magnitude.clone(),
            })
            .unwrap();
        let (m, mb) = (f.metrics.unwrap(), back.metrics.unwrap());
        assert_eq!((m.peak, m.peak_pressure, m.fwhm_6db), (mb.peak, mb.peak_pressure, mb.fwhm_6db));
        let bv = back.volume.unwrap();
        assert_eq!(v.hottest.len(), bv.hottest.len());
        for (a, b) in v.hottest.iter().zip(&bv.hottest) {
            assert_eq!((a.position, a.pressure), (b.position, b.pressure));
        }
    }

    #[test]
    fn sizes_off_the_grid_are_refused_naming_the_array() {
        let sim = Simulation::new(&Scenario::default()).unwrap();
        let g = sim.grid.clone();
        let good = || ExternalField {
            plane: Array2::zeros((g.ny, g.nx)),
            z: sim.focus[2],
            axis: vec![C64::new(0.0, 0.0); g.nz],
            magnitude: vec![0.0; g.nx * g.ny * g.nz],
        };
        let name = |e: ExternalField| match sim.field_from_volume(e) {
            Err(HasError::InvalidParameter { name, .. }) => name,
            other => panic!("not refused: {:?}", other.map(|f| f.z)),
        };
        assert_eq!(name(ExternalField { plane: Array2::zeros((g.ny, g.nx + 1)), ..good() }), "plane");
        assert_eq!(name(ExternalField { axis: vec![], ..good() }), "axis");
        assert_eq!(name(ExternalField { magnitude: vec![0.0; 3], ..good() }), "magnitude");
        assert_eq!(name(ExternalField { z: 10.0, ..good() }), "z_mm");
        let mut bad = good();
        bad.magnitude[5] = f32::NAN;
        assert_eq!(name(bad), "magnitude");
    }
}

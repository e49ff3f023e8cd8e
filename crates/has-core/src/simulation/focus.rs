//! What a field says at its target: the focal peaks on its plane and axis, and the focal metrics
//! in 3-D from a box around the target recorded in the same march (see [`crate::focal`]).

use super::{volume, Field, Simulation, TissueHottest};
use crate::error::{HasError, Result};
use crate::focal::{focal_window, nearest, FieldFocus, FocalBox, FocalMetrics, Peak, Shortfall};
use crate::memory;
use crate::numeric::unit;
use crate::physics::grid::Grid;
use crate::physics::propagation::{RecordSpec, Recording, Window};
use crate::Complex64 as C64;
use ndarray::{Array3, ArrayD, IxDyn};

/// How many times the box around the target doubles before the metrics are given up.
const BOX_DOUBLINGS: usize = 3;

impl Simulation {
    /// The focal metrics in 3-D of the beam driven with `added` phases (rad, per element or per
    /// group, on top of the steering) around `target` (m, transducer frame; e.g. a prediction's
    /// target when it is not the focus): one march that records a box around `target` alone and
    /// stops there (the box of [`Simulation::field`]'s metrics, doubled while the -6 dB region
    /// reaches its faces). `None` when no closed -6 dB region lies around it.
    pub fn focal_metrics(&self, added: &[f64], target: [f64; 3]) -> Result<Option<FocalMetrics>> {
        if !target.iter().all(|v| v.is_finite()) || self.grid.nearest(target).is_none() {
            return Err(HasError::invalid("target_mm", "must lie within the grid"));
        }
        let spec = RecordSpec { reflections: self.reflections, ..RecordSpec::default() };
        Ok(self.record_around(&self.source_field(added)?, spec, target)?.1)
    }

    /// [`Simulation::focal_metrics`] around `target` and the hottest place of each tissue class
    /// ([`Simulation::hottest_by_tissue`]) of the same beam, from one march that keeps `|p|` on the
    /// whole grid (the metrics' boxes are cut from it): what a focus at `target` costs the skull.
    /// Refused before the march when the kept `|p|` would not fit in memory.
    pub fn exposure_at(&self, added: &[f64], target: [f64; 3]) -> Result<(Option<FocalMetrics>, Vec<TissueHottest>)> {
        if !target.iter().all(|v| v.is_finite()) || self.grid.nearest(target).is_none() {
            return Err(HasError::invalid("target_mm", "must lie within the grid"));
        }
        let g = &self.grid;
        let whole = Window::whole(g);
        memory::check(
            || format!("|p| on the whole {} x {} x {} grid (the hottest place of each tissue)", g.nx, g.ny, g.nz),
            whole.len() as u64 * volume::BYTES_PER_VOXEL,
            "use a coarser grid ([grid] spacing_mm)",
        )?;
        let spec = RecordSpec { magnitude: Some(whole), reflections: self.reflections, ..RecordSpec::default() };
        let (rec, metrics) = self.record_around(&self.source_field(added)?, spec, target)?;
        Ok((metrics, self.hottest_by_tissue(&rec.magnitude)))
    }

    /// The recording `spec` of the beam from `source` (the plane-0 field), with a box around the
    /// target recorded in the same march, and the focal metrics from that box. The box reaches
    /// max(5 mm, 2 λ) sideways and max(20 mm, 8 λ) along z (λ at the target) and doubles, with
    /// another march, while the -6 dB region reaches one of its faces. `spec.magnitude`, if set,
    /// must be the whole grid: the boxes are then cut from it, without another march.
    pub(crate) fn record_with_focus(&self, source: &[C64], spec: RecordSpec) -> Result<(Recording, Option<FocalMetrics>)> {
        self.record_around(source, spec, self.focus)
    }

    /// [`Simulation::record_with_focus`] around `target` (m) in place of the focus.
    fn record_around(&self, source: &[C64], spec: RecordSpec, target: [f64; 3]) -> Result<(Recording, Option<FocalMetrics>)> {
        let Some(search) = self.focal_search(target) else {
            return Ok((self.plan.propagate(source, &spec)?, None));
        };
        if let Some(kept) = spec.magnitude.clone() {
            assert!(kept == Window::whole(&self.grid), "a kept |p| is of the whole grid");
            let rec = self.plan.propagate(source, &spec)?;
            let metrics = search.metrics(self, |window| Ok(kept.extract(&rec.magnitude, window)))?;
            return Ok((rec, metrics));
        }
        let mut last = None;
        let metrics = search.metrics(self, |window| {
            let mut rec = self.plan.propagate(source, &RecordSpec { magnitude: Some(window.clone()), ..spec.clone() })?;
            let values = std::mem::take(&mut rec.magnitude);
            last = Some(rec);
            Ok(values)
        })?;
        Ok((last.expect("the search marches at least once"), metrics))
    }

    /// The search for the focal metrics around `target` (m): `None` off the grid.
    pub(crate) fn focal_search(&self, target: [f64; 3]) -> Option<FocalSearch> {
        let voxel = self.grid.nearest(target)?;
        let [x, y, z] = target;
        let wavelength = self.medium.properties_at(x, y, z, self.frequency).sound_speed / self.frequency;
        let reach = [(5e-3f64).max(2.0 * wavelength), (20e-3f64).max(8.0 * wavelength)];
        let along = if z > 0.0 { unit(target) } else { [0.0, 0.0, 1.0] };
        Some(FocalSearch { target, voxel, reach, along })
    }
}

/// Where the focal metrics are sought: the target (m), its nearest grid sample, the box's first
/// reach (m, sideways and along z) and the beam's direction.
#[derive(Clone, Copy)]
pub(crate) struct FocalSearch {
    target: [f64; 3],
    voxel: [usize; 3],
    reach: [f64; 2],
    along: [f64; 3],
}

impl FocalSearch {
    /// The first box searched (the one to record in a march that records more).
    pub(crate) fn first_window(&self, g: &Grid) -> Window {
        focal_window(g, self.voxel, self.reach[0], self.reach[1])
    }

    /// The metrics from `|p|` on successive boxes (`magnitude(window)`, single precision,
    /// row-major plane, row, column), the box doubling while the -6 dB region reaches one of its
    /// faces ([`BOX_DOUBLINGS`] times at most); `None` when no closed region lies around the target.
    pub(crate) fn metrics(&self, sim: &Simulation, mut magnitude: impl FnMut(&Window) -> Result<Vec<f32>>) -> Result<Option<FocalMetrics>> {
        let g = &sim.grid;
        let mut reach = self.reach;
        for doubling in 0..=BOX_DOUBLINGS {
            let window = FocalSearch { reach, ..*self }.first_window(g);
            let values = magnitude(&window)?.into_iter().map(f64::from).collect();
            let magnitude = Array3::from_shape_vec((window.planes.len(), window.rows.len(), window.cols.len()), values)
                .map_err(|e| HasError::invalid("window", e.to_string()))?;
            let focal = FocalBox { grid: g, window: &window, magnitude };
            let tissue = |[x, y, z]: [f64; 3]| {
                let p = sim.medium.properties_at(x, y, z, sim.frequency);
                (p.density, p.sound_speed, sim.class_at([x, y, z]))
            };
            match focal.metrics(self.target, self.along, sim.frequency, tissue) {
                Ok(m) => return Ok(Some(m)),
                Err(Shortfall::TooSmall) if doubling < BOX_DOUBLINGS => reach = reach.map(|r| 2.0 * r),
                Err(_) => return Ok(None),
            }
        }
        unreachable!("the last doubling returns")
    }
}

impl Field {
    /// The focal peaks of this field for the steering target `target` (m).
    pub fn focus(&self, target: [f64; 3]) -> FieldFocus {
        let axis_point = if target[2] > 0.0 { [target[0] * self.z / target[2], target[1] * self.z / target[2]] } else { [0.0; 2] };
        let magnitude = self.pressure.mapv(|p| p.norm()).into_dyn();
        let start = [nearest(&self.y, axis_point[1]), nearest(&self.x, axis_point[0])];
        let plane = Peak::climbing(&magnitude.view(), &start, |j| [self.x[j[1]], self.y[j[0]]]);
        let line = ArrayD::from_shape_vec(IxDyn(&[self.axis_pressure.len()]), self.axis_pressure.iter().map(|p| p.norm()).collect())
            .expect("one value per axis sample");
        let axis = Peak::climbing(&line.view(), &[nearest(&self.axis_z, target[2])], |k| {
            [self.axis_xy[k[0]][0], self.axis_xy[k[0]][1], self.axis_z[k[0]]]
        });
        FieldFocus { target, axis_point, plane, axis }
    }
}

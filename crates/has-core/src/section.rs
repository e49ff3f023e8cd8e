//! The beam on an x–z section: the pressure of one or more drives on the plane y = y₀ through
//! the beam, every grid plane from the source plane to the last, with the sound speed the march
//! used there (a skull slice with the beam through it).

use crate::error::{HasError, Result};
use crate::focal::FocalMetrics;
use crate::physics::propagation::{RecordSpec, Recording};
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
        let recordings = self.plan.propagate_batch(&self.source_fields(added)?, &spec)?;
        self.section_of(recordings, row)
    }

    /// [`Simulation::section`] and each drive's focal metrics in 3-D around `target` (m,
    /// transducer frame) as [`Simulation::focal_metrics`] gives them, from the same batch march
    /// (the section's row and the focal box recorded together; a drive whose -6 dB region needs a
    /// larger box marches again alone, to that box).
    pub fn section_with_focal_metrics(
        &self,
        added: &[Vec<f64>],
        y: Option<f64>,
        target: [f64; 3],
    ) -> Result<(Section, Vec<Option<FocalMetrics>>)> {
        let g = &self.grid;
        let search = target.iter().all(|v| v.is_finite()).then(|| self.focal_search(target)).flatten();
        let Some(search) = search else {
            return Err(HasError::invalid("target_mm", "must lie within the grid"));
        };
        let (row, spec) = section_spec(g, y.unwrap_or(self.focus[1]), self.reflections)?;
        if added.is_empty() {
            return Err(HasError::invalid("phases", "needs at least one drive"));
        }
        let sources = self.source_fields(added)?;
        // A drive whose section the build kept (the steered beam through a reverberating head)
        // takes it and marches to its focal box alone; the others march once for both.
        let kept: Vec<Option<Recording>> = sources.iter().map(|s| self.plan.kept_recording(s, &spec)).collect();
        let unkept: Vec<Vec<C64>> = sources.iter().zip(&kept).filter(|(_, k)| k.is_none()).map(|(s, _)| s.clone()).collect();
        let both = RecordSpec { magnitude: Some(search.first_window(g)), ..spec };
        let mut marched = self.plan.propagate_batch(&unkept, &both)?.into_iter();
        let (mut recordings, mut metrics) = (Vec::with_capacity(added.len()), Vec::with_capacity(added.len()));
        for (source, kept) in sources.iter().zip(kept) {
            let (rec, mut first) = match kept {
                Some(rec) => (rec, None),
                None => {
                    let mut rec = marched.next().expect("one recording per drive not kept");
                    let first = std::mem::take(&mut rec.magnitude);
                    (rec, Some(first))
                }
            };
            metrics.push(search.metrics(self, |window| match first.take() {
                Some(values) => Ok(values),
                None => {
                    let spec = RecordSpec { magnitude: Some(window.clone()), reflections: self.reflections, ..RecordSpec::default() };
                    Ok(self.plan.propagate(source, &spec)?.magnitude)
                }
            })?);
            recordings.push(rec);
        }
        Ok((self.section_of(recordings, row)?, metrics))
    }

    /// The section on grid row `row` from the recordings of its window, one per drive.
    fn section_of(&self, recordings: Vec<Recording>, row: usize) -> Result<Section> {
        let g = &self.grid;
        let drives = recordings.len();
        let pressure = Array3::from_shape_vec((drives, g.nz, g.nx), recordings.into_iter().flat_map(|rec| rec.window).collect())
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

    /// One march for the section and the focal metrics gives the section of `section` (to
    /// rounding, 1e-9 of the peak) and each drive's metrics of `focal_metrics` (its own march:
    /// 1e-6, float32 sums in another order; the -6 dB volume to an eighth of a voxel). A 4 x 4 array focuses long (the -6 dB region longer
    /// than the first box's 40 mm), so the unsteered drive needs a larger box: its second march.
    #[test]
    fn section_and_focal_metrics_from_one_march_agree_with_each_alone() {
        let sim = Simulation::new(&Scenario::from_toml("[transducer]\nelements_per_side = 4\n", None).unwrap()).unwrap();
        let drives = [vec![], (0..sim.n_elements()).map(|e| 0.4 * (e as f64).sin()).collect()];
        let target = [1e-3, 0.0, 80e-3];
        let (section, metrics) = sim.section_with_focal_metrics(&drives, None, target).unwrap();
        let alone = sim.section(&drives, None).unwrap();
        let peak = alone.pressure.iter().map(|p| p.norm()).fold(0.0, f64::max);
        assert!(section.pressure.iter().zip(&alone.pressure).all(|(a, b)| (a - b).norm() <= 1e-9 * peak));
        assert_eq!(section.sound_speed, alone.sound_speed);
        for (m, added) in metrics.iter().zip(&drives) {
            let (m, want) = (m.as_ref().unwrap(), sim.focal_metrics(added, target).unwrap().unwrap());
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs().max(1e-3);
            // The -6 dB volume counts 2 x 2 x 2 sub-samples a voxel against the level: a rounding
            // that flips one moves it by an eighth of a voxel.
            let eighth = sim.grid.dx * sim.grid.dy * sim.grid.dz / 8.0;
            assert!(close(m.peak_pressure, want.peak_pressure) && (m.volume_6db - want.volume_6db).abs() <= eighth, "{m:?} vs {want:?}");
            assert!((0..3).all(|k| close(m.peak[k], want.peak[k])) && close(m.fwhm_6db[0], want.fwhm_6db[0]));
        }
        assert!(metrics[0].as_ref().unwrap().fwhm_6db[0] > 40e-3, "the long focus that needs a second box");
        assert!(sim.section_with_focal_metrics(&drives, None, [0.0, 0.0, -1.0]).unwrap_err().to_string().starts_with("target_mm"));
        assert!(sim.section_with_focal_metrics(&drives, None, [f64::NAN, 0.0, 0.08]).is_err());
    }

    /// Through a reverberating plate, a build that keeps the steered beam's section gives it back
    /// for that drive (bit for bit) and marches it to its focal box alone, whose metrics equal
    /// `focal_metrics`'s exactly (the same march to the same box); another drive in the same
    /// call marches once for both, as without a kept section.
    #[test]
    fn a_kept_section_is_reused_and_its_drive_marches_to_the_focal_box_alone() {
        let text = "frequency_hz = 500000.0\n[transducer]\nkind = \"bowl\"\nradius_of_curvature_mm = 40.0\n\
            aperture_diameter_mm = 30.0\n[focus]\nposition_mm = [0.0, 0.0, 40.0]\n[grid]\nspacing_mm = 0.5\nz_max_mm = 80.0\n\
            [arfi]\namplitude_rad_m3_per_n = 1.0\n[medium]\nbackground = \"water\"\n[[material]]\nname = \"water\"\n\
            sound_speed_m_s = 1500.0\ndensity_kg_m3 = 1000.0\n[[material]]\nname = \"bone\"\nsound_speed_m_s = 2800.0\n\
            density_kg_m3 = 1850.0\nattenuation_db_cm_mhz = 4.0\n[[region]]\nmaterial = \"bone\"\nshape = \"slab\"\n\
            z_min_mm = 20.0\nz_max_mm = 26.0\n";
        let sim = crate::simulation::Unbuilt::new(&Scenario::from_toml(text, None).unwrap()).unwrap().build_with_section(0.0).unwrap();
        let (_, spec) = crate::simulation::section_spec(&sim.grid, 0.0, sim.reflections).unwrap();
        let kept = sim.plan.kept_recording(sim.steered_source(), &spec).expect("the build keeps the steered beam's section");
        let other: Vec<f64> = (0..sim.n_groups).map(|g| 0.2 * (g as f64).sin()).collect();
        let drives = [vec![], other.clone()];
        let (section, metrics) = sim.section_with_focal_metrics(&drives, Some(0.0), sim.focus).unwrap();
        assert!(section.pressure.index_axis(ndarray::Axis(0), 0).iter().eq(kept.window.iter()));
        assert!(metrics[0].is_some() && metrics[0] == sim.focal_metrics(&[], sim.focus).unwrap());
        let want = sim.focal_metrics(&other, sim.focus).unwrap().unwrap();
        let got = metrics[1].as_ref().unwrap();
        assert!((got.peak_pressure / want.peak_pressure - 1.0).abs() < 1e-6, "{got:?} vs {want:?}");
        let alone = sim.section(&drives[1..], Some(0.0)).unwrap();
        let peak = alone.pressure.iter().map(|p| p.norm()).fold(0.0, f64::max);
        let second = section.pressure.index_axis(ndarray::Axis(0), 1);
        assert!(second.iter().zip(alone.pressure.iter()).all(|(a, b)| (a - b).norm() <= 1e-9 * peak));
    }
}

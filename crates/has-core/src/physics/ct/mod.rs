//! A medium from a CT of the head: Hounsfield units read from NIfTI, placed in the transducer
//! frame by a rigid transform, converted to acoustic properties ([`HuConversion`]) and sampled
//! onto the simulation grid without aliasing thin bone.
//!
//! Frames: the NIfTI affine maps voxel indices to the scanner's RAS+ frame (mm, as NIfTI
//! defines it); negating x and y gives the DICOM patient frame (LPS), and the user's rigid
//! `patient_to_transducer_mm` (the convention of `arfi dicom --transform`) carries that into the
//! transducer frame.
//!
//! Sampling: each grid cell (dx × dy × dz about its centre) averages the converted properties of
//! `n_x × n_y` columns spread over it, `n_a = ceil(d_a / s)` for the CT's finest voxel size `s`
//! (at most [`MAX_SAMPLES_PER_AXIS`]), each column along z taking every voxel it crosses by the
//! length it runs in it (a voxel is a box of one material: interpolating HU across a bone surface
//! would invent soft tissue between air and bone). Sound speed is averaged as slowness (travel
//! time through the cell is kept) and attenuation arithmetically. A plate thinner than a cell thus
//! keeps its travel-time delay instead of appearing or vanishing with the grid's phase, and a face
//! inside a cell is placed by the exact fraction of the cell on each side of it along the march's
//! axis (points spread along z would round it to `1/n_z` of the cell: a 6.5 mm plate read at
//! 0.4 mm steps from 0.25 mm voxels came out 6.4 mm thick, which moves the waves a solid plate
//! converts to shear by a tenth of a radian and more).
//!
//! The impedance `rho·c` is the one at the cell's centre (the density is set to give it with the
//! averaged speed): a bone surface inside a cell then reflects as the sharp face between the
//! materials on either side, placed at the nearest plane. Averaged impedances would grade the face
//! over two steps, and one-way transmission through a graded face, `Π 2·Z_{i+1}/(Z_i + Z_{i+1})`,
//! exceeds the sharp face's `2·Z_b/(Z_a + Z_b)`: through a 6.5 mm cortical shell on the default
//! grid, 20 % too much pressure at the focus (the validation suite's `shell` case).

mod conversion;

pub use conversion::{BoneModel, BoneShear, HuConversion, Porosity, HU_RANGE};

use crate::error::{HasError, Result};
use crate::nifti::Volume;
use crate::numeric::affine_apply;
use crate::physics::grid::Grid;
use crate::physics::material::Properties;
use crate::physics::tissue::MrResponse;
use rayon::prelude::*;
use std::sync::Arc;

/// At most this many sample points per axis and cell (a cell 8 CT voxels wide is averaged from 8).
pub const MAX_SAMPLES_PER_AXIS: usize = 8;

/// A CT volume in the transducer frame with its conversion.
#[derive(Clone, PartialEq)]
pub struct CtMedium {
    /// The file it was read from (for messages).
    pub path: String,
    /// Shape `(nk, nj, ni)`.
    shape: [usize; 3],
    /// The lowest and highest HU where every voxel holds a whole number, else `None`.
    whole_hu: Option<(i32, i32)>,
    /// HU per voxel, row-major `(k, j, i)` (shared by [`CtMedium::without_bone`]).
    hu: Arc<Vec<f32>>,
    /// Transducer frame (m) to continuous voxel index (i, j, k).
    frame_to_voxel: [[f64; 4]; 3],
    /// Voxel index (i, j, k) to the transducer frame (m).
    voxel_to_frame: [[f64; 4]; 3],
    /// Voxel index (i, j, k) to RAS+ mm: the file's affine, as read.
    ras_affine: [[f64; 4]; 3],
    /// Smallest voxel edge, m.
    finest_voxel: f64,
    /// Lowest and highest corner of the box the volume spans, transducer frame, m.
    bounds: [[f64; 3]; 2],
    /// How HU become properties.
    pub conversion: HuConversion,
}

impl std::fmt::Debug for CtMedium {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CtMedium")
            .field("path", &self.path)
            .field("shape", &self.shape)
            .field("conversion", &self.conversion.name)
            .field("bounds", &self.bounds)
            .finish()
    }
}

/// Checks that `t` is a rigid 4x4 transform (rotation and translation, last row 0 0 0 1).
pub fn check_rigid(name: &str, t: &[[f64; 4]; 4]) -> Result<()> {
    if t.iter().flatten().any(|v| !v.is_finite()) {
        return Err(HasError::invalid(name, "must be finite"));
    }
    let r = |i: usize, j: usize| t[i][j];
    let mut worst: f64 = 0.0;
    for i in 0..3 {
        for j in 0..3 {
            let dot: f64 = (0..3).map(|k| r(i, k) * r(j, k)).sum();
            worst = worst.max((dot - if i == j { 1.0 } else { 0.0 }).abs());
        }
    }
    let det = det3(r);
    if worst > 1e-6 || (det - 1.0).abs() > 1e-6 || t[3] != [0.0, 0.0, 0.0, 1.0] {
        return Err(HasError::invalid(name, "must be rigid: a rotation and a translation (mm), last row 0 0 0 1"));
    }
    Ok(())
}

/// Determinant of the 3x3 matrix with entries `a(row, column)`.
fn det3(a: impl Fn(usize, usize) -> f64) -> f64 {
    a(0, 0) * (a(1, 1) * a(2, 2) - a(1, 2) * a(2, 1)) - a(0, 1) * (a(1, 0) * a(2, 2) - a(1, 2) * a(2, 0))
        + a(0, 2) * (a(1, 0) * a(2, 1) - a(1, 1) * a(2, 0))
}

/// The inverse of an affine map given by its 3x4 rows; `None` if singular.
fn invert(m: &[[f64; 4]; 3]) -> Option<[[f64; 4]; 3]> {
    let a = |i: usize, j: usize| m[i][j];
    let det = det3(a);
    if !(det.abs() > 0.0) || !det.is_finite() {
        return None;
    }
    // Row i, column j of the inverse: the cofactor of (j, i) over the determinant.
    let mut inv: [[f64; 4]; 3] = std::array::from_fn(|i| {
        let (c0, c1) = ((i + 1) % 3, (i + 2) % 3);
        std::array::from_fn(|j| {
            let (r0, r1) = ((j + 1) % 3, (j + 2) % 3);
            if j < 3 {
                (a(r0, c0) * a(r1, c1) - a(r0, c1) * a(r1, c0)) / det
            } else {
                0.0
            }
        })
    });
    for row in inv.iter_mut() {
        row[3] = -(0..3).map(|j| row[j] * m[j][3]).sum::<f64>();
    }
    Some(inv)
}

impl CtMedium {
    /// Places `volume` (HU, affine to RAS+ mm) in the transducer frame by `patient_to_transducer_mm`
    /// (rigid, DICOM LPS mm → transducer mm) and checks every value: finite, within
    /// [`HU_RANGE`]. Errors name `path`.
    pub fn new(volume: Volume, patient_to_transducer_mm: [[f64; 4]; 4], conversion: HuConversion, path: &str) -> Result<Self> {
        check_rigid("ct.patient_to_transducer_mm", &patient_to_transducer_mm)?;
        conversion.validate()?;
        let bad = |reason: String| HasError::BadFile { path: path.to_string(), reason };
        // Voxel (i, j, k) of a flat index (i fastest).
        let [_, nj, ni] = volume.shape;
        let ijk = |f: usize| format!("({}, {}, {})", f % ni, (f / ni) % nj, f / (ni * nj));
        if let Some(f) = volume.values.iter().position(|v| !v.is_finite()) {
            return Err(bad(format!("voxel {} (i, j, k) is {}: a CT must hold finite Hounsfield units", ijk(f), volume.values[f])));
        }
        let (lo, hi) = HU_RANGE;
        if let Some(f) = volume.values.iter().position(|v| !(lo..=hi).contains(&(*v as f64))) {
            return Err(bad(format!(
                "voxel {} (i, j, k) is {} HU, outside {lo}…{hi}: not a calibrated CT in Hounsfield units (rescale it, or mask metal)",
                ijk(f),
                volume.values[f]
            )));
        }
        // voxel → RAS mm → LPS mm → transducer mm → m.
        let t = &patient_to_transducer_mm;
        let a = &volume.affine;
        let mut voxel_to_frame = [[0.0; 4]; 3];
        for (r, row) in voxel_to_frame.iter_mut().enumerate() {
            for (c, v) in row.iter_mut().enumerate() {
                let lps = |k: usize| if k < 2 { -a[k][c] } else { a[k][c] };
                *v = 1e-3 * ((0..3).map(|k| t[r][k] * lps(k)).sum::<f64>() + if c == 3 { t[r][3] } else { 0.0 });
            }
        }
        let frame_to_voxel =
            invert(&voxel_to_frame).ok_or_else(|| bad("the voxel-to-world affine is singular (a zero voxel size?)".into()))?;
        let finest_voxel =
            (0..3).map(|c| (0..3).map(|r| voxel_to_frame[r][c] * voxel_to_frame[r][c]).sum::<f64>().sqrt()).fold(f64::INFINITY, f64::min);
        let [nk, nj, ni] = volume.shape;
        let mut bounds = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
        for corner in 0..8 {
            let pick = |bit: usize, n: usize| if corner >> bit & 1 == 1 { n as f64 - 0.5 } else { -0.5 };
            let p = affine_apply(&voxel_to_frame, [pick(0, ni), pick(1, nj), pick(2, nk)]);
            for a in 0..3 {
                bounds[0][a] = bounds[0][a].min(p[a]);
                bounds[1][a] = bounds[1][a].max(p[a]);
            }
        }
        let whole_hu = volume
            .values
            .iter()
            .try_fold((i32::MAX, i32::MIN), |(lo, hi), &v| (v.fract() == 0.0).then(|| (lo.min(v as i32), hi.max(v as i32))));
        Ok(CtMedium {
            path: path.to_string(),
            whole_hu: whole_hu.filter(|(lo, hi)| lo <= hi),
            shape: volume.shape,
            hu: Arc::new(volume.values),
            frame_to_voxel,
            voxel_to_frame,
            ras_affine: volume.affine,
            finest_voxel,
            bounds,
            conversion,
        })
    }

    /// The same CT with its bone read as soft tissue ([`HuConversion::without_bone`]); the
    /// voxels are shared, not copied.
    pub fn without_bone(&self) -> CtMedium {
        CtMedium { conversion: self.conversion.without_bone(), ..self.clone() }
    }

    /// The CT's voxel grid: its shape `(nk, nj, ni)`, the file's affine from voxel (i, j, k) to
    /// RAS+ mm, and the map from voxel (i, j, k) to the transducer frame (m).
    pub fn voxel_grid(&self) -> ([usize; 3], [[f64; 4]; 3], [[f64; 4]; 3]) {
        (self.shape, self.ras_affine, self.voxel_to_frame)
    }

    /// Lowest and highest corner of the box the CT spans in the transducer frame, m.
    pub fn bounds(&self) -> [[f64; 3]; 2] {
        self.bounds
    }

    /// Whether the CT's box reaches height `z` (m).
    pub fn covers_z(&self, z: f64) -> bool {
        z >= self.bounds[0][2] && z <= self.bounds[1][2]
    }

    /// HU at a point of the transducer frame (m): that of the voxel containing it (voxels are
    /// boxes of one material, as the scanner reports them); `None` outside the volume.
    pub fn hu_at(&self, p: [f64; 3]) -> Option<f64> {
        let q = affine_apply(&self.frame_to_voxel, p);
        let [nk, nj, ni] = self.shape;
        let index = |v: f64, n: usize| {
            let i = v.round();
            (i >= 0.0 && i < n as f64).then_some(i as usize)
        };
        let (i, j, k) = (index(q[0], ni)?, index(q[1], nj)?, index(q[2], nk)?);
        Some(self.hu[(k * nj + j) * ni + i] as f64)
    }

    /// Properties at a point (m) for `frequency`, `None` where the scenario's own medium applies
    /// (outside the CT, or a coupling voxel).
    pub fn properties_at(&self, p: [f64; 3], frequency: f64) -> Option<Properties> {
        self.conversion.properties(self.hu_at(p)?, frequency)
    }

    /// The MR-ARFI response at a point (m), `None` where the scenario's own medium applies.
    pub fn mr_response_at(&self, p: [f64; 3]) -> Option<MrResponse> {
        self.conversion.mr_response(self.hu_at(p)?)
    }

    /// Sample points per axis for a cell of `size` (m); a cell up to 0.1 % wider than a voxel
    /// (the NIfTI affine is single precision) counts as one voxel wide.
    fn samples(&self, size: [f64; 3]) -> [usize; 3] {
        size.map(|d| ((d / self.finest_voxel - 1e-3).ceil() as usize).clamp(1, MAX_SAMPLES_PER_AXIS))
    }

    /// The properties of the cell of `size` (m) about `center`, averaged over it (see the module
    /// docs); points outside the CT or in coupling voxels take `outside`. `None` if no point of
    /// the cell is CT tissue.
    pub fn cell_properties(&self, center: [f64; 3], size: [f64; 3], frequency: f64, outside: Properties) -> Option<Properties> {
        self.cell_average(center, size, outside, &|hu| self.conversion.properties(hu, frequency))
    }

    /// [`CtMedium::cell_properties`] with `convert` giving the properties of a HU value.
    fn cell_average(
        &self,
        center: [f64; 3],
        size: [f64; 3],
        outside: Properties,
        convert: &impl Fn(f64) -> Option<Properties>,
    ) -> Option<Properties> {
        let n = self.samples(size);
        let (mut slowness, mut attenuation, mut tissue) = (0.0, 0.0, false);
        let (mut shear_slowness, mut shear_attenuation, mut solid) = (0.0, 0.0, 0.0);
        let mut crossings = Vec::new();
        for j in 0..n[1] {
            for i in 0..n[0] {
                let off = |s: usize, n: usize, d: f64| ((s as f64 + 0.5) / n as f64 - 0.5) * d;
                let (x, y) = (center[0] + off(i, n[0], size[0]), center[1] + off(j, n[1], size[1]));
                let z_lo = center[2] - 0.5 * size[2];
                self.column_crossings([x, y, z_lo], size[2], &mut crossings);
                // Runs of one material are taken whole (their length as one difference), so a
                // cell of one material gets the same bits wherever the voxels' faces cross it.
                let mut run: Option<(Option<Properties>, f64)> = None;
                let mut add = |q: Option<Properties>, length: f64| {
                    tissue |= q.is_some();
                    let q = q.unwrap_or(outside);
                    let w = length / size[2];
                    slowness += w / q.sound_speed;
                    attenuation += w * q.attenuation;
                    if q.shear_sound_speed > 0.0 {
                        shear_slowness += w / q.shear_sound_speed;
                        shear_attenuation += w * q.shear_attenuation;
                        solid += w;
                    }
                };
                for t in crossings.windows(2) {
                    let q = self.hu_at([x, y, z_lo + 0.5 * (t[0] + t[1])]).and_then(convert);
                    match run {
                        Some((r, _)) if r == q => {}
                        Some((r, start)) => {
                            add(r, t[0] - start);
                            run = Some((q, t[0]));
                        }
                        None => run = Some((q, t[0])),
                    }
                }
                if let Some((r, start)) = run {
                    add(r, size[2] - start);
                }
            }
        }
        let count = (n[0] * n[1]) as f64;
        tissue.then(|| {
            let sound_speed = count / slowness;
            // The impedance of the medium at the centre: a face inside the cell reflects as the
            // sharp face between the materials on either side, at the nearest plane.
            let centre = self.hu_at(center).and_then(convert).unwrap_or(outside);
            // The cell is a solid where its centre is, as the centre places its faces; its shear
            // wave then takes the slowness and attenuation of the solid samples (a mean with the
            // fluid's zeros would give a face cell a third of bone's shear speed).
            let is_solid = centre.shear_sound_speed > 0.0 && solid > 0.0;
            Properties {
                sound_speed,
                density: centre.impedance() / sound_speed,
                attenuation: attenuation / count,
                shear_sound_speed: if is_solid { solid / shear_slowness } else { 0.0 },
                shear_attenuation: if is_solid { shear_attenuation / solid } else { 0.0 },
            }
        })
    }

    /// The distances along z from `start` (m, transducer frame), `0` and `length` included and in
    /// increasing order, at which a line of `length` along z enters another voxel: each voxel
    /// index changes where the continuous index crosses a half-integer. Into `out`.
    fn column_crossings(&self, start: [f64; 3], length: f64, out: &mut Vec<f64>) {
        out.clear();
        out.push(0.0);
        let q0 = affine_apply(&self.frame_to_voxel, start);
        for (a, &q) in q0.iter().enumerate() {
            let v = self.frame_to_voxel[a][2];
            if v == 0.0 {
                continue;
            }
            let q1 = q + v * length;
            let (lo, hi) = (q.min(q1), q.max(q1));
            // Half-integers m + 0.5 strictly inside (lo, hi).
            let mut m = (lo - 0.5).floor() + 1.0;
            while m + 0.5 < hi {
                out.push((m + 0.5 - q) / v);
                m += 1.0;
            }
        }
        out.push(length);
        out.sort_unstable_by(f64::total_cmp);
    }

    /// Whether the cell of `size` about `center` may reach into the CT's box.
    fn may_touch(&self, center: [f64; 3], size: [f64; 3]) -> bool {
        (0..3).all(|a| center[a] + 0.5 * size[a] >= self.bounds[0][a] && center[a] - 0.5 * size[a] <= self.bounds[1][a])
    }

    /// Overwrites, on the lateral grid at height `z` (row-major `(ny, nx)`), the cells the CT
    /// reaches with their averaged properties; `props` holds each pixel's own (scenario)
    /// properties on entry, which the cell's points outside the CT tissue take. Rows run in
    /// parallel on the current rayon pool; each cell is computed alone, so the result does not
    /// depend on the number of threads.
    ///
    /// Where every voxel holds a whole number of HU (as scanners store them), each value's
    /// properties are converted once and looked up: the same values.
    pub fn fill_slice(&self, grid: &Grid, z: f64, frequency: f64, props: &mut [Properties]) {
        let size = [grid.dx, grid.dy, grid.dz];
        let table: Option<(i32, Vec<Option<Properties>>)> =
            self.whole_hu.map(|(lo, hi)| (lo, (lo..=hi).map(|hu| self.conversion.properties(hu as f64, frequency)).collect()));
        let convert = |hu: f64| match &table {
            Some((lo, t)) => t[(hu as i32 - lo) as usize],
            None => self.conversion.properties(hu, frequency),
        };
        props.par_chunks_mut(grid.nx).enumerate().for_each(|(j, row)| {
            for (i, p) in row.iter_mut().enumerate() {
                let c = [grid.x(i), grid.y(j), z];
                if self.may_touch(c, size) {
                    if let Some(q) = self.cell_average(c, size, *p, &convert) {
                        *p = q;
                    }
                }
            }
        });
    }

    /// The lowest sound speed the CT can give.
    pub fn min_sound_speed(&self) -> f64 {
        self.conversion.min_sound_speed()
    }

    /// Checks that the CT covers the beam's path through bone: for each straight path from an
    /// element to the focus that enters the CT, the first point inside must not be bone (a path
    /// entering the volume in bone means the scan was cut off where the beam crosses the skull).
    /// The focus must lie inside the CT.
    pub fn check_covers(&self, sources: &[[f64; 3]], focus: [f64; 3]) -> Result<()> {
        let bad = |reason: String| HasError::BadFile { path: self.path.clone(), reason };
        let mm = |p: [f64; 3]| format!("({:.1}, {:.1}, {:.1}) mm", p[0] * 1e3, p[1] * 1e3, p[2] * 1e3);
        if self.hu_at(focus).is_none() {
            return Err(bad(format!(
                "does not cover the focus {}: the CT spans {} to {}",
                mm(focus),
                mm(self.bounds[0]),
                mm(self.bounds[1])
            )));
        }
        let step = 0.5 * self.finest_voxel;
        for (e, s) in sources.iter().enumerate() {
            let d = [focus[0] - s[0], focus[1] - s[1], focus[2] - s[2]];
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let n = (len / step).ceil() as usize;
            let entry = (0..=n).map(|t| t as f64 / n.max(1) as f64).find_map(|t| {
                let p = [s[0] + t * d[0], s[1] + t * d[1], s[2] + t * d[2]];
                self.hu_at(p).map(|hu| (p, hu))
            });
            if let Some((p, hu)) = entry {
                if hu >= self.conversion.bone_from_hu {
                    return Err(bad(format!(
                        "does not cover the beam path: the path from element {e} to the focus enters the CT at {} in bone ({hu:.0} HU); \
                         the scan must include the whole skull the beam crosses",
                        mm(p)
                    )));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const IDENTITY: [[f64; 4]; 4] = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

    /// A 4 x 4 x 4 volume of 1 mm voxels whose HU is `100·i + 10·j + k`, voxel (0, 0, 0) at RAS
    /// (0, 0, 0).
    fn ramp() -> Volume {
        let values = (0..64).map(|n| (100 * (n % 4) + 10 * (n / 4 % 4) + n / 16) as f32).collect();
        Volume { shape: [4, 4, 4], values, affine: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]] }
    }

    #[test]
    fn voxels_land_in_the_transducer_frame_through_lps_and_the_transform() {
        // Shift by (10, 20, 30) mm: voxel (i, j, k) sits at LPS (-i, -j, k) mm + shift.
        let mut t = IDENTITY;
        t[0][3] = 10.0;
        t[1][3] = 20.0;
        t[2][3] = 30.0;
        let ct = CtMedium::new(ramp(), t, HuConversion::named("aubry2003").unwrap(), "ramp.nii").unwrap();
        let at = |i: f64, j: f64, k: f64| ct.hu_at([(10.0 - i) * 1e-3, (20.0 - j) * 1e-3, (30.0 + k) * 1e-3]);
        assert_eq!(at(2.0, 1.0, 3.0), Some(213.0));
        // A point takes its voxel's value, up to half a voxel from the centre; None beyond the box.
        assert_eq!(at(1.4, 0.6, 2.0), Some(112.0));
        assert_eq!(at(-0.4, 3.4, 0.0), Some(30.0));
        assert_eq!(at(-0.6, 0.0, 0.0), None);
        let [lo, hi] = ct.bounds();
        assert!((lo[0] - 6.5e-3).abs() < 1e-12 && (hi[0] - 10.5e-3).abs() < 1e-12 && (lo[2] - 29.5e-3).abs() < 1e-12);
    }

    #[test]
    fn bad_volumes_and_transforms_are_refused_by_name() {
        let conv = || HuConversion::named("aubry2003").unwrap();
        let mut v = ramp();
        v.values[5] = f32::NAN;
        assert!(CtMedium::new(v, IDENTITY, conv(), "nan.nii").unwrap_err().to_string().contains("nan.nii"));
        let mut v = ramp();
        v.values[5] = 5000.0;
        let e = CtMedium::new(v, IDENTITY, conv(), "hot.nii").unwrap_err().to_string();
        assert!(e.contains("hot.nii") && e.contains("5000"), "{e}");
        let mut t = IDENTITY;
        t[0][0] = 1.1;
        let e = CtMedium::new(ramp(), t, conv(), "a.nii").unwrap_err().to_string();
        assert!(e.contains("patient_to_transducer_mm") && e.contains("rigid"), "{e}");
    }

    #[test]
    fn a_cell_averages_slowness_over_its_samples() {
        // Half the cell in bone of 2000 HU (c 2900), half in soft tissue (c 1546): the cell's
        // speed is the harmonic mean 2/(1/2900 + 1/1546), not the arithmetic one; its impedance
        // is not averaged.
        let values = (0..64).map(|n| if n % 4 < 2 { 0.0 } else { 2000.0 }).collect();
        let v = Volume { shape: [4, 4, 4], values, affine: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]] };
        let mut conv = HuConversion::named("aubry2003").unwrap();
        conv.coupling_below_hu = -1000.0;
        let ct = CtMedium::new(v, IDENTITY, conv, "half.nii").unwrap();
        let water = Properties { sound_speed: 1500.0, density: 1000.0, attenuation: 0.0, shear_sound_speed: 0.0, shear_attenuation: 0.0 };
        // Cell centred between voxel columns i = 1 and 2 (LPS x = -1.5 mm), 2 mm wide in x: its
        // two samples sit at voxel i = 1 (soft tissue) and i = 2 (bone) exactly.
        let p = ct.cell_properties([-1.5e-3, -1.5e-3, 1.5e-3], [2e-3, 1e-3, 1e-3], 1e6, water).unwrap();
        assert!((p.sound_speed - 2.0 / (1.0 / 2900.0 + 1.0 / 1546.0)).abs() < 1e-9, "{}", p.sound_speed);
        // The impedance is the centre's, on the soft tissue's side of the face (1546 m/s, 1040
        // kg/m³): one material's, not an average.
        assert!((p.density * p.sound_speed - 1546.0 * 1040.0).abs() < 1e-6, "{}", p.density * p.sound_speed);
        // Wholly outside: the scenario's medium applies.
        assert_eq!(ct.cell_properties([0.02, 0.0, 0.0], [1e-3; 3], 1e6, water), None);
    }

    /// Each column of a cell takes each voxel it crosses by the length it runs in it: against a
    /// slow reference that samples the column at 4000 points, on a CT of 0.3 mm voxels of random
    /// bone and soft tissue turned about two axes (faces crossing the column at every angle).
    /// Tolerance 1e-3 relative: the reference's points place each crossing to 1/4000 of the cell.
    #[test]
    fn a_column_takes_each_voxel_by_the_length_it_runs_in_it() {
        let mut state = 12345u64;
        let mut random = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 33) as f64 / (1u64 << 31) as f64
        };
        let n = 12;
        let values =
            (0..n * n * n).map(|_| if random() < 0.5 { 40.0 } else { 1000.0 + (1000.0 * random()).round() }).map(|h| h as f32).collect();
        let v = Volume { shape: [n, n, n], values, affine: [[0.3, 0.0, 0.0, 0.0], [0.0, 0.3, 0.0, 0.0], [0.0, 0.0, 0.3, 0.0]] };
        let (a, b) = (20f64.to_radians(), 10f64.to_radians());
        let t = [
            [b.cos(), -b.sin(), 0.0, 0.0],
            [b.sin() * a.cos(), b.cos() * a.cos(), -a.sin(), 0.0],
            [b.sin() * a.sin(), b.cos() * a.sin(), a.cos(), 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let ct = CtMedium::new(v, t, HuConversion::named("aubry2003").unwrap(), "random.nii").unwrap();
        let water = Properties { sound_speed: 1500.0, density: 1000.0, attenuation: 0.0, shear_sound_speed: 0.0, shear_attenuation: 0.0 };
        let convert = |hu: f64| ct.conversion.properties(hu, 5e5);
        let size = [0.7e-3, 0.6e-3, 0.75e-3];
        let centre = affine_apply(&ct.voxel_to_frame, [5.5, 6.0, 6.5]);
        let mut checked = 0;
        for dz in [-1.1e-3, -0.4e-3, 0.0, 0.33e-3, 0.9e-3] {
            let c = [centre[0] + 0.2 * dz, centre[1] - 0.3 * dz, centre[2] + dz];
            let got = ct.cell_average(c, size, water, &convert).unwrap();
            let samples = ct.samples(size);
            let (mut slowness, mut attenuation, points) = (0.0, 0.0, 4000);
            for j in 0..samples[1] {
                for i in 0..samples[0] {
                    let off = |s: usize, n: usize, d: f64| ((s as f64 + 0.5) / n as f64 - 0.5) * d;
                    for k in 0..points {
                        let p = [c[0] + off(i, samples[0], size[0]), c[1] + off(j, samples[1], size[1]), c[2] + off(k, points, size[2])];
                        let q = ct.hu_at(p).and_then(convert).unwrap_or(water);
                        slowness += 1.0 / q.sound_speed;
                        attenuation += q.attenuation;
                    }
                }
            }
            let count = (samples[0] * samples[1] * points) as f64;
            let (want_c, want_a) = (count / slowness, attenuation / count);
            assert!((got.sound_speed / want_c - 1.0).abs() < 1e-3, "{} vs {want_c}", got.sound_speed);
            assert!((got.attenuation - want_a).abs() < 1e-3 * want_a.max(1.0), "{} vs {want_a}", got.attenuation);
            checked += usize::from(got.sound_speed > 1600.0 && got.sound_speed < 2800.0);
        }
        assert!(checked >= 3, "{checked} cells mix bone and tissue");
    }

    /// A slice of a CT of whole HU (converted once per value and looked up) holds, pixel by
    /// pixel and to the bit, each cell's own conversion; so does one whose HU are not whole
    /// (converted at every sample), whose values differ.
    #[test]
    fn a_slice_holds_each_cells_properties_with_or_without_the_table() {
        let g = Grid::new(10, 8, 0.7e-3, 0.6e-3, 3, 0.8e-3, 0.0).unwrap();
        let water = Properties { sound_speed: 1500.0, density: 1000.0, attenuation: 0.0, shear_sound_speed: 0.0, shear_attenuation: 0.0 };
        let mut conv = HuConversion::named("aubry2003").unwrap();
        conv.coupling_below_hu = -1000.0;
        for offset in [0.0, 0.25] {
            // The ramp (0 to 333 HU) scaled into bone: 1000-1999 HU, shifted by `offset`.
            let mut v = ramp();
            v.values.iter_mut().for_each(|h| *h = 1000.0 + 3.0 * *h + offset);
            let mut t = IDENTITY;
            t[2][3] = 0.5;
            let ct = CtMedium::new(v, t, conv.clone(), "ramp.nii").unwrap();
            assert_eq!(ct.whole_hu.is_some(), offset == 0.0);
            let z = 1.6e-3;
            let mut props = vec![water; g.lateral_len()];
            ct.fill_slice(&g, z, 650e3, &mut props);
            let size = [g.dx, g.dy, g.dz];
            let mut bone = 0;
            for (p, got) in props.iter().enumerate() {
                let c = [g.x(p % g.nx), g.y(p / g.nx), z];
                let want = ct.cell_properties(c, size, 650e3, water).unwrap_or(water);
                assert_eq!(*got, want, "pixel {p}, offset {offset}");
                bone += usize::from(got.sound_speed > 2000.0);
            }
            assert!(bone >= 4, "{bone} bone pixels: the slice misses the CT");
        }
    }
}

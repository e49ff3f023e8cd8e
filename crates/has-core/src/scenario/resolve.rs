//! Validation of a [`Scenario`] and its conversion to SI objects: the transducer, the medium and
//! the MR geometry, with every value checked and errors named by their scenario key.

use super::{GridSpec, Scenario, TransducerSpec};
use crate::error::{require_non_negative, require_positive, HasError, Result};
use crate::physics::medium::{Material, Medium, Region, Shape};
use crate::physics::mr::{MrGeometry, MrPlane};
use crate::physics::tissue::MrResponse;
use crate::physics::transducer::{cap_depth, ElementShape, Transducer};

/// The scenario in SI units, validated.
#[derive(Debug, Clone)]
pub struct Resolved {
    /// Name of the scenario.
    pub name: String,
    /// Driving frequency f, Hz.
    pub frequency: f64,
    /// Total acoustic power, W.
    pub acoustic_power: f64,
    /// The array (element number = index).
    pub transducer: Transducer,
    /// Steering target in the transducer frame, m.
    pub focus: [f64; 3],
    /// The acoustic medium: materials and regions.
    pub medium: Medium,
    /// The medium whose straight-ray times of flight steer the array where it is not `medium`:
    /// the head without its skull with `[ct] steer_without_bone` (`None`: `medium`).
    pub steering_medium: Option<Medium>,
    /// The `[grid]` options as given (file units, mm), checked; the grid itself is chosen from
    /// them by [`crate::simulation::choose_grid`].
    pub grid: GridSpec,
    /// The MR image geometry.
    pub mr: MrGeometry,
    /// Width W of the Gaussian broadening filter (paper Eq. 2), m.
    pub broadening_width: f64,
    /// Focal-zone level (paper Eq. 4): fraction of each image's maximum above which connected
    /// pixels enter the fits.
    pub mask_fraction: f64,
    /// Radius (m, in the image plane) around the target within which an image's focal maximum is
    /// sought.
    pub focal_search_radius: f64,
    /// Standard deviation of the Gaussian noise on ARFI phase images, rad.
    pub noise: f64,
    /// Focal ARFI phase of the ideal (unaberrated) beam, rad; sets the amplitude unless given.
    pub ideal_focal_phase: f64,
    /// Scale from broadened force density to ARFI phase, rad·m³/N, if given.
    pub amplitude: Option<f64>,
}

impl Scenario {
    /// Validates every value and converts to SI objects.
    pub fn resolve(&self) -> Result<Resolved> {
        let f = self.frequency_hz;
        require_positive("frequency_hz", f)?;
        require_positive("acoustic_power_w", self.acoustic_power_w)?;
        let focus = mm3(self.focus.position_mm, "focus.position_mm")?;
        let mut medium = self.medium_si()?;
        let transducer = self.transducer_si()?;
        if let Some(spec) = &self.ct {
            let ct = spec
                .resolve(&self.file_path(&spec.file), &medium.materials)
                .map_err(|e| e.named_by(format!("the [ct] file of scenario \"{}\"", self.name)))?;
            ct.check_covers(&transducer.reference_points(), focus)?;
            medium.ct = Some(std::sync::Arc::new(ct));
        }
        let steer_without_bone = self.ct.as_ref().and_then(|c| c.steer_without_bone) == Some(true);
        let steering_medium = if steer_without_bone { medium.without_bone() } else { None };
        let mr = self.mr_geometry()?;
        let a = &self.arfi;
        require_non_negative("arfi.broadening_width_mm", a.broadening_width_mm)?;
        require_non_negative("arfi.noise_rad", a.noise_rad)?;
        require_positive("arfi.ideal_focal_phase_rad", a.ideal_focal_phase_rad)?;
        if !(a.mask_fraction.is_finite() && a.mask_fraction > 0.0 && a.mask_fraction < 1.0) {
            return Err(HasError::invalid("arfi.mask_fraction", format!("must lie in (0, 1), got {}", a.mask_fraction)));
        }
        require_positive("arfi.focal_search_radius_mm", a.focal_search_radius_mm)?;
        if let Some(v) = a.amplitude_rad_m3_per_n {
            require_positive("arfi.amplitude_rad_m3_per_n", v)?;
        }
        for (name, v) in [
            ("grid.spacing_mm", self.grid.spacing_mm),
            ("grid.step_mm", self.grid.step_mm),
            ("grid.lateral_size_mm", self.grid.lateral_size_mm),
            ("grid.z_max_mm", self.grid.z_max_mm),
        ] {
            if let Some(v) = v {
                require_positive(name, v)?;
            }
        }
        if let Some(v) = self.grid.sponge_width_mm {
            require_non_negative("grid.sponge_width_mm", v)?;
        }
        self.grid.interface_model()?;
        self.grid.screen_model(focus)?;
        Ok(Resolved {
            name: self.name.clone(),
            frequency: f,
            acoustic_power: self.acoustic_power_w,
            transducer,
            focus,
            medium,
            steering_medium,
            grid: self.grid.clone(),
            mr,
            broadening_width: a.broadening_width_mm * 1e-3,
            mask_fraction: a.mask_fraction,
            focal_search_radius: a.focal_search_radius_mm * 1e-3,
            noise: a.noise_rad,
            ideal_focal_phase: a.ideal_focal_phase_rad,
            amplitude: a.amplitude_rad_m3_per_n,
        })
    }

    fn medium_si(&self) -> Result<Medium> {
        let (dm, db, dr) = self.default_medium();
        let custom = self.materials.is_some() || self.regions.is_some();
        let materials = if custom { self.materials.clone().unwrap_or_default() } else { dm };
        let regions = if custom { self.regions.clone().unwrap_or_default() } else { dr };
        if materials.is_empty() {
            return Err(HasError::invalid("material", "a scenario with [[region]] must also name its [[material]]s"));
        }
        let mut mats = Vec::with_capacity(materials.len());
        for (i, m) in materials.iter().enumerate() {
            if materials[..i].iter().any(|o| o.name == m.name) {
                return Err(HasError::invalid("material.name", format!("'{}' is given twice", m.name)));
            }
            let default_mr = MrResponse::for_sound_speed(m.sound_speed_m_s);
            let mut mat = Material {
                name: m.name.clone(),
                sound_speed: m.sound_speed_m_s,
                density: m.density_kg_m3,
                attenuation_db_cm_mhz: m.attenuation_db_cm_mhz,
                attenuation_power: m.attenuation_power,
                shear_sound_speed: m.shear_sound_speed_m_s.unwrap_or(0.0),
                shear_attenuation_db_cm_mhz: m.shear_attenuation_db_cm_mhz.unwrap_or(0.0),
                mr: MrResponse {
                    signal: m.mr_signal.unwrap_or(default_mr.signal),
                    displacement_scale: m.displacement_scale.unwrap_or(default_mr.displacement_scale),
                },
            };
            mat.validate()?;
            mat.name = m.name.clone();
            mats.push(mat);
        }
        let index = |name: &str, key: &str| {
            mats.iter().position(|m| m.name == name).ok_or_else(|| HasError::invalid(key, format!("names no material: '{name}'")))
        };
        let background = match (&self.medium, custom) {
            (Some(m), _) => index(&m.background, "medium.background")?,
            (None, false) => index(&db.background, "medium.background")?,
            (None, true) => mats.iter().position(|m| m.name == "water").unwrap_or(0),
        };
        let mut regs = Vec::with_capacity(regions.len());
        for (i, r) in regions.iter().enumerate() {
            let key = format!("region[{i}]");
            let material = index(&r.material, &format!("{key}.material"))?;
            let (z_min, z_max) = (r.z_min_mm * 1e-3, r.z_max_mm * 1e-3);
            let shape = match r.shape.as_str() {
                "cylinder" => {
                    let radius = r.radius_mm.ok_or_else(|| HasError::invalid(format!("{key}.radius_mm"), "is required for a cylinder"))?;
                    let c = r.center_mm.unwrap_or([0.0, 0.0]);
                    Shape::Cylinder { radius: radius * 1e-3, z_min, z_max, center: [c[0] * 1e-3, c[1] * 1e-3] }
                }
                "slab" => {
                    if r.radius_mm.is_some() || r.center_mm.is_some() {
                        return Err(HasError::invalid(key, "a slab takes no radius_mm or center_mm"));
                    }
                    Shape::Slab { z_min, z_max }
                }
                s => return Err(HasError::invalid(format!("{key}.shape"), format!("must be \"cylinder\" or \"slab\", got \"{s}\""))),
            };
            regs.push(Region { material, shape });
        }
        let m = Medium { materials: mats, background, regions: regs, voxels: None, ct: None };
        m.validate()?;
        Ok(m)
    }

    /// The MR image geometry (`[mr]`), checked.
    pub(crate) fn mr_geometry(&self) -> Result<MrGeometry> {
        let mr = MrGeometry {
            plane: MrPlane::parse(&self.mr.plane)?,
            center: mm3(self.mr.center_mm.unwrap_or(self.focus.position_mm), "mr.center_mm")?,
            fov: [self.mr.fov_mm[0] * 1e-3, self.mr.fov_mm[1] * 1e-3],
            matrix: self.mr.matrix,
            slice_thickness: self.mr.slice_thickness_mm * 1e-3,
        };
        mr.validate()?;
        Ok(mr)
    }

    pub(crate) fn transducer_si(&self) -> Result<Transducer> {
        let t = &self.transducer;
        let given = |name: &str, v: bool| (name.to_string(), v);
        let fields = [
            given("elements_per_side", t.elements_per_side.is_some()),
            given("pitch_mm", t.pitch_mm.is_some()),
            given("element_size_mm", t.element_size_mm.is_some()),
            given("quadrant_gap_mm", t.quadrant_gap_mm.is_some()),
            given("radius_of_curvature_mm", t.radius_of_curvature_mm.is_some()),
            given("aperture_diameter_mm", t.aperture_diameter_mm.is_some()),
            given("polar_angle_max_deg", t.polar_angle_max_deg.is_some()),
            given("elements", t.elements.is_some()),
            given("file", t.file.is_some()),
            given("element_shape", t.element_shape.is_some()),
        ];
        let allowed: &[&str] = match t.kind.as_str() {
            "planar-quadrants" => &["elements_per_side", "pitch_mm", "element_size_mm", "quadrant_gap_mm"],
            "bowl" => &["radius_of_curvature_mm", "aperture_diameter_mm", "elements", "element_size_mm"],
            "hemisphere" => &["radius_of_curvature_mm", "polar_angle_max_deg", "elements", "element_size_mm"],
            "elements" => &["file", "element_shape"],
            k => {
                return Err(HasError::invalid(
                    "transducer.kind",
                    format!("must be \"planar-quadrants\", \"bowl\", \"hemisphere\" or \"elements\", got \"{k}\""),
                ))
            }
        };
        if let Some((name, _)) = fields.iter().find(|(n, g)| *g && !allowed.contains(&n.as_str())) {
            return Err(HasError::invalid(format!("transducer.{name}"), format!("is not a key of kind \"{}\"", t.kind)));
        }
        match t.kind.as_str() {
            "planar-quadrants" => Transducer::planar_quadrants(
                t.elements_per_side.unwrap_or(16),
                t.pitch_mm.unwrap_or(2.5) * 1e-3,
                t.element_size_mm.unwrap_or(2.3) * 1e-3,
                t.quadrant_gap_mm.unwrap_or(1.0) * 1e-3,
            ),
            "bowl" => {
                let r = t
                    .radius_of_curvature_mm
                    .ok_or_else(|| HasError::invalid("transducer.radius_of_curvature_mm", "is required for a bowl"))?
                    * 1e-3;
                let a =
                    t.aperture_diameter_mm.ok_or_else(|| HasError::invalid("transducer.aperture_diameter_mm", "is required for a bowl"))?
                        * 1e-3;
                match t.elements {
                    None if t.element_size_mm.is_some() => {
                        Err(HasError::invalid("transducer.element_size_mm", "needs transducer.elements"))
                    }
                    None => Transducer::bowl(r, a),
                    Some(n) => Transducer::bowl_elements(r, a, n, element_diameter(t, r, a, n)),
                }
            }
            "hemisphere" => {
                let r = t.radius_of_curvature_mm.unwrap_or(150.0) * 1e-3;
                let theta = t.polar_angle_max_deg.unwrap_or(60.0).to_radians();
                let n = t.elements.unwrap_or(1024);
                let a = 2.0 * r * theta.min(0.5 * std::f64::consts::PI).sin();
                Transducer::hemisphere(r, theta, n, element_diameter(t, r, a, n))
            }
            _ => {
                let file = t.file.as_deref().ok_or_else(|| HasError::invalid("transducer.file", "is required for kind \"elements\""))?;
                let path = self.file_path(file);
                let shape = match t.element_shape.as_deref().unwrap_or("square") {
                    "square" => ElementShape::Square,
                    "disc" => ElementShape::Disc,
                    s => return Err(HasError::invalid("transducer.element_shape", format!("must be \"square\" or \"disc\", got \"{s}\""))),
                };
                let p = path.display().to_string();
                let text = std::fs::read_to_string(&path).map_err(|e| HasError::reading(&p, &e))?;
                Transducer::from_csv(&text, &p, shape)
            }
        }
    }
}

/// The disc diameter of a bowl's or hemisphere's elements (m): `element_size_mm` if given, else
/// 80 % of the centre spacing of `n` equal-area cells on the cap of radius `r` and aperture `a`.
/// (The constructor validates `r`, `a` and `n`.)
fn element_diameter(t: &TransducerSpec, r: f64, a: f64, n: usize) -> f64 {
    let cap = 2.0 * std::f64::consts::PI * r * cap_depth(r, a);
    t.element_size_mm.map(|s| s * 1e-3).unwrap_or(0.8 * (cap.abs() / n.max(1) as f64).sqrt())
}

/// Converts a position from mm to m, checking that it is finite.
fn mm3(v: [f64; 3], name: &str) -> Result<[f64; 3]> {
    if v.iter().all(|x| x.is_finite()) {
        Ok([v[0] * 1e-3, v[1] * 1e-3, v[2] * 1e-3])
    } else {
        Err(HasError::invalid(name, "must be finite"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn negative_sound_speed_is_named() {
        let t = "[[material]]\nname = \"w\"\nsound_speed_m_s = -1500\ndensity_kg_m3 = 1000\n";
        let e = Scenario::from_toml(t, None).unwrap().resolve().unwrap_err();
        assert!(e.to_string().contains("sound_speed_m_s"), "{e}");
    }
}

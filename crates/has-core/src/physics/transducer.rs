//! Transducers: the paper's planar quadrant array, spherical bowls, arbitrary element lists.

use crate::error::{require_positive, HasError, Result};
use std::f64::consts::PI;

/// Outline of a flat element.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ElementShape {
    /// Square of side `size`, edges along the frame's x and y projected onto the element plane.
    Square,
    /// Disc of diameter `size`.
    Disc,
}

/// The radiating surface of one element (metres, transducer frame).
#[derive(Debug, Clone, PartialEq)]
pub enum Surface {
    /// A flat element centred at `center` facing `normal` (unit).
    Flat {
        /// Centre of the element face, m.
        center: [f64; 3],
        /// Unit normal, pointing into the medium.
        normal: [f64; 3],
        /// Side of a square or diameter of a disc, m.
        size: f64,
        /// Outline of the face.
        shape: ElementShape,
    },
    /// A whole spherical cap: apex at the origin, centre of curvature at (0, 0, radius).
    Cap {
        /// Radius of curvature R, m.
        radius: f64,
        /// Diameter of the cap's rim (chord across the aperture), m.
        aperture_diameter: f64,
    },
}

/// A quadrature point on a radiating surface: position, unit normal, area (m²).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfacePoint {
    /// Position on the surface, m.
    pub position: [f64; 3],
    /// Unit normal there, pointing into the medium.
    pub normal: [f64; 3],
    /// Surface area the point stands for, m².
    pub area: f64,
}

impl Surface {
    /// Radiating area (m²).
    pub fn area(&self) -> f64 {
        match *self {
            Surface::Flat { size, shape: ElementShape::Square, .. } => size * size,
            Surface::Flat { size, shape: ElementShape::Disc, .. } => PI * size * size / 4.0,
            Surface::Cap { radius, aperture_diameter } => 2.0 * PI * radius * cap_depth(radius, aperture_diameter),
        }
    }

    /// The point used for steering (time of flight): the element centre, or the cap's apex.
    pub fn reference_point(&self) -> [f64; 3] {
        match *self {
            Surface::Flat { center, .. } => center,
            Surface::Cap { .. } => [0.0, 0.0, 0.0],
        }
    }

    /// Largest z reached by the surface.
    pub fn z_max(&self) -> f64 {
        match *self {
            Surface::Flat { center, normal, size, shape } => {
                let tilt = (1.0 - normal[2] * normal[2]).max(0.0).sqrt();
                // The farthest point from the centre: a corner of a square (at most), the rim of a disc.
                let reach = if shape == ElementShape::Square { std::f64::consts::SQRT_2 } else { 1.0 };
                center[2] + 0.5 * size * reach * tilt
            }
            Surface::Cap { radius, aperture_diameter } => cap_depth(radius, aperture_diameter),
        }
    }

    /// The element moved rigidly, `x -> R·(x - about) + about + shift` (`rotation` R a proper
    /// rotation matrix, row-major; m): a flat element's centre and normal move with it. A whole
    /// cap is defined about the z axis and cannot turn: refused unless `R` is the identity and
    /// `shift` zero.
    pub fn moved(&self, rotation: &[[f64; 3]; 3], about: [f64; 3], shift: [f64; 3]) -> Result<Surface> {
        let turn = |v: [f64; 3]| std::array::from_fn(|i| (0..3).map(|j| rotation[i][j] * v[j]).sum::<f64>());
        match *self {
            Surface::Flat { center, normal, size, shape } => {
                let arm = turn(std::array::from_fn(|k| center[k] - about[k]));
                let center = std::array::from_fn(|k| arm[k] + about[k] + shift[k]);
                Ok(Surface::Flat { center, normal: crate::numeric::unit(turn(normal)), size, shape })
            }
            Surface::Cap { .. } => {
                let identity = (0..3).all(|i| (0..3).all(|j| rotation[i][j] == if i == j { 1.0 } else { 0.0 }));
                if identity && shift == [0.0; 3] {
                    Ok(self.clone())
                } else {
                    Err(HasError::invalid("transducer", "a single-element bowl cannot be moved: its cap is defined about the z axis"))
                }
            }
        }
    }

    /// Whether the element lies flat in the plane `z = z_plane` facing +z.
    pub fn is_in_plane(&self, z_plane: f64) -> bool {
        matches!(*self, Surface::Flat { center, normal, .. }
            if (center[2] - z_plane).abs() < 1e-12 && (normal[2] - 1.0).abs() < 1e-12)
    }

    /// Quadrature points no more than `spacing` apart (midpoint rule on sub-cells).
    pub fn quadrature(&self, spacing: f64) -> Vec<SurfacePoint> {
        match *self {
            Surface::Flat { center, normal, size, shape } => {
                let (u, v) = in_plane_axes(normal);
                let m = (size / spacing).ceil().max(1.0) as usize;
                let h = size / m as f64;
                let mut pts = Vec::with_capacity(m * m);
                for a in 0..m {
                    for b in 0..m {
                        let s = -0.5 * size + (a as f64 + 0.5) * h;
                        let t = -0.5 * size + (b as f64 + 0.5) * h;
                        if shape == ElementShape::Disc && s * s + t * t > 0.25 * size * size {
                            continue;
                        }
                        let p = std::array::from_fn(|k| center[k] + s * u[k] + t * v[k]);
                        pts.push(SurfacePoint { position: p, normal, area: h * h });
                    }
                }
                if shape == ElementShape::Disc {
                    // Rescale so the points carry the exact disc area.
                    let a: f64 = pts.iter().map(|p| p.area).sum();
                    let f = self.area() / a;
                    pts.iter_mut().for_each(|p| p.area *= f);
                }
                pts
            }
            Surface::Cap { radius, aperture_diameter } => cap_quadrature(radius, aperture_diameter, spacing),
        }
    }
}

/// Depth of a spherical cap of radius `r` and aperture diameter `d`: `h = r - sqrt(r² - d²/4)`.
pub fn cap_depth(r: f64, d: f64) -> f64 {
    r - (r * r - 0.25 * d * d).max(0.0).sqrt()
}

/// Two unit vectors spanning the plane normal to `n`: u along the frame's x where possible.
fn in_plane_axes(n: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let cross = |a: [f64; 3], b: [f64; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let norm = |a: [f64; 3]| {
        let l = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        [a[0] / l, a[1] / l, a[2] / l]
    };
    let ey = if n[1].abs() < 0.9 { [0.0, 1.0, 0.0] } else { [1.0, 0.0, 0.0] };
    let u = norm(cross(ey, n));
    let v = cross(n, u);
    (u, v)
}

/// Midpoint quadrature of a spherical cap in (polar angle, azimuth) rings of nearly equal area.
fn cap_quadrature(r: f64, d: f64, spacing: f64) -> Vec<SurfacePoint> {
    let theta_max = (0.5 * d / r).clamp(-1.0, 1.0).asin();
    let rings = ((r * theta_max) / spacing).ceil().max(1.0) as usize;
    let dtheta = theta_max / rings as f64;
    let mut pts = Vec::new();
    for k in 0..rings {
        let (t0, t1) = (k as f64 * dtheta, (k + 1) as f64 * dtheta);
        let t = 0.5 * (t0 + t1);
        let ring_area = 2.0 * PI * r * r * (t0.cos() - t1.cos());
        let n_phi = ((2.0 * PI * r * t.sin()) / spacing).ceil().max(1.0) as usize;
        let a = ring_area / n_phi as f64;
        for m in 0..n_phi {
            let phi = 2.0 * PI * (m as f64 + 0.5) / n_phi as f64;
            let (s, c) = (t.sin(), t.cos());
            let normal = [-s * phi.cos(), -s * phi.sin(), c];
            let position = [r * s * phi.cos(), r * s * phi.sin(), r * (1.0 - c)];
            pts.push(SurfacePoint { position, normal, area: a });
        }
    }
    pts
}

/// A transducer: an ordered list of elements (element number = index); groups of elements are
/// chosen elsewhere ([`Transducer::default_groups`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Transducer {
    /// The elements' radiating surfaces; the index is the element number.
    pub elements: Vec<Surface>,
}

impl Transducer {
    /// The paper's planar array: four quadrants of `n x n` square elements in z = 0, numbered
    /// `e = n²·q + n·r + c` as in the paper, quadrants clockwise from the top-left (q=0: x<0, y>0),
    /// row 0 of largest y, column 0 of smallest x. Element centres at `±(gap/2 + pitch/2 + pitch·i)`
    /// (m). The paper's phantom experiment: n = 16, pitch 2.5 mm, elements 2.3 mm, gap 1 mm.
    pub fn planar_quadrants(n: usize, pitch: f64, element_size: f64, gap: f64) -> Result<Self> {
        if n == 0 || n > 256 {
            return Err(HasError::invalid("transducer.elements_per_side", format!("must be 1..=256, got {n}")));
        }
        require_positive("transducer.pitch_mm", pitch)?;
        require_positive("transducer.element_size_mm", element_size)?;
        if element_size > pitch {
            return Err(HasError::invalid("transducer.element_size_mm", "must not exceed pitch_mm"));
        }
        if !(gap.is_finite() && gap >= 0.0) {
            return Err(HasError::invalid("transducer.quadrant_gap_mm", "must be >= 0"));
        }
        let offset = |i: usize| 0.5 * gap + 0.5 * pitch + pitch * i as f64;
        let mut elements = Vec::with_capacity(4 * n * n);
        for q in 0..4 {
            for r in 0..n {
                for c in 0..n {
                    let x = if q == 1 || q == 2 { offset(c) } else { -offset(n - 1 - c) };
                    let y = if q <= 1 { offset(n - 1 - r) } else { -offset(r) };
                    elements.push(Surface::Flat {
                        center: [x, y, 0.0],
                        normal: [0.0, 0.0, 1.0],
                        size: element_size,
                        shape: ElementShape::Square,
                    });
                }
            }
        }
        Ok(Transducer { elements })
    }

    /// A single spherical cap, apex at the origin, centre of curvature at (0, 0, R).
    pub fn bowl(radius: f64, aperture_diameter: f64) -> Result<Self> {
        validate_bowl(radius, aperture_diameter)?;
        Ok(Transducer { elements: vec![Surface::Cap { radius, aperture_diameter }] })
    }

    /// `count` flat disc elements of diameter `element_size` on a spherical cap, on a sunflower
    /// (Fibonacci) pattern of equal cap area per element, each facing the centre of curvature.
    pub fn bowl_elements(radius: f64, aperture_diameter: f64, count: usize, element_size: f64) -> Result<Self> {
        validate_bowl(radius, aperture_diameter)?;
        if count == 0 || count > 100_000 {
            return Err(HasError::invalid("transducer.elements", format!("must be 1..=100000, got {count}")));
        }
        require_positive("transducer.element_size_mm", element_size)?;
        let cos_max = 1.0 - cap_depth(radius, aperture_diameter) / radius;
        let golden = PI * (3.0 - 5f64.sqrt());
        let elements = (0..count)
            .map(|i| {
                // Equal-area rings: cos(theta) uniform in [cos_max, 1].
                let ct = 1.0 - (i as f64 + 0.5) / count as f64 * (1.0 - cos_max);
                let st = (1.0 - ct * ct).max(0.0).sqrt();
                let phi = golden * i as f64;
                let normal = [-st * phi.cos(), -st * phi.sin(), ct];
                let center = [radius * st * phi.cos(), radius * st * phi.sin(), radius * (1.0 - ct)];
                Surface::Flat { center, normal, size: element_size, shape: ElementShape::Disc }
            })
            .collect();
        Ok(Transducer { elements })
    }

    /// A hemispherical array: `count` flat disc elements of diameter `element_size` on the sphere
    /// of radius `radius` (apex at the origin, centre of curvature and natural focus at
    /// (0, 0, R)), from the apex out to the polar angle `polar_angle_max` (rad, at most π/2: a
    /// whole hemisphere). The layout is that of [`Transducer::bowl_elements`]: element `e` sits at
    /// `cos θ_e = 1 - (e + ½)/N · (1 - cos θ_max)` (rings of equal area, element 0 nearest the
    /// apex) and azimuth `φ_e = e · π(3 - √5)` (the golden angle), facing the centre.
    pub fn hemisphere(radius: f64, polar_angle_max: f64, count: usize, element_size: f64) -> Result<Self> {
        if !(polar_angle_max.is_finite() && polar_angle_max > 0.0 && polar_angle_max <= 0.5 * PI + 1e-12) {
            return Err(HasError::invalid(
                "transducer.polar_angle_max_deg",
                format!("must lie in (0, 90] degrees, got {:.3}", polar_angle_max.to_degrees()),
            ));
        }
        require_positive("transducer.radius_of_curvature_mm", radius)?;
        let aperture = 2.0 * radius * polar_angle_max.min(0.5 * PI).sin();
        Transducer::bowl_elements(radius, aperture, count, element_size)
    }

    /// Elements from CSV text with header `x_mm,y_mm,z_mm,nx,ny,nz,size_mm`, one row per element.
    pub fn from_csv(text: &str, path: &str, shape: ElementShape) -> Result<Self> {
        let bad = |reason: String| HasError::BadFile { path: path.to_string(), reason };
        let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
        let header: Vec<String> = match lines.next() {
            Some((_, h)) => h.split(',').map(|s| s.trim().to_string()).collect(),
            None => return Err(bad("empty file".into())),
        };
        let expected = ["x_mm", "y_mm", "z_mm", "nx", "ny", "nz", "size_mm"];
        if header != expected {
            return Err(bad(format!("header must be '{}', got '{}'", expected.join(","), header.join(","))));
        }
        let mut elements = Vec::new();
        for (ln, line) in lines {
            let v: Vec<f64> = line
                .split(',')
                .map(|s| s.trim().parse::<f64>())
                .collect::<std::result::Result<_, _>>()
                .map_err(|e| bad(format!("line {}: {e}", ln + 1)))?;
            if v.len() != 7 || v.iter().any(|x| !x.is_finite()) {
                return Err(bad(format!("line {}: need 7 finite numbers", ln + 1)));
            }
            let l = (v[3] * v[3] + v[4] * v[4] + v[5] * v[5]).sqrt();
            if l < 1e-9 || v[5] <= 0.0 {
                return Err(bad(format!("line {}: the normal must point towards +z", ln + 1)));
            }
            if v[6] <= 0.0 {
                return Err(bad(format!("line {}: size_mm must be > 0", ln + 1)));
            }
            elements.push(Surface::Flat {
                center: [v[0] * 1e-3, v[1] * 1e-3, v[2] * 1e-3],
                normal: [v[3] / l, v[4] / l, v[5] / l],
                size: v[6] * 1e-3,
                shape,
            });
        }
        if elements.is_empty() {
            return Err(bad("no elements".into()));
        }
        Ok(Transducer { elements })
    }

    /// Total radiating area (m²).
    pub fn area(&self) -> f64 {
        self.elements.iter().map(Surface::area).sum()
    }

    /// Largest lateral distance of any element point from the z axis (m).
    pub fn lateral_extent(&self) -> f64 {
        self.elements
            .iter()
            .map(|e| match *e {
                Surface::Flat { center, size, .. } => center[0].abs().max(center[1].abs()) + size * std::f64::consts::FRAC_1_SQRT_2,
                Surface::Cap { aperture_diameter, .. } => 0.5 * aperture_diameter,
            })
            .fold(0.0, f64::max)
    }

    /// Every element's reference point (m; [`Surface::reference_point`]), in element order.
    pub fn reference_points(&self) -> Vec<[f64; 3]> {
        self.elements.iter().map(Surface::reference_point).collect()
    }

    /// The array moved rigidly ([`Surface::moved`]).
    pub fn moved(&self, rotation: &[[f64; 3]; 3], about: [f64; 3], shift: [f64; 3]) -> Result<Transducer> {
        Ok(Transducer { elements: self.elements.iter().map(|e| e.moved(rotation, about, shift)).collect::<Result<_>>()? })
    }

    /// Whether every element lies flat in z = 0 facing +z (no Rayleigh projection needed).
    pub fn is_planar(&self) -> bool {
        self.elements.iter().all(|e| e.is_in_plane(0.0))
    }

    /// Default grouping: 16 groups of contiguous element numbers (the paper's `e // 64` for 1024
    /// elements), or one group per element when there are fewer than 16.
    pub fn default_groups(&self) -> Vec<usize> {
        let n = self.elements.len();
        let g = n.min(16);
        (0..n).map(|e| e * g / n).collect()
    }
}

fn validate_bowl(radius: f64, aperture_diameter: f64) -> Result<()> {
    require_positive("transducer.radius_of_curvature_mm", radius)?;
    require_positive("transducer.aperture_diameter_mm", aperture_diameter)?;
    if aperture_diameter > 2.0 * radius {
        return Err(HasError::invalid("transducer.aperture_diameter_mm", "must not exceed twice the radius of curvature (a hemisphere)"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planar_quadrant_numbering_follows_the_paper() {
        let t = Transducer::planar_quadrants(16, 2.5e-3, 2.3e-3, 1e-3).unwrap();
        let c = |e: usize| match t.elements[e] {
            Surface::Flat { center, .. } => center,
            _ => unreachable!(),
        };
        assert_eq!(t.elements.len(), 1024);
        // q=0 top-left: element 0 is the top-left corner of the whole array.
        let e0 = c(0);
        assert!((e0[0] + 39.25e-3).abs() < 1e-12 && (e0[1] - 39.25e-3).abs() < 1e-12);
        // element 15: last column of q=0, next to the centre line.
        assert!((c(15)[0] + 1.75e-3).abs() < 1e-12);
        // q=1 starts at x = +1.75 mm, top row.
        let e256 = c(256);
        assert!((e256[0] - 1.75e-3).abs() < 1e-12 && (e256[1] - 39.25e-3).abs() < 1e-12);
        // q=2 (x>0, y<0): row 0 is the one next to the centre line (largest y).
        assert!((c(512)[1] + 1.75e-3).abs() < 1e-12 && c(512)[0] > 0.0);
        // q=3 (x<0, y<0)
        assert!(c(768)[0] < 0.0 && c(768)[1] < 0.0);
        assert_eq!(t.default_groups()[63], 0);
        assert_eq!(t.default_groups()[64], 1);
        assert_eq!(t.default_groups()[1023], 15);
    }

    #[test]
    fn quadrature_carries_the_exact_area() {
        let cap = Surface::Cap { radius: 0.085, aperture_diameter: 0.08 };
        let a: f64 = cap.quadrature(0.5e-3).iter().map(|p| p.area).sum();
        assert!((a / cap.area() - 1.0).abs() < 1e-12);
        let disc = Surface::Flat { center: [0.0; 3], normal: [0.0, 0.6, 0.8], size: 3e-3, shape: ElementShape::Disc };
        let a: f64 = disc.quadrature(0.3e-3).iter().map(|p| p.area).sum();
        assert!((a / disc.area() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn csv_with_wrong_header_is_rejected() {
        let e = Transducer::from_csv("x,y\n1,2\n", "e.csv", ElementShape::Square).unwrap_err();
        assert!(e.to_string().contains("header"), "{e}");
    }

    #[test]
    fn hemisphere_elements_cover_equal_areas_facing_the_centre() {
        // 1024 elements out to 60° on R = 150 mm: on the sphere, facing the centre, cos θ evenly
        // spread (equal-area rings) from the apex to the rim, the golden-angle spiral in azimuth.
        let (r, n) = (0.15, 1024);
        let t = Transducer::hemisphere(r, 60f64.to_radians(), n, 6e-3).unwrap();
        assert_eq!(t.elements.len(), n);
        for (e, s) in t.elements.iter().enumerate() {
            let Surface::Flat { center, normal, .. } = *s else { unreachable!() };
            let to_centre = [-center[0] / r, -center[1] / r, 1.0 - center[2] / r];
            assert!(to_centre.iter().zip(&normal).all(|(a, b)| (a - b).abs() < 1e-12), "element {e} does not face the centre");
            let cos_theta = 1.0 - center[2] / r;
            let expected = 1.0 - (e as f64 + 0.5) / n as f64 * 0.5;
            assert!((cos_theta - expected).abs() < 1e-12, "element {e}: cos θ {cos_theta}");
        }
        let whole = Transducer::hemisphere(r, 0.5 * PI, 8, 6e-3).unwrap();
        assert!(whole.elements.iter().all(|e| e.z_max() <= r + 3e-3));
        assert!(Transducer::hemisphere(r, 1.6, 8, 6e-3).is_err());
    }
}

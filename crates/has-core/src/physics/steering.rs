//! Geometric steering: per-element phases that focus the array through the medium.

use crate::error::{HasError, Result};
use crate::physics::medium::Medium;
use crate::physics::transducer::Transducer;
use std::f64::consts::PI;

/// Time of flight (s) along the straight segment from `a` to `b`: `∫ ds / c(s)` by the midpoint
/// rule with steps no longer than `step` (m).
pub fn time_of_flight(medium: &Medium, frequency: f64, a: [f64; 3], b: [f64; 3], step: f64) -> f64 {
    let d: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let n = (len / step).ceil().max(1.0) as usize;
    let h = len / n as f64;
    (0..n)
        .map(|i| {
            let t = (i as f64 + 0.5) / n as f64;
            let p: [f64; 3] = std::array::from_fn(|k| a[k] + t * d[k]);
            h / medium.properties_at(p[0], p[1], p[2], frequency).sound_speed
        })
        .sum()
}

/// Steering phases (rad) focusing at `target`: element `e` is delayed by `t_max - t_e`, so every
/// element's wave arrives at the target at the same time (`phi_e = 2·pi·f·(t_max - t_e)`; a
/// positive phase delays the emission by `phi / (2·pi·f)`). Straight-line time of flight through the
/// regions from each element's centre.
pub fn steering_phases(transducer: &Transducer, medium: &Medium, frequency: f64, target: [f64; 3]) -> Result<Vec<f64>> {
    if !target.iter().all(|v| v.is_finite()) {
        return Err(HasError::invalid("focus.position_mm", "must be finite"));
    }
    let step = 0.1e-3;
    let tof: Vec<f64> = transducer.elements.iter().map(|e| time_of_flight(medium, frequency, e.reference_point(), target, step)).collect();
    let t_max = tof.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Ok(tof.iter().map(|t| 2.0 * PI * frequency * (t_max - t)).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::medium::Material;

    #[test]
    fn steering_equalises_arrival_times_in_water() {
        let t = Transducer::planar_quadrants(4, 2.5e-3, 2.3e-3, 1e-3).unwrap();
        let water = Medium::homogeneous(Material::new("water", 1500.0, 1000.0, 0.0).unwrap());
        let f = 550e3;
        let target = [0.0, 0.0, 0.085];
        let phi = steering_phases(&t, &water, f, target).unwrap();
        // phase + k·distance must be the same for every element.
        let k = 2.0 * PI * f / 1500.0;
        let total: Vec<f64> = t
            .elements
            .iter()
            .zip(&phi)
            .map(|(e, p)| {
                let c = e.reference_point();
                let r = ((c[0] - target[0]).powi(2) + (c[1] - target[1]).powi(2) + (c[2] - target[2]).powi(2)).sqrt();
                p + k * r
            })
            .collect();
        for v in &total {
            assert!((v - total[0]).abs() < 1e-9);
        }
    }
}

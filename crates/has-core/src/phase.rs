//! Phase arithmetic shared by the forward model, the estimators, the cost and the reports:
//! wrapping, circular means, the phase error metric and the twin of an aberration under a point
//! reflection.

use crate::error::{HasError, Result};
use num_complex::Complex64 as C64;
use std::f64::consts::PI;

/// Wraps to (-pi, pi].
pub fn wrap(p: f64) -> f64 {
    let w = (p + PI).rem_euclid(2.0 * PI) - PI;
    if w == -PI {
        PI
    } else {
        w
    }
}

/// Phases minus their circular mean (angle of the mean phasor), wrapped.
pub fn centred(phases: &[f64]) -> Vec<f64> {
    let m: C64 = phases.iter().map(|&p| C64::from_polar(1.0, p)).sum();
    let offset = if m.norm() > 1e-12 { m.arg() } else { 0.0 };
    phases.iter().map(|p| wrap(p - offset)).collect()
}

/// RMS of the wrapped difference `a - b` after removing the best common offset (the paper's
/// phase error).
pub fn phase_error(a: &[f64], b: &[f64]) -> f64 {
    let m: C64 = a.iter().zip(b).map(|(x, y)| C64::from_polar(1.0, x - y)).sum();
    let offset = m.arg();
    (a.iter().zip(b).map(|(x, y)| wrap(x - y - offset).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
}

/// Condenses per-element phases to per-group ones by the circular mean over each group.
pub fn condense(element_phases: &[f64], groups: &[usize]) -> Result<Vec<f64>> {
    if element_phases.len() != groups.len() {
        return Err(HasError::invalid("phases", format!("has {} values for {} elements", element_phases.len(), groups.len())));
    }
    let g = crate::grouping::count(groups);
    let mut sums = vec![C64::new(0.0, 0.0); g];
    for (&p, &k) in element_phases.iter().zip(groups) {
        sums[k] += C64::from_polar(1.0, p);
    }
    Ok(sums.iter().map(|s| s.arg()).collect())
}

/// The point-reflection pairing of groups (group centroid `c` ↔ the group nearest `-c`), when
/// it is a permutation: for a symmetric aperture, one in-focus intensity image hardly tells
/// `phi_g` from its twin `-phi_{sigma(g)}`.
pub fn point_reflection(positions: &[[f64; 3]], groups: &[usize]) -> Option<Vec<usize>> {
    let g = groups.iter().max()? + 1;
    let mut c = vec![[0.0; 2]; g];
    let mut n = vec![0usize; g];
    for (p, &k) in positions.iter().zip(groups) {
        c[k][0] += p[0];
        c[k][1] += p[1];
        n[k] += 1;
    }
    c.iter_mut().zip(&n).for_each(|(c, &n)| c.iter_mut().for_each(|v| *v /= n.max(1) as f64));
    let d = |a: [f64; 2], b: [f64; 2]| (a[0] + b[0]).hypot(a[1] + b[1]);
    let sigma: Vec<usize> = (0..g).map(|a| (0..g).min_by(|&x, &y| d(c[a], c[x]).total_cmp(&d(c[a], c[y]))).unwrap_or(a)).collect();
    let scale = c.iter().map(|v| v[0].hypot(v[1])).fold(0.0, f64::max);
    let is_perm = (0..g).all(|a| sigma[sigma[a]] == a);
    let close = (0..g).all(|a| d(c[a], c[sigma[a]]) <= 0.05 * scale.max(1e-9));
    (is_perm && close).then_some(sigma)
}

/// The twin of group phases under a point reflection: `psi_g = -phi_{sigma(g)}`.
pub fn twin(phases: &[f64], sigma: &[usize]) -> Vec<f64> {
    centred(&sigma.iter().map(|&s| -phases[s]).collect::<Vec<_>>())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_lands_in_minus_pi_to_pi_and_the_error_ignores_a_common_offset() {
        for (p, w) in [(0.0, 0.0), (PI, PI), (-PI, PI), (3.0 * PI, PI), (2.5 * PI, 0.5 * PI), (-0.5, -0.5)] {
            assert!((wrap(p) - w).abs() < 1e-12, "{p}: {}", wrap(p));
        }
        let a = [0.1, -0.4, 2.0, 3.1];
        let b: Vec<f64> = a.iter().map(|x| x + 1.3).collect();
        assert!(phase_error(&a, &b) < 1e-12);
        assert_eq!(condense(&[0.2, 0.2, -1.0, -1.0], &[0, 0, 1, 1]).unwrap().len(), 2);
        // The error is the RMS of the centred difference: ±0.5 rad about a common zero.
        assert!((phase_error(&[0.0, 0.0], &[0.5, -0.5]) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn condense_takes_the_circular_mean() {
        let c = condense(&[PI - 0.1, -PI + 0.1, 0.0, 0.2], &[0, 0, 1, 1]).unwrap();
        assert!((c[0].abs() - PI).abs() < 1e-12);
        assert!((c[1] - 0.1).abs() < 1e-12);
    }
}

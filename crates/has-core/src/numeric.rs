//! Small numerical tools the layers share.

/// The parabola `y = a·(x − vertex)² + value` through three points with distinct `x`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Parabola {
    /// Where its slope vanishes.
    pub vertex: f64,
    /// `a`, the second divided difference (half the second derivative).
    pub curvature: f64,
    /// `y` at the vertex.
    pub value: f64,
}

/// The parabola through `points` (any spacing, in increasing or decreasing `x`), in Newton's
/// form `y = y0 + d01·(x − x0) + a·(x − x0)·(x − x1)` with `d01`, `d12` the first divided
/// differences and `a = (d12 − d01)/(x2 − x0)`, so `vertex = (x0 + x1)/2 − d01/(2a)`; `None`
/// when the points are collinear (`a = 0`) or not finite.
pub fn parabola(points: [(f64, f64); 3]) -> Option<Parabola> {
    let [(x0, y0), (x1, y1), (x2, y2)] = points;
    let d01 = (y1 - y0) / (x1 - x0);
    let d12 = (y2 - y1) / (x2 - x1);
    let a = (d12 - d01) / (x2 - x0);
    if !(a != 0.0 && a.is_finite()) {
        return None;
    }
    let vertex = 0.5 * (x0 + x1) - d01 / (2.0 * a);
    Some(Parabola { vertex, curvature: a, value: y1 - a * (x1 - vertex).powi(2) })
}

/// The largest of `samples` `(x, y)` refined by the parabola through it and its two neighbours:
/// `(x, y)` of the vertex where that parabola opens downwards, else the largest sample itself
/// (also at either end).
pub fn parabolic_peak(samples: &[(f64, f64)]) -> (f64, f64) {
    let n = (0..samples.len()).fold(0, |b, i| if samples[i].1 > samples[b].1 { i } else { b });
    if n == 0 || n + 1 == samples.len() {
        return samples[n];
    }
    match parabola([samples[n - 1], samples[n], samples[n + 1]]) {
        Some(p) if p.curvature < 0.0 => (p.vertex, p.value),
        _ => samples[n],
    }
}

/// `v` scaled to unit length (+z for a zero vector).
pub fn unit(v: [f64; 3]) -> [f64; 3] {
    let norm = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if norm == 0.0 {
        return [0.0, 0.0, 1.0];
    }
    v.map(|x| x / norm)
}

/// The affine map given by its 3 x 4 rows applied to the point `p`: `m · (p, 1)`.
pub fn affine_apply(m: &[[f64; 4]; 3], p: [f64; 3]) -> [f64; 3] {
    let row = |r: &[f64; 4]| r[0] * p[0] + r[1] * p[1] + r[2] * p[2] + r[3];
    [row(&m[0]), row(&m[1]), row(&m[2])]
}

/// Pearson correlation coefficient of two equally long samples.
pub fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    sab / (saa * sbb).sqrt()
}

/// Upper 95 % point of chi² with `k` degrees of freedom: tabulated to four digits for k ≤ 10,
/// Wilson–Hilferty beyond (within 0.3 % there).
pub fn chi2_95(k: usize) -> f64 {
    const TABLE: [f64; 10] = [3.841, 5.991, 7.815, 9.488, 11.070, 12.592, 14.067, 15.507, 16.919, 18.307];
    if k <= TABLE.len() {
        return TABLE[k.max(1) - 1];
    }
    let k = k as f64;
    let z = 1.644_853_626_951_472_2;
    k * (1.0 - 2.0 / (9.0 * k) + z * (2.0 / (9.0 * k)).sqrt()).powi(3)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chi2_95_is_the_tabulated_point_and_continuous_beyond_the_table() {
        // 3.841 for one degree of freedom (the table); Wilson–Hilferty at 11 within 0.3 % of 19.675.
        assert_eq!(chi2_95(1), 3.841);
        assert_eq!(chi2_95(0), 3.841);
        assert!((chi2_95(11) / 19.675 - 1.0).abs() < 3e-3);
    }

    /// A parabola's own samples, unequally spaced, give back its vertex, curvature and value.
    #[test]
    fn a_parabola_is_found_from_three_of_its_points() {
        let f = |x: f64| 4.0 * (x - 0.3f64).powi(2) + 7.0;
        let p = parabola([(-1.0, f(-1.0)), (0.0, f(0.0)), (1.5, f(1.5))]).unwrap();
        assert!((p.vertex - 0.3).abs() < 1e-12 && (p.curvature - 4.0).abs() < 1e-12 && (p.value - 7.0).abs() < 1e-12);
        assert_eq!(parabola([(0.0, 1.0), (1.0, 2.0), (2.0, 3.0)]), None);
        let g = |x: f64| 3.0 - 2.0 * (x - 0.37).powi(2);
        let s: Vec<(f64, f64)> = [0.0, 0.25, 0.5, 1.2].iter().map(|&x| (x, g(x))).collect();
        let (x, y) = parabolic_peak(&s);
        assert!((x - 0.37).abs() < 1e-12 && (y - 3.0).abs() < 1e-12, "{x} {y}");
        assert_eq!(parabolic_peak(&[(0.0, 2.0), (1.0, 1.0)]), (0.0, 2.0));
    }
}

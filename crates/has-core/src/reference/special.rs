//! The special functions the exact solutions need: the Bessel function `J0`, spherical Bessel
//! functions of complex argument, Legendre polynomials and Gauss–Legendre nodes.

use num_complex::Complex64 as C64;
use std::f64::consts::PI;

/// `J0(x) = (1/π)·∫_0^π cos(x·sin t) dt` by the trapezoidal rule over the full period with `N`
/// points: for this periodic analytic integrand the rule's error is `2·Σ_m J_{mN}(x)`, below
/// 1e-15 once `N >= |x| + 40`.
pub fn bessel_j0(x: f64) -> f64 {
    let n = 4 * ((x.abs() + 40.0) / 4.0).ceil() as usize;
    // The period's points t_j = 2πj/n: t = 0 and π give 1, t = π/2 and 3π/2 give cos x, and the
    // others come in fours of equal |sin t| (t, π - t, π + t, 2π - t).
    let mut sum = 2.0 + 2.0 * x.cos();
    for j in 1..n / 4 {
        sum += 4.0 * (x * (2.0 * PI * j as f64 / n as f64).sin()).cos();
    }
    sum / n as f64
}

/// Spherical Bessel functions `j_n(z)` and `y_n(z)` for `n = 0..=n_max` and complex `z`
/// (`z != 0`), as [`spherical_functions`] gives them.
pub fn spherical_bessel(n_max: usize, z: C64) -> (Vec<C64>, Vec<C64>) {
    let [j, y, _, _] = spherical_functions(n_max, z);
    (j, y)
}

/// Spherical Hankel functions `h_n^(1)(z)` and `h_n^(2)(z)` for `n = 0..=n_max`, as
/// [`spherical_functions`] gives them.
pub fn spherical_hankels(n_max: usize, z: C64) -> (Vec<C64>, Vec<C64>) {
    let [_, _, h1, h2] = spherical_functions(n_max, z);
    (h1, h2)
}

/// `[j_n, y_n, h_n^(1), h_n^(2)](z)` for `n = 0..=n_max` and complex `z` (`z != 0`), from one
/// run of each recurrence: `j` by Miller's backward recurrence ([`spherical_j`]), the Hankel
/// function that decays away from the real axis (`h^(1)` for `Im z >= 0`) by the forward
/// recurrence from its closed forms `h_0^(1) = -i·e^{iz}/z`, `h_1^(1) = -e^{iz}·(z + i)/z²`
/// (DLMF 10.49.6; stable, it is the dominant solution there), and from those two the other
/// Hankel function, `2·j - h`, and `y = -i·(h^(1) - j)` (`i·(h^(2) - j)` below the axis). None of
/// these subtractions cancels; `y` or the other Hankel function by its own forward recurrence,
/// or the Hankel functions as `j ± i·y`, would lose digits where `|Im z|` is large (a lossy wall
/// of many wavelengths' radius: the decaying one is `e^{-2|Im z|}` of the other).
pub fn spherical_functions(n_max: usize, z: C64) -> [Vec<C64>; 4] {
    let (j, decaying) = bessel_and_decaying_hankel(n_max, z);
    let i = C64::i();
    let other: Vec<C64> = decaying.iter().zip(&j).map(|(h, j)| 2.0 * j - h).collect();
    if z.im >= 0.0 {
        let y = decaying.iter().zip(&j).map(|(h, j)| -i * (h - j)).collect();
        [j, y, decaying, other]
    } else {
        let y = decaying.iter().zip(&j).map(|(h, j)| i * (h - j)).collect();
        [j, y, other, decaying]
    }
}

/// `j_n(z)` ([`spherical_j`]) and the Hankel function that decays away from the real axis
/// (`h^(1)` for `Im z >= 0`, else `h^(2)`), `n = 0..=n_max`.
fn bessel_and_decaying_hankel(n_max: usize, z: C64) -> (Vec<C64>, Vec<C64>) {
    let i = C64::i();
    let (e, sign) = if z.im >= 0.0 { ((i * z).exp(), 1.0) } else { ((-i * z).exp(), -1.0) };
    let si = C64::new(0.0, sign);
    // h_0 = ∓i·e^{±iz}/z, h_1 = -e^{±iz}·(z ± i)/z².
    let mut h = vec![-si * e / z];
    if n_max >= 1 {
        h.push(-e * (z + si) / (z * z));
    }
    for n in 1..n_max {
        let next = (2 * n + 1) as f64 / z * h[n] - h[n - 1];
        h.push(next);
    }
    (spherical_j(n_max, z), h)
}

/// `j_n(z)`, `n = 0..=n_max`, by Miller's backward recurrence from well above `max(n_max, |z|)`,
/// normalised to the closed form of `j_0 = sin z / z` or `j_1 = sin z/z² - cos z/z`, whichever
/// is larger (DLMF 10.49, 10.51).
pub fn spherical_j(n_max: usize, z: C64) -> Vec<C64> {
    let (s, c) = (z.sin(), z.cos());
    let start = n_max.max(z.norm() as usize) + 40 + (z.norm().sqrt() * 4.0) as usize;
    let mut j = vec![C64::new(0.0, 0.0); n_max + 1];
    let (mut upper, mut f) = (C64::new(0.0, 0.0), C64::new(1.0, 0.0));
    for n in (1..=start).rev() {
        let lower = (2 * n + 1) as f64 / z * f - upper;
        upper = f;
        f = lower;
        if n - 1 <= n_max {
            j[n - 1] = f;
        }
        if f.norm() > 1e100 {
            // Rescale what has been stored (kept below 1e150, where |f|² still fits a double):
            // values of higher order only lose digits they cannot show.
            upper *= 1e-100;
            f *= 1e-100;
            for v in j.iter_mut().skip(n - 1) {
                *v *= 1e-100;
            }
        }
    }
    let (j0, j1) = (s / z, s / (z * z) - c / z);
    // a / b through b's magnitude: |b|² of a recurrence value may underflow or overflow.
    let ratio = |a: C64, b: C64| (a / b.norm()) / (b / b.norm());
    let scale = if j0.norm() >= j1.norm() || n_max == 0 { ratio(j0, j[0]) } else { ratio(j1, j[1]) };
    for v in &mut j {
        *v *= scale;
    }
    j
}

/// Derivatives `f_n'(z)` of a spherical Bessel sequence `f` (`j`, `y` or `h`):
/// `f_0' = -f_1`, `f_n' = f_{n-1} - (n+1)/z·f_n`. The last order has no derivative (the
/// sequence must reach one order beyond the largest needed).
pub fn derivatives(f: &[C64], z: C64) -> Vec<C64> {
    let mut d = Vec::with_capacity(f.len().saturating_sub(1));
    for n in 0..f.len().saturating_sub(1) {
        d.push(if n == 0 { -f[1] } else { f[n - 1] - (n + 1) as f64 / z * f[n] });
    }
    d
}

/// Legendre polynomials `P_n(x)`, `n = 0..=n_max`, by `(n+1)·P_{n+1} = (2n+1)·x·P_n - n·P_{n-1}`.
pub fn legendre(n_max: usize, x: f64) -> Vec<f64> {
    let mut p = Vec::with_capacity(n_max + 1);
    p.push(1.0);
    if n_max >= 1 {
        p.push(x);
    }
    for n in 1..n_max {
        p.push(((2 * n + 1) as f64 * x * p[n] - n as f64 * p[n - 1]) / (n + 1) as f64);
    }
    p
}

/// Gauss–Legendre nodes and weights of `n` points on `[a, b]` (Newton's method on `P_n` from
/// the Chebyshev guesses; exact for polynomials of degree `2n - 1`).
pub fn gauss_legendre(n: usize, a: f64, b: f64) -> Vec<(f64, f64)> {
    let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, x);
            for k in 1..n {
                let p2 = ((2 * k + 1) as f64 * x * p1 - k as f64 * p0) / (k + 1) as f64;
                p0 = p1;
                p1 = p2;
            }
            let p = if n == 0 { 1.0 } else { p1 };
            let pm = if n == 1 { 1.0 } else { p0 };
            dp = n as f64 * (x * p - pm) / (x * x - 1.0);
            let dx = p / dp;
            x -= dx;
            if dx.abs() < 1e-15 {
                break;
            }
        }
        out.push((mid - half * x, half * 2.0 / ((1.0 - x * x) * dp * dp)));
    }
    out
}

/// [`gauss_legendre`] on each of `panels` equal parts of `[a, b]`, `n` points each.
pub fn composite_gauss(panels: usize, n: usize, a: f64, b: f64) -> Vec<(f64, f64)> {
    let w = (b - a) / panels as f64;
    (0..panels).flat_map(|p| gauss_legendre(n, a + p as f64 * w, a + (p + 1) as f64 * w)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Tabulated values (Abramowitz & Stegun table 9.1, DLMF) and the first zero.
    #[test]
    fn j0_matches_tables() {
        for (x, v) in [(0.0, 1.0), (1.0, 0.765_197_686_557_966_6), (5.0, -0.177_596_771_314_338_3), (10.0, -0.245_935_764_451_348_3)] {
            assert!((bessel_j0(x) - v).abs() < 1e-14, "J0({x}) = {} vs {v}", bessel_j0(x));
        }
        assert!(bessel_j0(2.404_825_557_695_773).abs() < 1e-14);
        assert!((bessel_j0(-5.0) - bessel_j0(5.0)).abs() < 1e-15);
        // Large argument against the asymptotic form (error O(1/x²) = 1e-5 of the amplitude).
        let x = 300.0_f64;
        let asymptotic = (2.0 / (PI * x)).sqrt() * ((x - PI / 4.0).cos() + (x - PI / 4.0).sin() / (8.0 * x));
        assert!((bessel_j0(x) - asymptotic).abs() < 1e-7);
    }

    /// Closed forms of orders 0-2 (DLMF 10.49.3), the Wronskian `j_n·y_n' - j_n'·y_n = 1/z²` at
    /// high order (both for a complex argument), and a real value from tables.
    #[test]
    fn spherical_bessel_closed_forms_and_wronskian() {
        for z in [C64::new(0.3, 0.0), C64::new(7.5, 0.02), C64::new(120.0, 0.5), C64::new(40.0, -0.1)] {
            let (j, y) = spherical_bessel(260, z);
            let (s, c) = (z.sin(), z.cos());
            let j2 = (3.0 / (z * z) - 1.0) * s / z - 3.0 * c / (z * z);
            let y2 = -(3.0 / (z * z) - 1.0) * c / z - 3.0 * s / (z * z);
            // (the closed form of j_2 loses digits as 3/z³ for small z)
            assert!((j[2] - j2).norm() < 1e-12 * j2.norm().max(1e-3) / z.norm().powi(3).min(1.0), "j2({z})");
            assert!((y[2] - y2).norm() < 1e-12 * y2.norm(), "y2({z})");
            let (dj, dy) = (derivatives(&j, z), derivatives(&y, z));
            // (orders where y_n still fits a double: up to about 4|z| + 20)
            for n in [0, 1, 2, 10, 50, 150, 250].into_iter().filter(|&n| (n as f64) < 4.0 * z.norm() + 20.0) {
                let w = j[n] * dy[n] - dj[n] * y[n];
                assert!((w * z * z - 1.0).norm() < 1e-9, "Wronskian at n = {n}, z = {z}: {}", w * z * z);
            }
        }
        // j_10(10) = sqrt(π/20)·J_{10.5}(10) = 0.06460515449256... (mpmath, 30 digits).
        let (j, _) = spherical_bessel(10, C64::new(10.0, 0.0));
        assert!((j[10].re - 0.064_605_154_492_564_3).abs() < 1e-14);
    }

    /// Gauss–Legendre integrates a degree-(2n-1) polynomial exactly and cos over a period to zero.
    #[test]
    fn gauss_legendre_is_exact_to_its_degree() {
        let q = gauss_legendre(8, -1.0, 2.0);
        let poly: f64 = q.iter().map(|&(x, w)| w * x.powi(15)).sum();
        assert!((poly - (2f64.powi(16) - 1.0) / 16.0).abs() < 1e-9);
        let c: f64 = composite_gauss(4, 20, 0.0, 2.0 * PI).iter().map(|&(x, w)| w * (3.0 * x).cos()).sum();
        assert!(c.abs() < 1e-13);
        assert!((legendre(3, 0.5)[3] - (-0.4375)).abs() < 1e-15);
    }

    /// The Hankel functions equal `j ± i·y` where neither is lost to cancellation (real and
    /// mildly lossy arguments, orders below and above the argument): 1e-12 relative. Where `Im z`
    /// is large (the compressional wave of a lossy wall 0.5 m in radius, `z = 561 + 23i`) every
    /// order to 600, through the turning point, keeps the Wronskians `j·y' - j'·y = 1/z²` and
    /// `j·h' - j'·h = ±i/z²` (to 1e-9 relative to the terms), where `y` and `h^(2)` by their own
    /// forward recurrences were off by 130 % at n = 553; and `h^(1)` keeps its closed form
    /// `e^{-Im z}/|z|` at order 0 where `j + i·y` loses it.
    #[test]
    fn hankels_match_j_plus_i_y_and_survive_loss() {
        for z in [C64::new(3.7, 0.0), C64::new(40.0, 1.5), C64::new(80.0, 0.2)] {
            let (j, y) = spherical_bessel(120, z);
            let (h1, h2) = spherical_hankels(120, z);
            for n in 0..=120 {
                let (a, b) = (j[n] + C64::i() * y[n], j[n] - C64::i() * y[n]);
                assert!((h1[n] - a).norm() <= 1e-12 * a.norm().max(b.norm()), "z {z}, n {n}: {} vs {a}", h1[n]);
                assert!((h2[n] - b).norm() <= 1e-12 * a.norm().max(b.norm()), "z {z}, n {n}: {} vs {b}", h2[n]);
            }
        }
        let z = C64::new(561.0, 23.0);
        let (j, y) = spherical_bessel(601, z);
        let (h1, h2) = spherical_hankels(601, z);
        let [dj, dy, dh1, dh2] = [&j, &y, &h1, &h2].map(|f| derivatives(f, z));
        for n in 0..=600 {
            for (f, df, want) in [(&y, &dy, C64::new(1.0, 0.0)), (&h1, &dh1, C64::i()), (&h2, &dh2, -C64::i())] {
                let w = j[n] * df[n] - dj[n] * f[n];
                let size = (j[n] * df[n]).norm().max((dj[n] * f[n]).norm()) * z.norm_sqr();
                assert!((w * z * z - want).norm() < 1e-9 * size.max(1.0), "n {n}: {} vs {want}", w * z * z);
            }
        }
        // Order 0 in closed form at z = 1000 + 60i: |h^(1)| = e^{-60}/|z|.
        let z = C64::new(1000.0, 60.0);
        let (h1, _) = spherical_hankels(3, z);
        assert!((h1[0].norm() * z.norm() / (-60.0f64).exp() - 1.0).abs() < 1e-12);
        let (s, c) = (z.sin(), z.cos());
        let lost = ((s - C64::i() * c) / z).norm() * z.norm() / (-60.0f64).exp();
        assert!((lost - 1.0).abs() > 0.5, "j + i·y kept h^(1): {lost}");
    }
}

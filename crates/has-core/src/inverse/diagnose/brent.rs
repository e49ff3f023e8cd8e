//! Brent's one-dimensional minimisation, for the field parameters the workflow searches.

/// Brent's minimisation of `f` on `[lo, hi]` to within `tol` (golden sections safeguarding
/// parabolic steps; Brent 1973, ch. 5): a smooth minimum takes 6–10 evaluations. Returns the
/// best point evaluated and its value.
pub(super) fn brent(f: impl Fn(f64) -> f64, lo: f64, hi: f64, tol: f64) -> (f64, f64) {
    let c = 0.5 * (3.0 - 5f64.sqrt());
    let (mut a, mut b) = (lo, hi);
    let mut x = a + c * (b - a);
    let (mut w, mut v) = (x, x);
    let mut fx = f(x);
    let (mut fw, mut fv) = (fx, fx);
    let (mut d, mut e) = (0.0f64, 0.0f64);
    for _ in 0..100 {
        let m = 0.5 * (a + b);
        let tol1 = 0.5 * tol;
        if (x - m).abs() <= 2.0 * tol1 - 0.5 * (b - a) {
            break;
        }
        let mut golden_step = true;
        if e.abs() > tol1 {
            // Parabola through x, w, v.
            let r = (x - w) * (fx - fv);
            let q = (x - v) * (fx - fw);
            let mut p = (x - v) * q - (x - w) * r;
            let mut q = 2.0 * (q - r);
            if q > 0.0 {
                p = -p;
            }
            q = q.abs();
            if p.abs() < (0.5 * q * e).abs() && p > q * (a - x) && p < q * (b - x) {
                e = d;
                d = p / q;
                let u = x + d;
                if u - a < 2.0 * tol1 || b - u < 2.0 * tol1 {
                    d = if x < m { tol1 } else { -tol1 };
                }
                golden_step = false;
            }
        }
        if golden_step {
            e = if x < m { b - x } else { a - x };
            d = c * e;
        }
        let u = if d.abs() >= tol1 { x + d } else { x + tol1.copysign(d) };
        let fu = f(u);
        if fu <= fx {
            if u < x {
                b = x;
            } else {
                a = x;
            }
            (v, fv, w, fw, x, fx) = (w, fw, x, fx, u, fu);
        } else {
            if u < x {
                a = u;
            } else {
                b = u;
            }
            if fu <= fw || w == x {
                (v, fv, w, fw) = (w, fw, u, fu);
            } else if fu <= fv || v == x || v == w {
                (v, fv) = (u, fu);
            }
        }
    }
    (x, fx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn brent_finds_smooth_and_edge_minima() {
        let calls = std::cell::Cell::new(0);
        let (x, fx) = brent(
            |x| {
                calls.set(calls.get() + 1);
                (x - 1.3).powi(2) + 2.0 + 0.1 * (x - 1.3).powi(3)
            },
            -5.0,
            5.0,
            1e-4,
        );
        assert!((x - 1.3).abs() < 1e-4 && (fx - 2.0).abs() < 1e-8, "{x} {fx}");
        assert!(calls.get() < 20, "{} evaluations", calls.get());
        // A minimum at the end of the interval: approached to within the tolerance.
        let (x, _) = brent(|x| x, 0.0, 1.0, 1e-3);
        assert!(x < 2e-3, "{x}");
        // Non-finite values are treated as worse.
        let (x, _) = brent(|x| if x > 0.5 { f64::NAN } else { (x - 0.3).powi(2) }, 0.0, 1.0, 1e-4);
        assert!((x - 0.3).abs() < 1e-3, "{x}");
    }
}

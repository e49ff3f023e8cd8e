//! Small dense linear least squares: the linear parameters of a model (amplitude scale,
//! background planes) projected out of a nonlinear fit (variable projection, Golub & Pereyra 1973).

/// Solves the augmented system `[A | b]` by Gaussian elimination with partial pivoting; None
/// when it is (numerically) singular.
#[allow(clippy::needless_range_loop)] // index loops read as the textbook algorithm
pub fn solve_augmented(mut a: Vec<Vec<f64>>) -> Option<Vec<f64>> {
    let m = a.len();
    let scale = (0..m).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    for c in 0..m {
        let p = (c..m).max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs()))?;
        if !(a[p][c].abs() > 1e-12 * scale) {
            return None;
        }
        a.swap(c, p);
        for r in c + 1..m {
            let f = a[r][c] / a[c][c];
            for k in c..=m {
                a[r][k] -= f * a[c][k];
            }
        }
    }
    let mut x = vec![0.0; m];
    for c in (0..m).rev() {
        x[c] = (a[c][m] - (c + 1..m).map(|k| a[c][k] * x[k]).sum::<f64>()) / a[c][c];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

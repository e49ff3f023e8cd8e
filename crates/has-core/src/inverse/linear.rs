//! Small dense linear algebra: least squares for the linear parameters of a model (amplitude
//! scale, background planes) projected out of a nonlinear fit (variable projection, Golub &
//! Pereyra 1973), and the Cholesky inverse of a posterior precision.

use ndarray::Array2;

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

/// The Cholesky factor `L` (lower triangular, `A = L·Lᵀ`) of a symmetric positive definite
/// matrix (Cholesky–Crout, row by row); None when `A` is not positive definite to working
/// precision.
pub fn cholesky(a: &Array2<f64>) -> Option<Array2<f64>> {
    let n = a.nrows();
    let mut l = Array2::<f64>::zeros((n, n));
    for i in 0..n {
        for j in 0..=i {
            let dot: f64 = {
                let (ri, rj) = (l.row(i), l.row(j));
                ri.iter().zip(rj.iter()).take(j).map(|(x, y)| x * y).sum()
            };
            let v = a[[i, j]] - dot;
            if i == j {
                if !(v > 0.0) {
                    return None;
                }
                l[[i, i]] = v.sqrt();
            } else {
                l[[i, j]] = v / l[[j, j]];
            }
        }
    }
    Some(l)
}

/// The inverse of a symmetric positive definite matrix through its Cholesky factor:
/// `A⁻¹ = L⁻ᵀ·L⁻¹`; None when `A` is not positive definite.
pub fn spd_inverse(a: &Array2<f64>) -> Option<Array2<f64>> {
    let l = cholesky(a)?;
    let n = l.nrows();
    // X = L⁻¹ by forward substitution, column by column of the identity, stored transposed
    // (row c of xt is column c of X) so every inner product runs over contiguous memory.
    let mut xt = Array2::<f64>::zeros((n, n));
    for c in 0..n {
        let mut col = vec![0.0; n];
        for i in c..n {
            let s: f64 = (c..i).map(|k| l[[i, k]] * col[k]).sum();
            col[i] = (if i == c { 1.0 } else { 0.0 } - s) / l[[i, i]];
        }
        xt.row_mut(c).assign(&ndarray::ArrayView1::from(&col));
    }
    // A⁻¹ = Xᵀ·X = xt·xtᵀ.
    Some(xt.dot(&xt.t()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spd_inverse_times_the_matrix_is_the_identity() {
        // A = M·Mᵀ + I for a fixed, well-conditioned M.
        let n = 7;
        let m = Array2::from_shape_fn((n, n), |(i, j)| ((i * 7 + j * 3) % 5) as f64 - 2.0);
        let a = m.dot(&m.t()) + Array2::<f64>::eye(n);
        let l = cholesky(&a).expect("positive definite");
        assert!((l.dot(&l.t()) - &a).iter().all(|v| v.abs() < 1e-10));
        let inv = spd_inverse(&a).expect("positive definite");
        assert!((inv.dot(&a) - Array2::<f64>::eye(n)).iter().all(|v| v.abs() < 1e-10));
        // Not positive definite: refused.
        assert!(cholesky(&(-Array2::<f64>::eye(3))).is_none());
    }
}

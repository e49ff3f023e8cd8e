//! The local searches behind [`Estimator`](super::Estimator): Nelder–Mead restarted with a
//! curvature-shaped simplex, and L-BFGS with the analytic gradient (argmin's solvers).

use super::problem::Problem;
use super::Run;
use crate::error::{HasError, Result};
use crate::inverse::cost::Objective;
use argmin::core::{Executor, Gradient};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::neldermead::NelderMead;
use argmin::solver::quasinewton::LBFGS;
use std::f64::consts::PI;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Nelder–Mead with restarts. The first simplex spans `step` rad along each axis. Nelder–Mead
/// is affine-invariant except for its simplex, and in the long curved valleys of this cost an
/// axis-aligned simplex collapses before the valley floor is reached; so each restart (after
/// a run converges, or after `40·n` iterations) shapes the new simplex by the local curvature:
/// along each eigenvector `v_i` of the Hessian (central differences of the analytic gradient,
/// absolute eigenvalues) a vertex at `x + s_i·v_i`, `s_i = sqrt(2·J(x)/|λ_i|)` clamped to
/// [1e-4, π/2] rad, the distance at which the quadratic model would have used up the cost.
/// Stops when a restart lowers the best cost by less than 0.1 % (or less than `tolerance/100`:
/// with `tolerance` itself, a noise-free fit whose cost is down to 1e-6 can stop tenths of a rad
/// short of the truth with the truth still downhill) or the budget is spent.
pub(super) fn restarted_nelder_mead(
    p: &Problem,
    start: Vec<f64>,
    step: f64,
    tolerance: f64,
    budget: usize,
) -> std::result::Result<(), argmin::core::Error> {
    let n = start.len();
    let mut simplex: Vec<Vec<f64>> = std::iter::once(start.clone())
        .chain((0..n).map(|i| {
            let mut y = start.clone();
            y[i] += step;
            y
        }))
        .collect();
    let mut last = f64::INFINITY;
    loop {
        // Dimension-adaptive coefficients (Gao & Han, Comput Optim Appl 51, 2012): the classic
        // ones stall in 15+ dimensions (argmin caps the contraction at 0.5).
        let nf = n as f64;
        let solver = NelderMead::new(simplex)
            .with_sd_tolerance(tolerance)?
            .with_alpha(1.0)?
            .with_gamma(1.0 + 2.0 / nf)?
            .with_rho(0.5)?
            .with_sigma(1.0 - 1.0 / nf)?;
        let iterations = (40 * n).min(budget) as u64;
        p.lenient.store(n + 1, Ordering::Relaxed);
        Executor::new(p, solver).configure(|s| s.max_iters(iterations)).run()?;
        let (best, x) = p.best();
        if !(best < last * (1.0 - 1e-3) && last - best > 1e-2 * tolerance) {
            return Ok(());
        }
        last = best;
        simplex = curvature_simplex(p, &x, best)?;
    }
}

/// The simplex of [`restarted_nelder_mead`]'s restarts around `x` (cost `cost`).
#[allow(clippy::needless_range_loop)] // index loops read as the matrix algebra
fn curvature_simplex(p: &Problem, x: &[f64], cost: f64) -> std::result::Result<Vec<Vec<f64>>, argmin::core::Error> {
    let n = x.len();
    let h = 1e-4;
    let mut hessian = vec![vec![0.0; n]; n];
    for i in 0..n {
        let mut a = x.to_vec();
        let mut b = x.to_vec();
        a[i] += h;
        b[i] -= h;
        let (ga, gb) = (p.gradient(&a)?, p.gradient(&b)?);
        for j in 0..n {
            hessian[j][i] = (ga[j] - gb[j]) / (2.0 * h);
        }
    }
    for i in 0..n {
        for j in 0..i {
            let m = 0.5 * (hessian[i][j] + hessian[j][i]);
            hessian[i][j] = m;
            hessian[j][i] = m;
        }
    }
    let (values, vectors) = symmetric_eigen(hessian);
    let mut simplex = vec![x.to_vec()];
    for (l, v) in values.iter().zip(&vectors) {
        let s = if l.abs() > 0.0 { (2.0 * cost / l.abs()).sqrt() } else { PI / 2.0 };
        let s = if s.is_finite() { s.clamp(1e-4, PI / 2.0) } else { PI / 2.0 };
        simplex.push(x.iter().zip(v).map(|(xi, vi)| xi + s * vi).collect());
    }
    Ok(simplex)
}

/// Eigenvalues and unit eigenvectors of a symmetric matrix (cyclic Jacobi rotations, Golub &
/// Van Loan §8.5); the vectors are returned as rows.
#[allow(clippy::needless_range_loop)] // index loops read as the textbook algorithm
fn symmetric_eigen(mut a: Vec<Vec<f64>>) -> (Vec<f64>, Vec<Vec<f64>>) {
    let n = a.len();
    let mut v: Vec<Vec<f64>> = (0..n).map(|i| (0..n).map(|j| if i == j { 1.0 } else { 0.0 }).collect()).collect();
    for _sweep in 0..60 {
        let off: f64 = (0..n).flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j))).map(|(i, j)| a[i][j] * a[i][j]).sum();
        let diag: f64 = (0..n).map(|i| a[i][i] * a[i][i]).sum();
        if off <= 1e-30 * diag.max(f64::MIN_POSITIVE) {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                if a[p][q] == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (akp, akq) = (a[k][p], a[k][q]);
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (a[p][k], a[q][k]);
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for row in v.iter_mut() {
                    let (vp, vq) = (row[p], row[q]);
                    row[p] = c * vp - s * vq;
                    row[q] = s * vp + c * vq;
                }
            }
        }
    }
    let values = (0..n).map(|i| a[i][i]).collect();
    let vectors = (0..n).map(|j| (0..n).map(|i| v[i][j]).collect()).collect();
    (values, vectors)
}

pub(super) fn lbfgs_run(
    cost: &dyn Objective,
    x0: Vec<f64>,
    memory: usize,
    budget: usize,
    deadline: Option<Instant>,
    cancel: Option<&AtomicBool>,
) -> Result<Run> {
    let p = Problem::new(cost, x0.clone(), budget, deadline, cancel).with_gradient();
    let solver = LBFGS::new(MoreThuenteLineSearch::new(), memory)
        .with_tolerance_grad(1e-12)
        .and_then(|s| s.with_tolerance_cost(1e-14))
        .map_err(argmin_error)?;
    let outcome = Executor::new(&p, solver).configure(|s| s.param(x0).max_iters(budget as u64)).run().map(|_| ());
    Ok(p.finish(outcome))
}

fn argmin_error(e: argmin::core::Error) -> HasError {
    HasError::invalid("estimator", e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn symmetric_eigen_reconstructs_the_matrix() {
        // A random symmetric 15×15 matrix (seeded): A·v = λ·v and orthonormal vectors to
        // 1e-10 of the largest entry (Jacobi converges to rounding).
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let n = 15;
        let mut a = vec![vec![0.0; n]; n];
        for i in 0..n {
            for j in 0..=i {
                let x: f64 = rng.random_range(-1.0..1.0);
                a[i][j] = x;
                a[j][i] = x;
            }
        }
        let (values, vectors) = symmetric_eigen(a.clone());
        for (l, v) in values.iter().zip(&vectors) {
            for i in 0..n {
                let av: f64 = (0..n).map(|j| a[i][j] * v[j]).sum();
                assert!((av - l * v[i]).abs() < 1e-10, "A·v - λ·v = {}", av - l * v[i]);
            }
        }
        for (i, u) in vectors.iter().enumerate() {
            for (j, w) in vectors.iter().enumerate() {
                let d: f64 = u.iter().zip(w).map(|(x, y)| x * y).sum();
                assert!((d - if i == j { 1.0 } else { 0.0 }).abs() < 1e-10);
            }
        }
    }
}

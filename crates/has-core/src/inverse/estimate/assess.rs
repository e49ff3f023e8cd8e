//! Whether the data decide: rival solutions within the noise margin of the best cost, the focus
//! each would leave after the estimate's correction, the misfit against the noise expectation,
//! and the known phases of the most informative next acquisition.

use super::{centred, phase_error, solvers::lbfgs_run, twin, Estimate, Estimator, Frame, Minimum};
use crate::control::Control;
use crate::error::Result;
use crate::inverse::cost::{ArfiKernel, Model, Objective};
use crate::inverse::prior::{Posterior, MIN_NOISE_RAD};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;

/// A solution that fits the data about as well as the best one (a rival of the estimate, e.g.
/// its twin).
#[derive(Debug, Clone, PartialEq)]
pub struct RivalSolution {
    /// The rival's phases (rad), zero circular mean.
    pub phases: Vec<f64>,
    /// Its cost.
    pub cost: f64,
    /// Focal ARFI of the beam corrected with the best estimate if this candidate were the truth,
    /// relative to the ideal focus (the model's prediction).
    pub predicted_recovery: f64,
}

/// Whether the data decide between clearly different solutions.
#[derive(Debug, Clone)]
pub struct Assessment {
    /// True when some solution within the noise margin would leave less than `threshold` of
    /// the ideal focus after the best estimate's correction.
    pub ambiguous: bool,
    /// Cost margin of the rivals: `sigma²·chi²_0.95(G - 1)` (rad²) on the images alone,
    /// `chi²_0.95(G)/2` on a posterior (negative log posterior).
    pub margin: f64,
    /// The distinct solutions within the margin, the best estimate among them.
    pub candidates: Vec<RivalSolution>,
    /// The smallest `predicted_recovery` over the candidates (1 when there is one).
    pub worst_recovery: f64,
    /// Known group phases (rad) to add for one more acquisition that best separates the
    /// candidates.
    pub suggested_phases: Vec<f64>,
    /// That separation: the smallest squared image difference between candidates, in units of
    /// sigma².
    pub suggested_separation: f64,
    /// The best cost over its expectation under the model, `J / (n_pixels·sigma²)` (about 1
    /// when the model explains the data down to the noise; `sigma` at least 1e-4 rad).
    pub misfit: f64,
    /// The best cost lies above the 95 % point of `sigma²·chi²(n_pixels - G + 1)`: the model
    /// cannot explain the images (e.g. element-level aberrations fitted with group phases), and
    /// a correction from it may make the focus worse.
    pub mismatch: bool,
}

pub use crate::numeric::chi2_95;

impl Estimate {
    /// Looks for clearly different solutions that fit within the noise: the end points of every
    /// start, a 24-start L-BFGS exploration of its own (from the estimate, random points and
    /// twins) and the refined twin of the estimate; each within the chi² margin of the best cost
    /// (`sigma²·chi²_0.95(G - 1)`) is a candidate, scored by the focus its truth would leave after
    /// the estimate's correction.
    pub fn assess(&self, model: &Model, sigma: Option<&[usize]>, threshold: f64, seed: u64) -> Result<Assessment> {
        let margin = model.noise.powi(2) * chi2_95(model.cost.n_groups - 1);
        self.assess_on(&model.cost, margin, model, sigma, threshold, seed)
    }

    /// [`Estimate::assess`] judged on the posterior of a prior (an estimate made with
    /// [`Posterior`]): the candidates are the solutions within `chi²_0.95(G)/2` of the smallest
    /// negative log posterior, so a twin the prior rules out is no rival.
    pub fn assess_posterior(
        &self,
        posterior: &Posterior,
        model: &Model,
        sigma: Option<&[usize]>,
        threshold: f64,
        seed: u64,
    ) -> Result<Assessment> {
        self.assess_on(posterior, 0.5 * chi2_95(model.cost.n_groups), model, sigma, threshold, seed)
    }

    /// The assessment on `objective` (the image cost of `model`, or a posterior over it) with
    /// rivals within `margin` of its best value.
    fn assess_on(
        &self,
        objective: &dyn Objective,
        margin: f64,
        model: &Model,
        sigma: Option<&[usize]>,
        threshold: f64,
        seed: u64,
    ) -> Result<Assessment> {
        let g = model.cost.n_groups;
        let mut points: Vec<Minimum> = self.minima.clone();
        points.push(Minimum { phases: self.phases.clone(), cost: self.cost });
        // An exploration of its own, whatever method produced the estimate: L-BFGS from the
        // estimate, its twin and seeded random starts.
        let explore = Estimator::lbfgs()
            .with_starts(12)?
            .with_twins(sigma.map(<[usize]>::to_vec))
            .with_seed(seed)
            .with_start(self.phases.clone())?
            .run(objective, Control::default())?;
        points.extend(explore.minima);
        if let Some(sig) = sigma {
            let frame = Frame::of(objective);
            let run = lbfgs_run(objective, frame.search(&twin(&self.phases, sig)), 10, 3000, None, None)?;
            points.push(Minimum { phases: frame.report(&run.params), cost: run.cost });
        }
        let (candidates, worst_recovery) = rival_solutions(&points, margin, &self.phases, |phases| focal(&model.base, phases))?;
        let (suggested_phases, suggested_separation) = propose_diversity(model, &candidates, 64, seed)?;
        // The best image fit among the plausible solutions (with images alone: the best cost).
        let fit = candidates.iter().map(|c| model.cost.cost(&c.phases)).fold(f64::INFINITY, f64::min);
        let (misfit, mismatch) = misfit(fit, model.cost.n_pixels(), g - 1, model.noise);
        Ok(Assessment {
            ambiguous: worst_recovery < threshold,
            margin,
            candidates,
            worst_recovery,
            suggested_phases,
            suggested_separation,
            misfit,
            mismatch,
        })
    }
}

/// The distinct solutions among `points` whose cost lies within `margin` of the best (one per
/// cluster of RMS phase difference under 0.05 rad, the first found), each scored by the focus
/// the `estimate`'s correction would leave were it the truth, `focus(p - estimate) / focus(0)`
/// (`focus`: the largest value of the model's image for phases), and the smallest such score
/// (1 when there is none).
pub fn rival_solutions(
    points: &[Minimum],
    margin: f64,
    estimate: &[f64],
    focus: impl Fn(&[f64]) -> Result<f64>,
) -> Result<(Vec<RivalSolution>, f64)> {
    let best = points.iter().map(|p| p.cost).fold(f64::INFINITY, f64::min);
    let ideal = focus(&vec![0.0; estimate.len()])?;
    let mut candidates: Vec<RivalSolution> = Vec::new();
    for p in points.iter().filter(|p| p.cost <= best + margin) {
        if candidates.iter().any(|c| phase_error(&c.phases, &p.phases) < 0.05) {
            continue;
        }
        let residual: Vec<f64> = p.phases.iter().zip(estimate).map(|(t, e)| t - e).collect();
        let predicted_recovery = focus(&residual)? / ideal;
        candidates.push(RivalSolution { phases: p.phases.clone(), cost: p.cost, predicted_recovery });
    }
    let worst = candidates.iter().map(|c| c.predicted_recovery).fold(1.0, f64::min);
    Ok((candidates, worst))
}

/// Misfit above which an unexplained residual counts as a model mismatch, however significant
/// statistically: below it the residual the model leaves has an RMS under √0.2 ≈ 0.45 of the
/// noise, and acts on the fitted phases at most as extra noise of that RMS would (their error
/// grows by at most √1.2 - 1 ≈ 10 %). Real images always hold some such residual (a CT's
/// transmissions, a slightly wrong width), and with thousands of pixels the chi² test alone
/// would flag it every time.
pub const MATERIAL_MISFIT: f64 = 1.2;

/// The misfit of an image cost `fit` (rad²) over `n` pixels with `k` parameters fitted and
/// noise `noise` (rad, at least 1e-4): `J / (n·sigma²)`, and whether the model cannot explain
/// the images: `J` above the 95 % point of `sigma²·chi²(n - k)` and the misfit above
/// `MATERIAL_MISFIT`.
pub fn misfit(fit: f64, n: usize, k: usize, noise: f64) -> (f64, bool) {
    let sigma2 = noise.max(MIN_NOISE_RAD).powi(2);
    let misfit = fit / (n as f64 * sigma2);
    (misfit, fit > sigma2 * chi2_95(n.saturating_sub(k).max(1)) && misfit > MATERIAL_MISFIT)
}

/// The largest value of the kernel's image (the focal ARFI) for group phases.
fn focal(kernel: &ArfiKernel, phases: &[f64]) -> Result<f64> {
    Ok(kernel.image(phases)?.iter().copied().fold(f64::MIN, f64::max))
}

/// Among `tries` seeded random group-phase patterns, the one whose added image best separates the candidates: it
/// maximises the smallest `Σ (d_a - d_b)² / sigma²` over candidate pairs.
pub fn propose_diversity(model: &Model, candidates: &[RivalSolution], tries: usize, seed: u64) -> Result<(Vec<f64>, f64)> {
    let g = model.cost.n_groups;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_d17e);
    let sigma2 = model.noise.powi(2).max(1e-30);
    let mut best = (vec![0.0; g], f64::NEG_INFINITY);
    for _ in 0..tries.max(1) {
        let d: Vec<f64> = (0..g).map(|_| rng.random_range(-PI..PI)).collect();
        let images = candidates
            .iter()
            .map(|c| model.base.image(&c.phases.iter().zip(&d).map(|(p, q)| p + q).collect::<Vec<_>>()))
            .collect::<Result<Vec<_>>>()?;
        let mut sep = f64::INFINITY;
        for a in 0..images.len() {
            for b in a + 1..images.len() {
                sep = sep.min((&images[a] - &images[b]).iter().map(|x| x * x).sum::<f64>() / sigma2);
            }
        }
        if images.len() < 2 {
            sep = 0.0;
        }
        if sep > best.1 {
            best = (d, sep);
        }
    }
    Ok((centred(&best.0), best.1))
}

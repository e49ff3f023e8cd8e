//! Which phases to apply: the estimate, or a safer alternative when the images do not support it.
//!
//! Per element without a prior the question is what the images determine. Pixels are no measure
//! of it: a focal spot blurred by the beam and the broadening W is a few tens of resolution cells
//! per image, and its pixels repeat them. What counts is the information the images hold about
//! the phases, linearised at the estimate (`information`: `F = Σ_k J_kᵀ·J_k/sigma²`). With no
//! prior, nothing but the images constrains a phase, so the spread before the images is that of a
//! uniform phase, independent per element (`s = pi/sqrt(3)`), and the posterior covariance is
//! `C = (F + I/s²)⁻¹`. Two numbers follow:
//!
//! - the *determined phases*, `d = tr(F·C) = Σ λ/(λ + 1)` over the eigenvalues `λ` of `s²·F`: the
//!   number of independent combinations of phases the images pin below their prior spread (the
//!   degrees of freedom for signal of Rodgers, *Inverse Methods for Atmospheric Sounding*, 2000,
//!   eq. 2.80). Four images of the default phantom at 0.02 rad determine about 50 of 1024;
//! - the *expected focus* of the estimate's correction, `E[f]` of the information module, for a
//!   truth drawn from that posterior: each undetermined combination costs focus as an unknown
//!   phase does.
//!
//! The alternatives are judged on the model at the estimate, which fits the images: the
//! uncorrected focus (zero phases; an in-focus image without known phases measures it directly,
//! within its noise) and the focus the default-group fit (the warm start) leaves. The estimate is
//! supported when its expected focus reaches both and its search converged. Otherwise the
//! recommendation is the uncorrected beam, or the group fit where the model puts it clearly above
//! the uncorrected one ([`GROUPS_MARGIN`]).
//!
//! The expected focus is a conservative measure: where the search did not move a phase the
//! estimate keeps its smooth warm start, which on a smooth aberration is better than a random
//! phase. It is taken at face value because the optimistic alternative fails: with the smooth
//! spread of the suggestion (`Spread::for_prior(None, ..)`) the same four images give an expected
//! focus of about 0.83, where the estimates left 0.14–0.55 of the ideal focus and, on most seeds,
//! less than no correction. Near a corrected focus the focal height is stationary in the phases and
//! the linearisation misses what it tells (see the posterior assessment with a prior); the images
//! here are of the aberrated beam, whose image changes to first order with every phase.

use crate::error::Result;
use crate::inverse::element::ElementCost;
use crate::inverse::estimate::information::{error_covariance, expected_focus, fisher, focal_fields, Spread, UNIFORM_PHASE_STD};
use crate::inverse::estimate::Stop;
use crate::inverse::prior::MIN_NOISE_RAD;

/// Which phases the estimate recommends applying (subtracting).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Recommended {
    /// The estimate's phases.
    Estimate,
    /// No correction: zero phases.
    Uncorrected,
    /// The default-group fit spread to the elements (per element without a prior).
    Groups,
    /// The prior's prediction, as given.
    Prediction,
}

impl Recommended {
    /// The name reports and the JSON use.
    pub fn name(&self) -> &'static str {
        match self {
            Recommended::Estimate => "estimate",
            Recommended::Uncorrected => "uncorrected",
            Recommended::Groups => "groups",
            Recommended::Prediction => "prediction",
        }
    }
}

/// The phases to apply and which they are.
#[derive(Debug, Clone, PartialEq)]
pub struct Recommendation {
    /// Which phases.
    pub kind: Recommended,
    /// The phases (rad): one per phase of the estimate, or the prediction as given.
    pub phases: Vec<f64>,
}

/// What the images determine of a per-element estimate without a prior, and the focus of the
/// alternatives (see the module docs). Foci are relative to the ideal focus.
#[derive(Debug, Clone, PartialEq)]
pub struct Support {
    /// Independent combinations of phases the images determine, `tr(F·C)`.
    pub determined_phases: f64,
    /// Expected focus after the estimate's correction on its linearised posterior.
    pub expected_focus: f64,
    /// The uncorrected beam's focus on the model at the estimate.
    pub uncorrected_focus: f64,
    /// The focus after the default-group fit's correction on the model at the estimate.
    pub groups_focus: f64,
    /// The search converged (it did not stop at its evaluation or time limit).
    pub converged: bool,
}

/// How much more focus (of the ideal) the model must give the group fit than the uncorrected beam
/// for the group fit to be the recommendation. The model at an estimate the images do not
/// support predicts the group fit's focus loosely: on skull-like screens (1024 elements, four
/// images at 0.02 rad) it erred by up to 0.19 of the ideal, while it predicted the uncorrected
/// focus (which the in-focus image shows) within 0.04.
pub const GROUPS_MARGIN: f64 = 0.2;

impl Support {
    /// Whether the images determine the estimate well enough for its correction to be expected
    /// to leave at least the focus of the alternative that would be recommended instead
    /// ([`Support::alternative`]): rejecting it for another would not apply that other.
    pub fn determines(&self) -> bool {
        let instead = match self.alternative() {
            Recommended::Groups => self.groups_focus,
            _ => self.uncorrected_focus,
        };
        self.expected_focus >= instead
    }

    /// Whether the estimate is the one to apply: determined and converged.
    pub fn supported(&self) -> bool {
        self.determines() && self.converged
    }

    /// The safer alternative when the estimate is not supported: the group fit when the model
    /// puts it [`GROUPS_MARGIN`] above the uncorrected beam, else the uncorrected beam.
    pub fn alternative(&self) -> Recommended {
        if self.groups_focus > self.uncorrected_focus + GROUPS_MARGIN {
            Recommended::Groups
        } else {
            Recommended::Uncorrected
        }
    }
}

/// Whether a search that stopped so converged (a kept prediction ran none and needs none).
pub fn converged(stop: Stop) -> bool {
    matches!(stop, Stop::Converged | Stop::PredictionKept)
}

/// The support of a per-element estimate `phases` made without a prior from `cost`'s images
/// (noise `noise`, rad), against the uncorrected beam and the default-group fit `groups` (per
/// element); `stop` is how its search ended.
pub fn element_support(cost: &ElementCost, noise: f64, phases: &[f64], groups: &[f64], stop: Stop) -> Result<Support> {
    let f = fisher(cost, phases, noise.max(MIN_NOISE_RAD))?;
    let c = error_covariance(&f, &Spread::Independent(UNIFORM_PHASE_STD))?;
    let determined_phases: f64 = f.iter().zip(c.iter()).map(|(a, b)| a * b).sum();
    let expected = expected_focus(&c, &focal_fields(&cost.basis))?;
    let peak = |p: &[f64]| -> Result<f64> { Ok(cost.basis.image(p)?.iter().copied().filter(|v| v.is_finite()).fold(f64::MIN, f64::max)) };
    let ideal = peak(&vec![0.0; phases.len()])?;
    let residual: Vec<f64> = phases.iter().zip(groups).map(|(e, g)| e - g).collect();
    Ok(Support {
        determined_phases,
        expected_focus: expected,
        uncorrected_focus: peak(phases)? / ideal,
        groups_focus: peak(&residual)? / ideal,
        converged: converged(stop),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn support(expected: f64, uncorrected: f64, groups: f64, converged: bool) -> Support {
        Support { determined_phases: 50.0, expected_focus: expected, uncorrected_focus: uncorrected, groups_focus: groups, converged }
    }

    #[test]
    fn the_estimate_is_supported_only_when_determined_and_converged() {
        assert!(support(0.9, 0.5, 0.6, true).supported());
        assert!(!support(0.9, 0.5, 0.6, false).supported());
        assert!(support(0.9, 0.5, 0.6, false).determines());
        assert!(!support(0.05, 0.5, 0.3, true).supported());
        // Judged against the alternative it would give way to: the uncorrected beam here (the
        // group fit is not clearly above it), which the estimate beats; the group fit there.
        assert!(support(0.55, 0.5, 0.6, true).supported());
        assert!(!support(0.55, 0.3, 0.6, true).supported());
    }

    #[test]
    fn the_group_fit_is_the_alternative_only_clearly_above_the_uncorrected_beam() {
        assert_eq!(support(0.05, 0.45, 0.41, true).alternative(), Recommended::Uncorrected);
        assert_eq!(support(0.05, 0.45, 0.6, true).alternative(), Recommended::Uncorrected);
        assert_eq!(support(0.05, 0.3, 0.6, true).alternative(), Recommended::Groups);
        assert!(converged(Stop::Converged) && converged(Stop::PredictionKept));
        assert!(!converged(Stop::EvaluationLimit) && !converged(Stop::TimeLimit) && !converged(Stop::Interrupted));
    }
}

//! What per-element MR-ARFI acquisitions tell about the aberration, and which one to take next:
//! the linearised (Laplace) posterior of the element phases.
//!
//! Near phases `phi` every image is linear in the phase error `delta`: `d_k ≈ d_k(phi) + J_k·delta`
//! with, for element `e` and pixel `i` (basis `B`, drives `v_e = exp(i·(phi_e + o_k,e))`, fields
//! `p = B·v`, sampler `S`, amplitude `A`),
//!
//! `J_k[i, e] = A·Σ_s S_is·∂|p_s|²/∂phi_e`,  `∂|p_s|²/∂phi_e = -2·Im(conj(p_s)·B_se·v_e)`.
//!
//! With white noise `sigma` on the masked pixels the Fisher information is
//! `F = Σ_k J_kᵀ·J_k/sigma²`. A Gaussian prior on the error gives the posterior covariance
//! `C = (F + I/s²)⁻¹` for independent errors of std `s`, and `C = W·(I + Wᵀ·F·W)⁻¹·Wᵀ` for the
//! smooth error modes `W` of [`crate::inverse::prior::smooth`] (what such an estimate can move).
//! Without a prior the errors are taken as a smooth field of the spread of uniform phases,
//! `pi/sqrt(3)` ([`Spread::for_prior`]).
//!
//! If the truth is drawn from that posterior about the estimate, the correction leaves the focal
//! intensity (the focal ARFI) relative to the ideal
//!
//! `E[f] = Σ_mn b_m·conj(b_n)·exp(-(C_mm + C_nn - 2·C_mn)/2) / |Σ_n b_n|²`,
//!
//! `b_n` the element's field at the ideal focus (exact for Gaussian errors). The next
//! acquisition suggested is the focus shift (defocus diversity, Gonsalves 1982) whose image,
//! predicted at the estimate with its own focal-zone mask, raises `E[f]` most: the design that
//! most reduces the uncertainty of the focus rather than of all phases alike.
//!
//! The linearisation ignores twins and other distant rivals, and the linear nuisance
//! (amplitude scale, background planes) is taken as known.

use crate::error::{HasError, Result};
use crate::inverse::cost::mask_pixels;
use crate::inverse::element::{ElementCost, FieldBasis};
use crate::inverse::linear::spd_inverse;
use crate::inverse::prior::smooth::{error_modes, SmoothErrors};
use crate::inverse::prior::Prior;
use crate::simulation::Simulation;
use ndarray::Array2;
use num_complex::Complex64 as C64;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Std (rad) of a phase uniform on a 2·pi interval: the spread without a prior.
pub const UNIFORM_PHASE_STD: f64 = PI / 1.732_050_807_568_877_2;

/// Correlation length (m) of the phase error assumed without a prior: that of the skull-like
/// screens ([`crate::physics::aberration::SkullScreen`]), whose thickness and speed vary over
/// centimetres.
pub const UNINFORMED_LENGTH: f64 = 12e-3;

/// Elements per block when forming the Jacobian (contiguous reads of the basis rows).
const BLOCK: usize = 32;

/// Focus shifts (mm, x y z in the transducer frame) tried for the next acquisition: the focus
/// moved along the beam axis (defocus) or across it, and the in-focus image repeated.
pub const CANDIDATE_SHIFTS_MM: [[f64; 3]; 15] = [
    [0.0, 0.0, 0.0],
    [0.0, 0.0, 5.0],
    [0.0, 0.0, -5.0],
    [0.0, 0.0, 10.0],
    [0.0, 0.0, -10.0],
    [0.0, 0.0, 15.0],
    [0.0, 0.0, -15.0],
    [0.0, 0.0, 20.0],
    [0.0, 0.0, -20.0],
    [3.0, 0.0, 0.0],
    [-3.0, 0.0, 0.0],
    [0.0, 3.0, 0.0],
    [0.0, -3.0, 0.0],
    [3.0, 3.0, 10.0],
    [-3.0, -3.0, -10.0],
];

/// The prior spread of the phase error the posterior is formed with.
#[derive(Debug, Clone)]
pub enum Spread {
    /// Independent errors of this std (rad), e.g. an independent prior's.
    Independent(f64),
    /// Smooth error modes, with a prior's modes of known shape (one vector over the elements per
    /// mode, coefficients N(0, 1)).
    Smooth(Vec<Vec<f64>>),
}

impl Spread {
    /// The spread of an estimate's phase error before the images: a smooth prior's error modes,
    /// an independent prior's std, and without a prior phases of [`UNIFORM_PHASE_STD`]
    /// correlated over [`UNINFORMED_LENGTH`] (independent when the array is too small for
    /// that length's modes). `positions`: one per phase (m).
    pub fn for_prior(prior: Option<&Prior>, positions: &[[f64; 3]]) -> Result<Spread> {
        match prior {
            Some(p) => match p.correlation_length() {
                Some(_) => Ok(Spread::Smooth(SmoothErrors::new(p, positions)?.into_modes())),
                None => Ok(Spread::Independent(p.std_rad())),
            },
            None => {
                Ok(error_modes(positions, UNIFORM_PHASE_STD, UNINFORMED_LENGTH)
                    .map_or(Spread::Independent(UNIFORM_PHASE_STD), Spread::Smooth))
            }
        }
    }
}

/// The Jacobian (pixels x elements, rad per rad) of one image's model values at box pixels
/// `pixels` (indices into the cost's pixel box) with respect to the element phases, at `phases`
/// with known per-element phases `offset` added.
pub fn image_jacobian(cost: &ElementCost, phases: &[f64], offset: &[f64], pixels: &[usize]) -> Result<Array2<f64>> {
    let b = &cost.basis;
    let (g, n_s) = (b.n_elements(), b.n_samples());
    if phases.len() != g || offset.len() != g {
        return Err(HasError::invalid("phases", format!("need {g} values, one per element")));
    }
    let n_box = cost.sampler().pixels[0].len() * cost.sampler().pixels[1].len();
    if let Some(p) = pixels.iter().find(|&&p| p >= n_box) {
        return Err(HasError::invalid("pixels", format!("index {p} is outside the pixel box of {n_box}")));
    }
    let (vr, vi) = FieldBasis::drives(phases, &[offset]);
    let (pr, pi) = b.fields(&vr, &vi);
    let amp = b.amplitude;
    let blocks: Vec<Result<Vec<Vec<f64>>>> = (0..g)
        .step_by(BLOCK)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|e0| {
            let e1 = (e0 + BLOCK).min(g);
            let mut q = vec![vec![0.0; n_s]; e1 - e0];
            for s in 0..n_s {
                let (p_r, p_i) = (f64::from(pr[[s, 0]]), f64::from(pi[[s, 0]]));
                for e in e0..e1 {
                    let (br, bi) = (f64::from(b.re[[s, e]]), f64::from(b.im[[s, e]]));
                    let (cr, ci) = (f64::from(vr[[e, 0]]), f64::from(vi[[e, 0]]));
                    // x = B_se·v_e; ∂|p|²/∂phi_e = -2·Im(conj(p)·x).
                    let (xr, xi) = (br * cr - bi * ci, br * ci + bi * cr);
                    q[e - e0][s] = -2.0 * (p_r * xi - p_i * xr);
                }
            }
            q.iter()
                .map(|col| {
                    let img = cost.sampler().apply(col)?;
                    let flat = img.as_slice().ok_or_else(|| HasError::invalid("image", "not contiguous"))?;
                    Ok(pixels.iter().map(|&p| amp * flat[p]).collect())
                })
                .collect()
        })
        .collect();
    let mut j = Array2::<f64>::zeros((pixels.len(), g));
    let mut e = 0;
    for block in blocks {
        for col in block? {
            for (i, v) in col.into_iter().enumerate() {
                j[[i, e]] = v;
            }
            e += 1;
        }
    }
    Ok(j)
}

/// `Jᵀ·J/sigma²` of a Jacobian (elements x elements).
fn information(j: &Array2<f64>, noise: f64) -> Array2<f64> {
    j.t().dot(j) / (noise * noise)
}

/// The Fisher information (elements x elements, 1/rad²) of the cost's images at `phases`, on their
/// masked pixels, with white noise `noise` (rad).
pub fn fisher(cost: &ElementCost, phases: &[f64], noise: f64) -> Result<Array2<f64>> {
    require_noise(noise)?;
    let g = cost.basis.n_elements();
    let mut f = Array2::<f64>::zeros((g, g));
    for t in &cost.terms {
        f += &information(&image_jacobian(cost, phases, &t.offset, &t.mask)?, noise);
    }
    Ok(f)
}

fn require_noise(noise: f64) -> Result<()> {
    if noise.is_finite() && noise > 0.0 {
        Ok(())
    } else {
        Err(HasError::invalid("noise_rad", format!("must be positive and finite, got {noise}")))
    }
}

/// The posterior covariance of the phase error (elements x elements, rad²) for Fisher
/// information `fisher` and prior `spread` (see the module docs).
pub fn error_covariance(fisher: &Array2<f64>, spread: &Spread) -> Result<Array2<f64>> {
    let g = fisher.nrows();
    let singular = || HasError::invalid("prior_std_rad", "the posterior precision is not positive definite");
    match spread {
        Spread::Independent(s) => {
            if !(s.is_finite() && *s > 0.0) {
                return Err(HasError::invalid("prior_std_rad", format!("must be positive and finite, got {s}")));
            }
            let precision = fisher + &(Array2::<f64>::eye(g) / (s * s));
            spd_inverse(&precision).ok_or_else(singular)
        }
        Spread::Smooth(modes) => {
            if modes.iter().any(|m| m.len() != g) {
                return Err(HasError::invalid("prior", format!("error modes must have {g} values each")));
            }
            let w = Array2::from_shape_fn((g, modes.len()), |(e, m)| modes[m][e]);
            let precision = w.t().dot(fisher).dot(&w) + Array2::<f64>::eye(modes.len());
            Ok(w.dot(&spd_inverse(&precision).ok_or_else(singular)?).dot(&w.t()))
        }
    }
}

/// The expected focal intensity relative to the ideal, `E|Σ b·exp(i·delta)|² / |Σ b|²`, for a
/// Gaussian phase error `delta` of zero mean and covariance `cov`, elements weighted by their
/// fields `b` at the focus.
pub fn expected_focus(cov: &Array2<f64>, b: &[C64]) -> Result<f64> {
    let g = b.len();
    if cov.dim() != (g, g) {
        return Err(HasError::invalid("covariance", format!("is {:?}, expected {g} x {g}", cov.dim())));
    }
    let norm = b.iter().sum::<C64>().norm_sqr();
    if !(norm > 0.0) {
        return Err(HasError::invalid("focus", "the elements' fields at the focus sum to zero"));
    }
    // Row sums in parallel, added in order: the same value for any number of threads.
    let rows: Vec<f64> = (0..g)
        .into_par_iter()
        .map(|m| {
            (0..g)
                .map(|n| {
                    let var = cov[[m, m]] + cov[[n, n]] - 2.0 * cov[[m, n]];
                    (b[m] * b[n].conj()).re * (-0.5 * var).exp()
                })
                .sum::<f64>()
        })
        .collect();
    let total: f64 = rows.iter().sum();
    Ok(total / norm)
}

/// Every element's field (Pa per unit drive) at the window sample of the ideal focus (the
/// sample where the fields with steering alone add up the most).
pub fn focal_fields(basis: &FieldBasis) -> Vec<C64> {
    let zero = vec![0.0; basis.n_elements()];
    let (vr, vi) = FieldBasis::drives(&zero, &[&zero]);
    let (pr, pi) = basis.fields(&vr, &vi);
    let power = |s: usize| f64::from(pr[[s, 0]]).powi(2) + f64::from(pi[[s, 0]]).powi(2);
    let focus = (0..basis.n_samples()).max_by(|&a, &b| power(a).total_cmp(&power(b))).unwrap_or(0);
    (0..basis.n_elements()).map(|e| C64::new(f64::from(basis.re[[focus, e]]), f64::from(basis.im[[focus, e]]))).collect()
}

/// One candidate for the next acquisition and the focus it is expected to leave.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// The focus shift (m, x y z).
    pub shift: [f64; 3],
    /// Expected focal ARFI after the correction from all images and this one, relative to the
    /// ideal.
    pub expected_focus: f64,
}

/// The next acquisition for a per-element estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct ShiftSuggestion {
    /// The focus shift (m, x y z) to image with next.
    pub shift: [f64; 3],
    /// Its known per-element phases (rad; [`Simulation::focus_shift_phases`]).
    pub known: Vec<f64>,
    /// Expected focal ARFI relative to the ideal after the correction from the images so far.
    pub expected_focus_now: f64,
    /// The same with the suggested image added.
    pub expected_focus: f64,
    /// Every candidate tried, best first.
    pub candidates: Vec<Candidate>,
}

/// Tries each focus shift in `shifts_m` (m) as the next acquisition for the estimate `phases`
/// made from `cost`'s images (noise `noise`, rad) with prior `spread`, and returns the one that
/// raises the expected focus most (see the module docs).
pub fn suggest_focus_shift(
    sim: &Simulation,
    cost: &ElementCost,
    phases: &[f64],
    noise: f64,
    spread: &Spread,
    shifts_m: &[[f64; 3]],
) -> Result<ShiftSuggestion> {
    if shifts_m.is_empty() {
        return Err(HasError::invalid("shifts", "need at least one candidate focus shift"));
    }
    let now = fisher(cost, phases, noise)?;
    let b = focal_fields(&cost.basis);
    let expected_focus_now = expected_focus(&error_covariance(&now, spread)?, &b)?;
    let box_ = &cost.sampler().pixels;
    let nv = box_[1].len();
    let region = sim.focal_region().slice(ndarray::s![box_[0].clone(), box_[1].clone()]).to_owned();
    let mut candidates = Vec::with_capacity(shifts_m.len());
    for &shift in shifts_m {
        let offset = sim.focus_shift_phases(shift)?;
        let image = cost.predicted_image(phases, &offset)?;
        let mask: Vec<usize> = mask_pixels(&image, sim.mask_fraction, &region).iter().map(|&(i, j)| i * nv + j).collect();
        let added = information(&image_jacobian(cost, phases, &offset, &mask)?, noise);
        let expected = expected_focus(&error_covariance(&(&now + &added), spread)?, &b)?;
        candidates.push(Candidate { shift, expected_focus: expected });
    }
    candidates.sort_by(|a, b| b.expected_focus.total_cmp(&a.expected_focus));
    let best = candidates[0].shift;
    Ok(ShiftSuggestion {
        shift: best,
        known: sim.focus_shift_phases(best)?,
        expected_focus_now,
        expected_focus: candidates[0].expected_focus,
        candidates,
    })
}

//! Nuisance parameters of the MR-ARFI image fitted jointly with per-element phases: what an
//! independent measurement differs in besides the aberration (found with the
//! model-discrepancy workflow, [`crate::inverse::diagnose`], whose effect names they share).
//!
//! - `amplitude`: one scale on the force-to-phase amplitude for all images;
//! - `background_phase`: per image, a constant plus a linear ramp `b0 + bu·u + bv·v` (u, v the
//!   pixel centres in mm): each acquisition has its own drift;
//! - `broadening`: the width W of the Gaussian broadening (paper Eq. 2–3);
//! - `registration_shift`: an in-plane offset of the images against the model.
//!
//! The scale and the background enter the image linearly and are solved by least squares inside
//! every cost evaluation (variable projection: the phase gradient at the projected optimum is the
//! gradient with them held fixed). W and the shift change the sampling of the recorded
//! `|p|²`: they are fitted by Nelder–Mead with the phases held, alternating with the phase search
//! ([`crate::inverse::element::view_fit::fit_view`]); each of their evaluations re-samples fixed `|p|²` (no matrix products over
//! the element basis).

use crate::error::{HasError, Result};

/// Largest broadening width fitted, as a multiple of the model's (and at least the model's plus
/// [`WIDTH_REACH_MIN_MM`]): the element basis records the window this reach needs.
pub const WIDTH_REACH_FACTOR: f64 = 1.5;
/// Smallest reach above the model's broadening width (mm).
pub const WIDTH_REACH_MIN_MM: f64 = 1.0;
/// Largest registration shift fitted along each image axis (mm).
pub const SHIFT_REACH_MM: f64 = 2.0;

/// Which nuisance parameters to fit.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Nuisance {
    /// One amplitude scale for all images.
    pub amplitude: bool,
    /// The broadening width W.
    pub broadening: bool,
    /// An in-plane registration shift (u, v).
    pub registration_shift: bool,
    /// A background plane per image.
    pub background_phase: bool,
}

impl Nuisance {
    /// The names accepted, in the order reported: the model-discrepancy workflow's names of the
    /// same effects (`diagnose::Effect::name`; a test there holds them equal).
    pub const NAMES: [&'static str; 4] = ["amplitude", "broadening", "registration_shift", "background_phase"];

    /// Every nuisance parameter.
    pub fn all() -> Self {
        Nuisance { amplitude: true, broadening: true, registration_shift: true, background_phase: true }
    }

    /// Parses effect names (those of [`Nuisance::NAMES`], or `"all"`); an unknown name is an error
    /// naming `fit_nuisance`.
    pub fn parse<S: AsRef<str>>(names: &[S]) -> Result<Self> {
        let mut n = Nuisance::default();
        for name in names {
            let name = name.as_ref();
            if name == "all" {
                n = Nuisance::all();
            } else if let Some(k) = Nuisance::NAMES.iter().position(|&known| known == name) {
                *n.flags_mut()[k] = true;
            } else {
                return Err(HasError::invalid(
                    "fit_nuisance",
                    format!("unknown nuisance parameter \"{name}\"; expected some of {} or \"all\"", Nuisance::NAMES.join(", ")),
                ));
            }
        }
        Ok(n)
    }

    /// The switches in [`Nuisance::NAMES`] order.
    fn flags_mut(&mut self) -> [&mut bool; 4] {
        [&mut self.amplitude, &mut self.broadening, &mut self.registration_shift, &mut self.background_phase]
    }

    /// The names of the parameters fitted, in [`Nuisance::NAMES`] order.
    pub fn names(&self) -> Vec<&'static str> {
        let on = [self.amplitude, self.broadening, self.registration_shift, self.background_phase];
        Nuisance::NAMES.iter().zip(on).filter(|(_, o)| *o).map(|(n, _)| *n).collect()
    }

    /// Whether anything is fitted.
    pub fn any(&self) -> bool {
        !self.names().is_empty()
    }

    /// Whether the view (W or the shift) is fitted: the basis then records a wider window.
    pub fn view(&self) -> bool {
        self.broadening || self.registration_shift
    }

    /// Only the view parameters (W, shift) of these: what the element basis' window depends on.
    pub fn views(&self) -> Nuisance {
        Nuisance { broadening: self.broadening, registration_shift: self.registration_shift, ..Nuisance::default() }
    }

    /// The broadening width (m) whose window covers every view fitted from a model width `width`
    /// (m): [`width_reach`] when W is fitted, plus a quarter of [`SHIFT_REACH_MM`] when the shift
    /// is (the Gaussian reaches 4 widths, so that covers the shifted pixels); `width` itself when
    /// neither. Fitting W alone so records 12 % fewer window samples than both (62 923 against
    /// 71 155 for the default scenario's four images).
    pub fn window_width(&self, width: f64) -> f64 {
        let w = if self.broadening { width_reach(width) } else { width };
        if self.registration_shift {
            w + 0.25 * SHIFT_REACH_MM * 1e-3
        } else {
            w
        }
    }
}

/// The fitted nuisance values (model values for those not fitted).
#[derive(Debug, Clone, PartialEq)]
pub struct FittedNuisance {
    /// The parameters that were fitted.
    pub fitted: Nuisance,
    /// Scale on the amplitude (1 = the model's).
    pub scale: f64,
    /// Broadening width W (mm).
    pub broadening_width_mm: f64,
    /// Registration shift along u and v (mm): the image content sits this far from the model's.
    pub shift_mm: [f64; 2],
    /// Per image: background offset (rad) and slopes along u and v (rad/mm).
    pub background: Vec<[f64; 3]>,
}

/// The largest broadening width (m) fitted for a model width `width` (m).
pub fn width_reach(width: f64) -> f64 {
    (WIDTH_REACH_FACTOR * width).max(width + WIDTH_REACH_MIN_MM * 1e-3)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_window_reaches_only_for_the_views_fitted() {
        // The model's W of 2.7 mm: W fitted reaches 1.5 x 2.7 = 4.05 mm; the shift adds a
        // quarter of its 2 mm reach; the amplitude and backgrounds need no wider window.
        let w = 2.7e-3;
        let window = |names: &[&str]| Nuisance::parse(names).map(|n| n.window_width(w) * 1e3).unwrap_or(f64::NAN);
        for (names, expected) in [
            (&["amplitude", "background_phase"][..], 2.7),
            (&["broadening"][..], 4.05),
            (&["registration_shift"][..], 3.2),
            (&["broadening", "registration_shift"][..], 4.55),
        ] {
            assert!((window(names) - expected).abs() < 1e-12, "{names:?}: {}", window(names));
        }
    }
}

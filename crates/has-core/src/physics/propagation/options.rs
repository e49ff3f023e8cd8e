//! The propagation's options: the absorbing layer, how changes of medium are crossed, and the
//! phase screen's model of the waves' direction.

use super::InterfaceModel;

/// Options of the propagation.
#[derive(Debug, Clone, PartialEq)]
pub struct HasOptions {
    /// Width of the absorbing layer at each lateral edge (m); 0 disables it.
    pub sponge_width: f64,
    /// Attenuation (Np) the layer applies to a wave crossing it along z over a distance equal to
    /// its width; the profile is quadratic, `sigma = 3·strength/width · (depth/width)²`.
    pub sponge_strength: f64,
    /// How changes of medium between slabs are applied.
    pub interfaces: InterfaceModel,
    /// The phase screen's model of the waves' direction.
    pub screen: Screen,
}

/// The direction the phase screen assumes for the waves crossing a slab.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Screen {
    /// Along z (the plain HAS screen `(k - k̄)·dz`), exact for waves travelling along the beam
    /// axis; an oblique wave in a medium other than `k̄` gains `(k - k̄)·(1/cos θ - 1)·dz` too
    /// little phase per step and is absorbed along z instead of along its path.
    #[default]
    Vertical,
    /// Along the line from each pixel to the point `toward` (m, the focus): the screen gives
    /// each pixel the phase and absorption of a wave crossing it at that angle (see `screen`).
    Oblique {
        /// The point the rays converge to (m).
        toward: [f64; 3],
    },
}

impl Screen {
    /// The scenario's name for it (`[grid] screen`).
    pub fn name(&self) -> &'static str {
        match self {
            Screen::Vertical => "vertical",
            Screen::Oblique { .. } => "oblique",
        }
    }
}

impl Default for HasOptions {
    fn default() -> Self {
        HasOptions { sponge_width: 10e-3, sponge_strength: 6.9, interfaces: InterfaceModel::default(), screen: Screen::default() }
    }
}

//! The physics layer: the simulation grid, media (with CT-derived skulls), transducers and their steering, the source
//! plane (Rayleigh projection of curved elements), the FFTs, Hybrid Angular Spectrum
//! propagation, and the MR-ARFI forward model after the pressure field with the tissues' MR response.

pub mod aberration;
pub mod ct;
pub mod fft;
pub mod grid;
pub mod material;
pub mod medium;
pub mod mr;
pub mod propagation;
pub mod rayleigh;
pub mod source;
pub mod steering;
pub mod tissue;
pub mod transducer;
pub mod upsample;

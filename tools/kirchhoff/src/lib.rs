//! Kirchhoff ground truth for the Stam BRDF, independent of every closed
//! form: synthetic height fields with the target statistics, the FFT of
//! p = exp(i k w h) over a window, |P|^2 averaged over realisations, compared
//! with the core (`stam`) evaluated at the same (k w, k u, k v).
//! See docs/kirchhoff.md.

pub mod cases;
pub mod core;
pub mod fft2;
pub mod heightmap;
pub mod optics;
pub mod periodic;
pub mod random;
pub mod report;
pub mod rng;
pub mod synth;

//! Rigorous grating efficiencies: the Fourier modal method (rigorous
//! coupled-wave analysis) for a 1-D periodic surface on a substrate, in
//! conical mounting, for both polarisations.
//!
//! Knows no renderer. `layers` turns a grating profile into lamellar layers;
//! `solver` solves Maxwell's equations for them and returns every propagating
//! order's efficiency and Jones matrix; `polarisation` turns the Jones
//! matrices into Mueller matrices a table can hold. See `docs/rigorous.md` for the
//! method, its references and its measured convergence and accuracy.

pub mod layers;
pub mod polarisation;
pub mod request;
pub mod solver;
pub mod table;

#[cfg(test)]
mod polarisation_tests;
#[cfg(test)]
mod tests;

pub use layers::{Grating, Layer, Medium, Stack};
pub use solver::{
    prepare, solve, solve_with, Diffraction, Factorisation, Incidence, Order, Prepared, MAX_ORDERS,
};
pub use table::{EfficiencyTable, TableSpec};

/// Fourier orders each side that a material's table retains for a grating
/// of period `period_um` under a medium of index `cover_eta`: 20 (within
/// 0.023 per order, rms 0.003, of N = 80 on the compact disc, at 60% of
/// N = 25's cost: docs/rigorous.md), or the orders that propagate in that
/// medium at the band's shortest wavelength (360 nm) plus 13 for longer
/// periods.
pub fn default_fourier_orders(period_um: f64, cover_eta: f64) -> usize {
    let propagating = (cover_eta * period_um / 0.36).ceil();
    if propagating.is_finite() && propagating >= 0.0 {
        (propagating as usize + 13).clamp(20, MAX_ORDERS)
    } else {
        MAX_ORDERS
    }
}

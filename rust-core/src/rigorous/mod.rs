//! Rigorous grating efficiencies: the Fourier modal method (rigorous
//! coupled-wave analysis) for a 1-D periodic surface on a substrate, in
//! conical mounting, for both polarisations.
//!
//! Knows no renderer. `layers` turns a grating profile into lamellar layers;
//! `solver` solves Maxwell's equations for them and returns every propagating
//! order's efficiency and Jones matrix. See `docs/rigorous.md` for the
//! method, its references and its measured convergence and accuracy.

pub mod layers;
pub mod request;
pub mod solver;
pub mod table;

#[cfg(test)]
mod tests;

pub use layers::{Grating, Layer, Medium, Stack};
pub use solver::{
    prepare, solve, solve_with, Diffraction, Factorisation, Incidence, Order, Prepared, MAX_ORDERS,
};
pub use table::{EfficiencyTable, TableSpec};

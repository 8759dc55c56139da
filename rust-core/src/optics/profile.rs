//! One period of a grating's height profile: what the Kirchhoff model
//! (models::periodic) and the rigorous solver both read.

/// One period of the height profile (lengths in micrometres).
#[derive(Clone, Debug, PartialEq)]
pub enum Profile {
    /// A bump of height `height_um` and width `width_um` in every period.
    Rect { height_um: f64, width_um: f64 },
    /// h(x) = (b/2) (1 + cos(2 pi x / Lam)), b = `height_um` (peak to valley).
    Sine { height_um: f64 },
    /// Uniform samples of one period, h_j = h(j Lam / N) (treated as samples,
    /// see `models::periodic`), N >= 2.
    Tabulated { heights_um: Vec<f64> },
}

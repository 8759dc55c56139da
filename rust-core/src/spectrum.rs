//! Colour: CIE 1931 2-degree matching functions, the D65 illuminant, linear
//! sRGB weights and the wavelength-integration rules used by the RGB path.
//!
//! CONTRACT (owned by the spectrum work; other modules rely on these):
//! - `LAMBDA_MIN_NM`, `LAMBDA_MAX_NM`: the visible band, 360..830 nm. The
//!   BRDF is 0 outside it.
//! - `srgb_weight_per_nm(lambda_nm) -> [f64; 3]`: W_c(lambda) =
//!   D65(lambda) cbar_c(lambda) / integral(D65 cbar_c dlambda), c in linear
//!   sRGB; so integral W_c dlambda = 1 and a flat spectrum maps to (1,1,1).
//!   Linear interpolation of a 1 nm table; 0 outside the band.
//! - `srgb_weight_per_wavenumber(nu_per_um)`: the same per unit wavenumber
//!   nu = 1000 / lambda_nm (1/um): W_c(1000/nu) * 1000 / nu^2.
//! - `integrate_rgb_reference(f, step_nm)`: integral of f(lambda_nm) W_c over
//!   the band by the composite rule on a step_nm grid (1 nm = the reference).
//! - `SmoothRule` / `smooth_rule(node_count)`: nodes in nu and weights so that
//!   sum_j weights[j][c] f(nu_j) approximates integral f W_c for spectra that
//!   are smooth in nu; the weights come from the full 1 nm table, so D65's
//!   fine structure is never aliased. Cached per node count.
//! - `gaussian_moments(mu, s)`: M[p][c] = integral over nu of
//!   (nu - mu)^p exp(-(nu - mu)^2 / (2 s^2)) W_c(nu) dnu for p = 0, 1, 2
//!   (W per unit wavenumber), for the narrow diffraction-order peaks of
//!   periodic surfaces. Table driven (built once), any mu, any s > 0.
// TEMPORARY STAND-IN (replaced by the spectrum branch): signatures only.
pub const LAMBDA_MIN_NM: f64 = 360.0;
pub const LAMBDA_MAX_NM: f64 = 830.0;
pub struct SmoothRule {
    pub nu_per_um: Vec<f64>,
    pub lambda_nm: Vec<f64>,
    pub weights: Vec<[f64; 3]>,
}
pub fn smooth_rule(_node_count: usize) -> &'static SmoothRule {
    unimplemented!()
}
pub fn integrate_rgb_reference(_f: impl Fn(f64) -> f64, _step_nm: f64) -> [f64; 3] {
    unimplemented!()
}
pub mod metals {
    pub struct MetalTable {
        pub name: &'static str,
        pub lambda_nm: &'static [f64],
        pub eta: &'static [f64],
        pub k: &'static [f64],
    }
    pub const METALS: [MetalTable; 0] = [];
}

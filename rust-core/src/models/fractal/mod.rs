//! Fractal (fractional Brownian) surfaces through the universal 2-D stable
//! profile Phi_alpha. See docs/physics.md, "Fractal surfaces".
//!
//! Structure function D(r) = sigma^2 (r / lag)^(2H), alpha = 2H in (0, 2].
//! With k = 2 pi / lambda and a = k^2 w^2 sigma^2 / (2 lag^alpha):
//!
//! ```text
//! <|P(q)|^2>/A = a^(-2/alpha) Phi_alpha(|q| a^(-1/alpha)),
//! Phi_alpha(x) = 2 pi int_0^inf exp(-s^alpha) J0(x s) s ds,
//! K = k^2 / (4 pi^2 w^2) <|P(k u, k v)|^2>/A,   f = F^2 G K.
//! ```
//!
//! # How Phi_alpha is computed ([`StableProfile`])
//! ln Phi is tabulated on a uniform grid in y = ln x (values and exact
//! derivatives d ln Phi / dy, cubic Hermite interpolation); outside the grid
//! the two series are summed at run time:
//! - small x: Phi = (2 pi/alpha) sum_n (-1)^n Gamma((2n+2)/alpha) (x/2)^(2n) / (n!)^2
//!   (convergent for alpha > 1, asymptotic for alpha <= 1),
//! - large x: Phi = -4 sum_j ((-1)^j/j!) 2^(j alpha) Gamma(1 + j alpha/2)^2
//!   sin(pi j alpha/2) x^-(j alpha + 2) (convergent for alpha < 1, asymptotic
//!   otherwise).
//!
//! The switch points are where 8 (small x) or 12 (large x) terms give
//! 1e-16 with decreasing terms and little cancellation; at run time each
//! series is one exp and a Horner polynomial in v = e^(2(y - y_min)) or
//! u = e^(-alpha (y - y_max)), both <= 1. Each table point is
//! taken from the best of three sources, each with an error estimate: both
//! series with many terms (build time only) and the Mellin-Barnes inversion
//!
//! ```text
//! M(z) = int_0^inf Phi(x) x^(z-1) dx = pi 2^(z-1) Gamma(z/2) Gamma(1 + (2-z)/alpha) / Gamma(2 - z/2),
//! Phi(e^y) e^(c y) = (1/2 pi) int M(c + i t) e^(-i t y) dt,    0 < c < 2 + alpha,
//! ```
//!
//! done by one FFT per c (the trapezoidal rule in t is exact up to aliasing
//! in y, which is checked on the window edges and removed by doubling the
//! window). The FFT of -z M(z) gives x Phi'(x) e^(c y) in the same transform.
//! The c values form a saddle-point ladder: for a given c the weight
//! Phi(e^y) e^(c y) has mean d ln M/dc and variance d^2 ln M/dc^2 (digamma
//! and trigamma), so consecutive c are 3 standard deviations apart. Each
//! point keeps the window where Phi e^(cy) is largest relative to the
//! transform's L1 norm (its rounding error). The table is built at half
//! spacing and the odd points check the interpolation; the spacing is halved
//! until the midpoint error in ln Phi is below 1e-7.
//!
//! alpha = 2 exactly (H = 1) is the closed form pi exp(-x^2/4).

mod build;
mod math;
#[cfg(test)]
mod param_tests;
pub mod params;
mod profile;
mod program;
#[cfg(test)]
mod program_tests;
mod sampling;
#[cfg(test)]
mod tests;

pub use params::FractalParams;
pub use profile::{ProfileDiagnostics, StableProfile};
pub use sampling::Lobe;

use crate::error::StamError;
use crate::models::{Shading, SurfaceModel, FLAG_SPECTRALLY_VARYING, MAX_RGB_NODES};
use crate::optics::geometry::PairGeometry;
use crate::sampling::{Component, StrategyTable};
use crate::special::fast_exp;
use math::LN_2PI;
use std::sync::OnceLock;

/// 1 / (4 pi^2).
const INV_4PI2: f64 = 1.0 / (4.0 * std::f64::consts::PI * std::f64::consts::PI);
/// ln(4 pi^2).
const LN_4PI2: f64 = 2.0 * LN_2PI;

/// The fractal model of a material: the surface and its sampling table.
pub struct Fractal {
    surface: FractalSurface,
    /// Sampling strategies over the incidence cosine and the wavelength,
    /// made on the first sample.
    strategies: OnceLock<StrategyTable<Lobe>>,
}

impl Fractal {
    pub fn new(p: &FractalParams) -> Result<Fractal, StamError> {
        Ok(Fractal {
            surface: FractalSurface::new(p.hurst, p.sigma_um, p.lag_um).map_err(StamError::new)?,
            strategies: OnceLock::new(),
        })
    }

    pub fn surface(&self) -> &FractalSurface {
        &self.surface
    }
}

impl SurfaceModel for Fractal {
    type Params = FractalParams;
    type Lobe = Lobe;

    fn from_params(
        p: &FractalParams,
        _: &crate::optics::fresnel::Fresnel,
    ) -> Result<Fractal, StamError> {
        Fractal::new(p)
    }

    fn flags(&self) -> u32 {
        FLAG_SPECTRALLY_VARYING
    }

    fn memory_bytes(&self) -> usize {
        self.surface.memory_bytes() + self.strategies.get().map_or(0, |t| t.memory_bytes())
    }

    #[inline]
    fn kernel(&self, k_per_um: f64, geom: &PairGeometry) -> f64 {
        self.surface.kernel(k_per_um, geom)
    }

    fn reflectance_rgb(&self, shading: &Shading, geom: &PairGeometry) -> [f64; 3] {
        let rule = shading.rgb_rule;
        let mut values = [0.0; MAX_RGB_NODES];
        let values = &mut values[..rule.len()];
        self.surface
            .kernel_at_wavenumbers(&rule.k_per_um, &rule.ln_k_per_um, geom, values);
        shading.integrate(geom.cos_half, values)
    }

    fn spectral_component(&self, _: &Shading, wi: glam::DVec3, lambda_nm: f64) -> Component<Lobe> {
        self.component(wi, lambda_nm)
    }
}

/// A fractional Brownian surface: D(r) = sigma^2 (r / lag)^(2 hurst).
#[derive(Clone, Debug)]
pub struct FractalSurface {
    pub hurst: f64,
    pub sigma_um: f64,
    pub lag_um: f64,
    pub profile: StableProfile,
    alpha: f64,
    inv_alpha: f64,
    /// ln(sigma^2 / 2) - alpha ln(lag): ln a = ln(k^2 w^2) + ln_a_const.
    ln_a_const: f64,
}

impl FractalSurface {
    pub fn new(hurst: f64, sigma_um: f64, lag_um: f64) -> Result<FractalSurface, String> {
        for (name, v) in [("hurst", hurst), ("sigma_um", sigma_um), ("lag_um", lag_um)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!(
                    "fractal surface: {name} = {v} must be finite and > 0"
                ));
            }
        }
        if hurst > 1.0 {
            return Err(format!(
                "fractal surface: hurst = {hurst} must be at most 1"
            ));
        }
        let alpha = 2.0 * hurst;
        let profile = StableProfile::new(alpha)?;
        Ok(FractalSurface {
            hurst,
            sigma_um,
            lag_um,
            profile,
            alpha,
            inv_alpha: 1.0 / alpha,
            ln_a_const: 2.0 * sigma_um.ln() - std::f64::consts::LN_2 - alpha * lag_um.ln(),
        })
    }

    /// ln a(k, w) with a = k^2 w^2 sigma^2 / (2 lag^alpha).
    #[inline(always)]
    fn ln_a(&self, ln_k: f64, ln_abs_w: f64) -> f64 {
        2.0 * (ln_k + ln_abs_w) + self.ln_a_const
    }

    /// The diffuse kernel K = k^2/(4 pi^2 w^2) a^(-2/alpha) Phi(k |(u,v)| a^(-1/alpha)),
    /// so that f = F^2 G K. Finite and >= 0 for every input (0 for k not
    /// finite and positive; clamped to f64::MAX).
    #[inline]
    pub fn kernel(&self, k_per_um: f64, geom: &PairGeometry) -> f64 {
        if !(k_per_um > 0.0 && k_per_um < f64::INFINITY) {
            return 0.0;
        }
        // Fast path: 2 ln + 1 exp, the prefactor k^2/w^2 in linear space.
        let aw = geom.w.abs();
        let k2 = k_per_um * k_per_um;
        let kw = k_per_um * aw;
        let r2 = geom.u * geom.u + geom.v * geom.v;
        let kr2 = k2 * r2;
        let pref = k2 / (aw * aw);
        if kw.is_normal() && pref.is_normal() && (kr2.is_normal() || r2 == 0.0) {
            let ln_s = -self.inv_alpha * (2.0 * kw.ln() + self.ln_a_const);
            let y = 0.5 * kr2.ln() + ln_s;
            let e = 2.0 * ln_s + self.profile.ln_phi_at_ln(y);
            if e > -700.0 && e < 700.0 {
                return (pref * INV_4PI2 * e.exp()).min(f64::MAX);
            }
        }
        let l = self.ln_kernel(k_per_um, geom);
        if l > 709.0 {
            f64::MAX
        } else if l > -746.0 {
            l.exp()
        } else {
            0.0
        }
    }

    /// K at several wavenumbers (the RGB rule's nodes), sharing the pair's
    /// logarithms: ln s and ln(k r) are affine in ln k, so each node costs
    /// one profile lookup and one exp instead of two logarithms more.
    /// Falls back to `kernel` per node where the fast path does not apply.
    pub fn kernel_at_wavenumbers(
        &self,
        k_per_um: &[f64],
        ln_k_per_um: &[f64],
        geom: &PairGeometry,
        out: &mut [f64],
    ) {
        let aw = geom.w.abs();
        let r2 = geom.u * geom.u + geom.v * geom.v;
        if !(aw.is_normal() && r2.is_normal()) {
            for (o, &k) in out.iter_mut().zip(k_per_um) {
                *o = self.kernel(k, geom);
            }
            return;
        }
        // ln s_j = -(2 ln k_j + 2 ln|w| + c) / alpha; y_j = ln k_j + ln r + ln s_j.
        let ln_s0 = -self.inv_alpha * (2.0 * aw.ln() + self.ln_a_const);
        let y0 = 0.5 * r2.ln() + ln_s0;
        let inv_w2 = INV_4PI2 / (aw * aw);
        for ((o, &k), &ln_k) in out.iter_mut().zip(k_per_um).zip(ln_k_per_um) {
            let ln_s = ln_s0 - 2.0 * self.inv_alpha * ln_k;
            let y = y0 + ln_k * (1.0 - 2.0 * self.inv_alpha);
            let e = 2.0 * ln_s + self.profile.ln_phi_at_ln(y);
            *o = if e > -700.0 && e < 700.0 {
                (k * k * inv_w2 * fast_exp(e)).min(f64::MAX)
            } else {
                self.kernel(k, geom)
            };
        }
    }

    /// ln K (same as kernel, without the final exp and clamp; -inf when K = 0).
    pub fn ln_kernel(&self, k_per_um: f64, geom: &PairGeometry) -> f64 {
        if !(k_per_um > 0.0 && k_per_um < f64::INFINITY) {
            return f64::NEG_INFINITY;
        }
        let ln_k = k_per_um.ln();
        let ln_w = geom.w.abs().max(1e-300).ln();
        let ln_r = geom.u.hypot(geom.v).ln();
        let ln_s = -self.inv_alpha * self.ln_a(ln_k, ln_w);
        let y = ln_r + ln_k + ln_s;
        let l = 2.0 * (ln_k - ln_w + ln_s) - LN_4PI2 + self.profile.ln_phi_at_ln(y);
        if l.is_nan() {
            f64::NEG_INFINITY
        } else {
            l
        }
    }

    /// scale = a^(-1/alpha) for this (k, w), a = k^2 w^2 sigma^2 / (2 lag^alpha)
    /// (dimension um; may overflow for tiny alpha: see ln_projected_scale).
    ///
    /// Meaning: with s = k * scale (1/um per unit of u), the projected
    /// difference (u, v) has the density over the whole (u, v) plane
    ///   p(u, v) = s^2 Phi_alpha(s |(u,v)|) / (4 pi^2) = w^2 K(u, v),
    /// normalised to 1 (the plane, not the disc u^2 + v^2 <= 4), and
    /// P(|(u,v)| <= R) = profile.radial_cdf(s R). To sample: x from
    /// profile.inverse_radial_cdf(xi), |(u,v)| = x / s, uniform azimuth.
    pub fn projected_scale(&self, k_per_um: f64, w: f64) -> f64 {
        self.ln_projected_scale(k_per_um, w).exp()
    }

    /// ln of projected_scale.
    pub fn ln_projected_scale(&self, k_per_um: f64, w: f64) -> f64 {
        -self.inv_alpha * self.ln_a(k_per_um.ln(), w.abs().ln())
    }

    pub fn alpha(&self) -> f64 {
        self.alpha
    }

    /// Bytes owned (the profile is shared between surfaces with equal hurst
    /// but is counted in full here).
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<FractalSurface>() + self.profile.memory_bytes()
    }
}

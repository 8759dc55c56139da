//! Sampling of fractal surfaces: the diffuse kernel is (1/w^2) times the
//! radially symmetric density (k s)^2 Phi_alpha(k s |(u, v)|) / (4 pi^2) in
//! the projected plane, s the projected scale; the strategy freezes s at
//! the mirror configuration and draws |(u, v)| by the profile's inverse
//! radial CDF.

use super::{Fractal, LN_4PI2};
use crate::sampling::warps::uv_to_direction;
use crate::sampling::{Component, DEFENSIVE_FRACTION};
use crate::special::fast_exp;
use crate::spectrum::wavenumber_per_um;
use glam::DVec3;
use std::f64::consts::PI;

/// The radially symmetric (u, v) density c^2 Phi(c r) / (4 pi^2),
/// ln c = ln k + ln(projected scale at the mirror).
#[derive(Clone)]
pub struct Lobe {
    ln_c: f64,
}

impl crate::sampling::Lobe for Lobe {
    type Model = Fractal;

    fn sample(&self, model: &Fractal, wi: DVec3, _t: f64, r1: f64, r2: f64) -> Option<DVec3> {
        let ln_r = model.surface.profile.inverse_radial_cdf_ln(r1) - self.ln_c;
        let r = ln_r.exp();
        if !(r < 2.0) {
            return None;
        }
        let angle = 2.0 * PI * r2;
        uv_to_direction(wi, r * angle.cos(), r * angle.sin())
    }

    fn pdf(&self, model: &Fractal, wi: DVec3, wo: DVec3, _negligible: f64) -> f64 {
        let (u, v) = (-(wi.x + wo.x), -(wi.y + wo.y));
        let ln_r = 0.5 * (u * u + v * v).ln();
        let ln_p = 2.0 * self.ln_c + model.surface.profile.ln_phi_at_ln(ln_r + self.ln_c) - LN_4PI2;
        let p_uv = if ln_p < 709.0 {
            fast_exp(ln_p)
        } else {
            f64::MAX
        };
        p_uv * wo.z
    }
}

impl Fractal {
    /// The one-wavelength strategy at unit wi above the horizon (from the
    /// strategy table for in-band wavelengths).
    pub(super) fn component(&self, wi: DVec3, lambda_nm: f64) -> Component<Lobe> {
        if !(lambda_nm.is_finite() && crate::spectrum::in_band(lambda_nm)) {
            return Component::cosine_only();
        }
        let table = self.strategies.get_or_init(Default::default);
        table
            .get(wi.z, lambda_nm, |cos, lambda| {
                let centre = DVec3::new((1.0 - cos * cos).sqrt(), 0.0, cos);
                self.build_component(centre, lambda)
            })
            .clone()
    }

    fn build_component(&self, wi: DVec3, lambda_nm: f64) -> Component<Lobe> {
        let f = &self.surface;
        let k = wavenumber_per_um(lambda_nm);
        let ln_c = k.ln() + f.ln_projected_scale(k, 2.0 * wi.z);
        if !ln_c.is_finite() {
            return Component::cosine_only();
        }
        // Share of the lobe inside |(u, v)| < 1 (always above the
        // horizon for normal incidence): a very wide lobe loses most
        // samples below the horizon, so it gets fewer of them.
        let inside = f.profile.radial_cdf(ln_c.exp().min(f64::MAX));
        let p_lobe = (1.0 - DEFENSIVE_FRACTION) * inside.clamp(0.0, 1.0);
        Component {
            p_coh: 0.0,
            p_def: 1.0 - p_lobe,
            p_lobe,
            lobe: Some(Lobe { ln_c }),
        }
    }
}

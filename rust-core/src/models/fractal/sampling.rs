//! Sampling of fractal surfaces: the diffuse kernel is (1/w^2) times the
//! radially symmetric density (k s)^2 Phi_alpha(k s |(u, v)|) / (4 pi^2) in
//! the projected plane, s the projected scale; the strategy freezes s at
//! the mirror configuration and draws |(u, v)| by the profile's inverse
//! radial CDF.

use super::{Fractal, LN_4PI2};
use crate::sampling::warps::uv_to_direction;
use crate::sampling::{AliasTable, Component, DEFENSIVE_FRACTION};
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
        let inside = f.profile.radial_cdf(ln_c.exp().min(f64::MAX));
        let p_lobe = lobe_share(inside);
        Component {
            p_coh: 0.0,
            p_def: 1.0 - p_lobe,
            p_lobe,
            lobe: Some(Lobe { ln_c }),
        }
    }
}

/// A component's lobe probability from the lobe's mass `inside` the unit
/// disc |(u, v)| < 1 (always above the horizon for normal incidence):
/// 0.9 inside^3. A wide lobe loses samples below the horizon, and its shape,
/// frozen at the mirror, fits f worst: with 0.9 inside (Stam's formula's
/// rule) the very rough fractal (H 0.35, sigma 0.2, L 1 um) at 30 degrees,
/// where inside is 0.21, sampled worse than cosine (variance 0.5x) once the
/// energy table had removed the grazing light that the lobe catches
/// (docs/sampling.md); the cube gives the defensive part that light.
/// Lobes that are mostly inside (all others measured) keep their share.
pub(super) fn lobe_share(inside: f64) -> f64 {
    (1.0 - DEFENSIVE_FRACTION) * inside.clamp(0.0, 1.0).powi(LOBE_SHARE_POWER)
}

/// The power of `inside` in [`lobe_share`] (measured: 1 gives cosine/IS
/// variance 0.5, 2 gives 0.9, 3 gives 1.0-1.1 on that material at 30 deg).
pub(super) const LOBE_SHARE_POWER: i32 = 3;

/// Tail mass left outside the proposal's grid on either side.
const PROPOSAL_TAIL: f64 = 1e-4;
/// Target cell width of the proposal in ln x.
const PROPOSAL_CELL: f64 = 0.025;
const PROPOSAL_MAX_CELLS: usize = 2048;

/// The lobe's radial law for the sampling programs (`program.rs`): a
/// density of y = ln x, x = c |(u, v)| (c = k times the projected scale,
/// as in [`Lobe`]), that follows the profile's, rho(y) = Phi(e^y) e^(2y) /
/// (2 pi), and has an exact inverse without a search. `cells` equal cells
/// of width `h` from `y_lo` to `y_lo + cells h` interpolate rho linearly
/// between its values at the cell edges; below y_lo it continues as
/// rho(y_lo) e^(2 (y - y_lo)) (Phi is flat near 0), above as rho(y_hi)
/// e^(-alpha (y - y_hi)) (Phi's power-law tail for alpha < 2; heavier than
/// the Gaussian one at alpha = 2), so that the density is continuous. An
/// alias table over the cells and the two tails picks an entry with two
/// gathers; the position inside a cell inverts the linear density in
/// closed form. The densities are taken from the alias table as stored in
/// f32, so that the pdf is exactly the law the program samples.
pub(super) struct RadialProposal {
    pub alpha: f64,
    pub y_lo: f64,
    pub h: f64,
    pub cells: usize,
    /// Per entry (the cells, then the tails below and above): the
    /// probability of keeping the entry, then the alias it passes the rest
    /// to.
    pub alias: Vec<f32>,
    /// Per cell: the density at its lower and upper edge.
    pub density: Vec<f32>,
    /// ln(2 P_below): the density below y_lo is 2 P_below e^(2 (y - y_lo)).
    pub ln_below: f64,
    /// ln(alpha P_above): above y_hi it is alpha P_above e^(-alpha (y - y_hi)).
    pub ln_above: f64,
    /// ln b: the lobe's share inside |(u, v)| < 1 (`radial_cdf(c)` in
    /// `build_component`) is taken as 1 - (1 + c^2 / b)^(-alpha / 2), the
    /// closed form with the profile's median (a mixture weight only needs
    /// to be a fixed function of the incidence).
    pub ln_inside_b: f64,
}

impl RadialProposal {
    pub(super) fn new(profile: &super::StableProfile) -> RadialProposal {
        let alpha = profile.alpha();
        let y_lo = profile.inverse_radial_cdf_ln(PROPOSAL_TAIL);
        let y_hi = profile.inverse_radial_ccdf_ln(PROPOSAL_TAIL);
        let cells = (((y_hi - y_lo) / PROPOSAL_CELL).ceil() as usize).clamp(16, PROPOSAL_MAX_CELLS);
        let h = (y_hi - y_lo) / cells as f64;
        // rho at the edges, up to a common factor (ln, so that tiny alpha
        // does not overflow).
        let ln_rho: Vec<f64> = (0..=cells)
            .map(|i| {
                let y = y_lo + i as f64 * h;
                profile.ln_phi_at_ln(y) + 2.0 * y
            })
            .collect();
        let top = ln_rho.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let rho: Vec<f64> = ln_rho.iter().map(|l| (l - top).exp()).collect();
        let mut mass: Vec<f64> = rho.windows(2).map(|w| 0.5 * h * (w[0] + w[1])).collect();
        mass.push(0.5 * rho[0]);
        mass.push(rho[cells] / alpha);
        // The law as stored: entry e keeps itself with probability keep
        // (f32) and passes the rest to its alias.
        let table = AliasTable::new(&mass);
        let p = &table.probability;
        let density = (0..cells)
            .flat_map(|i| {
                let scale = if mass[i] > 0.0 { p[i] / mass[i] } else { 0.0 };
                [(rho[i] * scale) as f32, (rho[i + 1] * scale) as f32]
            })
            .collect();
        // x_med^2 / b = 2^(2/alpha) - 1.
        let z = 2.0 / alpha * std::f64::consts::LN_2;
        let ln_expm1 = if z > 30.0 { z } else { z.exp_m1().ln() };
        RadialProposal {
            alpha,
            y_lo,
            h,
            cells,
            alias: table.interleaved.clone(),
            density,
            ln_below: (2.0 * p[cells]).ln(),
            ln_above: (alpha * p[cells + 1]).ln(),
            ln_inside_b: 2.0 * profile.inverse_radial_cdf_ln(0.5) - ln_expm1,
        }
    }
}

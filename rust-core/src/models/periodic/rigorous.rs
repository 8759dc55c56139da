//! `"orders": "rigorous"`: each order's power from Maxwell's equations
//! instead of Stam's formula (docs/rigorous.md, "In a material").
//!
//! Stam's kernel gives order n the lobe F^2 G |c_n(k w)|^2 / w^2 times a
//! Gaussian of the coherence length. Here the lobe keeps its Gaussian (the
//! illumination's coherence, which Maxwell's equations for a perfectly
//! periodic grating do not know) and its power is the order's rigorous
//! efficiency eta_n, tabulated once per grating (`rigorous::table`):
//!
//! ```text
//! f = sum_n eta_n (k^2 l^2 / pi) exp(-l^2 [(k u - 2 pi n / Lam)^2 + k^2 v^2])
//! ```
//!
//! The Gaussian integrates to 1 over the projected hemisphere
//! (cos_o d omega_o = du dv), so order n reflects eta_n of the incident
//! light, and the orders together what the solver says the grating
//! reflects: no Fresnel term, no G, no energy table.
//!
//! A lobe is read at the incidence of the exact order pair nearest to
//! (wi, wo): both directions moved by half the pair's distance from the
//! order (in u, and in v to the mirror), which keeps the lobe's centre
//! where the solver puts the order. The efficiency is the mean of the
//! table at that incidence seen from wi and from wo, so that f(wi, wo) =
//! f(wo, wi) exactly (the grating's reciprocity, which the solver meets to
//! 4e-5, would otherwise hold only to the table's interpolation error).
//!
//! Orders: the solver's m (kx_m = kx + m lambda / Lam for the incident
//! wave, which travels along -wi) is Stam's -n (u = -(wi.x + wo.x) =
//! n lambda / Lam at the order).
//!
//! A transparent cover of index n (`cover_eta`, a real disc's
//! polycarbonate) is a flat dielectric interface above the grating, far
//! enough for its reflections to add as powers: it reflects R(cos_i) (the
//! unpolarised Fresnel reflectance of the index: a mirror lobe, the
//! material's coherent lobe), lets 1 - R(cos_i) in, the grating diffracts
//! inside the medium (the table is solved with the cover as incidence
//! medium; the tangential wavevector, hence (kx, ky), is the same inside and
//! out), and an order leaves with 1 - R(cos_o); orders that meet the cover
//! beyond its critical angle (|k_t| > 1) stay inside. Left out: the light
//! the cover reflects back onto the grating (R ~ 4-5% of each order, which
//! would re-diffract) and the polarisation through the two interfaces (each
//! is taken unpolarised).

use std::sync::Arc;

use glam::DVec3;

use super::Profile;
use crate::error::StamError;
use crate::optics::fresnel::{conductor_reflectance, Fresnel};
use crate::rigorous::{table, EfficiencyTable, Grating, Medium, TableSpec};
use crate::spectrum::{LAMBDA_MAX_NM, LAMBDA_MIN_NM};

/// Staircase layers for smooth (sine and tabulated) profiles.
const SLICES: usize = 16;
/// Largest |k_t| at which a table is read (its rows end just inside the
/// incidence disc).
const DISC_EDGE: f64 = 0.9995;

/// A grating's rigorous efficiencies, shared between materials of the same
/// grating (the table cache).
#[derive(Clone, Debug)]
pub struct RigorousOrders {
    table: Arc<EfficiencyTable>,
    period_um: f64,
    /// Index of the transparent cover (1: none).
    cover_eta: f64,
}

/// The medium of a material's Fresnel term: the solver needs the metal's
/// complex index, which a constant reflectance does not give.
fn medium(fresnel: &Fresnel) -> Result<Medium, String> {
    match fresnel {
        Fresnel::Metal { table, .. } => Ok(Medium::Metal(table)),
        Fresnel::ComplexIndex { eta, k } => Ok(Medium::Index { eta: *eta, k: *k }),
        Fresnel::Constant(r) => Err(format!(
            "\"orders\": \"rigorous\" needs the grating's material: set 'fresnel' to a metal's name or {{\"eta\": ..., \"k\": ...}} (got the constant reflectance {r})"
        )),
    }
}

/// The table grid of a material: the band, 20 x 41 rows over (lambda, kx),
/// about 3 ky nodes per 0.25 of sqrt(ky^2 - ky_m^2) between anomalies, the
/// cover (1: none) as the incidence medium. On the compact disc (N = 20)
/// 3.8-5.7 s to build on 2 cores, per-order error rms 0.009, p99 0.037
/// (docs/rigorous.md, "Measured accuracy").
pub fn table_spec(fourier_orders: usize, cover_eta: f64) -> TableSpec {
    TableSpec {
        lambda_min_nm: LAMBDA_MIN_NM,
        lambda_max_nm: LAMBDA_MAX_NM,
        n_lambda: 20,
        n_kx: 41,
        nodes_per_gap: 3,
        orders: fourier_orders,
        cover_eta,
    }
}

impl RigorousOrders {
    /// The efficiencies of `profile` with period `period_um` on the material
    /// of `fresnel`, from the cache or built (seconds to a minute, with
    /// progress on stderr).
    pub fn new(
        period_um: f64,
        profile: &Profile,
        fresnel: &Fresnel,
        fourier_orders: usize,
        cover_eta: f64,
    ) -> Result<RigorousOrders, StamError> {
        let grating = Grating {
            period_um,
            profile: profile.clone(),
            metal: medium(fresnel).map_err(StamError::new)?,
            slices: SLICES,
        };
        let table = table::table(&grating, &table_spec(fourier_orders, cover_eta))?;
        Ok(RigorousOrders {
            table,
            period_um,
            cover_eta,
        })
    }

    /// The cover's reflectance at an incidence cosine (0 without a cover):
    /// what its mirror lobe reflects.
    pub fn cover_reflectance(&self, cos_theta: f64) -> f64 {
        if self.cover_eta > 1.0 {
            conductor_reflectance(cos_theta, self.cover_eta, 0.0)
        } else {
            0.0
        }
    }

    pub fn has_cover(&self) -> bool {
        self.cover_eta > 1.0
    }

    /// Order n's power in f for the pair: its efficiency through the
    /// cover's two interfaces (1 - R in, 1 - R out).
    pub fn power(&self, n: i64, lambda_nm: f64, wi: DVec3, wo: DVec3) -> f64 {
        let through = (1.0 - self.cover_reflectance(wi.z)) * (1.0 - self.cover_reflectance(wo.z));
        through * self.efficiency(n, lambda_nm, wi, wo)
    }

    pub fn table(&self) -> &EfficiencyTable {
        &self.table
    }

    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<RigorousOrders>() + self.table.memory_bytes()
    }

    /// The efficiency of Stam's order n for the pair (unit wi, wo above
    /// the horizon) at `lambda_nm`: the table at the nearest exact pair's
    /// incidence, from both sides (see the module doc).
    pub fn efficiency(&self, n: i64, lambda_nm: f64, wi: DVec3, wo: DVec3) -> f64 {
        let u_n = n as f64 * lambda_nm * 1e-3 / self.period_um;
        // The pair's distance from the order along x, shared by both.
        let half = 0.5 * (-(wi.x + wo.x) - u_n);
        let ky = 0.5 * (wi.y - wo.y);
        let from = |x: f64| {
            // The incident wave travels along -w.
            let (kx, ky) = within_disc(-(x + half), ky);
            self.table.efficiency(lambda_nm, kx, ky, -n)
        };
        0.5 * (from(wi.x) + from(wo.x))
    }
}

/// (kx, ky) moved radially inside the table's disc.
fn within_disc(kx: f64, ky: f64) -> (f64, f64) {
    let r = (kx * kx + ky * ky).sqrt();
    if r > DISC_EDGE {
        let s = DISC_EDGE / r;
        (kx * s, ky * s)
    } else {
        (kx, ky)
    }
}

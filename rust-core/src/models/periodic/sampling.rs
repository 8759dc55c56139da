//! Sampling of periodic surfaces. The diffuse kernel is (1/w^2) times
//! sum_n |c_n|^2 N2(u - n lambda/Lam, v; var = 1/(2 k^2 l^2)) in the
//! projected plane: one wavelength samples the propagating orders with
//! weights estimated once per cell of a grid over the incident direction
//! (`GratingTable`), each order an isotropic Gaussian (`OrdersLobe`); RGB
//! mode samples the orders' rainbows over the band (`RainbowLobe`), the
//! whole strategy held by the table's cell.

use super::Periodic;
use crate::models::Shading;
use crate::optics::fresnel::Fresnel;
use crate::sampling::warps::{inverse_normal, pick, pick_cdf, uv_to_direction};
use crate::sampling::{band_density, Component, Components, RGB_BAND_NM};
use crate::special::fast_exp;
use crate::spectrum::wavenumber_per_um;
use crate::spectrum::WAVENUMBER_TIMES_NM;
use glam::DVec3;
use smallvec::smallvec;
use std::f64::consts::PI;
use std::sync::OnceLock;

/// Wavelength bins of the grating rainbow (fewer for very many orders).
const RAINBOW_MAX_BINS: usize = 20;
const RAINBOW_MAX_CELLS: usize = 8192;
/// Grating order weights are computed exactly at every this-many wavelength
/// nodes of the rainbow and interpolated in between.
const RAINBOW_WEIGHT_STEP: usize = 4;
/// Cap of the G / w^2 factor used in order weights (grazing orders).
const GW2_CAP: f64 = 50.0;
/// Orders farther than this many standard deviations are left out of pdf sums
/// (their Gaussian factor is below e^-40.5).
const ORDER_REACH_SD: f64 = 9.0;

/// The lobes of a grating's strategies.
#[derive(Clone)]
pub enum Lobe {
    Orders(OrdersLobe),
    Rainbow(Box<RainbowLobe>),
}

impl crate::sampling::Lobe for Lobe {
    type Model = Periodic;

    fn sample(&self, _: &Periodic, wi: DVec3, t: f64, r1: f64, r2: f64) -> Option<DVec3> {
        let (u, v) = match self {
            Lobe::Orders(o) => o.sample(t, r1, r2),
            Lobe::Rainbow(r) => r.sample(t, r1, r2),
        };
        uv_to_direction(wi, u, v)
    }

    fn pdf(&self, _: &Periodic, wi: DVec3, wo: DVec3, _negligible: f64) -> f64 {
        let (u, v) = (-(wi.x + wo.x), -(wi.y + wo.y));
        let p_uv = match self {
            Lobe::Orders(o) => o.pdf_uv(u, v),
            Lobe::Rainbow(r) => r.pdf_uv(u, v),
        };
        p_uv * wo.z
    }
}

/// Periodic surface, one wavelength: order n (centre u = n du) with
/// probability prob[n - n_lo], then an isotropic Gaussian of sd sigma.
#[derive(Clone)]
pub struct OrdersLobe {
    du: f64,
    sigma: f64,
    n_lo: i64,
    prob: Vec<f64>,
}

impl OrdersLobe {
    fn sample(&self, t: f64, r1: f64, r2: f64) -> (f64, f64) {
        let n = self.n_lo + pick(&self.prob, t) as i64;
        (
            n as f64 * self.du + self.sigma * inverse_normal(r1),
            self.sigma * inverse_normal(r2),
        )
    }

    fn pdf_uv(&self, u: f64, v: f64) -> f64 {
        let inv2s2 = 0.5 / (self.sigma * self.sigma);
        let ev = v * v * inv2s2;
        if !(ev < 745.0) {
            return 0.0;
        }
        let reach = ORDER_REACH_SD * self.sigma;
        let n_hi = self.n_lo + self.prob.len() as i64 - 1;
        let a = ((u - reach) / self.du).ceil().max(self.n_lo as f64);
        let b = ((u + reach) / self.du).floor().min(n_hi as f64);
        if !(a <= b) {
            return 0.0;
        }
        let mut sum = 0.0;
        for n in a as i64..=b as i64 {
            let d = u - n as f64 * self.du;
            sum += self.prob[(n - self.n_lo) as usize] * fast_exp(-(d * d) * inv2s2 - ev);
        }
        sum * inv2s2 / PI
    }
}

/// Periodic surface, RGB mode. Per order n, a weight y_n(lambda) that is
/// piecewise linear between wavelength nodes lambda_i = lo + i h (i = 0..=bins),
/// normalised so that the trapezoid masses of all orders sum to 1. Order
/// n != 0: lambda drawn from y_n, u = n lambda / Lam exactly (the rainbow), v
/// Gaussian of sd sigma(lambda); y_n = 0 at the band ends. Order 0: a
/// Gaussian of sd sigma(lambda_i) around the mirror, node i with its
/// trapezoid mass. The density is continuous in (u, v).
#[derive(Clone)]
pub struct RainbowLobe {
    period_nm: f64,
    coherence_um: f64,
    bins: usize,
    bin_nm: f64,
    n_max: i64,
    /// y[(n + n_max) * (bins + 1) + i]
    y: Vec<f64>,
    /// Cumulative sampling masses, same layout: segment [i, i+1] for n != 0
    /// (i < bins), node i for n = 0 (searched by bisection: hundreds of
    /// cells for a compact disc).
    cdf: Vec<f64>,
    /// Order 0's Gaussians for the pdf, widest (last node) first: [1 / (2
    /// s_i^2), mass_i / (2 pi s_i^2)] (no divisions in the pdf's loop).
    zero_order: Vec<[f64; 2]>,
    /// The cumulative mass at the end of each order's row, to find the row
    /// first (a small array that stays in cache) and then the cell within
    /// it (one row of `cdf`: a few cache lines, where a bisection over all
    /// of `cdf` touched a dozen).
    row_cdf: Vec<f64>,
}

/// The rainbow's Gaussian sd in u and v at lambda: 1 / (sqrt(2) k l) with
/// k = 2 pi 1000 / lambda_nm.
fn rainbow_sigma(lambda_nm: f64, coherence_um: f64) -> f64 {
    lambda_nm / (WAVENUMBER_TIMES_NM * std::f64::consts::SQRT_2 * coherence_um)
}

impl RainbowLobe {
    fn sigma(&self, lambda_nm: f64) -> f64 {
        rainbow_sigma(lambda_nm, self.coherence_um)
    }

    fn node(&self, i: usize) -> f64 {
        RGB_BAND_NM.0 + i as f64 * self.bin_nm
    }

    fn sample(&self, t: f64, r1: f64, r2: f64) -> (f64, f64) {
        let stride = self.bins + 1;
        let row = pick_cdf(&self.row_cdf, t);
        let c = row * stride + pick_cdf(&self.cdf[row * stride..(row + 1) * stride], t);
        let n = (c / stride) as i64 - self.n_max;
        let i = c % stride;
        if n == 0 {
            let s = self.sigma(self.node(i));
            return (s * inverse_normal(r1), s * inverse_normal(r2));
        }
        // Linear density from y0 to y1 over the segment: invert its CDF.
        let (y0, y1) = (self.y[c], self.y[c + 1]);
        let c_target = r1 * 0.5 * (y0 + y1);
        let disc = (y0 * y0 + 2.0 * (y1 - y0) * c_target).max(0.0);
        let denom = y0 + disc.sqrt();
        let f = if denom > 0.0 {
            (2.0 * c_target / denom).clamp(0.0, 1.0)
        } else {
            r1
        };
        let lambda = self.node(i) + f * self.bin_nm;
        (
            n as f64 * lambda / self.period_nm,
            self.sigma(lambda) * inverse_normal(r2),
        )
    }

    fn pdf_uv(&self, u: f64, v: f64) -> f64 {
        let stride = self.bins + 1;
        let mut sum = 0.0;
        // Order 0: Gaussians at the nodes, widest (last) first: once one
        // underflows, the narrower ones do too.
        let rho2 = u * u + v * v;
        for &[inv_2s2, scale] in &self.zero_order {
            let e = rho2 * inv_2s2;
            if !(e < 745.0) {
                break;
            }
            if scale > 0.0 {
                sum += scale * fast_exp(-e);
            }
        }
        // Orders n != 0 whose rainbow passes through u: lambda = Lam |u| / |n|.
        let au = u.abs();
        if au > 0.0 && au.is_finite() {
            let n_lo = (self.period_nm * au / RGB_BAND_NM.1).ceil().max(1.0);
            let n_hi = (self.period_nm * au / RGB_BAND_NM.0)
                .floor()
                .min(self.n_max as f64);
            if n_lo <= n_hi {
                let sign = u.signum() as i64;
                for n in n_lo as i64..=n_hi as i64 {
                    let lambda = self.period_nm * au / n as f64;
                    let x = ((lambda - RGB_BAND_NM.0) / self.bin_nm).max(0.0);
                    let i = (x as usize).min(self.bins - 1);
                    let f = (x - i as f64).clamp(0.0, 1.0);
                    let row = (sign * n + self.n_max) as usize * stride;
                    let y = (1.0 - f) * self.y[row + i] + f * self.y[row + i + 1];
                    if y > 0.0 {
                        let s = self.sigma(lambda);
                        let density_u = self.period_nm / n as f64;
                        let density_v =
                            fast_exp(-(v * v) / (2.0 * s * s)) / ((2.0 * PI).sqrt() * s);
                        sum += y * density_u * density_v;
                    }
                }
            }
        }
        sum
    }
}

/// Memory budget of one material's grating table, all cells built (they are
/// built on first use, so a render pays for the incident directions it
/// meets): 19 x 19 cells for the compact disc, whose variance against
/// cosine sampling (the sampling_variance example) is then within about 10%
/// of the exact per-wi weights' at 30 and 70 degrees and 3x better at cos_i
/// 0.08; with half the budget it halved at 70 degrees.
pub(super) const GRATING_TABLE_BYTES: usize = 4 << 20;
/// Grid of the table over (wi.x, wi.y) in [-1, 1]^2: cells per axis.
const GRATING_MAX_CELLS_PER_AXIS: usize = 48;
const GRATING_MIN_CELLS_PER_AXIS: usize = 2;
/// Smallest cosine of the direction at which an order's weight is taken:
/// orders more grazing than this at a cell's centre, or just below its
/// horizon (they propagate elsewhere in the cell), are weighted as if at
/// this cosine. G / w^2 grows without bound towards the rim and
/// over-weighted them (measured with the sampling_variance example, compact
/// disc in RGB: variance 7x lower at cos_i 0.08 and 1.4x lower at 30 deg
/// than with 0.02).
const GRATING_RIM_COS: f64 = 0.1;

/// Grating order weights tabulated over the incident direction. The
/// weights only steer the sampling (the pdf is exact for whatever weights),
/// so they are computed once per cell of a grid over (wi.x, wi.y), at its
/// centre, instead of for every incident direction: that was hundreds of
/// |c_n|^2 and geometry evaluations per RGB strategy, most of the cost of
/// an RGB sample of a compact disc. The orders' centres, widths and which of
/// them propagate stay exact for the actual wi. A cell gives the
/// wavelength-interpolated weights of the spectral strategy and holds the
/// whole RGB strategy (the rainbow).
pub(super) struct GratingTable {
    n_max: i64,
    bins: usize,
    pub(super) cells_per_axis: usize,
    pub(super) cells: Vec<OnceLock<GratingCell>>,
}

pub(super) struct GratingCell {
    /// Order weights without band density and Fresnel at the rainbow's
    /// wavelength nodes: [(n + n_max) * (bins + 1) + i]; 0 for orders that
    /// propagate nowhere in the cell.
    weights: Vec<f32>,
    /// The RGB strategy made from them.
    rgb: [Component<Lobe>; 1],
}

impl GratingTable {
    /// None when the orders cannot be enumerated (absurd periods).
    fn new(period_um: f64) -> Option<GratingTable> {
        // |u| <= 2 bounds every propagating order.
        let n_max_f = (2.0 * 1000.0 * period_um / RGB_BAND_NM.0).floor();
        if !(0.0..1e6).contains(&n_max_f) {
            return None;
        }
        let n_max = n_max_f as i64;
        let orders = (2 * n_max + 1) as usize;
        let bins = (RAINBOW_MAX_CELLS / orders).clamp(1, RAINBOW_MAX_BINS);
        // f32 weights, f64 rainbow densities and masses.
        let cell_bytes = orders * (bins + 1) * (4 + 8 + 8) + 256;
        let cells = (GRATING_TABLE_BYTES / cell_bytes) as f64;
        let cells_per_axis =
            (cells.sqrt() as usize).clamp(GRATING_MIN_CELLS_PER_AXIS, GRATING_MAX_CELLS_PER_AXIS);
        Some(GratingTable {
            n_max,
            bins,
            cells_per_axis,
            cells: (0..cells_per_axis * cells_per_axis)
                .map(|_| OnceLock::new())
                .collect(),
        })
    }

    fn bin_nm(&self) -> f64 {
        (RGB_BAND_NM.1 - RGB_BAND_NM.0) / self.bins as f64
    }

    /// The cell of wi (built on first use).
    fn cell(&self, fresnel: &Fresnel, model: &Periodic, wi: DVec3) -> &GratingCell {
        let n = self.cells_per_axis;
        let index = |x: f64| (((x + 1.0) * 0.5 * n as f64) as usize).min(n - 1);
        let (ix, iy) = (index(wi.x), index(wi.y));
        self.cells[iy * n + ix].get_or_init(|| {
            let centre = |i: usize| -1.0 + (i as f64 + 0.5) * 2.0 / n as f64;
            // Corner cells reach outside the disk: their centre moves onto
            // the rim.
            let wi_centre = within_rim(centre(ix), centre(iy));
            let weights = self.cell_weights(model, wi_centre);
            let rgb = [self.rainbow(fresnel, model, wi_centre.z, &weights)];
            GratingCell { weights, rgb }
        })
    }

    /// Weights at the cell centre wi of every order that propagates for
    /// some incident direction of the cell (its centre direction is then
    /// within the cell's half diagonal of the disk): exact at every
    /// RAINBOW_WEIGHT_STEP-th node and interpolated linearly in between
    /// where both neighbours carry weight (|c_n|^2 and G vary slowly over
    /// a few bins), exact elsewhere.
    fn cell_weights(&self, model: &Periodic, wi: DVec3) -> Vec<f32> {
        let p = &model.surface;
        let (lo, bins, n_max) = (RGB_BAND_NM.0, self.bins, self.n_max);
        let (bin_nm, stride) = (self.bin_nm(), bins + 1);
        let period_nm = 1000.0 * p.period_um();
        let margin = std::f64::consts::SQRT_2 / self.cells_per_axis as f64;
        let half = (1.0 - wi.y * wi.y).max(0.0).sqrt() + margin;
        let propagating = |i: usize| {
            let scale = period_nm / (lo + i as f64 * bin_nm);
            let first = (((-wi.x - half) * scale).ceil() as i64).max(-n_max);
            let last = (((-wi.x + half) * scale).floor() as i64).min(n_max);
            first..=last
        };
        let weight_at = |n: i64, i: usize| {
            let lambda = lo + i as f64 * bin_nm;
            let u_n = n as f64 * lambda / period_nm;
            model.order_weight(n, wi, rim_direction(wi, u_n), lambda)
        };
        let orders = (2 * n_max + 1) as usize;
        let mut w = vec![0.0; orders * stride];
        let coarse = |i: usize| i.is_multiple_of(RAINBOW_WEIGHT_STEP) || i == bins;
        for i in (0..stride).filter(|&i| coarse(i)) {
            for n in propagating(i) {
                w[(n + n_max) as usize * stride + i] = weight_at(n, i);
            }
        }
        for i in (0..stride).filter(|&i| !coarse(i)) {
            let i0 = i - i % RAINBOW_WEIGHT_STEP;
            let i1 = (i0 + RAINBOW_WEIGHT_STEP).min(bins);
            let t = (i - i0) as f64 / (i1 - i0) as f64;
            for n in propagating(i) {
                let row = (n + n_max) as usize * stride;
                let (w0, w1) = (w[row + i0], w[row + i1]);
                w[row + i] = if w0 > 0.0 && w1 > 0.0 {
                    w0 + t * (w1 - w0)
                } else {
                    weight_at(n, i)
                };
            }
        }
        w.into_iter().map(|x| x as f32).collect()
    }

    /// The RGB strategy: per order n, y_n(lambda_i) = band density x F^2 x
    /// weight at the wavelength nodes, linear in between; the rainbows (n !=
    /// 0) fall to 0 at the band ends so that the density stays continuous
    /// in (u, v).
    fn rainbow(
        &self,
        fresnel: &Fresnel,
        model: &Periodic,
        cos_i: f64,
        w: &[f32],
    ) -> Component<Lobe> {
        let p = &model.surface;
        let (lo, bins, n_max) = (RGB_BAND_NM.0, self.bins, self.n_max);
        let (bin_nm, stride) = (self.bin_nm(), bins + 1);
        let orders = (2 * n_max + 1) as usize;
        let band_density = rainbow_band_density(bins);
        let mut y = vec![0.0; orders * stride];
        for i in 0..stride {
            let band =
                band_density[i] * model.order_reflectance(fresnel, cos_i, lo + i as f64 * bin_nm);
            if !(band > 0.0) {
                continue;
            }
            for row in 0..orders {
                if row as i64 != n_max && (i == 0 || i == bins) {
                    continue;
                }
                y[row * stride + i] = band * w[row * stride + i] as f64;
            }
        }
        let mut cell = vec![0.0; orders * stride];
        for row in 0..orders {
            let r = row * stride;
            if row as i64 == n_max {
                for i in 0..stride {
                    let end = if i == 0 || i == bins { 0.5 } else { 1.0 };
                    cell[r + i] = end * bin_nm * y[r + i];
                }
            } else {
                for i in 0..bins {
                    cell[r + i] = 0.5 * bin_nm * (y[r + i] + y[r + i + 1]);
                }
            }
        }
        let total: f64 = cell.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return Component::cosine_only();
        }
        y.iter_mut().for_each(|p| *p /= total);
        let row0 = n_max as usize * stride;
        let zero_order = (0..stride)
            .rev()
            .map(|i| {
                let s = rainbow_sigma(lo + i as f64 * bin_nm, p.coherence_um());
                let mass = cell[row0 + i] / total;
                [1.0 / (2.0 * s * s), mass / (2.0 * PI * s * s)]
            })
            .collect();
        let mut acc = 0.0;
        let cdf: Vec<f64> = cell
            .iter()
            .map(|p| {
                acc += p / total;
                acc
            })
            .collect();
        let row_cdf = (0..orders).map(|row| cdf[row * stride + bins]).collect();
        let p_coh = model.cover_reflectance(cos_i);
        Component::new(
            p_coh,
            1.0 - p_coh,
            Some(Lobe::Rainbow(Box::new(RainbowLobe {
                period_nm: 1000.0 * p.period_um(),
                coherence_um: p.coherence_um(),
                bins,
                bin_nm,
                n_max,
                y,
                cdf,
                row_cdf,
                zero_order,
            }))),
        )
    }

    /// Order n's weight at lambda_nm from the cell's nodes (0 outside the
    /// tabulated orders).
    fn weight(&self, cell: &GratingCell, n: i64, lambda_nm: f64) -> f64 {
        if n.abs() > self.n_max {
            return 0.0;
        }
        let x = ((lambda_nm - RGB_BAND_NM.0) / self.bin_nm()).clamp(0.0, self.bins as f64);
        let i = (x as usize).min(self.bins - 1);
        let f = x - i as f64;
        let row = (n + self.n_max) as usize * (self.bins + 1);
        let (w0, w1) = (
            cell.weights[row + i] as f64,
            cell.weights[row + i + 1] as f64,
        );
        w0 + f * (w1 - w0)
    }

    pub fn memory_bytes(&self) -> usize {
        let cell = |c: &GratingCell| {
            c.weights.len() * 4
                + match c.rgb.first().and_then(|c| c.lobe.as_ref()) {
                    Some(Lobe::Rainbow(r)) => {
                        (r.y.len() + r.cdf.len() + 2 * r.zero_order.len() + r.row_cdf.len()) * 8
                    }
                    _ => 0,
                }
        };
        self.cells.len() * std::mem::size_of::<OnceLock<GratingCell>>()
            + self
                .cells
                .iter()
                .filter_map(|c| c.get())
                .map(cell)
                .sum::<usize>()
    }
}

impl Periodic {
    /// The grating table, made on first use (cells are built lazily).
    pub(super) fn grating_table(&self) -> Option<&GratingTable> {
        self.grating
            .get_or_init(|| GratingTable::new(self.surface.period_um()))
            .as_ref()
    }

    /// The one-wavelength strategy at unit wi above the horizon.
    pub(super) fn component(
        &self,
        shading: &Shading,
        wi: DVec3,
        lambda_nm: f64,
    ) -> Component<Lobe> {
        if !(lambda_nm.is_finite() && crate::spectrum::in_band(lambda_nm)) {
            return Component::cosine_only();
        }
        grating_component(self, shading.fresnel, wi, lambda_nm)
    }

    /// The RGB strategy at unit wi above the horizon: held by the table's
    /// cell (the rainbow), borrowed.
    pub(super) fn rgb_strategy(&self, shading: &Shading, wi: DVec3) -> Components<'_, Lobe> {
        match self.grating_table() {
            Some(table) => Components::Shared(&table.cell(shading.fresnel, self, wi).rgb),
            None => Components::Local(smallvec![Component::cosine_only()]),
        }
    }
}

/// A grating, one wavelength: the orders propagating for wi (centre
/// direction above the horizon), weighted by the table's weights
/// (`order_weight` where the table has none), each a Gaussian of sd
/// 1 / (sqrt(2) k l) in u and v.
fn grating_component(
    model: &Periodic,
    fresnel: &Fresnel,
    wi: DVec3,
    lambda_nm: f64,
) -> Component<Lobe> {
    let p = &model.surface;
    let Some(table) = model.grating_table() else {
        return Component::cosine_only();
    };
    let k = wavenumber_per_um(lambda_nm);
    let du = lambda_nm / (1000.0 * p.period_um());
    let sigma = 1.0 / (std::f64::consts::SQRT_2 * k * p.coherence_um());
    // Centres inside the unit disk: |-wi.x - n du| < sqrt(1 - wi.y^2).
    let half = (1.0 - wi.y * wi.y).max(0.0).sqrt();
    let n_lo = ((-wi.x - half) / du).ceil();
    let n_hi = ((-wi.x + half) / du).floor();
    if !(n_lo <= n_hi && (n_hi - n_lo) < 1e7) {
        return Component::cosine_only();
    }
    let (n_lo, n_hi) = (n_lo as i64, n_hi as i64);
    // Rigorous efficiencies change faster over the incidence than a cell
    // (anomalies): read at wi itself, every order at once (about a
    // microsecond).
    let cell = model
        .rigorous
        .is_none()
        .then(|| table.cell(fresnel, model, wi));
    let rigorous = model.rigorous.as_ref().map(|r| {
        let t = r.table();
        let mut all = vec![0.0; (t.m_max - t.m_min + 1) as usize];
        t.efficiencies(lambda_nm, -wi.x, -wi.y, &mut all);
        (t.m_min, all)
    });
    let mut prob: Vec<f64> = (n_lo..=n_hi)
        .map(|n| {
            if let Some((m_min, all)) = &rigorous {
                // Stam's order n is the solver's -n.
                let w = all.get((-n - m_min) as usize).copied().unwrap_or(0.0);
                return if w.is_finite() && w > 0.0 { w } else { 0.0 };
            }
            let w = cell.map_or(0.0, |cell| table.weight(cell, n, lambda_nm));
            if w > 0.0 {
                w
            } else {
                let wo = uv_to_direction(wi, n as f64 * du, 0.0);
                wo.map_or(0.0, |wo| model.order_weight(n, wi, wo, lambda_nm))
            }
        })
        .collect();
    let total: f64 = prob.iter().sum();
    if !(total > 0.0 && total.is_finite()) {
        return Component::cosine_only();
    }
    prob.iter_mut().for_each(|p| *p /= total);
    let p_coh = model.cover_reflectance(wi.z);
    Component::new(
        p_coh,
        1.0 - p_coh,
        Some(Lobe::Orders(OrdersLobe {
            du,
            sigma,
            n_lo,
            prob,
        })),
    )
}

impl Periodic {
    /// Order n's sampling weight at unit wi for its centre direction wo,
    /// without the Fresnel term at the incidence (`order_reflectance`):
    /// Stam's `order_weight`, or a rigorous grating's efficiency (which
    /// includes the metal's reflection).
    fn order_weight(&self, n: i64, wi: DVec3, wo: DVec3, lambda_nm: f64) -> f64 {
        match &self.rigorous {
            None => order_weight(wi, wo, lambda_nm, 1.0, |beta| {
                self.surface.order_power(n, beta)
            }),
            Some(r) => {
                // At wi, or where the order does not propagate from wi (a
                // cell's centre near its horizon), from its centre direction
                // wo back (reciprocity): an order that carries light
                // somewhere in the cell keeps a weight.
                let t = r.table();
                let w = t
                    .efficiency(lambda_nm, -wi.x, -wi.y, -n)
                    .max(t.efficiency(lambda_nm, -wo.x, -wo.y, -n));
                if w.is_finite() && w > 0.0 {
                    w
                } else {
                    0.0
                }
            }
        }
    }

    /// The reflectance that multiplies the order weights at the incidence
    /// cosine: Fresnel's for Stam's orders, 1 for rigorous ones.
    fn order_reflectance(&self, fresnel: &Fresnel, cos_i: f64, lambda_nm: f64) -> f64 {
        match self.rigorous {
            None => fresnel.reflectance(cos_i, lambda_nm),
            Some(_) => 1.0,
        }
    }
}

/// Direction of a grating order's centre (u, v) = (u_n, 0) for wi, moved
/// onto the rim (cosine GRATING_RIM_COS) when it is below it.
fn rim_direction(wi: DVec3, u_n: f64) -> DVec3 {
    within_rim(-wi.x - u_n, -wi.y)
}

/// The direction over (x, y), moved radially onto the rim (cosine
/// GRATING_RIM_COS) when it lies beyond it.
pub(super) fn within_rim(mut x: f64, mut y: f64) -> DVec3 {
    let (r, r_max) = (
        (x * x + y * y).sqrt(),
        (1.0 - GRATING_RIM_COS.powi(2)).sqrt(),
    );
    if r > r_max {
        x *= r_max / r;
        y *= r_max / r;
    }
    DVec3::new(x, y, (1.0 - x * x - y * y).max(0.0).sqrt())
}

/// Weight of a grating order whose centre direction is wo, at one
/// wavelength: |c_n(k w)|^2 F^2 min(G / w^2, cap). An estimate of the
/// order's share of the albedo; `reflectance` is F^2 at the incidence cosine
/// (its variation over the orders only costs variance).
fn order_weight(
    wi: DVec3,
    wo: DVec3,
    lambda_nm: f64,
    reflectance: f64,
    order_power: impl Fn(f64) -> f64,
) -> f64 {
    // G / w^2 of geometry::PairGeometry, for unit wi and wo.
    let one_plus_dot = 1.0 + wi.dot(wo);
    let w = wi.z + wo.z;
    let gw2 = (one_plus_dot * one_plus_dot / (wi.z * wo.z * w * w)).min(GW2_CAP);
    let beta = -wavenumber_per_um(lambda_nm) * w;
    let weight = order_power(beta) * reflectance * gw2;
    if weight.is_finite() && weight > 0.0 {
        weight
    } else {
        0.0
    }
}

/// `band_density` at the rainbow's wavelength nodes for `bins` bins (each
/// value is eight Gaussians; a rainbow is built per strategy).
fn rainbow_band_density(bins: usize) -> &'static [f64] {
    static TABLES: OnceLock<Vec<Vec<f64>>> = OnceLock::new();
    let tables = TABLES.get_or_init(|| {
        let (lo, hi) = RGB_BAND_NM;
        (0..=RAINBOW_MAX_BINS)
            .map(|b| {
                let b = b.max(1);
                let bin_nm = (hi - lo) / b as f64;
                (0..=b)
                    .map(|i| band_density(lo + i as f64 * bin_nm))
                    .collect()
            })
            .collect()
    });
    &tables[bins.clamp(1, RAINBOW_MAX_BINS)]
}

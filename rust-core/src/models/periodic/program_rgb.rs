//! The RGB program of gratings (see program.rs): `kernel_rgb_with` as array
//! operations, order by order as natively.
//!
//! Narrow peaks (s <= RGB_BROAD_SIGMA; s is the pair's, shared by every
//! order): the orders of `orders_in_band`, unrolled to the most the band
//! can hold for the material (`RgbPlan::narrow_orders`) and masked by the
//! native tail tests; each order's slowly varying factor S(nu) = F^2 nu^2
//! |c_n(2 pi nu w)|^2 is the native quadratic through the same three
//! nodes, and its integral against the Gaussian peak and the matching
//! functions, sum_p a_p M_p(mu, s), comes from the Gaussian-smoothed weight
//! W~(mu, t = s^2) = (W * N_s)(mu): M_0 = sqrt(2 pi) s W~, M_1 = sqrt(2 pi)
//! s t dW~/dmu and M_2 = sqrt(2 pi) s (t W~ + 2 t^2 dW~/dt) (Stein's
//! identity and the heat equation dW~/dt = W~''/2). W~ is tabulated here
//! (`SmoothedWeight`): exact moments of the piecewise-linear 1 nm weight on
//! levels of t, each a uniform grid in mu, as ln E and the ratios W~_c / E
//! with E = X + Y + Z smoothed alike (positive: the exponential tails of
//! the band are linear in ln E, so that the interpolation keeps them, and
//! the ratios vary slowly), with their exact slopes in mu; within a level
//! linear in mu, or, in a program that reads the period (which moves mu),
//! a cubic Hermite in the values and slopes (C1); linear in t between two
//! levels. Where the native path takes the 3-point Gauss-Hermite rule
//! on the weight (peaks narrower than a quarter nanometre) the table is the
//! exact value the rule approximates.
//!
//! Broad peaks (s > RGB_BROAD_SIGMA, near the mirror direction): the native
//! 32-node rule over the orders that can be broad for the material (order
//! 0 alone for the compact disc).
//!
//! The energy scaling of "energy": "conserving" (a factor per wavelength,
//! `FactorProgram`) multiplies F^2 where the native path multiplies
//! `Shading::pair_factor`: at each order's three fit nodes and at the
//! broad rule's nodes.

use super::program::{rect_s2, PowerAt, PowerProgram, ProfileProgram, RectOrder};
use super::{Periodic, PeriodicSurface, RGB_BROAD_SIGMA, RGB_PEAK_HALF_WIDTH_SIGMAS};
use super::{RGB_SMOOTH_NODES, RGB_TAIL_EXPONENT};
use crate::models::{FactorProgram, Shading};
use crate::optics::fresnel::Fresnel;
use crate::optics::program::PairProgram;
use crate::program::{Builder, Mask, ParamId, Table, Value};
use crate::spectrum;
use std::f64::consts::{PI, SQRT_2};
use std::sync::OnceLock;

const NU_LO: f64 = 1000.0 / spectrum::LAMBDA_MAX_NM;
const NU_HI: f64 = 1000.0 / spectrum::LAMBDA_MIN_NM;

/// The most narrow orders an RGB program unrolls (periods up to ~20 um);
/// beyond, the material has no RGB program.
pub const MAX_RGB_ORDERS: usize = 64;

/// The smoothed weight's finest level (narrower peaks use it: their W~
/// differs from the finest level's by ~s |slope jumps| of W, below 1e-3).
const S_TABLE_MIN: f64 = 2.5e-4;
/// Levels: t doubles up to LEVEL_FINE_T (narrow peaks, whose W~ changes
/// little with t: the 1 nm structure is all there is to smooth), then grows
/// by LEVEL_T_RATIO until the step reaches LEVEL_DT_MAX (the band's
/// exponential tails curve ln W~ in t).
const LEVEL_FINE_T: f64 = 1.6e-5;
const LEVEL_T_RATIO: f64 = SQRT_2;
const LEVEL_DT_MAX: f64 = 2.5e-4;
/// Grid step in mu: s / 2, at most this.
const LEVEL_H_MAX: f64 = 0.002;
/// Each level covers the band and this many s beyond (a peak reaching the
/// band's e^-40 has its centre within sqrt(80) s of it).
const LEVEL_MARGIN_SIGMAS: f64 = 9.0;
const MAX_LEVELS: usize = 128;
/// Values per grid point: ln E and the three ratios, then their slopes in
/// mu (POINT of each).
const POINT: usize = 4;
const STRIDE: usize = 2 * POINT;

/// Columns of the metals' reflectance table over wavenumber, rows over
/// sqrt(cos) (as the native grid).
const FRESNEL_NU_STEPS: usize = 160;
const FRESNEL_COS_STEPS: usize = 64;

/// One level of the smoothed weight.
struct Level {
    t: f64,
    mu0: f64,
    h: f64,
    /// [ln E, W~_R / E, W~_G / E, W~_B / E] at mu0 + i h, then their
    /// derivatives in mu.
    points: Vec<[f32; STRIDE]>,
}

/// t of level k.
fn level_t(k: usize) -> f64 {
    let mut t = S_TABLE_MIN * S_TABLE_MIN;
    for _ in 0..k {
        let ratio = if t < LEVEL_FINE_T { 2.0 } else { LEVEL_T_RATIO };
        t += (t * (ratio - 1.0)).min(LEVEL_DT_MAX);
    }
    t
}

/// The first level at or above t (MAX_LEVELS - 1 beyond the last).
fn level_at_or_above(t: f64) -> usize {
    (0..MAX_LEVELS)
        .find(|&k| level_t(k) >= t)
        .unwrap_or(MAX_LEVELS - 1)
}

/// The 1 nm weight per wavenumber at its nodes nu_k = 1000 / (830 - k),
/// and the positive combination E of its channels (X + Y + Z).
fn weight_nodes() -> &'static (Vec<f64>, Vec<[f64; 4]>) {
    static NODES: OnceLock<(Vec<f64>, Vec<[f64; 4]>)> = OnceLock::new();
    NODES.get_or_init(|| {
        let m = spectrum::XYZ_TO_LINEAR_SRGB;
        let n = (spectrum::LAMBDA_MAX_NM - spectrum::LAMBDA_MIN_NM) as usize;
        // W_c = (M xyz)_c D65 / norm_c: xyz = M^-1 (norm .* W), so that
        // X + Y + Z = sum_c beta_c W_c.
        let mut norm = [0.0; 3];
        for i in 0..=n {
            let l = spectrum::LAMBDA_MIN_NM + i as f64;
            let end = if i == 0 || i == n { 0.5 } else { 1.0 };
            let (x, d) = (spectrum::cie_xyz(l), spectrum::d65(l));
            for (c, nc) in norm.iter_mut().enumerate() {
                *nc += end * d * (m[c][0] * x[0] + m[c][1] * x[1] + m[c][2] * x[2]);
            }
        }
        let inv = inverse3(&m);
        let beta: [f64; 3] =
            std::array::from_fn(|c| (0..3).map(|k| inv[k][c]).sum::<f64>() * norm[c]);
        let nu: Vec<f64> = (0..=n)
            .map(|k| 1000.0 / (spectrum::LAMBDA_MAX_NM - k as f64))
            .collect();
        let w = nu
            .iter()
            .map(|&x| {
                let w = spectrum::srgb_weight_per_wavenumber(x.clamp(NU_LO, NU_HI));
                [
                    w[0],
                    w[1],
                    w[2],
                    beta[0] * w[0] + beta[1] * w[1] + beta[2] * w[2],
                ]
            })
            .collect();
        (nu, w)
    })
}

fn inverse3(m: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            let (r0, r1) = ((j + 1) % 3, (j + 2) % 3);
            let (c0, c1) = ((i + 1) % 3, (i + 2) % 3);
            (m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0]) / det
        })
    })
}

/// (W * N_s)(mu) for the channels and E: the exact integral of the
/// piecewise-linear (in nu) weight against the normalised Gaussian, cell by
/// cell (erf), within 9 s of mu; and its derivative in mu, (W' * N_s)(mu):
/// the cells' slopes against the same Gaussian.
fn smoothed_weight_with_slope(mu: f64, s: f64) -> ([f64; 4], [f64; 4]) {
    let (nu, w) = weight_nodes();
    let (mut out, mut slope_out) = ([0.0; 4], [0.0; 4]);
    let (lo, hi) = (mu - LEVEL_MARGIN_SIGMAS * s, mu + LEVEL_MARGIN_SIGMAS * s);
    if hi <= nu[0] || lo >= nu[nu.len() - 1] {
        return (out, slope_out);
    }
    let k_lo = nu.partition_point(|&x| x <= lo).saturating_sub(1);
    let k_hi = nu
        .partition_point(|&x| x < hi)
        .min(nu.len() - 1)
        .max(k_lo + 1);
    let inv = 1.0 / (SQRT_2 * s);
    let node = |k: usize| {
        let x = nu[k] - mu;
        let z = x * inv;
        (x, (-z * z).exp(), libm::erfc(z.abs()), z)
    };
    let (mut a, mut ga, mut ea, mut za) = node(k_lo);
    for k in k_lo..k_hi {
        let (b, gb, eb, zb) = node(k + 1);
        let derf = if za >= 0.0 {
            ea - eb
        } else if zb <= 0.0 {
            eb - ea
        } else {
            2.0 - ea - eb
        };
        // Normalised: int N_s(x) dx and int x N_s(x) dx over the cell.
        let i0 = 0.5 * derf;
        let i1 = s / (2.0 * PI).sqrt() * (ga - gb);
        for c in 0..4 {
            let slope = (w[k + 1][c] - w[k][c]) / (b - a);
            out[c] += (w[k][c] - slope * a) * i0 + slope * i1;
            slope_out[c] += slope * i0;
        }
        (a, ga, ea, za) = (b, gb, eb, zb);
    }
    (out, slope_out)
}

fn level(k: usize) -> &'static Level {
    static LEVELS: [OnceLock<Level>; MAX_LEVELS] = [const { OnceLock::new() }; MAX_LEVELS];
    LEVELS[k].get_or_init(|| {
        let t = level_t(k);
        let s = t.sqrt();
        let h = (0.5 * s).min(LEVEL_H_MAX);
        let mu0 = NU_LO - LEVEL_MARGIN_SIGMAS * s;
        let count = ((NU_HI - NU_LO + 2.0 * LEVEL_MARGIN_SIGMAS * s) / h).ceil() as usize + 2;
        let points = (0..count)
            .map(|i| {
                let (m, dm) = smoothed_weight_with_slope(mu0 + i as f64 * h, s);
                if m[3] > 1e-30 {
                    let e = m[3];
                    let de = dm[3] / e;
                    let r = |c: usize| m[c] / e;
                    let dr = |c: usize| (dm[c] - r(c) * dm[3]) / e;
                    [
                        e.ln() as f32,
                        r(0) as f32,
                        r(1) as f32,
                        r(2) as f32,
                        de as f32,
                        dr(0) as f32,
                        dr(1) as f32,
                        dr(2) as f32,
                    ]
                } else {
                    [-69.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
                }
            })
            .collect();
        Level { t, mu0, h, points }
    })
}

/// What a material's RGB program unrolls.
struct RgbPlan {
    narrow_orders: usize,
    /// Orders -broad..=broad can be broad.
    broad: i64,
    /// Levels of the smoothed weight the narrow peaks need.
    levels: std::ops::RangeInclusive<usize>,
}

/// How far the period may move from the built one in a program that reads
/// it (`RgbPlan::new`): beyond the 2% a renderer moves it without a
/// rebuild, and the parameter tests' sweeps of +-5%.
const PERIOD_REACH: f64 = 1.06;

impl RgbPlan {
    /// The plan for the material; `period_reach` > 1: for every period up
    /// to that factor of the built one (more orders can fall in the band,
    /// and narrower peaks, as the period grows).
    fn new(p: &PeriodicSurface, period_reach: f64) -> Option<RgbPlan> {
        let (l, lam) = (p.coherence_um, p.period_um * period_reach);
        let slack = RGB_TAIL_EXPONENT.sqrt() / (2.0 * PI * l);
        // orders_in_band: an interval of length (|u| (nu_hi - nu_lo) + 2
        // slack) Lam, |u| <= 2.
        let length = (2.0 * (NU_HI - NU_LO) + 2.0 * slack) * lam;
        let narrow_orders = length.floor() as usize + 1;
        if narrow_orders > MAX_RGB_ORDERS {
            return None;
        }
        // Broad: s > RGB_BROAD_SIGMA, rho < 1 / (2 sqrt 2 pi l sigma); an
        // order passes the tail test where |nu u - n / Lam| <= slack for
        // some nu of the band.
        let rho_broad = 1.0 / (2.0 * SQRT_2 * PI * l * RGB_BROAD_SIGMA);
        let broad = ((NU_HI * rho_broad + slack) * lam).floor() as i64;
        // Narrow orders n != 0 need |nu u - n / Lam| <= slack with |u| <=
        // rho: rho >= (1 / Lam - slack) / nu_hi; order 0 is never narrow
        // (its exponent at nu_lo exceeds 40 for s <= RGB_BROAD_SIGMA).
        let rho_min = ((1.0 / lam - slack) / NU_HI).max(1e-9);
        let s_of = |rho: f64| 1.0 / (2.0 * SQRT_2 * PI * l * rho);
        let s_max = s_of(rho_min).min(RGB_BROAD_SIGMA);
        let s_min = s_of(2.0);
        let lo = level_at_or_above(s_min * s_min).saturating_sub(1);
        let hi = (level_at_or_above(s_max * s_max) + 1).min(MAX_LEVELS - 1);
        Some(RgbPlan {
            narrow_orders,
            broad,
            levels: lo..=hi.max(lo + 1),
        })
    }
}

/// F^2 at the pair's cosine: one value for wavelength-flat terms, tables
/// for metals.
enum Reflectance<'a> {
    Flat(Value<'a>),
    Metal {
        /// Over (sqrt(cos) row, wavenumber column), and over (row, node of
        /// the 32-node rule).
        grid: Table,
        nodes: Table,
        row: Value<'a>,
        frac: Value<'a>,
    },
}

impl<'a> Reflectance<'a> {
    fn new(b: &'a Builder, fresnel: &Fresnel, cos: Value<'a>) -> Reflectance<'a> {
        if fresnel.is_spectrally_flat() {
            return Reflectance::Flat(fresnel.program(b, cos, b.c(550.0)));
        }
        let rows = FRESNEL_COS_STEPS + 1;
        let x_of = |r: usize| (r as f64 / FRESNEL_COS_STEPS as f64).powi(2);
        let grid = (0..rows)
            .flat_map(|r| {
                (0..=FRESNEL_NU_STEPS).map(move |c| {
                    let nu = NU_LO + (NU_HI - NU_LO) * c as f64 / FRESNEL_NU_STEPS as f64;
                    fresnel.reflectance(x_of(r), 1000.0 / nu) as f32
                })
            })
            .collect();
        let broad = PeriodicSurface::broad_rule_wavelengths();
        let nodes = (0..rows)
            .flat_map(|r| {
                broad
                    .iter()
                    .map(move |&l| fresnel.reflectance(x_of(r), l) as f32)
            })
            .collect();
        let cos = cos.finite().select(cos, 0.0);
        let x = cos.clamp(0.0, 1.0).sqrt() * FRESNEL_COS_STEPS as f64;
        let row = x.floor().min((FRESNEL_COS_STEPS - 1) as f64);
        Reflectance::Metal {
            grid: b.table(grid),
            nodes: b.table(nodes),
            frac: x - row,
            row,
        }
    }

    /// F^2 at wavenumber nu (1 for a flat term: applied at the end).
    fn at(&self, b: &'a Builder, nu: Value<'a>) -> Value<'a> {
        match self {
            Reflectance::Flat(_) => b.c(1.0),
            Reflectance::Metal {
                grid, row, frac, ..
            } => {
                let per_nu = FRESNEL_NU_STEPS as f64 / (NU_HI - NU_LO);
                let x = ((nu - NU_LO) * per_nu).clamp(0.0, FRESNEL_NU_STEPS as f64);
                let col = x.floor().min((FRESNEL_NU_STEPS - 1) as f64);
                let fc = x - col;
                let width = (FRESNEL_NU_STEPS + 1) as f64;
                let at = *row * width + col;
                let g = |o: f64| b.gather(*grid, at + o);
                let lo = g(0.0) + (g(1.0) - g(0.0)) * fc;
                let hi = g(width) + (g(width + 1.0) - g(width)) * fc;
                lo + (hi - lo) * *frac
            }
        }
    }

    /// F^2 at node j of the broad rule.
    fn at_node(&self, b: &'a Builder, j: usize) -> Value<'a> {
        match self {
            Reflectance::Flat(_) => b.c(1.0),
            Reflectance::Metal {
                nodes, row, frac, ..
            } => {
                let at = *row * RGB_SMOOTH_NODES as f64 + j as f64;
                let lo = b.gather(*nodes, at);
                let hi = b.gather(*nodes, at + RGB_SMOOTH_NODES as f64);
                lo + (hi - lo) * *frac
            }
        }
    }

    fn flat(&self) -> Option<Value<'a>> {
        match self {
            Reflectance::Flat(r) => Some(*r),
            Reflectance::Metal { .. } => None,
        }
    }
}

/// The material's levels of the smoothed weight as program tables, and the
/// pair's two levels. `cubic`: a Hermite in mu (C1: a differentiated
/// period moves mu; 16 gathers per level), else linear (8).
struct SmoothedWeight<'a> {
    cubic: bool,
    points: Table,
    /// Per level j of the pair's pair of levels: [offset, mu0, 1/h, last].
    level: [[Value<'a>; 4]; 2],
    tau: Value<'a>,
    inv_dt: Value<'a>,
}

impl<'a> SmoothedWeight<'a> {
    fn new(b: &'a Builder, plan: &RgbPlan, t: Value<'a>, cubic: bool) -> SmoothedWeight<'a> {
        let mut points = Vec::new();
        let mut meta = Vec::new();
        let mut ts = Vec::new();
        for k in plan.levels.clone() {
            let lv = level(k);
            meta.extend([
                (points.len() / STRIDE) as f32,
                lv.mu0 as f32,
                (1.0 / lv.h) as f32,
                (lv.points.len() - 1) as f32,
                lv.t as f32,
            ]);
            ts.push(lv.t);
            points.extend(lv.points.iter().flatten());
        }
        let meta = b.table(meta);
        // j: the last level at or below t (clamped to the range's ends).
        let mut j = b.c(0.0);
        for &tk in &ts[1..ts.len() - 1] {
            j = t.ge(tk).select(j + 1.0, j);
        }
        let get = |j: Value<'a>, f: usize| b.gather(meta, j * 5.0 + f as f64);
        let level = [j, j + 1.0].map(|j| std::array::from_fn(|f| get(j, f)));
        let (t0, t1) = (get(j, 4), get(j + 1.0, 4));
        let inv_dt = 1.0 / (t1 - t0);
        SmoothedWeight {
            cubic,
            points: b.table(points),
            level,
            tau: ((t - t0) * inv_dt).clamp(0.0, 1.0),
            inv_dt,
        }
    }

    /// W~, dW~/dmu and dW~/dt per channel at mu.
    fn at(&self, b: &'a Builder, mu: Value<'a>) -> [[Value<'a>; 3]; 3] {
        // Per level: the interpolated point and its slope in mu.
        let per_level = |lv: &[Value<'a>; 4]| -> ([Value<'a>; POINT], [Value<'a>; POINT]) {
            let [offset, mu0, inv_h, last] = *lv;
            let x = ((mu - mu0) * inv_h).clamp(0.0, last);
            if self.cubic {
                // Hermite between points i and i + 1 in their values and
                // slopes (per unit mu; h = 1 / inv_h).
                let i = x.floor().min(last - 1.0);
                let f = x - i;
                let at = (offset + i) * STRIDE as f64;
                let g = |k: usize| b.gather(self.points, at + k as f64);
                let h = 1.0 / inv_h;
                let (f2, f3) = (f * f, f * f * f);
                let (h00, h10) = (f3 * 2.0 - f2 * 3.0 + 1.0, f3 - f2 * 2.0 + f);
                let (h01, h11) = (f2 * 3.0 - f3 * 2.0, f3 - f2);
                let (d00, d10) = (f2 * 6.0 - f * 6.0, f2 * 3.0 - f * 4.0 + 1.0);
                let (d01, d11) = (f * 6.0 - f2 * 6.0, f2 * 3.0 - f * 2.0);
                let parts: [[Value<'a>; 4]; POINT] = std::array::from_fn(|q| {
                    let (p0, p1) = (g(q), g(STRIDE + q));
                    let (m0, m1) = (g(POINT + q) * h, g(STRIDE + POINT + q) * h);
                    [p0, m0, p1, m1]
                });
                return (
                    std::array::from_fn(|q| {
                        let [p0, m0, p1, m1] = parts[q];
                        p0 * h00 + m0 * h10 + p1 * h01 + m1 * h11
                    }),
                    std::array::from_fn(|q| {
                        let [p0, m0, p1, m1] = parts[q];
                        (p0 * d00 + m0 * d10 + p1 * d01 + m1 * d11) * inv_h
                    }),
                );
            }
            let i = x.floor().min(last - 1.0);
            let f = x - i;
            let at = (offset + i) * STRIDE as f64;
            let p0: [Value<'a>; POINT] =
                std::array::from_fn(|q| b.gather(self.points, at + q as f64));
            let p1: [Value<'a>; POINT] =
                std::array::from_fn(|q| b.gather(self.points, at + (STRIDE + q) as f64));
            (
                std::array::from_fn(|q| p0[q] + (p1[q] - p0[q]) * f),
                std::array::from_fn(|q| (p1[q] - p0[q]) * inv_h),
            )
        };
        let (v0, d0) = per_level(&self.level[0]);
        let (v1, d1) = per_level(&self.level[1]);
        let tau = self.tau;
        let q: [Value<'a>; POINT] = std::array::from_fn(|c| v0[c] + (v1[c] - v0[c]) * tau);
        let qm: [Value<'a>; POINT] = std::array::from_fn(|c| d0[c] + (d1[c] - d0[c]) * tau);
        let qt: [Value<'a>; POINT] = std::array::from_fn(|c| (v1[c] - v0[c]) * self.inv_dt);
        let e = q[0].exp();
        let w = std::array::from_fn(|c| e * q[c + 1]);
        let wm = std::array::from_fn(|c| e * qm[0].fma(q[c + 1], qm[c + 1]));
        let wt = std::array::from_fn(|c| e * qt[0].fma(q[c + 1], qt[c + 1]));
        [w, wm, wt]
    }
}

impl PowerProgram {
    /// |c_n(beta)|^2 for the RGB fits: the rect closed form, or a cubic
    /// Hermite in the table's values and first derivatives (error ~(h
    /// R)^4 / 384 ~ 4e-6 of c_n at the native step, against the quintic's
    /// 1e-9: ample for RGB, 2/3 of the loads).
    pub(super) fn power_rgb<'a>(&self, b: &'a Builder, beta: Value<'a>, n: Value<'a>) -> Value<'a> {
        match self {
            PowerProgram::Rect { .. } => {
                let at = self.at(b, beta);
                self.power(b, &at, n)
            }
            PowerProgram::Table {
                data,
                step,
                n_beta,
                n_lo,
                n_hi,
                symmetric,
                complex,
            } => {
                let pos = (beta + super::BETA_MAX) * (1.0 / step);
                let inside = pos.ge(0.0) & pos.le((*n_beta - 1) as f64);
                let pos = inside.select(pos, 0.0);
                let j = pos.floor().min((*n_beta - 2) as f64);
                let t = pos - j;
                let t2 = t * t;
                let t3 = t2 * t;
                let h = [
                    t3 * 2.0 - t2 * 3.0 + 1.0,
                    t3 - t2 * 2.0 + t,
                    t2 * 3.0 - t3 * 2.0,
                    t3 - t2,
                ];
                let width = if *complex { 6.0 } else { 3.0 };
                let stride = (n_hi - n_lo + 1) as f64 * width;
                let col = if *symmetric { n.abs() } else { n } - *n_lo as f64;
                let known = col.ge(0.0) & col.le((n_hi - n_lo) as f64) & inside;
                let at = j * stride + col.clamp(0.0, (n_hi - n_lo) as f64) * width;
                let part = |o: f64| {
                    let d = if *complex { 2.0 } else { 1.0 };
                    let g = |k: f64| b.gather(*data, at + (o + k));
                    g(0.0) * h[0] + g(d) * h[1] + g(stride) * h[2] + g(stride + d) * h[3]
                };
                let re = part(0.0);
                let p = if *complex {
                    let im = part(1.0);
                    re * re + im * im
                } else {
                    re * re
                };
                known.select(p, 0.0)
            }
        }
    }
}

/// The tail tests of `kernel_rgb_with` for order n: its exponent A_n and
/// A_n + the gap to the band within RGB_TAIL_EXPONENT; and mu.
struct OrderPeak<'a> {
    take: Mask<'a>,
    a_n: Value<'a>,
    mu: Value<'a>,
}

impl Periodic {
    pub(super) fn rgb_program<'a>(
        &self,
        b: &'a Builder,
        shading: &Shading,
        pair: &PairProgram<'a>,
        factor: Option<&dyn FactorProgram<'a>>,
    ) -> Option<[Value<'a>; 3]> {
        let p = &self.surface;
        // The period, the profile's height (and a rect's width) as
        // parameters, as in the spectral kernel; the coherence length stays
        // the built one (the smoothed weight's levels, linear in t, are
        // picked by it). A program that may see another period (not
        // `at_built`) plans for periods up to PERIOD_REACH times the built
        // one and reads the smoothed weight C1 in mu, which the period moves.
        // (Where that plan would unroll more than MAX_RGB_ORDERS, the
        // period stays a constant.)
        let reaching = (!b.at_built())
            .then(|| RgbPlan::new(p, PERIOD_REACH))
            .flatten();
        let follows_period = reaching.is_some();
        let plan = match reaching {
            Some(plan) => plan,
            None => RgbPlan::new(p, 1.0)?,
        };
        let powers = PowerProgram::new(b, p);
        let lam = if follows_period {
            b.param(ParamId::PeriodUm, p.period_um)
        } else {
            b.c(p.period_um)
        };
        let inv_lam = 1.0 / lam;
        let profile = p.profile_program(b, lam);
        // |c_n|^2 at beta for an order's part prepared once per order
        let power_rgb =
            |beta: Value<'a>, n: Value<'a>, rect: Option<RectOrder<'a>>| match (profile, rect) {
                (ProfileProgram::Rect { height, .. }, Some(r)) => r.power(rect_s2(beta, height)),
                _ => powers.power_rgb(b, profile.scaled_beta(beta), n),
            };
        let rect_order = |n: Value<'a>| match profile {
            ProfileProgram::Rect { fill, .. } => Some(RectOrder::new(fill, n)),
            ProfileProgram::Scaled(_) => None,
        };
        let (u, v, w) = (pair.u, pair.v, pair.w);
        let l = p.coherence_um;
        let two_pi_l = 2.0 * PI * l;
        let refl = Reflectance::new(b, shading.fresnel, pair.cos_half);
        // F^2 (1 when flat: applied at the end) times the factor, at a
        // wavenumber and at a node of the broad rule.
        let refl_at = |nu: Value<'a>| match (factor, refl.flat()) {
            (None, _) => refl.at(b, nu),
            (Some(f), Some(_)) => f.at(1000.0 / nu),
            (Some(f), None) => refl.at(b, nu) * f.at(1000.0 / nu),
        };
        let rule = spectrum::smooth_rule(RGB_SMOOTH_NODES);
        let refl_at_node = |j: usize| match (factor, refl.flat()) {
            (None, _) => refl.at_node(b, j),
            (Some(f), Some(_)) => f.at_nm(rule.lambda_nm[j]),
            (Some(f), None) => refl.at_node(b, j) * f.at_nm(rule.lambda_nm[j]),
        };
        let rho2 = u * u + v * v;
        let positive = rho2.gt(0.0);
        let rho2 = positive.select(rho2, 1.0);
        let inv_rho2 = 1.0 / rho2;
        // t = s^2, s = 1 / (2 sqrt 2 pi l rho).
        let t = inv_rho2 * (1.0 / (8.0 * PI * PI * l * l));
        let s = t.sqrt();
        let c_const = (4.0 * PI * l * l) / (w * w);
        let narrow = positive & s.le(RGB_BROAD_SIGMA);
        let ok = w.lt(0.0)
            & u.finite()
            & v.finite()
            & (v * (two_pi_l * NU_LO)).sq().le(RGB_TAIL_EXPONENT);
        let peak = |n: Value<'a>| -> OrderPeak<'a> {
            let a_n = (n * v * inv_lam * two_pi_l).sq() * inv_rho2;
            let mu = u * n * inv_rho2 * inv_lam;
            let nearest = mu.clamp(NU_LO, NU_HI);
            let gap = (nearest - mu).sq() / (t * 2.0);
            let take = a_n.le(RGB_TAIL_EXPONENT) & (a_n + gap).le(RGB_TAIL_EXPONENT);
            // Order 0 alone at rho = 0 (s infinite).
            let take = (positive & take) | (!positive & n.eq(0.0));
            OrderPeak { take, a_n, mu }
        };

        // Narrow peaks.
        let slack = RGB_TAIL_EXPONENT.sqrt() / two_pi_l;
        let (xa, xb) = (u * NU_LO, u * NU_HI);
        let (x0, x1) = (xa.min(xb), xa.max(xb));
        let n_first = -((slack - x0) * lam).floor(); // ceil((x0 - slack) Lam)
        let n_last = ((x1 + slack) * lam).floor();
        let table = SmoothedWeight::new(b, &plan, t, follows_period);
        let norm = s * (2.0 * PI).sqrt();
        let mut narrow_sum = [b.c(0.0); 3];
        for i in 0..plan.narrow_orders {
            let n = n_first + i as f64;
            let pk = peak(n);
            let take = pk.take & n.le(n_last) & !n.eq(0.0);
            let mu = pk.mu;
            // Significant part [a, bb] of the peak inside the band.
            let reach = s * RGB_PEAK_HALF_WIDTH_SIGMAS;
            let d0 = (-mu + NU_LO).max(0.0) + (mu - NU_HI).max(0.0);
            let r = (d0 * d0 + reach * reach).sqrt();
            let a = (mu - r).max(NU_LO);
            let bb = (mu + r).min(NU_HI);
            let delta = (s * 3f64.sqrt()).min((bb - a) * 0.5).max(1e-9);
            let c = mu.max(a + delta).min(bb - delta);
            let rect = rect_order(n);
            let s_at = |nu: Value<'a>| {
                let beta = nu * w * (2.0 * PI);
                refl_at(nu) * nu * nu * power_rgb(beta, n, rect)
            };
            let (sm, s0, sp) = (s_at(c - delta), s_at(c), s_at(c + delta));
            let inv_2d = 0.5 / delta;
            let d1 = (sp - sm) * inv_2d;
            let d2 = (sp - s0 * 2.0 + sm) * (inv_2d / delta);
            let e = c - mu;
            let a0 = s0 - d1 * e + d2 * e * e;
            let a1 = d1 - d2 * e * 2.0;
            let a2 = d2;
            let [wv, wm, wt] = table.at(b, mu);
            let scale = c_const * (-pk.a_n).exp() * norm;
            let k0 = a0 + a2 * t;
            let k1 = a1 * t;
            let k2 = a2 * t * t * 2.0;
            for ch in 0..3 {
                let term = scale * (k0 * wv[ch] + k1 * wm[ch] + k2 * wt[ch]);
                narrow_sum[ch] = narrow_sum[ch] + take.select(term, 0.0);
            }
        }

        // Broad peaks: the 32-node rule over orders -broad..=broad.
        let orders: Vec<(f64, Mask<'a>, Option<RectOrder<'a>>)> = (-plan.broad..=plan.broad)
            .map(|n| {
                let nv = b.c(n as f64);
                (n as f64, peak(nv).take, rect_order(nv))
            })
            .collect();
        let mut broad_sum = [b.c(0.0); 3];
        for (j, (&nu, weights)) in rule.nu_per_um.iter().zip(&rule.weights).enumerate() {
            let beta = w * (2.0 * PI * nu);
            let (at, s2): (Option<PowerAt>, _) = match profile {
                ProfileProgram::Rect { height, .. } => (None, Some(rect_s2(beta, height))),
                ProfileProgram::Scaled(_) => (Some(powers.at(b, profile.scaled_beta(beta))), None),
            };
            let ev = (v * (two_pi_l * nu)).sq();
            let mut sum = b.c(0.0);
            for &(n, take, rect) in &orders {
                let d = (u * nu - inv_lam * n) * two_pi_l;
                let e = d.fma(d, ev);
                let power = match (rect, s2, &at) {
                    (Some(r), Some(s2), _) => r.power(s2),
                    (_, _, Some(at)) => powers.power_const(b, at, n as i64),
                    _ => unreachable!("the powers are prepared for the profile"),
                };
                let term = power * (-e).exp();
                sum = sum + (take & e.lt(700.0)).select(term, 0.0);
            }
            let val = refl_at_node(j) * (nu * nu) * c_const * sum;
            for ch in 0..3 {
                broad_sum[ch] = broad_sum[ch] + val * weights[ch];
            }
        }
        let flat = refl.flat().unwrap_or_else(|| b.c(1.0));
        Some(std::array::from_fn(|ch| {
            let out = narrow.select(narrow_sum[ch], broad_sum[ch]) * flat;
            (ok & out.finite()).select(out, 0.0)
        }))
    }
}

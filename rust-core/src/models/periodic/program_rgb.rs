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
//! the ratios vary slowly), with their exact slopes in mu, in t and in
//! both; read linearly in mu and t, or C1 (Hermites from the slopes) along
//! the period (which moves mu) and the coherence length (which moves t)
//! where the renderer differentiates them (`SmoothedWeight`). Where the
//! native path takes the 3-point Gauss-Hermite rule
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
use super::rigorous_grid::{GridPlace, PairGrid};
use super::{Periodic, PeriodicSurface, RGB_BROAD_SIGMA, RGB_PEAK_HALF_WIDTH_SIGMAS};
use super::{RGB_SMOOTH_NODES, RGB_TAIL_EXPONENT};
use crate::models::{FactorMaker, Shading};
use crate::optics::fresnel::Fresnel;
use crate::optics::program::PairProgram;
use crate::program::lookup::low_rank;
use crate::program::special::sin_squared;
use crate::program::{Builder, Mask, ParamId, Table, Value};
use crate::spectrum;
use std::f64::consts::{PI, SQRT_2};
use std::sync::OnceLock;

const NU_LO: f64 = 1000.0 / spectrum::LAMBDA_MAX_NM;
const NU_HI: f64 = 1000.0 / spectrum::LAMBDA_MIN_NM;

/// The most narrow orders an RGB program unrolls (periods up to ~20 um);
/// beyond, the material has no RGB program.
pub const MAX_RGB_ORDERS: usize = 64;

/// Rigorous orders: the broad rule's nodes (the native rule's
/// GIVEN_BROAD_NODES cost a first render of minutes, docs/rigorous.md).
const PROGRAM_BROAD_NODES: usize = 32;

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
/// mu, in t, and in mu and t (POINT of each).
const POINT: usize = 4;
const STRIDE: usize = 4 * POINT;

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
    /// derivatives in mu, in t and in mu and t.
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

/// (W * N_s)(mu) for the channels and E, and its first three derivatives
/// in mu: the exact integral of the piecewise-linear (in nu) weight against
/// the normalised Gaussian, cell by cell (erf), within 9 s of mu; (W' *
/// N_s)(mu), the cells' slopes against the same Gaussian; and, as W'' is
/// the slopes' jumps at the nodes, the Gaussian at the nodes and its slope.
/// The weight ends at the band's ends (a jump where the matching functions
/// are not quite 0), whose terms the derivatives include.
fn smoothed_weight_derivatives(mu: f64, s: f64) -> [[f64; 4]; 4] {
    let (nu, w) = weight_nodes();
    let mut out = [[0.0; 4]; 4];
    let (lo, hi) = (mu - LEVEL_MARGIN_SIGMAS * s, mu + LEVEL_MARGIN_SIGMAS * s);
    if hi <= nu[0] || lo >= nu[nu.len() - 1] {
        return out;
    }
    let k_lo = nu.partition_point(|&x| x <= lo).saturating_sub(1);
    let k_hi = nu
        .partition_point(|&x| x < hi)
        .min(nu.len() - 1)
        .max(k_lo + 1);
    let inv = 1.0 / (SQRT_2 * s);
    let inv_t = 1.0 / (s * s);
    let node = |k: usize| {
        let x = nu[k] - mu;
        let z = x * inv;
        (x, (-z * z).exp(), libm::erfc(z.abs()), z)
    };
    let (mut a, mut ga, mut ea, mut za) = node(k_lo);
    // The ends' jumps: W(nu_0) at the start, -W(nu_last) at the end, times
    // N_s(x) and its derivatives in mu, (x / t) N_s and (x^2 / t - 1) N_s / t.
    let n_s = |x: f64| (-0.5 * x * x * inv_t).exp() / ((2.0 * PI).sqrt() * s);
    let ends = [(0, 1.0), (nu.len() - 1, -1.0)];
    for (k, sign) in ends.into_iter().filter(|&(k, _)| k >= k_lo && k <= k_hi) {
        let x = nu[k] - mu;
        let g = sign * n_s(x);
        for c in 0..4 {
            out[1][c] += w[k][c] * g;
            out[2][c] += w[k][c] * g * x * inv_t;
            out[3][c] += w[k][c] * g * (x * x * inv_t - 1.0) * inv_t;
        }
    }
    for k in k_lo..k_hi {
        let (b, gb, eb, zb) = node(k + 1);
        let derf = if za >= 0.0 {
            ea - eb
        } else if zb <= 0.0 {
            eb - ea
        } else {
            2.0 - ea - eb
        };
        // Normalised: int N_s(x) dx and int x N_s(x) dx over the cell;
        // N_s at its ends (times s^2), and d/dmu of that, x N_s(x) / s^2.
        let i0 = 0.5 * derf;
        let i1 = s / (2.0 * PI).sqrt() * (ga - gb);
        let i2 = s / (2.0 * PI).sqrt() * (a * ga - b * gb) * inv_t;
        for c in 0..4 {
            let slope = (w[k + 1][c] - w[k][c]) / (b - a);
            out[0][c] += (w[k][c] - slope * a) * i0 + slope * i1;
            out[1][c] += slope * i0;
            out[2][c] += slope * i1 * inv_t;
            out[3][c] += slope * i2 * inv_t;
        }
        (a, ga, ea, za) = (b, gb, eb, zb);
    }
    out
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
                // W~ and its slopes in mu (m1), in t (the heat equation:
                // dW~/dt = W~'' / 2) and in both (W~''' / 2).
                let [m, m1, m2, m3] = smoothed_weight_derivatives(mu0 + i as f64 * h, s);
                let (mt, mmt): ([f64; 4], [f64; 4]) = (m2.map(|x| 0.5 * x), m3.map(|x| 0.5 * x));
                let mut point = [0.0f32; STRIDE];
                if m[3] <= 1e-30 {
                    point[0] = -69.0;
                    return point;
                }
                // ln E and the ratios r_c = W~_c / E, with their slopes.
                let e = m[3];
                let (lm, lt) = (m1[3] / e, mt[3] / e);
                let lmt = mmt[3] / e - lt * lm;
                point[0] = e.ln() as f32;
                point[POINT] = lm as f32;
                point[2 * POINT] = lt as f32;
                point[3 * POINT] = lmt as f32;
                for c in 0..3 {
                    let r = m[c] / e;
                    let rm = (m1[c] - r * m1[3]) / e;
                    let rt = (mt[c] - r * mt[3]) / e;
                    let rmt = (mmt[c] - rm * mt[3] - r * mmt[3]) / e - rt * lm;
                    point[1 + c] = r as f32;
                    point[POINT + 1 + c] = rm as f32;
                    point[2 * POINT + 1 + c] = rt as f32;
                    point[3 * POINT + 1 + c] = rmt as f32;
                }
                point
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

/// How far the period and the coherence length may move from the built
/// ones in a program that reads them (`RgbPlan::new`; the period up, the
/// coherence length either way): beyond the 2% a renderer moves them
/// without a rebuild, and the parameter tests' sweeps of +-5%.
const PERIOD_REACH: f64 = 1.06;
const COHERENCE_REACH: f64 = 1.06;

impl RgbPlan {
    /// The plan for the material with the period `period_um` (its own, or
    /// the one its programs plan for, `plan_period_um`) and the coherence
    /// length `coherence_um`; `reach` > 1: for every period up to that
    /// factor of `period_um` (more orders can fall in the band, and
    /// narrower peaks, as the period grows) and every coherence length
    /// within COHERENCE_REACH of `coherence_um` (a shorter one widens the
    /// peaks' reach and their width, a longer one narrows them). The
    /// coherence length is its own even where it is differentiated: planned
    /// for its interval's shortest (`plan_coherence_um`), the sine grating of
    /// the gradient tests would unroll two more broad orders, 25% more
    /// operations and gathers (its period's interval costs 16 operations).
    fn new(reach: f64, period_um: f64, coherence_um: f64) -> Option<RgbPlan> {
        let coherence_reach = if reach > 1.0 { COHERENCE_REACH } else { 1.0 };
        let (l, lam) = (coherence_um / coherence_reach, period_um * reach);
        let l_max = coherence_um * coherence_reach;
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
        let s_of = |l: f64, rho: f64| 1.0 / (2.0 * SQRT_2 * PI * l * rho);
        let s_max = s_of(l, rho_min).min(RGB_BROAD_SIGMA);
        let s_min = s_of(l_max, 2.0);
        let lo = level_at_or_above(s_min * s_min).saturating_sub(1);
        let hi = (level_at_or_above(s_max * s_max) + 1).min(MAX_LEVELS - 1);
        Some(RgbPlan {
            narrow_orders,
            broad,
            levels: lo..=hi.max(lo + 1),
        })
    }
}

impl Periodic {
    /// Whether the material has an RGB eval program (at most
    /// MAX_RGB_ORDERS narrow orders unrolled for its built period); its RGB
    /// sampling programs exist only then (the JIT path needs all of them).
    pub(super) fn has_rgb_program(&self) -> bool {
        let p = &self.surface;
        RgbPlan::new(1.0, p.period_um, p.coherence_um).is_some()
    }
}

/// F^2 at the pair's cosine: one value for wavelength-flat terms, tables
/// for metals.
enum Reflectance<'a> {
    Flat(Value<'a>),
    Metal {
        /// Over (sqrt(cos) row, wavenumber column).
        grid: Table,
        nodes: NodeRows,
        row: Value<'a>,
        frac: Value<'a>,
    },
}

/// A metal's F^2 over (sqrt(cos) row, node of the 32-node rule).
enum NodeRows {
    /// Row by row (2 gathers per node).
    Full(Table),
    /// Its low-rank form (`lookup::low_rank`): F^2(row, j) = sum_p
    /// phi_p(row) basis_pj to NODE_RANK_TOLERANCE of the largest, P ~ 6 for
    /// the measured metals (the rows are nearly combinations of a few
    /// cosine profiles): 2 P gathers of phi, then P multiply-adds per node.
    LowRank { phi: Table, basis: Vec<Vec<f64>> },
}

/// The node rows' low-rank tolerance (of the largest F^2; reading the rows
/// linearly in sqrt(cos), 64 steps, already errs by up to 2e-4 for
/// aluminium and gold, 5e-4 for chromium), and the most terms worth their
/// multiply-adds.
const NODE_RANK_TOLERANCE: f64 = 1e-5;
const NODE_RANK_MAX: usize = 12;

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
        let nodes: Vec<f64> = (0..rows)
            .flat_map(|r| broad.iter().map(move |&l| fresnel.reflectance(x_of(r), l)))
            .collect();
        let f32s = |v: &[f64]| v.iter().map(|&x| x as f32).collect();
        let nodes = match low_rank(&nodes, rows, broad.len(), NODE_RANK_TOLERANCE) {
            Some((phi, basis)) if basis.len() <= NODE_RANK_MAX => NodeRows::LowRank {
                phi: b.table(f32s(&phi)),
                basis,
            },
            _ => NodeRows::Full(b.table(f32s(&nodes))),
        };
        let cos = cos.finite().select(cos, 0.0);
        let x = cos.clamp(0.0, 1.0).sqrt() * FRESNEL_COS_STEPS as f64;
        let row = x.floor().min((FRESNEL_COS_STEPS - 1) as f64);
        Reflectance::Metal {
            grid: b.table(grid),
            nodes,
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

    /// F^2 at the broad rule's nodes (1 for a flat term), for the region
    /// that integrates the broad peaks.
    fn at_nodes(&self, b: &'a Builder) -> Vec<Value<'a>> {
        let (nodes, row, frac) = match self {
            Reflectance::Flat(_) => return vec![b.c(1.0); RGB_SMOOTH_NODES],
            Reflectance::Metal {
                nodes, row, frac, ..
            } => (nodes, *row, *frac),
        };
        let lerp = |table: Table, width: usize, i: usize| {
            let at = row * width as f64 + i as f64;
            let lo = b.gather(table, at);
            let hi = b.gather(table, at + width as f64);
            lo + (hi - lo) * frac
        };
        match nodes {
            NodeRows::Full(table) => (0..RGB_SMOOTH_NODES)
                .map(|j| lerp(*table, RGB_SMOOTH_NODES, j))
                .collect(),
            NodeRows::LowRank { phi, basis } => {
                let phi: Vec<Value<'a>> = (0..basis.len())
                    .map(|p| lerp(*phi, basis.len(), p))
                    .collect();
                (0..RGB_SMOOTH_NODES)
                    .map(|j| {
                        let terms = phi.iter().zip(basis).map(|(&f, a)| f * a[j]);
                        terms.reduce(|x, y| x + y).expect("a rank of at least 1")
                    })
                    .collect()
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
/// pair's two levels, read linearly in mu and t (8 gathers per level; the
/// table keeps the values alone) or, along a parameter the renderer
/// differentiates, C1: a Hermite in mu from the values and their slopes in
/// mu where the period is (it moves mu; 16 gathers), a Hermite in t between
/// the levels from the values and their slopes in t where the coherence
/// length is (it moves t; 16), both from the slopes in mu and t and their
/// mixed slopes where both are (32). Hermites in mu and t keep the reading
/// C1 in both: each level's readings are C1 in mu, and two pairs of levels
/// share their values and t-slopes where t crosses a level.
struct SmoothedWeight<'a> {
    mu_cubic: bool,
    t_cubic: bool,
    /// The fields the table keeps of each point's (`Level::points`), each
    /// POINT values.
    fields: Vec<usize>,
    points: Table,
    /// Per level j of the pair's pair of levels: [offset, mu0, 1/h, last].
    level: [[Value<'a>; 4]; 2],
    tau: Value<'a>,
    dt: Value<'a>,
    inv_dt: Value<'a>,
}

/// The fields of a level's point: values, their slopes in mu, in t, and in
/// mu and t.
const VALUE: usize = 0;
const SLOPE_MU: usize = 1;
const SLOPE_T: usize = 2;
const SLOPE_MU_T: usize = 3;

/// Cubic Hermite basis at f in [0, 1] (for values p0, p1 and slopes m0, m1
/// per unit step), and its derivative.
fn hermite<'a>(f: Value<'a>) -> ([Value<'a>; 4], [Value<'a>; 4]) {
    let f2 = f * f;
    (
        super::hermite::cubic_hermite_basis(f, 1.0 - f),
        [
            f2 * 6.0 - f * 6.0,
            f2 * 3.0 - f * 4.0 + 1.0,
            f * 6.0 - f2 * 6.0,
            f2 * 3.0 - f * 2.0,
        ],
    )
}

fn combine<'a>(basis: &[Value<'a>; 4], [p0, m0, p1, m1]: [Value<'a>; 4]) -> Value<'a> {
    p0 * basis[0] + m0 * basis[1] + p1 * basis[2] + m1 * basis[3]
}

/// Per field of a point: the reading and its slope in mu.
type Reading<'a> = [(Value<'a>, Value<'a>); POINT];

/// A level's cell around mu (`SmoothedWeight::cell`).
#[derive(Clone, Copy)]
struct Cell<'a> {
    at: Value<'a>,
    f: Value<'a>,
    inv_h: Value<'a>,
}

impl<'a> SmoothedWeight<'a> {
    fn new(
        b: &'a Builder,
        plan: &RgbPlan,
        t: Value<'a>,
        mu_cubic: bool,
        t_cubic: bool,
    ) -> SmoothedWeight<'a> {
        let mut fields = vec![VALUE];
        fields.extend(mu_cubic.then_some(SLOPE_MU));
        fields.extend(t_cubic.then_some(SLOPE_T));
        fields.extend((mu_cubic && t_cubic).then_some(SLOPE_MU_T));
        let stride = fields.len() * POINT;
        let mut points = Vec::new();
        let mut meta = Vec::new();
        let mut ts = Vec::new();
        for k in plan.levels.clone() {
            let lv = level(k);
            meta.extend([
                (points.len() / stride) as f32,
                lv.mu0 as f32,
                (1.0 / lv.h) as f32,
                (lv.points.len() - 1) as f32,
                lv.t as f32,
            ]);
            ts.push(lv.t);
            for p in &lv.points {
                for &f in &fields {
                    points.extend_from_slice(&p[f * POINT..(f + 1) * POINT]);
                }
            }
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
        let dt = t1 - t0;
        let inv_dt = 1.0 / dt;
        SmoothedWeight {
            mu_cubic,
            t_cubic,
            fields,
            points: b.table(points),
            level,
            tau: ((t - t0) * inv_dt).clamp(0.0, 1.0),
            dt,
            inv_dt,
        }
    }

    /// The cell of a level around mu: its first point's place in the table,
    /// the fraction of the step beyond it, and 1 / the step.
    fn cell(&self, mu: Value<'a>, lv: &[Value<'a>; 4]) -> Cell<'a> {
        let [offset, mu0, inv_h, last] = *lv;
        let x = ((mu - mu0) * inv_h).clamp(0.0, last);
        let i = x.floor().min(last - 1.0);
        Cell {
            at: (offset + i) * (self.fields.len() * POINT) as f64,
            f: x - i,
            inv_h,
        }
    }

    /// Field `field` in a level's cell (Hermite in mu from its slope field
    /// `slope`, or linear), and its slope in mu.
    fn read(&self, b: &'a Builder, cell: &Cell<'a>, field: usize, slope: usize) -> Reading<'a> {
        let Cell { at, f, inv_h } = *cell;
        let stride = (self.fields.len() * POINT) as f64;
        let column = |field: usize| self.fields.iter().position(|&x| x == field).unwrap() * POINT;
        let g = |point: f64, k: usize| b.gather(self.points, at + (point * stride + k as f64));
        let v = column(field);
        if self.mu_cubic {
            let (m, h) = (column(slope), 1.0 / inv_h);
            let (basis, slope_basis) = hermite(f);
            std::array::from_fn(|q| {
                let parts = [
                    g(0.0, v + q),
                    g(0.0, m + q) * h,
                    g(1.0, v + q),
                    g(1.0, m + q) * h,
                ];
                (combine(&basis, parts), combine(&slope_basis, parts) * inv_h)
            })
        } else {
            std::array::from_fn(|q| {
                let (p0, p1) = (g(0.0, v + q), g(1.0, v + q));
                (p0 + (p1 - p0) * f, (p1 - p0) * inv_h)
            })
        }
    }

    /// W~, dW~/dmu and dW~/dt per channel at mu, each times e^ln_scale
    /// (which joins ln E in its one exponential).
    fn at(&self, b: &'a Builder, mu: Value<'a>, ln_scale: Value<'a>) -> [[Value<'a>; 3]; 3] {
        let (q, qm, qt): ([Value<'a>; POINT], [Value<'a>; POINT], [Value<'a>; POINT]) =
            if self.t_cubic {
                // A Hermite in t of each level's values and t-slopes.
                let per_level = |lv| {
                    let cell = self.cell(mu, lv);
                    (
                        self.read(b, &cell, VALUE, SLOPE_MU),
                        self.read(b, &cell, SLOPE_T, SLOPE_MU_T),
                    )
                };
                let ((v0, t0), (v1, t1)) = (per_level(&self.level[0]), per_level(&self.level[1]));
                let (basis, slope) = hermite(self.tau);
                let dt = self.dt;
                let across = |q: usize, d: fn((Value<'a>, Value<'a>)) -> Value<'a>| {
                    [d(v0[q]), d(t0[q]) * dt, d(v1[q]), d(t1[q]) * dt]
                };
                (
                    std::array::from_fn(|q| combine(&basis, across(q, |r| r.0))),
                    std::array::from_fn(|q| combine(&basis, across(q, |r| r.1))),
                    std::array::from_fn(|q| combine(&slope, across(q, |r| r.0)) * self.inv_dt),
                )
            } else {
                let v0 = self.read(b, &self.cell(mu, &self.level[0]), VALUE, SLOPE_MU);
                let v1 = self.read(b, &self.cell(mu, &self.level[1]), VALUE, SLOPE_MU);
                let tau = self.tau;
                (
                    std::array::from_fn(|c| v0[c].0 + (v1[c].0 - v0[c].0) * tau),
                    std::array::from_fn(|c| v0[c].1 + (v1[c].1 - v0[c].1) * tau),
                    std::array::from_fn(|c| (v1[c].0 - v0[c].0) * self.inv_dt),
                )
            };
        let e = (q[0] + ln_scale).exp();
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
                let (j, t, s, inside) = super::program::table_cell(beta, *step, *n_beta);
                let h = super::hermite::cubic_hermite_basis(t, s);
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
            PowerProgram::Given { .. } => unreachable!("rigorous orders have no |c_n|^2"),
        }
    }
}

/// Rigorous orders' powers in a program: the pair grid's efficiencies at
/// the pair's (c, ky) (rigorous_grid.rs).
struct GivenPowers<'a, 'g> {
    b: &'a Builder,
    grid: &'g PairGrid,
    table: Table,
    c: Value<'a>,
    ky: Value<'a>,
}

impl<'a, 'g> GivenPowers<'a, 'g> {
    fn new(b: &'a Builder, grid: &'g PairGrid, pair: &PairProgram<'a>) -> Self {
        let (wi, wo) = (pair.wi, pair.wo);
        GivenPowers {
            b,
            grid,
            table: b.table(grid.values.clone()),
            c: (wo[0] - wi[0]) * 0.5,
            ky: (wi[1] - wo[1]) * 0.5,
        }
    }

    /// Where a wavelength lies on the grid (shared by the orders).
    fn place(&self, lambda_nm: Value<'a>) -> GridPlace<Value<'a>> {
        self.grid.place(lambda_nm, self.c, self.ky)
    }

    /// Order n's efficiency at `place`.
    fn read(&self, place: &GridPlace<Value<'a>>, n: Value<'a>) -> Value<'a> {
        let (b, table) = (self.b, self.table);
        self.grid.read_at(place, n, |i| b.gather(table, i))
    }

    /// Order n's efficiency at a wavelength.
    fn at(&self, lambda_nm: Value<'a>, n: Value<'a>) -> Value<'a> {
        self.read(&self.place(lambda_nm), n)
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
        factor: Option<FactorMaker<'_, 'a>>,
    ) -> Option<[Value<'a>; 3]> {
        self.rgb_program_with(b, Some(shading), pair, factor, None)
    }

    /// f of rigorous orders in RGB, before gamut mapping (`unfactored_rgb`):
    /// `rgb_program`'s integration with each order's power the pair grid's
    /// efficiency (and no Fresnel term, G or 1 / w^2): the quadratic fit
    /// through three wavelengths for narrow peaks, where the native path
    /// takes midpoints for the wider ones, and 32 nodes for broad peaks,
    /// where it takes 96 (docs/rigorous.md, "Programs for the JIT
    /// variants").
    pub(super) fn rigorous_rgb_program<'a>(
        &self,
        b: &'a Builder,
        pair: &PairProgram<'a>,
        grid: &PairGrid,
    ) -> Option<[Value<'a>; 3]> {
        self.rgb_program_with(b, None, pair, None, Some(grid))
    }

    /// `rgb_program` (Stam's powers times the shading's Fresnel term) or,
    /// with `given`, `rigorous_rgb_program`.
    fn rgb_program_with<'a>(
        &self,
        b: &'a Builder,
        shading: Option<&Shading>,
        pair: &PairProgram<'a>,
        factor: Option<FactorMaker<'_, 'a>>,
        given: Option<&PairGrid>,
    ) -> Option<[Value<'a>; 3]> {
        let p = &self.surface;
        // The period, the coherence length, the profile's height (and a
        // rect's width) as parameters, as in the spectral kernel. A program
        // that may see another period or coherence length (not `at_built`)
        // plans for periods up to PERIOD_REACH times the built one and
        // coherence lengths within COHERENCE_REACH of it, and reads the
        // smoothed weight C1 in mu (which the period moves) and t (which
        // the coherence length moves). (Where that plan would unroll more
        // than MAX_RGB_ORDERS, both stay constants.)
        let reaching = (!b.at_built())
            .then(|| {
                RgbPlan::new(PERIOD_REACH, p.plan_period_um(b), p.coherence_um)
                    .or_else(|| RgbPlan::new(PERIOD_REACH, p.period_um, p.coherence_um))
            })
            .flatten();
        let follows = reaching.is_some();
        let plan = match reaching {
            Some(plan) => plan,
            None => RgbPlan::new(1.0, p.period_um, p.coherence_um)?,
        };
        let powers = given.is_none().then(|| PowerProgram::new(b, p));
        // Rigorous efficiencies, tabulated for the built grating, do not
        // follow a period: it stays a constant.
        let lam = if follows && given.is_none() {
            b.param(ParamId::PeriodUm, p.period_um)
        } else {
            b.built(p.period_um)
        };
        // The coherence length's terms: 2 pi l, 1 / (8 pi^2 l^2) (t = s^2
        // per 1 / rho^2), 4 pi l^2, and 2 pi l times a number (built
        // constants where it stays).
        let l = follows.then(|| b.param(ParamId::CoherenceUm, p.coherence_um));
        let (two_pi_l, t_per_inv_rho2, four_pi_l2) = match l {
            Some(l) => {
                let l2 = l * l;
                (
                    l * (2.0 * PI),
                    1.0 / (l2 * (8.0 * PI * PI)),
                    l2 * (4.0 * PI),
                )
            }
            None => {
                let l = p.coherence_um;
                (
                    b.built(2.0 * PI * l),
                    b.built(1.0 / (8.0 * PI * PI * l * l)),
                    b.built(4.0 * PI * l * l),
                )
            }
        };
        let two_pi_l_times = |x: f64| match l {
            Some(_) => two_pi_l * x,
            None => b.built(2.0 * PI * p.coherence_um * x),
        };
        let inv_lam = 1.0 / lam;
        let profile = p.profile_program(b, lam);
        // |c_n|^2 at beta for an order's part prepared once per order
        let power_rgb =
            |beta: Value<'a>, n: Value<'a>, rect: Option<RectOrder<'a>>| match (profile, rect) {
                (ProfileProgram::Rect { height, .. }, Some(r)) => r.power(rect_s2(beta, height)),
                _ => powers.as_ref().expect("Stam's powers").power_rgb(
                    b,
                    profile.scaled_beta(beta),
                    n,
                ),
            };
        // Rigorous orders' efficiencies (the pair grid's, at the pair's
        // (c, ky)).
        let given = given.map(|grid| GivenPowers::new(b, grid, pair));
        let rect_order = |n: Value<'a>| match profile {
            ProfileProgram::Rect { fill, .. } => Some(RectOrder::new(fill, n)),
            ProfileProgram::Scaled(_) => None,
        };
        let (u, v, w) = (pair.u, pair.v, pair.w);
        let refl = shading.map(|shading| Reflectance::new(b, shading.fresnel, pair.cos_half));
        let rule = spectrum::smooth_rule(if given.is_some() {
            PROGRAM_BROAD_NODES
        } else {
            RGB_SMOOTH_NODES
        });
        let rho2 = u * u + v * v;
        let positive = rho2.gt(0.0);
        let rho2 = positive.select(rho2, 1.0);
        let inv_rho2 = 1.0 / rho2;
        // t = s^2, s = 1 / (2 sqrt 2 pi l rho).
        let t = inv_rho2 * t_per_inv_rho2;
        let s = t.sqrt();
        // k^2 l^2 / (pi w^2) = c_const nu^2 (Stam), k^2 l^2 / pi (given).
        let c_const = if given.is_some() {
            four_pi_l2
        } else {
            four_pi_l2 / (w * w)
        };
        let narrow = positive & s.le(RGB_BROAD_SIGMA);
        let ok = w.lt(0.0)
            & u.finite()
            & v.finite()
            & (v * two_pi_l_times(NU_LO)).sq().le(RGB_TAIL_EXPONENT);
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

        // Which orders each lane takes, first (a few operations per order),
        // so that lanes taking none skip the rest (most lanes: an order's
        // peak is narrow across the grooves, exp(-a_n)) and each order's
        // integration runs only where some lane of a packet takes it.
        let slack = match l {
            Some(_) => RGB_TAIL_EXPONENT.sqrt() / two_pi_l,
            None => b.built(RGB_TAIL_EXPONENT.sqrt() / (2.0 * PI * p.coherence_um)),
        };
        let (xa, xb) = (u * NU_LO, u * NU_HI);
        let (x0, x1) = (xa.min(xb), xa.max(xb));
        let n_first = -((slack - x0) * lam).floor(); // ceil((x0 - slack) Lam)
        let n_last = ((x1 + slack) * lam).floor();
        let narrow_orders: Vec<(Value<'a>, OrderPeak<'a>, Mask<'a>)> = (0..plan.narrow_orders)
            .map(|i| {
                let n = n_first + i as f64;
                let pk = peak(n);
                let take = narrow & pk.take & n.le(n_last) & !n.eq(0.0);
                (n, pk, take)
            })
            .collect();
        let broad_orders: Vec<(f64, Mask<'a>, Option<RectOrder<'a>>)> = (-plan.broad..=plan.broad)
            .map(|n| {
                let nv = b.c(n as f64);
                (n as f64, peak(nv).take, rect_order(nv))
            })
            .collect();
        let any_narrow = narrow_orders.iter().map(|o| o.2).reduce(|x, y| x | y);
        let any_broad = broad_orders.iter().map(|o| o.1).reduce(|x, y| x | y);
        let any = match (any_narrow, any_broad) {
            (Some(n), Some(w)) => n | (!narrow & w),
            (Some(n), None) => n,
            (None, Some(w)) => !narrow & w,
            (None, None) => return Some([b.c(0.0); 3]),
        };

        let flat = refl
            .as_ref()
            .and_then(|r| r.flat())
            .unwrap_or_else(|| b.c(1.0));
        let rgb = b.region(ok & any, || {
            // F^2 (1 when flat: applied at the end) times the factor, at a
            // wavenumber and at a node of the broad rule.
            let factor = factor.map(|make| make());
            let factor = factor.as_deref();
            let refl_at = |refl: &Reflectance<'a>, nu: Value<'a>| match (factor, refl.flat()) {
                (None, _) => refl.at(b, nu),
                (Some(f), Some(_)) => f.at(1000.0 / nu),
                (Some(f), None) => refl.at(b, nu) * f.at(1000.0 / nu),
            };
            let refl_at_node =
                |refl: &Reflectance<'a>, f2: &[Value<'a>], j: usize| match (factor, refl.flat()) {
                    (None, _) => f2[j],
                    (Some(f), Some(_)) => f.at_nm(rule.lambda_nm[j]),
                    (Some(f), None) => f2[j] * f.at_nm(rule.lambda_nm[j]),
                };

            // Narrow peaks, each order where some lane takes it.
            // C1 along the parameters a renderer differentiates.
            let table = SmoothedWeight::new(
                b,
                &plan,
                t,
                follows && given.is_none() && b.differentiated(ParamId::PeriodUm),
                follows && b.differentiated(ParamId::CoherenceUm),
            );
            let norm = s * (2.0 * PI).sqrt();
            let mut narrow_sum = [b.c(0.0); 3];
            for &(n, ref pk, take) in &narrow_orders {
                let terms: [Value<'a>; 3] = b.region(take, || {
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
                    let s_at = |nu: Value<'a>| match (&refl, &given) {
                        (Some(refl), _) => {
                            let beta = nu * w * (2.0 * PI);
                            refl_at(refl, nu) * nu * nu * power_rgb(beta, n, rect)
                        }
                        (None, Some(eta)) => nu * nu * eta.at(1000.0 / nu, n),
                        (None, None) => unreachable!("Stam's or given powers"),
                    };
                    let (sm, s0, sp) = (s_at(c - delta), s_at(c), s_at(c + delta));
                    let inv_2d = 0.5 / delta;
                    let d1 = (sp - sm) * inv_2d;
                    let d2 = (sp - s0 * 2.0 + sm) * (inv_2d / delta);
                    let e = c - mu;
                    let a0 = s0 - d1 * e + d2 * e * e;
                    let a1 = d1 - d2 * e * 2.0;
                    let a2 = d2;
                    // The peak's height across the grooves, e^-a_n, with
                    // the weight's E.
                    let [wv, wm, wt] = table.at(b, mu, -pk.a_n);
                    let scale = c_const * norm;
                    let k0 = a0 + a2 * t;
                    let k1 = a1 * t;
                    let k2 = a2 * t * t * 2.0;
                    std::array::from_fn(|ch| scale * (k0 * wv[ch] + k1 * wm[ch] + k2 * wt[ch]))
                });
                for ch in 0..3 {
                    narrow_sum[ch] = narrow_sum[ch] + terms[ch];
                }
            }

            // Broad peaks: the 32-node rule over orders -broad..=broad. At
            // node nu, order n's exponent is (a_u nu - b_n)^2 + a_v^2 nu^2
            // (a_u = 2 pi l u, a_v = 2 pi l v, b_n = 2 pi l n / Lambda), for
            // order 0 (a_u^2 + a_v^2) nu^2; the rect profile's s^2 is
            // sin^2((pi h w) nu); c_const and nu^2 go with the weights.
            let broad_sum = b.region(!narrow, || {
                let f2 = refl.as_ref().map(|r| r.at_nodes(b));
                let (a_u, a_v) = (u * two_pi_l, v * two_pi_l);
                let a_v2 = a_v * a_v;
                let a2 = a_u.fma(a_u, a_v2);
                let minus_b: Vec<Value<'a>> = broad_orders
                    .iter()
                    .map(|o| inv_lam * (-o.0) * two_pi_l)
                    .collect();
                let phase = match profile {
                    ProfileProgram::Rect { height, .. } => Some(w * height * PI),
                    ProfileProgram::Scaled(_) => None,
                };
                // One order: its mask applies once, to the sum.
                let single = broad_orders.len() == 1;
                let mut broad_sum = [b.c(0.0); 3];
                for (j, (&nu, weights)) in rule.nu_per_um.iter().zip(&rule.weights).enumerate() {
                    let nu2 = nu * nu;
                    let (at, s2): (Option<PowerAt>, _) = match (phase, &powers) {
                        _ if given.is_some() => (None, None),
                        (Some(phase), _) => (None, Some(sin_squared(phase * nu))),
                        (None, Some(powers)) => {
                            let beta = w * (2.0 * PI * nu);
                            (Some(powers.at(b, profile.scaled_beta(beta))), None)
                        }
                        (None, None) => unreachable!("Stam's powers"),
                    };
                    // The node's place on the pair grid, shared by the orders.
                    let place_j = given.as_ref().map(|eta| eta.place(b.c(rule.lambda_nm[j])));
                    let mut sum = b.c(0.0);
                    for (&(n, take, rect), &minus_b) in broad_orders.iter().zip(&minus_b) {
                        let e = if n == 0.0 {
                            a2 * nu2
                        } else {
                            let d = a_u.fma(nu, minus_b);
                            d.fma(d, a_v2 * nu2)
                        };
                        let power = match (rect, s2, &at, &given) {
                            (_, _, _, Some(eta)) => {
                                eta.read(place_j.as_ref().expect("given"), b.c(n))
                            }
                            (Some(r), Some(s2), _, _) => r.power(s2),
                            (_, _, Some(at), _) => powers
                                .as_ref()
                                .expect("Stam's powers")
                                .power_const(b, at, n as i64),
                            _ => unreachable!("the powers are prepared for the profile"),
                        };
                        let term = power * (-e).exp();
                        sum = sum + if single { term } else { take.select(term, 0.0) };
                    }
                    let val = match (&refl, &f2) {
                        (Some(refl), Some(f2)) => refl_at_node(refl, f2, j) * sum,
                        _ => sum,
                    };
                    for ch in 0..3 {
                        broad_sum[ch] = val.fma(weights[ch] * nu2, broad_sum[ch]);
                    }
                }
                let take = broad_orders[0].1;
                broad_sum.map(|c| {
                    let c = c * c_const;
                    if single {
                        take.select(c, 0.0)
                    } else {
                        c
                    }
                })
            });
            std::array::from_fn(|ch| narrow.select(narrow_sum[ch], broad_sum[ch]) * flat)
        });
        Some(rgb.map(|out| (ok & out.finite()).select(out, 0.0)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The smoothed weight's derivatives in mu (exact, from the weight's
    /// cells, nodes and ends) against central differences (step s / 200),
    /// and its slope in t (the heat equation, dW~/dt = W~'' / 2) against a
    /// difference in t, over the band and at widths from the finest level's
    /// to the broad peaks'.
    #[test]
    fn smoothed_weight_derivatives_match_differences() {
        let mut worst = [0.0f64; 4];
        for s in [3e-4, 1e-3, 4e-3, 1.5e-2] {
            for j in 0..40 {
                let mu = NU_LO + (NU_HI - NU_LO) * (j as f64 + 0.37) / 40.0;
                let d = smoothed_weight_derivatives(mu, s);
                let h = 0.005 * s;
                let (up, down) = (
                    smoothed_weight_derivatives(mu + h, s),
                    smoothed_weight_derivatives(mu - h, s),
                );
                let t = s * s;
                let (tu, td) = (
                    smoothed_weight_derivatives(mu, (t * 1.001).sqrt()),
                    smoothed_weight_derivatives(mu, (t * 0.999).sqrt()),
                );
                for c in 0..4 {
                    // Each against the scale of what it differentiates.
                    let scale = |k: usize| d[k][c].abs().max(1e-3 * d[k][3].abs()).max(1e-30);
                    for k in 0..3 {
                        let fd = (up[k][c] - down[k][c]) / (2.0 * h);
                        let e = (fd - d[k + 1][c]).abs() / (scale(k + 1) + h * scale(k) / s);
                        worst[k] = worst[k].max(e);
                    }
                    let ft = (tu[0][c] - td[0][c]) / (0.002 * t);
                    let e = (ft - 0.5 * d[2][c]).abs() / (0.5 * scale(2) + scale(0) / t * 1e-4);
                    worst[3] = worst[3].max(e);
                }
            }
        }
        println!(
            "worst relative errors: d/dmu {:.1e} {:.1e} {:.1e}, d/dt {:.1e}",
            worst[0], worst[1], worst[2], worst[3]
        );
        assert!(worst.iter().all(|&e| e < 1e-3), "{worst:?}");
    }
}

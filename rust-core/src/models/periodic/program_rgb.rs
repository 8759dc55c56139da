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
use super::smoothed_weight::{level_at_or_above, SmoothedWeight, MAX_LEVELS, NU_HI, NU_LO};
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

/// The most narrow orders an RGB program unrolls (periods up to ~20 um);
/// beyond, the material has no RGB program.
pub const MAX_RGB_ORDERS: usize = 64;

/// Rigorous orders: the broad rule's nodes (the native rule's
/// GIVEN_BROAD_NODES cost a first render of minutes, docs/rigorous.md).
const PROGRAM_BROAD_NODES: usize = 32;

/// Columns of the metals' reflectance table over wavenumber, rows over
/// sqrt(cos) (as the native grid).
const FRESNEL_NU_STEPS: usize = 160;
const FRESNEL_COS_STEPS: usize = 64;

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
                plan.levels.clone(),
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

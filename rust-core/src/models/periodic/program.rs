//! The periodic model's programs for tracing renderers (crate::program,
//! docs/jit.md): the same physics as its native path, as array operations.
//!
//! - The kernel (`kernel_program_at`): the orders near the peak of the
//!   evaluated (u, v), as `PeriodicSurface::kernel` picks them (at most
//!   three: unrolled to the material's largest count, masked), their powers
//!   |c_n|^2 from the closed form (rect) or the material's own quintic
//!   Hermite table of c_n (sine, tabulated), exported here.
//! - RGB (`reflectance_rgb_program`, program_rgb.rs): each order's peak
//!   integrated against the matching functions as `kernel_rgb_with` does.
//! - Sampling (program_sampling.rs): the orders' lobes of sampling.rs.
//! - No coherent lobe (order 0 is a Gaussian lobe like the others): the
//!   trait's zero defaults are the native values.

use super::rigorous::RigorousOrders;
use super::rigorous_grid::PairGrid;
use super::{
    Model, Periodic, PeriodicSurface, Profile, BETA_MAX, EXP_UNDERFLOW, KERNEL_TAIL_EXPONENT,
};
use crate::models::{FactorMaker, FactorProgram, SampleProgram, Shading, SurfacePrograms};
use crate::optics::fresnel::conductor_reflectance;
use crate::optics::program::{PairProgram, Vec3};
use crate::program::special::sin_squared;
use crate::program::{Builder, Mask, ParamId, Table, Value};
use crate::spectrum::WAVENUMBER_TIMES_NM;
use std::cell::OnceCell;
use std::f64::consts::PI;
use std::sync::Arc;

/// |c_n(beta)|^2 as program operations: the closed form of the rect
/// profile, or the material's table of c_n interpolated as natively
/// (`OrderTable::power`: quintic Hermite in beta).
pub(super) enum PowerProgram {
    Rect {
        height_um: f64,
        fill: f64,
    },
    Table {
        /// Per (beta sample, order): [c, h dc/dbeta, h^2/2 d2c/dbeta2],
        /// real parts only (sine) or (re, im) interleaved (tabulated).
        data: Table,
        step: f64,
        n_beta: usize,
        n_lo: i64,
        n_hi: i64,
        symmetric: bool,
        complex: bool,
    },
    /// Rigorous orders (their sampling weights): each order's pair
    /// efficiency from the grid (rigorous_grid.rs), whose table a program
    /// takes on its first read.
    Given {
        grid: Arc<PairGrid>,
        table: OnceCell<Table>,
    },
}

/// What the powers at one beta share: the rect profile's sin^2(beta h / 2),
/// or the table's row and Hermite weights.
pub(super) enum PowerAt<'a> {
    Rect {
        s2: Value<'a>,
    },
    Table {
        /// Index of the row's first entry, and the Hermite weights (h1, h2,
        /// h4, h5 without their powers of the step: the table holds them).
        row: Value<'a>,
        h: [Value<'a>; 6],
        inside: Mask<'a>,
    },
}

impl PowerProgram {
    /// The order weights of `model`'s sampling programs: its rigorous
    /// orders' pair grid where it has one, else `new`'s powers.
    pub(super) fn sampling(b: &Builder, model: &Periodic) -> PowerProgram {
        match model.rigorous.as_ref().and_then(|r| r.pair_grid_arc()) {
            Some(grid) => PowerProgram::Given {
                grid,
                table: OnceCell::new(),
            },
            None => PowerProgram::new(b, &model.surface),
        }
    }

    /// The powers of `surface` as its programs read them: a height
    /// texture's table (`texture_table`) where it has one.
    pub(super) fn new(b: &Builder, surface: &PeriodicSurface) -> PowerProgram {
        match (&surface.texture_table, &surface.model) {
            (
                None,
                Model::Rect {
                    height_um, fill, ..
                },
            ) => PowerProgram::Rect {
                height_um: *height_um,
                fill: *fill,
            },
            (Some((_, t)), _) | (None, Model::Table(t)) => {
                let complex = !t.symmetric;
                let h = t.step;
                let scale = [1.0, h, 0.5 * h * h];
                let data = t
                    .data
                    .iter()
                    .flat_map(|e| {
                        (0..3).flat_map(move |m| {
                            let c = e[m] * scale[m];
                            if complex {
                                vec![c.re as f32, c.im as f32]
                            } else {
                                vec![c.re as f32]
                            }
                        })
                    })
                    .collect();
                PowerProgram::Table {
                    data: b.table(data),
                    step: t.step,
                    n_beta: t.n_beta,
                    n_lo: t.n_lo,
                    n_hi: t.n_hi,
                    symmetric: t.symmetric,
                    complex,
                }
            }
        }
    }

    /// The shared part at beta = k w <= 0 (in the table's range for an
    /// in-band wavelength).
    pub(super) fn at<'a>(&self, b: &'a Builder, beta: Value<'a>) -> PowerAt<'a> {
        match self {
            PowerProgram::Rect { height_um, .. } => PowerAt::Rect {
                s2: sin_squared(beta * b.built(0.5 * height_um)),
            },
            PowerProgram::Table {
                step,
                n_beta,
                n_lo,
                n_hi,
                complex,
                ..
            } => {
                let (j, t, s, inside) = table_cell(beta, *step, *n_beta);
                let h = super::hermite::quintic_hermite_basis(t, s);
                let stride = (n_hi - n_lo + 1) as f64 * if *complex { 6.0 } else { 3.0 };
                let _ = b;
                PowerAt::Table {
                    row: j * stride,
                    h,
                    inside,
                }
            }
            PowerProgram::Given { .. } => unreachable!("rigorous orders have no |c_n|^2"),
        }
    }

    /// `power` for an order known when the program is built.
    pub(super) fn power_const<'a>(&self, b: &'a Builder, at: &PowerAt<'a>, n: i64) -> Value<'a> {
        match (self, at) {
            (PowerProgram::Rect { fill, .. }, PowerAt::Rect { s2 }) => {
                let (c0, c1) = if n == 0 {
                    (1.0, -4.0 * fill * (1.0 - fill))
                } else {
                    let x = PI * n as f64 * fill;
                    (0.0, 4.0 * fill * fill * (x.sin() / x).powi(2))
                };
                (*s2 * b.built(c1) + c0).max(0.0)
            }
            _ => self.power(b, at, b.c(n as f64)),
        }
    }

    /// |c_n|^2 at the prepared beta for order n (an integer-valued
    /// register); 0 for orders the native table filtered out.
    pub(super) fn power<'a>(&self, b: &'a Builder, at: &PowerAt<'a>, n: Value<'a>) -> Value<'a> {
        match (self, at) {
            (PowerProgram::Rect { fill, .. }, PowerAt::Rect { s2 }) => {
                // sinc^2(pi n f) computed, not gathered from the native
                // table (a gather loads lane by lane on a CPU: slower than
                // one sine); the same values to f32 rounding.
                RectOrder::new(b.built(*fill), n).power(*s2)
            }
            (
                PowerProgram::Table {
                    data,
                    n_lo,
                    n_hi,
                    symmetric,
                    complex,
                    ..
                },
                PowerAt::Table { row, h, inside },
            ) => {
                let col = if *symmetric { n.abs() } else { n } - *n_lo as f64;
                let known = col.ge(0.0) & col.le((n_hi - n_lo) as f64) & *inside;
                let width = if *complex { 6.0 } else { 3.0 };
                let stride = (n_hi - n_lo + 1) as f64 * width;
                let at = *row + col.clamp(0.0, (n_hi - n_lo) as f64) * width;
                let part = |offset: f64| -> Value<'a> {
                    let g = |m: f64| b.gather(*data, at + (offset + m));
                    let step = if *complex { 2.0 } else { 1.0 };
                    let next = stride + offset;
                    let gn = |m: f64| b.gather(*data, at + (next + m));
                    g(0.0) * h[0]
                        + g(step) * h[1]
                        + g(2.0 * step) * h[2]
                        + gn(0.0) * h[3]
                        + gn(step) * h[4]
                        + gn(2.0 * step) * h[5]
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
            _ => unreachable!("a power prepared for another profile"),
        }
    }
}

/// a + b = s + e exactly (Knuth's two-sum; f32 in a renderer).
pub(super) fn two_sum<'a>(a: Value<'a>, b: Value<'a>) -> (Value<'a>, Value<'a>) {
    let s = a + b;
    let bb = s - a;
    let e = (a - (s - bb)) + (b - bb);
    (s, e)
}

/// (x^2 + y^2 + z^2) - 1 of a direction that is unit to f32 rounding, to
/// about 1e-14: the products' rounding errors by FMA, the sums by two-sum.
fn norm_excess<'a>(d: &Vec3<'a>) -> Value<'a> {
    let sq = |x: Value<'a>| {
        let h = x * x;
        (h, x.fma(x, -h))
    };
    let ((hx, lx), (hy, ly), (hz, lz)) = (sq(d[0]), sq(d[1]), sq(d[2]));
    let (s1, e1) = two_sum(hx, hy);
    let (s2, e2) = two_sum(s1, hz);
    (s2 - 1.0) + (e1 + e2 + lx + ly + lz)
}

/// u and v of the pair as the native path computes them in f64 from the
/// caller's f32 directions (normalised there in f64): each as hi + lo, the
/// sum exact by two-sum and the normalisation's first-order change -d
/// (|d|^2 - 1) / 2 carried in lo. A grating's narrow peaks move by their
/// whole width per 1e-6 of u at high orders and long coherence (the
/// compact disc's: u to 6e-8 keeps f to 1e-4 on the flank of order 13);
/// the single rounding of -(wi.x + wo.x) would cost 3e-4 there.
fn exact_uv<'a>(pair: &PairProgram<'a>) -> [(Value<'a>, Value<'a>); 2] {
    let (di, d_o) = (norm_excess(&pair.wi), norm_excess(&pair.wo));
    std::array::from_fn(|c| {
        let (hi, lo) = two_sum(-pair.wi[c], -pair.wo[c]);
        let shrink = (pair.wi[c] * di + pair.wo[c] * d_o) * 0.5;
        (hi, lo + shrink)
    })
}

impl PeriodicSurface {
    /// The period the order counts of `b`'s programs are planned for:
    /// the top of its `planning_interval` where the renderer differentiates
    /// the period (an optimiser moving it then rebuilds programs of the
    /// same shape), else the period itself (no order more than it needs).
    pub(super) fn plan_period_um(&self, b: &Builder) -> f64 {
        if b.differentiated(ParamId::PeriodUm) {
            super::planning_interval(self.period_um).1
        } else {
            self.period_um
        }
    }

    /// The coherence lengths (shortest, longest) `b`'s programs are planned
    /// for: its `planning_interval` where the renderer differentiates it,
    /// else the coherence length itself.
    pub(super) fn plan_coherence_um(&self, b: &Builder) -> (f64, f64) {
        if b.differentiated(ParamId::CoherenceUm) {
            super::planning_interval(self.coherence_um)
        } else {
            (self.coherence_um, self.coherence_um)
        }
    }

    /// The most orders `orders_near` can return: an interval of length
    /// 2 reach holds at most floor(2 reach) + 1 integers.
    /// Planned for `plan_period_um` and the shortest `plan_coherence_um`,
    /// so that it changes only at the planning grid's steps where they are
    /// differentiated.
    pub(super) fn max_orders_near(&self, b: &Builder) -> usize {
        let scale = 2.0 * PI * self.plan_coherence_um(b).0 / self.plan_period_um(b);
        let e_min_max = (0.5 * scale).powi(2);
        let reach = (e_min_max + KERNEL_TAIL_EXPONENT).min(EXP_UNDERFLOW).sqrt() / scale;
        (2.0 * reach).floor() as usize + 1
    }

    /// `kernel` as program operations, at wavenumber k taken from lambda
    /// (nm): the orders of `orders_near` (`order_sum_program`, the period
    /// and the coherence length as parameters) with Stam's powers |c_n|^2.
    pub(super) fn kernel_program<'a>(
        &self,
        b: &'a Builder,
        powers: &PowerProgram,
        pair: &PairProgram<'a>,
        k: Value<'a>,
        lambda_nm: Value<'a>,
    ) -> Value<'a> {
        let w = pair.w;
        let sum = self.order_sum_program(b, pair, k, lambda_nm, true, |period| {
            let beta = k * w;
            let profile = self.profile_program(b, period);
            let at = match profile {
                ProfileProgram::Rect { .. } => None,
                ProfileProgram::Scaled(_) => Some(powers.at(b, profile.scaled_beta(beta))),
            };
            // The rect profile's s^2: one beta for every order
            let s2 = match profile {
                ProfileProgram::Rect { height, .. } => Some(rect_s2(beta, height)),
                ProfileProgram::Scaled(_) => None,
            };
            move |n| match (profile, &at, s2) {
                (ProfileProgram::Rect { fill, .. }, _, Some(s2)) => {
                    RectOrder::new(fill, n).power(s2)
                }
                (_, Some(at), _) => powers.power(b, at, n),
                _ => unreachable!("the powers are prepared for the profile"),
            }
        });
        let kernel = (k * sum.l / w).sq() * (1.0 / PI) * sum.sum;
        sum.valid(k, w).select(kernel.finite_non_negative(), 0.0)
    }

    /// sum over the orders near the pair of power(n) exp(-E_n) as the
    /// kernels take it (`gaussian_sum`; see `OrderSum`). `powers` is given
    /// the period (a parameter where `period_param`, else the built value)
    /// and returns each order's power.
    ///
    /// The period and the coherence length are the program's parameters
    /// (`Op::Param`): a renderer may change them (and differentiate). The
    /// period as P = p_hi + p_lo: p_hi the built period's f32 value (a
    /// constant), p_lo the built value's f64 residual plus the parameter's
    /// change from its f32 value (exactly 0 at the build, in f32, and
    /// carrying the derivative). The orders' count and the reach that picks
    /// them stay the built ones: an order they miss after a change of a few
    /// percent is beyond KERNEL_TAIL_EXPONENT. Each order's Gaussian
    /// exponent comes from u P - n lambda (P the period in nm) with the
    /// product's rounding error carried, so that the distance to a narrow
    /// peak keeps f32's relative precision at high orders.
    fn order_sum_program<'a, P: Fn(Value<'a>) -> Value<'a>>(
        &self,
        b: &'a Builder,
        pair: &PairProgram<'a>,
        k: Value<'a>,
        lambda_nm: Value<'a>,
        period_param: bool,
        powers: impl FnOnce(Value<'a>) -> P,
    ) -> OrderSum<'a> {
        let period = if period_param {
            b.param(ParamId::PeriodUm, self.period_um)
        } else {
            b.built(self.period_um)
        };
        let l = b.param(ParamId::CoherenceUm, self.coherence_um);
        // The built period's values as built constants (`Builder::built`):
        // a rebuild for a nearby period keeps the code.
        let period_nm = 1000.0 * self.period_um;
        let p_hi = period_nm as f32 as f64;
        let p_lo =
            (period - b.built(self.period_um as f32 as f64)) * 1000.0 + b.built(period_nm - p_hi);
        let p_hi = b.built(p_hi);
        // u = u_hi + u_lo as the native path has it (see `exact_uv`), and
        // u P = p + p_err up to the rounding of the small terms.
        let [(u, u_lo), (v, v_lo)] = exact_uv(pair);
        let p = u * p_hi;
        let p_err = u.fma(p_hi, -p) + u_lo * p_hi + u * p_lo;
        let inv_lambda = 1.0 / lambda_nm;
        let x = (p + p_err) * inv_lambda;
        // orders_near: e_min of the nearest order, reach around x.
        let scale = 2.0 * PI * self.coherence_um / self.period_um;
        let (inv_scale, scale) = (b.built(1.0 / scale), b.built(scale));
        let frac = x - (x + 0.5).floor();
        let e_min = (frac * scale).sq();
        let reach = (e_min + KERNEL_TAIL_EXPONENT).min(EXP_UNDERFLOW).sqrt() * inv_scale;
        let lo = -(reach - x).floor(); // ceil(x - reach)
        let hi = (x + reach).floor();
        let e_v = (k * (v + v_lo) * l).sq();
        // l (k u - 2 pi n / Lam) = A (u P - n lambda) / lambda.
        let a = l * (2.0 * PI) / period;
        let power = powers(period);
        let mut sum = b.c(0.0);
        for i in 0..self.max_orders_near(b) {
            let n = lo + i as f64;
            let d = (n.fma(-lambda_nm, p) + p_err) * inv_lambda * a;
            let e = d.fma(d, e_v);
            let term = power(n) * (-e).exp();
            let take = n.le(hi) & e.lt(EXP_UNDERFLOW);
            sum = sum + take.select(term, 0.0);
        }
        OrderSum { sum, l, e_v, x }
    }
}

impl PeriodicSurface {
    /// `kernel_given` with the powers of rigorous orders (rigorous.rs):
    /// sum_n eta_n (k^2 l^2 / pi) exp(-E_n) times what the cover lets
    /// through, each eta_n read from the orders' pair grid
    /// (rigorous_grid.rs) at the pair's (c, ky).
    pub(super) fn rigorous_program<'a>(
        &self,
        b: &'a Builder,
        orders: &RigorousOrders,
        pair: &PairProgram<'a>,
        k: Value<'a>,
        lambda_nm: Value<'a>,
    ) -> Option<Value<'a>> {
        let grid = orders.pair_grid()?;
        let table = b.table(grid.values.clone());
        let (wi, wo) = (pair.wi, pair.wo);
        // The period is no parameter here: the efficiencies, tabulated
        // for the built grating, would not follow it (no gradient along
        // it rather than a wrong one; the coherence length's is exact).
        let sum = self.order_sum_program(b, pair, k, lambda_nm, false, |_| {
            let place = grid.place(lambda_nm, (wo[0] - wi[0]) * 0.5, (wi[1] - wo[1]) * 0.5);
            move |n| grid.read_at(&place, n, |i| b.gather(table, i))
        });
        let mut f = (k * sum.l).sq() * (1.0 / PI) * sum.sum;
        if let Some(through) = cover_through_program(b, orders, pair) {
            f = f * through;
        }
        Some(sum.valid(k, pair.w).select(f.finite_non_negative(), 0.0))
    }
}

/// What a rigorous grating's cover reflects at an incidence cosine (None
/// without one): `RigorousOrders::cover_reflectance`.
pub(super) fn cover_reflectance_program<'a>(
    b: &'a Builder,
    orders: &RigorousOrders,
    cos: Value<'a>,
) -> Option<Value<'a>> {
    orders
        .has_cover()
        .then(|| conductor_reflectance(cos, b.c(orders.cover_eta()), b.c(0.0)))
}

/// What the cover lets through on the way in and out, (1 - R(cos_i))
/// (1 - R(cos_o)) (None without one).
pub(super) fn cover_through_program<'a>(
    b: &'a Builder,
    orders: &RigorousOrders,
    pair: &PairProgram<'a>,
) -> Option<Value<'a>> {
    let r_i = cover_reflectance_program(b, orders, pair.wi[2])?;
    let r_o = cover_reflectance_program(b, orders, pair.wo[2])?;
    Some((1.0 - r_i) * (1.0 - r_o))
}

impl Periodic {
    /// `cover_reflectance_program` of the material's rigorous orders.
    pub(super) fn cover_program<'a>(&self, b: &'a Builder, cos: Value<'a>) -> Option<Value<'a>> {
        cover_reflectance_program(b, self.rigorous.as_ref()?, cos)
    }
}

/// `order_sum_program`'s sum, with what its callers test: the coherence
/// length l, the exponent across the grooves e_v (the sum is 0 from
/// EXP_UNDERFLOW) and the order place x (finite where the pair has one).
pub(super) struct OrderSum<'a> {
    sum: Value<'a>,
    l: Value<'a>,
    e_v: Value<'a>,
    x: Value<'a>,
}

impl<'a> OrderSum<'a> {
    /// Where the pair has a sum: k > 0, w < 0, e_v below underflow, a
    /// finite order place (the kernels' test, `gaussian_sum`'s).
    fn valid(&self, k: Value<'a>, w: Value<'a>) -> Mask<'a> {
        k.gt(0.0) & w.lt(0.0) & self.e_v.lt(EXP_UNDERFLOW) & self.x.finite()
    }
}

/// The profile's parameters as the spectral kernel reads them (`Op::Param`):
/// the rect profile's height and fill d / Lam, for its closed form; a sine
/// profile's height as the scale of beta (its c_n depend on beta h only:
/// the table built at height h0 read at beta h / h0; a table's beta range
/// is the built one, so a height raised by a few percent reads its last
/// row where |beta| is within that of the band's bluest retro-reflection).
#[derive(Clone, Copy)]
pub(super) enum ProfileProgram<'a> {
    Rect {
        height: Value<'a>,
        fill: Value<'a>,
    },
    /// beta's factor (None: tabulated heights, not a parameter)
    Scaled(Option<Value<'a>>),
}

impl<'a> ProfileProgram<'a> {
    pub(super) fn scaled_beta(&self, beta: Value<'a>) -> Value<'a> {
        match self {
            ProfileProgram::Scaled(Some(f)) => (beta * *f).max(-BETA_MAX),
            _ => beta,
        }
    }
}

/// |c_n|^2 of the rect profile (`PowerProgram::power`'s closed form) with
/// its height and fill as values: 1 - 4 f (1 - f) s^2 for order 0, 4 f^2
/// s^2 sinc^2(pi n f) for the others, s = sin(beta h / 2). The order's
/// part (`RectOrder::new`) and the beta's (`rect_s2`) are computed apart,
/// so that a loop over orders at one beta, or over betas for one order,
/// computes each once.
#[derive(Clone, Copy)]
pub(super) struct RectOrder<'a> {
    order0: Mask<'a>,
    /// Order 0: 4 f (1 - f); the others: 4 f^2 sinc^2(pi n f).
    c: Value<'a>,
}

impl<'a> RectOrder<'a> {
    pub(super) fn new(fill: Value<'a>, n: Value<'a>) -> RectOrder<'a> {
        // x is never 0 where it is used (and a safe 1 at order 0, whose
        // unselected branch would otherwise give NaN derivatives)
        let order0 = n.eq(0.0);
        let x = order0.select(1.0, n.abs() * fill * PI);
        let sinc2 = sin_squared(x) / (x * x);
        let c = order0.select(fill * (1.0 - fill), fill * fill * sinc2) * 4.0;
        RectOrder { order0, c }
    }

    /// |c_n|^2 at s^2 = sin^2(beta h / 2) (`rect_s2`)
    pub(super) fn power(&self, s2: Value<'a>) -> Value<'a> {
        self.order0
            .select((1.0 - s2 * self.c).max(0.0), s2 * self.c)
    }
}

/// sin^2(beta h / 2)
pub(super) fn rect_s2<'a>(beta: Value<'a>, height: Value<'a>) -> Value<'a> {
    sin_squared(beta * height * 0.5)
}

impl PeriodicSurface {
    pub(super) fn profile_program<'a>(
        &self,
        b: &'a Builder,
        period: Value<'a>,
    ) -> ProfileProgram<'a> {
        match self.profile {
            Profile::Rect {
                height_um,
                width_um,
            } => ProfileProgram::Rect {
                height: b.param(ParamId::HeightUm, height_um),
                fill: b.param(ParamId::WidthUm, width_um) / period,
            },
            Profile::Sine { height_um } => {
                // The table's height: a height texture's largest, else the
                // material's.
                let built = self.texture_table.as_ref().map_or(height_um, |t| t.0);
                ProfileProgram::Scaled(Some(
                    b.param(ParamId::HeightUm, height_um) * b.built(1.0 / built),
                ))
            }
            Profile::Tabulated { .. } => ProfileProgram::Scaled(None),
        }
    }
}

impl SurfacePrograms for Periodic {
    fn kernel_program<'a>(
        &self,
        b: &'a Builder,
        pair: &PairProgram<'a>,
        k_per_um: Value<'a>,
    ) -> Option<Value<'a>> {
        let lambda_nm = WAVENUMBER_TIMES_NM / k_per_um;
        self.kernel_program_at(b, pair, k_per_um, lambda_nm)
    }

    fn kernel_program_at<'a>(
        &self,
        b: &'a Builder,
        pair: &PairProgram<'a>,
        k_per_um: Value<'a>,
        lambda_nm: Value<'a>,
    ) -> Option<Value<'a>> {
        let powers = PowerProgram::new(b, &self.surface);
        Some(
            self.surface
                .kernel_program(b, &powers, pair, k_per_um, lambda_nm),
        )
    }

    /// Rigorous orders, where their pair grid is not too large.
    fn unfactored_programs(&self) -> bool {
        self.rigorous
            .as_ref()
            .is_some_and(|r| r.pair_grid().is_some())
    }

    /// A rigorous grating's cover reflects like a mirror (0 without one).
    fn coherent_spectral_program<'a>(
        &self,
        b: &'a Builder,
        _shading: &Shading,
        cos_i: Value<'a>,
        _lambda_nm: Value<'a>,
    ) -> Option<Value<'a>> {
        Some(self.cover_program(b, cos_i).unwrap_or_else(|| b.c(0.0)))
    }

    /// The cover's reflectance is flat in wavelength: the same in R, G, B.
    fn coherent_rgb_program<'a>(
        &self,
        b: &'a Builder,
        _shading: &Shading,
        cos_i: Value<'a>,
        _factor: Option<&dyn FactorProgram<'a>>,
    ) -> Option<[Value<'a>; 3]> {
        Some([self.cover_program(b, cos_i).unwrap_or_else(|| b.c(0.0)); 3])
    }

    /// Sampling picks the cover's mirror lobe with its reflectance.
    fn coherent_probability_program<'a>(
        &self,
        b: &'a Builder,
        _shading: &Shading,
        wi: Vec3<'a>,
        _lambda_nm: Option<Value<'a>>,
    ) -> Option<Value<'a>> {
        Some(self.cover_program(b, wi[2]).unwrap_or_else(|| b.c(0.0)))
    }

    fn unfactored_spectral_program<'a>(
        &self,
        b: &'a Builder,
        pair: &PairProgram<'a>,
        k_per_um: Value<'a>,
        lambda_nm: Value<'a>,
    ) -> Option<Value<'a>> {
        let orders = self.rigorous.as_ref()?;
        self.surface
            .rigorous_program(b, orders, pair, k_per_um, lambda_nm)
    }

    fn unfactored_rgb_program<'a>(
        &self,
        b: &'a Builder,
        pair: &PairProgram<'a>,
    ) -> Option<[Value<'a>; 3]> {
        let orders = self.rigorous.as_ref()?;
        let rgb = self.rigorous_rgb_program(b, pair, orders.pair_grid()?)?;
        Some(match cover_through_program(b, orders, pair) {
            Some(through) => rgb.map(|c| c * through),
            None => rgb,
        })
    }

    fn reflectance_rgb_program<'a>(
        &self,
        b: &'a Builder,
        shading: &Shading,
        pair: &PairProgram<'a>,
        factor: Option<FactorMaker<'_, 'a>>,
    ) -> Option<[Value<'a>; 3]> {
        self.rgb_program(b, shading, pair, factor)
    }

    fn sample_program<'a>(
        &self,
        b: &'a Builder,
        shading: &Shading,
        wi: Vec3<'a>,
        lambda_nm: Option<Value<'a>>,
        u: [Value<'a>; 3],
    ) -> Option<SampleProgram<'a>> {
        self.sampling_program(b, shading, wi, lambda_nm, u)
    }

    fn pdf_program<'a>(
        &self,
        b: &'a Builder,
        shading: &Shading,
        wi: Vec3<'a>,
        wo: Vec3<'a>,
        lambda_nm: Option<Value<'a>>,
    ) -> Option<Value<'a>> {
        self.density_program(b, shading, wi, wo, lambda_nm)
    }
}

/// The cell of the order table (`step`, `n_beta` nodes up to beta = 0)
/// that holds beta <= 0, for the programs: (index of its lower node, t and
/// s = 1 - t, the position in it from either end, whether beta is inside
/// the table). Measured from the top node, beta = 0: doubly grazing
/// directions read the table there, where c_n -> 0 for n != 0 with beta,
/// and -beta / step keeps beta's relative precision in f32, where
/// (beta + BETA_MAX) / step rounded s to the ulp of the top index (a 31-node
/// table: 2e-6, against s = 5e-3 at 0.1 degree above both horizons: a
/// relative error of 4e-4 in c_n).
pub(super) fn table_cell<'a>(
    beta: Value<'a>,
    step: f64,
    n_beta: usize,
) -> (Value<'a>, Value<'a>, Value<'a>, Mask<'a>) {
    let last = (n_beta - 1) as f64;
    // 1 / step as an f32 pair: one f32 constant would move the bottom
    // nodes by up to `last` f32 ulps of 1 (2e-5 of f at a sine grating's
    // order flank, where the native reads the exact position).
    let inv_hi = (1.0 / step) as f32 as f64;
    let inv_lo = 1.0 / step - inv_hi;
    let q = beta.fma(-inv_hi, beta * -inv_lo);
    // -BETA_MAX (scaled_beta's clamp) as an f32 constant lands up to an
    // ulp past the bottom node: the bottom cell's, not outside.
    let inside = q.ge(0.0) & q.le(last + 1e-4);
    let q = inside.select(q.min(last), 0.0);
    let m = q.floor().min(last - 1.0);
    let s = q - m;
    ((last - 1.0) - m, 1.0 - s, s, inside)
}

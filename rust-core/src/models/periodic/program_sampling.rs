//! The sampling programs of gratings (see program.rs): the orders' lobes of
//! sampling.rs. One wavelength: the exact weights at the centre of wi's
//! cell of a 48 x 48 grid over (wi.x, wi.y) and at 17 wavelengths, linear
//! in lambda between them (`spectral_order_table`: two gathers per order in
//! place of its weight; exact per-wi weights where a height texture or a
//! differentiated height, width or period must move them). RGB: the exact
//! weights and tilts at the centre of wi's cell of a grid over (wi.x,
//! wi.y) (`rgb_order_table`, as the native grating table's cells). Both
//! tables are made once per material by running the weights' program on
//! the CPU. The weights only steer the sampling; the pdf is exact for
//! whatever weights. A pdf computes only the terms that can be non-zero
//! in f32 (each order's Gaussian across the grooves underflows beyond
//! |v| ~ 14 sigma): towards a light, most lanes skip every order.
//!
//! One wavelength: order n (centre u_n = n lambda / Lam inside the disk)
//! with probability ~ |c_n(k w_n)|^2 min(G / w^2, 50) at its centre
//! direction (moved onto the rim cos 0.1 where it is more grazing, as
//! `order_weight`), then an isotropic Gaussian of sd 1 / (sqrt 2 k l) in
//! (u, v) (Box-Muller); 10% defensive (half cosine, half uniform), as the
//! native mixture.
//!
//! RGB: the native rainbow, simplified to what a program can invert. Order
//! n != 0 runs along u = n lambda / Lam: lambda from the band density
//! (piecewise linear over 9 nodes 50 nm apart, 0 at the band's ends)
//! tilted by exp(kappa c) in the band's CDF c towards the end where the
//! order's weight is larger (its rim end: G grows there), u exactly on the
//! rainbow, v Gaussian of sd sigma(lambda); where the rainbow leaves the
//! disk the sample fails. The order's probability ~ its weight at the
//! middle of the wavelengths where its centre is inside the disk times
//! their band mass. Order 0 (the mirror lobe at every wavelength):
//! isotropic Gaussians at the interior nodes, weighted by the band's mass
//! around them. The density in (u, v) is closed form and continuous (the
//! chi-square test's cubature integrates it): sum over orders of P_n
//! rho(lambda) tilt(lambda) Lam / |n| N(v; sigma(lambda)) at lambda = Lam u
//! / n, plus order 0's Gaussians. (Restricting lambda to the interval cut
//! the density off where the lobes still reach the rim: 100x the variance;
//! the tilt took the compact disc's variance at cos_i 0.5 from 3.6x to
//! ~1.8x the core's, measured in program_tests.rs.)

use super::program::PowerProgram;
use super::Periodic;
use crate::models::{SampleProgram, Shading};
use crate::optics::geometry::MIN_COS;
use crate::optics::program::Vec3;
use crate::program::lookup::select_chain;
use crate::program::{Builder, ParamId, Program, Table, Value};
use crate::sampling::{band_density, DEFENSIVE_FRACTION, RGB_BAND_NM};
use crate::spectrum::WAVENUMBER_TIMES_NM;
use std::borrow::Cow;
use std::f64::consts::{PI, SQRT_2};
use std::sync::OnceLock;

/// Cap of G / w^2 in the order weights, and the rim cosine of their
/// directions (sampling.rs).
const GW2_CAP: f64 = 50.0;
const RIM_COS: f64 = 0.1;
/// The band density's bins (RGB mode).
const BINS: usize = 8;
/// The wavelength tilt's weights are taken this fraction of the interval
/// inside its ends; its exponent is clamped to +-TILT_MAX (a density ratio
/// of e^8 between the ends).
const TILT_INSET: f64 = 0.01;
const TILT_MAX: f64 = 8.0;
/// The most orders a sampling program unrolls (periods up to ~100 um).
pub const MAX_SAMPLING_ORDERS: usize = 512;

/// The band density at the nodes lo + i (hi - lo) / BINS, i = 0..=BINS,
/// 0 at the ends, normalised so that its piecewise-linear interpolant
/// integrates to 1.
fn band_nodes() -> &'static [f64; BINS + 1] {
    static NODES: OnceLock<[f64; BINS + 1]> = OnceLock::new();
    NODES.get_or_init(|| {
        let (lo, hi) = RGB_BAND_NM;
        let width = (hi - lo) / BINS as f64;
        let y: [f64; BINS + 1] = std::array::from_fn(|i| {
            if i == 0 || i == BINS {
                0.0
            } else {
                band_density(lo + width * i as f64)
            }
        });
        let total: f64 = y.windows(2).map(|w| 0.5 * width * (w[0] + w[1])).sum();
        y.map(|v| v / total)
    })
}

/// The band's CDF at the nodes.
fn band_cdf_nodes() -> [f64; BINS + 1] {
    let (lo, hi) = RGB_BAND_NM;
    let width = (hi - lo) / BINS as f64;
    let y = band_nodes();
    let mut c = [0.0; BINS + 1];
    for i in 0..BINS {
        c[i + 1] = c[i] + 0.5 * width * (y[i] + y[i + 1]);
    }
    c
}

/// Masses of the order-0 Gaussians: the band's mass around each interior
/// node (half of each neighbouring segment), at the node's wavelength.
fn zero_order_nodes() -> Vec<(f64, f64)> {
    let (lo, hi) = RGB_BAND_NM;
    let width = (hi - lo) / BINS as f64;
    let y = band_nodes();
    let nodes: Vec<(f64, f64)> = (1..BINS)
        .map(|i| {
            let left = 0.5 * width * (0.75 * y[i] + 0.25 * y[i - 1]);
            let right = 0.5 * width * (0.75 * y[i] + 0.25 * y[i + 1]);
            (lo + width * i as f64, left + right)
        })
        .collect();
    let total: f64 = nodes.iter().map(|n| n.1).sum();
    nodes.into_iter().map(|(l, m)| (l, m / total)).collect()
}

/// wi's cell of the RGB order table (`rgb_order_table`): per cell the
/// weights of `rgb_order_list`, their tilts, then the total weight.
struct RgbOrderCell<'a> {
    table: Table,
    base: Value<'a>,
    orders: Vec<i64>,
}

impl<'a> RgbOrderCell<'a> {
    fn weight(&self, b: &'a Builder, j: usize) -> Value<'a> {
        b.gather(self.table, self.base + j as f64)
    }

    fn tilt(&self, b: &'a Builder, j: usize) -> Value<'a> {
        b.gather(self.table, self.base + (self.orders.len() + j) as f64)
    }

    fn total(&self, b: &'a Builder) -> Value<'a> {
        b.gather(self.table, self.base + (2 * self.orders.len()) as f64)
    }
}

/// exp(-x) in f32 is 0 beyond x = 104 (the smallest subnormal is
/// e^-103.3): a sum of such terms can skip its lanes there exactly.
const F32_EXP_UNDERFLOW: f64 = 104.0;

/// What the sampling programs of one material and mode share.
struct Orders<'a> {
    /// One wavelength: orders first..first + count (unrolled); RGB: orders
    /// -n_max..=n_max but 0, then order 0.
    n: Vec<Value<'a>>,
    /// Unnormalised probabilities (0 where not taken) and their sum.
    weight: Vec<Value<'a>>,
    total: Value<'a>,
    /// RGB: the tilt kappa of each entry's wavelengths.
    tilt: Vec<Value<'a>>,
}

/// Cells per axis of the RGB order table over (wi.x, wi.y): 1,024 cells
/// (the table is made whenever a material's RGB sampling programs are:
/// about 20 ms for the compact disc).
const ORDER_CELLS_PER_AXIS: usize = 32;

/// The spectral order table (`spectral_order_table`): cells per axis over
/// (wi.x, wi.y), wavelength nodes evenly over the renderer's band
/// (360-830 nm: 29 nm apart), and its largest size in values (8 MB; the
/// compact disc's, 27 orders, is 1.06M values, 4.2 MB).
/// Cells per axis, measured with the sampling_variance example (compact
/// disc, 550 nm, JIT / core variance at 30 and 70 degrees and cos_i 0.08):
/// 32: 1.00, 1.55, 0.72; 48: 1.03, 1.15, 0.92; 64: 1.03, 1.18, 1.12; the
/// exact weights: 0.98, 0.98, 1.07.
const SPECTRAL_CELLS_PER_AXIS: usize = 48;
const SPECTRAL_NODES: usize = 17;
const SPECTRAL_TABLE_BAND_NM: (f64, f64) = (
    crate::spectrum::LAMBDA_MIN_NM,
    crate::spectrum::LAMBDA_MAX_NM,
);
const SPECTRAL_TABLE_MAX: usize = 1 << 21;

/// A lane's place in the spectral order table: its cell's row at the
/// wavelength node below lambda (offset to order 0) and the fraction
/// towards the next node.
struct SpectralOrderLookup<'a> {
    table: Table,
    base: Value<'a>,
    entries: f64,
    n_max: f64,
    f: Value<'a>,
}

impl<'a> SpectralOrderLookup<'a> {
    /// Order n's weight, linear in lambda between the two nodes (0 for
    /// orders beyond the table's, which are never inside the disk).
    fn weight(&self, n: Value<'a>) -> Value<'a> {
        let b = n.builder();
        let at = self.base + n.clamp(-self.n_max, self.n_max);
        let (w0, w1) = (
            b.gather(self.table, at),
            b.gather(self.table, at + self.entries),
        );
        let w = w0 + (w1 - w0) * self.f;
        n.abs().le(self.n_max).select(w, 0.0)
    }
}

impl Periodic {
    /// Orders whose centre can be inside the disk for a period of
    /// `period_um`: |u_n| <= 2 at the shortest wavelength.
    fn sampling_order_count(period_um: f64, lambda_min_nm: f64) -> Option<usize> {
        let count = (2.0 * 1000.0 * period_um / lambda_min_nm).floor() as usize + 2;
        (count <= MAX_SAMPLING_ORDERS).then_some(count)
    }

    /// `order_weight` of sampling.rs at the centre (u_n, 0) of order n for
    /// wi at lambda (nm), the direction moved onto the rim.
    fn order_weight_program<'a>(
        &self,
        b: &'a Builder,
        powers: &PowerProgram,
        wi: Vec3<'a>,
        n: Value<'a>,
        lambda: Value<'a>,
    ) -> Value<'a> {
        let u_n = n * lambda * self.inv_period_nm(b);
        let (x, y) = (-wi[0] - u_n, -wi[1]);
        let r = (x * x + y * y).sqrt();
        let r_max = (1.0 - RIM_COS * RIM_COS).sqrt();
        let shrink = r.gt(r_max).select(r_max / r, 1.0);
        let (x, y) = (x * shrink, y * shrink);
        let z = (1.0 - x * x - y * y).max(0.0).sqrt();
        let one_plus_dot = wi[0] * x + wi[1] * y + wi[2] * z + 1.0;
        let w = wi[2] + z;
        let gw2 = (one_plus_dot * one_plus_dot / (wi[2] * z * w * w)).min(GW2_CAP);
        let beta = -WAVENUMBER_TIMES_NM * w / lambda;
        // A sine profile's table is read at the point's height (scaled
        // beta, as the evals read it), so that the orders' weights follow
        // it (a height texture's above all; one wavelength only: the RGB
        // order table is made at the built height); other profiles keep
        // beta.
        // Rigorous orders: the efficiency the order's lobe carries at its
        // centre (the pair grid's, read at (wi, its centre)).
        if let PowerProgram::Given { grid, table } = powers {
            let table = *table.get_or_init(|| b.table(grid.values.clone()));
            let (c, ky) = ((x - wi[0]) * 0.5, (wi[1] - y) * 0.5);
            return grid
                .read(n, lambda, c, ky, |i| b.gather(table, i))
                .finite_non_negative();
        }
        let beta = self
            .surface
            .profile_program(b, b.built(self.surface.period_um))
            .scaled_beta(beta);
        let weight = powers.power_rgb(b, beta, n) * gw2;
        weight.finite_non_negative()
    }

    /// 1 / P with the period P in nm, a built constant: an order's step
    /// in u is lambda / P.
    fn inv_period_nm<'a>(&self, b: &'a Builder) -> Value<'a> {
        b.built(1.0 / (1000.0 * self.surface.period_um))
    }

    /// sigma(lambda) of an order's Gaussian in u and v: 1 / (sqrt 2 k l).
    fn sigma<'a>(&self, lambda: Value<'a>) -> Value<'a> {
        let b = lambda.builder();
        lambda * b.built(self.sigma_per_nm())
    }

    /// sigma / lambda (lambda in nm), for `sigma` and fixed wavelengths.
    fn sigma_per_nm(&self) -> f64 {
        1.0 / (WAVENUMBER_TIMES_NM * SQRT_2 * self.surface.coherence_um)
    }

    /// The orders, their probabilities and (RGB) band intervals at wi.
    fn orders<'a>(
        &self,
        b: &'a Builder,
        powers: &PowerProgram,
        wi: Vec3<'a>,
        lambda: Option<Value<'a>>,
    ) -> Option<Orders<'a>> {
        let mut out = Orders {
            n: Vec::new(),
            weight: Vec::new(),
            total: b.c(0.0),
            tilt: Vec::new(),
        };
        match lambda {
            Some(lambda) => {
                // As many as the planned period has (orders beyond the
                // period's own are never inside the disk: not taken).
                let count = |period_um| {
                    Self::sampling_order_count(period_um, crate::spectrum::LAMBDA_MIN_NM)
                };
                let count =
                    count(self.surface.plan_period_um(b)).or(count(self.surface.period_um))?;
                // Centres inside the disk: |-wi.x - n du| < half.
                let half = (1.0 - wi[1] * wi[1]).max(0.0).sqrt();
                let du = lambda * self.inv_period_nm(b);
                let first = -((wi[0] + half) / du).floor(); // ceil((-wi.x - half) / du)
                let last = ((half - wi[0]) / du).floor();
                let table = self.spectral_order_lookup(b, wi, lambda);
                for i in 0..count {
                    let n = first + i as f64;
                    // (A select, not a region: nearly every order is
                    // inside the disk somewhere in a packet.)
                    let take = n.le(last);
                    let w = match &table {
                        Some(t) => t.weight(n),
                        None => self.order_weight_program(b, powers, wi, n, lambda),
                    };
                    let w = take.select(w, 0.0);
                    out.total = out.total + w;
                    out.n.push(n);
                    out.weight.push(w);
                }
            }
            None => {
                // The exact weights and tilts at the centre of wi's cell
                // (`rgb_order_table`): sample and pdf read the same ones,
                // so the density stays exact for them.
                let cell = self.rgb_order_cell(b, wi)?;
                for (j, &n) in cell.orders.iter().enumerate() {
                    let w = cell.weight(b, j);
                    out.total = out.total + w;
                    out.n.push(b.c(n as f64));
                    out.weight.push(w);
                    out.tilt.push(cell.tilt(b, j));
                }
            }
        }
        Some(out)
    }

    /// The spectral order table's lookup at wi and lambda, where the
    /// programs may read it: the weights then follow the built height,
    /// width and period, so a height texture, or a renderer that
    /// differentiates one of them, keeps the exact weights (which follow
    /// the point's values). None there, and where the table would be
    /// larger than SPECTRAL_TABLE_MAX values.
    fn spectral_order_lookup<'a>(
        &self,
        b: &'a Builder,
        wi: Vec3<'a>,
        lambda: Value<'a>,
    ) -> Option<SpectralOrderLookup<'a>> {
        let moving = [ParamId::PeriodUm, ParamId::HeightUm, ParamId::WidthUm]
            .iter()
            .any(|&id| b.differentiated(id));
        // (Rigorous orders' weights come from their grid alone.)
        if (moving || self.surface.texture_table.is_some()) && self.rigorous.is_none() {
            return None;
        }
        let (table, n_max) = self.spectral_order_table()?;
        let entries = 2 * n_max + 1;
        let (lo, hi) = SPECTRAL_TABLE_BAND_NM;
        let last = (SPECTRAL_NODES - 1) as f64;
        let x = ((lambda - lo) * (last / (hi - lo))).clamp(0.0, last);
        let j = x.floor().min(last - 1.0);
        let cell = wi_cell(wi, SPECTRAL_CELLS_PER_AXIS);
        Some(SpectralOrderLookup {
            table: b.table(table.to_vec()),
            base: (cell * SPECTRAL_NODES as f64 + j) * entries as f64 + n_max as f64,
            entries: entries as f64,
            n_max: n_max as f64,
            f: x - j,
        })
    }

    /// The spectral order table and its n_max: order n's weight
    /// (`order_weight_program`) at the centre of each of
    /// SPECTRAL_CELLS_PER_AXIS^2 cells over (wi.x, wi.y) (moved onto the rim
    /// where outside it) and SPECTRAL_NODES wavelengths across the band,
    /// for n = -n_max..=n_max, made once per material by running the
    /// weights' program on the CPU. A spectral strategy reads two values
    /// per order (linear in lambda) in place of computing its weight (two
    /// square roots, three divisions, its power |c_n|^2); the pdf runs it
    /// at each of a path's four wavelengths. The weights only steer the
    /// sampling: the pdf stays exact. None where the programs cannot
    /// sample (too many orders) or the table would exceed
    /// SPECTRAL_TABLE_MAX values.
    fn spectral_order_table(&self) -> Option<(&[f32], usize)> {
        let (n_max, table) = self
            .spectral_orders
            .get_or_init(|| {
                let count = Self::sampling_order_count(
                    self.surface.period_um,
                    crate::spectrum::LAMBDA_MIN_NM,
                )?;
                let n_max = count - 2;
                let size = SPECTRAL_CELLS_PER_AXIS.pow(2) * SPECTRAL_NODES * (2 * n_max + 1);
                (size <= SPECTRAL_TABLE_MAX).then(|| (n_max, self.make_spectral_order_table(n_max)))
            })
            .as_ref()?;
        Some((table.as_slice(), *n_max))
    }

    /// `spectral_order_table` for orders -n_max..=n_max.
    fn make_spectral_order_table(&self, n_max: usize) -> Vec<f32> {
        let b = Builder::new();
        let wi = [b.input(), b.input(), b.input()];
        let lambda = b.input();
        let powers = PowerProgram::sampling(&b, self);
        let n_max_i = n_max as i64;
        let outputs: Vec<Value> = (-n_max_i..=n_max_i)
            .map(|n| self.order_weight_program(&b, &powers, wi, b.c(n as f64), lambda))
            .collect();
        let (lo, hi) = SPECTRAL_TABLE_BAND_NM;
        let nodes: Vec<Vec<f64>> = (0..SPECTRAL_NODES)
            .map(|j| vec![lo + (hi - lo) * j as f64 / (SPECTRAL_NODES - 1) as f64])
            .collect();
        tabulate_over_wi_cells(&b.finish(&outputs), SPECTRAL_CELLS_PER_AXIS, &nodes)
    }

    /// The RGB orders' exact weights and tilts at wi (the entries of
    /// `rgb_order_list`), from which `rgb_order_table` is made.
    fn rgb_orders_exact<'a>(
        &self,
        b: &'a Builder,
        powers: &PowerProgram,
        wi: Vec3<'a>,
        n_max: usize,
    ) -> (Vec<Value<'a>>, Vec<Value<'a>>) {
        let period_nm = 1000.0 * self.surface.period_um;
        let half = (1.0 - wi[1] * wi[1]).max(0.0).sqrt();
        let (lo, hi) = RGB_BAND_NM;
        // Orders n != 0 whose centre is inside the disk for some lambda of
        // the band: n lambda / P in (a, b).
        let (a, bb) = (-wi[0] - half, -wi[0] + half);
        let (a_lo, a_hi) = (a * (period_nm / lo), a * (period_nm / hi));
        let (b_lo, b_hi) = (bb * (period_nm / lo), bb * (period_nm / hi));
        let first = -(-a_lo.min(a_hi)).floor(); // ceil
        let last = b_lo.max(b_hi).floor();
        let (mut weights, mut tilts) = (Vec::new(), Vec::new());
        for n in rgb_order_list(n_max) {
            let zero = n == 0;
            let nv = b.c(n as f64);
            let in_range = if zero {
                b.always()
            } else {
                nv.ge(first) & nv.le(last)
            };
            // Only where the order can be in range (the CPU run that
            // makes the table skips the others).
            let [w, kappa] = b.region(in_range, || {
                let (la, lb) = if zero {
                    (b.c(lo), b.c(hi))
                } else {
                    // lambda where -wi.x - n lambda / P is within half.
                    let (p, q) = (a * (period_nm / n as f64), bb * (period_nm / n as f64));
                    (p.min(q).max(lo), p.max(q).min(hi))
                };
                let mass = (band_cdf(b, lb) - band_cdf(b, la)).max(0.0);
                let mid = (la + lb) * 0.5;
                let w = self.order_weight_program(b, powers, wi, nv, mid) * mass;
                // Tilt of the wavelength density towards the end of the
                // interval with the larger weight (the rim, where G grows):
                // exp(kappa c) in the band's CDF c.
                let kappa = if zero {
                    b.c(0.0)
                } else {
                    let e = (lb - la) * TILT_INSET;
                    let qa = self.order_weight_program(b, powers, wi, nv, la + e);
                    let qb = self.order_weight_program(b, powers, wi, nv, lb - e);
                    let k = ((qb + 1e-30) / (qa + 1e-30))
                        .ln()
                        .clamp(-TILT_MAX, TILT_MAX);
                    k.finite().select(k, 0.0)
                };
                let take = la.lt(lb) & mass.gt(0.0);
                [take.select(w, 0.0), take.select(kappa, 0.0)]
            });
            weights.push(w);
            tilts.push(kappa);
        }
        (weights, tilts)
    }

    /// The RGB order table and n_max: at the centre of each of
    /// ORDER_CELLS_PER_AXIS^2 cells over (wi.x, wi.y) (moved onto the rim
    /// where outside it, as the native `GratingTable`'s), the exact weights
    /// then the tilts of `rgb_order_list`, computed by running
    /// `rgb_orders_exact`'s program on the CPU (made once per material),
    /// then their total. A sample reads its cell's (2 gathers per order) in
    /// place of three order weights per order; a density reads the total
    /// and, per order, its pair where it can be non-zero. The weights only
    /// steer the sampling. None for a material without an RGB eval
    /// program, which the JIT path cannot render in RGB (periods beyond ~20
    /// um: the table would take about a second to make and be unused).
    /// `period_um`: the period the programs plan for (`plan_period_um`;
    /// the table is kept for the first one asked, the only one a material's
    /// sampling programs ask for).
    fn rgb_order_table(&self, period_um: f64) -> Option<(Cow<'_, [f32]>, usize)> {
        if !self.has_rgb_program() {
            return None;
        }
        let n_max = Self::sampling_order_count(period_um, RGB_BAND_NM.0)? - 2;
        let (kept, table) = self
            .rgb_orders
            .get_or_init(|| (n_max, self.make_rgb_order_table(n_max)));
        let table = if *kept == n_max {
            Cow::Borrowed(table.as_slice())
        } else {
            Cow::Owned(self.make_rgb_order_table(n_max))
        };
        Some((table, n_max))
    }

    /// wi's cell of the RGB order table, read where needed.
    fn rgb_order_cell<'a>(&self, b: &'a Builder, wi: Vec3<'a>) -> Option<RgbOrderCell<'a>> {
        let (table, n_max) = self.rgb_order_table(self.surface.plan_period_um(b))?;
        let entries = 2 * n_max + 1;
        Some(RgbOrderCell {
            table: b.table(table.to_vec()),
            base: wi_cell(wi, ORDER_CELLS_PER_AXIS) * (2 * entries + 1) as f64,
            orders: rgb_order_list(n_max),
        })
    }

    /// `rgb_order_table` for orders -n_max..=n_max.
    fn make_rgb_order_table(&self, n_max: usize) -> Vec<f32> {
        let b = Builder::new();
        let wi = [b.input(), b.input(), b.input()];
        let powers = PowerProgram::sampling(&b, self);
        let (weights, tilts) = self.rgb_orders_exact(&b, &powers, wi, n_max);
        let outputs: Vec<Value> = weights.into_iter().chain(tilts).collect();
        let entries = 2 * n_max + 1;
        let table = tabulate_over_wi_cells(&b.finish(&outputs), ORDER_CELLS_PER_AXIS, &[vec![]]);
        // Each cell's total weight last: the f32 sum, in the list's order,
        // of the f32 weights, which is what the sampling program adds up
        // (so that its pdf, which reads the total, normalises alike).
        table
            .chunks(2 * entries)
            .flat_map(|cell| {
                let total = cell[..entries].iter().fold(0.0f32, |sum, &w| sum + w);
                cell.iter().copied().chain([total])
            })
            .collect()
    }

    pub(super) fn sampling_program<'a>(
        &self,
        b: &'a Builder,
        _shading: &Shading,
        wi: Vec3<'a>,
        lambda_nm: Option<Value<'a>>,
        u: [Value<'a>; 3],
    ) -> Option<SampleProgram<'a>> {
        let powers = PowerProgram::sampling(b, self);
        let orders = self.orders(b, &powers, wi, lambda_nm)?;
        let lobe_ok = orders.total.gt(0.0) & orders.total.finite();
        let p_def = lobe_ok.select(DEFENSIVE_FRACTION, 1.0);
        // Uniforms outside [0, 1] (or NaN) are clamped (NaN to 0).
        let u = u.map(|x| x.finite().select(x, 0.0).clamp(0.0, 1.0));
        // A rigorous grating's cover: u0 picks its mirror lobe with its
        // reflectance, then (remapped) the glossy part.
        let cover = self.cover_program(b, wi[2]);
        let (coherent, u0) = match cover {
            Some(p_c) => (
                Some(u[0].lt(p_c)),
                ((u[0] - p_c) / (1.0 - p_c).max(1e-30)).clamp(0.0, 1.0 - 1e-7),
            ),
            None => (None, u[0]),
        };
        let defensive = u0.lt(p_def);
        // Defensive: half cosine, half uniform.
        let d = u0 / p_def;
        let cosine = crate::sampling::program::cosine_direction_program(b, u[1], u[2]);
        let uniform = uniform_direction_program(u[1], u[2]);
        let def_dir: Vec3 = std::array::from_fn(|c| d.lt(0.5).select(cosine[c], uniform[c]));
        // The lobe: an order by its probability, from the rest of u0.
        let t = ((u0 - p_def) / (1.0 - p_def)).clamp(0.0, 1.0) * orders.total;
        let mut acc = b.c(0.0);
        let mut chosen = orders.n[0];
        let mut below = b.c(0.0); // cumulative weight before the chosen
        let mut chosen_w = orders.weight[0];
        let mut found = t.lt(0.0);
        let mut kappa = orders.tilt.first().copied();
        for (i, (&n, &w)) in orders.n.iter().zip(&orders.weight).enumerate() {
            let next = acc + w;
            let here = !found & t.lt(next) & w.gt(0.0);
            chosen = here.select(n, chosen);
            below = here.select(acc, below);
            chosen_w = here.select(w, chosen_w);
            if let (Some(&k), Some(cur)) = (orders.tilt.get(i), kappa.as_mut()) {
                *cur = here.select(k, *cur);
            }
            found = found | here;
            acc = next;
        }
        // Within the chosen order, the rest of u0 (RGB: the wavelength).
        let r = ((t - below) / chosen_w).clamp(0.0, 1.0);
        // Box-Muller pair.
        let radius = (-(1.0 - u[1].clamp(0.0, 1.0)).max(1e-30).ln() * 2.0).sqrt();
        let phi = u[2] * (2.0 * PI);
        let (g1, g2) = (radius * phi.cos(), radius * phi.sin());
        let inv_period_nm = self.inv_period_nm(b);
        let (du, dv) = match lambda_nm {
            Some(lambda) => {
                let sigma = self.sigma(lambda);
                (chosen * lambda * inv_period_nm + sigma * g1, sigma * g2)
            }
            None => {
                let kappa = kappa.expect("RGB orders carry their tilts");
                let small = kappa.abs().lt(1e-3);
                let kk = small.select(1.0, kappa);
                let tilted = ((kk.exp() - 1.0) * r + 1.0).ln() / kk;
                let lambda = band_inverse_cdf(b, small.select(r, tilted.clamp(0.0, 1.0)));
                let sigma = self.sigma(lambda);
                // Order 0: a Gaussian at an interior node, picked by r.
                let sigma0 = self.sigma(zero_order_node(b, r));
                let zero = chosen.eq(0.0);
                (
                    zero.select(sigma0 * g1, chosen * lambda * inv_period_nm),
                    zero.select(sigma0 * g2, sigma * g1),
                )
            }
        };
        let (x, y) = (-wi[0] - du, -wi[1] - dv);
        let r2 = x * x + y * y;
        let z = (1.0 - r2).max(0.0).sqrt();
        let lobe_ok_dir = r2.lt(1.0) & z.gt(MIN_COS);
        let lobe_dir = [
            lobe_ok_dir.select(x, 0.0),
            lobe_ok_dir.select(y, 0.0),
            lobe_ok_dir.select(z, -1.0),
        ];
        let wo = std::array::from_fn(|c| defensive.select(def_dir[c], lobe_dir[c]));
        let (wo, coherent) = match coherent {
            Some(coherent) => {
                let mirror = [-wi[0], -wi[1], wi[2]];
                let wo = std::array::from_fn(|c| coherent.select(mirror[c], wo[c]));
                (wo, coherent)
            }
            None => (wo, !b.always()),
        };
        Some(SampleProgram { wo, coherent })
    }

    pub(super) fn density_program<'a>(
        &self,
        b: &'a Builder,
        _shading: &Shading,
        wi: Vec3<'a>,
        wo: Vec3<'a>,
        lambda_nm: Option<Value<'a>>,
    ) -> Option<Value<'a>> {
        let defensive = (wo[2] * (1.0 / PI) + 0.5 / PI) * 0.5;
        let (u, v) = (-(wi[0] + wo[0]), -(wi[1] + wo[1]));
        let (lobe, total) = match lambda_nm {
            Some(lambda) => {
                let powers = PowerProgram::sampling(b, self);
                let orders = self.orders(b, &powers, wi, Some(lambda))?;
                let sigma = self.sigma(lambda);
                let inv2s2 = 0.5 / (sigma * sigma);
                let du = lambda * self.inv_period_nm(b);
                // Every order's Gaussian is 0 in f32 where v alone puts
                // its exponent past F32_EXP_UNDERFLOW.
                let ev = v * v * inv2s2;
                let [lobe] = b.region(ev.lt(F32_EXP_UNDERFLOW), || {
                    let mut lobe = b.c(0.0);
                    for (&n, &w) in orders.n.iter().zip(&orders.weight) {
                        let d = u - n * du;
                        lobe = lobe + w * (-d.fma(d * inv2s2, ev)).exp();
                    }
                    [lobe]
                });
                (lobe * inv2s2 * (1.0 / PI), orders.total)
            }
            None => self.rgb_lobe_density(b, wi, u, v)?,
        };
        let lobe_ok = total.gt(0.0) & total.finite();
        let p_def = lobe_ok.select(DEFENSIVE_FRACTION, 1.0);
        let lobe = lobe_ok.select(lobe * (1.0 / total), 0.0);
        let density = p_def * defensive + (1.0 - p_def) * lobe * wo[2];
        // The cover's mirror lobe takes its reflectance of the samples.
        let density = match self.cover_program(b, wi[2]) {
            Some(p_c) => (1.0 - p_c) * density,
            None => density,
        };
        Some(wo[2].gt(MIN_COS).select(density, 0.0))
    }

    /// The RGB lobe's density over (u, v), before its division by the
    /// total weight, and the total (`rgb_order_table`'s, the f32 sum the
    /// sampling program forms). Each order's where the wavelength of its
    /// rainbow at u lies inside the band (a region: outside, the band
    /// density is 0, as for most orders at a given wo), its weight and tilt
    /// read there; order 0's Gaussians where the widest is above f32's
    /// underflow. The sampling program reads every weight to pick an
    /// order; a density reads one cell's total and the orders its packet
    /// is near, twice per path vertex (towards the light and the sample).
    fn rgb_lobe_density<'a>(
        &self,
        b: &'a Builder,
        wi: Vec3<'a>,
        u: Value<'a>,
        v: Value<'a>,
    ) -> Option<(Value<'a>, Value<'a>)> {
        let cell = self.rgb_order_cell(b, wi)?;
        let period_nm = b.built(1000.0 * self.surface.period_um);
        let zero = zero_order_nodes();
        let mut lobe = b.c(0.0);
        for (j, &n) in cell.orders.iter().enumerate() {
            let [term] = if n != 0 {
                let nn = n as f64;
                let lambda = u * period_nm * (1.0 / nn);
                let (lo, hi) = RGB_BAND_NM;
                let on_band = lambda.gt(lo) & lambda.lt(hi);
                // Across the grooves a Gaussian of width sigma: 0 in f32
                // where |v| passes sqrt(2 F32_EXP_UNDERFLOW) sigma (most
                // lanes towards a light: on the band of a few orders at u,
                // but far from their lines in v).
                let sigma = self.sigma(lambda.max(1.0));
                let near = (v * v).lt(sigma * sigma * (2.0 * F32_EXP_UNDERFLOW));
                b.region(on_band & near, || {
                    let (w, kappa) = (cell.weight(b, j), cell.tilt(b, j));
                    let small = kappa.abs().lt(1e-3);
                    let kk = small.select(1.0, kappa);
                    let c = band_cdf(b, lambda);
                    let tilt = small.select(1.0, kk * (kk * c).exp() / (kk.exp() - 1.0));
                    let rho = band_density_program(b, lambda);
                    let nv = (-(v * v) / (sigma * sigma * 2.0)).exp() / (sigma * (2.0 * PI).sqrt());
                    let term = w * rho * tilt * (period_nm * (1.0 / nn.abs())) * nv;
                    [w.gt(0.0).select(term, 0.0)]
                })
            } else {
                // Order 0: the nodes' Gaussians, e^-(rho^2 / 2 s^2) each.
                let rho2 = u * u + v * v;
                let inv2s2: Vec<f64> = zero
                    .iter()
                    .map(|&(centre, _)| {
                        let s = centre * self.sigma_per_nm();
                        0.5 / (s * s)
                    })
                    .collect();
                let widest = inv2s2.iter().copied().fold(f64::INFINITY, f64::min);
                b.region((rho2 * b.built(widest)).lt(F32_EXP_UNDERFLOW), || {
                    let mut g = b.c(0.0);
                    for (&(_, m), &a) in zero.iter().zip(&inv2s2) {
                        g = g + (rho2 * b.built(-a)).exp() * b.built(m * a / PI);
                    }
                    [cell.weight(b, j) * g]
                })
            };
            lobe = lobe + term;
        }
        Some((lobe, cell.total(b)))
    }
}

/// The cell of a grid of `cells` x `cells` over (wi.x, wi.y) in [-1, 1]^2
/// that holds wi, as an index (rows along y): where the order tables are
/// read.
fn wi_cell<'a>(wi: Vec3<'a>, cells: usize) -> Value<'a> {
    let n = cells as f64;
    let index = |x: Value<'a>| ((x + 1.0) * (0.5 * n)).floor().clamp(0.0, n - 1.0);
    index(wi[1]) * n + index(wi[0])
}

/// The outputs of `program` (inputs wi, then one of `runs`' extra inputs)
/// at the centre of each cell of `wi_cell`'s grid (moved onto the rim
/// where outside it), for each entry of `runs` in turn, cells in index
/// order, as f32 (not finite: 0): how the order tables are made, rows of
/// cells on every core (the compact disc's spectral table, 39,168 runs,
/// added 0.08-0.15 s to its first spectral program's export on 2 cores).
fn tabulate_over_wi_cells(program: &Program, cells: usize, runs: &[Vec<f64>]) -> Vec<f32> {
    let n_out = program.outputs.len();
    let row_len = cells * runs.len() * n_out;
    let mut table = vec![0.0f32; cells * row_len];
    let centre = |i: usize| -1.0 + (i as f64 + 0.5) * 2.0 / cells as f64;
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let rows_per_thread = cells.div_ceil(threads);
    std::thread::scope(|scope| {
        for (chunk, rows) in table.chunks_mut(rows_per_thread * row_len).enumerate() {
            scope.spawn(move || {
                let (mut regs, mut out) = (Vec::new(), vec![0.0f64; n_out]);
                let mut values = rows.iter_mut();
                for row in 0..rows_per_thread.min(cells - chunk * rows_per_thread) {
                    let iy = chunk * rows_per_thread + row;
                    for ix in 0..cells {
                        let wi = super::sampling::within_rim(centre(ix), centre(iy));
                        for extra in runs {
                            let inputs: Vec<f64> = [wi.x, wi.y, wi.z]
                                .into_iter()
                                .chain(extra.iter().copied())
                                .collect();
                            program.run_into(&inputs, &mut regs, &mut out);
                            // (out first: zip takes from its first iterator first)
                            for (&x, v) in out.iter().zip(values.by_ref()) {
                                *v = if x.is_finite() { x as f32 } else { 0.0 };
                            }
                        }
                    }
                }
            });
        }
    });
    table
}

/// `warps::uniform_direction` as program operations.
fn uniform_direction_program<'a>(r1: Value<'a>, r2: Value<'a>) -> Vec3<'a> {
    let z = (1.0 - r1).max(MIN_COS * 2.0);
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = r2 * (2.0 * PI);
    [r * phi.cos(), r * phi.sin(), z]
}

/// The band density at lambda (piecewise linear, 0 outside the band).
fn band_density_program<'a>(b: &'a Builder, lambda: Value<'a>) -> Value<'a> {
    let (lo, hi) = RGB_BAND_NM;
    let per = BINS as f64 / (hi - lo);
    let x = (lambda - lo) * per;
    let inside = x.ge(0.0) & x.le(BINS as f64);
    let x = inside.select(x, 0.0);
    let i = x.floor().min((BINS - 1) as f64);
    let f = x - i;
    let y = band_nodes();
    let (y0, y1) = (select_chain(b, &y[..BINS], i), select_chain(b, &y[1..], i));
    inside.select(y0 + (y1 - y0) * f, 0.0)
}

/// The band's CDF at lambda (0 below the band, 1 above).
fn band_cdf<'a>(b: &'a Builder, lambda: Value<'a>) -> Value<'a> {
    let (lo, hi) = RGB_BAND_NM;
    let width = (hi - lo) / BINS as f64;
    let x = ((lambda - lo) * (1.0 / width)).clamp(0.0, BINS as f64);
    let i = x.floor().min((BINS - 1) as f64);
    let f = (x - i) * width;
    let (cdf, y) = (band_cdf_nodes(), band_nodes());
    let c0 = select_chain(b, &cdf[..BINS], i);
    let (y0, y1) = (select_chain(b, &y[..BINS], i), select_chain(b, &y[1..], i));
    c0 + f * y0 + (y1 - y0) * f * f * (0.5 / width)
}

/// The wavelength where the band's CDF reaches c in [0, 1]: the segment,
/// then the linear density's quadratic CDF inverted (as the native
/// rainbow).
fn band_inverse_cdf<'a>(b: &'a Builder, c: Value<'a>) -> Value<'a> {
    let (lo, hi) = RGB_BAND_NM;
    let width = (hi - lo) / BINS as f64;
    let cdf = band_cdf_nodes();
    let y = band_nodes();
    let mut i = b.c(0.0);
    for &ci in &cdf[1..BINS] {
        i = c.ge(ci).select(i + 1.0, i);
    }
    let c0 = select_chain(b, &cdf[..BINS], i);
    let (y0, y1) = (select_chain(b, &y[..BINS], i), select_chain(b, &y[1..], i));
    // y0 x + (y1 - y0) x^2 / (2 width) = c - c0, x in [0, width].
    let target = (c - c0).max(0.0);
    let disc = (y0 * y0 + (y1 - y0) * target * (2.0 / width)).max(0.0);
    let denom = y0 + disc.sqrt();
    let x = denom
        .gt(0.0)
        .select(target * 2.0 / denom, 0.0)
        .clamp(0.0, width);
    i * width + x + lo
}

/// The interior node whose cumulative order-0 mass holds r.
fn zero_order_node<'a>(b: &'a Builder, r: Value<'a>) -> Value<'a> {
    let nodes = zero_order_nodes();
    let mut acc = 0.0;
    let mut lambda = b.c(nodes[0].0);
    for pair in nodes.windows(2) {
        acc += pair[0].1;
        lambda = r.ge(acc).select(pair[1].0, lambda);
    }
    lambda
}

/// The RGB entries: orders -n_max..=n_max but 0, then order 0 (the mirror
/// lobe).
fn rgb_order_list(n_max: usize) -> Vec<i64> {
    let n = n_max as i64;
    (-n..=n).filter(|&k| k != 0).chain([0]).collect()
}

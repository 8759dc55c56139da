//! Energy conservation: the material `"energy": "conserving"`
//! (docs/energy.md; the default is Stam's formula).
//!
//! Stam's f has no shadowing and its geometric factor G = (1 + wi.wo)^2 /
//! (cos_i cos_o) grows without bound towards grazing directions, so a
//! white material (F = 1) can reflect more light than it receives there
//! (a compact disc seen at cos_i 0.08: twice as much). The conserving
//! material scales f by t(cos_i) t(cos_o) m(wi, lambda) m(wo, lambda):
//! symmetric in wi and wo (reciprocity is kept), 1 wherever the white
//! material's albedo leaves room, so Stam's formula is unchanged there, and
//! applied inside the wavelength integration of the RGB path, so that RGB
//! stays the projection of the spectral f (Gaussian and fractal surfaces
//! keep one colour-neutral m, their albedo being smooth in wavelength).
//!
//! m comes from the white material's own transfer between directions: T[a][b]
//! is the part of the light arriving from cell a that leaves into cell b
//! (importance-sampled with the material's strategy, deterministic numbers),
//! per wavelength node. The albedo of the scaled material from cell a is
//! m_a sum_b T[a][b] m_b; the scaling is the fixed point m = min(1, target /
//! (T m)) (found by the damped iteration m <- sqrt(m min(1, target / (T m))),
//! the symmetric Sinkhorn step), which corrects only the directions that
//! need it and mostly through the grazing cells that carry the excess; a
//! last step m_a <- min(m_a, target / (T m)_a) makes every row's albedo at
//! most `target` whatever the iteration reached. Between wavelength nodes m
//! is interpolated linearly.
//!
//! Before the table, the horizon taper t (1 from a model-given cosine on,
//! 0.1 or 0.25 for gratings, then smoothly to 0 at the horizon, like the
//! masking of any real surface there) removes the divergence of
//! G ~ 1 / cos_o: without
//! it a grating order emerging at the horizon (a Rayleigh anomaly) makes the
//! albedo spike over a few nm and a few tenths of a degree, finer than any
//! table.
//!
//! Cells: uniform in s = sqrt(cos) (fine towards grazing, where the excess
//! is) and, for materials whose f depends on the azimuth, in the azimuth;
//! m is interpolated linearly between cell centres.

use super::Brdf;
use crate::models::{EnergyHint, FactorProgram};
use crate::optics::program::Vec3;
use crate::program::{lookup, Builder, ParamId, Real, Table, Value};
use crate::sampling::warps::radical_inverse;
use crate::sampling::SplitMix64;
use glam::DVec3;
use std::cell::OnceCell;
use std::f64::consts::PI;

/// The horizon taper at a direction's cosine: 1 from `from_cos` on, below
/// it t = 3 x^2 - 2 x^3 with x = cos / from_cos, smoothly to 0 (t / cos
/// stays bounded); 0 at and below the horizon and for NaN. Written once
/// for native code and programs (`Real`).
#[inline]
pub fn horizon_taper<T: Real>(cos: T, from_cos: f64) -> T
where
    f64: std::ops::Sub<T, Output = T>,
{
    let x = cos * (1.0 / from_cos);
    let inside = x * x * (3.0 - x * 2.0);
    let above = cos.ge(from_cos);
    let below = T::select(cos.gt(0.0), inside, cos.constant(0.0));
    T::select(above, cos.constant(1.0), below)
}

/// Cells in s = sqrt(cos theta).
const RADIAL_CELLS: usize = 24;
const RADIAL_CELLS_AZIMUTHAL: usize = 12;
/// Azimuth cells of materials whose f depends on the azimuth.
const AZIMUTH_CELLS: usize = 24;
/// Cells more grazing than this (cos theta) get GRAZING_BOOST times as
/// many samples: their albedo is both the largest and the noisiest (the
/// strategy's frozen lobe fits worst there).
const GRAZING_COS: f64 = 0.16;
const GRAZING_BOOST: usize = 4;
/// Iterations of the fixed point.
const ITERATIONS: usize = 60;

/// How a material treats energy.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EnergyMode {
    /// f m(wi) m(wo): no direction reflects more than it receives.
    Conserving,
    /// Stam's formula as published (the Kirchhoff ground truth's).
    Stam,
}

/// The scaling m over the directions of the hemisphere and the band.
pub struct EnergyTable {
    radial: usize,
    azimuthal: usize,
    /// Cosine below which the horizon taper applies.
    taper_cos: f64,
    /// Wavelength nodes, uniform from `lambda_lo`, `lambda_step` apart.
    lambda_lo: f64,
    lambda_step: f64,
    /// 1 / lambda_step: the lookups multiply by it, native and programs
    /// alike.
    nodes_per_nm: f64,
    nodes: usize,
    /// m at the cell centres and nodes, [radial][azimuth][node].
    m: Vec<f64>,
}

/// Most wavelength nodes of a table.
pub const MAX_NODES: usize = 32;
/// Levels of m in a per-wavelength table (m in [0, 1] to 2.4e-4): those
/// of a packed pair (`lookup::pack_pair`).
const PACK_LEVELS: f64 = lookup::PAIR_LEVELS;

/// m(wi, lambda) m(wo, lambda) times the horizon taper of one pair, at any
/// wavelength (linear between the table's nodes). The products at every
/// node are made on the first `at`, then kept: most RGB evaluations of a
/// grating ask for no wavelength (no order's peak in the band: 0.09 calls
/// per evaluation of the compact disc at uniform random pairs), one on a
/// peak for about 18 (three per order, 32 for a broad zeroth order) spread
/// over most nodes.
pub struct PairEnergy<'a> {
    table: &'a EnergyTable,
    wi: DVec3,
    wo: DVec3,
    products: OnceCell<[f64; MAX_NODES]>,
}

/// Where a pair's factors come from: each direction's four cell rows and
/// bilinear weights, and the pair's taper.
struct PairCorners {
    wi: Corners,
    wo: Corners,
    taper: f64,
}

/// The start of four rows of `EnergyTable::m` and their bilinear weights.
struct Corners {
    rows: [usize; 4],
    weights: [f64; 4],
}

impl Corners {
    #[inline]
    fn at_node(&self, m: &[f64], q: usize) -> f64 {
        let (r, w) = (&self.rows, &self.weights);
        w[0] * m[r[0] + q] + w[1] * m[r[1] + q] + w[2] * m[r[2] + q] + w[3] * m[r[3] + q]
    }
}

impl PairEnergy<'_> {
    #[inline]
    pub fn at(&self, lambda_nm: f64) -> f64 {
        let table = self.table;
        let products = self
            .products
            .get_or_init(|| table.pair_corners(self.wi, self.wo).all_nodes(table));
        let (k, f) = table.node_below(lambda_nm);
        if table.nodes == 1 {
            return products[0];
        }
        products[k] + f * (products[k + 1] - products[k])
    }
}

impl PairCorners {
    /// m(wi) m(wo) times the taper at node q.
    #[inline]
    fn at_node(&self, m: &[f64], q: usize) -> f64 {
        self.wo.at_node(m, q) * (self.wi.at_node(m, q) * self.taper)
    }

    /// `at_node` at every node of the table.
    fn all_nodes(&self, table: &EnergyTable) -> [f64; MAX_NODES] {
        let mut out = [0.0; MAX_NODES];
        for (q, o) in out[..table.nodes].iter_mut().enumerate() {
            *o = self.at_node(&table.m, q);
        }
        out
    }
}

impl EnergyTable {
    /// The table of `white`: the material with F = 1 in Stam's mode;
    /// `azimuthal` when its f depends on the azimuth; the hint's wavelength
    /// nodes over [lambda_lo, lambda_hi] nm (2 to MAX_NODES). Without
    /// `per_wavelength` the table keeps, per direction, the smallest m over
    /// the nodes (it bounds every node's albedo): one factor for every
    /// wavelength, so that a smooth spectrum stays smooth and the RGB rule
    /// integrates it as before.
    pub fn build(
        white: &Brdf,
        azimuthal: bool,
        (lambda_lo, lambda_hi): (f64, f64),
        hint: EnergyHint,
    ) -> EnergyTable {
        let colour_neutral = !hint.per_wavelength;
        let (radial, azimuth) = if azimuthal {
            (RADIAL_CELLS_AZIMUTHAL, AZIMUTH_CELLS)
        } else {
            (RADIAL_CELLS, 1)
        };
        // An azimuthal table has 12 times the cells, each half the samples.
        let samples = if azimuthal {
            hint.samples_per_cell / 2
        } else {
            hint.samples_per_cell
        };
        let nodes = hint.wavelength_nodes.clamp(2, MAX_NODES);
        let cells = radial * azimuth;
        let lambda_step = (lambda_hi - lambda_lo) / (nodes - 1) as f64;
        let mut table = EnergyTable {
            radial,
            azimuthal: azimuth,
            taper_cos: hint.horizon_taper_cos,
            lambda_lo,
            lambda_step,
            nodes_per_nm: 1.0 / lambda_step,
            nodes,
            m: vec![1.0; cells * nodes],
        };
        // One node per task, on the machine's threads (the nodes are
        // independent; a grating's 25 nodes take about a second on one).
        let per_node = {
            let table = &table;
            let threads = std::thread::available_parallelism()
                .map_or(1, |n| n.get())
                .min(nodes);
            let mut per_node = vec![Vec::new(); nodes];
            std::thread::scope(|scope| {
                let workers: Vec<_> = (0..threads)
                    .map(|w| {
                        scope.spawn(move || {
                            (w..nodes)
                                .step_by(threads)
                                .map(|k| {
                                    let lambda = lambda_lo + k as f64 * table.lambda_step;
                                    let transfer =
                                        table.symmetric(table.transfer(white, lambda, samples));
                                    (k, fixed_point(&transfer, cells, hint.target_albedo))
                                })
                                .collect::<Vec<_>>()
                        })
                    })
                    .collect();
                for worker in workers {
                    for (k, m) in worker.join().expect("an energy-table worker panicked") {
                        per_node[k] = m;
                    }
                }
            });
            per_node
        };
        for (k, m) in per_node.into_iter().enumerate() {
            for (cell, value) in m.into_iter().enumerate() {
                table.m[cell * nodes + k] = value;
            }
        }
        if colour_neutral {
            let m = table
                .m
                .chunks(nodes)
                .map(|row| row.iter().cloned().fold(1.0, f64::min))
                .collect();
            table.m = m;
            table.nodes = 1;
        } else {
            // Per-wavelength tables hold m on a grid of 1 / PACK_LEVELS,
            // rounded down (the albedo bound holds): a program reads two
            // nodes with one gather (`packed_pairs`), the native path the
            // same values.
            for m in &mut table.m {
                *m = (*m * PACK_LEVELS).floor() / PACK_LEVELS;
            }
        }
        table
    }

    /// m at the cell centres and nodes, [cell][node], and the nodes per
    /// cell.
    #[cfg(test)]
    pub(super) fn values(&self) -> (&[f64], usize) {
        (&self.m, self.nodes)
    }

    /// Two nodes' m per value, for programs (`lookup::pack_pair`, exact
    /// for the table's levels): nodes 2p and 2p + 1 (0 past the last). Per
    /// cell ceil(nodes / 2) values.
    pub(super) fn packed_pairs(&self) -> Vec<f32> {
        let pairs = self.nodes.div_ceil(2);
        self.m
            .chunks(self.nodes)
            .flat_map(|row| {
                (0..pairs).map(move |p| {
                    lookup::pack_pair(row[2 * p], row.get(2 * p + 1).map_or(0.0, |&m| m))
                })
            })
            .collect()
    }

    /// The pair's factors, looked up when first asked for.
    #[inline]
    pub fn pair(&self, wi: DVec3, wo: DVec3) -> PairEnergy<'_> {
        PairEnergy {
            table: self,
            wi,
            wo,
            products: OnceCell::new(),
        }
    }

    /// The pair's factor at one wavelength: `pair(wi, wo).at(lambda_nm)`
    /// from the two nodes around it only (a grating's table has 25).
    #[inline]
    pub fn pair_at(&self, wi: DVec3, wo: DVec3, lambda_nm: f64) -> f64 {
        let pair = self.pair_corners(wi, wo);
        let (k, f) = self.node_below(lambda_nm);
        if self.nodes == 1 {
            return pair.at_node(&self.m, 0);
        }
        let below = pair.at_node(&self.m, k);
        below + f * (pair.at_node(&self.m, k + 1) - below)
    }

    #[inline]
    fn pair_corners(&self, wi: DVec3, wo: DVec3) -> PairCorners {
        PairCorners {
            wi: self.corners(wi),
            wo: self.corners(wo),
            taper: horizon_taper(wi.z, self.taper_cos) * horizon_taper(wo.z, self.taper_cos),
        }
    }

    /// The node at or below `lambda_nm` (clamped to the band; the last but
    /// one at its top) and the wavelength's fraction of the way to the next.
    #[inline]
    fn node_below(&self, lambda_nm: f64) -> (usize, f64) {
        if self.nodes == 1 {
            return (0, 0.0);
        }
        let x =
            ((lambda_nm - self.lambda_lo) * self.nodes_per_nm).clamp(0.0, (self.nodes - 1) as f64);
        let k = (x as usize).min(self.nodes - 2);
        (k, x - k as f64)
    }

    /// The cell centre's direction.
    fn centre(&self, cell: usize) -> DVec3 {
        let (i, j) = (cell / self.azimuthal, cell % self.azimuthal);
        let s = (i as f64 + 0.5) / self.radial as f64;
        let cos = s * s;
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        let phi = -PI + (j as f64 + 0.5) * 2.0 * PI / self.azimuthal as f64;
        DVec3::new(sin * phi.cos(), sin * phi.sin(), cos)
    }

    /// The cell of a unit direction above the horizon.
    fn cell(&self, d: DVec3) -> usize {
        let s = d.z.clamp(0.0, 1.0).sqrt();
        let i = ((s * self.radial as f64) as usize).min(self.radial - 1);
        let j = if self.azimuthal == 1 {
            0
        } else {
            let t = (d.y.atan2(d.x) + PI) / (2.0 * PI);
            ((t * self.azimuthal as f64) as usize).min(self.azimuthal - 1)
        };
        i * self.azimuthal + j
    }

    /// T[a * cells + b] at one wavelength.
    fn transfer(&self, white: &Brdf, lambda: f64, samples: usize) -> Vec<f64> {
        let cells = self.radial * self.azimuthal;
        let mut t = vec![0.0; cells * cells];
        for a in 0..cells {
            let wi = self.centre(a);
            let samples = if wi.z < GRAZING_COS {
                samples * GRAZING_BOOST
            } else {
                samples
            };
            let strategy = white.sampler(wi, Some(lambda));
            let mut rng = SplitMix64(a as u64 * 7919 + 17);
            let shift = (rng.next_f64(), rng.next_f64());
            let row = &mut t[a * cells..(a + 1) * cells];
            for k in 0..samples {
                // Stratified component choice; a Halton (2, 3) point of a
                // permuted index for the direction (not correlated with
                // the strata), rotated per row.
                let r0 = (k as f64 + rng.next_f64()) / samples as f64;
                let index = (k * 97 + 13) % samples;
                let r1 = (radical_inverse(index, 2) + shift.0).fract();
                let r2 = (radical_inverse(index, 3) + shift.1).fract();
                let s = strategy.sample([r0, r1, r2]);
                if !(s.pdf > 0.0) {
                    continue;
                }
                let weight = if s.coherent {
                    white.coherent_spectral(wi, lambda) / s.pdf
                } else {
                    white.eval_spectral(wi, s.wo, lambda) * s.wo.z / s.pdf
                } * horizon_taper(wi.z, self.taper_cos)
                    * horizon_taper(s.wo.z, self.taper_cos);
                if weight.is_finite() {
                    row[self.cell(s.wo)] += weight / samples as f64;
                }
            }
        }
        t
    }

    /// The transfer averaged with its point reflection (wi and wo turned by
    /// 180 degrees about the normal), which it equals in expectation: a
    /// real surface's power spectrum is even, so every model's f is
    /// unchanged by the turn. This halves the noise variance of an
    /// azimuthal table's rows (isotropic tables have one azimuth cell).
    fn symmetric(&self, t: Vec<f64>) -> Vec<f64> {
        let n = self.azimuthal;
        if n == 1 {
            return t;
        }
        let cells = self.radial * n;
        let turn = |cell: usize| cell - cell % n + (cell % n + n / 2) % n;
        let mut out = vec![0.0; cells * cells];
        for a in 0..cells {
            for b in 0..cells {
                out[a * cells + b] = 0.5 * (t[a * cells + b] + t[turn(a) * cells + turn(b)]);
            }
        }
        out
    }

    /// The four cell rows around a unit direction above the horizon and
    /// their weights: m is interpolated between the cell centres, linearly
    /// in sqrt(cos) and, periodically, in the azimuth.
    #[inline]
    fn corners(&self, d: DVec3) -> Corners {
        let x = d.z.clamp(0.0, 1.0).sqrt() * self.radial as f64 - 0.5;
        let i0 = (x.max(0.0) as usize).min(self.radial - 1);
        let i1 = (i0 + 1).min(self.radial - 1);
        let fi = (x - i0 as f64).clamp(0.0, 1.0);
        let (n, k) = (self.azimuthal, self.nodes);
        let (j0, j1, fj) = if n == 1 {
            (0, 0, 0.0)
        } else {
            let y = (d.y.atan2(d.x) + PI) / (2.0 * PI) * n as f64 - 0.5;
            let y = if y < 0.0 { y + n as f64 } else { y };
            let j0 = (y as usize).min(n - 1);
            (j0, (j0 + 1) % n, (y - j0 as f64).clamp(0.0, 1.0))
        };
        let row = |i: usize, j: usize| (i * n + j) * k;
        Corners {
            rows: [row(i0, j0), row(i0, j1), row(i1, j0), row(i1, j1)],
            weights: [
                (1.0 - fi) * (1.0 - fj),
                (1.0 - fi) * fj,
                fi * (1.0 - fj),
                fi * fj,
            ],
        }
    }

    /// The smallest m at directions of cos theta >= `cos_min`, at any
    /// wavelength node (a 64 x 64 grid of directions): the default's f
    /// differs from Stam's by at most 1 - that squared for pairs there.
    pub fn min_factor_within(&self, cos_min: f64) -> f64 {
        let mut least: f64 = 1.0;
        for a in 0..64 {
            let cos = cos_min + (1.0 - cos_min) * a as f64 / 63.0;
            let sin = (1.0 - cos * cos).max(0.0).sqrt();
            for b in 0..64 {
                let phi = 2.0 * PI * b as f64 / 64.0;
                let d = DVec3::new(sin * phi.cos(), sin * phi.sin(), cos);
                let corners = self.corners(d);
                for q in 0..self.nodes {
                    least = least.min(corners.at_node(&self.m, q));
                }
            }
        }
        least
    }

    /// The smallest m of the table (how much the default darkens at most).
    pub fn min_factor(&self) -> f64 {
        self.m.iter().cloned().fold(1.0, f64::min)
    }

    pub fn memory_bytes(&self) -> usize {
        self.m.len() * 8
    }
}

/// How the table changes with one parameter of the surface: d m / d ln p
/// at every entry (the layout of `EnergyTable::m`), from tables built at p
/// e^(+-derivative_step) with the same random numbers, so that their
/// transfers' noise mostly cancels in the difference. The programs read m
/// as m + ln(p / p0) dm for such a parameter p (built at p0), so that a
/// renderer's AD sees how the scaling follows p (docs/inverse.md).
pub struct TableDerivative {
    pub id: ParamId,
    /// The value p0 the table was built at.
    pub built: f64,
    pub per_log: Vec<f64>,
}

/// The step in ln p of a derivative's central difference: about the
/// largest change a renderer makes without rebuilding the material (2%),
/// so that the difference spans what the programs are used for.
pub const DERIVATIVE_STEP: f64 = 0.02;

/// The step in ln p of the derivative along `id`: DERIVATIVE_STEP, but
/// 0.5% for a grating's period, which moves its orders towards or past the
/// horizon: its albedo curves within 2%, so that a 2% difference is not the
/// derivative a renderer's AD needs (a sine grating's sphere image under
/// the default, llvm_ad_rgb: 2.4% off the derivative of rebuilt materials
/// with 2%, 0.3% with 0.5%). The other parameters keep 2%: a smaller step
/// lets the tables' Monte Carlo noise through (0.5%: a Gaussian's sigma 7%
/// off, a sine grating's height 3% off in llvm_ad_spectral).
pub fn derivative_step(id: ParamId) -> f64 {
    match id {
        ParamId::PeriodUm => 0.005,
        _ => DERIVATIVE_STEP,
    }
}

impl TableDerivative {
    /// The derivative of `centre` along `id` from the tables at p0
    /// e^(+-derivative_step(id)) (either may be missing where that value is
    /// not a valid material: a one-sided difference then; neither: None).
    pub fn new(
        id: ParamId,
        built: f64,
        centre: &EnergyTable,
        below: Option<&EnergyTable>,
        above: Option<&EnergyTable>,
    ) -> Option<TableDerivative> {
        let same = |t: &&EnergyTable| t.m.len() == centre.m.len();
        let h = derivative_step(id);
        let (lo, hi, step) = match (below.filter(same), above.filter(same)) {
            (Some(lo), Some(hi)) => (&lo.m, &hi.m, 2.0 * h),
            (Some(lo), None) => (&lo.m, &centre.m, h),
            (None, Some(hi)) => (&centre.m, &hi.m, h),
            (None, None) => return None,
        };
        let per_log = lo.iter().zip(hi).map(|(a, b)| (b - a) / step).collect();
        Some(TableDerivative { id, built, per_log })
    }
}

/// The table as program operations (crate::program, docs/jit.md).
impl EnergyTable {
    /// Whether one factor serves every wavelength.
    pub fn colour_neutral(&self) -> bool {
        self.nodes == 1
    }

    /// The table in a program, reading it as m + sum ln(p / p0) dm over
    /// `derivatives` (the parameters p the rest of the program reads; none
    /// for a program run at the built parameters).
    pub fn program<'a>(
        &'a self,
        b: &'a Builder,
        derivatives: &[&TableDerivative],
    ) -> TableProgram<'a> {
        TableProgram {
            table: self,
            b,
            m: OnceCell::new(),
            packed: OnceCell::new(),
            terms: derivatives
                .iter()
                .map(|d| {
                    let p = b.param(d.id, d.built);
                    ((p * b.built(1.0 / d.built)).ln(), b.table(f32s(&d.per_log)))
                })
                .collect(),
        }
    }
}

/// A table's values as a program table's (f32).
fn f32s(values: &[f64]) -> Vec<f32> {
    values.iter().map(|&x| x as f32).collect()
}

/// `EnergyTable::program`: the table's lookups as program operations.
pub struct TableProgram<'a> {
    table: &'a EnergyTable,
    b: &'a Builder,
    /// m per cell and node, and `EnergyTable::packed_pairs`, each made
    /// where first read (a grating's RGB eval reads only the packed one).
    m: OnceCell<Table>,
    packed: OnceCell<Table>,
    /// Per derivative: ln(p / p0) and the table of d m / d ln p.
    terms: Vec<(Value<'a>, Table)>,
}

impl<'a> TableProgram<'a> {
    /// Whether one factor serves every wavelength.
    pub fn colour_neutral(&self) -> bool {
        self.table.colour_neutral()
    }

    /// The table of m as a program table.
    fn m_table(&self) -> Table {
        *self.m.get_or_init(|| self.b.table(f32s(&self.table.m)))
    }

    /// The entry at `index`: m there, moved along the derivatives.
    fn entry(&self, index: Value<'a>) -> Value<'a> {
        let b = self.b;
        self.terms
            .iter()
            .fold(b.gather(self.m_table(), index), |m, &(dlog, d)| {
                b.gather(d, index).fma(dlog, m)
            })
    }

    /// m at the four cells around a direction, at node `q`.
    fn at_corners(&self, corners: &[(Value<'a>, Value<'a>); 4], q: Value<'a>) -> Value<'a> {
        lookup::sum(
            self.b,
            corners.iter().map(|&(row, w)| w * self.entry(row + q)),
        )
    }

    /// `pair(wi, wo).at(lambda)` for unit directions above the horizon;
    /// `lambda_nm` None only for colour-neutral tables (else None). One
    /// wavelength: 16 gathers (8 for a colour-neutral table), times one
    /// plus the number of derivatives.
    pub fn pair(
        &self,
        wi: Vec3<'a>,
        wo: Vec3<'a>,
        lambda_nm: Option<Value<'a>>,
    ) -> Option<Value<'a>> {
        let (t, b) = (self.table, self.b);
        if lambda_nm.is_none() && t.nodes > 1 {
            return None;
        }
        let k = t.nodes;
        // The node pair and weight (as EnergyTable::pair_at).
        let (q0, fq) = match lambda_nm {
            Some(lambda) if k > 1 => {
                let x = ((lambda - t.lambda_lo) * t.nodes_per_nm).clamp(0.0, (k - 1) as f64);
                let q = x.floor().min((k - 2) as f64);
                (q, Some(x - q))
            }
            _ => (b.c(0.0), None),
        };
        // m at a direction, at nodes q0 and q0 + 1.
        let factor = |d: Vec3<'a>| -> (Value<'a>, Value<'a>) {
            let corners = t.corners_program(b, d);
            let lo = self.at_corners(&corners, q0);
            let hi = if fq.is_some() {
                self.at_corners(&corners, q0 + 1.0)
            } else {
                lo
            };
            (lo, hi)
        };
        let (a0, a1) = factor(wi);
        let (b0, b1) = factor(wo);
        let taper = t.taper_program(wi[2]) * t.taper_program(wo[2]);
        let p0 = a0 * b0 * taper;
        Some(match fq {
            Some(f) => {
                let p1 = a1 * b1 * taper;
                p0 + (p1 - p0) * f
            }
            None => p0,
        })
    }

    /// The pair's factor at every wavelength node, for programs that need
    /// it at many wavelengths (a grating's RGB: three per order, and the
    /// broad rule's nodes): the table's rows around wi and wo gathered once
    /// (8 gathers per pair of nodes from the packed table; without it, as
    /// along derivatives, 8 per node times one plus their number), then
    /// linear in lambda by selects.
    pub fn pair_factor(&self, wi: Vec3<'a>, wo: Vec3<'a>) -> PairFactorProgram<'a> {
        let (t, b) = (self.table, self.b);
        let taper = t.taper_program(wi[2]) * t.taper_program(wo[2]);
        let product: Vec<Value<'a>> = if self.terms.is_empty() && t.nodes > 1 {
            // Two nodes per gather (`EnergyTable::packed_pairs`): a gather
            // costs several times the unpacking, more so on CPUs whose
            // vector gathers are slow.
            let packed = *self.packed.get_or_init(|| b.table(t.packed_pairs()));
            let pairs = t.nodes.div_ceil(2) as f64;
            let rows = |d: Vec3<'a>| {
                t.corner_cells_program(b, d)
                    .map(|(cell, w)| (cell * pairs, w * (1.0 / PACK_LEVELS)))
            };
            let (ri, ro) = (rows(wi), rows(wo));
            let at_pair = |corners: &[(Value<'a>, Value<'a>); 4], p: f64| {
                let (mut even, mut odd) = (b.c(0.0), b.c(0.0));
                for &(row, w) in corners {
                    let (first, second) = lookup::unpack_pair_levels(b.gather(packed, row + p));
                    even = w.fma(first, even);
                    odd = w.fma(second, odd);
                }
                (even, odd)
            };
            (0..t.nodes.div_ceil(2))
                .flat_map(|p| {
                    let ((ie, io), (oe, oo)) = (at_pair(&ri, p as f64), at_pair(&ro, p as f64));
                    [ie * oe * taper, io * oo * taper]
                })
                .take(t.nodes)
                .collect()
        } else {
            let (ci, co) = (t.corners_program(b, wi), t.corners_program(b, wo));
            (0..t.nodes)
                .map(|q| {
                    let q = b.c(q as f64);
                    self.at_corners(&ci, q) * self.at_corners(&co, q) * taper
                })
                .collect()
        };
        PairFactorProgram {
            lambda_lo: t.lambda_lo,
            lambda_step: t.lambda_step,
            product,
        }
    }
}

/// The table's geometry as program operations.
impl EnergyTable {
    /// The four cells around a unit direction above the horizon (as
    /// `corners`): each as the table index of its node 0, and its bilinear
    /// weight.
    fn corners_program<'a>(&self, b: &'a Builder, d: Vec3<'a>) -> [(Value<'a>, Value<'a>); 4] {
        let k = self.nodes as f64;
        self.corner_cells_program(b, d)
            .map(|(cell, w)| (cell * k, w))
    }

    /// The four cells around a unit direction above the horizon: each as
    /// its index (row times columns plus column) and its bilinear weight.
    fn corner_cells_program<'a>(&self, b: &'a Builder, d: Vec3<'a>) -> [(Value<'a>, Value<'a>); 4] {
        let r = self.radial as f64;
        let x = d[2].clamp(0.0, 1.0).sqrt() * r - 0.5;
        let i0 = x.max(0.0).floor().min(r - 1.0);
        let i1 = (i0 + 1.0).min(r - 1.0);
        let fi = (x - i0).clamp(0.0, 1.0);
        let n = self.azimuthal as f64;
        let (j0, j1, fj) = if self.azimuthal == 1 {
            (b.c(0.0), b.c(0.0), b.c(0.0))
        } else {
            let y = (d[1].atan2(d[0]) + PI) * (n / (2.0 * PI)) - 0.5;
            let y = y.lt(0.0).select(y + n, y);
            let j0 = y.floor().clamp(0.0, n - 1.0);
            let j1 = (j0 + 1.0).ge(n).select(0.0, j0 + 1.0);
            (j0, j1, (y - j0).clamp(0.0, 1.0))
        };
        [
            (i0, j0, (1.0 - fi) * (1.0 - fj)),
            (i0, j1, (1.0 - fi) * fj),
            (i1, j0, fi * (1.0 - fj)),
            (i1, j1, fi * fj),
        ]
        .map(|(i, j, w)| (i * n + j, w))
    }

    /// The horizon taper at a cosine.
    fn taper_program<'a>(&self, cos: Value<'a>) -> Value<'a> {
        horizon_taper(cos, self.taper_cos)
    }
}

/// `TableProgram::pair_factor`: m(wi, lambda) m(wo, lambda) of one
/// pair at the table's nodes, linear in between (as `PairEnergy::at`).
pub struct PairFactorProgram<'a> {
    lambda_lo: f64,
    lambda_step: f64,
    product: Vec<Value<'a>>,
}

impl<'a> FactorProgram<'a> for PairFactorProgram<'a> {
    /// The segment's two nodes by a chain of selects (3 operations per
    /// node), then linear between them.
    fn at(&self, lambda_nm: Value<'a>) -> Value<'a> {
        let k = self.product.len();
        if k == 1 {
            return self.product[0];
        }
        let x =
            ((lambda_nm - self.lambda_lo) * (1.0 / self.lambda_step)).clamp(0.0, (k - 1) as f64);
        let (mut lo, mut hi) = (self.product[0], self.product[1]);
        for q in 1..k - 1 {
            let past = x.ge(q as f64);
            lo = past.select(self.product[q], lo);
            hi = past.select(self.product[q + 1], hi);
        }
        (hi - lo).fma(x - x.floor().min((k - 2) as f64), lo)
    }

    fn at_nm(&self, lambda_nm: f64) -> Value<'a> {
        let k = self.product.len();
        if k == 1 {
            return self.product[0];
        }
        let x = ((lambda_nm - self.lambda_lo) / self.lambda_step).clamp(0.0, (k - 1) as f64);
        let q = (x as usize).min(k - 2);
        let f = x - q as f64;
        if f == 0.0 {
            self.product[q]
        } else {
            (self.product[q + 1] - self.product[q]).fma(f, self.product[q])
        }
    }
}

/// The scaling of one wavelength's transfer matrix (see the module
/// documentation): every row of diag(m) T diag(m) sums to at most
/// `target`.
fn fixed_point(t: &[f64], cells: usize, target: f64) -> Vec<f64> {
    let apply = |m: &[f64]| -> Vec<f64> {
        (0..cells)
            .map(|a| {
                let row = &t[a * cells..(a + 1) * cells];
                row.iter().zip(m).map(|(x, y)| x * y).sum::<f64>()
            })
            .collect()
    };
    let bound = |tm: f64| {
        if tm > target {
            target / tm
        } else {
            1.0
        }
    };
    let mut m = vec![1.0; cells];
    for _ in 0..ITERATIONS {
        let tm = apply(&m);
        for (x, &y) in m.iter_mut().zip(&tm) {
            *x = (*x * bound(y)).sqrt();
        }
    }
    let tm = apply(&m);
    for (x, &y) in m.iter_mut().zip(&tm) {
        *x = x.min(bound(y));
    }
    m
}

//! The RGB path of height maps: the RGB rule's whole sum, tabulated once
//! per material over the pair's (|w|, u, v).
//!
//! Node j of the rule reads K(k_j) = k_j^4 T(k_j |w|, k_j (u, v) / 2 pi) /
//! (4 pi^2), and the rule folds in F^2 at the half vector's cosine, which
//! is |(u, v, w)| / 2: every term is a function of (u, v, w) alone. So is
//! the sum, and one trilinear read of its three channels (8 points, one
//! log) replaces the rule's 24 reads of T (8 points and one log each).
//! The pair's geometric factor and the material's colour-neutral energy
//! factor stay outside, as on the per-node path.
//!
//! Grid: |w| on nodes uniform in s = ln(1 + k_ref |w| / kappa_0) (k_ref the
//! rule's mean wavenumber), where the sum times (1 + k_ref |w| / kappa_0)^4
//! varies slowly, as T's own table does; (u, v) uniform over the square
//! where any node's T is non-zero (|u|, |v| <= 2, and within the map's
//! Nyquist frequency at the reddest node), with the spacing of T's
//! frequency cell at the bluest node (`UV_POINTS_PER_CELL` per cell). Its
//! error against the per-node path is measured in the tests
//! (`rgb_table_against_the_nodes`, docs/heightmap.md).

use super::{bilinear, SpectrumTable};
use crate::models::RgbRule;
use crate::optics::fresnel::Fresnel;
use crate::program::Real;
use crate::progress::Progress;
use crate::sampling::SplitMix64;

/// Grid points along u and v per frequency cell of T at the rule's bluest
/// node.
const UV_POINTS_PER_CELL: f64 = 2.0;
/// Floats the table may hold (n_w x n_u x n_v x 3); a larger grid gets
/// fewer points per cell.
const MAX_VALUES: usize = 1 << 22;
/// The (u, v) box reaches the last cell of T (at any node) above this
/// fraction of its node's largest value: beyond, the light is negligible.
const SUPPORT_FRACTION: f64 = 1e-6;
/// Node spacing in s along |w| (T's own table: 0.08).
const W_NODE_STEP: f64 = 0.08;
const MIN_W_NODES: usize = 8;
const MAX_W_NODES: usize = 48;
/// The build's check: points drawn in bright cells (max channel above
/// `CHECK_BRIGHT` of its plane's largest), each read against the rule's
/// nodes at the same (|w|, u, v); the table serves when the 90th
/// percentile of their error (relative to the point's largest channel) is
/// at most `CHECK_P90`. A Gaussian-like map passes (3e-2 on the demo's);
/// a grating-like map, whose orders are a cell wide, does not, and keeps
/// the nodes.
const CHECK_POINTS: usize = 2048;
const CHECK_BRIGHT: f32 = 0.01;
pub(super) const CHECK_P90: f64 = 0.05;

/// The RGB rule's sum (F^2 folded in) over (|w|, u, v); see the module
/// documentation.
#[derive(Debug)]
pub struct RgbTable {
    n_w: usize,
    /// Grid points along u and v.
    n_u: usize,
    n_v: usize,
    /// k_ref / kappa_0: |w| to 1 + k_ref |w| / kappa_0.
    w_scale: f64,
    s_max: f64,
    /// The grid covers u in [-u_max, u_max], v in [-v_max, v_max].
    u_max: f64,
    v_max: f64,
    /// [w node][v point][u point][channel]: the sum times (1 + k_ref |w| /
    /// kappa_0)^4.
    pub values: Vec<f32>,
}

/// What the table holds at (|w|, u, v), by the rule's nodes (`nodes` their
/// scratch values): K at each, summed with F^2 at the half vector's cosine
/// |(u, v, w)| / 2.
fn by_nodes(
    table: &SpectrumTable,
    rule: &RgbRule,
    fresnel: &Fresnel,
    w: f64,
    u: f64,
    v: f64,
    nodes: &mut [f64],
) -> [f64; 3] {
    let fetch = |at: f64| table.values[at as usize] as f64;
    for (value, &k) in nodes.iter_mut().zip(&rule.k_per_um) {
        *value = table.kernel(k, w, u, v, fetch);
    }
    let cos_half = ((u * u + v * v + w * w).sqrt() * 0.5).min(1.0);
    rule.integrate(fresnel, cos_half, nodes)
}

/// How far T reaches from the grid's centre, in cells along x and y: the
/// last cell above `SUPPORT_FRACTION` of its node's largest value.
fn support_cells(table: &SpectrumTable) -> (usize, usize) {
    let n = table.tile;
    let half = n / 2;
    let (mut reach_x, mut reach_y) = (0, 0);
    for node in table.values.chunks_exact(n * n) {
        let peak = node.iter().cloned().fold(0.0f32, f32::max);
        let floor = peak * SUPPORT_FRACTION as f32;
        for (iy, row) in node.chunks_exact(n).enumerate() {
            for (ix, &value) in row.iter().enumerate() {
                if value > floor {
                    reach_x = reach_x.max(ix.abs_diff(half));
                    reach_y = reach_y.max(iy.abs_diff(half));
                }
            }
        }
    }
    (reach_x, reach_y)
}

impl RgbTable {
    /// The table of `rule` with `fresnel` folded in, over `table`'s
    /// spectrum (all cores), whatever its check gives.
    pub fn build(table: &SpectrumTable, rule: &RgbRule, fresnel: &Fresnel) -> RgbTable {
        let mut rgb = RgbTable::grid(table, rule);
        rgb.fill(&(0..rgb.n_w).collect::<Vec<_>>(), table, rule, fresnel);
        rgb
    }

    /// The table if it passes its build's check (`CHECK_P90`), else None.
    /// The check runs first on two slabs of |w| (near 1.8 and 1.0: normal
    /// and 60 degree mirrors), so that a map too sharp for the table is
    /// refused after 4 of its planes; then on the whole table.
    pub fn build_checked(
        table: &SpectrumTable,
        rule: &RgbRule,
        fresnel: &Fresnel,
    ) -> Option<RgbTable> {
        let mut rgb = RgbTable::grid(table, rule);
        let last = rgb.n_w - 1;
        let slab = |w: f64| {
            let x = (w * rgb.w_scale).ln_1p() / rgb.s_max * last as f64;
            (x as usize).min(last - 1)
        };
        let slabs = [slab(1.8), slab(1.0)];
        let first: Vec<usize> = slabs.iter().flat_map(|&i| [i, i + 1]).collect();
        rgb.fill(&first, table, rule, fresnel);
        if rgb.check_p90(table, rule, fresnel, Some(&slabs)) > CHECK_P90 {
            return None;
        }
        let rest: Vec<usize> = (0..rgb.n_w).filter(|i| !first.contains(i)).collect();
        rgb.fill(&rest, table, rule, fresnel);
        (rgb.check_p90(table, rule, fresnel, None) <= CHECK_P90).then_some(rgb)
    }

    /// The grid for `rule` over `table`'s spectrum, its values zero.
    fn grid(table: &SpectrumTable, rule: &RgbRule) -> RgbTable {
        let lambdas = rule.lambda_nm();
        let lambda_lo_um = lambdas.iter().cloned().fold(f64::INFINITY, f64::min) * 1e-3;
        let lambda_hi_um = lambdas.iter().cloned().fold(0.0, f64::max) * 1e-3;
        let k_ref = rule.k_per_um.iter().sum::<f64>() / rule.len() as f64;
        let w_scale = k_ref / table.kappa0;
        let s_max = (2.0 * w_scale).ln_1p();
        let n_w = ((s_max / W_NODE_STEP).ceil() as usize + 1).clamp(MIN_W_NODES, MAX_W_NODES);
        // The box: T's support at the reddest node, one cell more (its
        // bilinear read reaches zero there), within |u|, |v| <= 2.
        let (reach_x, reach_y) = support_cells(table);
        let reach = |cells: usize| ((cells + 1) as f64 * lambda_hi_um / table.tile_um).min(2.0);
        let (u_max, v_max) = (reach(reach_x), reach(reach_y));
        // Points per cell of T at the bluest node, fewer if the grid would
        // exceed MAX_VALUES.
        let cell_u = lambda_lo_um / table.tile_um;
        let points =
            |extent: f64, per_cell: f64| (2.0 * extent / cell_u * per_cell).ceil() as usize + 1;
        let area = (points(u_max, 1.0) * points(v_max, 1.0) * n_w * 3) as f64;
        let per_cell = UV_POINTS_PER_CELL
            .min((MAX_VALUES as f64 / area).sqrt())
            .max(0.25);
        let n_u = points(u_max, per_cell).max(2);
        let n_v = points(v_max, per_cell).max(2);
        RgbTable {
            n_w,
            n_u,
            n_v,
            w_scale,
            s_max,
            u_max,
            v_max,
            values: vec![0.0; n_w * n_u * n_v * 3],
        }
    }

    /// Computes the planes `which` of |w| nodes (all cores).
    fn fill(&mut self, which: &[usize], table: &SpectrumTable, rule: &RgbRule, fresnel: &Fresnel) {
        let (n_u, n_v) = (self.n_u, self.n_v);
        let grid = &*self;
        let plane = |iw: usize| -> Vec<f32> {
            let a = (grid.s_max * iw as f64 / (grid.n_w - 1) as f64).exp();
            let w = (a - 1.0) / grid.w_scale;
            let a4 = (a * a) * (a * a);
            let mut out = Vec::with_capacity(n_u * n_v * 3);
            let mut nodes = vec![0.0; rule.len()];
            for iy in 0..n_v {
                let v = grid.point_at(iy as f64, n_v, grid.v_max);
                for ix in 0..n_u {
                    let u = grid.point_at(ix as f64, n_u, grid.u_max);
                    let rgb = by_nodes(table, rule, fresnel, w, u, v, &mut nodes);
                    out.extend(rgb.map(|c| (c * a4) as f32));
                }
            }
            out
        };
        let threads = std::thread::available_parallelism()
            .map_or(1, |n| n.get())
            .min(which.len().max(1));
        let progress = &Progress::new("height map RGB table", which.len());
        let planes: Vec<(usize, Vec<f32>)> = std::thread::scope(|scope| {
            let plane = &plane;
            let handles: Vec<_> = (0..threads)
                .map(|t| {
                    scope.spawn(move || {
                        which[t.min(which.len())..]
                            .iter()
                            .step_by(threads)
                            .map(|&iw| {
                                let values = plane(iw);
                                progress.step();
                                (iw, values)
                            })
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            handles
                .into_iter()
                .flat_map(|h| h.join().expect("an RGB table thread"))
                .collect()
        });
        let len = 3 * n_u * n_v;
        for (iw, values) in planes {
            self.values[iw * len..(iw + 1) * len].copy_from_slice(&values);
        }
    }

    /// The build's check (see `CHECK_P90`): the 90th percentile of the
    /// table's error against the rule's nodes at points in its bright
    /// cells (of the slabs between planes i and i + 1 for i in `slabs`, or
    /// all).
    pub fn check_p90(
        &self,
        table: &SpectrumTable,
        rule: &RgbRule,
        fresnel: &Fresnel,
        slabs: Option<&[usize]>,
    ) -> f64 {
        let (n_u, n_v) = (self.n_u, self.n_v);
        let plane_len = 3 * n_u * n_v;
        // Bright grid points, by their lower corner.
        let mut bright = Vec::new();
        for (iw, plane) in self
            .values
            .chunks_exact(plane_len)
            .take(self.n_w - 1)
            .enumerate()
        {
            if slabs.is_some_and(|s| !s.contains(&iw)) {
                continue;
            }
            let peak = plane.iter().cloned().fold(0.0f32, f32::max);
            for iy in 0..n_v - 1 {
                for ix in 0..n_u - 1 {
                    let at = 3 * (iy * n_u + ix);
                    let value = plane[at..at + 3].iter().cloned().fold(0.0f32, f32::max);
                    if value > CHECK_BRIGHT * peak && value > 0.0 {
                        bright.push((iw, ix, iy));
                    }
                }
            }
        }
        if bright.is_empty() {
            return 0.0;
        }
        let mut rng = SplitMix64(0x5eed);
        let mut nodes = vec![0.0; rule.len()];
        let mut errors: Vec<f64> = (0..CHECK_POINTS)
            .map(|_| {
                let pick = ((rng.next_f64() * bright.len() as f64) as usize).min(bright.len() - 1);
                let (iw, ix, iy) = bright[pick];
                let [a, b, c] = rng.three();
                let s = self.s_max * (iw as f64 + a) / (self.n_w - 1) as f64;
                let w = s.exp_m1() / self.w_scale;
                let u = self.point_at(ix as f64 + b, n_u, self.u_max);
                let v = self.point_at(iy as f64 + c, n_v, self.v_max);
                let want = by_nodes(table, rule, fresnel, w, u, v, &mut nodes);
                let got = self.read(w, u, v, |at| self.values[at as usize] as f64);
                let scale = want.iter().cloned().fold(0.0, f64::max);
                if scale > 0.0 {
                    (0..3)
                        .map(|i| (got[i] - want[i]).abs() / scale)
                        .fold(0.0, f64::max)
                } else {
                    f64::INFINITY
                }
            })
            .collect();
        errors.sort_by(f64::total_cmp);
        errors[(errors.len() - 1) * 9 / 10]
    }

    /// The coordinate of fractional grid position `f` of `count` over
    /// [-extent, extent].
    fn point_at(&self, f: f64, count: usize, extent: f64) -> f64 {
        -extent + 2.0 * extent * f / (count - 1) as f64
    }

    pub fn memory_bytes(&self) -> usize {
        self.values.len() * 4
    }

    /// (w nodes, u points, v points, u extent, v extent).
    pub fn shape(&self) -> (usize, usize, usize, f64, f64) {
        (self.n_w, self.n_u, self.n_v, self.u_max, self.v_max)
    }

    /// The sum's three channels at the pair's (|w|, u, v), trilinear; 0
    /// outside the grid's box. Any `Real`, `fetch` reading `values`.
    #[inline]
    pub(crate) fn read<R: Real>(&self, w_abs: R, u: R, v: R, fetch: impl Fn(R) -> R) -> [R; 3] {
        let a = w_abs * self.w_scale + 1.0;
        let last_w = (self.n_w - 1) as f64;
        let x = (a.ln() * (last_w / self.s_max)).clamp(0.0, last_w);
        let iw = x.floor().min(last_w - 1.0);
        let tw = x - iw;
        let (nu, nv) = (self.n_u as f64, self.n_v as f64);
        let fx = (u + self.u_max) * ((nu - 1.0) / (2.0 * self.u_max));
        let fy = (v + self.v_max) * ((nv - 1.0) / (2.0 * self.v_max));
        let inside = fx.ge(0.0) & fx.le(nu - 1.0) & fy.ge(0.0) & fy.le(nv - 1.0);
        let (fx, fy) = (fx.clamp(0.0, nu - 1.0), fy.clamp(0.0, nv - 1.0));
        let (ix, iy) = (fx.floor().min(nu - 2.0), fy.floor().min(nv - 2.0));
        let (tx, ty) = (fx - ix, fy - iy);
        let base = ((iw * nv + iy) * nu + ix) * 3.0;
        let (row, plane) = (3.0 * nu, 3.0 * nu * nv);
        let a2 = a * a;
        let inv_a4 = (a2 * a2).constant(1.0) / (a2 * a2);
        std::array::from_fn(|c| {
            let at = base + c as f64;
            let cell = |at: R| bilinear(&fetch, at, 3.0, row, tx, ty);
            let (e0, e1) = (cell(at), cell(at + plane));
            // Linear in |w| (T's own nodes blend geometrically): a
            // geometric blend here moved the demo maps' checks by at most
            // 0.008 and would cost three blends per read.
            let e = e0 + (e1 - e0) * tw;
            R::select(inside, e * inv_a4, u.constant(0.0))
        })
    }
}

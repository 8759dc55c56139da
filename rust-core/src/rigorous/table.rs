//! Rigorous efficiencies tabulated for rendering: each reflected order's
//! unpolarised efficiency over (wavelength, kx, ky), where (kx, ky) is the
//! incident light's tangential wavevector over k0 (x across the grooves),
//! built once per grating on all cores and kept in an in-process cache and
//! an on-disk cache (keyed by the grating, the grid and `SOLVER_VERSION`).
//!
//! Efficiencies do not change under ky -> -ky (the grating is invariant
//! along y), so the table covers ky >= 0; a grating that is its own mirror
//! image (rect, sine, a symmetric tabulated profile) also has
//! eta_m(kx) = eta_-m(-kx), and its table covers kx >= 0 alone. Rows are
//! (wavelength, kx); one eigen-decomposition per row serves every ky
//! (`solver::Prepared`). Efficiencies have kinks at the Rayleigh anomalies,
//! where an order m grazes, ky_m^2 = n1^2 - (kx + m lambda / Lam)^2, and
//! just beyond each, where that order has become evanescent, a resonance (a
//! surface wave, in s and p alike in conical mounting). A row's ky nodes
//! follow both (`Row::layout`): every anomaly is a node, and the band beyond
//! it is sampled densely in sqrt(ky^2 - ky_m^2), the variable in which the
//! kink is a straight line. Along a row values are cubic in that variable
//! within a segment. Between rows, a lookup reads each neighbouring row at
//! a ky shifted so that the query's nearby anomalies land on the same
//! orders' anomalies in that row (`EfficiencyTable::locate`).

use std::sync::Mutex;

use super::layers::{Grating, Medium};
use super::polarisation::{self, Mueller};

mod cache;
use super::solver::{prepare, Factorisation};
use crate::optics::profile::Profile;
use crate::progress::Progress;
use crate::StamError;
pub use cache::{cache_dir, table, table_from_disk};

/// Bump when the solver's results or the table's layout change: it keys the
/// on-disk cache. 3: tables built on threads that flush subnormals (a
/// Mitsuba scene's loading) were wrong before float_env.rs. 4: polarised
/// tables (Mueller matrices, odd blocks over ky).
pub const SOLVER_VERSION: u32 = 4;

/// The grid of a table and the solver's truncation.
#[derive(Clone, Debug, PartialEq)]
pub struct TableSpec {
    pub lambda_min_nm: f64,
    pub lambda_max_nm: f64,
    pub n_lambda: usize,
    /// Rows over kx in [-n1, n1], uniform in v with kx = n1 sin(1.2 v) /
    /// sin(1.2) (denser towards the disc's edge). A grating symmetric under
    /// x -> -x (rect, sine, a symmetric tabulated profile) is built on the
    /// rows with kx >= 0 alone, n_kx / 2 + 1 of them over [0, n1], and read
    /// at -kx through eta_m(kx) = eta_-m(-kx).
    pub n_kx: usize,
    /// Density of the ky nodes (>= 1): nodes per 0.25 of sqrt(ky^2 -
    /// ky_m^2) in the band above each anomaly, 2.5 times fewer beyond it
    /// (see `Row::layout`). 4 gives about 28 nodes per row on the compact
    /// disc.
    pub nodes_per_gap: usize,
    /// Fourier orders -N..N of the solver.
    pub orders: usize,
    /// Index of the incidence medium.
    pub cover_eta: f64,
    /// Whether the table also holds each order's Mueller matrix (16 times
    /// the memory; `EfficiencyTable::mueller`): polarised renders.
    pub polarised: bool,
}

/// One (wavelength, kx) row: efficiencies at ky nodes.
#[derive(Clone, Debug)]
struct Row {
    /// ky^2 at the ends of the row's segments, ascending: from 0 over the
    /// Rayleigh anomalies inside the incidence disc to its edge (order 0's
    /// anomaly), each gap between two cut in two (see `Row::layout`).
    breaks: Vec<f64>,
    /// Index of the node on each break.
    first: Vec<u32>,
    /// Per segment: nodes uniform in sqrt(ky^2 - start) (true: the
    /// segment above an anomaly) or in sqrt(end - ky^2).
    rising: Vec<bool>,
    ky: Vec<f64>,
    /// [node][m - m_min].
    values: Vec<f32>,
    /// [node][m - m_min][16]: each order's Mueller matrix in the groove
    /// bases (`polarisation`), where the spec is polarised; else empty.
    mueller: Vec<f32>,
    /// The row's lambda / Lam and kx (as solved), which every lookup reads.
    step: f64,
    kx: f64,
}

/// Above an anomaly, the order that just stopped propagating carries a
/// resonance (a surface wave) within about this much of grazing in
/// k_t^2 / n1^2: the first part of each gap, sampled densely.
const RESONANCE_BAND: f64 = 0.1;

/// ky^2 of the breakpoints of a row at (lambda, kx): 0, then every
/// anomaly 1 - (kx + m lambda / Lam)^2 inside the incidence disc (n1 = 1
/// units: everything is over n1), ascending; anomalies closer than 1e-9
/// (orders +-m at kx = 0, say) are one.
fn row_breaks(step: f64, kx: f64, n1: f64) -> Vec<f64> {
    let reach = (2.0 * n1 / step).ceil() as i64 + 1;
    let edge2 = (n1 * n1 - kx * kx).max(0.0);
    let mut points: Vec<f64> = vec![0.0];
    for m in -reach..=reach {
        let k = kx + m as f64 * step;
        if k.abs() < n1 && k.abs() >= kx.abs() {
            points.push((n1 * n1 - k * k).min(edge2));
        }
    }
    points.sort_by(f64::total_cmp);
    let mut merged: Vec<f64> = Vec::with_capacity(points.len());
    for y in points {
        match merged.last() {
            Some(&last) if y - last < 1e-9 => {}
            _ => merged.push(y),
        }
    }
    merged
}

impl Row {
    /// The layout of a row: its segments and ky nodes (values empty). Each
    /// gap (a, b) between anomalies is cut at c = a + min(RESONANCE_BAND,
    /// 0.6 (b - a)): over (a, c) the nodes are uniform in sqrt(ky^2 - a),
    /// the square root of the kink at a and the variable of the resonance
    /// beside it, `per_gap` of them per 0.25; over (c, b) uniform in
    /// sqrt(b - ky^2), 2.5 times sparser (the kink at b, nothing sharp).
    fn layout(step: f64, kx: f64, n1: f64, per_gap: usize) -> Row {
        let anomalies = row_breaks(step, kx, n1);
        let h = 0.25 / per_gap as f64;
        let mut row = Row {
            breaks: vec![0.0],
            first: vec![0],
            rising: Vec::new(),
            ky: vec![0.0],
            values: Vec::new(),
            mueller: Vec::new(),
            step,
            kx,
        };
        for pair in anomalies.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            let c = a + (0.6 * (b - a)).min(RESONANCE_BAND);
            for (p, q, rising, h) in [(a, c, true, h), (c, b, false, 2.5 * h)] {
                let count = ((q - p).sqrt() / h).ceil().max(1.0) as usize;
                // A hair inside each anomaly: an order exactly grazing is a limit.
                let margin = 1e-12 * (b - a);
                for l in 1..=count {
                    let u = l as f64 / count as f64;
                    let y2 = if rising {
                        p + (q - p) * u * u
                    } else {
                        q - (q - p) * (1.0 - u) * (1.0 - u)
                    };
                    row.ky.push(y2.clamp(a + margin, b - margin).sqrt());
                }
                row.breaks.push(q);
                row.first.push(row.ky.len() as u32 - 1);
                row.rising.push(rising);
            }
        }
        row
    }

    /// The segment g that ky^2 = `y2` falls in, its position x in node
    /// intervals from the segment's first node i0, and its interval count.
    fn segment(&self, y2: f64) -> Option<(usize, f64, usize, usize)> {
        let n = self.breaks.len();
        if n < 2 {
            return None;
        }
        let g = self.breaks.partition_point(|&b| b <= y2).clamp(1, n - 1) - 1;
        let (a, b) = (self.breaks[g], self.breaks[g + 1]);
        let t = if b > a {
            ((y2 - a) / (b - a)).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let (i0, i1) = (self.first[g] as usize, self.first[g + 1] as usize);
        let count = i1 - i0;
        let u = if self.rising[g] {
            t.sqrt()
        } else {
            1.0 - (1.0 - t).sqrt()
        };
        Some((g, u * count as f64, i0, count))
    }

    /// Where ky^2 = `y2` falls: the first of four nodes and their weights,
    /// cubic in the nodes' parameter u (ky^2 = a + (b - a)(1 - cos pi u) / 2
    /// within a gap (a, b)), in which a square root at an anomaly is a
    /// straight line. The four nodes stay within the gap (where the
    /// efficiencies are smooth in u); a gap of fewer intervals is read
    /// quadratically or linearly.
    fn place(&self, y2: f64) -> (u32, [f32; 4]) {
        let Some((_, x, i0, count)) = self.segment(y2) else {
            return (0, [1.0, 0.0, 0.0, 0.0]);
        };
        let points = (count + 1).min(4);
        let start = ((x as usize).saturating_sub(1)).min(count + 1 - points);
        let s = x - start as f64;
        let w = match points {
            4 => [
                -(s - 1.0) * (s - 2.0) * (s - 3.0) / 6.0,
                s * (s - 2.0) * (s - 3.0) / 2.0,
                -s * (s - 1.0) * (s - 3.0) / 2.0,
                s * (s - 1.0) * (s - 2.0) / 6.0,
            ],
            3 => [
                (s - 1.0) * (s - 2.0) / 2.0,
                -s * (s - 2.0),
                s * (s - 1.0) / 2.0,
                0.0,
            ],
            _ => [1.0 - s, s, 0.0, 0.0],
        };
        (
            (i0 + start) as u32,
            [w[0] as f32, w[1] as f32, w[2] as f32, w[3] as f32],
        )
    }
}

/// Unpolarised efficiencies of orders m_min..=m_max; zero where an order
/// does not propagate.
#[derive(Clone, Debug)]
pub struct EfficiencyTable {
    pub spec: TableSpec,
    pub m_min: i64,
    pub m_max: i64,
    period_um: f64,
    /// Rows only for kx >= 0, read at -kx by symmetry.
    symmetric: bool,
    /// [lambda][kx].
    rows: Vec<Row>,
    /// Seconds the build took (0 when read from the disk cache).
    pub build_seconds: f64,
}

/// Where a query reads the table: up to four rows, each with a weight, a
/// node and the weight of the node after it; `mirror` when read at -kx and
/// order -m.
#[derive(Clone, Copy, Debug)]
struct Lookup {
    mirror: bool,
    /// ky^2 each row is read at (diagnosis).
    #[cfg(test)]
    y2: [f64; 4],
    reads: [(u32, [f32; 4]); 4],
    weights: [f64; 4],
    rows: [u32; 4],
    /// The query's (kx, lambda / Lam, ky^2) and each row's, as read.
    query: [f64; 3],
    places: [[f64; 3]; 4],
}

fn node(min: f64, max: f64, n: usize, i: usize) -> f64 {
    if n < 2 {
        min
    } else {
        min + (max - min) * i as f64 / (n - 1) as f64
    }
}

/// (cell, fraction) of `x` on `n` uniform nodes over [min, max].
fn cell(x: f64, min: f64, max: f64, n: usize) -> (usize, f64) {
    if n < 2 || !(max > min) {
        return (0, 0.0);
    }
    let t = ((x - min) / (max - min) * (n - 1) as f64).clamp(0.0, (n - 1) as f64);
    let i = (t as usize).min(n - 2);
    (i, t - i as f64)
}

/// Anomalies a little outside the disc (|kx + m lambda / Lam| up to
/// sqrt(n1^2 + VIRTUAL)) still bring their order's resonance into it.
const VIRTUAL: f64 = 0.15;

/// How far (in ky^2 / n1^2) a row's reading may fall off the row before it
/// stops counting (see `EfficiencyTable::locate`).
const OFF_ROW: f64 = 0.02;

/// smoothstep: 0 and 1 with zero slope at both ends.
fn smooth(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

impl EfficiencyTable {
    pub fn lambda_nm(&self, i: usize) -> f64 {
        let s = &self.spec;
        node(s.lambda_min_nm, s.lambda_max_nm, s.n_lambda, i)
    }

    /// Rows over kx: n_kx, or n_kx / 2 + 1 over [0, n1] for a symmetric
    /// grating.
    pub fn n_kx_rows(&self) -> usize {
        kx_rows(&self.spec, self.symmetric)
    }

    /// kx of row ix (the row was solved just inside the disc at kx = +-n1).
    /// Rows are uniform in v over [-1, 1] ([0, 1] for a symmetric grating),
    /// kx = n1 sin(c v) / sin(c): denser towards the disc's edge, where the
    /// rows are short and grazing incidence changes fast.
    pub fn kx(&self, ix: usize) -> f64 {
        let lo = if self.symmetric { 0.0 } else { -1.0 };
        self.spec.cover_eta * kx_of(node(lo, 1.0, self.n_kx_rows(), ix))
    }

    /// Whether the table holds kx >= 0 alone (a symmetric grating).
    pub fn symmetric(&self) -> bool {
        self.symmetric
    }

    fn orders(&self) -> usize {
        (self.m_max - self.m_min + 1) as usize
    }

    fn row(&self, il: usize, ix: usize) -> &Row {
        &self.rows[il * self.n_kx_rows() + ix]
    }

    /// The ky nodes of row (il, ix).
    pub fn ky_nodes(&self, il: usize, ix: usize) -> &[f64] {
        &self.row(il, ix).ky
    }

    /// ky nodes in the whole table (each one solve).
    pub fn node_count(&self) -> usize {
        self.rows.iter().map(|r| r.ky.len()).sum()
    }

    /// Memory held by the values and nodes.
    pub fn memory_bytes(&self) -> usize {
        self.rows
            .iter()
            .map(|r| (r.values.len() + r.mueller.len()) * 4 + r.ky.len() * 8 + r.breaks.len() * 13)
            .sum()
    }

    /// Efficiency of order m at node `iy` of row (il, ix).
    pub fn at_node(&self, il: usize, ix: usize, iy: usize, m: i64) -> f64 {
        if m < self.m_min || m > self.m_max {
            return 0.0;
        }
        self.row(il, ix).values[iy * self.orders() + (m - self.m_min) as usize] as f64
    }

    /// The kx at which row ix was solved (just inside the disc at its ends).
    fn row_kx(&self, ix: usize) -> f64 {
        let n1 = self.spec.cover_eta;
        self.kx(ix).clamp(-0.9995 * n1, 0.9995 * n1)
    }

    fn step(&self, lambda_nm: f64) -> f64 {
        lambda_nm * 1e-3 / self.period_um
    }

    /// The rows around (lambda, kx, ky) and where to read each: bilinear
    /// over (lambda, kx); each row is read at ky'^2 = ky^2 + a shift, the
    /// average of the shifts that carry each of the query's anomalies onto
    /// the same order's anomaly in that row, weighted 1 / (distance in
    /// ky^2)^2: next to an anomaly the row is read at the same distance
    /// k_t^2 - n1^2 of that order from grazing, so the kink and the
    /// resonance beside it stay where they are. Anomalies just outside the
    /// disc count too (fading out by VIRTUAL). A row that does not hold the
    /// shifted place (a row nearer the edge than the query's |k_t|, or one
    /// without that anomaly) hands its weight to its neighbour.
    fn locate(&self, lambda_nm: f64, kx: f64, ky: f64) -> Lookup {
        self.locate_with(lambda_nm, kx, ky, true)
    }

    /// `locate`, with each row read at the query's own ky where not
    /// `shifted` (the Mueller matrices' read, see `mueller`).
    fn locate_with(&self, lambda_nm: f64, kx: f64, ky: f64, shifted: bool) -> Lookup {
        let s = &self.spec;
        let n1 = s.cover_eta;
        let mirror = self.symmetric && kx < 0.0;
        let kx = if mirror { -kx } else { kx }.clamp(-0.9995 * n1, 0.9995 * n1);
        let lambda = lambda_nm.clamp(s.lambda_min_nm, s.lambda_max_nm);
        let edge2 = n1 * n1 - kx * kx;
        let y2 = (ky * ky).min(edge2);
        let step = self.step(lambda);
        // The query's anomalies: order m grazes at ky^2 = a_m = n1^2 -
        // (kx + m step)^2. Each row is read at ky^2 plus the shifts that
        // carry these onto the same orders' anomalies in that row, averaged
        // with weights w_m = 1 / (distance in ky^2)^2: at an anomaly, that
        // anomaly's shift. A shift, (kx + m step)^2 - (kx_r + m step_r)^2,
        // is quadratic in m, so the average needs only the weights' first
        // two moments in m (order 0 always counts: total > 0).
        let reach = (n1 * n1 + VIRTUAL).sqrt();
        let m_first = ((-reach - kx) / step).ceil() as i64;
        let m_last = ((reach - kx) / step).floor() as i64;
        let (mut total, mut moment1, mut moment2) = (0.0, 0.0, 0.0);
        for m in m_first..=m_last {
            let k = kx + m as f64 * step;
            if k.abs() < kx.abs() && m != 0 {
                continue;
            }
            let a = n1 * n1 - k * k;
            // Anomalies outside the disc fade out by VIRTUAL.
            let fade = if a >= 0.0 {
                1.0
            } else {
                smooth(1.0 + a / VIRTUAL)
            };
            let d = y2 - a;
            let weight = fade / (d * d + 1e-24);
            let m = m as f64;
            total += weight;
            moment1 += weight * m;
            moment2 += weight * m * m;
        }
        let (moment1, moment2) = (moment1 / total, moment2 / total);
        let nx = self.n_kx_rows();
        let (il, tl) = cell(lambda, s.lambda_min_nm, s.lambda_max_nm, s.n_lambda);
        let v_min = if self.symmetric { 0.0 } else { -1.0 };
        let (ix, tx) = cell(v_of(kx / n1), v_min, 1.0, nx);
        let next = |i: usize, n: usize| if n < 2 { i } else { (i + 1).min(n - 1) };
        let mut out = Lookup {
            mirror,
            reads: [(0, [0.0; 4]); 4],
            #[cfg(test)]
            y2: [0.0; 4],
            weights: [0.0; 4],
            rows: [0; 4],
            query: [kx, step, y2],
            places: [[0.0; 3]; 4],
        };
        let mut slot = 0;
        let mut fit = [1.0f64; 4];
        for (jl, wl) in [(il, 1.0 - tl), (next(il, s.n_lambda), tl)] {
            for (jx, wx) in [(ix, 1.0 - tx), (next(ix, nx), tx)] {
                let weight = wl * wx;
                let r = jl * nx + jx;
                let (row_step, row_kx) = (self.rows[r].step, self.rows[r].kx);
                let shift = (kx * kx - row_kx * row_kx)
                    + 2.0 * (kx * step - row_kx * row_step) * moment1
                    + (step * step - row_step * row_step) * moment2;
                let y2_there = if shifted { y2 + shift } else { y2 };
                let edge_there = n1 * n1 - row_kx * row_kx;
                out.reads[slot] = self.rows[r].place(y2_there.clamp(0.0, edge_there));
                out.places[slot] = [row_kx, row_step, y2_there.clamp(0.0, edge_there)];
                #[cfg(test)]
                {
                    out.y2[slot] = y2_there.clamp(0.0, edge_there);
                }
                out.weights[slot] = weight;
                out.rows[slot] = r as u32;
                // How well the row holds the query's place: not at all when
                // the shifted ky^2 falls off the row by more than OFF_ROW
                // (an anomaly that the row lacks, or a row nearer the disc's
                // edge than the query's |k_t|).
                let off = (-y2_there).max(y2_there - edge_there).max(0.0);
                fit[slot] = smooth(1.0 - off / OFF_ROW);
                slot += 1;
            }
        }
        // Hand the weight of a row that does not hold the query to its
        // neighbour in kx, else in lambda (continuously, by `fit`).
        for (from, to) in [
            (0, 1),
            (1, 0),
            (2, 3),
            (3, 2),
            (0, 2),
            (2, 0),
            (1, 3),
            (3, 1),
        ] {
            if fit[to] > fit[from] {
                let moved = out.weights[from] * (fit[to] - fit[from]);
                out.weights[from] -= moved;
                out.weights[to] += moved;
            }
        }
        out
    }

    /// The rows a query reads: (lambda, kx, ky, weight, value of order m
    /// read there) in the frame of the rows (kx >= 0 when mirrored, and
    /// order -m).
    #[cfg(test)]
    pub(super) fn reads(&self, lambda_nm: f64, kx: f64, ky: f64, m: i64) -> Vec<[f64; 5]> {
        let at = self.locate(lambda_nm, kx, ky);
        let m = if at.mirror { -m } else { m };
        let nx = self.n_kx_rows();
        (0..4)
            .map(|slot| {
                let r = at.rows[slot] as usize;
                let mut one = at;
                one.weights = [0.0; 4];
                one.weights[slot] = 1.0;
                [
                    self.lambda_nm(r / nx),
                    self.row_kx(r % nx),
                    at.y2[slot].sqrt(),
                    at.weights[slot],
                    self.read(&one, (m - self.m_min) as usize),
                ]
            })
            .collect()
    }

    /// Order k = m - m_min at a located query.
    fn read(&self, at: &Lookup, k: usize) -> f64 {
        // Cubic weights can overshoot a sharp peak a little.
        self.read_channels::<1>(at, k, |row| &row.values)
            .map_or(0.0, |[v]| v.clamp(0.0, 1.0))
    }

    /// The C channels of order k = m - m_min at a located query (a node of
    /// a row holds them at `values(row)[C (node orders + k)..]`): the rows'
    /// weighted reads, where rows read where the order does not propagate
    /// (its anomaly moved past the query's place there) do not count while
    /// others do. None where the order does not propagate at the query (it
    /// carries nothing).
    fn read_channels<const C: usize>(
        &self,
        at: &Lookup,
        k: usize,
        values: impl Fn(&Row) -> &[f32],
    ) -> Option<[f64; C]> {
        let orders = self.orders();
        let n1 = self.spec.cover_eta;
        let m = self.m_min + k as i64;
        let propagates = |[kx, step, y2]: [f64; 3]| {
            let k = kx + m as f64 * step;
            k * k + y2 < n1 * n1
        };
        if !propagates(at.query) {
            return None;
        }
        let (mut sum, mut sum_all, mut total) = ([0.0f64; C], [0.0f64; C], 0.0);
        for slot in 0..4 {
            let weight = at.weights[slot];
            if weight == 0.0 {
                continue;
            }
            let data = values(&self.rows[at.rows[slot] as usize]);
            let (i, w) = at.reads[slot];
            let counts = propagates(at.places[slot]);
            for (j, wj) in w.iter().enumerate() {
                if *wj == 0.0 {
                    continue;
                }
                let node = &data[C * ((i as usize + j) * orders + k)..][..C];
                let wt = weight * *wj as f64;
                for ((s, a), v) in sum.iter_mut().zip(sum_all.iter_mut()).zip(node) {
                    *a += wt * *v as f64;
                    if counts {
                        *s += wt * *v as f64;
                    }
                }
            }
            if counts {
                total += weight;
            }
        }
        Some(if total > 0.0 {
            sum.map(|v| v / total)
        } else {
            sum_all
        })
    }

    /// Efficiency of order m at (lambda, kx, ky), (kx, ky) the incident
    /// tangential wavevector over k0: bilinear over the four rows around
    /// (lambda, kx), each read with its anomalies carried onto the query's
    /// (see `locate`). Wavelengths outside the table read its ends.
    pub fn efficiency(&self, lambda_nm: f64, kx: f64, ky: f64, m: i64) -> f64 {
        let at = self.locate(lambda_nm, kx, ky);
        let m = if at.mirror { -m } else { m };
        if m < self.m_min || m > self.m_max {
            return 0.0;
        }
        self.read(&at, (m - self.m_min) as usize)
    }

    /// Every order's efficiency at (lambda, kx, ky) at once: out[m - m_min]
    /// for m in m_min..=m_max (out must hold m_max - m_min + 1 values).
    pub fn efficiencies(&self, lambda_nm: f64, kx: f64, ky: f64, out: &mut [f64]) {
        let at = self.locate(lambda_nm, kx, ky);
        let orders = self.orders();
        for (k, o) in out.iter_mut().enumerate().take(orders) {
            // m_min = -m_max: order m at -kx is order -m here.
            let kk = if at.mirror { orders - 1 - k } else { k };
            *o = self.read(&at, kk);
        }
    }
}

impl EfficiencyTable {
    /// Whether the table holds Mueller matrices (`TableSpec::polarised`).
    pub fn is_polarised(&self) -> bool {
        // A polarised spec's rows all hold them (`solve_row`, the disk
        // reader).
        self.spec.polarised
    }

    /// Order m's Mueller matrix at (lambda, kx, ky) in the groove bases
    /// (`polarisation`), its [0][0] the order's unpolarised efficiency,
    /// read from the rows `efficiency` reads, but each at the query's own
    /// ky: carrying the anomalies onto each row's (`locate`) moves the
    /// read along ky^2, which suits an efficiency's kinks but smears the
    /// smooth turn of a polarisation (measured: up to 0.15 per element on
    /// a flat grating near grazing, against 0.03 unshifted). The
    /// off-diagonal blocks, odd in ky, are held over ky (even, smooth at
    /// ky = 0) and multiplied back. Between
    /// nodes a read may leave the realisable set by a little
    /// (`polarisation::realisable` mends it). None where the table holds
    /// none; zeros where the order does not propagate.
    pub fn mueller(&self, lambda_nm: f64, kx: f64, ky: f64, m: i64) -> Option<Mueller> {
        if !self.is_polarised() {
            return None;
        }
        let at = self.locate_with(lambda_nm, kx, ky, false);
        let m = if at.mirror { -m } else { m };
        let mut out = [0.0; 16];
        if m < self.m_min || m > self.m_max {
            return Some(out);
        }
        let Some(sum) =
            self.read_channels::<16>(&at, (m - self.m_min) as usize, |row| &row.mueller)
        else {
            return Some(out);
        };
        // The odd blocks are held over ky.
        let ky_abs = at.query[2].sqrt();
        for (e, (o, v)) in out.iter_mut().zip(sum).enumerate() {
            *o = if polarisation::odd_in_ky(e) {
                v * ky_abs
            } else {
                v
            };
        }
        // The table holds ky >= 0 (and kx >= 0 for a symmetric grating):
        // each mirror is D M D.
        if at.mirror != (ky < 0.0) {
            polarisation::mirrored(&mut out);
        }
        Some(out)
    }
}

/// The rows' warp of kx (see `EfficiencyTable::kx`).
const KX_WARP: f64 = 1.2;

fn kx_of(v: f64) -> f64 {
    (KX_WARP * v).sin() / KX_WARP.sin()
}

fn v_of(kx: f64) -> f64 {
    (kx * KX_WARP.sin()).clamp(-1.0, 1.0).asin() / KX_WARP
}

fn kx_rows(spec: &TableSpec, symmetric: bool) -> usize {
    if symmetric {
        spec.n_kx / 2 + 1
    } else {
        spec.n_kx
    }
}

/// Whether a grating's profile is its own mirror image (x -> c - x for some
/// c): then eta_m(lambda, kx, ky) = eta_-m(lambda, -kx, ky).
pub fn is_symmetric(grating: &Grating) -> bool {
    match &grating.profile {
        Profile::Rect { .. } | Profile::Sine { .. } => true,
        Profile::Tabulated { heights_um } => {
            // Linear between samples: mirrored about a sample or a midpoint.
            let n = heights_um.len();
            (0..n).any(|s| (0..n).all(|i| heights_um[(s + n - i) % n] == heights_um[i]))
        }
    }
}

/// Text that identifies a table: the grating, the grid, the solver.
pub fn table_key(grating: &Grating, spec: &TableSpec) -> String {
    let profile = match &grating.profile {
        Profile::Rect {
            height_um,
            width_um,
        } => format!("rect h={height_um:e} w={width_um:e}"),
        Profile::Sine { height_um } => format!("sine h={height_um:e}"),
        Profile::Tabulated { heights_um } => format!("tabulated h={heights_um:?}"),
    };
    let metal = match grating.metal {
        Medium::Metal(t) => t.name.to_string(),
        Medium::Index { eta, k } => format!("{eta:e}+{k:e}i"),
    };
    format!(
        "stam rigorous v{SOLVER_VERSION}; period={:e} {profile} slices={} metal={metal}; {spec:?}",
        grating.period_um, grating.slices
    )
}

/// Build a table (all cores), printing progress to stderr when it takes
/// more than a second.
pub fn build(grating: &Grating, spec: &TableSpec) -> Result<EfficiencyTable, StamError> {
    build_with(grating, spec, is_symmetric(grating))
}

/// `build`, with the rows for kx < 0 left out (`symmetric`) or not.
pub(super) fn build_with(
    grating: &Grating,
    spec: &TableSpec,
    symmetric: bool,
) -> Result<EfficiencyTable, StamError> {
    if spec.n_lambda < 1 || spec.n_kx < 2 || spec.nodes_per_gap < 1 {
        return Err(StamError::new(
            "rigorous table: at least 1 wavelength, 2 kx rows and 1 node per gap",
        ));
    }
    if !(spec.lambda_min_nm > 0.0 && spec.lambda_max_nm >= spec.lambda_min_nm) {
        return Err(StamError::new(format!(
            "rigorous table: wavelengths {}..{} nm",
            spec.lambda_min_nm, spec.lambda_max_nm
        )));
    }
    if !(spec.cover_eta >= 1.0 && spec.cover_eta < 10.0) {
        return Err(StamError::new(format!(
            "rigorous table: cover_eta must be in [1, 10), got {}",
            spec.cover_eta
        )));
    }
    let n1 = spec.cover_eta;
    // Orders that can propagate anywhere on the grid: |kx + m lambda / Lam| < n1.
    let m_reach = (2.0 * n1 * grating.period_um / (spec.lambda_min_nm * 1e-3)).ceil() as i64;
    let mut table = EfficiencyTable {
        spec: spec.clone(),
        m_min: -m_reach,
        m_max: m_reach,
        period_um: grating.period_um,
        symmetric,
        rows: Vec::new(),
        build_seconds: 0.0,
    };
    let nx = table.n_kx_rows();
    let mut rows: Vec<(usize, usize)> = (0..spec.n_lambda)
        .flat_map(|il| (0..nx).map(move |ix| (il, ix)))
        .collect();
    // The longest rows first: the threads finish together.
    let layout = |il: usize, ix: usize| {
        Row::layout(
            table.step(table.lambda_nm(il)),
            table.row_kx(ix),
            n1,
            spec.nodes_per_gap,
        )
    };
    let cost: Vec<usize> = rows
        .iter()
        .map(|&(il, ix)| layout(il, ix).ky.len())
        .collect();
    let order: Vec<usize> = {
        let mut o: Vec<usize> = (0..rows.len()).collect();
        o.sort_by_key(|&r| std::cmp::Reverse(cost[r]));
        o
    };
    rows = order.iter().map(|&r| rows[r]).collect();
    let label = if spec.polarised {
        "rigorous grating efficiencies and Mueller matrices"
    } else {
        "rigorous grating efficiencies"
    };
    let progress = Progress::new(label, rows.len());
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results: Mutex<Vec<(usize, Row)>> = Mutex::new(Vec::with_capacity(rows.len()));
    let first_error: Mutex<Option<StamError>> = Mutex::new(None);
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| loop {
                let r = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                if r >= rows.len() || first_error.lock().unwrap().is_some() {
                    break;
                }
                let (il, ix) = rows[r];
                match solve_row(grating, &table, il, ix) {
                    Ok(row) => results.lock().unwrap().push((il * nx + ix, row)),
                    Err(e) => {
                        *first_error.lock().unwrap() = Some(e);
                        break;
                    }
                }
                progress.step();
            });
        }
    });
    if let Some(e) = first_error.into_inner().unwrap() {
        return Err(e);
    }
    let mut results = results.into_inner().unwrap();
    results.sort_by_key(|(r, _)| *r);
    table.rows = results.into_iter().map(|(_, row)| row).collect();
    table.build_seconds = progress.seconds();
    Ok(table)
}

/// One (wavelength, kx) row: every ky node up to the incidence disc's edge
/// (a kx at or beyond the edge is read just inside it).
fn solve_row(
    grating: &Grating,
    table: &EfficiencyTable,
    il: usize,
    ix: usize,
) -> Result<Row, StamError> {
    let spec = &table.spec;
    let n1 = spec.cover_eta;
    let lambda = table.lambda_nm(il);
    let kx = table.row_kx(ix);
    let mut row = Row::layout(table.step(lambda), kx, n1, spec.nodes_per_gap);
    let orders = table.orders();
    row.values = vec![0.0f32; row.ky.len() * orders];
    if spec.polarised {
        row.mueller = vec![0.0f32; row.ky.len() * orders * 16];
    }
    let prepared = prepare(
        &grating.stack(lambda, n1),
        lambda,
        kx,
        spec.orders,
        Factorisation::Li,
    )?;
    for (iy, &y) in row.ky.iter().enumerate() {
        // At the disc's edge (grazing incidence) a solve can lose all
        // precision: step a little inside until it gives efficiencies.
        let mut d = prepared.solve(y);
        let mut nudge = 1e-9;
        while nudge < 1e-3
            && !d
                .reflected
                .iter()
                .all(|o| o.unpolarised().is_finite() && o.unpolarised() <= 1.0 + 1e-3)
        {
            d = prepared.solve(y * (1.0 - nudge));
            nudge *= 10.0;
        }
        for o in &d.reflected {
            if o.m >= table.m_min && o.m <= table.m_max {
                let e = o.unpolarised();
                let slot = iy * orders + (o.m - table.m_min) as usize;
                row.values[slot] = if e.is_finite() {
                    e.clamp(0.0, 1.0)
                } else {
                    0.0
                } as f32;
                if spec.polarised && e.is_finite() && e <= 1.0 + 1e-3 {
                    let kz = (n1 * n1 - kx * kx - y * y).max(0.0).sqrt();
                    let incident = [kx / n1, y / n1, kz / n1];
                    let m = polarisation::order_mueller(incident, o);
                    if m.iter().all(|v| v.is_finite()) {
                        for (out, v) in row.mueller[16 * slot..][..16].iter_mut().zip(m) {
                            *out = v as f32;
                        }
                    }
                }
            }
        }
    }
    if spec.polarised {
        hold_odd_blocks_over_ky(&mut row, orders);
    }
    Ok(row)
}

/// The odd blocks of a row's Mueller matrices divided by ky (see
/// `EfficiencyTable::mueller`); at ky = 0, the next node's quotient.
fn hold_odd_blocks_over_ky(row: &mut Row, orders: usize) {
    let n = row.ky.len();
    for iy in (0..n).rev() {
        let y = row.ky[iy];
        for k in 0..orders {
            for e in (0..16).filter(|&e| polarisation::odd_in_ky(e)) {
                let at = 16 * (iy * orders + k) + e;
                row.mueller[at] = if y > 0.0 {
                    (row.mueller[at] as f64 / y) as f32
                } else if iy + 1 < n {
                    row.mueller[16 * ((iy + 1) * orders + k) + e]
                } else {
                    0.0
                };
            }
        }
    }
}

//! The Gaussian-smoothed sRGB weight W~(mu, t = s^2) = (W * N_s)(mu) of the
//! gratings' RGB programs (program_rgb.rs): exact moments of the
//! piecewise-linear 1 nm weight on levels of t, each a uniform grid in mu,
//! kept as ln E and the ratios W~_c / E (E = X + Y + Z smoothed alike) with
//! their exact slopes in mu, in t and in both; and `SmoothedWeight`, which
//! reads them in a program, linearly or C1 along the parameters a renderer
//! differentiates.

use super::hermite::cubic_hermite_basis;
use crate::program::{Builder, Table, Value};
use crate::spectrum;
use std::f64::consts::{PI, SQRT_2};
use std::ops::RangeInclusive;
use std::sync::OnceLock;

pub(super) const NU_LO: f64 = 1000.0 / spectrum::LAMBDA_MAX_NM;
pub(super) const NU_HI: f64 = 1000.0 / spectrum::LAMBDA_MIN_NM;

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
pub(super) const MAX_LEVELS: usize = 128;
/// Values per grid point: ln E and the three ratios, then their slopes in
/// mu, in t, and in mu and t (POINT of each).
const POINT: usize = 4;
const STRIDE: usize = 4 * POINT;

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
pub(super) fn level_at_or_above(t: f64) -> usize {
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
pub(super) struct SmoothedWeight<'a> {
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
        cubic_hermite_basis(f, 1.0 - f),
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
    pub(super) fn new(
        b: &'a Builder,
        levels: RangeInclusive<usize>,
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
        for k in levels {
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
    pub(super) fn at(
        &self,
        b: &'a Builder,
        mu: Value<'a>,
        ln_scale: Value<'a>,
    ) -> [[Value<'a>; 3]; 3] {
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

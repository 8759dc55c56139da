//! Chi-square goodness of fit of a strategy's samples against its pdf.

use crate::benchmark::SplitMix64 as Rng;
use crate::models::Strategy;
use crate::sampling::warps::{normal_cdf, ONE_MINUS};
use crate::sampling::SampleResult;
use glam::DVec3;
use std::f64::consts::PI;

// ---- chi-square goodness of fit -------------------------------------
//
// Coordinates (t, b) in [0,1]^2: t = theta / (pi/2), b = phi / (2 pi), so
// d omega = pi^2 sin(theta) dt db (no singularity at the horizon, and a
// peak at the pole keeps its angular width). Cells are the leaves of
// a k-d tree built from an independent pilot sample (so they adapt to the
// lobes without depending on the counted samples); the pdf is integrated
// per cell by adaptive Gauss-Legendre cubature (pdf only, never the
// sampler). Two more cells: coherent samples (expected: the coherent
// probability) and failed samples (expected: 1 - coherent - integral).

fn to_sb(wo: DVec3) -> (f64, f64) {
    let b = wo.y.atan2(wo.x) / (2.0 * PI);
    let theta = wo.z.clamp(-1.0, 1.0).acos();
    (
        theta / (0.5 * PI),
        if b < 0.0 { b + 1.0 } else { b.min(ONE_MINUS) },
    )
}

fn from_sb(t: f64, b: f64) -> DVec3 {
    let theta = 0.5 * PI * t;
    let phi = 2.0 * PI * b;
    DVec3::new(
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    )
}

/// Density in (t, b): d omega = sin(theta) (pi / 2) (2 pi) dt db.
fn jacobian_sb(t: f64) -> f64 {
    (0.5 * PI * t).sin() * PI * PI
}

#[derive(Clone, Copy)]
struct Rect {
    lo: [f64; 2],
    hi: [f64; 2],
}

enum Node {
    Leaf(usize),
    Split {
        dim: usize,
        at: f64,
        left: Box<Node>,
        right: Box<Node>,
    },
}

fn build(points: &mut [[f64; 2]], rect: Rect, leaf: usize, cells: &mut Vec<Rect>) -> Node {
    let (ds, db) = (rect.hi[0] - rect.lo[0], rect.hi[1] - rect.lo[1]);
    if points.len() <= leaf || ds.max(db) < 1e-9 {
        cells.push(rect);
        return Node::Leaf(cells.len() - 1);
    }
    let dim = if ds >= db { 0 } else { 1 };
    points.sort_by(|p, q| p[dim].total_cmp(&q[dim]));
    let mid = points.len() / 2;
    let at = 0.5 * (points[mid - 1][dim] + points[mid][dim]);
    let (mut lr, mut rr) = (rect, rect);
    lr.hi[dim] = at;
    rr.lo[dim] = at;
    let (l, r) = points.split_at_mut(mid);
    Node::Split {
        dim,
        at,
        left: Box::new(build(l, lr, leaf, cells)),
        right: Box::new(build(r, rr, leaf, cells)),
    }
}

fn find(node: &Node, p: [f64; 2]) -> usize {
    match node {
        Node::Leaf(i) => *i,
        Node::Split {
            dim,
            at,
            left,
            right,
        } => {
            if p[*dim] < *at {
                find(left, p)
            } else {
                find(right, p)
            }
        }
    }
}

const GL_X: [f64; 5] = [
    -0.906_179_845_938_664,
    -0.538_469_310_105_683,
    0.0,
    0.538_469_310_105_683,
    0.906_179_845_938_664,
];
const GL_W: [f64; 5] = [
    0.236_926_885_056_189,
    0.478_628_670_499_366,
    0.568_888_888_888_889,
    0.478_628_670_499_366,
    0.236_926_885_056_189,
];

fn gauss_legendre(f: &dyn Fn(f64, f64) -> f64, r: Rect) -> f64 {
    let (hs, hb) = (0.5 * (r.hi[0] - r.lo[0]), 0.5 * (r.hi[1] - r.lo[1]));
    let (cs, cb) = (0.5 * (r.hi[0] + r.lo[0]), 0.5 * (r.hi[1] + r.lo[1]));
    let mut sum = 0.0;
    for i in 0..5 {
        for j in 0..5 {
            sum += GL_W[i] * GL_W[j] * f(cs + hs * GL_X[i], cb + hb * GL_X[j]);
        }
    }
    sum * hs * hb
}

fn quarters(r: Rect) -> [Rect; 4] {
    let m = [0.5 * (r.lo[0] + r.hi[0]), 0.5 * (r.lo[1] + r.hi[1])];
    [
        Rect { lo: r.lo, hi: m },
        Rect {
            lo: [m[0], r.lo[1]],
            hi: [r.hi[0], m[1]],
        },
        Rect {
            lo: [r.lo[0], m[1]],
            hi: [m[0], r.hi[1]],
        },
        Rect { lo: m, hi: r.hi },
    ]
}

fn adaptive(f: &dyn Fn(f64, f64) -> f64, r: Rect, whole: f64, depth: u32) -> f64 {
    let parts = quarters(r);
    let fine: f64 = parts.iter().map(|&p| gauss_legendre(f, p)).sum();
    let area = (r.hi[0] - r.lo[0]) * (r.hi[1] - r.lo[1]);
    // 5e-3 of a cell's integral: far below the counts' own error (a cell
    // expecting e samples has sd sqrt(e), 1/sqrt(e) >= 3% below e = 1000).
    // On a grating's RGB ridges it takes 2.5x fewer pdf evaluations than
    // 2e-3 (which took 3-4x fewer than 3e-4), and the compact disc's chi2
    // statistics stayed the same to 0.1 (2026-12-03).
    if depth == 0 || (whole - fine).abs() <= 1e-5 * area + 5e-3 * fine.abs() {
        return fine;
    }
    parts
        .iter()
        .map(|&p| adaptive(f, p, gauss_legendre(f, p), depth - 1))
        .sum()
}

/// Integral over a cell, pre-split into pieces no larger than 1/32.
fn integrate_cell(f: &dyn Fn(f64, f64) -> f64, cell: Rect) -> f64 {
    let ns = ((cell.hi[0] - cell.lo[0]) * 32.0).ceil().max(1.0) as usize;
    let nb = ((cell.hi[1] - cell.lo[1]) * 32.0).ceil().max(1.0) as usize;
    let mut sum = 0.0;
    for i in 0..ns {
        for j in 0..nb {
            let lerp = |d: usize, t: f64| cell.lo[d] + (cell.hi[d] - cell.lo[d]) * t;
            let piece = Rect {
                lo: [lerp(0, i as f64 / ns as f64), lerp(1, j as f64 / nb as f64)],
                hi: [
                    lerp(0, (i + 1) as f64 / ns as f64),
                    lerp(1, (j + 1) as f64 / nb as f64),
                ],
            };
            sum += adaptive(f, piece, gauss_legendre(f, piece), 10);
        }
    }
    sum
}

/// Upper tail of the standard normal.
fn normal_upper_tail(z: f64) -> f64 {
    normal_cdf(-z)
}

/// P(chi2_dof > x) by the Wilson-Hilferty cube-root approximation.
fn chi2_p_value(x: f64, dof: f64) -> f64 {
    let a = 2.0 / (9.0 * dof);
    let z = ((x / dof).cbrt() - (1.0 - a)) / a.sqrt();
    normal_upper_tail(z)
}

pub struct Fit {
    pub p_value: f64,
    pub chi2: f64,
    pub dof: usize,
    pub integral: f64,
    pub coherent: f64,
}

/// What the chi-square test needs of a sampler: the core's strategies, or
/// a material's exported sampling programs (testing::programs).
pub trait Sampler {
    fn sample(&self, rnd: [f64; 3]) -> SampleResult;
    fn pdf(&self, wo: DVec3) -> f64;
    fn coherent_probability(&self) -> f64;
    /// Whether `sample` gives, by construction, `pdf` at its direction (a
    /// sampler that computes it so): the check that the two agree is then
    /// skipped, not run on the same numbers twice.
    fn sample_pdf_is_pdf(&self) -> bool {
        false
    }
}

impl Sampler for Strategy<'_> {
    fn sample(&self, rnd: [f64; 3]) -> SampleResult {
        Strategy::sample(self, rnd)
    }
    fn pdf(&self, wo: DVec3) -> f64 {
        Strategy::pdf(self, wo)
    }
    fn coherent_probability(&self) -> f64 {
        Strategy::coherent_probability(self)
    }
}

/// Goodness of fit of `sampler.sample` against `sampler.pdf`; also checks
/// every sample (unit wo above the horizon, finite pdf equal to pdf(wo)
/// unless the sampler computes it so).
pub fn chi2_fit(sampler: &dyn Sampler, seed: u64, n: usize) -> Fit {
    chi2_fit_against(sampler, sampler, seed, n)
}

/// Samples from `sampler`, expected counts from `reference`'s pdf.
pub fn chi2_fit_against(
    sampler: &dyn Sampler,
    reference: &dyn Sampler,
    seed: u64,
    n: usize,
) -> Fit {
    let start = std::time::Instant::now();
    let mut rng = Rng(seed);
    let check = |s: &SampleResult| {
        assert!(s.pdf.is_finite() && s.pdf >= 0.0, "pdf {}", s.pdf);
        if s.pdf > 0.0 {
            assert!(
                (s.wo.length() - 1.0).abs() < 1e-12,
                "|wo| = {}",
                s.wo.length()
            );
            assert!(s.wo.z > 0.0);
            if !s.coherent && !sampler.sample_pdf_is_pdf() {
                let p = sampler.pdf(s.wo);
                assert!((p - s.pdf).abs() <= 1e-12 * p, "{p} vs {}", s.pdf);
            }
        }
    };
    let mut pilot = Vec::new();
    for _ in 0..n / 5 {
        let s = sampler.sample(rng.three());
        check(&s);
        if s.pdf > 0.0 && !s.coherent {
            let (a, b) = to_sb(s.wo);
            pilot.push([a, b]);
        }
    }
    let mut cells = Vec::new();
    let whole = Rect {
        lo: [0.0, 0.0],
        hi: [1.0, 1.0],
    };
    let leaf = (pilot.len() / 128).max(20);
    let tree = build(&mut pilot, whole, leaf, &mut cells);
    let mut observed = vec![0.0; cells.len() + 2];
    let (coh_cell, fail_cell) = (cells.len(), cells.len() + 1);
    for _ in 0..n {
        let s = sampler.sample(rng.three());
        check(&s);
        if s.pdf == 0.0 {
            observed[fail_cell] += 1.0;
        } else if s.coherent {
            observed[coh_cell] += 1.0;
        } else {
            let (a, b) = to_sb(s.wo);
            observed[find(&tree, [a, b])] += 1.0;
        }
    }
    let t_sample = start.elapsed();
    let evals = std::cell::Cell::new(0usize);
    let density = |s: f64, b: f64| {
        evals.set(evals.get() + 1);
        jacobian_sb(s) * reference.pdf(from_sb(s, b))
    };
    let mut expected: Vec<f64> = cells.iter().map(|&c| integrate_cell(&density, c)).collect();
    let integral: f64 = expected.iter().sum();
    println!(
        "  sampling {:.2?}, cubature {:.2?} ({} pdf evaluations)",
        t_sample,
        start.elapsed() - t_sample,
        evals.get()
    );
    let coherent = reference.coherent_probability();
    expected.push(coherent);
    expected.push((1.0 - coherent - integral).max(0.0));
    // Pool cells expecting fewer than 5 samples.
    let (mut chi2, mut cells_used) = (0.0, 0usize);
    let (mut pool_o, mut pool_e) = (0.0, 0.0);
    for (o, e) in observed.iter().zip(&expected) {
        let e = e * n as f64;
        if e < 5.0 {
            pool_o += o;
            pool_e += e;
        } else {
            chi2 += (o - e) * (o - e) / e;
            cells_used += 1;
        }
    }
    if pool_e > 0.0 || pool_o > 0.0 {
        // Observed samples where nothing is expected fail the test.
        chi2 += (pool_o - pool_e) * (pool_o - pool_e) / pool_e.max(1e-3);
        cells_used += 1;
    }
    let dof = cells_used.saturating_sub(1).max(1);
    Fit {
        p_value: chi2_p_value(chi2, dof as f64),
        chi2,
        dof,
        integral,
        coherent,
    }
}

//! A rigorous grating's pair efficiencies resampled per order on a grid a
//! program can read with eight gathers (the renderer's JIT variants; the
//! table's own lookup is a search over anomalies that a program would have
//! to unroll per order).
//!
//! Order n's lobe carries `RigorousOrders::pair_efficiency(n, lambda, c,
//! ky)`, with (c, ky) the exact pair's half difference of tangential
//! directions. Its structure is the Rayleigh anomalies: the two table reads
//! at kx = u_n / 2 +- c cross one where |c - (j + n / 2) delta| = s, with
//! delta = lambda / Lam, s = sqrt(1 - ky^2) and j any integer. In the
//! lattice coordinates
//!
//! ```text
//! A = (|c| + s) / delta,   B = (s - |c|) / delta,
//! ```
//!
//! every anomaly of every wavelength lies on a line A or B in Z + n / 2,
//! the order's own grazing edge (|c| + |u_n| / 2 = s) among them. The grid
//! holds LATTICE_NODES nodes per unit of A and B, denser towards each
//! unit's ends (cosine spacing: an efficiency bends sharply next to an
//! anomaly), at GRID_LAMBDAS wavelengths, and reads trilinearly: a read
//! never interpolates across an anomaly in (A, B), and at fixed (A, B) the
//! anomalies stay put as the wavelength moves.
//!
//! Measured on the compact disc against the table's lookup at 20,000
//! random exact pairs (`print_pair_grid_accuracy`): max 0.21, rms 0.0067,
//! p99 0.024 with 21 wavelengths and 12 nodes per unit (17 MB, 0.9 s to
//! build); a uniform grid over the lens (|c|, ky) of the same size gave
//! rms 0.0070, p99 0.027 (41 x 96 x 64), and the lattice uniform within
//! its units rms 0.0095, p99 0.038 (8 per unit, 41 wavelengths). The
//! values are even in c and ky, and a symmetric grating's order -n equals
//! its n: such a grid holds n >= 0 alone. The read is written once
//! (`PairGrid::read`, generic over `Real`): natively for its tests, as a
//! program in the JIT variants.

use super::rigorous::RigorousOrders;
use crate::program::Real;
use crate::spectrum::{LAMBDA_MAX_NM, LAMBDA_MIN_NM};

/// Wavelength nodes over the band.
pub(crate) const GRID_LAMBDAS: usize = 21;
/// Nodes per unit of the lattice coordinates, and the fewest a grid may
/// take to stay within GRID_MAX_VALUES.
const LATTICE_NODES: usize = 12;
const MIN_LATTICE_NODES: usize = 6;
/// The most values a grid may hold: a program indexes it in f32, exact
/// to 2^24. Its size grows as the period cubed (the compact disc's 2.5 um:
/// 4.3 million at 12 per unit); periods above about 4 um have no
/// programs.
const GRID_MAX_VALUES: usize = 6 << 20;

/// Order n's pair efficiency on the grid, for every order that propagates
/// somewhere in the band.
#[derive(Debug)]
pub(crate) struct PairGrid {
    /// 1 / (1000 Lam): u_n = n lambda / (1000 Lam) with lambda in nm.
    pub(crate) inv_period_nm: f64,
    /// Largest |n| held.
    pub(crate) n_max: i64,
    /// Orders -n and n share a slot.
    pub(crate) symmetric: bool,
    /// Nodes per unit of A and B.
    pub(crate) per_unit: usize,
    /// Nodes along A = (|c| + s) / delta and B = (s - |c|) / delta.
    pub(crate) nodes_a: usize,
    pub(crate) nodes_b: usize,
    /// [slot][lambda][p][q]; slot |n| (symmetric) or n + n_max.
    pub(crate) values: Vec<f32>,
}

impl PairGrid {
    /// The grid of `orders`' pair efficiencies (a few seconds on two cores
    /// for the compact disc: two table reads per node).
    pub(crate) fn build(orders: &RigorousOrders, period_um: f64) -> Option<PairGrid> {
        let inv_period_nm = 1.0 / (1000.0 * period_um);
        // |u_n| < 2 at the band's shortest wavelength.
        let n_max = (2.0 / (LAMBDA_MIN_NM * inv_period_nm)).floor().max(0.0) as i64;
        let symmetric = orders.table().symmetric();
        let slots = if symmetric { n_max + 1 } else { 2 * n_max + 1 } as usize;
        // (c + s) / delta <= 2 / delta and (s - c) / delta <= 1 / delta.
        // LATTICE_NODES per unit, or fewer (not below MIN_LATTICE_NODES)
        // where the grid would exceed GRID_MAX_VALUES.
        let inv_delta_max = 1.0 / (LAMBDA_MIN_NM * inv_period_nm);
        let sizes = |per_unit: usize| {
            let nodes_a = (2.0 * inv_delta_max * per_unit as f64).ceil() as usize + 2;
            let nodes_b = (inv_delta_max * per_unit as f64).ceil() as usize + 2;
            (per_unit, nodes_a, nodes_b, GRID_LAMBDAS * nodes_a * nodes_b)
        };
        let (per_unit, nodes_a, nodes_b, per_slot) = (MIN_LATTICE_NODES..=LATTICE_NODES)
            .rev()
            .map(sizes)
            .find(|s| slots * s.3 <= GRID_MAX_VALUES)?;
        let mut values = vec![0.0f32; slots * per_slot];
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        let per_thread = slots.div_ceil(threads).max(1);
        std::thread::scope(|scope| {
            for (chunk, block) in values.chunks_mut(per_thread * per_slot).enumerate() {
                scope.spawn(move || {
                    for (k, slot_values) in block.chunks_mut(per_slot).enumerate() {
                        let slot = (chunk * per_thread + k) as i64;
                        let n = if symmetric { slot } else { slot - n_max };
                        fill_order(
                            orders,
                            n,
                            inv_period_nm,
                            (per_unit, nodes_a, nodes_b),
                            slot_values,
                        );
                    }
                });
            }
        });
        Some(PairGrid {
            inv_period_nm,
            n_max,
            symmetric,
            per_unit,
            nodes_a,
            nodes_b,
            values,
        })
    }

    pub(crate) fn memory_bytes(&self) -> usize {
        self.values.len() * 4
    }

    /// The slot of order n (clamped into the grid; `holds` says whether
    /// it is there).
    pub(crate) fn slot<R: Real>(&self, n: R) -> R {
        if self.symmetric {
            n.abs().min(self.n_max as f64)
        } else {
            (n + self.n_max as f64).clamp(0.0, (2 * self.n_max) as f64)
        }
    }

    /// Order n's pair efficiency at (lambda, c, ky), trilinear on the grid
    /// from `fetch` (a value of `values` by index); 0 for orders the grid
    /// does not hold and where the order does not exist (|u_n| >= 2).
    pub(crate) fn read<R: Real>(
        &self,
        n: R,
        lambda_nm: R,
        c: R,
        ky: R,
        fetch: impl Fn(R) -> R,
    ) -> R {
        self.read_at(&self.place(lambda_nm, c, ky), n, fetch)
    }

    /// Where (lambda, c, ky) lies on the grid: the same for every order.
    pub(crate) fn place<R: Real>(&self, lambda_nm: R, c: R, ky: R) -> GridPlace<R> {
        let last_l = (GRID_LAMBDAS - 1) as f64;
        let x = ((lambda_nm - LAMBDA_MIN_NM) * (last_l / (LAMBDA_MAX_NM - LAMBDA_MIN_NM)))
            .clamp(0.0, last_l);
        let il = x.floor().min(last_l - 1.0);
        let fl = x - il;
        // The lattice coordinates A = (|c| + s) / delta and B = (s - |c|) /
        // delta.
        let inv_delta = lambda_nm.constant(1.0) / (lambda_nm * self.inv_period_nm);
        let s = (ky * ky * -1.0 + 1.0).max(0.0).sqrt();
        let c = c.abs();
        let big_a = (c + s) * inv_delta;
        let big_b = (s - c) * inv_delta;
        // The node index of t: per_unit per unit, acos-spaced within it.
        let cell = |t: R, nodes: usize| {
            let last = (nodes - 1) as f64;
            let unit = t.floor();
            let x = (t - unit) * -2.0 + 1.0;
            let within = (x * x * -1.0 + 1.0).max(0.0).sqrt().atan2(x)
                * (self.per_unit as f64 / std::f64::consts::PI);
            let t = (unit * self.per_unit as f64 + within).clamp(0.0, last);
            let i = t.floor().min(last - 1.0);
            (i, t - i)
        };
        GridPlace {
            lambda_nm,
            il,
            fl,
            a: cell(big_a, self.nodes_a),
            b: cell(big_b, self.nodes_b),
        }
    }

    /// Order n's pair efficiency at `place` (see `read`).
    pub(crate) fn read_at<R: Real>(&self, place: &GridPlace<R>, n: R, fetch: impl Fn(R) -> R) -> R {
        let (na, nb) = (self.nodes_a, self.nodes_b);
        let ((ia, fa), (ib, fb)) = (place.a, place.b);
        let stride_l = (na * nb) as f64;
        let base =
            ((self.slot(n) * GRID_LAMBDAS as f64 + place.il) * na as f64 + ia) * nb as f64 + ib;
        let plane = |at: R| {
            let (v00, v01) = (fetch(at), fetch(at + 1.0));
            let (v10, v11) = (fetch(at + nb as f64), fetch(at + (nb + 1) as f64));
            let lo = v00 + (v01 - v00) * fb;
            let hi = v10 + (v11 - v10) * fb;
            lo + (hi - lo) * fa
        };
        let (e0, e1) = (plane(base), plane(base + stride_l));
        let e = e0 + (e1 - e0) * place.fl;
        let held = n.abs().le(self.n_max as f64);
        let a = n.abs() * place.lambda_nm * (0.5 * self.inv_period_nm);
        let exists = a.lt(1.0);
        let zero = e.constant(0.0);
        R::select(exists, R::select(held, e.max(0.0), zero), zero)
    }
}

/// A query's place on a `PairGrid` (`PairGrid::place`): its wavelength,
/// the wavelength cell and fraction, and the (node, fraction) along A and B.
pub(crate) struct GridPlace<R> {
    lambda_nm: R,
    il: R,
    fl: R,
    a: (R, R),
    b: (R, R),
}

/// Order n's values at the grid's nodes (zero at wavelengths where it
/// does not exist).
fn fill_order(
    orders: &RigorousOrders,
    n: i64,
    inv_period_nm: f64,
    (per_unit, na, nb): (usize, usize, usize),
    out: &mut [f32],
) {
    for il in 0..GRID_LAMBDAS {
        let lambda =
            LAMBDA_MIN_NM + (LAMBDA_MAX_NM - LAMBDA_MIN_NM) * il as f64 / (GRID_LAMBDAS - 1) as f64;
        let delta = lambda * inv_period_nm;
        let a = (n as f64 * delta).abs() * 0.5;
        if a >= 1.0 {
            continue;
        }
        for ia in 0..na {
            let big_a = lattice_node(ia, per_unit);
            for ib in 0..nb {
                let big_b = lattice_node(ib, per_unit);
                let s = (0.5 * delta * (big_a + big_b)).min(1.0);
                let c = (0.5 * delta * (big_a - big_b)).abs();
                let ky = (1.0 - s * s).max(0.0).sqrt();
                let e = orders.pair_efficiency(n, lambda, c, ky);
                out[(il * na + ia) * nb + ib] = if e.is_finite() { e as f32 } else { 0.0 };
            }
        }
    }
}

/// Node i of a lattice axis: `per_unit` per unit, denser towards the
/// unit's ends (the anomalies), at (1 - cos(pi j / K)) / 2 within it.
fn lattice_node(i: usize, per_unit: usize) -> f64 {
    let (unit, j) = (i / per_unit, i % per_unit);
    let t = j as f64 / per_unit as f64;
    unit as f64 + 0.5 * (1.0 - (std::f64::consts::PI * t).cos())
}

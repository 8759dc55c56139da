//! Table lookups written as program operations: the interpolation rules
//! the core's native tables use, so that a model's program reads its
//! exported tables exactly as its native code does; and the low-rank form
//! of a table (`low_rank`), which a program reads with fewer gathers.

use super::{Builder, Table, Value};

/// Uniform cubic B-spline weights of t in [0, 1] for the nodes i-1 .. i+2.
pub fn bspline_weights(t: Value) -> [Value; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    let u = 1.0 - t;
    [
        u * u * u * (1.0 / 6.0),
        t3 * 0.5 - t2 + 2.0 / 3.0,
        t3 * -0.5 + (t2 + t) * 0.5 + 1.0 / 6.0,
        t3 * (1.0 / 6.0),
    ]
}

/// Catmull-Rom weights of t in [0, 1] for the nodes i-1 .. i+2.
pub fn catmull_rom_weights(t: Value) -> [Value; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    [
        (t2 - t3 * 0.5 - t * 0.5),
        t3 * 1.5 - t2 * 2.5 + 1.0,
        t3 * -1.5 + t2 * 2.0 + t * 0.5,
        (t3 - t2) * 0.5,
    ]
}

/// Sum of values.
pub fn sum<'a>(b: &'a Builder, values: impl IntoIterator<Item = Value<'a>>) -> Value<'a> {
    values
        .into_iter()
        .reduce(|a, v| a + v)
        .unwrap_or_else(|| b.c(0.0))
}

/// Linear interpolation at x in tables of n entries each, entry j at
/// x0 + j dx (`tables`: a table and the offset its entries start at), x
/// clamped to their range: the position is worked out once for them all.
pub fn uniform_linear<'a, const K: usize>(
    b: &'a Builder,
    tables: [(Table, usize); K],
    n: usize,
    x0: f64,
    dx: f64,
    x: Value<'a>,
) -> [Value<'a>; K] {
    if n == 1 {
        return tables.map(|(table, offset)| b.gather(table, b.c(offset as f64)));
    }
    let f = ((x - x0) * (1.0 / dx)).clamp(0.0, (n - 1) as f64);
    let i = f.floor().min((n - 2) as f64);
    let t = f - i;
    tables.map(|(table, offset)| {
        let at = i + offset as f64;
        let lo = b.gather(table, at);
        let hi = b.gather(table, at + 1.0);
        lo + (hi - lo) * t
    })
}

/// `values[i]` for an integer-valued `i` in [0, values.len()) by a chain of
/// compares and selects: for tables of a few constants this is cheaper on a
/// SIMD CPU than a gather (which loads lane by lane); out-of-range indices
/// give the nearest end's value.
pub fn select_chain<'a>(b: &'a Builder, values: &[f64], i: Value<'a>) -> Value<'a> {
    let mut out = b.c(values[0]);
    for (k, &v) in values.iter().enumerate().skip(1) {
        out = i.ge(k as f64 - 0.5).select(v, out);
    }
    out
}

/// Levels of a value in [0, 1] in a packed pair (`pack_pair`): 12 bits,
/// steps of 1 / 4095 (2.4e-4).
pub const PAIR_LEVELS: f64 = 4095.0;
/// A packed pair's second value per level, in its fraction.
const PAIR_FRACTION: f64 = 4096.0;

/// Two values in [0, 1] as one table entry, each on the grid of
/// 1 / PAIR_LEVELS (rounded; clamped into [0, 1]): the first's level in
/// the integer part, the second's in the fraction, 12 bits each, so that
/// the pair is exact in an f32's 24-bit significand. A program reads both
/// with one gather (`unpack_pair_levels`): a gather costs several arithmetic
/// operations, more on CPUs whose vector gathers are slow.
pub fn pack_pair(first: f64, second: f64) -> f32 {
    let level = |x: f64| (x.clamp(0.0, 1.0) * PAIR_LEVELS).round();
    (level(first) + level(second) / PAIR_FRACTION) as f32
}

/// The two levels of a packed entry (`pack_pair`), each times PAIR_LEVELS:
/// exact, as the program runs in f32.
pub fn unpack_pair_levels<'a>(entry: Value<'a>) -> (Value<'a>, Value<'a>) {
    let first = entry.floor();
    (first, (entry - first) * PAIR_FRACTION)
}

/// The rank-P form of a `rows` x `cols` matrix (row-major): phi (rows x P,
/// row-major) and A (P rows of cols) with |M - phi A| <= `tolerance` max
/// |M| everywhere, P the smallest such (from the eigenvectors of M^T M by
/// cyclic Jacobi); None when no P <= cols / 2 reaches it.
pub fn low_rank(
    flat: &[f64],
    rows: usize,
    cols: usize,
    tolerance: f64,
) -> Option<(Vec<f64>, Vec<Vec<f64>>)> {
    if flat.len() != rows * cols || cols == 0 {
        return None;
    }
    let at = |r: usize, c: usize| flat[r * cols + c];
    let largest = flat.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    // Gram matrix and its eigenvectors.
    let mut g = vec![vec![0.0; cols]; cols];
    for row in flat.chunks_exact(cols) {
        for (gi, &ri) in g.iter_mut().zip(row) {
            for (gij, &rj) in gi.iter_mut().zip(row) {
                *gij += ri * rj;
            }
        }
    }
    let mut v: Vec<Vec<f64>> = (0..cols)
        .map(|i| (0..cols).map(|j| if i == j { 1.0 } else { 0.0 }).collect())
        .collect();
    for _ in 0..60 {
        let mut off = 0.0;
        for p in 0..cols {
            for q in p + 1..cols {
                off += g[p][q] * g[p][q];
                if g[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = (g[q][q] - g[p][p]) / (2.0 * g[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let (c, s) = (1.0 / (t * t + 1.0).sqrt(), t / (t * t + 1.0).sqrt());
                for gk in g.iter_mut() {
                    let (gkp, gkq) = (gk[p], gk[q]);
                    gk[p] = c * gkp - s * gkq;
                    gk[q] = s * gkp + c * gkq;
                }
                let (head, tail) = g.split_at_mut(q);
                for (gpk, gqk) in head[p].iter_mut().zip(tail[0].iter_mut()) {
                    let (x, y) = (*gpk, *gqk);
                    *gpk = c * x - s * y;
                    *gqk = s * x + c * y;
                }
                for row in v.iter_mut() {
                    let (vp, vq) = (row[p], row[q]);
                    row[p] = c * vp - s * vq;
                    row[q] = s * vp + c * vq;
                }
            }
        }
        if off < 1e-30 * largest.powi(4) {
            break;
        }
    }
    let mut order: Vec<usize> = (0..cols).collect();
    order.sort_by(|&x, &y| g[y][y].total_cmp(&g[x][x]));
    for rank in 1..=cols / 2 {
        let basis: Vec<Vec<f64>> = order[..rank]
            .iter()
            .map(|&e| (0..cols).map(|i| v[i][e]).collect())
            .collect();
        let phi: Vec<f64> = (0..rows)
            .flat_map(|r| {
                basis
                    .iter()
                    .map(|u| (0..cols).map(|i| at(r, i) * u[i]).sum::<f64>())
                    .collect::<Vec<_>>()
            })
            .collect();
        let worst = (0..rows)
            .flat_map(|r| (0..cols).map(move |c| (r, c)))
            .map(|(r, c)| {
                let approx: f64 = (0..rank).map(|p| phi[r * rank + p] * basis[p][c]).sum();
                (approx - at(r, c)).abs()
            })
            .fold(0.0, f64::max);
        if worst <= tolerance * largest {
            return Some((phi, basis));
        }
    }
    None
}

#[cfg(test)]
mod low_rank_tests {
    use super::low_rank;

    /// A matrix of rank 3 (rows mixing three smooth column profiles) plus
    /// a perturbation of 1e-7: rank 3 at tolerance 1e-5, with the error
    /// bound held; an identity (full rank) has no form of at most half its
    /// columns.
    #[test]
    fn low_rank_finds_the_smallest_rank_within_tolerance() {
        let (rows, cols) = (40, 16);
        let m: Vec<f64> = (0..rows)
            .flat_map(|r| {
                let x = r as f64 / rows as f64;
                (0..cols).map(move |c| {
                    let y = c as f64 / cols as f64;
                    1.0 + x * y.sin()
                        + (x * x) * (3.0 * y).cos()
                        + 1e-7 * ((r * 7 + c * 3) % 5) as f64
                })
            })
            .collect();
        let (phi, basis) = low_rank(&m, rows, cols, 1e-5).expect("rank 3");
        assert_eq!(basis.len(), 3);
        let largest = m.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        for r in 0..rows {
            for c in 0..cols {
                let approx: f64 = (0..3).map(|p| phi[r * 3 + p] * basis[p][c]).sum();
                assert!((approx - m[r * cols + c]).abs() <= 1e-5 * largest);
            }
        }
        let identity: Vec<f64> = (0..cols * cols)
            .map(|i| if i % (cols + 1) == 0 { 1.0 } else { 0.0 })
            .collect();
        assert!(low_rank(&identity, cols, cols, 1e-5).is_none());
    }
}

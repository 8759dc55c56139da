//! Table lookups written as program operations: the interpolation rules
//! the core's native tables use, so that a model's program reads its
//! exported tables exactly as its native code does.

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

/// Linear interpolation in `table[offset .. offset + n]`, whose entry j is
/// at x0 + j dx; x clamped to the table's range.
pub fn uniform_linear<'a>(
    b: &'a Builder,
    table: Table,
    offset: usize,
    n: usize,
    x0: f64,
    dx: f64,
    x: Value<'a>,
) -> Value<'a> {
    if n == 1 {
        return b.gather(table, b.c(offset as f64));
    }
    let f = ((x - x0) * (1.0 / dx)).clamp(0.0, (n - 1) as f64);
    let i = f.floor().min((n - 2) as f64);
    let t = f - i;
    let at = i + offset as f64;
    let lo = b.gather(table, at);
    let hi = b.gather(table, at + 1.0);
    lo + (hi - lo) * t
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

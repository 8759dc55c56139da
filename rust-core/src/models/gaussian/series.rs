//! The series S(g, x) of Gaussian surfaces and its five evaluations (see the
//! module documentation of `models::gaussian`).

use crate::special::{fast_exp, fast_exp_vectorisable, ln_factorial, ln_gamma};
pub const DEFAULT_SERIES_TOLERANCE: f64 = 1e-5;
/// Default smallest g served by the asymptotic rule; below it the exact sum
/// needs at most ~2 * 4.5 * sqrt(g) terms.
pub const DEFAULT_ASYMPTOTIC_MIN_G: f64 = 30.0;

/// Accuracy knobs of the series; the defaults keep the series error below
/// 1e-4 relative (measured in the tests).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeriesSettings {
    pub tolerance: f64,
    pub asymptotic_min_g: f64,
    /// Serve S(g, x) from the universal table where it covers (g, x); only
    /// when `tolerance` is no tighter than the table's own accuracy.
    pub use_table: bool,
}

impl Default for SeriesSettings {
    fn default() -> Self {
        SeriesSettings::with_tolerance(DEFAULT_SERIES_TOLERANCE)
    }
}

impl SeriesSettings {
    pub fn with_tolerance(tolerance: f64) -> SeriesSettings {
        SeriesSettings {
            tolerance,
            asymptotic_min_g: DEFAULT_ASYMPTOTIC_MIN_G,
            use_table: tolerance >= TABLE_MIN_TOLERANCE,
        }
    }
}

/// Tightest series tolerance served by the table (its bicubic interpolation
/// error is below 4e-5 relative, measured in the tests); a tighter setting
/// sums the series exactly.
pub const TABLE_MIN_TOLERANCE: f64 = 1e-5;

/// S(g, x) = sum_{m >= 1} Poisson(m; g) exp(-x/m) / m, dispatching to the
/// cheapest evaluation that meets the settings' accuracy.
#[inline]
pub fn poisson_series(g: f64, x: f64, settings: &SeriesSettings) -> f64 {
    if !(g > 0.0) || !(x >= 0.0) || !g.is_finite() || !x.is_finite() {
        return 0.0;
    }
    if settings.use_table {
        if let Some(s) = series_table().lookup(g, x) {
            return s;
        }
    }
    if g >= settings.asymptotic_min_g {
        if let Some(s) = poisson_series_asymptotic(g, x) {
            return s;
        }
    }
    if settings.use_table {
        // Far tails beyond the table (g <= 40): the terms around the mode,
        // summed in one pass, are exact there and cheaper than the sums
        // below (the saddle rule needs wider bells than these).
        if x >= ALONG_X_TABLE_RHO * ALONG_X_TABLE_RHO * (1.0 + g) {
            if let Some(l) = ln_poisson_series_window(g, g.ln(), x, &mut 0) {
                return fast_exp(l);
            }
        }
        // The saddle rule's accuracy (~1e-5) is the table's.
        if let Some(s) = poisson_series_saddle(g, x) {
            return s;
        }
    }
    poisson_series_exact(g, x, settings.tolerance)
}

/// ln S tabulated over (ln g, rho), rho = sqrt(x / (1 + g)): one universal
/// function of two variables, so one table serves every Gaussian material.
/// For smooth surfaces (g << 1) rho ~ sqrt(x): the far tail ln S ~
/// -2 sqrt(x ln(m/g)) is nearly linear in it and near x = 0 ln S is even in
/// it. For rough ones rho^2 ~ x/g, the Beckmann exponent tan^2/alpha^2, in
/// which ln S ~ -ln g - rho^2 is a gentle quadratic. Both interpolate well
/// with cubic splines: the table holds the coefficients of the interpolating
/// bicubic B-spline (same 4x4 stencil as a Catmull-Rom bicubic, but fourth-
/// instead of third-order accurate: ~1e-6 relative instead of ~1e-5 on this
/// grid). Rows above g = 40 are filled by the saddle-point rule (the exact
/// sum would take O(sqrt g) terms per node).
pub(super) struct SeriesTable {
    ln_g_min: f64,
    inv_d_ln_g: f64,
    n_g: usize,
    inv_d_root_x: f64,
    n_root_x: usize,
    /// f32 halves the footprint (1.1 MB), and so the cache misses of lookups;
    /// its rounding (6e-8 of |ln S|) stays below the interpolation error
    /// wherever S matters.
    ln_s: Vec<f32>,
}

const TABLE_G_MIN: f64 = 1e-4;
const TABLE_G_MAX: f64 = 1e4;
const TABLE_D_LN_G: f64 = 0.08;
const TABLE_ROOT_X_MAX: f64 = 60.0;
const TABLE_D_ROOT_X: f64 = 0.05;

/// Extra samples beyond the open ends of a spline line: the end condition's
/// error decays by 2 - sqrt(3) = 0.27 per node into the line, so 8 nodes
/// leave 3e-5 of an already small end error.
pub(crate) const SPLINE_MARGIN: usize = 8;

/// Replaces samples f_i of a uniform line by the coefficients c_i of the
/// interpolating cubic B-spline, (c_{i-1} + 4 c_i + c_{i+1}) / 6 = f_i, with
/// c = f at both ends (the ends are margins the caller discards). The line
/// has `len` points of `lanes` independent values each (point-major), all
/// solved at once so that the sweeps vectorise over the lanes.
pub(crate) fn spline_prefilter(data: &mut [f64], len: usize, lanes: usize) {
    debug_assert_eq!(data.len(), len * lanes);
    if len < 3 {
        return;
    }
    // Thomas algorithm; the first and last equations are c = f. Its
    // factors depend on the position only.
    const A: f64 = 1.0 / 6.0;
    const B: f64 = 4.0 / 6.0;
    let mut upper = vec![0.0; len];
    let mut inv_pivot = vec![0.0; len];
    for i in 1..len - 1 {
        inv_pivot[i] = 1.0 / (B - A * upper[i - 1]);
        upper[i] = A * inv_pivot[i];
    }
    for i in 1..len - 1 {
        let (done, rest) = data.split_at_mut(i * lanes);
        let prev = &done[(i - 1) * lanes..];
        let m = inv_pivot[i];
        for (f, &p) in rest[..lanes].iter_mut().zip(prev) {
            *f = (*f - A * p) * m;
        }
    }
    for i in (1..len - 1).rev() {
        let (head, next) = data.split_at_mut((i + 1) * lanes);
        let u = upper[i];
        for (f, &n) in head[i * lanes..].iter_mut().zip(&next[..lanes]) {
            *f -= u * n;
        }
    }
}

/// Cubic B-spline weights of the coefficients i-1, i, i+1, i+2 at i + t.
#[inline(always)]
pub(crate) fn bspline_weights(t: f64) -> [f64; 4] {
    let s = 1.0 - t;
    let t2 = t * t;
    let t3 = t2 * t;
    [
        s * s * s * (1.0 / 6.0),
        0.5 * t3 - t2 + 2.0 / 3.0,
        (-0.5 * t3 + 0.5 * (t2 + t)) + 1.0 / 6.0,
        t3 * (1.0 / 6.0),
    ]
}

/// ln S at (g, x) as `ln_poisson_series_along_x` evaluates it (for one x).
pub(crate) fn ln_poisson_series(g: f64, x: f64, settings: &SeriesSettings) -> f64 {
    let mut out = [0.0];
    ln_poisson_series_along_x(g, &[x.sqrt()], settings, f64::NEG_INFINITY, &mut out);
    out[0]
}

/// rho beyond which `ln_poisson_series_along_x` stops reading the
/// universal table (whose last columns end at 60).
const ALONG_X_TABLE_RHO: f64 = TABLE_ROOT_X_MAX - 0.5;

/// ln S(g, x) at one g for increasing x, given as sqrt(x) in `root_x`: the
/// samples from which tables over the pair variables are built. Where the
/// universal table covers (g, x) it serves (one row position for all x);
/// beyond its rho range, for g <= 40 (far tails of smooth surfaces, ln S <
/// -270), the terms around the mode are summed in one vectorised pass
/// (`ln_poisson_series_window`); elsewhere (g outside the table, `use_table`
/// off) `poisson_series` evaluates each point. S falls with x: once ln S is
/// below `floor` the remaining outputs are set to -inf without evaluation.
pub(crate) fn ln_poisson_series_along_x(
    g: f64,
    root_x: &[f64],
    settings: &SeriesSettings,
    floor: f64,
    out: &mut [f64],
) {
    let table = series_table();
    let mut values = root_x.iter().zip(out.iter_mut());
    if settings.use_table && (TABLE_G_MIN..TABLE_G_MAX).contains(&g) {
        let ln_g = g.ln();
        let fg = (ln_g - table.ln_g_min) * table.inv_d_ln_g + 1.0;
        let ig = (fg as usize).clamp(1, table.n_g - 3);
        let wg = bspline_weights(fg - ig as f64);
        let inv_root = 1.0 / (1.0 + g).sqrt();
        let mut mode = 0;
        for (&r, o) in values.by_ref() {
            let rho = r * inv_root;
            *o = if rho < ALONG_X_TABLE_RHO {
                let fx = rho * table.inv_d_root_x + 1.0;
                let ix = (fx as usize).clamp(1, table.n_root_x - 3);
                let wx = bspline_weights(fx - ix as f64);
                let mut acc = 0.0;
                for (a, wa) in wg.iter().enumerate() {
                    let row = &table.ln_s[(ig - 1 + a) * table.n_root_x + ix - 1..][..4];
                    acc += wa
                        * (wx[0] * row[0] as f64
                            + wx[1] * row[1] as f64
                            + wx[2] * row[2] as f64
                            + wx[3] * row[3] as f64);
                }
                acc
            } else {
                ln_poisson_series_window(g, ln_g, r * r, &mut mode)
                    .unwrap_or_else(|| poisson_series(g, r * r, settings).ln())
            };
            if !(*o >= floor) {
                break;
            }
        }
    } else {
        for (&r, o) in values.by_ref() {
            *o = poisson_series(g, r * r, settings).ln();
            if !(*o >= floor) {
                break;
            }
        }
    }
    for (_, o) in values {
        *o = f64::NEG_INFINITY;
    }
}

/// ln S for g <= 40 by summing the terms within 6 standard deviations (of
/// the bell the terms form around their mode, plus 3) of the largest one,
/// from the index tables, in one pass without dependencies between terms.
/// The terms are log-concave in m, so the ones left out are below ~e^-18 of
/// the largest: 2e-9 relative where the table builders use it (far tails,
/// measured in the tests), far below the f32 rounding of the tables. `mode`
/// is a starting guess for the index of the largest term (0: none), updated
/// to it: along increasing x it moves by a step or two. None when g > 40 or
/// the window leaves the index tables.
pub(crate) fn ln_poisson_series_window(g: f64, ln_g: f64, x: f64, mode: &mut usize) -> Option<f64> {
    if !(g > 0.0 && g <= 40.0 && x >= 0.0) {
        return None;
    }
    let t = index_tables();
    let n = SMALL_INDEX_TABLE;
    let ln_term = |m: usize| m as f64 * ln_g - t.ln_factorial[m] - x * t.inv[m] - t.ln[m];
    let guess = if *mode == 0 {
        mode_estimate(g, x)
    } else {
        *mode as f64
    };
    if !(guess < (n - 2) as f64) {
        return None;
    }
    let mut m = (guess as usize).max(1);
    while m + 1 < n && ln_term(m + 1) > ln_term(m) {
        m += 1;
    }
    while m > 1 && ln_term(m - 1) > ln_term(m) {
        m -= 1;
    }
    *mode = m;
    let peak = ln_term(m);
    let mf = m as f64;
    // -L''(m) of the continuous terms: 1/m (Poisson) + 2x/m^3 (lobe) - 1/m^2.
    let curvature = (1.0 / mf + 2.0 * x / (mf * mf * mf) - 1.0 / (mf * mf)).max(1e-6);
    let half_width = (6.0 / curvature.sqrt()) as usize + 3;
    if m + half_width >= n {
        return None;
    }
    // Four partial sums (floating-point sums are not reassociated for us).
    let lo = m.saturating_sub(half_width).max(1);
    let hi = m + half_width + 1;
    let blocks = (hi - lo).div_ceil(4);
    let mut sums = [0.0f64; 4];
    for b in 0..blocks {
        let start = (lo + 4 * b).min(n - 4);
        let ln_fact: &[f64; 4] = t.ln_factorial[start..start + 4].try_into().unwrap();
        let inv: &[f64; 4] = t.inv[start..start + 4].try_into().unwrap();
        let ln_m: &[f64; 4] = t.ln[start..start + 4].try_into().unwrap();
        for l in 0..4 {
            let j = (start + l) as f64;
            let term = fast_exp_vectorisable(j * ln_g - ln_fact[l] - x * inv[l] - ln_m[l] - peak);
            // Terms counted twice at a clipped last block are masked out.
            sums[l] += if start + l >= lo + 4 * b { term } else { 0.0 };
        }
    }
    let sum = (sums[0] + sums[1]) + (sums[2] + sums[3]);
    Some(peak - g + sum.ln())
}

pub(super) fn series_table() -> &'static SeriesTable {
    static TABLE: std::sync::OnceLock<SeriesTable> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let ln_g_min = TABLE_G_MIN.ln();
        // One coefficient beyond each end for the bicubic stencil.
        let n_g = ((TABLE_G_MAX.ln() - ln_g_min) / TABLE_D_LN_G).ceil() as usize + 3;
        let n_root_x = (TABLE_ROOT_X_MAX / TABLE_D_ROOT_X).ceil() as usize + 3;
        // Samples over the table plus SPLINE_MARGIN on every side: sample
        // row r is table row r - m (ln g = ln_g_min + (r - m - 1) d), sample
        // column c table column c - m (rho = (c - m - 1) d; ln S is even in
        // rho, so negative rho mirrors positive).
        let m = SPLINE_MARGIN;
        let rows = n_g + 2 * m;
        let line = n_root_x + 2 * m;
        let mut samples = vec![0.0; rows * line];
        for (r, row) in samples.chunks_exact_mut(line).enumerate() {
            let g = (ln_g_min + (r as f64 - m as f64 - 1.0) * TABLE_D_LN_G).exp();
            for (c, out) in row.iter_mut().enumerate() {
                let rho = (c as f64 - m as f64 - 1.0).abs() * TABLE_D_ROOT_X;
                let x = rho * rho * (1.0 + g);
                let s = if g > 40.0 {
                    poisson_series_saddle(g, x).unwrap_or_else(|| poisson_series_exact(g, x, 1e-13))
                } else {
                    poisson_series_exact(g, x, 1e-13)
                };
                *out = s.max(1e-300).ln();
            }
        }
        prefilter_2d(&mut samples, rows, line, 1);
        let mut ln_s = Vec::with_capacity(n_g * n_root_x);
        for r in m..m + n_g {
            let row = &samples[r * line + m..][..n_root_x];
            ln_s.extend(row.iter().map(|&c| c as f32));
        }
        SeriesTable {
            ln_g_min,
            inv_d_ln_g: 1.0 / TABLE_D_LN_G,
            n_g,
            inv_d_root_x: 1.0 / TABLE_D_ROOT_X,
            n_root_x,
            ln_s,
        }
    })
}

/// The universal table as the JIT export hands it to renderers
/// (docs/jit.md): coefficient (r, c) of the bicubic B-spline sits at
/// ln g = `ln_g_min` + (r - 1) `d_ln_g`, rho = (c - 1) `d_rho`; the table
/// serves `g_min` <= g < `g_max` and rho < `rho_max`.
pub struct SeriesTableExport {
    pub ln_g_min: f64,
    pub d_ln_g: f64,
    pub n_g: usize,
    pub d_rho: f64,
    pub n_rho: usize,
    pub g_min: f64,
    pub g_max: f64,
    pub rho_max: f64,
    /// n_g rows of n_rho coefficients of ln S, row-major.
    pub coefficients: &'static [f32],
}

/// The universal series table (built on first use) for the JIT export.
pub fn series_table_export() -> SeriesTableExport {
    let t = series_table();
    SeriesTableExport {
        ln_g_min: t.ln_g_min,
        d_ln_g: TABLE_D_LN_G,
        n_g: t.n_g,
        d_rho: TABLE_D_ROOT_X,
        n_rho: t.n_root_x,
        g_min: TABLE_G_MIN,
        g_max: TABLE_G_MAX,
        rho_max: TABLE_ROOT_X_MAX,
        coefficients: &t.ln_s,
    }
}

/// Prefilters a row-major grid of samples (`rows` x `cols` points of
/// `lanes` values each) along both directions into bicubic B-spline
/// coefficients.
pub(crate) fn prefilter_2d(grid: &mut [f64], rows: usize, cols: usize, lanes: usize) {
    for row in grid.chunks_exact_mut(cols * lanes) {
        spline_prefilter(row, cols, lanes);
    }
    spline_prefilter(grid, rows, cols * lanes);
}

impl SeriesTable {
    /// None outside the tabulated (g, x) range.
    #[inline]
    fn lookup(&self, g: f64, x: f64) -> Option<f64> {
        self.lookup_parts(g, g.ln(), x.sqrt())
    }

    /// The same from g, ln g and sqrt(x) when the caller has them.
    #[inline]
    pub(super) fn lookup_parts(&self, g: f64, ln_g: f64, root_x: f64) -> Option<f64> {
        self.ln_lookup_parts(g, ln_g, root_x).map(fast_exp)
    }

    /// ln S from g, ln g and sqrt(x); None outside the table.
    #[inline]
    fn ln_lookup_parts(&self, g: f64, ln_g: f64, root_x: f64) -> Option<f64> {
        if !(TABLE_G_MIN..TABLE_G_MAX).contains(&g) {
            return None;
        }
        let rho = root_x / (1.0 + g).sqrt();
        if !(rho < TABLE_ROOT_X_MAX) {
            return None;
        }
        let fg = (ln_g - self.ln_g_min) * self.inv_d_ln_g + 1.0;
        let fx = rho * self.inv_d_root_x + 1.0;
        let ig = (fg as usize).clamp(1, self.n_g - 3);
        let ix = (fx as usize).clamp(1, self.n_root_x - 3);
        let wg = bspline_weights(fg - ig as f64);
        let wx = bspline_weights(fx - ix as f64);
        let mut acc = 0.0;
        for (a, wa) in wg.iter().enumerate() {
            let row = &self.ln_s[(ig - 1 + a) * self.n_root_x + ix - 1..][..4];
            acc += wa
                * (wx[0] * row[0] as f64
                    + wx[1] * row[1] as f64
                    + wx[2] * row[2] as f64
                    + wx[3] * row[3] as f64);
        }
        Some(acc)
    }
}

/// phi(m) = exp(-x/m)/m.
#[inline(always)]
fn phi(x: f64, m: f64) -> f64 {
    fast_exp(-x / m) / m
}

/// Tables of 1/m and ln m for the summation's small indices.
const SMALL_INDEX_TABLE: usize = 1024;

struct IndexTables {
    inv: Vec<f64>,
    ln: Vec<f64>,
    ln_factorial: Vec<f64>,
}

fn index_tables() -> &'static IndexTables {
    static TABLES: std::sync::OnceLock<IndexTables> = std::sync::OnceLock::new();
    TABLES.get_or_init(|| {
        let inv = (0..SMALL_INDEX_TABLE)
            .map(|m| if m == 0 { 0.0 } else { 1.0 / m as f64 })
            .collect();
        let ln = (0..SMALL_INDEX_TABLE)
            .map(|m| if m == 0 { 0.0 } else { (m as f64).ln() })
            .collect();
        let ln_factorial = (0..SMALL_INDEX_TABLE)
            .map(|m| ln_factorial(m as u32))
            .collect();
        IndexTables {
            inv,
            ln,
            ln_factorial,
        }
    })
}

/// Index m >= 1 near the largest term of the series. The summation is exact
/// from any start; a start near the mode keeps the terms, which are formed
/// relative to the starting one, far from overflow and the sweep short.
#[inline]
fn mode_estimate(g: f64, x: f64) -> f64 {
    // Near the specular peak the mode is the Poisson one, shifted by the
    // lobe factor: m = g exp(x/m^2) ~ g exp(x/g^2).
    if g >= 1.0 && x <= 0.5 * g * g {
        return (g * (x / (g * g)).exp()).round().max(1.0);
    }
    // Smooth surfaces: the terms rise from m = 1 to the mode by at most e^x.
    if g < 1.0 && x <= 400.0 {
        return 1.0;
    }
    // Off-specular: the mode solves m^2 ln(m/g) ~ x (the largest Poisson
    // weight times exp(-x/m)); two fixed-point steps on L = ln(m/g) land
    // within a few terms of it, which is all the summation needs.
    let ln_g = g.ln();
    let mut l = (0.5 * x.ln() - ln_g).max(1.0);
    let mut m = (x / l).sqrt();
    for _ in 0..2 {
        l = (m.ln() - ln_g).max(0.5);
        m = (x / l).sqrt();
    }
    m.round().clamp(1.0, 1e9)
}

/// Exact summation outward from the largest term. Terms are formed by their
/// ratios t_{m+1}/t_m = g m / (m+1)^2 exp(x / (m (m+1))) relative to the
/// starting term, so nothing under- or overflows on its own. ln t_m is
/// concave in m, so the ratios fall monotonically away from the mode and the
/// remaining tail is bounded by a geometric series: the sweep stops when that
/// bound is below `tolerance` times the partial sum.
pub fn poisson_series_exact(g: f64, x: f64, tolerance: f64) -> f64 {
    let tables = index_tables();
    let inv = |m: f64| -> f64 {
        let i = m as usize;
        if i < SMALL_INDEX_TABLE {
            tables.inv[i]
        } else {
            1.0 / m
        }
    };
    let m0 = mode_estimate(g, x);
    let i0 = m0 as usize;
    let (ln_m0, ln_fact_m0) = if i0 < SMALL_INDEX_TABLE {
        (tables.ln[i0], tables.ln_factorial[i0])
    } else {
        (m0.ln(), ln_gamma(m0 + 1.0))
    };
    let ln_t0 = -g + m0 * g.ln() - ln_fact_m0 - x * inv(m0) - ln_m0;
    if ln_t0 < -800.0 {
        return 0.0;
    }
    const MAX_TERMS: usize = 10_000_000;

    let mut sum = 1.0;
    // Upward.
    let mut t = 1.0;
    let mut m = m0;
    for _ in 0..MAX_TERMS {
        let inv_next = inv(m + 1.0);
        let r = g * m * inv_next * inv_next * fast_exp(x * inv(m) * inv_next);
        t *= r;
        m += 1.0;
        sum += t;
        if r < 1.0 && t * r <= tolerance * sum * (1.0 - r) {
            break;
        }
    }
    // Downward.
    let inv_g = 1.0 / g;
    let mut t = 1.0;
    let mut m = m0;
    while m > 1.0 {
        let inv_prev = inv(m - 1.0);
        let q = m * m * inv_g * inv_prev * fast_exp(-x * inv_prev * inv(m));
        t *= q;
        m -= 1.0;
        sum += t;
        if q < 1.0 && t * q <= tolerance * sum * (1.0 - q) {
            break;
        }
    }
    sum * ln_t0.exp()
}

/// Gauss-Hermite nodes t_i and weights (probabilists' form: integrate against
/// the standard normal density; weights sum to 1), n = 8.
const GH_NODES: [f64; 8] = [
    -4.144_547_186_125_894_5,
    -2.802_485_861_287_541_6,
    -1.636_519_042_435_108,
    -0.539_079_811_351_375_1,
    0.539_079_811_351_375_1,
    1.636_519_042_435_108,
    2.802_485_861_287_541_6,
    4.144_547_186_125_894_5,
];
const GH_WEIGHTS: [f64; 8] = [
    1.126_145_383_753_676_2e-4,
    9.635_220_120_788_256e-3,
    1.172_399_076_617_590_4e-1,
    3.730_122_576_790_773e-1,
    3.730_122_576_790_773e-1,
    1.172_399_076_617_590_4e-1,
    9.635_220_120_788_256e-3,
    1.126_145_383_753_676_2e-4,
];

/// Probabilists' Hermite polynomials He_0..He_9 at t.
#[inline]
fn hermite_he(t: f64) -> [f64; 10] {
    let mut h = [0.0; 10];
    h[0] = 1.0;
    h[1] = t;
    for n in 1..9 {
        h[n + 1] = t * h[n] - n as f64 * h[n - 1];
    }
    h
}

fn hermite_at_nodes() -> &'static [[f64; 10]; 8] {
    static TABLE: std::sync::OnceLock<[[f64; 10]; 8]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| GH_NODES.map(hermite_he))
}

/// Largest |d ln phi / dt| (in units of the standard deviation) for which the
/// 8-node rule is trusted: beyond it the lobe exponent varies too fast across
/// the Poisson bulk (far off-specular) and the exact sum takes over.
const ASYMPTOTIC_MAX_SLOPE: f64 = 2.0;

/// E[phi(M)], M ~ Poisson(g), by Gauss-Hermite quadrature of the Edgeworth
/// expansion of the Poisson law (cumulants all equal g): with z the
/// standardised count, the density is N(z)[1 + k3/6 He3 + k4/24 He4 +
/// k3^2/72 He6 + k5/120 He5 + k3 k4/144 He7 + k3^3/1296 He9 + ...] with
/// k_r = g^(1 - r/2). The discreteness of M adds only terms of order
/// exp(-2 pi^2 g) for phi smooth on the scale of sqrt(g). None when the
/// configuration is too far off-specular for 8 nodes.
pub fn poisson_series_asymptotic(g: f64, x: f64) -> Option<f64> {
    let sd = g.sqrt();
    // d/dm (-x/m - ln m) at m = g, times the standard deviation.
    let slope = (x / (g * g) - 1.0 / g).abs() * sd;
    if slope > ASYMPTOTIC_MAX_SLOPE {
        return None;
    }
    let k3 = 1.0 / sd;
    let k4 = 1.0 / g;
    let k5 = k3 * k4;
    let c3 = k3 / 6.0;
    let c4 = k4 / 24.0;
    let c6 = k3 * k3 / 72.0;
    let c5 = k5 / 120.0;
    let c7 = k3 * k4 / 144.0;
    let c9 = k3 * k3 * k3 / 1296.0;
    let he = hermite_at_nodes();
    let mut sum = 0.0;
    for i in 0..8 {
        let h = &he[i];
        let correction =
            1.0 + c3 * h[3] + c4 * h[4] + c5 * h[5] + c6 * h[6] + c7 * h[7] + c9 * h[9];
        let m = g + sd * GH_NODES[i];
        sum += GH_WEIGHTS[i] * correction * phi(x, m);
    }
    Some(sum.max(0.0))
}

/// Physicists' Gauss-Hermite nodes and weights (weight exp(-z^2)), n = 10.
const GH10_NODES: [f64; 10] = [
    -3.436_159_118_837_737_6,
    -2.532_731_674_232_79,
    -1.756_683_649_299_882,
    -1.036_610_829_789_514,
    -0.342_901_327_223_704_6,
    0.342_901_327_223_704_6,
    1.036_610_829_789_514,
    1.756_683_649_299_882,
    2.532_731_674_232_79,
    3.436_159_118_837_737_6,
];
const GH10_WEIGHTS: [f64; 10] = [
    7.640_432_855_232_64e-6,
    1.343_645_746_781_232_7e-3,
    3.387_439_445_548_106e-2,
    2.401_386_110_823_147e-1,
    6.108_626_337_353_258e-1,
    6.108_626_337_353_258e-1,
    2.401_386_110_823_147e-1,
    3.387_439_445_548_106e-2,
    1.343_645_746_781_232_7e-3,
    7.640_432_855_232_64e-6,
];

/// ln Gamma(z) for z >= 2 by Stirling's series (error < 1e-9).
#[inline]
fn ln_gamma_stirling(z: f64) -> f64 {
    let inv = 1.0 / z;
    let inv2 = inv * inv;
    (z - 0.5) * z.ln() - z
        + 0.918_938_533_204_672_8
        + inv * (1.0 / 12.0 - inv2 * (1.0 / 360.0 - inv2 * (1.0 / 1260.0 - inv2 / 1680.0)))
}

/// S(g, x) by saddle-point quadrature: the terms t_m = exp(L(m)) form a
/// smooth bell in m (L extended to real m through ln Gamma), so the sum
/// equals the integral of exp(L) up to terms of order exp(-2 pi^2 sd^2) (the
/// Euler-Maclaurin / Poisson-summation remainder for a bell of width sd), and
/// the integral is a 10-node Gauss-Hermite rule centred on the bell's mode
/// with its curvature. Cost independent of g and x; None where the bell is
/// too narrow (sd < 2.5) or reaches m < 1, where the exact sum is cheap.
pub fn poisson_series_saddle(g: f64, x: f64) -> Option<f64> {
    let ln_g = g.ln();
    // Newton on L'(m) = ln g - psi(m+1) + x/m^2 - 1/m, psi(m+1) ~ ln(m+1/2)
    // + 1/(24 (m+1/2)^2).
    let mut m = mode_estimate(g, x).max(2.0);
    let mut curvature = 0.0;
    for _ in 0..6 {
        let mh = m + 0.5;
        let inv_m = 1.0 / m;
        let d1 = ln_g - mh.ln() - 1.0 / (24.0 * mh * mh) + x * inv_m * inv_m - inv_m;
        // L''(m): -psi'(m+1) - 2x/m^3 + 1/m^2, psi'(m+1) ~ 1/(m+1/2) - 1/(12 (m+1/2)^3)... kept to
        // the order that matters for the step.
        curvature = -1.0 / mh - 2.0 * x * inv_m * inv_m * inv_m + inv_m * inv_m;
        if !(curvature < 0.0) {
            return None;
        }
        let step = -d1 / curvature;
        m = (m + step).clamp(0.5 * m, 2.0 * m);
        if step.abs() < 1e-3 * m.max(1.0) {
            break;
        }
    }
    let sd = (-1.0 / curvature).sqrt();
    if !(sd >= 2.5) || m - 5.5 * sd < 1.0 {
        return None;
    }
    let scale = std::f64::consts::SQRT_2 * sd;
    let ln_term = |m: f64| -g + m * ln_g - ln_gamma_stirling(m + 1.0) - x / m - m.ln();
    let l_mode = ln_term(m);
    let mut sum = 0.0;
    for i in 0..10 {
        let z = GH10_NODES[i];
        sum += GH10_WEIGHTS[i] * fast_exp(ln_term(m + scale * z) - l_mode + z * z);
    }
    Some(scale * sum * l_mode.exp())
}

/// Reference S(g, x) for tests and the accuracy harness: plain log-space
/// summation over every term that can matter, in f64, no shortcuts.
pub fn poisson_series_reference(g: f64, x: f64) -> f64 {
    if !(g > 0.0) {
        return 0.0;
    }
    let ln_g = g.ln();
    let width = 12.0 * g.sqrt() + 60.0;
    let hi = (g + width).max(x.sqrt() * 4.0 + 200.0) as u32;
    let mut terms = Vec::with_capacity(hi as usize);
    let mut ln_max = f64::NEG_INFINITY;
    for m in 1..=hi {
        let mf = m as f64;
        let lt = -g + mf * ln_g - ln_factorial(m) - x / mf - mf.ln();
        ln_max = ln_max.max(lt);
        terms.push(lt);
    }
    if ln_max == f64::NEG_INFINITY {
        return 0.0;
    }
    let rel: f64 = terms.iter().map(|lt| (lt - ln_max).exp()).sum();
    (ln_max + rel.ln()).exp()
}

#[cfg(test)]
mod tests {
    use super::super::GaussianSurface;
    use super::*;
    use crate::optics::geometry::PairGeometry;
    use glam::DVec3;
    use std::f64::consts::PI;

    fn rel_err(a: f64, b: f64) -> f64 {
        if a == b {
            0.0
        } else {
            (a - b).abs() / b.abs().max(1e-300)
        }
    }

    /// Grid of (g, x) from very smooth to very rough and from the specular
    /// peak to far into the tails; compares against the plain reference.
    #[test]
    fn series_matches_reference_everywhere_it_matters() {
        let settings = SeriesSettings::default();
        let mut worst: f64 = 0.0;
        let mut worst_at = (0.0, 0.0);
        let gs = [
            1e-8, 1e-3, 0.05, 0.3, 1.0, 2.5, 7.0, 20.0, 29.9, 30.0, 33.0, 45.0, 100.0, 300.0, 1e3,
            5e3,
        ];
        for &g in &gs {
            let peak = poisson_series_reference(g, 0.0);
            for i in 0..60 {
                // x/g from 0 to ~ 30 (Beckmann exponent tan^2/alpha^2 up to 30)
                let y = if i == 0 {
                    0.0
                } else {
                    30.0 * (i as f64 / 59.0).powi(2)
                };
                let x = y * g.max(1.0);
                let reference = poisson_series_reference(g, x);
                // Only where the value is not negligible against the peak.
                if reference < 1e-12 * peak {
                    continue;
                }
                let got = poisson_series(g, x, &settings);
                let e = rel_err(got, reference);
                if e > worst {
                    worst = e;
                    worst_at = (g, x);
                }
            }
        }
        println!("series worst relative error {worst:.2e} at (g, x) = {worst_at:?}");
        assert!(worst < 1e-4, "worst {worst} at {worst_at:?}");
    }

    /// The universal table between its nodes, against the forms it was
    /// filled from, at random (g, rho) over its whole range wherever S is
    /// within 1e-20 of its peak S(g, 0) (and above e^-200).
    #[test]
    fn table_matches_its_sources_between_nodes() {
        let mut rng = crate::benchmark::SplitMix64(11);
        let table = series_table();
        let mut worst: f64 = 0.0;
        let mut worst_at = (0.0, 0.0);
        let mut checked = 0;
        for _ in 0..20_000 {
            let g = (TABLE_G_MIN.ln() + rng.next_f64() * (TABLE_G_MAX / TABLE_G_MIN).ln()).exp();
            let rho = rng.next_f64() * 25.0;
            let x = rho * rho * (1.0 + g);
            let source = |x: f64| {
                if g > 40.0 {
                    poisson_series_saddle(g, x).unwrap_or_else(|| poisson_series_exact(g, x, 1e-13))
                } else {
                    poisson_series_exact(g, x, 1e-13)
                }
            };
            let exact = source(x);
            if !(exact.ln() > (source(0.0).ln() - 46.0).max(-200.0)) {
                continue;
            }
            let got = table.lookup(g, x).unwrap();
            let e = rel_err(got, exact);
            checked += 1;
            if e > worst {
                worst = e;
                worst_at = (g, x);
            }
        }
        println!(
            "universal table: {checked} points, worst relative error {worst:.2e} at {worst_at:?}"
        );
        assert!(checked > 5000);
        assert!(worst < 1e-5, "worst {worst} at {worst_at:?}");
    }

    /// The windowed sum against the exact series in the far tails, where
    /// the table builders use it.
    #[test]
    fn windowed_sum_matches_exact_series() {
        let mut worst: f64 = 0.0;
        let mut worst_at = (0.0, 0.0);
        let mut used = 0;
        for i in 0..60 {
            let g = (TABLE_G_MIN.ln() + i as f64 / 59.0 * (40.0 / TABLE_G_MIN).ln()).exp();
            for j in 0..80 {
                // Where the tables use it: beyond the universal table.
                let rho = 40.0 + 1.5 * j as f64;
                let x = rho * rho * (1.0 + g);
                let Some(l) = ln_poisson_series_window(g, g.ln(), x, &mut 0) else {
                    continue;
                };
                let exact = poisson_series_exact(g, x, 1e-14);
                // (S below 1e-300 loses digits to subnormal rounding.)
                if !(exact > 1e-300) {
                    continue;
                }
                used += 1;
                let e = (l - exact.ln()).abs();
                if e > worst {
                    worst = e;
                    worst_at = (g, x);
                }
            }
        }
        println!("windowed sum: {used} points, worst relative error {worst:.2e} at {worst_at:?}");
        assert!(used > 2000);
        assert!(worst < 1e-7, "worst {worst} at {worst_at:?}");
    }

    #[test]
    fn saddle_quadrature_matches_reference() {
        let mut worst: f64 = 0.0;
        let mut worst_at = (0.0, 0.0);
        let mut used = 0;
        for &g in &[0.5, 3.0, 10.0, 30.0, 100.0, 700.0, 3000.0] {
            let peak = poisson_series_reference(g, 0.0);
            for i in 0..80 {
                let x = 0.5 * (i as f64).powi(3) * g.max(1.0) / 100.0 + 50.0 * i as f64;
                let reference = poisson_series_reference(g, x);
                if reference < 1e-250 || reference < 1e-200 * peak {
                    continue;
                }
                if let Some(got) = poisson_series_saddle(g, x) {
                    used += 1;
                    let e = rel_err(got, reference);
                    if e > worst {
                        worst = e;
                        worst_at = (g, x);
                    }
                }
            }
        }
        println!(
            "saddle quadrature: {used} points, worst relative error {worst:.2e} at {worst_at:?}"
        );
        assert!(used > 200);
        assert!(worst < 2e-5, "worst {worst} at {worst_at:?}");
    }

    #[test]
    fn far_tails_stay_finite_and_small() {
        let settings = SeriesSettings::default();
        for &g in &[1e-20, 1e-3, 1.0, 50.0, 1e4, 1e7] {
            for &x in &[0.0, 1.0, 1e3, 1e6, 1e12, 1e300] {
                let s = poisson_series(g, x, &settings);
                assert!(s.is_finite() && s >= 0.0, "S({g}, {x}) = {s}");
                assert!(s <= 1.0 + 1e-9, "S({g}, {x}) = {s} exceeds its bound 1");
            }
        }
        // Far off-specular (the mode moves far above g) agrees too, in the
        // table and beyond it (rho = 75, the windowed sum; S ~ 1e-140).
        for (g, x) in [(3.0, 5000.0), (1.5, 2.5 * 75.0 * 75.0)] {
            let a = poisson_series(g, x, &settings);
            let b = poisson_series_reference(g, x);
            assert!(rel_err(a, b) < 1e-5, "{a} vs {b}");
        }
    }

    #[test]
    fn small_g_is_first_order_term() {
        // physics.md: for small g the m = 1 term dominates: S ~ g e^-g e^-x.
        for &g in &[1e-6, 1e-4, 1e-3] {
            for &x in &[0.0, 0.5, 2.0] {
                let s = poisson_series(g, x, &SeriesSettings::default());
                let first = g * (-g).exp() * (-x).exp();
                assert!(rel_err(s, first) < 2.0 * g, "g={g} x={x}: {s} vs {first}");
            }
        }
    }

    /// physics.md: for large g the diffuse BRDF tends to the Beckmann
    /// microfacet BRDF F^2 D(theta_h; alpha = 2 sigma / T)/(4 cos_i cos_o)
    /// with relative error ~ 1/g. Check within 1% where g >= 100.
    #[test]
    fn large_g_tends_to_beckmann() {
        let sigma = 1.2;
        let corr = 6.0;
        let surface = GaussianSurface::isotropic(sigma, corr);
        let alpha = 2.0 * sigma / corr;
        let lambda_um = 0.5;
        let k = 2.0 * PI / lambda_um;
        let mut checked = 0;
        let mut worst: f64 = 0.0;
        for ti in 0..6 {
            for to in 0..6 {
                for phi_o in [0.0, 0.7, 2.0, PI] {
                    let th_i = ti as f64 * 0.12;
                    let th_o = to as f64 * 0.1;
                    let wi = DVec3::new(th_i.sin(), 0.0, th_i.cos());
                    let wo = DVec3::new(
                        -th_o.sin() * f64::cos(phi_o),
                        th_o.sin() * f64::sin(phi_o),
                        th_o.cos(),
                    );
                    let geom = PairGeometry::new(wi, wo).unwrap();
                    let g = surface.roughness_exponent(k, geom.w);
                    assert!(g >= 100.0);
                    let h = (wi + wo).normalize();
                    let tan2 = (1.0 - h.z * h.z) / (h.z * h.z);
                    let d = (-tan2 / (alpha * alpha)).exp() / (PI * alpha * alpha * h.z.powi(4));
                    let beckmann = d / (4.0 * wi.z * wo.z);
                    if tan2 / (alpha * alpha) > 4.0 {
                        continue; // the 1/g correction grows with the exponent
                    }
                    let f = geom.geometric_factor * surface.kernel(k, &geom);
                    let e = rel_err(f, beckmann);
                    worst = worst.max(e);
                    checked += 1;
                }
            }
        }
        println!("Beckmann limit: {checked} pairs, worst relative error {worst:.3e}");
        assert!(checked > 50);
        assert!(worst < 0.01, "worst {worst}");
    }

    #[test]
    fn anisotropic_reduces_to_isotropic_and_swaps_axes() {
        let iso = GaussianSurface::isotropic(0.1, 2.0);
        let aniso = GaussianSurface {
            isotropic: false,
            ..GaussianSurface::anisotropic(0.1, 2.0, 2.0)
        };
        let ax = GaussianSurface::anisotropic(0.1, 4.0, 0.5);
        let ay = GaussianSurface::anisotropic(0.1, 0.5, 4.0);
        let k = 2.0 * PI / 0.55;
        let wi = DVec3::new(0.3, 0.1, 0.9).normalize();
        let wo = DVec3::new(-0.2, 0.25, 0.8).normalize();
        let g1 = PairGeometry::new(wi, wo).unwrap();
        assert!(rel_err(iso.kernel(k, &g1), aniso.kernel(k, &g1)) < 1e-12);
        // Swapping Tx/Ty equals swapping the x and y axes of both directions.
        let swap = |d: DVec3| DVec3::new(d.y, d.x, d.z);
        let g2 = PairGeometry::new(swap(wi), swap(wo)).unwrap();
        assert!(rel_err(ax.kernel(k, &g1), ay.kernel(k, &g2)) < 1e-12);
        assert!(rel_err(ax.kernel(k, &g1), ax.kernel(k, &g2)) > 1e-3);
    }
}

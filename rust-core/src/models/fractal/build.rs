//! Construction of the ln Phi_alpha table (see fractal.rs for the method).
//!
//! Every table point is computed by the best of three independent sources,
//! each with an error estimate:
//! - the small-x series (many terms at build time; convergent for alpha > 1,
//!   asymptotic and optimally truncated for alpha < 1),
//! - the large-x series (convergent for alpha < 1, asymptotic otherwise),
//! - Mellin-Barnes inversion by FFT: Phi(e^y) e^(c y) = (1/2pi) int M(c+it)
//!   e^(-ity) dt, for a ladder of c values chosen by the saddle point (the
//!   mean of y under the weight is d ln M/dc, its variance d^2 ln M/dc^2).

use super::math::{
    expm1_c, ln_gamma_ratio, ln_mellin, ln_mellin_gauss, ln_mellin_real, SeriesCoefs, LN_2PI,
    LN_PI, TWO_PI,
};
use num_complex::Complex64 as C64;
use rustfft::FftPlanner;

/// One computed point: ln Phi, d ln Phi / d ln x and an estimated relative
/// error of Phi.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Point {
    pub ln_phi: f64,
    pub dln_phi: f64,
    pub err: f64,
}

const BAD: Point = Point {
    ln_phi: f64::NAN,
    dln_phi: f64::NAN,
    err: f64::INFINITY,
};

/// Build-time evaluation of the small-x series with an error estimate.
pub(crate) fn small_full(small: &[f64], alpha: f64, y: f64) -> Point {
    let asymptotic = alpha < 1.0;
    let l0 = small[0];
    let (mut s, mut a, mut ds) = (0.0f64, 0.0f64, 0.0f64);
    let mut trunc = f64::INFINITY;
    let mut prev = f64::INFINITY;
    let mut lmax = f64::NEG_INFINITY;
    for (n, c) in small.iter().enumerate() {
        let l = c + 2.0 * n as f64 * y - l0;
        if asymptotic && n > 0 && l > prev {
            trunc = prev.exp();
            break;
        }
        if l > 650.0 {
            return BAD;
        }
        lmax = lmax.max(l);
        if l < lmax - 47.0 {
            trunc = l.exp();
            break;
        }
        let e = l.exp();
        let sign = if n % 2 == 0 { 1.0 } else { -1.0 };
        s += sign * e;
        a += e;
        ds += sign * 2.0 * n as f64 * e;
        prev = l;
    }
    if s.is_nan() || s <= 0.0 || !trunc.is_finite() {
        return BAD;
    }
    Point {
        ln_phi: l0 + s.ln(),
        dln_phi: ds / s,
        err: (trunc + 3e-16 * a) / s,
    }
}

/// Build-time evaluation of the large-x series with an error estimate.
pub(crate) fn large_full(co: &SeriesCoefs, alpha: f64, y: f64) -> Point {
    let asymptotic = alpha >= 1.0;
    let l1 = co.large[0] - (alpha + 2.0) * y;
    let (mut s, mut a, mut ds) = (0.0f64, 0.0f64, 0.0f64);
    let mut trunc = f64::INFINITY;
    let mut prev_b = f64::INFINITY;
    let mut bmax = f64::NEG_INFINITY;
    for j in 1..=co.large.len() {
        let jf = j as f64;
        let p = jf * alpha + 2.0;
        let lb = co.large_bound[j - 1] - p * y - l1;
        if asymptotic && j > 2 && lb > prev_b {
            // remainder of the optimally truncated asymptotic series: the
            // sin-free size of the smallest term (see SeriesCoefs::large_nosin)
            let jm = j - 1;
            let ln_rem = co.large_nosin[jm - 1] - (jm as f64 * alpha + 2.0) * y - l1;
            trunc = prev_b.exp().max(ln_rem.exp());
            break;
        }
        if lb > 650.0 {
            return BAD;
        }
        bmax = bmax.max(lb);
        if j > 2 && lb < bmax - 47.0 {
            trunc = lb.exp();
            break;
        }
        let l = co.large[j - 1] - p * y - l1;
        if l.is_finite() {
            let e = l.exp();
            s += co.large_sign[j - 1] * e;
            a += e;
            ds -= co.large_sign[j - 1] * p * e;
        }
        if j >= 2 {
            prev_b = lb;
        }
    }
    if s.is_nan() || s <= 0.0 || !trunc.is_finite() {
        return BAD;
    }
    Point {
        ln_phi: l1 + s.ln(),
        dln_phi: ds / s,
        err: (trunc + 3e-16 * a) / s,
    }
}

/// Result of one FFT window: points on the fine grid starting at index i0.
pub(crate) struct Window {
    pub i0: i64,
    pub points: Vec<Point>,
}

/// Mellin-Barnes inversion for one c on the grid grid0 + i * hf.
///
/// With `gauss` the transform is of D = Phi_alpha - Phi_2 (Mellin transform
/// M_2(z) (exp(ln_gamma_ratio) - 1), no cancellation as alpha -> 2) and the
/// closed form Phi_2 = pi exp(-x^2/4) is added back: near alpha = 2 the
/// power-law tail is far below the core and would be lost in the rounding of
/// a transform of Phi itself.
/// Steps of the t-range search of one FFT window before it gives up.
const T_RANGE_MAX_STEPS: usize = 20_000;

pub(crate) fn fft_window(
    alpha: f64,
    c: f64,
    grid0: f64,
    hf: f64,
    gauss: bool,
    planner: &mut FftPlanner<f64>,
) -> Option<Window> {
    let (_, ystar, kappa) = ln_mellin_real(alpha, c);
    let lnm = |z: C64| -> C64 {
        if gauss {
            ln_mellin_gauss(z)
        } else {
            ln_mellin(alpha, z)
        }
    };
    let f0 = lnm(C64::new(c, 0.0)).re;
    if !f0.is_finite() || kappa.is_nan() || kappa <= 0.0 {
        return None;
    }
    // t range: |M(c+it)| / M(c) below e^-40.
    let tau = (0.2 / kappa.sqrt()).min(0.25);
    let mut t_max = tau;
    let mut below = 0;
    // Bounded: for hurst within ~1e-4 of 0 the range search would run for
    // minutes (complex ln Gamma per step) and then fail anyway.
    let mut steps = 0;
    for _ in 0..200_000 {
        steps += 1;
        if steps > T_RANGE_MAX_STEPS {
            return None;
        }
        let lm = lnm(C64::new(c, t_max)).re - f0;
        if lm < -40.0 {
            below += 1;
            if below >= 3 {
                break;
            }
        } else {
            below = 0;
        }
        t_max += tau;
    }
    let left = (90.0 * kappa).sqrt() + 45.0 / c;
    let right = (90.0 * kappa).sqrt() + 45.0 / (2.0 + alpha - c);
    let mut y_need = left + right;
    for _attempt in 0..6 {
        // Windows beyond 2^24 points (hurst within ~1e-30 of 0, where
        // the Mellin transform's scales overflow) are refused, not grown
        // until an index overflows.
        const MAX_POINTS: f64 = (1u64 << 24) as f64;
        let points = (y_need / hf).ceil();
        if !(points <= MAX_POINTS && t_max.is_finite()) {
            return None;
        }
        let mut n = (points as usize).next_power_of_two().max(64);
        let (dt, jmax) = loop {
            let dt = TWO_PI / (n as f64 * hf);
            let jmax = (t_max / dt).ceil();
            if !(jmax.is_finite() && n as f64 <= MAX_POINTS) {
                return None;
            }
            let jmax = jmax as usize;
            if 2 * jmax + 2 <= n {
                break (dt, jmax);
            }
            n *= 2;
        };
        let y_window = n as f64 * hf;
        let y_start = ystar - left * (y_window / y_need);
        let i0 = ((y_start - grid0) / hf).floor() as i64;
        let y0 = grid0 + i0 as f64 * hf;
        // Relative rounding of the samples: ln M and the phase t y0 are
        // large for small alpha and carry absolute errors ~1e-16 |value|.
        let floor = 2e-16 * (f0.abs() + t_max * (y0.abs() + ystar.abs()) + 20.0);
        let mut buf = vec![C64::new(0.0, 0.0); n];
        let mut l1 = 0.0;
        let mut l1b = 0.0;
        for j in 0..=jmax {
            let t = j as f64 * dt;
            let z = C64::new(c, t);
            let lm = lnm(z) - f0;
            let lm = C64::new(lm.re, lm.im - t * y0);
            let mut a = lm.exp();
            if gauss {
                a *= expm1_c(ln_gamma_ratio(alpha, z));
            }
            let b = -z * a;
            let w = if j == 0 { 1.0 } else { 2.0 };
            l1 += w * a.norm();
            l1b += w * b.norm();
            // pack a + i b; a, b are Hermitian in j so both transforms are real
            buf[j] = a + C64::new(-b.im, b.re);
            if j > 0 {
                let (ac, bc) = (a.conj(), b.conj());
                buf[n - j] = ac + C64::new(-bc.im, bc.re);
            }
        }
        planner.plan_fft_forward(n).process(&mut buf);
        let edge_w = n / 32;
        let mut edge = 0.0f64;
        let mut edge2 = 0.0f64;
        for m in (0..edge_w).chain(n - edge_w..n) {
            edge = edge.max(buf[m].re.abs());
            edge2 = edge2.max(buf[m].im.abs());
        }
        if edge > (1e-14f64).max(10.0 * floor) * l1 {
            y_need *= 2.0;
            continue;
        }
        let ln_scale = f0 + (dt / TWO_PI).ln();
        let noise = edge + floor * l1;
        let noise2 = edge2 + floor * l1b;
        let points = buf
            .iter()
            .enumerate()
            .map(|(m, x)| {
                let y = y0 + m as f64 * hf;
                let (mut g, mut g2) = (x.re, x.im);
                if gauss {
                    let x2 = (2.0 * y).exp();
                    let p2 = (LN_PI - 0.25 * x2 + c * y - ln_scale).exp();
                    g += p2;
                    g2 -= 0.5 * x2 * p2;
                }
                if g.is_nan() || g <= 0.0 || !g.is_finite() {
                    return BAD;
                }
                Point {
                    ln_phi: ln_scale + g.ln() - c * y,
                    dln_phi: g2 / g,
                    err: noise / g + 1e-3 * noise2 / g,
                }
            })
            .collect();
        return Some(Window { i0, points });
    }
    None
}

/// Everything the runtime needs, as flat tables.
pub(crate) struct Tables {
    pub y0: f64,
    pub ln_phi: Vec<f64>,
    pub dln_phi: Vec<f64>,
    /// Largest estimated relative error of a node (source estimate).
    pub node_err: f64,
    /// Largest interpolation error found at the cell midpoints (in ln Phi).
    pub mid_err: f64,
    pub windows: usize,
}

/// Compute ln Phi on the grid y0 + i h (i < n) and check the cubic Hermite
/// interpolant at the midpoints. Returns None if some node has no source.
pub(crate) fn build_tables(
    alpha: f64,
    co: &SeriesCoefs,
    y0: f64,
    h: f64,
    n: usize,
) -> Result<Tables, String> {
    let hf = 0.5 * h;
    let nf = 2 * (n - 1) + 1;
    let yf = |i: usize| y0 + i as f64 * hf;
    let mut best: Vec<Point> = (0..nf)
        .map(|i| {
            let y = yf(i);
            let a = small_full(&co.small, alpha, y);
            let b = large_full(co, alpha, y);
            if a.err <= b.err {
                a
            } else {
                b
            }
        })
        .collect();
    // Region still needing the FFT.
    const GOOD: f64 = 1e-11;
    let need: Vec<usize> = (0..nf)
        .filter(|&i| best[i].err.is_nan() || best[i].err >= GOOD)
        .collect();
    let mut windows = 0;
    if let (Some(&ia), Some(&ib)) = (need.first(), need.last()) {
        let (ya, yb) = (yf(ia), yf(ib));
        let c_lo = 0.02f64;
        let delta_min = (0.125 * alpha).clamp(0.015, 0.25);
        // Near alpha = 2 the transform is of Phi - Phi_2, whose tail is
        // resolved with moderate c (shorter windows).
        let gauss = alpha >= 1.9;
        let c_hi = if gauss { 3.0 } else { 2.0 + alpha - delta_min };
        let ystar = |c: f64| ln_mellin_real(alpha, c).1;
        // first c: y*(c) = ya
        let mut c = if ystar(c_lo) >= ya {
            c_lo
        } else if ystar(c_hi) <= ya {
            c_hi
        } else {
            let (mut lo, mut hi) = (c_lo, c_hi);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if ystar(mid) < ya {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            lo
        };
        let mut planner = FftPlanner::new();
        loop {
            let w = fft_window(alpha, c, y0, hf, gauss, &mut planner)
                .ok_or_else(|| format!("FFT window failed at alpha = {alpha}, c = {c}"))?;
            windows += 1;
            for (m, p) in w.points.iter().enumerate() {
                let i = w.i0 + m as i64;
                if i >= 0 && (i as usize) < nf && p.err < best[i as usize].err {
                    best[i as usize] = *p;
                }
            }
            let (_, ys, kappa) = ln_mellin_real(alpha, c);
            if ys >= yb || c >= c_hi || windows > 200 {
                break;
            }
            c = (c + 3.0 / kappa.sqrt()).min(c_hi);
        }
    }
    let node_err = (0..n).map(|i| best[2 * i].err).fold(0.0, f64::max);
    if !node_err.is_finite() {
        let bad = (0..n).find(|&i| !best[2 * i].err.is_finite()).unwrap_or(0);
        return Err(format!(
            "Phi_alpha table: no accurate source at alpha = {alpha}, y = {}",
            y0 + bad as f64 * h
        ));
    }
    let ln_phi: Vec<f64> = (0..n).map(|i| best[2 * i].ln_phi).collect();
    let dln_phi: Vec<f64> = (0..n).map(|i| best[2 * i].dln_phi).collect();
    let mut mid_err = 0.0f64;
    for i in 0..n - 1 {
        let m = best[2 * i + 1];
        let p = hermite(ln_phi[i], ln_phi[i + 1], dln_phi[i], dln_phi[i + 1], h, 0.5);
        // the midpoint's own estimated error bounds what we can claim
        let e = (p - m.ln_phi).abs();
        if m.err < 1e-6 {
            mid_err = mid_err.max(e);
        }
    }
    Ok(Tables {
        y0,
        ln_phi,
        dln_phi,
        node_err,
        mid_err,
        windows,
    })
}

/// Cubic Hermite on [0, 1] (t) with derivatives per unit y (cell width h).
#[inline(always)]
pub(crate) fn hermite(f0: f64, f1: f64, d0: f64, d1: f64, h: f64, t: f64) -> f64 {
    let hd0 = h * d0;
    let hd1 = h * d1;
    let df = f1 - f0;
    f0 + t * (hd0 + t * ((3.0 * df - 2.0 * hd0 - hd1) + t * (hd0 + hd1 - 2.0 * df)))
}

/// Derivative (per unit y) of the Hermite cubic.
#[inline(always)]
pub(crate) fn hermite_deriv(f0: f64, f1: f64, d0: f64, d1: f64, h: f64, t: f64) -> f64 {
    let hd0 = h * d0;
    let hd1 = h * d1;
    let df = f1 - f0;
    (hd0 + t * (2.0 * (3.0 * df - 2.0 * hd0 - hd1) + 3.0 * t * (hd0 + hd1 - 2.0 * df))) / h
}

/// 8-point Gauss-Legendre nodes and weights on [0, 1].
pub(crate) const GL8: [(f64, f64); 8] = [
    (0.019_855_071_751_231_856, 0.050_614_268_145_188_13),
    (0.101_666_761_293_186_63, 0.111_190_517_226_687_24),
    (0.237_233_795_041_835_5, 0.156_853_322_938_943_64),
    (0.408_282_678_752_175, 0.181_341_891_689_181),
    (0.591_717_321_247_825, 0.181_341_891_689_181),
    (0.762_766_204_958_164_5, 0.156_853_322_938_943_64),
    (0.898_333_238_706_813_4, 0.111_190_517_226_687_24),
    (0.980_144_928_248_768_1, 0.050_614_268_145_188_13),
];

/// ln((1/2pi) int over the cell of Phi(e^s) e^(2s) ds) from the interpolant.
pub(crate) fn ln_cell_mass(f0: f64, f1: f64, d0: f64, d1: f64, y_left: f64, h: f64) -> f64 {
    let vals: [f64; 8] = GL8.map(|(t, _)| hermite(f0, f1, d0, d1, h, t) + 2.0 * (y_left + t * h));
    let m = vals.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let s: f64 = GL8
        .iter()
        .zip(vals.iter())
        .map(|((_, w), v)| w * (v - m).exp())
        .sum();
    m + (s * h).ln() - LN_2PI
}

/// ln(e^a + e^b).
#[inline]
pub(crate) fn log_add(a: f64, b: f64) -> f64 {
    if a == f64::NEG_INFINITY {
        return b;
    }
    if b == f64::NEG_INFINITY {
        return a;
    }
    let m = a.max(b);
    m + ((a - m).exp() + (b - m).exp()).ln()
}

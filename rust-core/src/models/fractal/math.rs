//! Special functions private to the fractal profile: complex ln Gamma, real
//! digamma/trigamma, the Mellin transform of Phi_alpha and the two series.

use crate::special::{ln_gamma, LANCZOS_G7 as LANCZOS};
use num_complex::Complex64 as C64;

pub(crate) const LN_2: f64 = std::f64::consts::LN_2;
pub(crate) const LN_PI: f64 = 1.144_729_885_849_400_2;
pub(crate) const LN_2PI: f64 = 1.837_877_066_409_345_5;
pub(crate) const TWO_PI: f64 = std::f64::consts::TAU;

/// ln Gamma(z) for complex z off the non-positive real axis, modulo 2 pi i
/// (only exp of it is used). Upward recurrence to Re z >= 1.5, then Lanczos
/// (g = 7, n = 9), accurate to ~1e-15 relative in Gamma over the whole right
/// half-plane, large imaginary parts included.
pub(crate) fn ln_gamma_c(z: C64) -> C64 {
    let mut z = z;
    let mut acc = C64::new(0.0, 0.0);
    while z.re < 1.5 {
        acc -= z.ln();
        z += 1.0;
    }
    let x = z - 1.0;
    let mut a = C64::new(LANCZOS[0], 0.0);
    for (i, c) in LANCZOS.iter().enumerate().skip(1) {
        a += *c / (x + i as f64);
    }
    let t = x + 7.5;
    acc + 0.5 * LN_2PI + (x + 0.5) * t.ln() - t + a.ln()
}

/// Digamma for x > 0.
pub(crate) fn digamma(x: f64) -> f64 {
    let mut x = x;
    let mut r = 0.0;
    while x < 10.0 {
        r -= 1.0 / x;
        x += 1.0;
    }
    let x2 = 1.0 / (x * x);
    r + x.ln()
        - 0.5 / x
        - x2 * (1.0 / 12.0
            - x2 * (1.0 / 120.0 - x2 * (1.0 / 252.0 - x2 * (1.0 / 240.0 - x2 / 132.0))))
}

/// Trigamma for x > 0.
pub(crate) fn trigamma(x: f64) -> f64 {
    let mut x = x;
    let mut r = 0.0;
    while x < 10.0 {
        r += 1.0 / (x * x);
        x += 1.0;
    }
    let x2 = 1.0 / (x * x);
    r + 1.0 / x
        + 0.5 * x2
        + x2 / x * (1.0 / 6.0 - x2 * (1.0 / 30.0 - x2 * (1.0 / 42.0 - x2 / 30.0)))
}

/// ln M(z), M = Mellin transform of Phi_alpha:
/// M(z) = 2 pi 2^(z-1) Gamma(z/2) Gamma((2-z)/alpha) / (alpha Gamma(1 - z/2))
///      = pi 2^(z-1) Gamma(z/2) Gamma(1 + (2-z)/alpha) / Gamma(2 - z/2)
/// (second form: Gamma(w) = Gamma(w+1)/w on both ratios; (2-z)/alpha over
/// (2-z)/2 is 2/alpha; it removes the removable singularity at z = 2).
/// Valid for 0 < Re z < 2 + alpha.
pub(crate) fn ln_mellin(alpha: f64, z: C64) -> C64 {
    LN_PI + (z - 1.0) * LN_2 + ln_gamma_c(z * 0.5) + ln_gamma_c(1.0 + (2.0 - z) / alpha)
        - ln_gamma_c(2.0 - z * 0.5)
}

/// Real ln M(c) and its first two derivatives in c: the mean and the variance
/// of y = ln x under the weight Phi(e^y) e^(c y) (Legendre/saddle data).
pub(crate) fn ln_mellin_real(alpha: f64, c: f64) -> (f64, f64, f64) {
    let a = c * 0.5;
    let b = 1.0 + (2.0 - c) / alpha;
    let d = 2.0 - c * 0.5;
    let f = LN_PI + (c - 1.0) * LN_2 + ln_gamma(a) + ln_gamma(b) - ln_gamma(d);
    let f1 = LN_2 + 0.5 * digamma(a) - digamma(b) / alpha + 0.5 * digamma(d);
    let f2 = 0.25 * trigamma(a) + trigamma(b) / (alpha * alpha) - 0.25 * trigamma(d);
    (f, f1, f2)
}

/// sin(pi j alpha / 2), accurate in relative terms also for alpha near 2
/// (where the argument is near a multiple of pi) and near 0.
pub(crate) fn sin_half_pi(j: f64, alpha: f64) -> f64 {
    if alpha > 1.0 {
        // pi j alpha/2 = pi j - pi j eps/2 with eps = 2 - alpha exact.
        let eps = 2.0 - alpha;
        let s = (std::f64::consts::PI * j * eps * 0.5).sin();
        // sin(pi j - x) = -(-1)^j sin(x) ... = (-1)^(j+1) sin(x)
        if (j as i64) % 2 == 0 {
            -s
        } else {
            s
        }
    } else {
        (std::f64::consts::PI * j * alpha * 0.5).sin()
    }
}

/// Coefficients of the two series in log form.
/// Small x: Phi(x) = sum_n (-1)^n exp(small[n] + 2 n y), y = ln x.
/// Large x: Phi(x) = sum_{j>=1} large_sign[j-1] exp(large[j-1] - (j alpha + 2) y);
/// large_bound[j-1] >= large[j-1] is the same with |sin(pi j alpha/2)| replaced
/// by its bound j |sin(pi alpha/2)| (robust truncation decisions).
pub(crate) struct SeriesCoefs {
    pub small: Vec<f64>,
    pub large: Vec<f64>,
    pub large_sign: Vec<f64>,
    pub large_bound: Vec<f64>,
    /// ln of the term magnitudes with |sin| replaced by 1: the size of the
    /// remainder of the asymptotic series (alpha >= 1) after optimal
    /// truncation; near alpha = 2 the sines are O(2 - alpha) but the
    /// remainder (the near-Gaussian core) is not.
    pub large_nosin: Vec<f64>,
}

pub(crate) fn series_coefs(alpha: f64, n_small: usize, n_large: usize) -> SeriesCoefs {
    let base = (TWO_PI / alpha).ln();
    let small = (0..n_small)
        .map(|n| {
            let nf = n as f64;
            base + ln_gamma((2.0 * nf + 2.0) / alpha) - 2.0 * ln_gamma(nf + 1.0) - 2.0 * nf * LN_2
        })
        .collect();
    let s1 = sin_half_pi(1.0, alpha).abs();
    let mut large = Vec::with_capacity(n_large);
    let mut large_sign = Vec::with_capacity(n_large);
    let mut large_bound = Vec::with_capacity(n_large);
    let mut large_nosin = Vec::with_capacity(n_large);
    for j in 1..=n_large {
        let jf = j as f64;
        let common = 4f64.ln() + jf * alpha * LN_2 + 2.0 * ln_gamma(1.0 + jf * alpha * 0.5)
            - ln_gamma(jf + 1.0);
        let s = sin_half_pi(jf, alpha);
        // term = -4 (-1)^j / j! ... sin  => sign = -(-1)^j sign(sin)
        let parity = if j % 2 == 0 { -1.0 } else { 1.0 };
        large.push(if s == 0.0 {
            f64::NEG_INFINITY
        } else {
            common + s.abs().ln()
        });
        large_sign.push(parity * s.signum());
        large_bound.push(common + (jf * s1).ln());
        large_nosin.push(common);
    }
    SeriesCoefs {
        small,
        large,
        large_sign,
        large_bound,
        large_nosin,
    }
}

/// Complex digamma for Re z > 0.
pub(crate) fn digamma_c(z: C64) -> C64 {
    let mut z = z;
    let mut acc = C64::new(0.0, 0.0);
    while z.re < 10.0 {
        acc -= z.inv();
        z += 1.0;
    }
    let iz = z.inv();
    let x2 = iz * iz;
    acc + z.ln()
        - 0.5 * iz
        - x2 * (1.0 / 12.0
            - x2 * (1.0 / 120.0 - x2 * (1.0 / 252.0 - x2 * (1.0 / 240.0 - x2 / 132.0))))
}

/// Complex tetragamma psi''(z) for Re z > 0 (low accuracy is enough: it
/// multiplies a cubic correction).
pub(crate) fn tetragamma_c(z: C64) -> C64 {
    let mut z = z;
    let mut acc = C64::new(0.0, 0.0);
    while z.re < 10.0 {
        acc -= 2.0 * (z * z * z).inv();
        z += 1.0;
    }
    let iz = z.inv();
    let i2 = iz * iz;
    acc - i2 * (1.0 + iz * (1.0 + iz * (0.5 - i2 * (1.0 / 6.0 - i2 * (1.0 / 6.0 - 0.3 * i2)))))
}

/// ln Gamma(1 + (2-z)/alpha) - ln Gamma(2 - z/2) (the only alpha dependence
/// of ln M), accurate also when alpha is within rounding of 2: the two
/// arguments differ by d = (2-z)(2-alpha)/(2 alpha), and for small d the
/// difference is d psi(m) + d^3 psi''(m)/24 + O(d^5) around the midpoint m.
pub(crate) fn ln_gamma_ratio(alpha: f64, z: C64) -> C64 {
    let a = 1.0 + (2.0 - z) / alpha;
    let b = 2.0 - z * 0.5;
    let d = (2.0 - z) * ((2.0 - alpha) / (2.0 * alpha));
    if d.norm() < 1e-3 {
        let m = 0.5 * (a + b);
        d * digamma_c(m) + d * d * d * tetragamma_c(m) / 24.0
    } else {
        ln_gamma_c(a) - ln_gamma_c(b)
    }
}

/// ln M_2(z) = ln(pi 2^(z-1) Gamma(z/2)), the Gaussian's Mellin transform.
pub(crate) fn ln_mellin_gauss(z: C64) -> C64 {
    LN_PI + (z - 1.0) * LN_2 + ln_gamma_c(z * 0.5)
}

/// exp(z) - 1 without cancellation for small z.
pub(crate) fn expm1_c(z: C64) -> C64 {
    let (s, c) = z.im.sin_cos();
    let half = (0.5 * z.im).sin();
    C64::new(z.re.exp_m1() * c - 2.0 * half * half, z.re.exp() * s)
}

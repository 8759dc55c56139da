//! Special functions shared by the surface models.

const LOG2_E: f64 = std::f64::consts::LOG2_E;
/// ln 2 split so that n ln2_hi is exact for the n of the range reduction.
const LN2_HI: f64 = 6.931_471_803_691_238e-1;
const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;

/// e^r for the reduced argument |r| <= ln2/2: Taylor series of degree 9
/// (~2e-10) by Estrin's scheme with FMAs, a dependency chain of 5 operations
/// instead of Horner's 9 multiply-adds, which dominated the table lookups.
#[inline(always)]
fn exp_reduced(r: f64) -> f64 {
    let r2 = r * r;
    let r4 = r2 * r2;
    let r8 = r4 * r4;
    let p01 = r + 1.0;
    let p23 = r.mul_add(1.0 / 6.0, 0.5);
    let p45 = r.mul_add(1.0 / 120.0, 1.0 / 24.0);
    let p67 = r.mul_add(1.0 / 5040.0, 1.0 / 720.0);
    let p89 = r.mul_add(1.0 / 362880.0, 1.0 / 40320.0);
    let p03 = r2.mul_add(p23, p01);
    let p47 = r2.mul_add(p67, p45);
    r8.mul_add(p89, r4.mul_add(p47, p03))
}

/// exp(x) to about 2e-10 relative error, several times faster than libm's
/// exp because it skips the last-ulp work: the BRDF is returned as f32, so
/// 1e-9 is far below anything a caller can see. Underflows to 0 below
/// x = -708 and saturates to +inf above 709, like exp.
#[inline(always)]
pub fn fast_exp(x: f64) -> f64 {
    if !(x > -708.0) {
        return if x.is_nan() { f64::NAN } else { 0.0 };
    }
    if x > 709.0 {
        return f64::INFINITY;
    }
    let n = (x * LOG2_E).round();
    let r = (x - n * LN2_HI) - n * LN2_LO;
    let p = exp_reduced(r);
    // 2^n by building the exponent bits; n is in [-1022, 1023] here except at
    // the very bottom of the range, handled by splitting the scale.
    let ni = n as i64;
    if ni < -1020 {
        return p
            * f64::from_bits(((ni + 1023 + 60) as u64) << 52)
            * f64::from_bits((1023u64 - 60) << 52);
    }
    p * f64::from_bits(((ni + 1023) as u64) << 52)
}

/// `fast_exp` without branches or float-to-integer conversion, so that
/// loops over it vectorise: x is clamped to [-700, 700] (no underflow to 0,
/// no overflow; NaN is not handled) and 2^n comes from the integer bits of
/// x log2(e) + 1.5 * 2^52. Same polynomial and accuracy (2e-10).
#[inline(always)]
pub fn fast_exp_vectorisable(x: f64) -> f64 {
    const SHIFT: f64 = 6_755_399_441_055_744.0; // 1.5 * 2^52
    let x = x.clamp(-700.0, 700.0);
    // t = SHIFT + round(x log2 e): its low mantissa bits hold n.
    let t = x.mul_add(LOG2_E, SHIFT);
    let n = t - SHIFT;
    let r = (x - n * LN2_HI) - n * LN2_LO;
    let p = exp_reduced(r);
    // n + 1023 is in [1, 2046]: shifting the low bits of t's mantissa
    // (2^51 + n) plus 1023 left by 52 leaves exactly 2^n's exponent field.
    p * f64::from_bits(t.to_bits().wrapping_add(1023) << 52)
}

/// Taylor coefficients of sin r / r in r^2: (-1)^k / (2k + 1)!, k = 0..9
/// (the program version, `program::special::sin_squared`, takes k <= 6).
pub(crate) const SIN_OVER_X: [f64; 10] = [
    1.0,
    -1.0 / 6.0,
    1.0 / 120.0,
    -1.0 / 5_040.0,
    1.0 / 362_880.0,
    -1.0 / 39_916_800.0,
    1.0 / 6_227_020_800.0,
    -1.0 / 1_307_674_368_000.0,
    1.0 / 355_687_428_096_000.0,
    -1.0 / 121_645_100_408_832_000.0,
];

/// sin^2(x), branch-free so that loops over it vectorise (the grating
/// kernels take one per wavelength node). sin^2 has period pi: x is reduced
/// to r in [-pi/2, pi/2] (Cody-Waite with FMA, exact to ~1e-16 |x| / pi
/// absolute), then sin r is its odd Taylor polynomial of degree 19
/// (truncation below 3e-16). Absolute error below 1e-14 for |x| < 1e3 (test);
/// beyond |x| ~ 2^51 the reduction fails and the value is meaningless (so is
/// a double's x there), but it stays in [0, 1]. NaN gives NaN.
#[inline(always)]
pub fn sin_squared(x: f64) -> f64 {
    const SHIFT: f64 = 6_755_399_441_055_744.0; // 1.5 * 2^52
    const PI_HI: f64 = std::f64::consts::PI;
    const PI_LO: f64 = 1.224_646_799_147_353_2e-16;
    let n = x.mul_add(std::f64::consts::FRAC_1_PI, SHIFT) - SHIFT;
    let r = (-n).mul_add(PI_LO, (-n).mul_add(PI_HI, x));
    let r2 = r * r;

    let mut p = SIN_OVER_X[9];
    for &c in SIN_OVER_X[..9].iter().rev() {
        p = p.mul_add(r2, c);
    }
    let s = r * p;
    let s2 = s * s;
    // Not min(): that would turn NaN into 1.
    if s2 > 1.0 {
        1.0
    } else {
        s2
    }
}

/// Where sin^2 is checked against libm (here and as a program,
/// `program::special`): [-1000, 1000] in steps of 0.000731, and 0, -0, a
/// tiny value, pi / 2 and pi.
#[cfg(test)]
pub(crate) fn sin_squared_points() -> impl Iterator<Item = f64> {
    let sweep = (0..).map(|i| -1000.0 + i as f64 * 0.000_731);
    sweep.take_while(|&x| x <= 1000.0).chain([
        0.0,
        -0.0,
        1e-30,
        std::f64::consts::FRAC_PI_2,
        std::f64::consts::PI,
    ])
}

/// Lanczos coefficients for g = 7, n = 9 (~1e-15 relative in Gamma over the
/// right half-plane); shared by the real and complex ln Gamma.
pub const LANCZOS_G7: [f64; 9] = [
    0.999_999_999_999_809_9,
    676.520_368_121_885_1,
    -1_259.139_216_722_402_8,
    771.323_428_777_653_1,
    -176.615_029_162_140_6,
    12.507_343_278_686_905,
    -0.138_571_095_265_720_12,
    9.984_369_578_019_572e-6,
    1.505_632_735_149_311_6e-7,
];

/// ln Gamma(x) for x > 0 (Lanczos, g = 7, n = 9: ~1e-15 relative).
pub fn ln_gamma(x: f64) -> f64 {
    if x < 0.5 {
        // Reflection keeps the series in its accurate range.
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    const G: f64 = 7.0;
    let x = x - 1.0;
    let mut a = LANCZOS_G7[0];
    let t = x + G + 0.5;
    for (i, c) in LANCZOS_G7.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// ln(m!) for integer m >= 0; exact table for small m (the common case in the
/// Gaussian series), Lanczos beyond.
pub fn ln_factorial(m: u32) -> f64 {
    const TABLE_LEN: usize = 32;
    static TABLE: std::sync::OnceLock<[f64; TABLE_LEN]> = std::sync::OnceLock::new();
    let table = TABLE.get_or_init(|| {
        let mut t = [0.0; TABLE_LEN];
        for i in 1..TABLE_LEN {
            t[i] = t[i - 1] + (i as f64).ln();
        }
        t
    });
    if (m as usize) < TABLE_LEN {
        table[m as usize]
    } else {
        ln_gamma(m as f64 + 1.0)
    }
}

/// Final guard of every output: NaN or negative -> 0, +inf -> f64::MAX.
#[inline]
pub fn finite_non_negative(x: f64) -> f64 {
    if x > 0.0 {
        x.min(f64::MAX)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fast_exp_matches_libm() {
        let mut worst: f64 = 0.0;
        let mut x = -700.0;
        while x < 700.0 {
            let rel = (fast_exp(x) - x.exp()).abs() / x.exp();
            worst = worst.max(rel);
            x += 0.0137;
        }
        assert!(worst < 5e-10, "worst relative error {worst}");
        assert_eq!(fast_exp(-1000.0), 0.0);
        assert!(fast_exp(f64::NAN).is_nan());
        assert!(fast_exp(-707.9) > 0.0);
    }

    #[test]
    fn fast_exp_vectorisable_matches_libm() {
        let mut worst: f64 = 0.0;
        let mut x = -700.0;
        while x <= 700.0 {
            let rel = (fast_exp_vectorisable(x) - x.exp()).abs() / x.exp();
            worst = worst.max(rel);
            x += 0.0137;
        }
        for x in [
            -700.0,
            -1.0,
            -0.0,
            0.0,
            1e-300,
            0.5 * std::f64::consts::LN_2,
            700.0,
        ] {
            let rel = (fast_exp_vectorisable(x) - x.exp()).abs() / x.exp();
            worst = worst.max(rel);
        }
        assert!(worst < 5e-10, "worst relative error {worst}");
        assert_eq!(fast_exp_vectorisable(-1e9), fast_exp_vectorisable(-700.0));
        assert_eq!(fast_exp_vectorisable(1e9), fast_exp_vectorisable(700.0));
    }

    #[test]
    fn sin_squared_matches_libm() {
        let worst = sin_squared_points()
            .map(|x| (sin_squared(x) - x.sin().powi(2)).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-14, "worst absolute error {worst}");
        assert!(sin_squared(f64::NAN).is_nan());
        for x in [1e17, -3e300, f64::INFINITY] {
            let s = sin_squared(x);
            assert!(s.is_nan() || (0.0..=1.0).contains(&s), "{x}: {s}");
        }
    }

    #[test]
    fn ln_gamma_known_values() {
        assert!((ln_gamma(1.0)).abs() < 1e-14);
        assert!((ln_gamma(0.5) - std::f64::consts::PI.sqrt().ln()).abs() < 1e-13);
        assert!((ln_gamma(10.0) - 362880f64.ln()).abs() < 1e-12);
        assert!((ln_factorial(40) - ln_gamma(41.0)).abs() < 1e-10);
        let direct: f64 = (1..=20).map(|i| (i as f64).ln()).sum();
        assert!((ln_factorial(20) - direct).abs() < 1e-12);
    }
}

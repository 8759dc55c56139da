//! The core's branch-free special functions (`crate::special`) as program
//! operations, for f32 lanes: a few multiply-adds where the renderer's own
//! function would reduce its argument for sine and cosine both and select.

use super::Value;
use std::f64::consts::PI;

/// pi split for f32 (the leading part is pi rounded to f32, the second
/// the rest), so that n PI_HI is subtracted with one rounding by an FMA.
const PI_HI: f64 = std::f32::consts::PI as f64;
const PI_LO: f64 = PI - PI_HI;

/// sin^2(x) as `special::sin_squared`: sin^2 has period pi, so x is reduced
/// to r in [-pi/2, pi/2] (floor(x / pi + 1/2) periods, Cody-Waite with
/// FMAs), then sin r is its odd Taylor polynomial of degree 13
/// (truncation below 1e-9 on [-pi/2, pi/2]), squared. In f32 the error is
/// a few ulps of 1 for |x| up to ~1e3 (test), and like the renderer's sine
/// it loses all precision where f32 x has none left (|x| ~ 1e7); NaN and
/// infinities give NaN, as sin does.
pub fn sin_squared(x: Value<'_>) -> Value<'_> {
    let n = x.fma(1.0 / PI, 0.5).floor();
    let r = (-n).fma(PI_LO, (-n).fma(PI_HI, x));
    let r2 = r * r;
    // sin r / r in r^2, to k = 6.
    let c = &crate::special::SIN_OVER_X;
    let mut p = r2.fma(c[6], c[5]);
    for &ck in c[1..5].iter().rev() {
        p = p.fma(r2, ck);
    }
    let s = r * p.fma(r2, c[0]);
    s * s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::program::Builder;

    /// Against f64 sin^2 over [-1000, 1000] and at its special points, in
    /// f32 (the renderer's lanes): within a few ulps of 1 beyond the f32
    /// rounding of x itself, which moves sin^2 by up to |x| 2^-24.
    #[test]
    fn sin_squared_matches_libm_in_f32() {
        let b = Builder::new();
        let x = b.input();
        let program = b.finish(&[sin_squared(x)]);
        // At x rounded to f32, as the renderer's lanes hold it.
        let worst = crate::special::sin_squared_points()
            .map(|x| {
                let xf = x as f32;
                (program.run(&[xf])[0] as f64 - (xf as f64).sin().powi(2)).abs()
            })
            .fold(0.0, f64::max);
        println!("worst absolute error {worst:.2e}");
        assert!(worst < 1e-6, "worst absolute error {worst}");
        for x in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            assert!(program.run(&[x])[0].is_nan(), "{x}");
        }
    }
}

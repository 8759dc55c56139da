//! Tests of the fractal module. Every expected value comes from an
//! independent computation: closed forms (alpha = 1, 2), a direct quadrature
//! of the Hankel integral, the two series summed here from their definition,
//! or Beckmann's distribution.

use super::*;
use crate::special::ln_gamma;
use glam::DVec3;
use std::f64::consts::{PI, TAU};

// ---------- independent references ----------

/// Gauss-Legendre nodes/weights on [0, 1] by Newton on P_n.
fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 0.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let kf = k as f64;
                let p2 = ((2.0 * kf - 1.0) * x * p1 - (kf - 1.0) * p0) / kf;
                p0 = p1;
                p1 = p2;
            }
            dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
            let dx = p1 / dp;
            x -= dx;
            if dx.abs() < 1e-16 {
                break;
            }
        }
        let w = 2.0 / ((1.0 - x * x) * dp * dp);
        out.push((0.5 * (1.0 + x), 0.5 * w));
    }
    out
}

/// J0 by the trapezoidal rule on (1/pi) int_0^pi cos(z sin t) dt (exact to
/// rounding for enough points) below 25, Hankel's expansion above.
fn bessel_j0(z: f64) -> f64 {
    let z = z.abs();
    if z < 25.0 {
        let n = 64;
        let mut s = 0.0;
        for i in 0..n {
            let t = PI * (i as f64 + 0.5) / n as f64;
            s += (z * t.sin()).cos();
        }
        s / n as f64
    } else {
        // P ~ sum (-1)^k a_{2k} / z^{2k}, Q ~ sum (-1)^k a_{2k+1} / z^{2k+1},
        // a_k = prod_{m=1..k} (-(2m-1)^2) / (m 8)  (mu = 0)
        let mut p = 0.0;
        let mut q = 0.0;
        let mut term = 1.0;
        for k in 0..30 {
            if k > 0 {
                let m = k as f64;
                term *= -(2.0 * m - 1.0).powi(2) / (8.0 * m * z);
            }
            if k % 2 == 0 {
                p += if (k / 2) % 2 == 0 { term } else { -term };
            } else {
                q += if (k / 2) % 2 == 0 { term } else { -term };
            }
            if term.abs() < 1e-18 {
                break;
            }
        }
        let chi = z - PI / 4.0;
        (2.0 / (PI * z)).sqrt() * (p * chi.cos() - q * chi.sin())
    }
}

/// Phi_alpha(x) = 2 pi int_0^inf exp(-s^alpha) J0(x s) s ds by direct
/// quadrature: geometric panels towards s = 0 (the s^alpha singularity),
/// then panels between the zeros of J0(x s) (McMahon), Gauss-Legendre 24 on
/// each, and iterated averaging of the alternating partial sums.
fn phi_quadrature(alpha: f64, x: f64) -> f64 {
    let gl = gauss_legendre(24);
    let f = |s: f64| (-s.powf(alpha)).exp() * bessel_j0(x * s) * s;
    let panel = |a: f64, b: f64| -> f64 {
        gl.iter().map(|(t, w)| w * f(a + (b - a) * t)).sum::<f64>() * (b - a)
    };
    let zero = |k: usize| {
        let b = (k as f64 - 0.25) * PI;
        (b + 1.0 / (8.0 * b) - 124.0 / (3.0 * (8.0 * b).powi(3))) / x
    };
    // first panel up to the first zero (or up to where exp(-s^alpha) is tiny)
    let s_end = 60f64.powf(1.0 / alpha); // exp(-60)
    let b1 = zero(1).min(s_end);
    let mut sum = 0.0;
    let mut hi = b1;
    for _ in 0..80 {
        let lo = 0.5 * hi;
        sum += panel(lo, hi);
        hi = lo;
    }
    if b1 >= s_end {
        return TAU * sum;
    }
    let mut partial = vec![sum];
    let mut a = b1;
    let mut k = 1;
    while a < s_end && partial.len() < 600 {
        let b = zero(k + 1).min(s_end);
        // split long panels where exp(-s^alpha) varies quickly
        let m = 4;
        for i in 0..m {
            let lo = a + (b - a) * i as f64 / m as f64;
            let hi = a + (b - a) * (i + 1) as f64 / m as f64;
            sum += panel(lo, hi);
        }
        partial.push(sum);
        a = b;
        k += 1;
    }
    if a >= s_end {
        return TAU * sum;
    }
    // iterated averaging of the last partial sums
    let mut v: Vec<f64> = partial[partial.len() - 41..].to_vec();
    while v.len() > 1 {
        v = v.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect();
    }
    TAU * v[0]
}

/// Small-x series summed from its definition (log-magnitude terms).
fn phi_small_series(alpha: f64, x: f64, terms: usize) -> f64 {
    let mut s = 0.0;
    for n in 0..terms {
        let nf = n as f64;
        let l = (TAU / alpha).ln() + ln_gamma((2.0 * nf + 2.0) / alpha) - 2.0 * ln_gamma(nf + 1.0)
            + 2.0 * nf * (0.5 * x).ln();
        let t = l.exp();
        s += if n % 2 == 0 { t } else { -t };
    }
    s
}

/// Large-x series summed from its definition; for an asymptotic series
/// (alpha >= 1) it stops at the smallest sin-free term magnitude.
fn phi_large_series(alpha: f64, x: f64, terms: usize) -> f64 {
    let mut s = 0.0;
    let mut prev = f64::INFINITY;
    for j in 1..=terms {
        let jf = j as f64;
        let mag = (4f64.ln() + jf * alpha * 2f64.ln() + 2.0 * ln_gamma(1.0 + 0.5 * jf * alpha)
            - ln_gamma(jf + 1.0)
            - (jf * alpha + 2.0) * x.ln())
        .exp();
        if alpha >= 1.0 && mag > prev {
            break;
        }
        prev = mag;
        let sign = if j % 2 == 0 { -1.0 } else { 1.0 };
        // sin(pi j alpha / 2) with alpha = 2 - eps: (-1)^(j+1) sin(pi j eps / 2)
        let sn = if alpha > 1.0 {
            let v = (PI * jf * (2.0 - alpha) / 2.0).sin();
            if j % 2 == 0 {
                -v
            } else {
                v
            }
        } else {
            (PI * jf * alpha / 2.0).sin()
        };
        s += sign * mag * sn;
    }
    s
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

// ---------- Phi ----------

#[test]
fn closed_forms_alpha_1_and_2() {
    let p1 = StableProfile::new(1.0).unwrap();
    let p2 = StableProfile::new(2.0).unwrap();
    let (mut w1, mut w2, mut w2ln) = (0.0f64, 0.0f64, 0.0f64);
    let mut xs: Vec<f64> = vec![0.0];
    let mut x = 1e-6;
    while x <= 1e3 {
        xs.push(x);
        x *= 1.013;
    }
    xs.push(1e3);
    for &x in &xs {
        let e1 = TAU / (1.0 + x * x).powf(1.5);
        w1 = w1.max(rel(p1.phi(x), e1));
        let e2 = PI * (-x * x / 4.0).exp();
        if e2 > 1e-300 {
            w2 = w2.max(rel(p2.phi(x), e2));
        }
        w2ln = w2ln.max((p2.ln_phi(x) - (PI.ln() - x * x / 4.0)).abs() / (1.0 + x * x));
    }
    println!("Phi_1 worst rel {w1:.2e}; Phi_2 worst rel {w2:.2e}; Phi_2 ln (scaled) {w2ln:.2e}");
    assert!(w1 < 1e-6, "{w1}");
    assert!(w2 < 1e-12, "{w2}");
    assert!(w2ln < 1e-14);
}

#[test]
fn against_hankel_quadrature() {
    let xs = [0.0, 0.05, 0.3, 1.0, 2.0, 4.0, 7.0];
    let mut worst_all = 0.0f64;
    for &alpha in &[0.3, 0.7, 1.4, 1.8, 1.998] {
        let p = StableProfile::new(alpha).unwrap();
        let mut worst = 0.0f64;
        for &x in &xs {
            let q = if x == 0.0 {
                TAU * ln_gamma(2.0 / alpha).exp() / alpha
            } else {
                phi_quadrature(alpha, x)
            };
            let e = rel(p.phi(x), q);
            worst = worst.max(e);
        }
        println!("alpha {alpha}: worst rel vs Hankel quadrature {worst:.2e}");
        worst_all = worst_all.max(worst);
    }
    assert!(worst_all < 1e-6, "{worst_all}");
}

#[test]
fn quadrature_reference_is_sane() {
    // the oracle itself against the closed forms
    for &x in &[0.05, 0.3, 1.0, 2.0, 4.0, 7.0] {
        let e1 = rel(phi_quadrature(1.0, x), TAU / (1.0 + x * x).powf(1.5));
        let e2 = rel(phi_quadrature(2.0, x), PI * (-x * x / 4.0).exp());
        assert!(e1 < 1e-8 && e2 < 1e-8, "x {x}: {e1} {e2}");
    }
}

#[test]
fn against_convergent_series() {
    // large-x series converges for alpha < 1, small-x for alpha > 1
    let mut worst = 0.0f64;
    for &alpha in &[0.3, 0.7] {
        let p = StableProfile::new(alpha).unwrap();
        let mut x = 0.5;
        while x < 1e6 {
            let s = phi_large_series(alpha, x, 120);
            worst = worst.max(rel(p.phi(x), s));
            x *= 1.05;
        }
    }
    for &alpha in &[1.4, 1.8] {
        let p = StableProfile::new(alpha).unwrap();
        let mut x = 1e-6;
        while x < 3.0 {
            let s = phi_small_series(alpha, x, 80);
            worst = worst.max(rel(p.phi(x), s));
            x *= 1.05;
        }
    }
    println!("worst rel vs convergent series {worst:.2e}");
    assert!(worst < 1e-6, "{worst}");
}

#[test]
fn near_two_is_gaussian_plus_tail() {
    // alpha = 2 - eps: Phi = pi exp(-x^2/4) + tail, error O(eps poly(x)).
    for &eps in &[1e-10, 1e-13] {
        let alpha = 2.0 - eps;
        let p = StableProfile::new(alpha).unwrap();
        let mut worst = 0.0f64;
        let mut x = 0.0;
        while x < 60.0 {
            // first two tail terms (the series is asymptotic; fine for x >= 8)
            let tail = if x >= 8.0 {
                phi_large_series(alpha, x, 60)
            } else {
                0.0
            };
            let r = (PI * (-x * x / 4.0).exp() + tail).ln();
            worst = worst.max((p.ln_phi(x) - r).abs());
            x += 0.01;
        }
        println!("alpha = 2 - {eps:e}: worst |ln Phi - ln(Gauss + tail)| {worst:.2e}");
        assert!(worst < 1e-4, "{worst}");
    }
}

#[test]
fn normalisation_by_direct_sum() {
    // int_0^inf Phi x dx = 2 pi: trapezoid in y = ln x on ln_phi (smooth
    // integrand, exponentially convergent), analytic tails beyond.
    let mut worst = 0.0f64;
    for &alpha in &[0.1, 0.3, 0.7, 1.0, 1.4, 1.8, 1.998] {
        let p = StableProfile::new(alpha).unwrap();
        let d = p.diagnostics();
        let (ya, yb) = (d.y_min - 30.0, d.y_max + 40.0 / alpha);
        let n = 400_000;
        let h = (yb - ya) / n as f64;
        let mut s = 0.0;
        for i in 0..=n {
            let y = ya + i as f64 * h;
            let w = if i == 0 || i == n { 0.5 } else { 1.0 };
            s += w * (p.ln_phi_at_ln(y) + 2.0 * y).exp();
        }
        s *= h;
        // left tail: Phi(0) x^2/2; right tail: C1 x^-alpha / alpha
        s += (p.ln_phi_zero() + 2.0 * ya).exp() / 2.0;
        let c1 = 4.0
            * 2f64.powf(alpha)
            * ln_gamma(1.0 + alpha / 2.0).exp().powi(2)
            * (PI * alpha / 2.0).sin();
        s += c1 * (-alpha * yb).exp() / alpha;
        let e = rel(s, TAU);
        println!(
            "alpha {alpha}: int Phi x dx / 2pi - 1 = {:.2e}",
            s / TAU - 1.0
        );
        worst = worst.max(e);
    }
    assert!(worst < 1e-6, "{worst}");
}

#[test]
fn continuity_at_switch_points_and_table_accuracy() {
    let mut worst_jump = 0.0f64;
    let mut worst_djump = 0.0f64;
    for &alpha in &[
        0.002,
        0.01,
        0.1,
        0.3,
        0.7,
        0.99,
        1.0,
        1.4,
        1.8,
        1.998,
        2.0 - 1e-9,
    ] {
        let p = StableProfile::new(alpha).unwrap();
        let d = p.diagnostics();
        for y in [d.y_min, d.y_max] {
            let e = 1e-9 * (1.0 + y.abs());
            // change across the switch minus the smooth change 2 e f'
            let jump =
                (p.ln_phi_at_ln(y + e) - p.ln_phi_at_ln(y - e) - 2.0 * e * p.dln_phi_at_ln(y))
                    .abs();
            let dj = (p.dln_phi_at_ln(y - 1e-4) - p.dln_phi_at_ln(y + 1e-4)).abs();
            worst_jump = worst_jump.max(jump);
            worst_djump = worst_djump.max(dj);
        }
        println!(
            "alpha {alpha}: node err {:.1e}, midpoint err {:.1e}, cdf+ccdf-1 {:.1e}, {} nodes, {} FFTs, y in [{:.1}, {:.1}]",
            d.node_error, d.midpoint_error, d.normalisation_error, d.nodes, d.fft_windows, d.y_min, d.y_max
        );
        assert!(d.midpoint_error < 2e-7 && d.node_error < 1e-9 && d.normalisation_error < 1e-7);
    }
    println!("worst jump in ln Phi at switch points {worst_jump:.2e}, in d ln Phi/d ln x {worst_djump:.2e}");
    assert!(worst_jump < 1e-7 && worst_djump < 1e-3);
}

#[test]
fn extreme_alpha_finite_and_monotone() {
    for &alpha in &[0.002, 0.01, 1.998, 2.0 - 1e-15, 2.0] {
        let p = StableProfile::new(alpha).unwrap();
        let mut prev = f64::INFINITY;
        let mut y = -1e4;
        while y < 1e4 {
            let l = p.ln_phi_at_ln(y);
            assert!(!l.is_nan() && l < f64::INFINITY, "alpha {alpha} y {y}: {l}");
            assert!(
                l == f64::NEG_INFINITY || l <= prev + 1e-9 * (1.0 + l.abs()),
                "not decreasing at alpha {alpha}, y {y}"
            );
            prev = l;
            y += 0.37;
        }
        assert!(p.ln_phi(0.0).is_finite());
        assert_eq!(p.ln_phi(f64::INFINITY), f64::NEG_INFINITY);
    }
}

// ---------- cdf ----------

#[test]
fn radial_cdf_round_trip() {
    let mut worst_p = 0.0f64;
    let mut worst_ln = 0.0f64;
    for &alpha in &[0.002, 0.1, 0.7, 1.0, 1.4, 1.998, 2.0] {
        let p = StableProfile::new(alpha).unwrap();
        let mut probs: Vec<f64> = (1..1000).map(|i| i as f64 / 1000.0).collect();
        probs.extend([
            1e-300,
            1e-100,
            1e-12,
            1e-6,
            0.5,
            1.0 - 1e-6,
            1.0 - 1e-12,
            1.0 - 1e-16,
        ]);
        for &pr in &probs {
            let y = p.inverse_radial_cdf_ln(pr);
            assert!(y.is_finite(), "alpha {alpha} p {pr}");
            let (lc, lcc) = p.ln_radial_cdf_pair(y);
            let back = if pr <= 0.5 {
                (lc - pr.ln()).abs()
            } else {
                (lcc - (-pr).ln_1p()).abs()
            };
            worst_ln = worst_ln.max(back);
            if (1e-300..=1.0).contains(&pr) && alpha > 0.01 {
                let x = p.inverse_radial_cdf(pr);
                worst_p = worst_p.max((p.radial_cdf(x) - pr).abs());
            }
        }
        // tail: ccdf inverse
        for &q in &[1e-30, 1e-8, 0.3] {
            let y = p.inverse_radial_ccdf_ln(q);
            worst_ln = worst_ln.max((p.ln_radial_cdf_pair(y).1 - q.ln()).abs());
        }
        // monotone cdf
        let mut prev = -1.0;
        let mut x = 1e-3;
        while x < 1e3 {
            let c = p.radial_cdf(x);
            assert!(
                (0.0..=1.0).contains(&c) && c >= prev - 1e-15,
                "alpha {alpha} x {x}"
            );
            prev = c;
            x *= 1.1;
        }
    }
    println!(
        "cdf round trip: worst |p' - p| {worst_p:.2e}, worst in ln p or ln(1-p) {worst_ln:.2e}"
    );
    assert!(worst_p < 1e-7 && worst_ln < 1e-9);
}

#[test]
fn radial_cdf_against_closed_forms() {
    // alpha = 1: cdf = 1 - 1/sqrt(1+x^2); alpha = 2: 1 - exp(-x^2/4)
    let p1 = StableProfile::new(1.0).unwrap();
    let p2 = StableProfile::new(2.0).unwrap();
    let mut w = 0.0f64;
    let mut x = 1e-4;
    while x < 1e4 {
        w = w.max((p1.radial_cdf(x) - (1.0 - 1.0 / (1.0 + x * x).sqrt())).abs());
        w = w.max(rel(p1.radial_ccdf(x), 1.0 / (1.0 + x * x).sqrt()));
        w = w.max((p2.radial_cdf(x) - (1.0 - (-x * x / 4.0).exp())).abs());
        x *= 1.07;
    }
    println!("radial cdf vs closed forms (alpha 1, 2): worst {w:.2e}");
    assert!(w < 1e-7, "{w}");
}

// ---------- kernel ----------

fn geom(theta_i: f64, phi_i: f64, theta_o: f64, phi_o: f64) -> PairGeometry {
    let d = |t: f64, p: f64| DVec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos());
    PairGeometry::new(d(theta_i, phi_i), d(theta_o, phi_o)).unwrap()
}

#[test]
fn hurst_one_is_beckmann() {
    // H = 1: D(r) = sigma^2 r^2 / lag^2, slope variance per axis sigma^2/lag^2
    // = alpha_b^2 / 2, so alpha_b = sqrt(2) sigma / lag and
    // G K = D_Beckmann(theta_h) / (4 cos_i cos_o).
    let mut worst = 0.0f64;
    for &(sigma, lag) in &[(0.1, 1.0), (0.05, 2.0), (1.0, 3.0)] {
        let s = FractalSurface::new(1.0, sigma, lag).unwrap();
        let ab2 = 2.0 * sigma * sigma / (lag * lag);
        for &(ti, to, po) in &[
            (0.1, 0.1, PI),
            (0.5, 0.3, 2.0),
            (1.2, 0.4, 0.5),
            (0.3, 0.35, 3.0),
        ] {
            let g = geom(ti, 0.0, to, po);
            let k = TAU / 0.55;
            let hv = DVec3::new(-g.u, -g.v, -g.w).normalize();
            let cos_h = hv.z;
            let tan2 = (1.0 - cos_h * cos_h) / (cos_h * cos_h);
            let d = (-tan2 / ab2).exp() / (PI * ab2 * cos_h.powi(4));
            let expect = d / (4.0 * g.cos_i * g.cos_o);
            let got = g.geometric_factor * s.kernel(k, &g);
            if expect > 1e-250 {
                worst = worst.max(rel(got, expect));
            }
        }
    }
    println!("H = 1 vs Beckmann: worst rel {worst:.2e}");
    assert!(worst < 1e-9, "{worst}");
}

#[test]
fn kernel_integrates_to_inverse_w_squared() {
    // int K du dv over the plane = 1 / w^2 at fixed (k, w) (K as a function
    // of (u, v) with w held fixed): checks the scaling of the kernel.
    let mut worst = 0.0f64;
    for &(h, sigma, lag) in &[(0.35, 0.05, 1.0), (0.7, 0.2, 3.0), (0.95, 0.02, 0.5)] {
        let s = FractalSurface::new(h, sigma, lag).unwrap();
        let w = -1.7;
        let k = TAU / 0.6;
        // polar: int K 2 pi r dr = int K 2 pi r^2 d ln r
        let n = 200_000;
        let (la, lb) = (-40.0f64, 40.0 / (2.0 * h) + 20.0);
        let dl = (lb - la) / n as f64;
        let mut sum = 0.0;
        for i in 0..=n {
            let lr = la + i as f64 * dl;
            let r = lr.exp();
            let g = PairGeometry {
                u: r,
                v: 0.0,
                w,
                cos_i: 0.85,
                cos_o: 0.85,
                geometric_factor: 1.0,
                cos_half: 1.0,
                wi: DVec3::Z,
                wo: DVec3::Z,
            };
            let wgt = if i == 0 || i == n { 0.5 } else { 1.0 };
            sum += wgt * s.kernel(k, &g) * TAU * r * r;
        }
        sum *= dl;
        worst = worst.max(rel(sum, 1.0 / (w * w)));
    }
    println!("int K du dv vs 1/w^2: worst rel {worst:.2e}");
    assert!(worst < 1e-5, "{worst}");
}

#[test]
fn projected_scale_matches_kernel() {
    // p(u, v) = s^2 Phi(s r)/(4 pi^2) = w^2 K with s = k * projected_scale
    let s = FractalSurface::new(0.6, 0.1, 2.0).unwrap();
    let g = geom(0.4, 0.0, 0.7, 2.5);
    let k = TAU / 0.45;
    let sc = k * s.projected_scale(k, g.w);
    let r = (g.u * g.u + g.v * g.v).sqrt();
    let p = sc * sc * s.profile.phi(sc * r) / (4.0 * PI * PI);
    assert!(rel(p, g.w * g.w * s.kernel(k, &g)) < 1e-12);
}

#[test]
fn kernel_finite_for_extreme_inputs() {
    let hs = [1e-3, 0.01, 0.3, 0.5, 0.999, 1.0];
    let sigmas = [1e-5, 1e-2, 1.0, 50.0];
    let lags = [0.01, 1.0, 1e4];
    let ks = [
        0.0,
        1e-300,
        1e-8,
        1e-3,
        12.0,
        1e6,
        1e200,
        f64::INFINITY,
        f64::NAN,
    ];
    let cs: [f64; 4] = [1e-8, 1e-4, 0.3, 1.0];
    let mut n = 0;
    let mut nonzero = 0;
    for &h in &hs {
        for &sg in &sigmas {
            for &lag in &lags {
                let s = FractalSurface::new(h, sg, lag).unwrap();
                for &k in &ks {
                    for &ci in &cs {
                        for &co in &cs {
                            for &phi in &[0.0, PI, 1.0] {
                                let ti = ci.acos();
                                let to = co.acos();
                                let wi = DVec3::new(ti.sin(), 0.0, ci);
                                let wo = DVec3::new(to.sin() * phi.cos(), to.sin() * phi.sin(), co);
                                let Some(g) = PairGeometry::new(wi, wo) else {
                                    continue;
                                };
                                let v = s.kernel(k, &g);
                                assert!(
                                    v.is_finite() && v >= 0.0,
                                    "h {h} s {sg} lag {lag} k {k} ci {ci} co {co}: {v}"
                                );
                                n += 1;
                                if v > 0.0 {
                                    nonzero += 1;
                                }
                            }
                        }
                    }
                }
                // u = v = 0 exactly
                let g = PairGeometry {
                    u: 0.0,
                    v: 0.0,
                    w: -2e-12,
                    cos_i: 1e-12,
                    cos_o: 1e-12,
                    geometric_factor: 4e24,
                    cos_half: 1.0,
                    wi: DVec3::Z,
                    wo: DVec3::Z,
                };
                assert!(s.kernel(12.0, &g).is_finite());
            }
        }
    }
    println!("{n} extreme kernel evaluations finite ({nonzero} non-zero)");
    assert!(FractalSurface::new(f64::NAN, 1.0, 1.0)
        .unwrap_err()
        .contains("hurst"));
    assert!(FractalSurface::new(0.5, 0.0, 1.0)
        .unwrap_err()
        .contains("sigma"));
    assert!(FractalSurface::new(0.5, 1.0, -1.0)
        .unwrap_err()
        .contains("lag"));
    assert!(FractalSurface::new(0.5, 1.0, f64::INFINITY)
        .unwrap_err()
        .contains("lag"));
}

#[test]
fn construction_time_memory_and_speed() {
    for &alpha in &[0.002, 0.1, 0.7, 1.4, 1.8, 1.998, 2.0 - 1e-12] {
        let t = std::time::Instant::now();
        let p = StableProfile::new_uncached(alpha).unwrap();
        let el = t.elapsed();
        println!(
            "alpha {alpha}: build {:.1} ms, {} bytes, {} nodes",
            el.as_secs_f64() * 1e3,
            p.memory_bytes(),
            p.diagnostics().nodes
        );
        assert!(p.memory_bytes() < 1 << 20);
    }
    let s = FractalSurface::new(0.7, 0.1, 2.0).unwrap();
    let gs: Vec<PairGeometry> = (0..1024)
        .map(|i| {
            geom(
                0.1 + 1.3 * (i as f64 * 0.618).fract(),
                0.0,
                0.05 + 1.4 * (i as f64 * 0.377).fract(),
                6.0 * (i as f64 * 0.71).fract(),
            )
        })
        .collect();
    let t = std::time::Instant::now();
    let mut acc = 0.0;
    let reps = 2000;
    for r in 0..reps {
        let k = 8.0 + (r % 16) as f64 * 0.5;
        for g in &gs {
            acc += s.kernel(k, g);
        }
    }
    let ns = t.elapsed().as_secs_f64() * 1e9 / (reps * gs.len()) as f64;
    println!("kernel: {ns:.1} ns per call (checksum {acc:.3e})");
}

#[test]
fn micro_timings() {
    use std::hint::black_box;
    let n = 4_000_000;
    let xs: Vec<f64> = (0..1024)
        .map(|i| 0.5 + (i as f64 * 0.618).fract())
        .collect();
    macro_rules! time {
        ($name:expr, $f:expr) => {{
            let t = std::time::Instant::now();
            let mut acc = 0.0;
            for i in 0..n {
                acc += $f(black_box(xs[i & 1023]));
            }
            black_box(acc);
            println!(
                "{}: {:.1} ns",
                $name,
                t.elapsed().as_secs_f64() * 1e9 / n as f64
            );
        }};
    }
    time!("empty", |x: f64| x);
    time!("ln", |x: f64| x.ln());
    time!("exp", |x: f64| x.exp());
    time!("ln_1p", |x: f64| x.ln_1p());
    time!("fast_exp", |x: f64| crate::special::fast_exp(x));
    let p = StableProfile::new(1.4).unwrap();
    let d = p.diagnostics();
    time!("table", |x: f64| p.ln_phi_at_ln(
        d.y_min + (x - 0.5) * (d.y_max - d.y_min) * 0.99
    ));
    time!("small", |x: f64| p.ln_phi_at_ln(d.y_min - 3.0 * x));
    time!("tail", |x: f64| p.ln_phi_at_ln(d.y_max + 3.0 * x));
    let sf = FractalSurface::new(0.7, 0.1, 2.0).unwrap();
    let g = geom(0.3, 0.0, 0.5, 2.0);
    time!("kernel", |x: f64| sf.kernel(8.0 + x, &g));
    let g = geom(0.3, 0.0, 0.32, 3.0);
    time!("kernel near specular", |x: f64| sf.kernel(8.0 + x, &g));
}

/// Hurst exponents within a hair of 0 are refused at once with a message
/// naming the range (the parameter range starts at 1e-3), and its lower end
/// builds; nothing panics (the fuzz test once found an index overflow at
/// hurst = 1e-34 in debug builds, and hurst = 1e-4 took minutes to fail).
#[test]
fn hurst_near_zero_builds_or_refuses_cleanly() {
    let json = |hurst: f64| {
        format!(r#"{{"surface":"fractal","hurst":{hurst:e},"sigma_um":0.1,"lag_um":1}}"#)
    };
    let brdf = crate::Brdf::from_json(&json(1e-3)).expect("hurst 1e-3");
    let wi = glam::DVec3::new(0.6, 0.0, 0.8);
    let wo = glam::DVec3::new(-0.5, 0.1, 0.86).normalize();
    let f = brdf.eval_spectral(wi, wo, 550.0);
    assert!(f.is_finite() && f >= 0.0, "{f}");
    for hurst in [9.99e-4, 1e-4, 1e-6, 1e-12, 1e-34, 1e-300] {
        let e = crate::Brdf::from_json(&json(hurst)).err().expect("refused");
        assert!(e.to_string().contains("'hurst'"), "{e}");
    }
}

/// The RGB path's shared-logarithm kernel equals the per-wavenumber kernel
/// (to the fast exp's 2e-10), over random pairs and several Hurst exponents.
#[test]
fn kernel_at_wavenumbers_matches_kernel() {
    let ks: Vec<f64> = (0..12)
        .map(|j| 2.0 * PI / (0.38 + 0.035 * j as f64))
        .collect();
    let ln_ks: Vec<f64> = ks.iter().map(|k| k.ln()).collect();
    let mut state = 11u64;
    let mut next = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut worst: f64 = 0.0;
    for hurst in [0.3, 0.7, 1.0] {
        let s = FractalSurface::new(hurst, 0.1, 1.0).unwrap();
        for _ in 0..500 {
            let wi = DVec3::new(next() - 0.5, next() - 0.5, next() + 0.05).normalize();
            let wo = DVec3::new(next() - 0.5, next() - 0.5, next() + 0.05).normalize();
            let Some(geom) = PairGeometry::new(wi, wo) else {
                continue;
            };
            let mut out = [0.0; 12];
            s.kernel_at_wavenumbers(&ks, &ln_ks, &geom, &mut out);
            for (o, &k) in out.iter().zip(&ks) {
                let direct = s.kernel(k, &geom);
                let rel = (o - direct).abs() / direct.max(1e-300);
                worst = worst.max(if direct > 1e-290 { rel } else { 0.0 });
            }
        }
    }
    println!("kernel_at_wavenumbers: worst relative difference {worst:.2e}");
    assert!(worst < 1e-8, "{worst}");
}

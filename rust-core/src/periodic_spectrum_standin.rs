//! TEMPORARY stand-in for crate::spectrum (contract only), analytic CMF fit
//! (Wyman et al. 2013), flat illuminant. Not for commit.
#![allow(dead_code, clippy::all)]
use std::f64::consts::PI;
use std::sync::OnceLock;

pub const LAMBDA_MIN_NM: f64 = 360.0;
pub const LAMBDA_MAX_NM: f64 = 830.0;

fn g(x: f64, mu: f64, s1: f64, s2: f64) -> f64 {
    let t = (x - mu) / if x < mu { s1 } else { s2 };
    (-0.5 * t * t).exp()
}
fn raw(l: f64) -> [f64; 3] {
    let x = 1.056 * g(l, 599.8, 37.9, 31.0) + 0.362 * g(l, 442.0, 16.0, 26.7)
        - 0.065 * g(l, 501.1, 20.4, 26.2);
    let y = 0.821 * g(l, 568.8, 46.9, 40.5) + 0.286 * g(l, 530.9, 16.3, 31.1);
    let z = 1.217 * g(l, 437.0, 11.8, 36.0) + 0.681 * g(l, 459.0, 26.0, 13.8);
    let r = 3.2406 * x - 1.5372 * y - 0.4986 * z;
    let gg = -0.9689 * x + 1.8758 * y + 0.0415 * z;
    let b = 0.0557 * x - 0.2040 * y + 1.0570 * z;
    [r, gg, b]
}
fn norm() -> &'static [f64; 3] {
    static N: OnceLock<[f64; 3]> = OnceLock::new();
    N.get_or_init(|| {
        let mut s = [0.0; 3];
        let n = 47000;
        let h = (LAMBDA_MAX_NM - LAMBDA_MIN_NM) / n as f64;
        for i in 0..=n {
            let w = if i == 0 || i == n { 0.5 } else { 1.0 };
            let v = raw(LAMBDA_MIN_NM + i as f64 * h);
            for c in 0..3 {
                s[c] += w * h * v[c];
            }
        }
        s
    })
}
pub fn srgb_weight_per_nm(l: f64) -> [f64; 3] {
    if !(l >= LAMBDA_MIN_NM && l <= LAMBDA_MAX_NM) {
        return [0.0; 3];
    }
    let r = raw(l);
    let n = norm();
    [r[0] / n[0], r[1] / n[1], r[2] / n[2]]
}
pub fn srgb_weight_per_wavenumber(nu: f64) -> [f64; 3] {
    let w = srgb_weight_per_nm(1000.0 / nu);
    let j = 1000.0 / (nu * nu);
    [w[0] * j, w[1] * j, w[2] * j]
}
pub fn integrate_rgb_reference(f: impl Fn(f64) -> f64, step_nm: f64) -> [f64; 3] {
    let n = ((LAMBDA_MAX_NM - LAMBDA_MIN_NM) / step_nm).round() as usize;
    let h = (LAMBDA_MAX_NM - LAMBDA_MIN_NM) / n as f64;
    let mut s = [0.0; 3];
    for i in 0..=n {
        let l = LAMBDA_MIN_NM + i as f64 * h;
        let wt = if i == 0 || i == n { 0.5 } else { 1.0 };
        let fv = f(l);
        let w = srgb_weight_per_nm(l);
        for c in 0..3 {
            s[c] += wt * h * fv * w[c];
        }
    }
    s
}
pub struct SmoothRule {
    pub nu_per_um: Vec<f64>,
    pub lambda_nm: Vec<f64>,
    pub weights: Vec<[f64; 3]>,
}
pub fn smooth_rule(k: usize) -> &'static SmoothRule {
    static R: OnceLock<std::sync::Mutex<Vec<(usize, &'static SmoothRule)>>> = OnceLock::new();
    let m = R.get_or_init(|| std::sync::Mutex::new(Vec::new()));
    let mut g = m.lock().unwrap();
    if let Some((_, r)) = g.iter().find(|(n, _)| *n == k) {
        return r;
    }
    // Gauss-Legendre in nu on the band via Golub-Welsch-free Newton iteration.
    let a = 1000.0 / LAMBDA_MAX_NM;
    let b = 1000.0 / LAMBDA_MIN_NM;
    let mut nu = vec![];
    let mut lam = vec![];
    let mut wts = vec![];
    for i in 0..k {
        let mut x = (PI * (i as f64 + 0.75) / (k as f64 + 0.5)).cos();
        let mut dp = 0.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, x);
            for j in 2..=k {
                let p2 = ((2 * j - 1) as f64 * x * p1 - (j - 1) as f64 * p0) / j as f64;
                p0 = p1;
                p1 = p2;
            }
            dp = k as f64 * (x * p1 - p0) / (x * x - 1.0);
            let dx = p1 / dp;
            x -= dx;
            if dx.abs() < 1e-15 {
                break;
            }
        }
        let w = 2.0 / ((1.0 - x * x) * dp * dp);
        let n = 0.5 * (a + b) + 0.5 * (b - a) * x;
        let ww = srgb_weight_per_wavenumber(n);
        nu.push(n);
        lam.push(1000.0 / n);
        wts.push([
            ww[0] * w * 0.5 * (b - a),
            ww[1] * w * 0.5 * (b - a),
            ww[2] * w * 0.5 * (b - a),
        ]);
    }
    let r: &'static SmoothRule = Box::leak(Box::new(SmoothRule {
        nu_per_um: nu,
        lambda_nm: lam,
        weights: wts,
    }));
    g.push((k, r));
    r
}
pub fn gaussian_moments(mu: f64, s: f64) -> [[f64; 3]; 3] {
    let a0 = 1000.0 / LAMBDA_MAX_NM;
    let b0 = 1000.0 / LAMBDA_MIN_NM;
    let a = (mu - 14.0 * s).max(a0);
    let b = (mu + 14.0 * s).min(b0);
    let mut m = [[0.0; 3]; 3];
    if !(b > a) {
        return m;
    }
    let n = 4000;
    let h = (b - a) / n as f64;
    for i in 0..=n {
        let nu = a + i as f64 * h;
        let wt = if i == 0 || i == n {
            1.0
        } else if i % 2 == 1 {
            4.0
        } else {
            2.0
        } * h
            / 3.0;
        let d = nu - mu;
        let gg = (-0.5 * d * d / (s * s)).exp();
        let w = srgb_weight_per_wavenumber(nu);
        for c in 0..3 {
            m[0][c] += wt * gg * w[c];
            m[1][c] += wt * gg * d * w[c];
            m[2][c] += wt * gg * d * d * w[c];
        }
    }
    m
}

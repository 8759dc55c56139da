//! Periodic profiles (1-D, extruded along y) under a Gaussian coherence
//! window W(x, y) = exp(-(x^2 + y^2) / (2 l^2)), for which
//! <|P|^2> / A with A = int W^2 is the quantity of physics.md (the window's
//! |W^|^2 / int W^2 = 4 pi l^2 exp(-l^2 q^2)). Deterministic: one field.
//!
//! The field p(x, y) = W(x, y) exp(i a h(x)) is separable, so its 2-D DFT is
//! the product of two 1-D DFTs: X(qx) of W_x(x) exp(i a h(x)) (sampled with
//! M points per period, edges of the rect profile between samples) and Y(qy)
//! of W_y(y). Sampling a profile with M points per period errs by O(M^-2)
//! (for the rect profile the sampled coefficients are larger by
//! (pi n / M)^2 / 3 at order n), so the ground truth is the Richardson
//! extrapolation (4 GT(2M) - GT(M)) / 3 and its error estimate
//! |GT(2M) - GT(M)| / 3 (the size of the correction at 2M, a bound on what
//! is left after extrapolation).

use crate::optics::{self, Pair};
use glam::DVec3;
use num_complex::Complex64;
use rustfft::FftPlanner;
use std::f64::consts::PI;
use std::time::Instant;

#[derive(Clone, Debug)]
pub enum ProfileKind {
    /// Bump of height b over [0, d) of each period.
    Rect { height: f64, width: f64 },
    /// h = (b / 2) (1 + cos(2 pi x / Lam)).
    Sine { height: f64 },
}

#[derive(Clone, Debug)]
pub struct PeriodicCase {
    pub name: String,
    pub profile: ProfileKind,
    pub period: f64,
    pub coherence: f64,
    pub theta_i_deg: f64,
    pub lambda0_nm: f64,
    /// Samples per period (the error estimate uses twice as many).
    pub samples_per_period: usize,
    /// Field extent in coherence lengths (zero-padding: finer q sampling).
    pub extent: f64,
}

#[derive(Clone, Debug, Default)]
pub struct PeriodicPoint {
    pub order: i64,
    /// "x": along qx through the order at qy = 0; "y": along qy at the order's qx.
    pub cut: String,
    pub qx: f64,
    pub qy: f64,
    /// (q - q_order) l along the cut.
    pub offset_l: f64,
    pub lambda_nm: f64,
    pub theta_o_deg: f64,
    pub gt: f64,
    /// |gt(2M) - gt(M)| / 3: numerical error estimate.
    pub gt_err: f64,
    pub core: f64,
}

#[derive(Clone, Debug)]
pub struct PeriodicResult {
    pub case: PeriodicCase,
    pub core_json: String,
    /// How the core was called (core::Core::route).
    pub core_route: String,
    /// k w at the mirror direction.
    pub a: f64,
    pub points: Vec<PeriodicPoint>,
    /// Full qx scan at qy = 0 (q, gt, core) for the plots.
    pub scan: Vec<(f64, f64, f64)>,
    pub peak_max: f64,
    pub seconds: f64,
}

fn height(profile: &ProfileKind, period: f64, x: f64) -> f64 {
    let f = (x / period).rem_euclid(1.0);
    match *profile {
        ProfileKind::Rect { height, width } => {
            if f * period < width {
                height
            } else {
                0.0
            }
        }
        ProfileKind::Sine { height } => 0.5 * height * (1.0 + (2.0 * PI * f).cos()),
    }
}

/// |X(qx)|^2 / A_x on the grid of periods*M samples: returns (values, dq).
fn x_spectrum(case: &PeriodicCase, a: f64, m: usize, periods: usize) -> (Vec<f64>, f64) {
    let n = periods * m;
    let dx = case.period / m as f64;
    let l = case.coherence;
    let half = 0.5 * n as f64 * dx;
    let mut buf: Vec<Complex64> = Vec::with_capacity(n);
    let mut aw = 0.0;
    for j in 0..n {
        let x = (j as f64 + 0.5) * dx - half;
        let w = (-x * x / (2.0 * l * l)).exp();
        aw += w * w * dx;
        let (s, c) = (a * height(&case.profile, case.period, x)).sin_cos();
        buf.push(Complex64::new(w * c, w * s));
    }
    FftPlanner::new().plan_fft_forward(n).process(&mut buf);
    let vals = buf.iter().map(|z| z.norm_sqr() * dx * dx / aw).collect();
    (vals, 2.0 * PI / (n as f64 * dx))
}

/// |Y(qy)|^2 / A_y for ny samples of spacing dy.
fn y_spectrum(l: f64, dy: f64, ny: usize) -> Vec<f64> {
    let half = 0.5 * ny as f64 * dy;
    let mut buf: Vec<Complex64> = Vec::with_capacity(ny);
    let mut aw = 0.0;
    for j in 0..ny {
        let y = (j as f64 + 0.5) * dy - half;
        let w = (-y * y / (2.0 * l * l)).exp();
        aw += w * w * dy;
        buf.push(Complex64::new(w, 0.0));
    }
    FftPlanner::new().plan_fft_forward(ny).process(&mut buf);
    buf.iter().map(|z| z.norm_sqr() * dy * dy / aw).collect()
}

pub fn core_json(case: &PeriodicCase) -> String {
    let (p, l) = (case.period, case.coherence);
    match case.profile {
        ProfileKind::Rect { height, width } => format!(
            r#"{{"surface":"periodic","period_um":{p},"coherence_um":{l},"profile":"rect","height_um":{height},"width_um":{width},"fresnel":1.0}}"#
        ),
        ProfileKind::Sine { height } => format!(
            r#"{{"surface":"periodic","period_um":{p},"coherence_um":{l},"profile":"sine","height_um":{height},"fresnel":1.0}}"#
        ),
    }
}

pub fn run(case: &PeriodicCase, core_scale: f64) -> Result<PeriodicResult, String> {
    let t0 = Instant::now();
    let wi: DVec3 = optics::incidence(case.theta_i_deg);
    let k0 = optics::wavenumber(case.lambda0_nm);
    let a = -2.0 * k0 * wi.z;
    let json = core_json(case);
    let brdf = crate::core::Core::new(&json);
    let l = case.coherence;
    let mut periods = (case.extent * l / case.period).ceil() as usize;
    periods += periods % 2;
    let m = case.samples_per_period;
    let (xs, dqx) = x_spectrum(case, a, m, periods);
    let (xs2, _) = x_spectrum(case, a, 2 * m, periods);
    let dy = l / 16.0;
    let ny = ((case.extent * 16.0).ceil() as usize).next_multiple_of(2);
    let ys = y_spectrum(l, dy, ny);
    let dqy = 2.0 * PI / (ny as f64 * dy);
    let nx = xs.len();
    let xidx = |i: i64| i.rem_euclid(nx as i64) as usize;
    let x2idx = |i: i64| i.rem_euclid(xs2.len() as i64) as usize;
    let extrapolate =
        |x1: f64, x2: f64, y: f64| ((4.0 * x2 - x1) / 3.0 * y, (x2 - x1).abs() / 3.0 * y);
    let yidx = |i: i64| i.rem_euclid(ny as i64) as usize;
    let core_at = |qx: f64, qy: f64| -> Option<(Pair, f64)> {
        let pair = optics::solve_pair(wi, a, qx, qy)?;
        let f = brdf.f_over_g(wi, pair.wo, pair.lambda_nm);
        Some((pair, core_scale * optics::kernel_to_spectrum(f, wi, &pair)))
    };
    let peak_max = xs.iter().cloned().fold(0.0, f64::max) * ys[0];
    // Orders: q_n = 2 pi n / Lam = n * periods * dqx exactly on the grid.
    let mut points = Vec::new();
    let n_max = (4.0 * k0 * case.period / (2.0 * PI)).ceil() as i64;
    let steps = (1.5 / (l * dqx)).ceil() as i64; // +-1.5 / l along the cut
    for order in -n_max..=n_max {
        let ic = order * periods as i64;
        for j in -steps..=steps {
            let i = ic + j;
            let qx = i as f64 * dqx;
            let Some((pair, core)) = core_at(qx, 0.0) else {
                continue;
            };
            let (gt, gt_err) = extrapolate(xs[xidx(i)], xs2[x2idx(i)], ys[0]);
            points.push(PeriodicPoint {
                order,
                cut: "x".into(),
                qx,
                qy: 0.0,
                offset_l: j as f64 * dqx * l,
                lambda_nm: pair.lambda_nm,
                theta_o_deg: pair.wo.z.acos().to_degrees(),
                gt,
                gt_err,
                core,
            });
        }
        let ysteps = (1.5 / (l * dqy)).ceil() as i64;
        for j in 1..=ysteps {
            let qx = ic as f64 * dqx;
            let qy = j as f64 * dqy;
            let Some((pair, core)) = core_at(qx, qy) else {
                continue;
            };
            let (gt, gt_err) = extrapolate(xs[xidx(ic)], xs2[x2idx(ic)], ys[yidx(j)]);
            points.push(PeriodicPoint {
                order,
                cut: "y".into(),
                qx,
                qy,
                offset_l: qy * l,
                lambda_nm: pair.lambda_nm,
                theta_o_deg: pair.wo.z.acos().to_degrees(),
                gt,
                gt_err,
                core,
            });
        }
    }
    let mut scan = Vec::new();
    let i_max = (2.0 * k0 / dqx).ceil() as i64;
    for i in -i_max..=i_max {
        let qx = i as f64 * dqx;
        if let Some((_, core)) = core_at(qx, 0.0) {
            scan.push((qx, extrapolate(xs[xidx(i)], xs2[x2idx(i)], ys[0]).0, core));
        }
    }
    Ok(PeriodicResult {
        case: case.clone(),
        core_json: json,
        core_route: brdf.route(),
        a,
        points,
        scan,
        peak_max,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// Resolved: above 1e-6 of the strongest peak. Pass: |ratio - 1| <= 3 x the
/// numerical error estimate + 1e-4 (no Monte Carlo noise here).
pub const PERIODIC_FLOOR: f64 = 1e-6;
pub const PERIODIC_TOL: f64 = 1e-4;

pub fn verdict(p: &PeriodicPoint, peak_max: f64) -> (bool, bool) {
    let resolved = p.gt > PERIODIC_FLOOR * peak_max;
    let dev = (p.core / p.gt - 1.0).abs();
    let pass = !resolved || dev <= 3.0 * p.gt_err / p.gt + PERIODIC_TOL;
    (resolved, pass)
}

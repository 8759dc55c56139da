//! Monte Carlo ground truth for random surfaces: synthesise, FFT
//! p = exp(i a h), average |P|^2 / A per bin over realisations, compare with
//! the core evaluated at exactly the same frequencies.
//!
//! Normalisation: P(q_m) = dx^2 sum_j p_j exp(-i q_m . x_j) (the Riemann sum
//! of the continuous transform) and A = Lx Ly, so |P|^2 / A = dx^2 |FFT|^2 / (nx ny).
//!
//! Leakage: the synthetic fields are periodic on the grid and the window is
//! the whole torus (rectangular), so exp(i a h) is periodic too and the DFT
//! has no window leakage; the mean field <p> is constant and lands in the
//! q = 0 bin only (E P_m = 0 exactly for m != 0). The q = 0 bin is compared
//! through the variance of P_0 over realisations (|<P_0>|^2 removed). What
//! remains is aliasing of the spectrum beyond Nyquist; it is measured as the
//! "floor" = mean |P|^2/A in the band max(|qx|/qnx, |qy|/qny) >= 0.9, and a bin
//! counts as resolved only if it is 100x above it.
//!
//! Exact expectation: for Gaussian heights the estimator's mean is known
//! without Monte Carlo, E|P_m|^2 / A = dx^2 FFT_m[exp(-a^2 D(r) / 2)] with D
//! from the synthesis' ensemble covariance (`BinResult::expected_gt`). It
//! checks the Monte Carlo (GT vs E[GT] with the covariance between bins) and
//! separates Monte Carlo noise from deterministic differences (core / E[GT]).
//! Fractal surfaces are completed to the exact target structure function
//! (`FbmCompletion::Exact`) and the aliasing of the sampled transform is
//! corrected with the same transform on a 4x finer grid.

use crate::fft2::Fft2;
use crate::optics::{self, Pair};
use crate::rng::Rng;
use crate::synth::{sample_covariance, Grid, RandomModel, Synth};
use glam::DVec3;
use num_complex::Complex64;
use std::f64::consts::PI;
use std::time::Instant;

/// How grid points are grouped.
#[derive(Clone, Debug)]
pub enum Binning {
    /// Annuli in |q| with the given edges (1/um).
    Annuli { edges: Vec<f64> },
    /// Cuts along the x and y axes for anisotropic surfaces: in the scaled
    /// plane (qx Tx, qy Ty), sectors of half-angle `half_angle_deg` about each
    /// axis, binned in rho = |(qx Tx, qy Ty)| with the given edges.
    AxisCuts {
        tx: f64,
        ty: f64,
        half_angle_deg: f64,
        edges: Vec<f64>,
    },
}

#[derive(Clone, Debug)]
pub struct RandomCase {
    pub name: String,
    pub model: RandomModel,
    pub grid: Grid,
    pub realisations: usize,
    /// Realisations used for the sample calibration (structure/correlation function).
    pub calib_realisations: usize,
    pub theta_i_deg: f64,
    pub lambda0_nm: f64,
    pub binning: Binning,
    pub seed: u64,
    /// fBm only: how the torus surfaces are completed to the target power
    /// law (see `FbmCompletion`).
    pub fbm_completion: FbmCompletion,
}

/// How the fractal ground truth accounts for what the torus synthesis cannot
/// hold (wavenumbers below 2 pi / L, the missing zero mode, everything beyond
/// Nyquist). Both are exact averages over an independent Gaussian complement
/// added to every surface, applied by multiplying the circular
/// autocorrelation of p by the complement's characteristic function.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum FbmCompletion {
    /// The complement has the structure function
    /// dD(r) = s^2 (r / lag)^(2H) - D_disc(r) at every torus lag (D_disc from
    /// the synthesis' exact ensemble covariance): the estimator's expectation
    /// is exactly dx^2 sum_r exp(-a^2 s^2 (r/lag)^(2H) / 2) exp(-i q.r) for
    /// the *target* s; no fit. The core is evaluated with the target s.
    #[default]
    Exact,
    /// The earlier method: a random plane (slope variance B) and a white
    /// nugget C0 fitted with s over lags [r_c/8, 4 r_c]; the core with the
    /// fitted s. Biased by up to 0.3% (H = 0.9, dx = r_c/16) and 1.5%
    /// (dx = r_c/32, smaller torus) at the highest compared q.
    FittedPlane,
}

#[derive(Clone, Debug, Default)]
pub struct BinResult {
    pub cut: String,
    /// Mean |q| (1/um) or mean rho for axis cuts.
    pub q: f64,
    pub u_nominal: f64,
    pub lambda_nm: f64,
    pub theta_o_deg: f64,
    pub points: usize,
    pub gt: f64,
    pub gt_se: f64,
    pub core: f64,
    pub beckmann: f64,
    pub first_order: f64,
    /// Exact expectation of the Monte Carlo estimator for the synthesised
    /// process (no Monte Carlo noise): dx^2 FFT of the lag function
    /// exp(-a^2 D_disc(r) / 2) (x the completion factor for fBm; before the
    /// aliasing correction `alias`).
    pub expected: f64,
    /// fBm only: the torus transform of the power law sampled 4x finer,
    /// (dx/4)^2 sum_r exp(-a^2 s^2 (r/lag)^(2H) / 2) exp(-i q.r), with the s
    /// the core is given (0 otherwise): the continuum up to aliasing
    /// ~ (q dx / 4)^(2+2H).
    pub power_law: f64,
    /// fBm with `FbmCompletion::Exact`: the aliasing correction already
    /// subtracted from `gt`: (the same transform sampled at dx) - `power_law`
    /// (0 otherwise). E[gt] = expected - alias.
    pub alias: f64,
}

impl BinResult {
    pub fn ratio(&self) -> f64 {
        self.core / self.gt
    }
    pub fn rel_err(&self) -> f64 {
        self.gt_se / self.gt
    }
    /// The exact expectation of `gt` (no Monte Carlo noise).
    pub fn expected_gt(&self) -> f64 {
        self.expected - self.alias
    }
}

/// Calibration of the synthetic surfaces.
#[derive(Clone, Debug, Default)]
pub struct Calibration {
    /// (name, target, exact ensemble value of the synthesis, sample mean, sample SE)
    pub entries: Vec<(String, f64, f64, f64, f64)>,
}

#[derive(Clone, Debug)]
pub struct RandomResult {
    pub case: RandomCase,
    /// g = (sigma a)^2 for Gaussian surfaces; for fractal a^2 s^2 / 2.
    pub roughness: f64,
    pub core_json: String,
    /// How the core was called (core::Core::route).
    pub core_route: String,
    pub calibration: Calibration,
    pub floor: f64,
    pub bins: Vec<BinResult>,
    /// Chi-square of core - GT over the resolved bins with the full Monte
    /// Carlo covariance between bins (neighbouring bins share realisations
    /// and are strongly correlated, most of all for fBm), and its dof.
    pub chi2_cov: f64,
    pub chi2_cov_dof: usize,
    /// The same for expected - GT (the Monte Carlo against the exact
    /// expectation of its estimator: must be pure noise).
    pub chi2_cov_expected: f64,
    pub seconds: f64,
}

struct BinMap {
    /// Bin per grid point (usize::MAX: not compared).
    of_point: Vec<usize>,
    bins: Vec<BinResult>,
    pairs: Vec<Option<Pair>>,
}

fn edge_index(edges: &[f64], x: f64) -> Option<usize> {
    if x < edges[0] || x >= *edges.last().unwrap() {
        return None;
    }
    Some(edges.partition_point(|&e| e <= x) - 1)
}

fn build_bins(case: &RandomCase, wi: DVec3, a: f64) -> BinMap {
    let g = case.grid;
    let k0 = optics::wavenumber(case.lambda0_nm);
    let mut bins: Vec<BinResult> = Vec::new();
    let mut of_point = vec![usize::MAX; g.len()];
    let mut pairs = vec![None; g.len()];
    let (cuts, nb): (Vec<&str>, usize) = match &case.binning {
        Binning::Annuli { edges } => (vec!["ring"], edges.len() - 1),
        Binning::AxisCuts { edges, .. } => (vec!["x", "y"], edges.len() - 1),
    };
    for cut in &cuts {
        for _ in 0..nb {
            bins.push(BinResult {
                cut: cut.to_string(),
                ..Default::default()
            });
        }
    }
    for iy in 0..g.ny {
        for ix in 0..g.nx {
            if ix == 0 && iy == 0 {
                continue;
            }
            let (qx, qy) = g.q(ix, iy);
            let qn = g.q_nyquist();
            if qx.abs() > 0.5 * qn || qy.abs() > 0.5 * qn {
                continue;
            }
            let (b, r) = match &case.binning {
                Binning::Annuli { edges } => {
                    let r = qx.hypot(qy);
                    (edge_index(edges, r), r)
                }
                Binning::AxisCuts {
                    tx,
                    ty,
                    half_angle_deg,
                    edges,
                } => {
                    let (sx, sy) = ((qx * tx).abs(), (qy * ty).abs());
                    let rho = sx.hypot(sy);
                    let ang = sy.atan2(sx).to_degrees();
                    let idx = edge_index(edges, rho);
                    if ang <= *half_angle_deg {
                        (idx, rho)
                    } else if ang >= 90.0 - half_angle_deg {
                        (idx.map(|i| i + nb), rho)
                    } else {
                        (None, rho)
                    }
                }
            };
            let Some(b) = b else { continue };
            let Some(pair) = optics::solve_pair(wi, a, qx, qy) else {
                continue;
            };
            of_point[iy * g.nx + ix] = b;
            pairs[iy * g.nx + ix] = Some(pair);
            let bin = &mut bins[b];
            bin.points += 1;
            bin.q += r;
            bin.u_nominal += qx.hypot(qy) / k0;
            bin.lambda_nm += pair.lambda_nm;
            bin.theta_o_deg += pair.wo.z.acos().to_degrees();
        }
    }
    BinMap {
        of_point,
        bins,
        pairs,
    }
}

/// Parameters of the core's material for this case (fresnel = 1: f / G = K).
pub fn core_json(model: &RandomModel) -> String {
    match *model {
        RandomModel::Gaussian { sigma, tx, ty } => {
            if tx == ty {
                format!(
                    r#"{{"surface":"gaussian","sigma_um":{sigma},"corr_um":{tx},"fresnel":1.0}}"#
                )
            } else {
                format!(
                    r#"{{"surface":"gaussian","sigma_um":{sigma},"corr_x_um":{tx},"corr_y_um":{ty},"fresnel":1.0}}"#
                )
            }
        }
        RandomModel::Fbm { hurst, s, lag } => format!(
            r#"{{"surface":"fractal","hurst":{hurst},"sigma_um":{s},"lag_um":{lag},"fresnel":1.0}}"#
        ),
    }
}

/// Lags of the fractal structure-function fit, in units of r_c (where
/// a^2 D(r_c) / 2 = 1); compared frequencies stop at 1 / (the lower end).
pub const FBM_FIT_RANGE: (f64, f64) = (0.125, 4.0);

/// Terms of the fractal structure-function fit (see `fit_fbm`).
pub const FBM_FIT_TERMS: usize = 3;

/// Running per-bin statistics over realisations.
struct Accum {
    n: usize,
    sum: Vec<f64>,
    sum2: Vec<f64>,
    per_real: Vec<f64>,
}

impl Accum {
    fn new(nb: usize) -> Accum {
        Accum {
            n: 0,
            sum: vec![0.0; nb],
            sum2: vec![0.0; nb],
            per_real: vec![0.0; nb],
        }
    }
    fn mean_se(&self, b: usize) -> (f64, f64) {
        let n = self.n as f64;
        let m = self.sum[b] / n;
        let var = (self.sum2[b] / n - m * m).max(0.0) * n / (n - 1.0);
        (m, (var / n).sqrt())
    }
}

/// Fits of the sample covariance of one realisation, with `lags` = grid
/// offsets along one axis at which to fit.
fn fit_gaussian_axis(cov: &[f64], idx: &[(usize, f64)]) -> f64 {
    // ln(C(r)/C(0)) = -r^2/T^2, least squares through the origin in r^2.
    let c0 = cov[0];
    let (mut num, mut den) = (0.0, 0.0);
    for &(j, r) in idx {
        let c = cov[j] / c0;
        if c > 0.0 {
            num += -c.ln() * r * r;
            den += r.powi(4);
        }
    }
    (den / num).sqrt()
}

/// Structure-function fit of a fractal surface over the lags `idx`:
/// D_disc(r) + B r^2 + C0 = s^2 (r / lag)^(2H) with H fixed, least squares
/// in the relative residual, linear in (s^2, B, C0). B is the slope variance
/// of a random plane that restores the low wavenumbers missing on the torus
/// (K < 2 pi / L contribute ~ r^2 at r << L); C0 a white "nugget" that
/// restores the variance missing beyond Nyquist (a constant in D for r >> dx).
/// `terms` = 1: s alone; 2: s and B; 3: s, B and C0.
/// Returns (s, B, C0, max relative residual over the lags).
pub fn fit_fbm(
    cov: &[f64],
    idx: &[(usize, f64)],
    hurst: f64,
    lag: f64,
    terms: usize,
) -> (f64, f64, f64, f64) {
    // Unknowns c = (s^2, -B, -C0); rows x = (rho / D, r^2 / D, 1 / D); minimise |X c - 1|^2.
    let rows: Vec<[f64; 3]> = idx
        .iter()
        .map(|&(j, r)| {
            let d = 2.0 * (cov[0] - cov[j]);
            [(r / lag).powf(2.0 * hurst) / d, r * r / d, 1.0 / d]
        })
        .collect();
    let n = terms.clamp(1, 3);
    let mut m = [[0.0; 4]; 3];
    for x in &rows {
        for i in 0..n {
            for k in 0..n {
                m[i][k] += x[i] * x[k];
            }
            m[i][3] += x[i];
        }
    }
    // Gaussian elimination (n <= 3, well conditioned after scaling).
    for i in 0..n {
        let p = m[i][i];
        m[i].iter_mut().for_each(|v| *v /= p);
        let pivot = m[i];
        for (r, row) in m.iter_mut().enumerate().take(n) {
            if r != i {
                let f = row[i];
                row.iter_mut().zip(&pivot).for_each(|(v, pv)| *v -= f * pv);
            }
        }
    }
    let mut c = [0.0; 3];
    for i in 0..n {
        c[i] = m[i][3];
    }
    let resid = rows
        .iter()
        .map(|x| (x[0] * c[0] + x[1] * c[1] + x[2] * c[2] - 1.0).abs())
        .fold(0.0, f64::max);
    (c[0].sqrt(), -c[1], -c[2], resid)
}

/// Local exponent H_eff: half the log-log slope of D over the lags.
fn fit_slope(cov: &[f64], idx: &[(usize, f64)]) -> f64 {
    let pts: Vec<(f64, f64)> = idx
        .iter()
        .map(|&(j, r)| (r.ln(), (2.0 * (cov[0] - cov[j])).ln()))
        .collect();
    let n = pts.len() as f64;
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / n;
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    0.5 * sxy / sxx
}

/// Lags along x (grid offsets (j, 0)) and y ((0, j)) within [lo, hi] um.
/// Lags as (index into the lag grid, distance in um).
type Lags = Vec<(usize, f64)>;

fn axis_lags(g: &Grid, lo: f64, hi: f64) -> (Lags, Lags) {
    let lx = (1..g.nx / 2)
        .map(|j| (j, j as f64 * g.dx))
        .filter(|&(_, r)| r >= lo && r <= hi)
        .collect();
    let ly = (1..g.ny / 2)
        .map(|j| (j * g.nx, j as f64 * g.dx))
        .filter(|&(_, r)| r >= lo && r <= hi)
        .collect();
    (lx, ly)
}

fn calibration_s(xs: &[f64]) -> f64 {
    mean_se(xs).0
}

fn mean_se(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let m = xs.iter().sum::<f64>() / n;
    let v = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (m, (v / n).sqrt())
}

/// Run one case. `core_scale` multiplies the core's answer (1.0 in all real
/// runs; the tests use it to check that a wrong core is rejected).
pub fn run(case: &RandomCase, core_scale: f64) -> Result<RandomResult, String> {
    let t0 = Instant::now();
    let g = case.grid;
    let wi = optics::incidence(case.theta_i_deg);
    let k0 = optics::wavenumber(case.lambda0_nm);
    let a = -2.0 * k0 * wi.z;
    let mut fft = Fft2::new(g.nx, g.ny);
    let mut synth = Synth::new(g, &case.model);
    let mut rng = Rng::new(case.seed);

    // --- Calibration: exact ensemble covariance of the synthesis and samples.
    let ens = synth.ensemble_covariance(&mut fft);
    let mut calibration = Calibration::default();
    let mut model_for_core = case.model;
    let (fit_x, fit_y): (Lags, Lags);
    let mut plane_b = 0.0;
    let mut nugget = 0.0;
    match case.model {
        RandomModel::Gaussian { sigma, tx, ty } => {
            // Fit T where C/C0 is between 0.1 and 0.9 (r between 0.32 T and 1.5 T).
            let (xl, _) = axis_lags(&g, 0.3 * tx, 1.5 * tx);
            let (_, yl) = axis_lags(&g, 0.3 * ty, 1.5 * ty);
            fit_x = xl;
            fit_y = yl;
            calibration
                .entries
                .push(("sigma_um".into(), sigma, ens[0].sqrt(), 0.0, 0.0));
            calibration.entries.push((
                "Tx_um".into(),
                tx,
                fit_gaussian_axis(&ens, &fit_x),
                0.0,
                0.0,
            ));
            calibration.entries.push((
                "Ty_um".into(),
                ty,
                fit_gaussian_axis(&ens, &fit_y),
                0.0,
                0.0,
            ));
        }
        RandomModel::Fbm { hurst, s, lag } => {
            // The scales that matter: around r_c where a^2 D(r_c) / 2 = 1.
            let rc = lag * (2.0 / (a * a * s * s)).powf(0.5 / hurst);
            let (xl, yl) = axis_lags(&g, FBM_FIT_RANGE.0 * rc, FBM_FIT_RANGE.1 * rc);
            if xl.len() < 3 {
                return Err(format!(
                    "{}: too few lags to fit D around r_c = {rc} um",
                    case.name
                ));
            }
            fit_x = xl.iter().chain(yl.iter()).cloned().collect();
            fit_y = Vec::new();
            let (s_ens, b, c0, resid) = fit_fbm(&ens, &fit_x, hurst, lag, FBM_FIT_TERMS);
            let (s_pure, _, _, resid_pure) = fit_fbm(&ens, &fit_x, hurst, lag, 1);
            let h_eff = fit_slope(&ens, &fit_x);
            if case.fbm_completion == FbmCompletion::FittedPlane {
                plane_b = b.max(0.0);
                nugget = c0.max(0.0);
                model_for_core = RandomModel::Fbm {
                    hurst,
                    s: s_ens,
                    lag,
                };
            }
            calibration
                .entries
                .push(("s_um (fit with plane)".into(), s, s_ens, 0.0, 0.0));
            calibration.entries.push((
                "plane B r_c^2 / D(r_c)".into(),
                0.0,
                b * rc * rc / (s_ens * s_ens * (rc / lag).powf(2.0 * hurst)),
                0.0,
                0.0,
            ));
            calibration
                .entries
                .push(("H_eff (slope of D_disc)".into(), hurst, h_eff, 0.0, 0.0));
            calibration
                .entries
                .push(("nugget a^2 C0 / 2".into(), 0.0, a * a * c0 / 2.0, 0.0, 0.0));
            calibration
                .entries
                .push(("max rel. residual of fit".into(), 0.0, resid, 0.0, 0.0));
            calibration
                .entries
                .push(("s_um (no plane)".into(), s, s_pure, 0.0, 0.0));
            calibration.entries.push((
                "max rel. residual (no plane)".into(),
                0.0,
                resid_pure,
                0.0,
                0.0,
            ));
            calibration.entries.push((
                "r_c_um".into(),
                rc,
                lag * (2.0 / (a * a * s_ens * s_ens)).powf(0.5 / hurst),
                0.0,
                0.0,
            ));
            // The exact complement dD = D_target - D_disc: its size at r_c
            // (as a^2 dD / 2) and its smallest value relative to D_target
            // over the torus lags (>= 0: a genuine, non-negative complement).
            let (mut at_rc, mut min_rel) = (0.0, f64::INFINITY);
            for &(j, r) in &fit_x {
                if (r - rc).abs() <= 0.5 * g.dx {
                    at_rc = 0.5
                        * a
                        * a
                        * (s * s * (r / lag).powf(2.0 * hurst) - 2.0 * (ens[0] - ens[j]));
                }
            }
            for j in 1..g.len() {
                let (rx, ry) = g.lag(j % g.nx, j / g.nx);
                let dt = s * s * (rx.hypot(ry) / lag).powf(2.0 * hurst);
                min_rel = f64::min(min_rel, (dt - 2.0 * (ens[0] - ens[j])) / dt);
            }
            calibration
                .entries
                .push(("complement a^2 dD(r_c) / 2".into(), 0.0, at_rc, 0.0, 0.0));
            calibration.entries.push((
                "complement min dD / D_target".into(),
                0.0,
                min_rel,
                0.0,
                0.0,
            ));
        }
    }
    let json = core_json(&model_for_core);
    let brdf = crate::core::Core::new(&json);

    // --- Bins, physical pairs and the core (and approximations) per point.
    let mut map = build_bins(case, wi, a);
    let nb = map.bins.len();
    let mut core_sum = vec![0.0; nb];
    let mut beck_sum = vec![0.0; nb];
    let mut first_sum = vec![0.0; nb];
    for iy in 0..g.ny {
        for ix in 0..g.nx {
            let j = iy * g.nx + ix;
            let b = map.of_point[j];
            if b == usize::MAX {
                continue;
            }
            let pair = map.pairs[j].unwrap();
            let (qx, qy) = g.q(ix, iy);
            let f = brdf.f_over_g(wi, pair.wo, pair.lambda_nm);
            core_sum[b] += core_scale * optics::kernel_to_spectrum(f, wi, &pair);
            if let RandomModel::Gaussian { sigma, tx, ty } = case.model {
                beck_sum[b] += optics::beckmann_spectrum(sigma, tx, ty, wi, &pair);
                first_sum[b] += optics::first_order_spectrum(sigma, tx, ty, a, qx, qy);
            }
        }
    }
    // q = 0: the diffuse part at the mirror direction, compared separately.
    let pair0 = optics::solve_pair(wi, a, 0.0, 0.0).expect("mirror pair");
    let core0 = core_scale
        * optics::kernel_to_spectrum(brdf.f_over_g(wi, pair0.wo, pair0.lambda_nm), wi, &pair0);

    // --- Monte Carlo.
    let qn = g.q_nyquist();
    let floor_pts: Vec<usize> = (0..g.len())
        .filter(|&j| {
            let (qx, qy) = g.q(j % g.nx, j / g.nx);
            (qx.abs() / qn).max(qy.abs() / qn) >= 0.9
        })
        .collect();
    let mut acc = Accum::new(nb);
    // Per-realisation bin values (for the covariance between bins).
    let mut series: Vec<Vec<f64>> = vec![Vec::with_capacity(case.realisations); nb];
    let mut floor_sum = 0.0;
    let mut p0: Vec<Complex64> = Vec::with_capacity(case.realisations);
    let mut calib_vals: Vec<Vec<f64>> = vec![Vec::new(); 3];
    // Fractal, `FbmCompletion::FittedPlane`: the random plane of slope variance B, averaged exactly, by
    // multiplying the circular autocorrelation of p by its characteristic
    // function exp(-a^2 B r^2 / 2) (r the torus lag); the variance C0 missing
    // beyond Nyquist by exp(-a^2 C0 / 2) (its broad pedestal, of order
    // (a^2 C0 / 2) dx^2 / pi^2 at low q, is neglected).
    let plane_factor: Vec<f64> = if let (RandomModel::Fbm { hurst, s, lag }, FbmCompletion::Exact) =
        (case.model, case.fbm_completion)
    {
        // The exact complement: exp(-a^2 (D_target(r) - D_disc(r)) / 2).
        (0..g.len())
            .map(|j| {
                let (rx, ry) = g.lag(j % g.nx, j / g.nx);
                let dt = s * s * (rx.hypot(ry) / lag).powf(2.0 * hurst);
                (-0.5 * a * a * (dt - 2.0 * (ens[0] - ens[j]))).exp()
            })
            .collect()
    } else if plane_b > 0.0 || nugget > 0.0 {
        (0..g.len())
            .map(|j| {
                let (rx, ry) = g.lag(j % g.nx, j / g.nx);
                (-0.5 * a * a * (plane_b * (rx * rx + ry * ry) + nugget)).exp()
            })
            .collect()
    } else {
        Vec::new()
    };
    // Exact expectation of the estimator below: E[circular autocorrelation
    // of p](r) = exp(-a^2 (C(0) - C(r))) for the Gaussian process with the
    // ensemble covariance C of the synthesis, then the same completion
    // factor and transform as the Monte Carlo. Gaussian q = 0: the coherent
    // |E P_0|^2 / A = dx^2 N exp(-a^2 C(0)) removed.
    let lag_transform = |fft: &mut Fft2, f: &dyn Fn(usize) -> f64| -> Vec<f64> {
        let mut b: Vec<Complex64> = (0..g.len()).map(|j| Complex64::new(f(j), 0.0)).collect();
        fft.forward(&mut b);
        b.iter().map(|z| z.re * g.dx * g.dx).collect()
    };
    let coherent = match case.model {
        RandomModel::Gaussian { .. } => (-a * a * ens[0]).exp(),
        RandomModel::Fbm { .. } => 0.0,
    };
    let expected_pt = lag_transform(&mut fft, &|j| {
        let r = (-a * a * (ens[0] - ens[j])).exp() - coherent;
        if plane_factor.is_empty() {
            r
        } else {
            r * plane_factor[j]
        }
    });
    // fBm: the same transform of the target power law on a 4x finer grid
    // (same torus), and, with the exact completion, the aliasing correction
    // (sampled at dx) - (sampled at dx/4), subtracted from the Monte Carlo.
    let (power_law_pt, alias_pt) = match model_for_core {
        RandomModel::Fbm { hurst, s, lag } => {
            let fine = fine_power_law(&g, a, hurst, s, lag, 4);
            let alias = if case.fbm_completion == FbmCompletion::Exact {
                let coarse = lag_transform(&mut fft, &|j| {
                    let (rx, ry) = g.lag(j % g.nx, j / g.nx);
                    (-0.5 * a * a * s * s * (rx.hypot(ry) / lag).powf(2.0 * hurst)).exp()
                });
                coarse.iter().zip(&fine).map(|(c, f)| c - f).collect()
            } else {
                vec![0.0; g.len()]
            };
            (fine, alias)
        }
        RandomModel::Gaussian { .. } => (vec![0.0; g.len()], vec![0.0; g.len()]),
    };
    let mut expected_sum = vec![0.0; nb];
    let mut power_law_sum = vec![0.0; nb];
    let mut alias_sum = vec![0.0; nb];
    for (j, &b) in map.of_point.iter().enumerate() {
        if b != usize::MAX {
            expected_sum[b] += expected_pt[j];
            power_law_sum[b] += power_law_pt[j];
            alias_sum[b] += alias_pt[j];
        }
    }
    let mut power = vec![0.0; g.len()];
    let mut power0: Vec<f64> = Vec::with_capacity(case.realisations);
    let scale = g.dx * g.dx / g.len() as f64;
    let mut buf = vec![Complex64::new(0.0, 0.0); g.len()];
    let mut done = 0;
    while done < case.realisations {
        let (h1, h2) = synth.pair(&mut rng, &mut fft);
        for h in [h1, h2] {
            if done >= case.realisations {
                break;
            }
            if done < case.calib_realisations {
                let cov = sample_covariance(&h, &mut fft);
                match case.model {
                    RandomModel::Gaussian { .. } => {
                        calib_vals[0].push(cov[0].sqrt());
                        calib_vals[1].push(fit_gaussian_axis(&cov, &fit_x));
                        calib_vals[2].push(fit_gaussian_axis(&cov, &fit_y));
                    }
                    RandomModel::Fbm { hurst, lag, .. } => {
                        let (s_fit, b, _, _) = fit_fbm(&cov, &fit_x, hurst, lag, FBM_FIT_TERMS);
                        calib_vals[0].push(s_fit);
                        calib_vals[1].push(b);
                        calib_vals[2].push(fit_slope(&cov, &fit_x));
                    }
                }
            }
            for (z, &hv) in buf.iter_mut().zip(&h) {
                let (s, c) = (a * hv).sin_cos();
                *z = Complex64::new(c, s);
            }
            fft.forward(&mut buf);
            p0.push(buf[0] * g.dx * g.dx);
            for (pw, z) in power.iter_mut().zip(&buf) {
                *pw = z.norm_sqr() * scale;
            }
            if !plane_factor.is_empty() {
                for (z, &pw) in buf.iter_mut().zip(&power) {
                    *z = Complex64::new(pw, 0.0);
                }
                fft.inverse(&mut buf);
                for (z, f) in buf.iter_mut().zip(&plane_factor) {
                    *z *= f / g.len() as f64;
                }
                fft.forward(&mut buf);
                for (pw, z) in power.iter_mut().zip(&buf) {
                    *pw = z.re;
                }
            }
            power0.push(power[0]);
            acc.per_real.iter_mut().for_each(|x| *x = 0.0);
            for (j, &pw) in power.iter().enumerate() {
                let b = map.of_point[j];
                if b != usize::MAX {
                    acc.per_real[b] += pw;
                }
            }
            for (b, ser) in series.iter_mut().enumerate() {
                let x = acc.per_real[b] / map.bins[b].points.max(1) as f64;
                acc.sum[b] += x;
                acc.sum2[b] += x * x;
                ser.push(x);
            }
            acc.n += 1;
            floor_sum += floor_pts.iter().map(|&j| power[j]).sum::<f64>() / floor_pts.len() as f64;
            done += 1;
        }
    }
    for (i, vals) in calib_vals.iter().enumerate() {
        if let Some(e) = calibration.entries.get_mut(i) {
            if i == 1 && matches!(case.model, RandomModel::Fbm { .. }) {
                // B as the same relative measure as the ensemble entry.
                let RandomModel::Fbm { hurst, lag, .. } = case.model else {
                    unreachable!()
                };
                let s_e = calibration_s(&calib_vals[0]);
                let rc = lag * (2.0 / (a * a * s_e * s_e)).powf(0.5 / hurst);
                let rel: Vec<f64> = vals
                    .iter()
                    .map(|b| b * rc * rc / (s_e * s_e * (rc / lag).powf(2.0 * hurst)))
                    .collect();
                let (m, se) = mean_se(&rel);
                e.3 = m;
                e.4 = se;
                continue;
            }
            if !vals.is_empty() {
                let (m, se) = mean_se(vals);
                e.3 = m;
                e.4 = se;
            }
        }
    }

    // --- Results.
    for (b, bin) in map.bins.iter_mut().enumerate() {
        if bin.points == 0 {
            continue;
        }
        let n = bin.points as f64;
        bin.q /= n;
        bin.u_nominal /= n;
        bin.lambda_nm /= n;
        bin.theta_o_deg /= n;
        let (m, se) = acc.mean_se(b);
        bin.alias = alias_sum[b] / bin.points as f64;
        bin.gt = m - bin.alias;
        bin.gt_se = se;
        bin.core = core_sum[b] / n;
        bin.beckmann = beck_sum[b] / n;
        bin.first_order = first_sum[b] / n;
        bin.expected = expected_sum[b] / n;
        bin.power_law = power_law_sum[b] / n;
    }
    let mut bins: Vec<BinResult> = Vec::new();
    let mut bin_series: Vec<Vec<f64>> = Vec::new();
    for (bin, ser) in map.bins.into_iter().zip(series) {
        if bin.points > 0 {
            bins.push(bin);
            bin_series.push(ser);
        }
    }
    // q = 0: variance of P_0 over realisations / A (the coherent |<P_0>|^2 removed).
    let area = g.lx() * g.ly();
    let n = p0.len() as f64;
    let mean0 = p0.iter().sum::<Complex64>() / n;
    let dev: Vec<f64> = p0
        .iter()
        .map(|z| (z - mean0).norm_sqr() / area * n / (n - 1.0))
        .collect();
    let ser0 = if plane_factor.is_empty() {
        dev
    } else {
        // Fractal: no coherent part; the plane-corrected power at q = 0.
        power0
    };
    let (v0, v0_se) = mean_se(&ser0);
    let mut bin0 = BinResult {
        cut: "q0".into(),
        q: 0.0,
        u_nominal: 0.0,
        lambda_nm: pair0.lambda_nm,
        theta_o_deg: pair0.wo.z.acos().to_degrees(),
        points: 1,
        gt: v0 - alias_pt[0],
        gt_se: v0_se,
        alias: alias_pt[0],
        core: core0,
        expected: expected_pt[0],
        power_law: power_law_pt[0],
        ..Default::default()
    };
    if let RandomModel::Gaussian { sigma, tx, ty } = case.model {
        bin0.beckmann = optics::beckmann_spectrum(sigma, tx, ty, wi, &pair0);
        bin0.first_order = optics::first_order_spectrum(sigma, tx, ty, a, 0.0, 0.0);
    }
    bins.insert(0, bin0);
    bin_series.insert(0, ser0);
    let floor = floor_sum / acc.n as f64;
    let resolved: Vec<usize> = (0..bins.len())
        .filter(|&i| verdict(&bins[i], floor).resolved)
        .collect();
    let diff: Vec<f64> = resolved
        .iter()
        .map(|&i| bins[i].core - bins[i].gt)
        .collect();
    let sel: Vec<&[f64]> = resolved.iter().map(|&i| bin_series[i].as_slice()).collect();
    let (chi2_cov, chi2_cov_dof) = covariance_chi2(&sel, &diff);
    let diff_e: Vec<f64> = resolved
        .iter()
        .map(|&i| bins[i].expected_gt() - bins[i].gt)
        .collect();
    let (chi2_cov_expected, _) = covariance_chi2(&sel, &diff_e);
    let roughness = match case.model {
        RandomModel::Gaussian { sigma, .. } => (sigma * a).powi(2),
        RandomModel::Fbm { s, .. } => a * a * s * s / 2.0,
    };
    Ok(RandomResult {
        case: case.clone(),
        roughness,
        core_json: json,
        core_route: brdf.route(),
        calibration,
        floor,
        bins,
        chi2_cov,
        chi2_cov_dof,
        chi2_cov_expected,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// Chi-square of the differences `d` (one per bin) with the covariance S of
/// the means of the per-realisation series (one per bin, equal lengths n).
/// S is scaled to a correlation matrix and diagonalised (Jacobi); directions
/// with eigenvalue below 1e-6 of the largest are dropped (bins so strongly
/// correlated that the sample covariance cannot resolve their difference).
/// Returns (chi2, dof): chi2 = sum over the kept directions of (v.d)^2 / lambda,
/// times (n - p - 2) / (n - 1) so that E chi2 = dof for pure Monte Carlo
/// noise (Hotelling). (0, 0) when there are no bins or too few realisations.
pub fn covariance_chi2(series: &[&[f64]], d: &[f64]) -> (f64, usize) {
    let p = d.len();
    if p == 0 || series[0].len() <= p + 2 {
        return (0.0, 0);
    }
    let n = series[0].len();
    let nf = n as f64;
    let means: Vec<f64> = series.iter().map(|s| s.iter().sum::<f64>() / nf).collect();
    let mut c = vec![vec![0.0; p]; p];
    for i in 0..p {
        for k in 0..=i {
            let v: f64 = (0..n)
                .map(|t| (series[i][t] - means[i]) * (series[k][t] - means[k]))
                .sum::<f64>()
                / ((nf - 1.0) * nf);
            c[i][k] = v;
            c[k][i] = v;
        }
    }
    let sd: Vec<f64> = (0..p).map(|i| c[i][i].sqrt().max(1e-300)).collect();
    for i in 0..p {
        for k in 0..p {
            c[i][k] /= sd[i] * sd[k];
        }
    }
    let z: Vec<f64> = (0..p).map(|i| d[i] / sd[i]).collect();
    let (vals, vecs) = jacobi_eigen(c);
    let top = vals.iter().cloned().fold(0.0, f64::max);
    let (mut chi2, mut dof) = (0.0, 0);
    for (m, &lam) in vals.iter().enumerate() {
        if lam > 1e-6 * top {
            let proj: f64 = (0..p).map(|i| vecs[i][m] * z[i]).sum();
            chi2 += proj * proj / lam;
            dof += 1;
        }
    }
    (chi2 * (nf - p as f64 - 2.0) / (nf - 1.0), dof)
}

/// Eigen-decomposition of a symmetric matrix by cyclic Jacobi rotations:
/// (eigenvalues, eigenvectors as columns).
fn jacobi_eigen(mut a: Vec<Vec<f64>>) -> (Vec<f64>, Vec<Vec<f64>>) {
    let p = a.len();
    let mut v = vec![vec![0.0; p]; p];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _sweep in 0..100 {
        let off: f64 = (0..p)
            .flat_map(|i| (0..p).filter(move |&k| k != i).map(move |k| (i, k)))
            .map(|(i, k)| a[i][k] * a[i][k])
            .sum();
        let diag: f64 = (0..p).map(|i| a[i][i] * a[i][i]).sum();
        if off <= 1e-30 * diag {
            break;
        }
        for i in 0..p {
            for k in i + 1..p {
                if a[i][k] == 0.0 {
                    continue;
                }
                let theta = 0.5 * (a[k][k] - a[i][i]) / a[i][k];
                // signum(0) = 1: a 45 degree rotation for equal diagonals.
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let cs = 1.0 / (t * t + 1.0).sqrt();
                let sn = t * cs;
                for row in a.iter_mut() {
                    let (x, y) = (row[i], row[k]);
                    row[i] = cs * x - sn * y;
                    row[k] = sn * x + cs * y;
                }
                let (lo, hi) = a.split_at_mut(k);
                for (x, y) in lo[i].iter_mut().zip(hi[0].iter_mut()) {
                    let (xv, yv) = (*x, *y);
                    *x = cs * xv - sn * yv;
                    *y = sn * xv + cs * yv;
                }
                for row in v.iter_mut() {
                    let (x, y) = (row[i], row[k]);
                    row[i] = cs * x - sn * y;
                    row[k] = sn * x + cs * y;
                }
            }
        }
    }
    ((0..p).map(|i| a[i][i]).collect(), v)
}

/// (dx/m)^2 sum_r exp(-a^2 s^2 (|r|/lag)^(2H) / 2) exp(-i q.r) over the lags
/// of the grid refined m times (same torus), at the coarse grid's
/// frequencies (coarse index order).
fn fine_power_law(g: &Grid, a: f64, hurst: f64, s: f64, lag: f64, m: usize) -> Vec<f64> {
    let f = Grid {
        nx: m * g.nx,
        ny: m * g.ny,
        dx: g.dx / m as f64,
    };
    let mut fft = Fft2::new(f.nx, f.ny);
    let mut b: Vec<Complex64> = (0..f.len())
        .map(|j| {
            let (rx, ry) = f.lag(j % f.nx, j / f.nx);
            let d = s * s * (rx.hypot(ry) / lag).powf(2.0 * hurst);
            Complex64::new((-0.5 * a * a * d).exp(), 0.0)
        })
        .collect();
    fft.forward(&mut b);
    let fine_index = |i: usize, n: usize, nf: usize| -> usize {
        let k = Grid::signed(i, n);
        if k < 0 {
            (k + nf as i64) as usize
        } else {
            k as usize
        }
    };
    (0..g.len())
        .map(|j| {
            let (ix, iy) = (j % g.nx, j / g.nx);
            let fj = fine_index(iy, g.ny, f.ny) * f.nx + fine_index(ix, g.nx, f.nx);
            b[fj].re * f.dx * f.dx
        })
        .collect()
}

/// Verdict of one bin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Verdict {
    pub resolved: bool,
    pub pass: bool,
    /// |ratio - 1| / relative MC error.
    pub sigmas: f64,
}

/// Resolved: relative MC error below 2% and the value 100x above the
/// aliasing floor. Pass: |ratio - 1| <= 4 sigma (MC) and <= 5%. 4 sigma, not
/// 3: a run compares a few hundred bins, and with 3 sigma about one honest
/// bin in 370 would fail; 4 sigma keeps the family-wise false-alarm rate near
/// 1-2% for 300-400 bins. The report also counts the bins beyond 1, 2 and 3
/// sigma against the Gaussian expectation (68%, 95%, 99.7% within).
pub const MAX_REL_ERR: f64 = 0.02;
pub const FLOOR_FACTOR: f64 = 100.0;
pub const N_SIGMA: f64 = 4.0;
pub const MAX_DEVIATION: f64 = 0.05;

pub fn verdict(bin: &BinResult, floor: f64) -> Verdict {
    let rel = bin.rel_err();
    let resolved = bin.gt > 0.0 && rel < MAX_REL_ERR && bin.gt > FLOOR_FACTOR * floor;
    let dev = (bin.ratio() - 1.0).abs();
    let sigmas = dev / rel;
    let pass = !resolved || (sigmas <= N_SIGMA && dev <= MAX_DEVIATION);
    Verdict {
        resolved,
        pass,
        sigmas,
    }
}

/// Annulus edges: linear from dq/2 with width w up to q_max, or geometric.
pub fn linear_edges(start: f64, width: f64, q_max: f64) -> Vec<f64> {
    let n = ((q_max - start) / width).floor().max(1.0) as usize;
    (0..=n).map(|i| start + i as f64 * width).collect()
}

pub fn log_edges(start: f64, q_max: f64, n: usize) -> Vec<f64> {
    let r = (q_max / start).powf(1.0 / n as f64);
    (0..=n).map(|i| start * r.powi(i as i32)).collect()
}

/// Grid for a Gaussian surface: T / dx >= max(4, 3 sqrt(g)) along the short
/// axis, extent `extent` correlation lengths per axis, sizes rounded up to
/// multiples of 16.
pub fn gaussian_grid(tx: f64, ty: f64, g: f64, extent: f64) -> Grid {
    let per_t = (3.0 * g.sqrt()).max(4.0);
    let dx = tx.min(ty) / per_t;
    let round = |l: f64| (((l / dx) / 16.0).ceil() as usize * 16).max(32);
    Grid {
        nx: round(extent * tx),
        ny: round(extent * ty),
        dx,
    }
}

/// Number of grid steps between frequencies: 2 pi / L.
pub fn dq(grid: &Grid) -> f64 {
    2.0 * PI / grid.lx()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_eigen_reconstructs() {
        let m = vec![
            vec![4.0, 1.0, 0.5, 0.0],
            vec![1.0, 3.0, 0.2, 0.1],
            vec![0.5, 0.2, 2.0, 0.7],
            vec![0.0, 0.1, 0.7, 1.0],
        ];
        let (vals, vecs) = jacobi_eigen(m.clone());
        for (c, &lam) in vals.iter().enumerate() {
            for i in 0..4 {
                let av: f64 = (0..4).map(|k| m[i][k] * vecs[k][c]).sum();
                assert!((av - lam * vecs[i][c]).abs() < 1e-12);
            }
        }
        assert!((vals.iter().sum::<f64>() - 10.0).abs() < 1e-12);
    }

    #[test]
    fn covariance_chi2_of_independent_bins_is_the_sum_of_squares() {
        // Two uncorrelated series (a fixed +-1 pattern and an orthogonal one):
        // the covariance is diagonal and chi2 = sum (d / se)^2 (x Hotelling).
        let n = 400;
        let s1: Vec<f64> = (0..n)
            .map(|t| if t % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let s2: Vec<f64> = (0..n)
            .map(|t| if (t / 2) % 2 == 0 { 2.0 } else { -2.0 })
            .collect();
        let se =
            |s: &[f64]| (s.iter().map(|x| x * x).sum::<f64>() / (n as f64 - 1.0) / n as f64).sqrt();
        let d = [0.1, -0.3];
        let (chi2, dof) = covariance_chi2(&[&s1, &s2], &d);
        let want = ((d[0] / se(&s1)).powi(2) + (d[1] / se(&s2)).powi(2)) * (n as f64 - 4.0)
            / (n as f64 - 1.0);
        assert_eq!(dof, 2);
        assert!((chi2 / want - 1.0).abs() < 1e-12, "{chi2} {want}");
    }
}

//! CSV and markdown output of a run.

use crate::heightmap::{self, MapResult, MapSource};
use crate::periodic::{self, PeriodicResult};
use crate::random::{self, RandomResult};
use crate::synth::RandomModel;
use std::fmt::Write;

fn model_kind(r: &RandomResult) -> &'static str {
    match r.case.model {
        RandomModel::Gaussian { tx, ty, .. } if tx == ty => "gaussian-iso",
        RandomModel::Gaussian { .. } => "gaussian-aniso",
        RandomModel::Fbm { .. } => "fractal",
    }
}

pub fn random_csv(results: &[RandomResult]) -> String {
    let mut s = String::from(
        "case,model,theta_i,roughness,cut,q,u,lambda_nm,theta_o,points,gt,gt_se,core,ratio,ratio_err,resolved,pass,sigmas,beckmann_ratio,first_order_ratio,floor,expected_gt,alias,power_law_fine\n",
    );
    for r in results {
        for b in &r.bins {
            let v = random::verdict(b, r.floor);
            let _ = writeln!(
                s,
                "{},{},{},{:.6e},{},{:.6e},{:.6e},{:.3},{:.3},{},{:.8e},{:.8e},{:.8e},{:.8e},{:.8e},{},{},{:.4},{:.8e},{:.8e},{:.6e},{:.8e},{:.8e},{:.8e}",
                r.case.name,
                model_kind(r),
                r.case.theta_i_deg,
                r.roughness,
                b.cut,
                b.q,
                b.u_nominal,
                b.lambda_nm,
                b.theta_o_deg,
                b.points,
                b.gt,
                b.gt_se,
                b.core,
                b.ratio(),
                b.ratio() * b.rel_err(),
                v.resolved as u8,
                v.pass as u8,
                v.sigmas,
                b.beckmann / b.gt,
                b.first_order / b.gt,
                r.floor,
                b.expected_gt(),
                b.alias,
                b.power_law
            );
        }
    }
    s
}

pub fn periodic_csv(results: &[PeriodicResult]) -> String {
    let mut s = String::from(
        "case,theta_i,order,cut,qx,qy,offset_l,lambda_nm,theta_o,gt,gt_err,core,ratio,resolved,pass\n",
    );
    for r in results {
        for p in &r.points {
            let (res, pass) = periodic::verdict(p, r.peak_max);
            let _ = writeln!(
                s,
                "{},{},{},{},{:.6e},{:.6e},{:.4},{:.3},{:.3},{:.10e},{:.3e},{:.10e},{:.10e},{},{}",
                r.case.name,
                r.case.theta_i_deg,
                p.order,
                p.cut,
                p.qx,
                p.qy,
                p.offset_l,
                p.lambda_nm,
                p.theta_o_deg,
                p.gt,
                p.gt_err,
                p.core,
                p.core / p.gt,
                res as u8,
                pass as u8
            );
        }
    }
    s
}

pub fn scan_csv(results: &[PeriodicResult]) -> String {
    let mut s = String::from("case,qx,gt,core,peak_max\n");
    for r in results {
        for &(q, gt, core) in &r.scan {
            let _ = writeln!(
                s,
                "{},{:.6e},{:.8e},{:.8e},{:.6e}",
                r.case.name, q, gt, core, r.peak_max
            );
        }
    }
    s
}

pub fn calibration_csv(results: &[RandomResult]) -> String {
    let mut s = String::from("case,quantity,target,ensemble,sample_mean,sample_se\n");
    for r in results {
        for (name, t, e, m, se) in &r.calibration.entries {
            let _ = writeln!(
                s,
                "{},{},{:.8e},{:.8e},{:.8e},{:.3e}",
                r.case.name, name, t, e, m, se
            );
        }
    }
    s
}

/// Summary numbers of a case (random or height map) over its resolved bins.
#[derive(Clone, Debug, Default)]
pub struct Summary {
    pub available: bool,
    pub bins: usize,
    pub resolved: usize,
    pub failed: usize,
    pub max_dev: f64,
    /// median |ratio - 1|.
    pub median_dev: f64,
    pub max_sigmas: f64,
    /// mean of ((ratio - 1) / rel_err)^2.
    pub chi2_dof: f64,
    /// max |core / E[GT] - 1| over the resolved bins (deterministic;
    /// random cases only).
    pub max_dev_expected: f64,
    pub within1: f64,
    pub within2: f64,
    /// Resolved bins beyond 3 sigma (expected: 0.27% of them).
    pub beyond3: usize,
    devs: Vec<f64>,
}

impl Summary {
    pub fn new(bins: usize, available: bool) -> Summary {
        Summary {
            available,
            bins,
            ..Default::default()
        }
    }

    /// One resolved bin compared: |ratio - 1|, that in standard errors,
    /// and the bin's verdict.
    pub fn add(&mut self, dev: f64, sigmas: f64, pass: bool) {
        self.resolved += 1;
        self.failed += (!pass) as usize;
        self.devs.push(dev);
        self.max_dev = self.max_dev.max(dev);
        self.max_sigmas = self.max_sigmas.max(sigmas);
        self.chi2_dof += sigmas * sigmas;
        self.within1 += (sigmas <= 1.0) as usize as f64;
        self.within2 += (sigmas <= 2.0) as usize as f64;
        self.beyond3 += (sigmas > 3.0) as usize;
    }

    /// The means and the median, once every bin is added.
    pub fn finish(mut self) -> Summary {
        if !self.devs.is_empty() {
            let n = self.devs.len() as f64;
            self.chi2_dof /= n;
            self.within1 /= n;
            self.within2 /= n;
            self.devs.sort_by(f64::total_cmp);
            self.median_dev = self.devs[self.devs.len() / 2];
        }
        self
    }
}

pub fn summarise(r: &RandomResult) -> Summary {
    let available = !r.core_route.starts_with(crate::core::UNAVAILABLE);
    let mut s = Summary::new(r.bins.len(), available);
    for b in &r.bins {
        let v = random::verdict(b, r.floor);
        if !v.resolved {
            continue;
        }
        if !available {
            s.resolved += 1;
            continue;
        }
        s.add((b.ratio() - 1.0).abs(), v.sigmas, v.pass);
        s.max_dev_expected = s
            .max_dev_expected
            .max((b.core / b.expected_gt() - 1.0).abs());
    }
    s.finish()
}

fn grid_text(r: &RandomResult) -> String {
    let g = r.case.grid;
    format!("{}x{}, dx={:.3}", g.nx, g.ny, g.dx)
}

/// Ratio range (min, median, max) of an approximation over resolved bins.
fn approx_range(
    r: &RandomResult,
    pick: impl Fn(&random::BinResult) -> f64,
) -> Option<(f64, f64, f64)> {
    let mut v: Vec<f64> = r
        .bins
        .iter()
        .filter(|b| random::verdict(b, r.floor).resolved)
        .map(|b| pick(b) / b.gt)
        .collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    Some((v[0], v[v.len() / 2], v[v.len() - 1]))
}

pub fn markdown(
    random: &[RandomResult],
    periodic: &[PeriodicResult],
    maps: &[MapResult],
    header: &str,
    total_seconds: f64,
) -> String {
    let mut s = String::new();
    s.push_str(header);
    let _ = writeln!(
        s,
        "\n## Summary: random surfaces (core / ground truth over resolved bins)\n"
    );
    s.push_str("| case | roughness g (a^2 s^2/2 for fBm) | grid | realisations | time (s) | bins | resolved | failed | max abs(ratio-1) | max dev / MC err | chi2/dof | chi2/dof, bin covariance (dof) | GT vs E[GT]: chi2/dof, bin covariance | max abs(core / E[GT] - 1) | within 1 sigma | within 2 sigma | beyond 3 sigma |\n");
    s.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for r in random {
        let m = summarise(r);
        if !m.available {
            let _ = writeln!(
                s,
                "| {} | {:.3} | {} | {} | {:.1} | {} | {} | core n/a | - | - | - | - | - | - | - | - | - |",
                r.case.name,
                r.roughness,
                grid_text(r),
                r.case.realisations,
                r.seconds,
                m.bins,
                m.resolved
            );
            continue;
        }
        let _ = writeln!(
            s,
            "| {} | {:.3} | {} | {} | {:.1} | {} | {} | {} | {:.4} | {:.2} | {:.2} | {:.2} ({}) | {:.2} | {:.1e} | {:.0}% | {:.0}% | {} |",
            r.case.name,
            r.roughness,
            grid_text(r),
            r.case.realisations,
            r.seconds,
            m.bins,
            m.resolved,
            m.failed,
            m.max_dev,
            m.max_sigmas,
            m.chi2_dof,
            r.chi2_cov / r.chi2_cov_dof.max(1) as f64,
            r.chi2_cov_dof,
            r.chi2_cov_expected / r.chi2_cov_dof.max(1) as f64,
            m.max_dev_expected,
            100.0 * m.within1,
            100.0 * m.within2,
            m.beyond3
        );
    }
    let (mut tot, mut w1, mut w2, mut b3, mut failed) = (0usize, 0.0, 0.0, 0usize, 0usize);
    for r in random {
        let m = summarise(r);
        if m.available {
            tot += m.resolved;
            w1 += m.within1 * m.resolved as f64;
            w2 += m.within2 * m.resolved as f64;
            b3 += m.beyond3;
            failed += m.failed;
        }
    }
    if tot > 0 {
        let _ = writeln!(
            s,
            "\nAll random cases: {tot} resolved bins, {failed} failed; {:.1}% within 1 sigma (Gaussian: 68.3%), {:.1}% within 2 sigma (95.4%), {b3} beyond 3 sigma (expected {:.1}).",
            100.0 * w1 / tot as f64,
            100.0 * w2 / tot as f64,
            0.0027 * tot as f64
        );
    }
    let _ = writeln!(s, "\n## Calibration of the synthetic surfaces\n");
    s.push_str("'ensemble' is the exact expectation for the synthesis (from its filter amplitudes); 'sample' is measured on the first realisations (mean +- standard error over realisations). Gaussian: sigma = sqrt(C(0)), T from a least-squares fit of ln C(r)/C(0) = -r^2/T^2 for r in [0.3 T, 1.5 T] along each axis. Fractal: s from ln D(r) - 2H ln(r/L) averaged over lags r in [r_c/4, 4 r_c] (the scales where a^2 D/2 ~ 1), H_eff the local log-log slope / 2, r_c recomputed with the measured s. The core is evaluated with the target sigma, T (Gaussian) and with the ensemble-measured s (fractal).\n\n");
    s.push_str("| case | quantity | target | ensemble | ensemble/target | sample (mean +- SE) |\n|---|---|---|---|---|---|\n");
    for r in random {
        for (name, t, e, m, se) in &r.calibration.entries {
            let sample = if *m != 0.0 {
                format!("{m:.5} +- {se:.5}")
            } else {
                "-".into()
            };
            let rel = if *t != 0.0 {
                format!("{:.5}", e / t)
            } else {
                "-".into()
            };
            let _ = writeln!(
                s,
                "| {} | {} | {:.5} | {:.5} | {} | {} |",
                r.case.name, name, t, e, rel, sample
            );
        }
    }
    let _ = writeln!(
        s,
        "\n## Where the closed-form approximations hold (Gaussian)\n"
    );
    s.push_str("Ratio approximation / ground truth over the resolved bins: min, median, max. Beckmann = the large-g limit F^2 D_Beckmann(alpha = 2 sigma / T) / (4 cos_i cos_o); first order = the m = 1 term alone.\n\n");
    s.push_str("| case | g | core (min / median / max) | Beckmann (min / median / max) | first order (min / median / max) |\n|---|---|---|---|---|\n");
    for r in random {
        if matches!(r.case.model, RandomModel::Fbm { .. }) {
            continue;
        }
        let f = |o: Option<(f64, f64, f64)>| match o {
            Some((a, b, c)) => format!("{a:.3} / {b:.3} / {c:.3}"),
            None => "-".into(),
        };
        let _ = writeln!(
            s,
            "| {} | {:.3} | {} | {} | {} |",
            r.case.name,
            r.roughness,
            f(approx_range(r, |b| b.core)),
            f(approx_range(r, |b| b.beckmann)),
            f(approx_range(r, |b| b.first_order))
        );
    }
    if !periodic.is_empty() {
        let _ = writeln!(
            s,
            "\n## Periodic profiles (deterministic; GT Richardson-extrapolated from M and 2M samples per period, error = |GT(2M) - GT(M)| / 3)\n"
        );
        s.push_str("| case | a = k w | time (s) | points | resolved | failed | max abs(ratio-1) at the order centres | max abs(ratio-1) within 1.5/l of the centres |\n|---|---|---|---|---|---|---|---|\n");
        for r in periodic {
            let (mut res, mut fail, mut dc, mut dall) = (0, 0, 0.0f64, 0.0f64);
            for p in &r.points {
                let (rv, pv) = periodic::verdict(p, r.peak_max);
                if rv {
                    res += 1;
                    if !pv {
                        fail += 1;
                    }
                    let d = (p.core / p.gt - 1.0).abs();
                    dall = dall.max(d);
                    if p.offset_l == 0.0 {
                        dc = dc.max(d);
                    }
                }
            }
            let _ = writeln!(
                s,
                "| {} | {:.3} | {:.2} | {} | {} | {} | {:.2e} | {:.2e} |",
                r.case.name,
                r.a,
                r.seconds,
                r.points.len(),
                res,
                fail,
                dc,
                dall
            );
        }
        s.push_str("\nPer order, at the order's centre (q_x = 2 pi n / period, q_y = 0):\n\n| case | order | lambda (nm) | theta_o (deg) | GT <abs(P)^2>/A (um^2) | core / GT | numerical err |\n|---|---|---|---|---|---|---|\n");
        for r in periodic {
            for p in r
                .points
                .iter()
                .filter(|p| p.cut == "x" && p.offset_l == 0.0)
            {
                if !periodic::verdict(p, r.peak_max).0 {
                    continue;
                }
                let _ = writeln!(
                    s,
                    "| {} | {} | {:.1} | {:.1} | {:.6e} | {:.7} | {:.1e} |",
                    r.case.name,
                    p.order,
                    p.lambda_nm,
                    p.theta_o_deg,
                    p.gt,
                    p.core / p.gt,
                    p.gt_err / p.gt
                );
            }
        }
    }
    if !maps.is_empty() {
        s.push_str(&map_markdown(maps));
    }
    let _ = writeln!(s, "\n## Per-bin ratios, random surfaces\n");
    s.push_str("ratio = core / ground truth +- its Monte Carlo standard error; `R` resolved, `-` not resolved (MC error >= 2% or within 100x of the aliasing floor), `FAIL` resolved and outside 4 sigma or 5%. q in 1/um (for axis cuts: rho = |(q_x T_x, q_y T_y)|), u = |q| / k0.\n");
    for r in random {
        let _ = writeln!(
            s,
            "\n### {}\n\ncore: `{}` via {}; floor {:.3e} um^2\n",
            r.case.name, r.core_json, r.core_route, r.floor
        );
        s.push_str("| cut | q | u | lambda (nm) | theta_o (deg) | points | GT (um^2) | core / GT | core / E[GT] | status |\n|---|---|---|---|---|---|---|---|---|---|\n");
        for b in &r.bins {
            let v = random::verdict(b, r.floor);
            let st = if !v.resolved {
                "-"
            } else if v.pass {
                "R"
            } else {
                "FAIL"
            };
            let _ = writeln!(
                s,
                "| {} | {:.4} | {:.4} | {:.1} | {:.1} | {} | {:.4e} | {:.4} +- {:.4} | {:.6} | {} |",
                b.cut,
                b.q,
                b.u_nominal,
                b.lambda_nm,
                b.theta_o_deg,
                b.points,
                b.gt,
                b.ratio(),
                b.ratio() * b.rel_err(),
                b.core / b.expected_gt(),
                st
            );
        }
    }
    let _ = writeln!(s, "\nTotal run time: {total_seconds:.0} s (single thread).");
    s
}

/// Per bin of every height-map case: case, bin centre, wavelength, cells,
/// ground truth and its standard error, core, resolved.
pub fn map_csv(results: &[MapResult]) -> String {
    let mut s = String::from(
        "case,qx_per_um,qy_per_um,lambda_nm,cells,gt_um2,gt_se_um2,core_um2,resolved\n",
    );
    for r in results {
        for b in &r.bins {
            let _ = writeln!(
                s,
                "{},{:.5},{:.5},{:.2},{},{:.6e},{:.6e},{:.6e},{}",
                r.case.name,
                b.qx,
                b.qy,
                b.lambda_nm,
                b.cells,
                b.gt,
                b.gt_se,
                b.core,
                heightmap::verdict(b, r.peak).resolved as u8
            );
        }
    }
    s
}

fn map_source(r: &MapResult) -> String {
    match &r.case.source {
        MapSource::Npy(path) => format!(
            "`scenes/heightmaps/{}`",
            path.file_name().map_or("?".into(), |f| f.to_string_lossy())
        ),
        MapSource::Gaussian {
            sigma_um, corr_um, ..
        } => format!("synthetic Gaussian, sigma {sigma_um} um, T {corr_um} um"),
        MapSource::Grating {
            profile,
            period_um,
            depth_um,
            noise_um,
            ..
        } => format!(
            "synthetic {profile:?} grating, period {period_um} um, {depth_um} um peak to peak, noise {noise_um} um rms"
        ),
    }
}

fn map_markdown(maps: &[MapResult]) -> String {
    let mut s = String::new();
    s.push_str(
        "\n## Height maps (`surface: heightmap`; one map, its own tiles as the realisations)\n\n",
    );
    s.push_str("The map is written to .npy (synthetic maps) or read from the demo scene's folder, and given to the core as a file (`pixel_um` 0.08, `tile_px` the tool's tile, fresnel 1). The tool reads, detrends and transforms it with its own code: non-overlapping Hann tiles, P(q) = dx^2 sum W (exp(i a h) - c) exp(i q . x), bins of frequency cells (rings about the mirror for isotropic maps, square blocks for the others; the zero-frequency cell left out), the tiles' mean and its standard error; the core at each cell's exact (wo, lambda) for the case's a = k w. Resolved: standard error at most 5% and at least 1e-4 of the brightest bin. A case passes when no resolved bin is beyond 4 standard errors and chi2/dof is at most 2. The core's half-overlapping tiles include the tool's, so the two estimates share data (about 0.8 sigma of spread expected). Coherent: the map's abs(mean exp(i a h))^2 against the core's coherent lobe.\n\n![core / Kirchhoff per resolved bin of each map](img/kirchhoff_heightmap.png)\n\n");
    s.push_str("| case | map | size | tile (tiles) | g | bins | resolved | failed | median abs(ratio-1) | max abs(ratio-1) | max dev / MC err | chi2/dof | coherent core / map - 1 | passes |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for r in maps {
        let m = heightmap::summarise(r);
        let _ = writeln!(
            s,
            "| {} | {} | {}x{} | {} ({}) | {:.3} | {} | {} | {} | {:.4} | {:.4} | {:.2} | {:.2} | {:.1e} | {} |",
            r.case.name,
            map_source(r),
            r.nx,
            r.ny,
            r.case.tile_px,
            r.tiles,
            r.roughness,
            m.bins,
            m.resolved,
            m.failed,
            m.median_dev,
            m.max_dev,
            m.max_sigmas,
            m.chi2_dof,
            r.coherent_core / r.coherent_gt - 1.0,
            if heightmap::passes(&m) { "yes" } else { "**no**" }
        );
    }
    s
}

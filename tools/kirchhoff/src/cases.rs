//! The case lists: the full run (docs/kirchhoff.md) and the reduced CI run.

use crate::heightmap::{GratingProfile, MapBins, MapCase, MapSource};
use crate::optics;
use crate::periodic::{PeriodicCase, ProfileKind};
use crate::random::{dq, gaussian_grid, linear_edges, log_edges, Binning, RandomCase};
use crate::synth::{Grid, RandomModel};

pub const LAMBDA0_NM: f64 = 550.0;

/// Size knobs of a run.
#[derive(Clone, Copy, Debug)]
pub struct Budget {
    /// Field extent in correlation lengths (Gaussian).
    pub extent: f64,
    /// Target number of realisations x grid points per case.
    pub point_realisations: f64,
    pub min_realisations: usize,
    pub max_realisations: usize,
    pub calib_realisations: usize,
    /// Grid steps per r_c (fractal).
    pub fbm_per_rc: f64,
}

pub const FULL: Budget = Budget {
    extent: 16.0,
    point_realisations: 1.5e8,
    min_realisations: 48,
    max_realisations: 10000,
    calib_realisations: 32,
    fbm_per_rc: 16.0,
};

pub const CI: Budget = Budget {
    extent: 12.0,
    point_realisations: 2.5e7,
    min_realisations: 64,
    max_realisations: 1000,
    calib_realisations: 16,
    fbm_per_rc: 16.0,
};

fn realisations(b: &Budget, grid: &Grid) -> usize {
    let r = (b.point_realisations / grid.len() as f64) as usize;
    let r = r.clamp(b.min_realisations, b.max_realisations);
    r + r % 2
}

pub fn gaussian_case(
    sigma_over_lambda: f64,
    tx: f64,
    ty: f64,
    theta_i_deg: f64,
    b: &Budget,
    seed: u64,
) -> RandomCase {
    let sigma = sigma_over_lambda * LAMBDA0_NM / 1000.0;
    let wi = optics::incidence(theta_i_deg);
    let a = 2.0 * optics::wavenumber(LAMBDA0_NM) * wi.z;
    let g = (sigma * a).powi(2);
    let grid = gaussian_grid(tx, ty, g, b.extent);
    let lobe = 6.0 * g.max(1.0).sqrt();
    let q_nyq = grid.q_nyquist();
    let (binning, kind) = if tx == ty {
        let q_max = (lobe / tx).min(0.5 * q_nyq);
        let d = dq(&grid);
        let width = d.max(q_max / 20.0);
        (
            Binning::Annuli {
                edges: linear_edges(0.5 * d, width, q_max),
            },
            "iso",
        )
    } else {
        let d = dq(&grid) * tx; // grid step in rho = q T units
        let rho_max = lobe.min(0.5 * q_nyq * tx.min(ty));
        let width = (1.5 * d).max(rho_max / 16.0);
        (
            Binning::AxisCuts {
                tx,
                ty,
                half_angle_deg: 20.0,
                edges: linear_edges(0.5 * d, width, rho_max),
            },
            "aniso",
        )
    };
    RandomCase {
        name: format!("gauss-{kind} s/l={sigma_over_lambda} th={theta_i_deg}"),
        model: RandomModel::Gaussian { sigma, tx, ty },
        grid,
        realisations: realisations(b, &grid),
        calib_realisations: b.calib_realisations,
        theta_i_deg,
        lambda0_nm: LAMBDA0_NM,
        binning,
        seed,
        fbm_completion: Default::default(),
    }
}

pub fn fbm_case(
    hurst: f64,
    s_over_lambda: f64,
    lag: f64,
    theta_i_deg: f64,
    b: &Budget,
    seed: u64,
) -> RandomCase {
    let s = s_over_lambda * LAMBDA0_NM / 1000.0;
    let wi = optics::incidence(theta_i_deg);
    let a = 2.0 * optics::wavenumber(LAMBDA0_NM) * wi.z;
    let rc = lag * (2.0 / (a * a * s * s)).powf(0.5 / hurst);
    let dx = rc / b.fbm_per_rc;
    // R(L/2) = exp(-(L / 2 r_c)^(2H)) below 1e-6.
    let extent = 2.0 * rc * 14f64.powf(0.5 / hurst);
    let n = (((extent / dx) / 16.0).ceil() as usize * 16).max(256);
    let grid = Grid { nx: n, ny: n, dx };
    let d = dq(&grid);
    let q_max = (0.25 * grid.q_nyquist()).min(1.0 / (crate::random::FBM_FIT_RANGE.0 * rc));
    RandomCase {
        name: format!("fbm H={hurst} s/l={s_over_lambda} th={theta_i_deg}"),
        model: RandomModel::Fbm { hurst, s, lag },
        grid,
        realisations: realisations(b, &grid),
        calib_realisations: b.calib_realisations,
        theta_i_deg,
        lambda0_nm: LAMBDA0_NM,
        binning: Binning::Annuli {
            edges: log_edges(0.5 * d, q_max, 18),
        },
        seed,
        fbm_completion: Default::default(),
    }
}

pub fn full_random() -> Vec<RandomCase> {
    full_random_with(&FULL)
}

/// The full case list with another budget (experiments: `--fbm-per-rc`).
pub fn full_random_with(b: &Budget) -> Vec<RandomCase> {
    let mut v = Vec::new();
    let mut seed = 1000;
    for &th in &[0.0, 40.0] {
        for &r in &[0.01, 0.03, 0.1, 0.3, 1.0] {
            seed += 1;
            v.push(gaussian_case(r, 5.0, 5.0, th, b, seed));
        }
    }
    for &th in &[0.0, 40.0] {
        for &r in &[0.01, 0.1, 0.3] {
            seed += 1;
            v.push(gaussian_case(r, 3.0, 12.0, th, b, seed));
        }
    }
    seed += 1;
    v.push(gaussian_case(1.0, 6.0, 18.0, 0.0, b, seed));
    for &th in &[0.0, 40.0] {
        for &h in &[0.5, 0.7, 0.9] {
            for &r in &[0.05, 0.2] {
                seed += 1;
                v.push(fbm_case(h, r, 1.0, th, b, seed));
            }
        }
    }
    v
}

pub fn full_periodic() -> Vec<PeriodicCase> {
    let mut v = Vec::new();
    for &th in &[0.0, 40.0] {
        for &l in &[3.75, 25.0] {
            v.push(PeriodicCase {
                name: format!("cd-rect l={l} th={th}"),
                profile: ProfileKind::Rect {
                    height: 0.15,
                    width: 0.5,
                },
                period: 2.5,
                coherence: l,
                theta_i_deg: th,
                lambda0_nm: LAMBDA0_NM,
                samples_per_period: 1000,
                extent: 24.0,
            });
        }
        v.push(PeriodicCase {
            name: format!("sine b=0.5 l=10 th={th}"),
            profile: ProfileKind::Sine { height: 0.5 },
            period: 2.0,
            coherence: 10.0,
            theta_i_deg: th,
            lambda0_nm: LAMBDA0_NM,
            samples_per_period: 256,
            extent: 24.0,
        });
    }
    v
}

/// The reduced CI list (also used by tests/ground_truth.rs).
pub fn ci_random() -> Vec<RandomCase> {
    let b = &CI;
    vec![
        gaussian_case(0.03, 5.0, 5.0, 0.0, b, 11),
        gaussian_case(0.1, 5.0, 5.0, 40.0, b, 12),
        gaussian_case(0.3, 5.0, 5.0, 0.0, b, 13),
        gaussian_case(0.1, 3.0, 12.0, 40.0, b, 14),
        fbm_case(0.7, 0.2, 1.0, 0.0, b, 15),
    ]
}

pub fn ci_periodic() -> Vec<PeriodicCase> {
    vec![PeriodicCase {
        name: "cd-rect l=3.75 th=40".into(),
        profile: ProfileKind::Rect {
            height: 0.15,
            width: 0.5,
        },
        period: 2.5,
        coherence: 3.75,
        theta_i_deg: 40.0,
        lambda0_nm: LAMBDA0_NM,
        samples_per_period: 200,
        extent: 24.0,
    }]
}

/// The height-map cases: maps the tool synthesises (written to .npy for the
/// core), at normal and oblique incidence.
pub fn ci_maps() -> Vec<MapCase> {
    let gaussian = MapSource::Gaussian {
        sigma_um: 0.05,
        corr_um: 1.0,
        n: 2048,
        seed: 21,
    };
    let grating = |profile, period_um, depth_um, n, seed| MapSource::Grating {
        profile,
        period_um,
        depth_um,
        noise_um: 0.005,
        noise_corr_um: 0.5,
        n,
        seed,
    };
    let mut v: Vec<MapCase> = [0.0, 40.0]
        .into_iter()
        .map(|theta| {
            let name = format!("map gaussian s=0.05 T=1 th={theta}");
            map_case(&name, gaussian.clone(), 256, theta, MapBins::Rings(1))
        })
        .collect();
    v.extend([
        map_case(
            "map sine 1.6um pp=0.12 th=0",
            grating(GratingProfile::Sine, 1.6, 0.12, 1024, 22),
            256,
            0.0,
            MapBins::Blocks(2),
        ),
        map_case(
            "map blazed 2.56um depth=0.1 th=20",
            grating(GratingProfile::Sawtooth, 2.56, 0.1, 512, 23),
            128,
            20.0,
            MapBins::Blocks(2),
        ),
    ]);
    v
}

/// The CI maps and the demo scene's maps (scenes/heightmaps/*.npy, written
/// by `make heightmaps`), where they exist.
pub fn full_maps() -> Vec<MapCase> {
    let mut v = ci_maps();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/heightmaps");
    for (name, bins) in [
        ("gaussian", MapBins::Rings(1)),
        ("fractal", MapBins::Rings(2)),
        ("grating", MapBins::Blocks(2)),
        ("scales", MapBins::Blocks(2)),
    ] {
        let file = dir.join(format!("{name}.npy"));
        if file.exists() {
            for theta in [0.0, 40.0] {
                v.push(map_case(
                    &format!("demo map {name} th={theta}"),
                    MapSource::Npy(file.clone()),
                    256,
                    theta,
                    bins,
                ));
            }
        }
    }
    v
}

fn map_case(name: &str, source: MapSource, tile_px: usize, theta: f64, bins: MapBins) -> MapCase {
    MapCase {
        name: name.into(),
        source,
        pixel_um: 0.08,
        tile_px,
        theta_i_deg: theta,
        lambda0_nm: LAMBDA0_NM,
        bins,
    }
}

//! The height-map model's programs (`program.rs`) against its native
//! path: eval (spectral and RGB) in f32 and f64, the coherent lobe and its
//! probability, the sampling programs by chi-square and against the
//! native strategy's densities, and hostile inputs.

use super::tests::{gaussian_map_file, map_json, material, write_npy};
use crate::benchmark::SplitMix64 as Rng;
use crate::material::program::ProgramKind;
use crate::testing::chi2::chi2_fit;
use crate::testing::programs::{
    eval_rgb_errors, eval_spectral_errors, exported, pairs, ProgramSampler,
};
use crate::Brdf;
use glam::DVec3;
use std::f64::consts::PI;

/// A sine grating map with noise (the sharpest spectrum the model meets)
/// besides the Gaussian one.
fn grating_file() -> std::path::PathBuf {
    static FILE: std::sync::OnceLock<std::path::PathBuf> = std::sync::OnceLock::new();
    FILE.get_or_init(|| {
        let n = 256;
        let mut rng = Rng(5);
        let h: Vec<f64> = (0..n * n)
            .map(|i| {
                0.06 * (2.0 * PI * (i % n) as f64 * 0.08 / 1.6).sin()
                    + 0.002 * (rng.three()[0] - 0.5)
            })
            .collect();
        write_npy("grating.npy", n, n, &h)
    })
    .clone()
}

fn materials() -> Vec<Brdf> {
    vec![
        material(&map_json(&gaussian_map_file(), r#","fresnel":"aluminium""#)),
        material(&map_json(
            &grating_file(),
            r#","fresnel":"gold","rgb_nodes":12"#,
        )),
    ]
}

/// Pairs where the lobe is: around the mirror of random incidences.
fn lobe_pairs(n: usize, seed: u64) -> Vec<(DVec3, DVec3)> {
    let mut rng = Rng(seed);
    (0..n)
        .map(|_| {
            let [a, b, c] = rng.three();
            let [d, _, _] = rng.three();
            let theta = 1.3 * a;
            let wi = DVec3::new(
                theta.sin() * (6.0 * b).cos(),
                theta.sin() * (6.0 * b).sin(),
                theta.cos(),
            );
            let tilt = 0.3 * c;
            let wo = (DVec3::new(-wi.x, -wi.y, wi.z)
                + DVec3::new(tilt * (6.0 * d).cos(), tilt * (6.0 * d).sin(), 0.0))
            .normalize();
            (wi, if wo.z > 0.01 { wo } else { DVec3::Z })
        })
        .collect()
}

#[test]
fn eval_programs_match_native() {
    for brdf in materials() {
        let mut all = pairs(400, 7);
        all.extend(lobe_pairs(600, 9));
        let spectral = eval_spectral_errors(&brdf, &all, 3);
        let rgb = eval_rgb_errors(&brdf, &all);
        println!(
            "spectral: f32 {:.2e} f64 {:.2e} ({} checked); rgb: f32 {:.2e} f64 {:.2e} ({} checked)",
            spectral.max_rel_f32,
            spectral.max_rel_f64,
            spectral.checked,
            rgb.max_rel_f32,
            rgb.max_rel_f64,
            rgb.checked
        );
        assert!(spectral.checked > 300 && rgb.checked > 300);
        // f64: the same reads, with the program's f32 constants (1 /
        // kappa_0, the tile's length, the RGB nodes' k): measured 1.0e-6
        // (Gaussian map) and 6.9e-5 (the grating's steep peaks, RGB: the
        // geometric blend between nodes turns a shift dt of the node
        // weight into a relative error dt ln(e1 / e0), 2.5e-5 with the
        // linear blend before); f32: the table coordinates' rounding on
        // top, 6.4e-6 and 3.1e-4.
        assert!(spectral.max_rel_f64 < 1.5e-4, "{}", spectral.max_rel_f64);
        assert!(rgb.max_rel_f64 < 1.5e-4, "{}", rgb.max_rel_f64);
        assert!(spectral.max_rel_f32 < 1e-3, "{}", spectral.max_rel_f32);
        assert!(rgb.max_rel_f32 < 1e-3, "{}", rgb.max_rel_f32);
    }
}

/// The coherent programs: reflectance and probability as the native
/// `coherent_*` and the strategy's.
#[test]
fn coherent_programs_match_native() {
    for brdf in materials() {
        let spectral = exported(&brdf, ProgramKind::CoherentSpectral).unwrap();
        let rgb = exported(&brdf, ProgramKind::CoherentRgb).unwrap();
        let mut worst: f64 = 0.0;
        for i in 0..40 {
            let theta = 1.5 * i as f64 / 40.0;
            let wi = DVec3::new(theta.sin() * 0.6, theta.sin() * 0.8, theta.cos());
            for lambda in [380.0, 450.0, 550.0, 700.0, 820.0] {
                let out = spectral.run::<f64>(&[wi.x, wi.y, wi.z, lambda]);
                let native = brdf.coherent_spectral(wi, lambda);
                let p = brdf.sampler(wi, Some(lambda)).coherent_probability();
                worst = worst.max((out[0] - native).abs()).max((out[1] - p).abs());
            }
            let out = rgb.run::<f64>(&[wi.x, wi.y, wi.z]);
            let native = brdf.coherent_rgb(wi);
            let p = brdf.sampler(wi, None).coherent_probability();
            for c in 0..3 {
                worst = worst.max((out[c] - native[c]).abs());
            }
            worst = worst.max((out[3] - p).abs());
        }
        println!("coherent programs against native: {worst:.2e}");
        // The program's constants are f32.
        assert!(worst < 1e-6, "{worst}");
    }
}

/// The sampling programs draw the native strategy's law: chi-square of
/// their samples against their pdf, and their pdf equals the native one
/// (two cases; `sampling_programs_sweep` runs more: the chi-square's
/// cubature of a piecewise-constant pdf through the interpreter takes up
/// to a minute a case).
#[test]
fn sampling_programs_pass_chi_square_and_match_native() {
    check_sampling_programs(&[(0.0, Some(600.0)), (60.0, None)]);
}

#[test]
#[ignore]
fn sampling_programs_sweep() {
    let mut cases = Vec::new();
    for theta in [0.0, 30.0, 60.0, 80.0] {
        for lambda in [Some(400.0), Some(600.0), Some(800.0), None] {
            cases.push((theta, lambda));
        }
    }
    check_sampling_programs(&cases);
}

fn check_sampling_programs(cases: &[(f64, Option<f64>)]) {
    let brdf = &materials()[0];
    let mut failures = Vec::new();
    for (k, &(theta, lambda)) in cases.iter().enumerate() {
        let l = 0;
        let t = f64::to_radians(theta);
        let wi = DVec3::new(t.sin() * 0.8, t.sin() * 0.6, t.cos());
        {
            let sampler = ProgramSampler::new(brdf, wi, lambda);
            let native = brdf.sampler(wi, lambda);
            let mut worst: f64 = 0.0;
            for (_, wo) in lobe_pairs(300, 40 + k as u64) {
                let (a, b) = (
                    crate::testing::chi2::Sampler::pdf(&sampler, wo),
                    native.pdf(wo),
                );
                worst = worst.max((a - b).abs() / b.max(1e-3));
            }
            let fit = chi2_fit(&sampler, 71 + 10 * k as u64 + l as u64, 100_000);
            println!(
                "program sampling {theta} deg {lambda:?}: p = {:.4}, integral {:.5}, pdf vs native {worst:.1e}",
                fit.p_value, fit.integral
            );
            if !(fit.p_value > 0.01) || fit.integral > 1.0 + 2e-3 || worst > 1e-6 {
                failures.push(format!("{theta} {lambda:?}: p {} pdf {worst}", fit.p_value));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}

/// NaN, infinite and below-horizon inputs give finite, non-negative
/// outputs in f32.
#[test]
fn bad_inputs_give_finite_outputs() {
    let brdf = &materials()[1];
    let bad = [
        f64::NAN,
        f64::INFINITY,
        -f64::INFINITY,
        -1.0,
        0.0,
        1e-30,
        1e30,
    ];
    let mut rng = Rng(3);
    for kind in ProgramKind::ALL {
        let program = exported(brdf, kind).unwrap();
        for _ in 0..500 {
            let inputs: Vec<f32> = (0..program.n_inputs)
                .map(|_| {
                    let [a, b, _] = rng.three();
                    if a < 0.3 {
                        bad[(b * bad.len() as f64) as usize % bad.len()] as f32
                    } else {
                        (2.0 * b - 1.0) as f32 * if a > 0.9 { 900.0 } else { 1.0 }
                    }
                })
                .collect();
            for v in program.run::<f32>(&inputs) {
                assert!(v.is_finite(), "{kind:?} {inputs:?} -> {v}");
            }
        }
    }
}

//! The fractal model's programs (`program.rs`) against its native path:
//! eval (spectral and RGB) through the exported programs in f32 and f64,
//! the sampling programs by chi-square, their variance against the core's
//! strategies and cosine sampling, bad inputs, and the programs' sizes.

use crate::benchmark::SplitMix64 as Rng;
use crate::material::program::ProgramKind;
use crate::program::{Op, Program};
use crate::testing::chi2::chi2_fit;
use crate::testing::programs::{
    eval_rgb_errors, eval_spectral_errors, exported, pairs, ProgramSampler,
};
use crate::testing::{cosine_weights, mean_var, sampled_weights};
use crate::Brdf;
use glam::DVec3;

fn material(json: &str) -> Brdf {
    let json = crate::testing::stam_formula(json);
    Brdf::from_json(&json).unwrap_or_else(|e| panic!("{json}: {}", e.message))
}

/// The fractal materials of tests/materials.json, then a spread of hurst
/// 0.3 .. 1, sigma 0.02 .. 0.5 um, lag 0.5 .. 5 um, metals, a complex
/// index and constant Fresnel terms.
fn materials() -> Vec<(String, String)> {
    let shared: serde_json::Value =
        serde_json::from_str(include_str!("../../../../tests/materials.json")).expect("json");
    let mut out: Vec<(String, String)> = shared
        .as_array()
        .expect("a list")
        .iter()
        .filter(|m| m["model"] == "fractal")
        .map(|m| {
            (
                m["name"].as_str().unwrap().to_string(),
                m["params"].to_string(),
            )
        })
        .collect();
    assert!(
        out.len() >= 5,
        "tests/materials.json lists its fractal materials"
    );
    for (name, json) in [
        (
            "h0.3 s0.5 lag0.5",
            r#"{"surface":"fractal","hurst":0.3,"sigma_um":0.5,"lag_um":0.5}"#,
        ),
        (
            "h0.9 s0.02 lag5",
            r#"{"surface":"fractal","hurst":0.9,"sigma_um":0.02,"lag_um":5,"fresnel":0.8}"#,
        ),
        (
            "h0.5 s0.2 lag2 gold",
            r#"{"surface":"fractal","hurst":0.5,"sigma_um":0.2,"lag_um":2,"fresnel":"gold"}"#,
        ),
        (
            "h0.8 s0.02 lag0.5 alu",
            r#"{"surface":"fractal","hurst":0.8,"sigma_um":0.02,"lag_um":0.5,"fresnel":"aluminium"}"#,
        ),
        (
            "h0.35 s0.1 lag5 eta",
            r#"{"surface":"fractal","hurst":0.35,"sigma_um":0.1,"lag_um":5,"fresnel":{"eta":1.5,"k":3}}"#,
        ),
        (
            "h1 s0.05 lag1",
            r#"{"surface":"fractal","hurst":1.0,"sigma_um":0.05,"lag_um":1,"fresnel":0.9}"#,
        ),
        (
            "h0.7 s0.05 lag1 rgb12",
            r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.05,"lag_um":1,"rgb_nodes":12}"#,
        ),
    ] {
        out.push((name.to_string(), json.to_string()));
    }
    out
}

/// A direction normalised in f32 as the material's programs do
/// (`optics::program::upper_direction`).
fn normalised_f32(d: DVec3) -> DVec3 {
    let (x, y, z) = (d.x as f32, d.y as f32, d.z as f32);
    let inv = 1.0 / (x * x + y * y + z * z).sqrt();
    DVec3::new((x * inv) as f64, (y * inv) as f64, (z * inv) as f64)
}

/// The pair geometry the program computes (`PairProgram`: directions
/// normalised in f32, u, v, w their exact sums, 1 + wi.wo from them), in
/// f64 and without normalising again.
fn program_geometry(wi: DVec3, wo: DVec3) -> crate::geometry::PairGeometry {
    let (wi, wo) = (normalised_f32(wi), normalised_f32(wo));
    let sum = wi + wo;
    let one_plus_dot = 0.5 * sum.length_squared();
    crate::geometry::PairGeometry {
        u: -sum.x,
        v: -sum.y,
        w: -sum.z,
        cos_i: wi.z,
        cos_o: wo.z,
        geometric_factor: one_plus_dot * one_plus_dot / (wi.z * wo.z),
        cos_half: (0.5 * one_plus_dot).sqrt(),
        wi,
        wo,
    }
}

/// The spectral eval program in f32 against the native path at the
/// program's own pair geometry (this isolates the model's program from the
/// conditioning of the pair geometry, see `eval_spectral_matches_native`):
/// relative error where f >= 1e-6 of its peak.
fn spectral_errors_at_program_geometry(brdf: &Brdf, pairs: &[(DVec3, DVec3)], seed: u64) -> f64 {
    let program = exported(brdf, ProgramKind::EvalSpectral).expect("a program");
    let mut rng = Rng(seed);
    let rows: Vec<(f64, f64)> = pairs
        .iter()
        .map(|&(wi, wo)| {
            let lambda = (360.0 + 470.0 * rng.three()[0]) as f32 as f64;
            let (wi, wo) = (
                crate::testing::programs::round(wi),
                crate::testing::programs::round(wo),
            );
            let native = brdf.eval_spectral_at(&program_geometry(wi, wo), lambda);
            let x = [wi.x, wi.y, wi.z, wo.x, wo.y, wo.z, lambda].map(|v| v as f32);
            (native, program.run::<f32>(&x)[0] as f64)
        })
        .collect();
    let peak = rows.iter().map(|r| r.0).fold(1e-300, f64::max);
    rows.iter()
        .filter(|r| r.0 >= 1e-6 * peak)
        .map(|r| (r.1 - r.0).abs() / r.0)
        .fold(0.0, f64::max)
}

/// The spectral eval program against `Brdf::eval_spectral` (the shared
/// harness: f32 inputs, random, grazing and near-mirror pairs), within the
/// issue's 1e-4. Where both directions graze and wo is within ~1e-4 of the
/// mirror direction, |(u, v)| is a difference of f32 components near 1: an
/// f32 normalisation of the inputs before it would move f by up to ~5e-4
/// (printed for information), which `PairProgram` avoids.
#[test]
fn eval_spectral_matches_native() {
    let pairs = pairs(4000, 11);
    let mut worst_harness: f64 = 0.0;
    for (name, json) in materials() {
        let brdf = material(&json);
        let e = eval_spectral_errors(&brdf, &pairs, 5);
        let own = spectral_errors_at_program_geometry(&brdf, &pairs, 5);
        println!(
            "spectral {name:>24}: f32 {:.2e} (at directions normalised in f32 first: {own:.2e}), f64 {:.2e}, abs {:.2e} ({} checked)",
            e.max_rel_f32, e.max_rel_f64, e.max_abs_f32, e.checked
        );
        assert!(e.checked > 200, "{name}: {} pairs checked", e.checked);
        let _ = own;
        assert!(e.max_rel_f64 <= 1e-5, "{name}: f64 {}", e.max_rel_f64);
        worst_harness = worst_harness.max(e.max_rel_f32);
    }
    // PairProgram takes u, v from the inputs as given (exact where they
    // nearly cancel): the issue's 1e-4 against the native path itself.
    assert!(worst_harness <= 1e-4, "f32 {worst_harness}");
}

/// The RGB eval program in f32 against the native path at the program's
/// own pair geometry: errors relative to the pair's largest channel where
/// that is >= 1e-6 of the peak.
fn rgb_errors_at_program_geometry(brdf: &Brdf, pairs: &[(DVec3, DVec3)]) -> f64 {
    let program = exported(brdf, ProgramKind::EvalRgb).expect("a program");
    let shading = brdf.shading();
    let rows: Vec<([f64; 3], [f64; 3])> = pairs
        .iter()
        .map(|&(wi, wo)| {
            let (wi, wo) = (
                crate::testing::programs::round(wi),
                crate::testing::programs::round(wo),
            );
            let geom = program_geometry(wi, wo);
            let rgb = brdf.surface().reflectance_rgb(&shading, &geom);
            let native = crate::spectrum::gamut_map(rgb.map(|c| c * geom.geometric_factor));
            let x = [wi.x, wi.y, wi.z, wo.x, wo.y, wo.z].map(|v| v as f32);
            let out = program.run::<f32>(&x);
            (native, [0, 1, 2].map(|c| out[c] as f64))
        })
        .collect();
    let max3 = |c: &[f64; 3]| c[0].max(c[1]).max(c[2]);
    let peak = rows.iter().map(|r| max3(&r.0)).fold(1e-300, f64::max);
    rows.iter()
        .filter(|r| max3(&r.0) >= 1e-6 * peak)
        .map(|r| {
            (0..3)
                .map(|c| (r.1[c] - r.0[c]).abs() / max3(&r.0))
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
}

/// The RGB program uses the native rule (nodes, weights, Fresnel folded
/// in): at the program's geometry it agrees with the native path to f32
/// rounding, far inside the rule's documented error against the 1 nm
/// reference (docs/implementation.md: 2.0e-5 of the largest channel on the
/// survey's fractal material, 5.1e-3 on the rule's worst test spectrum
/// with 8 nodes). Against `eval_rgb` through the shared harness the
/// grazing near-mirror pairs add the geometry's f32 conditioning, as in
/// `eval_spectral_matches_native`.
#[test]
fn eval_rgb_matches_native() {
    let pairs = pairs(3000, 12);
    let mut worst_harness: f64 = 0.0;
    for (name, json) in materials() {
        let brdf = material(&json);
        let e = eval_rgb_errors(&brdf, &pairs);
        let own = rgb_errors_at_program_geometry(&brdf, &pairs);
        println!(
            "rgb {name:>24}: f32 {:.2e} (at directions normalised in f32 first: {own:.2e}), f64 {:.2e}, abs {:.2e} ({} checked)",
            e.max_rel_f32, e.max_rel_f64, e.max_abs_f32, e.checked
        );
        assert!(e.checked > 200, "{name}: {} pairs checked", e.checked);
        let _ = own;
        assert!(e.max_rel_f64 <= 1e-5, "{name}: f64 {}", e.max_rel_f64);
        worst_harness = worst_harness.max(e.max_rel_f32);
    }
    assert!(worst_harness <= 1e-4, "f32 {worst_harness}");
}

/// The spectral program's K near the mirror direction and at the exact
/// mirror (r = 0: the small-x series at y = -inf), where the pairs above
/// rarely go.
#[test]
fn eval_at_and_near_the_mirror() {
    let program = |b: &Brdf| exported(b, ProgramKind::EvalSpectral).unwrap();
    for (name, json) in materials() {
        let brdf = material(&json);
        let p = program(&brdf);
        for &cos_i in &[1.0, 0.7, 0.2, 0.03] {
            let sin_i = (1.0f64 - cos_i * cos_i).sqrt();
            let wi = DVec3::new(sin_i, 0.0, cos_i);
            for &d in &[0.0, 1e-4, 1e-3, 1e-2] {
                let wo = DVec3::new(-sin_i + d, d, cos_i).normalize();
                let wi32 = crate::testing::programs::round(wi);
                let wo32 = crate::testing::programs::round(wo);
                for &lambda in &[380.0, 550.0, 780.0] {
                    let native = brdf.eval_spectral(wi32, wo32, lambda);
                    let inputs = [wi32.x, wi32.y, wi32.z, wo32.x, wo32.y, wo32.z, lambda];
                    let got = p.run::<f64>(&inputs)[0];
                    let rel = (got - native).abs() / native.max(1e-300);
                    assert!(
                        rel < 1e-5 && native > 0.0,
                        "{name} cos {cos_i} d {d} {lambda} nm: {got} vs {native}"
                    );
                }
            }
        }
    }
}

/// The three parts of ln Phi (small-x series, table, large-x series) and
/// their switch points: the spectral program (f64 run, f32 tables) against
/// the native kernel along lines through the mirror direction, each part
/// hit many times.
#[test]
fn eval_across_the_profile_parts() {
    let mut tail_hits = 0;
    for (name, json) in materials() {
        let brdf = material(&json);
        let crate::models::Surface::Fractal(model) = brdf.surface() else {
            panic!("{name}: not fractal");
        };
        let f = model.surface();
        if f.hurst == 1.0 {
            continue;
        }
        let d = f.profile.diagnostics();
        let p = exported(&brdf, ProgramKind::EvalSpectral).unwrap();
        let (mut hits, mut worst) = ([0usize; 3], 0.0f64);
        for &cos_i in &[0.9f64, 0.4, 0.05, 0.005] {
            let wi = incidence(cos_i, 0.3);
            for j in 0..400 {
                let r = 1e-7 * (2e7f64).powf(j as f64 / 399.0);
                for (phi, lambda) in [(0.0f64, 380.0), (2.0, 550.0), (4.0, 780.0)] {
                    let (x, y) = (-wi.x - r * phi.cos(), -wi.y - r * phi.sin());
                    let z2 = 1.0 - x * x - y * y;
                    if z2 <= 1e-10 {
                        continue;
                    }
                    let wo = DVec3::new(x, y, z2.sqrt());
                    let g = crate::geometry::PairGeometry::new(wi, wo).unwrap();
                    let k = crate::spectrum::wavenumber_per_um(lambda);
                    let ln_y = k.ln() + 0.5 * g.uv_length_sq().ln() + f.ln_projected_scale(k, g.w);
                    let part = if ln_y < d.y_min {
                        0
                    } else if ln_y < d.y_max {
                        1
                    } else {
                        2
                    };
                    let native = brdf.eval_spectral(wi, wo, lambda);
                    let got = p.run::<f64>(&[wi.x, wi.y, wi.z, wo.x, wo.y, wo.z, lambda])[0];
                    if native > 1e-250 {
                        hits[part] += 1;
                        worst = worst.max((got - native).abs() / native);
                    }
                }
            }
        }
        println!("{name:>24}: parts hit {hits:?}, worst {worst:.2e}");
        // The tail lies beyond the hemisphere's reach for rough surfaces
        // but at the most grazing pairs: at least one hit each, many overall.
        assert!(
            hits[0] >= 10 && hits[1] >= 10 && hits[2] >= 1,
            "{name}: {hits:?}"
        );
        assert!(worst < 3e-6, "{name}: {worst}");
        tail_hits += hits[2];
    }
    assert!(tail_hits >= 1000, "{tail_hits} pairs in the large-x series");
}

fn mode_name(lambda: Option<f64>) -> String {
    match lambda {
        Some(l) => format!("{l} nm"),
        None => "RGB".into(),
    }
}

fn incidence(cos_t: f64, phi: f64) -> DVec3 {
    let sin_t = (1.0 - cos_t * cos_t).sqrt();
    DVec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
}

/// Chi-square of the sampling programs against their pdf program at
/// normal, oblique and grazing incidence, RGB and spectral (a low p is
/// re-tested once with 4x the samples and an independent seed, as the
/// native strategies' test does).
#[test]
fn chi2_sampling_programs() {
    let jsons = [
        r#"{"surface":"fractal","sigma_um":0.1,"hurst":0.8,"lag_um":0.5}"#,
        r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.05,"lag_um":1,"fresnel":0.9}"#,
        r#"{"surface":"fractal","hurst":0.3,"sigma_um":0.05,"lag_um":2,"fresnel":"gold"}"#,
        r#"{"surface":"fractal","hurst":1.0,"sigma_um":0.1,"lag_um":1}"#,
    ];
    let n = 100_000;
    let mut failures = Vec::new();
    for (m, json) in jsons.iter().enumerate() {
        let brdf = material(json);
        for (k, &cos_i) in [1.0, 0.5, 0.1].iter().enumerate() {
            let wi = incidence(cos_i, 0.7);
            for (l, lambda) in [None, Some(450.0), Some(650.0)].into_iter().enumerate() {
                let sampler = ProgramSampler::new(&brdf, wi, lambda);
                let seed = 100 * m as u64 + 10 * k as u64 + l as u64 + 3;
                let fit = chi2_fit(&sampler, seed, n);
                let label = format!("{json} cos {cos_i} {}", mode_name(lambda));
                println!(
                    "chi2 {label}: p = {:.4} (chi2 {:.1}, dof {}), integral {:.5}",
                    fit.p_value, fit.chi2, fit.dof, fit.integral
                );
                if fit.integral > 1.0 + 2e-3 {
                    failures.push(format!("{label}: integral {}", fit.integral));
                }
                if !(fit.p_value > 0.01) {
                    let again = chi2_fit(&sampler, seed + 7_777_777, 4 * n);
                    println!("    re-test: p = {:.4}", again.p_value);
                    if !(again.p_value > 0.01) {
                        failures.push(format!("{label}: p {} then {}", fit.p_value, again.p_value));
                    }
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}

/// A sampling program whose pdf is off fails the test above: the
/// chi-square of the RGB sampler against the 550 nm pdf (a lobe about
/// 10% narrower or wider) is rejected.
#[test]
fn chi2_rejects_a_mismatched_pdf() {
    let brdf = material(r#"{"surface":"fractal","sigma_um":0.05,"hurst":0.7,"lag_um":1}"#);
    let wi = incidence(0.5, 0.7);
    let good = ProgramSampler::new(&brdf, wi, Some(450.0));
    let off = ProgramSampler::new(&brdf, wi, Some(500.0));
    let fit = crate::testing::chi2::chi2_fit_against(&good, &off, 9, 100_000);
    println!(
        "450 nm samples against the 500 nm pdf: p = {:.3e}",
        fit.p_value
    );
    assert!(fit.p_value < 1e-6, "p = {}", fit.p_value);
}

/// Variance of the directional-albedo estimate f cos / pdf with the
/// sampling programs, with the core's strategies (`Brdf::sample`) and
/// with cosine sampling, at the same sample count (the estimator and
/// materials of examples/sampling_variance.rs, and the shared ones).
/// The programs must not be worse than cosine sampling and stay within
/// 2x of the core's strategies.
#[test]
fn sampling_variance_against_core_and_cosine() {
    let n = 100_000;
    let jsons = [
        (
            "H0.7 s0.05",
            r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.05,"lag_um":1,"fresnel":0.9}"#,
        ),
        (
            "H0.35 s0.2",
            r#"{"surface":"fractal","hurst":0.35,"sigma_um":0.2,"lag_um":1,"fresnel":0.9}"#,
        ),
        (
            "H0.8 s0.1 l0.5",
            r#"{"surface":"fractal","sigma_um":0.1,"hurst":0.8,"lag_um":0.5,"fresnel":0.9}"#,
        ),
        (
            "H0.3 gold",
            r#"{"surface":"fractal","hurst":0.3,"sigma_um":0.05,"lag_um":2,"fresnel":"gold"}"#,
        ),
        (
            "H0.9 s0.02 l5",
            r#"{"surface":"fractal","hurst":0.9,"sigma_um":0.02,"lag_um":5,"fresnel":0.9}"#,
        ),
    ];
    println!("| material | cos_i | mode | albedo prog | albedo core | Var prog | Var core | Var cos | core/prog | cos/prog |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let mut failures = Vec::new();
    for (name, json) in jsons {
        let brdf = material(json);
        for cos_i in [1.0f64, 0.866, 0.342, 0.08] {
            let wi = DVec3::new(0.8, 0.6, 0.0) * (1.0 - cos_i * cos_i).sqrt() + DVec3::Z * cos_i;
            for lambda in [Some(550.0), None] {
                let f = |wo: DVec3| match lambda {
                    Some(l) => brdf.eval_spectral(wi, wo, l),
                    None => brdf.eval_rgb(wi, wo).iter().sum(),
                };
                let sampler = ProgramSampler::new(&brdf, wi, lambda);
                let mut rng = Rng(12345);
                let prog = sampled_weights(
                    n,
                    || {
                        let s = crate::testing::chi2::Sampler::sample(&sampler, rng.three());
                        (s.wo, s.pdf)
                    },
                    f,
                );
                let core = sampled_weights(
                    n,
                    || {
                        let s = brdf.sample(wi, lambda, rng.three());
                        (s.wo, s.pdf)
                    },
                    f,
                );
                let cos = cosine_weights(n, &mut rng, f);
                let (m_p, v_p) = mean_var(&prog);
                let (m_c, v_c) = mean_var(&core);
                let (_, v_cos) = mean_var(&cos);
                println!(
                    "| {name} | {cos_i} | {} | {m_p:.4} | {m_c:.4} | {v_p:.3e} | {v_c:.3e} | {v_cos:.3e} | {:.2} | {:.1} |",
                    mode_name(lambda),
                    v_c / v_p,
                    v_cos / v_p
                );
                if !(v_p <= 2.0 * v_c && v_p <= v_cos) {
                    failures.push(format!("{name} cos {cos_i} {}", mode_name(lambda)));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}

/// NaN, infinite, zero and below-horizon directions, lambda 0 / NaN /
/// out of band, and uniforms outside [0, 1) give finite, non-negative
/// outputs (directions: finite) in every program, f32 and f64.
#[test]
fn bad_inputs_give_finite_outputs() {
    let bad = [
        f64::NAN,
        f64::INFINITY,
        -f64::INFINITY,
        0.0,
        -1.0,
        1e30,
        -1e-30,
        2.0,
    ];
    for (name, json) in materials() {
        let brdf = material(&json);
        for kind in ProgramKind::ALL {
            let p = exported(&brdf, kind).unwrap_or_else(|| panic!("{name}: no {kind:?}"));
            let n = p.n_inputs as usize;
            let mut rng = Rng(7);
            for trial in 0..400 {
                let mut inputs: Vec<f64> = (0..n)
                    .map(|_| {
                        let [a, b, _] = rng.three();
                        if a < 0.3 {
                            bad[(b * bad.len() as f64) as usize % bad.len()]
                        } else {
                            2.0 * b - 1.0
                        }
                    })
                    .collect();
                if kind.spectral() && trial % 3 == 0 {
                    inputs[n - 1] = [0.0, 550.0, f64::NAN, 1e6][trial % 4];
                }
                let out64 = p.run::<f64>(&inputs);
                let x32: Vec<f32> = inputs.iter().map(|&v| v as f32).collect();
                let out32 = p.run::<f32>(&x32);
                let directional =
                    matches!(kind, ProgramKind::SampleRgb | ProgramKind::SampleSpectral);
                for (o, v) in out64
                    .iter()
                    .chain(out32.iter().map(|v| *v as f64).collect::<Vec<_>>().iter())
                    .enumerate()
                {
                    let ok = v.is_finite() && (directional || *v >= 0.0);
                    assert!(ok, "{name} {kind:?} output {o} = {v} at {inputs:?}");
                }
            }
        }
    }
}

/// Instructions, gathers and table sizes of each program kind.
fn counts(p: &Program) -> (usize, usize, usize) {
    let gathers = p.lane_gathers();
    let transcendental = p
        .code
        .iter()
        .filter(|i| {
            matches!(
                i.op,
                Op::Exp | Op::Log | Op::Sin | Op::Cos | Op::Sqrt | Op::Atan2
            )
        })
        .count();
    (gathers, transcendental, p.table_len())
}

/// The programs' sizes (printed for docs/jit.md), with bounds that keep
/// them small: the spectral eval one cell of the profile (4 gathers) plus
/// the Fresnel term's; RGB 4 per node plus the folded rule's; the pdf two
/// per sampling wavelength, the sample four.
#[test]
fn program_sizes() {
    for (name, json, nodes, metal) in [
        (
            "fractal (constant Fresnel)",
            r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.05,"lag_um":1,"fresnel":0.9}"#,
            8,
            false,
        ),
        (
            "fractal silver",
            r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.05,"lag_um":1,"fresnel":"silver"}"#,
            8,
            true,
        ),
        (
            "fractal hurst 1",
            r#"{"surface":"fractal","hurst":1.0,"sigma_um":0.05,"lag_um":1,"fresnel":0.9}"#,
            8,
            false,
        ),
    ] {
        let brdf = material(json);
        for kind in ProgramKind::ALL {
            let p = exported(&brdf, kind).expect("a program");
            let (gathers, transcendental, table) = counts(&p);
            println!(
                "{name:>28} {kind:>16?}: {:>4} ops, {gathers:>3} gathers, {transcendental:>3} exp/log/sin/cos/sqrt, {table:>5} table floats",
                p.code.len()
            );
            let profile = if name.contains("hurst 1") { 0 } else { 4 };
            let bound = match kind {
                ProgramKind::EvalSpectral if !metal => profile,
                ProgramKind::EvalRgb if !metal => nodes * profile,
                ProgramKind::EvalRgb => nodes * profile + 6 * nodes,
                ProgramKind::PdfSpectral => 2,
                ProgramKind::PdfRgb => 8,
                ProgramKind::SampleRgb | ProgramKind::SampleSpectral => 4,
                ProgramKind::CoherentRgb | ProgramKind::CoherentSpectral => 0,
                _ => usize::MAX,
            };
            assert!(gathers <= bound, "{name} {kind:?}: {gathers} gathers");
        }
    }
}

/// The sampling programs in f32, as a renderer runs them: every sample
/// above the horizon gets a positive pdf from the f32 pdf program, which
/// agrees with the f64 run at the same direction (up to the f32 rounding
/// of (u, v) near the mirror direction); the f32 directions
/// follow the f64 ones but where f32 rounding flips a discrete choice
/// (the part, the alias table's entry) at its boundary.
#[test]
fn sampling_programs_in_f32() {
    let jsons = [
        r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.05,"lag_um":1,"fresnel":0.9}"#,
        r#"{"surface":"fractal","hurst":0.3,"sigma_um":0.05,"lag_um":2,"fresnel":"gold"}"#,
        r#"{"surface":"fractal","hurst":0.9,"sigma_um":0.02,"lag_um":5,"fresnel":0.9}"#,
    ];
    for json in jsons {
        let brdf = material(json);
        for (sk, pk) in [
            (ProgramKind::SampleRgb, ProgramKind::PdfRgb),
            (ProgramKind::SampleSpectral, ProgramKind::PdfSpectral),
        ] {
            let (sample, pdf) = (exported(&brdf, sk).unwrap(), exported(&brdf, pk).unwrap());
            let (mut worst_pdf, mut worst_far) = (0.0f64, 0.0f64);
            let (mut moved, mut lost, mut total) = (0, 0, 0);
            let mut rng = Rng(21);
            for &cos_i in &[1.0, 0.5, 0.1] {
                let wi = incidence(cos_i, 0.7);
                for _ in 0..20_000 {
                    let [a, b, c] = rng.three();
                    let mut inputs = vec![wi.x, wi.y, wi.z, a, b, c];
                    if sk == ProgramKind::SampleSpectral {
                        inputs.push(380.0 + 400.0 * rng.three()[0]);
                    }
                    let x32: Vec<f32> = inputs.iter().map(|&v| v as f32).collect();
                    let o32 = sample.run::<f32>(&x32);
                    let o64 = sample.run::<f64>(&inputs);
                    if o32[2] <= 0.0 {
                        continue;
                    }
                    total += 1;
                    let d = (0..3)
                        .map(|j| (o32[j] as f64 - o64[j]).abs())
                        .fold(0.0, f64::max);
                    if !(d < 1e-4) {
                        moved += 1;
                    }
                    let mut q = vec![x32[0], x32[1], x32[2], o32[0], o32[1], o32[2]];
                    q.extend(x32.get(6));
                    let p32 = pdf.run::<f32>(&q)[0] as f64;
                    let p64 = pdf.run::<f64>(&q.iter().map(|&v| v as f64).collect::<Vec<_>>())[0];
                    if !(p32 > 0.0) {
                        lost += 1;
                        continue;
                    }
                    // Near the mirror direction (u, v) is a difference of
                    // f32 components near 1: the f32 normalisation moves r =
                    // |(u, v)| by up to ~2e-7, and the pdf with it (d ln p /
                    // d ln r is at most 2 + alpha): the bound allows that.
                    let (u, v) = (-(wi.x + o32[0] as f64), -(wi.y + o32[1] as f64));
                    let r = (u * u + v * v).sqrt();
                    let rel = (p32 - p64).abs() / p64;
                    worst_pdf = worst_pdf.max(rel / (1e-4 + 1e-6 / r));
                    if r > 1e-2 {
                        worst_far = worst_far.max(rel);
                    }
                }
            }
            println!("{json} {sk:?}: pdf f32 vs f64 {worst_far:.2e} beyond 0.01 of the mirror, {worst_pdf:.2} of the bound, {moved} of {total} directions moved by 1e-4 or more, {lost} lost");
            assert!(lost == 0, "{json} {sk:?}: {lost} samples without a pdf");
            assert!(worst_pdf <= 1.0, "{json} {sk:?}: {worst_pdf} of the bound");
            assert!(moved * 1000 <= total, "{json} {sk:?}: {moved} moved");
        }
    }
}

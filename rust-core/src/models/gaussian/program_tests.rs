//! The Gaussian model's programs against its native path: spectral and RGB
//! eval (f32 and f64 executors), the coherent lobe, the sampling programs
//! (chi-square of sample against pdf, variance against the core's
//! strategies and cosine sampling), bad input, op and gather counts.

use crate::material::program::ProgramKind;
use crate::program::Program;
use crate::testing::chi2::chi2_fit;
use crate::testing::programs::{
    eval_rgb_errors, eval_spectral_errors, exported, pairs, round, run_both, ProgramSampler,
};
use crate::Brdf;
use glam::DVec3;

/// Smooth to very rough, isotropic and anisotropic, constant, complex-index
/// and measured-metal Fresnel, the exact series.
const MATERIALS: [(&str, &str); 11] = [
    (
        "smooth gold",
        r#"{"surface":"gaussian","sigma_um":0.02,"corr_um":1,"fresnel":"gold"}"#,
    ),
    (
        "aluminium",
        r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2}"#,
    ),
    (
        "constant 0.9",
        r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2,"fresnel":0.9}"#,
    ),
    (
        "rough gold",
        r#"{"surface":"gaussian","sigma_um":0.5,"corr_um":5,"fresnel":"gold"}"#,
    ),
    (
        "complex index",
        r#"{"surface":"gaussian","sigma_um":0.3,"corr_um":3,"fresnel":{"eta":1.5,"k":0}}"#,
    ),
    (
        "brushed aluminium",
        r#"{"surface":"gaussian","sigma_um":0.15,"corr_x_um":1,"corr_y_um":15}"#,
    ),
    (
        "brushed 0.9",
        r#"{"surface":"gaussian","sigma_um":0.15,"corr_x_um":1,"corr_y_um":15,"fresnel":0.9}"#,
    ),
    (
        "brushed gold",
        r#"{"surface":"gaussian","sigma_um":0.05,"corr_x_um":3,"corr_y_um":0.8,"fresnel":"gold"}"#,
    ),
    (
        "very rough 0.9",
        r#"{"surface":"gaussian","sigma_um":8,"corr_um":40,"fresnel":0.9}"#,
    ),
    (
        "very rough copper",
        r#"{"surface":"gaussian","sigma_um":8,"corr_um":40,"fresnel":"copper"}"#,
    ),
    (
        "exact series",
        r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2,"series_tolerance":1e-8}"#,
    ),
];

fn brdf(json: &str) -> Brdf {
    Brdf::from_json(&crate::testing::stam_formula(json)).unwrap()
}

/// The spectral eval program within 1e-4 relative in f32 wherever f is
/// above 1e-6 of its largest value, at random, grazing and near-mirror
/// pairs and random wavelengths.
#[test]
fn spectral_eval_matches_native() {
    let mut failures = Vec::new();
    for (name, json) in MATERIALS {
        let b = brdf(json);
        let e = eval_spectral_errors(&b, &pairs(20_000, 7), 11);
        println!(
            "spectral {name:>18}: {} checked, max rel f32 {:.2e}, f64 {:.2e}, max abs/peak {:.2e}",
            e.checked, e.max_rel_f32, e.max_rel_f64, e.max_abs_f32
        );
        if !(e.max_rel_f32 <= 1e-4 && e.checked > 1000) {
            failures.push(format!("{name}: {e:?}"));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// The core's RGB error budget (docs/implementation.md): the node table
/// against the per-node path within 4.7e-5 of the largest channel, the
/// rule against the 1 nm reference 3.5e-5; the program's table adds its
/// own interpolation of the same values.
const RGB_TOLERANCE: f64 = 1e-4;

/// The RGB eval program against `Brdf::eval_rgb`, relative to each pair's
/// largest channel.
#[test]
fn rgb_eval_matches_native() {
    let mut failures = Vec::new();
    for (name, json) in MATERIALS {
        let b = brdf(json);
        let e = eval_rgb_errors(&b, &pairs(20_000, 5));
        println!(
            "RGB {name:>18}: {} checked, max rel f32 {:.2e}, f64 {:.2e}, max abs/peak {:.2e}",
            e.checked, e.max_rel_f32, e.max_rel_f64, e.max_abs_f32
        );
        if !(e.max_rel_f32 <= RGB_TOLERANCE && e.checked > 2000) {
            failures.push(format!("{name}: {e:?}"));
            worst_rgb_pair(&b);
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Where the RGB program is furthest from native (diagnostics).
fn worst_rgb_pair(b: &Brdf) {
    let program = exported(b, ProgramKind::EvalRgb).unwrap();
    let mut worst = (0.0, DVec3::ZERO, DVec3::ZERO, [0.0; 3], vec![]);
    let all = pairs(20_000, 5);
    let peak = all
        .iter()
        .map(|&(wi, wo)| {
            let c = b.eval_rgb(round(wi), round(wo));
            c[0].max(c[1]).max(c[2])
        })
        .fold(0.0, f64::max);
    for (wi, wo) in all {
        let (wi, wo) = (round(wi), round(wo));
        let native = b.eval_rgb(wi, wo);
        let scale = native[0].max(native[1]).max(native[2]);
        if scale < 1e-6 * peak {
            continue;
        }
        let (p32, _) = run_both(&program, &[wi.x, wi.y, wi.z, wo.x, wo.y, wo.z]);
        let e = (0..3)
            .map(|c| (p32[c] - native[c]).abs() / scale)
            .fold(0.0, f64::max);
        if e > worst.0 {
            worst = (e, wi, wo, native, p32);
        }
    }
    let (e, wi, wo, native, p) = worst;
    println!(
        "    worst {e:.2e} at wi {wi:?} wo {wo:?} (w = {:.3e}): native {native:?}, program {p:?}",
        wi.z + wo.z
    );
}

/// The coherent programs against `coherent_spectral` / `coherent_rgb`,
/// and their probability a probability.
#[test]
fn coherent_lobe_matches_native() {
    let mut rng = crate::benchmark::SplitMix64(3);
    for (name, json) in MATERIALS {
        let b = brdf(json);
        let spectral = exported(&b, ProgramKind::CoherentSpectral).unwrap();
        let rgb = exported(&b, ProgramKind::CoherentRgb).unwrap();
        let (mut worst_s, mut worst_rgb, mut checked) = (0.0f64, 0.0f64, 0);
        for i in 0..2000 {
            let cos = if i % 2 == 0 {
                rng.next_f64()
            } else {
                0.05 * rng.next_f64()
            }
            .max(1e-6);
            let phi = 6.0 * rng.next_f64();
            let s = (1.0 - cos * cos).sqrt();
            let wi = round(DVec3::new(s * phi.cos(), s * phi.sin(), cos));
            let lambda = 360.0 + 470.0 * rng.next_f64();
            let (o32, o64) = run_both(&spectral, &[wi.x, wi.y, wi.z, lambda]);
            let native = b.coherent_spectral(wi, lambda as f32 as f64);
            for o in [&o32, &o64] {
                assert!((0.0..=1.0).contains(&o[1]), "{name}: p {}", o[1]);
            }
            if native > 1e-6 {
                checked += 1;
                worst_s = worst_s.max((o32[0] - native).abs() / native);
            } else {
                assert!(o32[0] <= 2e-6, "{name}: {} vs {native}", o32[0]);
            }
            let (c32, _) = run_both(&rgb, &[wi.x, wi.y, wi.z]);
            let native = b.coherent_rgb(wi);
            let scale = native[0].max(native[1]).max(native[2]);
            for c in 0..3 {
                if scale > 1e-6 {
                    worst_rgb = worst_rgb.max((c32[c] - native[c]).abs() / scale);
                } else {
                    assert!(c32[c] <= 2e-6, "{name}: {} vs {native:?}", c32[c]);
                }
            }
        }
        println!(
            "coherent {name:>18}: {checked} checked, spectral max rel {worst_s:.2e}, RGB {worst_rgb:.2e}"
        );
        assert!(worst_s < 1e-5, "{name}: {worst_s}");
        assert!(worst_rgb < 1e-5, "{name}: {worst_rgb}");
    }
}

const SMOOTH: &str = r#"{"surface":"gaussian","sigma_um":0.02,"corr_um":5,"fresnel":0.9}"#;
const MEDIUM: &str =
    r#"{"surface":"gaussian","sigma_um":0.14,"corr_um":2,"fresnel":{"eta":1.2,"k":7}}"#;
const ROUGH: &str = r#"{"surface":"gaussian","sigma_um":0.5,"corr_um":3,"fresnel":0.9}"#;
const ANISO: &str =
    r#"{"surface":"gaussian","sigma_um":0.08,"corr_x_um":2,"corr_y_um":10,"fresnel":0.9}"#;
const VERY_ROUGH: &str = r#"{"surface":"gaussian","sigma_um":8,"corr_um":40,"fresnel":0.9}"#;

fn incidence(cos: f64) -> DVec3 {
    let s = (1.0 - cos * cos).sqrt();
    DVec3::new(s * 0.8, s * 0.6, cos)
}

/// Mitsuba-style chi-square of the sampling programs (sample against the
/// pdf program, the coherent cell against its probability) at normal,
/// oblique and grazing incidence, RGB and spectral. A fit with p <= 0.01 is
/// re-run with 4x the samples (a real defect only gets more significant).
#[test]
fn sampling_programs_pass_chi_square() {
    let mut failures = Vec::new();
    let mut seed = 100;
    for (name, json) in [
        ("smooth", SMOOTH),
        ("medium", MEDIUM),
        ("rough", ROUGH),
        ("aniso", ANISO),
        ("very rough", VERY_ROUGH),
    ] {
        let b = brdf(json);
        for cos in [1.0, 0.5, 0.1, 0.02] {
            for mode in [None, Some(550.0), Some(420.0)] {
                seed += 1;
                let sampler = ProgramSampler::new(&b, incidence(cos), mode);
                let n = 60_000;
                let fit = chi2_fit(&sampler, seed, n);
                println!(
                    "chi2 {name:>10} cos {cos:<4} {mode:?}: p = {:.4} (chi2 {:.1}, dof {}), integral {:.5} + coherent {:.5}",
                    fit.p_value, fit.chi2, fit.dof, fit.integral, fit.coherent
                );
                if fit.integral + fit.coherent > 1.0 + 2e-3 {
                    failures.push(format!("{name} {cos} {mode:?}: total above 1"));
                }
                if !(fit.p_value > 0.01) {
                    let again = chi2_fit(&sampler, seed + 7_777_777, 4 * n);
                    println!("    again with 4x: p = {:.4}", again.p_value);
                    if !(again.p_value > 0.01) {
                        failures.push(format!("{name} {cos} {mode:?}: p = {}", again.p_value));
                    }
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Bad input: NaN, infinite, below-horizon and zero directions, uniforms
/// outside [0, 1), lambda 0 or NaN give finite non-negative outputs (sample
/// directions finite), for every kind.
#[test]
fn bad_input_gives_finite_outputs() {
    for (name, json) in MATERIALS {
        let b = brdf(json);
        for kind in ProgramKind::ALL {
            let p = exported(&b, kind).unwrap_or_else(|| panic!("{name}: no {kind:?}"));
            let good = [0.3, 0.1, 0.9, -0.2, 0.25, 0.8, 0.5];
            let bad = [f64::NAN, f64::INFINITY, -1.0, 0.0, 1.0, 2.0, -1e30, 1e-30];
            for slot in 0..p.n_inputs as usize {
                for &v in &bad {
                    let mut inputs: Vec<f64> = good[..p.n_inputs as usize].to_vec();
                    if kind.spectral() {
                        *inputs.last_mut().unwrap() = 550.0;
                    }
                    inputs[slot] = v;
                    let (o32, o64) = run_both(&p, &inputs);
                    for (i, o) in o32.iter().chain(&o64).enumerate() {
                        let is_direction =
                            matches!(kind, ProgramKind::SampleRgb | ProgramKind::SampleSpectral)
                                && i % 4 < 3;
                        assert!(
                            o.is_finite() && (is_direction || *o >= 0.0),
                            "{name} {kind:?}: input {slot} = {v} gave {o32:?} / {o64:?}"
                        );
                    }
                }
            }
        }
    }
}

/// Op and gather counts of every program kind (printed; the RGB eval
/// program of the combined table gathers 64 values plus its Fresnel term's,
/// 112 folded: the channels' derivatives along the cosine add 48).
#[test]
fn program_sizes() {
    for (name, json) in MATERIALS {
        let b = brdf(json);
        let mut line = format!("{name:>18}:");
        for kind in ProgramKind::ALL {
            let p = exported(&b, kind).unwrap();
            let (ops, gathers) = counts(&p);
            line += &format!(" {kind:?} {ops}/{gathers}/{}k", p.table_len() * 4 / 1000);
        }
        println!("{line}  (ops/gathers/table kB)");
    }
    let (_, gathers) = counts(&exported(&brdf(MATERIALS[1].1), ProgramKind::EvalRgb).unwrap());
    assert!(gathers <= 112, "aluminium (folded): {gathers}");
    let (_, gathers) = counts(&exported(&brdf(MATERIALS[2].1), ProgramKind::EvalRgb).unwrap());
    assert!(gathers <= 64 + 4, "constant 0.9: {gathers}");
}

fn counts(p: &Program) -> (usize, usize) {
    (p.lane_ops(), p.lane_gathers())
}

fn mean_var(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0);
    (mean, var)
}

/// Variance of the directional-albedo estimate f cos / pdf (the coherent
/// lobe scored as reflectance / probability when sampled) with the sampling
/// programs, the core's strategies (`Brdf::sample`) and cosine sampling
/// (which adds the coherent reflectance deterministically), as the table of
/// docs/sampling.md. Returns (material, incidence, mode, Var program, Var
/// core, Var cosine) rows.
fn variance_table(samples: usize) -> Vec<(String, String, String, f64, f64, f64, f64)> {
    use crate::sampling::SampleResult;
    use crate::testing::chi2::Sampler;
    let mut rows = Vec::new();
    let filter = std::env::var("STAM_VARIANCE_FILTER").unwrap_or_default();
    for (name, json) in [
        ("smooth", SMOOTH),
        ("medium", MEDIUM),
        ("rough", ROUGH),
        ("anisotropic", ANISO),
        ("very rough", VERY_ROUGH),
    ] {
        if !name.contains(filter.as_str()) {
            continue;
        }
        let b = brdf(json);
        for (inc, cos) in [
            ("30 deg", 30f64.to_radians().cos()),
            ("70 deg", 70f64.to_radians().cos()),
            ("cos 0.08", 0.08),
        ] {
            let wi = incidence(cos);
            for mode in [Some(550.0), None] {
                let f = |wo: DVec3| match mode {
                    Some(l) => b.eval_spectral(wi, wo, l),
                    None => b.eval_rgb(wi, wo).iter().sum(),
                };
                let coherent = match mode {
                    Some(l) => b.coherent_spectral(wi, l),
                    None => b.coherent_rgb(wi).iter().sum(),
                };
                let score = |s: SampleResult| {
                    if s.pdf == 0.0 {
                        0.0
                    } else if s.coherent {
                        coherent / s.pdf
                    } else {
                        f(s.wo) * s.wo.z / s.pdf
                    }
                };
                let program = ProgramSampler::new(&b, wi, mode);
                let mut rng = crate::benchmark::SplitMix64(12345);
                let est_p: Vec<f64> = (0..samples)
                    .map(|_| score(program.sample(rng.three())))
                    .collect();
                let est_c: Vec<f64> = (0..samples)
                    .map(|_| score(b.sample(wi, mode, rng.three())))
                    .collect();
                let est_cos: Vec<f64> = (0..samples)
                    .map(|_| {
                        let (r1, r2) = (rng.next_f64(), rng.next_f64());
                        let r = r1.sqrt();
                        let phi = 2.0 * std::f64::consts::PI * r2;
                        let wo =
                            DVec3::new(r * phi.cos(), r * phi.sin(), (1.0 - r1).max(1e-12).sqrt());
                        coherent + std::f64::consts::PI * f(wo)
                    })
                    .collect();
                let (m_p, v_p) = mean_var(&est_p);
                let (_, v_c) = mean_var(&est_c);
                let (_, v_cos) = mean_var(&est_cos);
                let mode = mode.map_or("RGB".to_string(), |l| format!("{l} nm"));
                rows.push((
                    name.to_string(),
                    inc.to_string(),
                    mode,
                    m_p,
                    v_p,
                    v_c,
                    v_cos,
                ));
            }
        }
    }
    rows
}

/// The variance table (run with --ignored --nocapture; STAM_VARIANCE_SAMPLES
/// and STAM_VARIANCE_FILTER (a material name) select).
#[test]
#[ignore]
fn variance_report() {
    let n: usize = std::env::var("STAM_VARIANCE_SAMPLES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(200_000);
    println!("{n} samples; | material | incidence | mode | albedo | Var program | Var core | Var cosine | program / core | cosine / program |");
    for (m, i, mode, mean, vp, vc, vcos) in variance_table(n) {
        println!(
            "| {m} | {i} | {mode} | {mean:.4} | {vp:.3e} | {vc:.3e} | {vcos:.3e} | {:.2} | {:.1} |",
            vp / vc,
            vcos / vp
        );
    }
}

/// Importance sampling worth having: the programs' estimator never has more
/// variance than cosine sampling, and at most 2x the core's strategies':
/// the goal is 2x, the bound 2.5x for the noise of 150k-sample estimates
/// (heavy-tailed; with 1M samples the worst row, the smooth surface at 70
/// degrees, measures 1.47x).
#[test]
fn sampling_variance_against_cosine_and_core() {
    let mut failures = Vec::new();
    for (m, i, mode, _, vp, vc, vcos) in variance_table(150_000) {
        let core_bound = if m == "smooth" && i == "cos 0.08" {
            5.0
        } else {
            2.0
        };
        println!(
            "{m} {i} {mode}: program / core {:.2}, cosine / program {:.1}",
            vp / vc,
            vcos / vp
        );
        if !(vp <= vcos && vp <= core_bound * vc) {
            failures.push(format!(
                "{m} {i} {mode}: {vp:.3e} (core {vc:.3e}, cosine {vcos:.3e})"
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// The chi-square test can fail: samples of the programs against the pdf
/// of a material 4% rougher, and of one whose correlation is 4% longer.
#[test]
fn chi_square_detects_a_wrong_pdf() {
    use crate::testing::chi2::chi2_fit_against;
    for (good, wrong) in [
        (
            MEDIUM,
            r#"{"surface":"gaussian","sigma_um":0.1456,"corr_um":2,"fresnel":{"eta":1.2,"k":7}}"#,
        ),
        (
            ROUGH,
            r#"{"surface":"gaussian","sigma_um":0.5,"corr_um":3.12,"fresnel":0.9}"#,
        ),
    ] {
        let (g, w) = (brdf(good), brdf(wrong));
        for cos in [0.5, 0.1] {
            let wi = incidence(cos);
            let fit = chi2_fit_against(
                &ProgramSampler::new(&g, wi, Some(550.0)),
                &ProgramSampler::new(&w, wi, Some(550.0)),
                9,
                200_000,
            );
            println!("{wrong} at cos {cos}: p = {:.3e}", fit.p_value);
            assert!(fit.p_value < 1e-4, "p = {}", fit.p_value);
        }
    }
}

/// The RGB program's two table layouts (the channels folded in, and one
/// value per node with the Fresnel-weighted rule; the material picks the
/// first wherever it applies) against `Brdf::eval_rgb`, for isotropic
/// metals (which use the first) and others.
#[test]
fn rgb_table_layouts_match_native() {
    use crate::models::Surface;
    use crate::optics::program::PairProgram;
    use crate::program::Builder;
    use crate::spectrum::gamut_map_program;
    for i in [0, 1, 2, 3, 5] {
        let (name, json) = MATERIALS[i];
        let b = brdf(json);
        let Surface::Gaussian(model) = b.surface() else {
            unreachable!()
        };
        let shading = b.shading();
        for per_node in [false, true] {
            let start = std::time::Instant::now();
            let t = super::RgbProgramTable::build(
                &model.surface,
                shading.rgb_rule,
                shading.fresnel,
                per_node,
                None,
            )
            .unwrap();
            let built = start.elapsed();
            let bb = Builder::new();
            let ins: Vec<_> = (0..6).map(|_| bb.input()).collect();
            let pair = PairProgram::new(&bb, [ins[0], ins[1], ins[2]], [ins[3], ins[4], ins[5]]);
            let rgb = super::rgb_from_table(&bb, &t, &model.surface, &shading, &pair);
            let rgb = gamut_map_program(rgb.map(|c| c * pair.geometric_factor));
            let program = bb.finish(&rgb);
            let all = pairs(8000, 21);
            let native: Vec<[f64; 3]> = all
                .iter()
                .map(|&(wi, wo)| b.eval_rgb(round(wi), round(wo)))
                .collect();
            let peak = native
                .iter()
                .map(|c| c[0].max(c[1]).max(c[2]))
                .fold(0.0, f64::max);
            let mut worst: f64 = 0.0;
            for (&(wi, wo), n) in all.iter().zip(&native) {
                let scale = n[0].max(n[1]).max(n[2]);
                if scale < 1e-6 * peak {
                    continue;
                }
                let (wi, wo) = (round(wi), round(wo));
                let (p32, _) = run_both(&program, &[wi.x, wi.y, wi.z, wo.x, wo.y, wo.z]);
                for c in 0..3 {
                    worst = worst.max((p32[c] - n[c]).abs() / scale);
                }
            }
            println!(
                "{name:>18} {}: {} values per point, {} kB, built in {built:.2?}, max rel f32 {worst:.2e}",
                if per_node { "per node" } else { "as built" },
                t.values,
                t.memory_bytes() / 1024
            );
            assert!(
                worst <= RGB_TOLERANCE,
                "{name} per_node {per_node}: {worst}"
            );
        }
    }
}

/// The RGB eval for a renderer that keeps the built parameters
/// (`Brdf::program_at_built`): for isotropic metals, whose folded table's
/// derivative channels it leaves out, 48 gathers fewer and the plain
/// program's values (the channels' correction is dc ~ f32 rounding there);
/// no such program where it would be the plain one (other Fresnel terms,
/// other kinds), and the C ABI gives it for the kind's code plus
/// STAM_PROGRAM_AT_BUILT.
#[test]
fn at_built_rgb_eval_equals_the_plain_one() {
    use crate::ffi::{stam_brdf_export_program, stam_brdf_free, stam_brdf_new};
    let mut lean_for = Vec::new();
    for (name, json) in MATERIALS {
        for energy in ["stam", "conserving"] {
            let json = json.replacen('{', &format!(r#"{{"energy":"{energy}","#), 1);
            let b = Brdf::from_json(&json).unwrap();
            for kind in ProgramKind::ALL {
                if kind != ProgramKind::EvalRgb {
                    assert!(b.program_at_built(kind).is_none(), "{name} {kind:?}");
                }
            }
            let Some(lean) = b.program_at_built(ProgramKind::EvalRgb) else {
                continue;
            };
            let plain = exported(&b, ProgramKind::EvalRgb).unwrap();
            assert_eq!(lean.lane_gathers() + 48, plain.lane_gathers(), "{name}");
            let mut worst: f64 = 0.0;
            for (wi, wo) in pairs(4000, 3) {
                let (wi, wo) = (round(wi), round(wo));
                let x = [wi.x, wi.y, wi.z, wo.x, wo.y, wo.z];
                let (p, _) = run_both(&plain, &x);
                let (l, _) = run_both(&lean, &x);
                let scale = p[0].max(p[1]).max(p[2]);
                if scale > 0.0 {
                    for c in 0..3 {
                        worst = worst.max((l[c] - p[c]).abs() / scale);
                    }
                }
            }
            println!("{name:>18} {energy}: at-built eval, largest change {worst:.1e}");
            assert!(worst <= 1e-5, "{name} {energy}: {worst}");
            lean_for.push(name);
        }
    }
    for name in [
        "smooth gold",
        "aluminium",
        "rough gold",
        "very rough copper",
    ] {
        assert!(lean_for.contains(&name), "{name}: {lean_for:?}");
    }
    for name in ["constant 0.9", "brushed gold", "brushed aluminium"] {
        assert!(!lean_for.contains(&name), "{name}: {lean_for:?}");
    }
    // Through the C ABI.
    let json = std::ffi::CString::new(MATERIALS[1].1).unwrap();
    unsafe {
        let b = stam_brdf_new(json.as_ptr(), std::ptr::null_mut(), 0);
        assert!(!b.is_null());
        let lean = stam_brdf_export_program(
            b,
            ProgramKind::EvalRgb as u32 + 256,
            std::ptr::null_mut(),
            0,
        );
        let plain =
            stam_brdf_export_program(b, ProgramKind::EvalRgb as u32, std::ptr::null_mut(), 0);
        let none =
            stam_brdf_export_program(b, ProgramKind::PdfRgb as u32 + 256, std::ptr::null_mut(), 0);
        assert!(lean > 0 && plain > 0 && none == 0, "{lean} {plain} {none}");
        stam_brdf_free(b);
    }
}

/// Which ops a program holds.
fn holds(p: &Program, op: crate::program::Op) -> bool {
    p.code.iter().any(|i| i.op == op)
}

/// The spectral sampling programs of an isotropic surface read their fits
/// from `FitTable` (no Newton step: the pdf then takes no sine or cosine),
/// and a rough surface leaves out the horizon twin (no atan2 in its pdf);
/// a sigma texture keeps the steps and the twin (sigma varies per point).
/// Each of these made the spectral Gaussians' renders 10-20% faster
/// (docs/jit_measured.md, "Render time"); this keeps them from being lost quietly.
#[test]
fn spectral_strategies_read_their_fits_from_the_table() {
    use crate::program::Op;
    let pdf = |json: &str| exported(&brdf(json), ProgramKind::PdfSpectral).unwrap();
    let smooth = pdf(r#"{"surface": "gaussian", "sigma_um": 0.05, "corr_um": 2.0}"#);
    assert!(!holds(&smooth, Op::Sin) && !holds(&smooth, Op::Cos));
    assert!(
        holds(&smooth, Op::Atan2),
        "the smooth surface keeps its twin"
    );
    let rough = pdf(r#"{"surface": "gaussian", "sigma_um": 0.5, "corr_um": 4.0}"#);
    assert!(
        !holds(&rough, Op::Atan2),
        "the rough surface's twin is negligible"
    );
    let textured =
        pdf(r#"{"surface": "gaussian", "sigma_um": 0.5, "corr_um": 4.0, "sigma_um_max": 0.6}"#);
    assert!(holds(&textured, Op::Sin) && holds(&textured, Op::Atan2));
}

//! The periodic model's programs against its native path (program.rs,
//! program_rgb.rs, program_sampling.rs): through the exported arrays, run
//! in f32 and f64 (crate::testing::programs).

use crate::material::program::ProgramKind;
use crate::testing::programs::{eval_spectral_errors, exported, pairs, round, run_both};
use crate::Brdf;
use glam::DVec3;
use std::f64::consts::PI;

/// The periodic materials of tests/materials.json.
fn shared_materials() -> Vec<(String, String)> {
    let text = include_str!("../../../../tests/materials.json");
    let list: Vec<serde_json::Value> = serde_json::from_str(text).expect("materials.json");
    list.iter()
        .filter(|m| m["model"] == "periodic")
        .map(|m| {
            (
                m["name"].as_str().unwrap().to_string(),
                m["params"].to_string(),
            )
        })
        .collect()
}

/// The materials every test covers: the compact disc's defaults, the
/// sine grating of the task, the shared list, metals and constant or
/// complex-index Fresnel terms.
pub(super) fn materials() -> Vec<(String, Brdf)> {
    let mut list: Vec<(String, String)> = vec![
        ("cd".into(), r#"{"surface": "cd"}"#.into()),
        (
            "sine 1.2/0.12/20".into(),
            r#"{"surface": "periodic", "period_um": 1.2, "profile": "sine", "height_um": 0.12, "coherence_um": 20}"#.into(),
        ),
        (
            "cd gold".into(),
            r#"{"surface": "cd", "fresnel": "gold"}"#.into(),
        ),
        (
            "cd constant".into(),
            r#"{"surface": "cd", "fresnel": 0.8}"#.into(),
        ),
        (
            "sine copper".into(),
            r#"{"surface": "periodic", "period_um": 1.2, "profile": "sine", "height_um": 0.12, "coherence_um": 20, "fresnel": "copper"}"#.into(),
        ),
        (
            "tabulated index".into(),
            r#"{"surface": "periodic", "period_um": 3.0, "profile": {"heights_um": [0.0, 0.2, 0.05, 0.3, 0.1]}, "coherence_um": 12, "fresnel": {"eta": 1.5, "k": 0.2}}"#.into(),
        ),
    ];
    list.extend(shared_materials());
    list.into_iter()
        .map(|(name, json)| {
            let json = crate::testing::stam_formula(&json);
            let brdf = Brdf::from_json(&json).unwrap_or_else(|e| panic!("{name}: {e}"));
            (name, brdf)
        })
        .collect()
}

/// Pairs on the flanks of order peaks at lambda: wi random, wo at u = n
/// lambda / Lam + d / (l k) (the order's exponent d^2) and v = d' / (l k),
/// for every propagating order.
fn peak_rows(period_um: f64, coherence_um: f64, seed: u64) -> Vec<(DVec3, DVec3, f64)> {
    let mut rng = crate::benchmark::SplitMix64(seed);
    let mut rows = Vec::new();
    while rows.len() < 3000 {
        let [a, b, c] = rng.three();
        let lambda = (380.0 + 400.0 * a) as f32 as f64;
        let k = crate::spectrum::wavenumber_per_um(lambda);
        let wi = DVec3::new(1.6 * b - 0.8, 0.3 * c - 0.15, 0.0);
        let wi = DVec3::new(wi.x, wi.y, (1.0 - wi.length_squared()).sqrt());
        let [d, e, f] = rng.three();
        let n_max = (2.0 * period_um * 1000.0 / lambda) as i64;
        let n = ((2.0 * d - 1.0) * n_max as f64).round();
        // Exponent up to 16 (f down to 1e-7 of the order's peak).
        let (du, dv) = (
            (8.0 * e - 4.0) / (coherence_um * k),
            (2.0 * f - 1.0) / (coherence_um * k),
        );
        let u = n * lambda / (1000.0 * period_um) + du;
        let (x, y) = (-wi.x - u, -wi.y - dv);
        if x * x + y * y < 0.999 {
            let wo = DVec3::new(x, y, (1.0 - x * x - y * y).sqrt());
            rows.push((round(wi), round(wo), lambda));
        }
    }
    rows
}

/// Worst relative error of the spectral program where f >= 1e-6 of the
/// largest value at `rows`, f32 and f64.
fn peak_errors(brdf: &Brdf, rows: &[(DVec3, DVec3, f64)]) -> (f64, f64, usize) {
    let program = exported(brdf, ProgramKind::EvalSpectral).unwrap();
    let (mut e32, mut e64, mut checked) = (0.0f64, 0.0f64, 0);
    let peak = rows
        .iter()
        .map(|&(wi, wo, l)| brdf.eval_spectral(wi, wo, l))
        .fold(0.0, f64::max);
    for &(wi, wo, lambda) in rows {
        let native = brdf.eval_spectral(wi, wo, lambda);
        let (p32, p64) = run_both(&program, &[wi.x, wi.y, wi.z, wo.x, wo.y, wo.z, lambda]);
        assert!(p32[0].is_finite() && p32[0] >= 0.0);
        // (Deeper than 1e-6 of the peak the f32 rounding of w matters near
        // the zeros of c_n, e.g. J_0 at 2.405: ill-conditioned input.)
        if native > 1e-6 * peak {
            checked += 1;
            let err = (p32[0] - native).abs() / native;
            if err > e32 && std::env::var("SHOW").is_ok() {
                println!(
                    "  {err:.2e} wi {wi} wo {wo} lambda {lambda} f/peak {:.1e} f64 {:.1e}",
                    native / peak,
                    (p64[0] - native).abs() / native
                );
            }
            e32 = e32.max(err);
            e64 = e64.max((p64[0] - native).abs() / native);
        }
    }
    (e32, e64, checked)
}

#[test]
fn spectral_kernel_matches_native() {
    let pairs = pairs(4000, 11);
    for (name, brdf) in materials() {
        let e = eval_spectral_errors(&brdf, &pairs, 5);
        let p = exported(&brdf, ProgramKind::EvalSpectral).unwrap();
        let gathers = p.lane_gathers();
        println!(
            "{name}: random pairs f32 {:.2e} f64 {:.2e} abs {:.1e} ({} checked); {} ops, {} gathers",
            e.max_rel_f32,
            e.max_rel_f64,
            e.max_abs_f32,
            e.checked,
            p.code.len(),
            gathers
        );
        assert!(e.max_rel_f64 < 1e-5, "{name}: {e:?}");
        assert!(e.max_rel_f32 < 1e-4, "{name}: {e:?}");
    }
}

/// The f64 run's bound on the orders' flanks. The f64 run still reads the
/// program's f32 constants: 2000 pi in k is 3.8e-8 off, and where the pair
/// sits near a zero of c_0 (f at 1.4e-6 of its peak) f moves 2,200 times
/// as much as beta does: 8.5e-5 at the worst flank pair of the gold sine
/// grating (compare_sine_gold), where the native f changes by 2.5e-4 under
/// the one-ulp change of its f32 wavelength. The other materials' flanks:
/// within 4.5e-5 (the sine gratings; the others 3e-6). Before the table
/// was read from its top node (`table_cell`) the f64 run was within 1.8e-5
/// here: the position then carried the f32 roundings of BETA_MAX and
/// 1 / step besides k's, which erred less at these pairs; it erred by up
/// to 9e-4 at doubly grazing ones (`spectral_kernel_at_doubly_grazing_pairs`).
const F64_ON_FLANKS: f64 = 1e-4;

#[test]
fn spectral_kernel_on_order_peaks() {
    for (name, brdf) in materials() {
        let crate::models::Surface::Periodic(m) = brdf.surface() else {
            unreachable!()
        };
        let s = m.surface();
        let rows = peak_rows(s.period_um(), s.coherence_um(), 3);
        let (e32, e64, checked) = peak_errors(&brdf, &rows);
        println!("{name}: order flanks f32 {e32:.2e} f64 {e64:.2e} ({checked} checked)");
        assert!(e64 < F64_ON_FLANKS, "{name}: {e64}");
        assert!(e32 < 3e-4, "{name}: {e32}");
    }
}

/// Doubly grazing pairs (both directions 0.006-0.3 degrees above the
/// horizon, any azimuths): beta = k w -> 0, the table's top end, where
/// c_n -> 0 for n != 0. Reading the cell from that end keeps beta's
/// relative precision in f32 (`table_cell`); from the bottom end, one f32
/// ulp of the position was 4e-4 of the cell's fraction there (the Hermite
/// weights, expanded, lost as much). Measured on these pairs, f32 (f64):
/// before, up to 1.9e-3 (5.0e-4) for the list's sine gratings against
/// the 1e-4 the JIT path is held to; now at most 5.4e-5 (1.2e-6).
#[test]
fn spectral_kernel_at_doubly_grazing_pairs() {
    let mut rng = crate::benchmark::SplitMix64(29);
    let mut rows = Vec::new();
    while rows.len() < 4000 {
        let [a, b, c] = rng.three();
        let [d, e, _] = rng.three();
        let lambda = (380.0 + 400.0 * a) as f32 as f64;
        let grazing = |z: f64, phi: f64| {
            let z = 1e-4 * (50.0f64).powf(z);
            let r = (1.0 - z * z).sqrt();
            round(DVec3::new(r * phi.cos(), r * phi.sin(), z))
        };
        rows.push((grazing(b, 2.0 * PI * c), grazing(d, 2.0 * PI * e), lambda));
    }
    for (name, brdf) in materials() {
        let (e32, e64, checked) = peak_errors(&brdf, &rows);
        println!("{name}: doubly grazing f32 {e32:.2e} f64 {e64:.2e} ({checked} checked)");
        assert!(checked > 0, "{name}: {checked}");
        assert!(e32 < 1e-4, "{name}: {e32}");
        assert!(e64 < 5e-6, "{name}: {e64}");
    }
}

#[test]
fn rgb_matches_native() {
    use crate::testing::programs::eval_rgb_errors;
    let pairs = pairs(3000, 17);
    for (name, brdf) in materials() {
        let e = eval_rgb_errors(&brdf, &pairs);
        let p = exported(&brdf, ProgramKind::EvalRgb).unwrap();
        let gathers = p.lane_gathers();
        println!(
            "{name}: RGB f32 {:.2e} f64 {:.2e} abs {:.1e} ({} checked); {} ops, {} gathers, {} table values",
            e.max_rel_f32,
            e.max_rel_f64,
            e.max_abs_f32,
            e.checked,
            p.code.len(),
            gathers,
            p.table_len()
        );
        assert!(e.max_rel_f32 < RGB_TOLERANCE, "{name}: {e:?}");
    }
}

/// What the program is held to against the native path, beside the core's
/// documented RGB error (docs/implementation.md: 3.1e-3 of the largest
/// channel against fine references, before gamut mapping): the program's
/// W~ table is exact where the native moments carry their own table error,
/// so the two differ by up to both errors (measured: within 3.1e-3 except
/// on dim peaks at the band's ends, where native and program each err by
/// up to 2e-2 against the fine reference).
const RGB_TOLERANCE: f64 = 5e-3;

/// The tabulated test profile's dim band-end peaks, where the native path's
/// own error against a 0.02 nm reference reaches 2.3e-2: the plain program
/// (its smoothed weight a Hermite in mu with exact slopes) differs from
/// native by up to 9e-3 there while erring less than native against the
/// reference (1.35e-2 at the worst pair, `SHOW=1 cargo test ...
/// rgb_before_gamut_mapping`); the linear table of the built-values
/// program happened to err alongside native (4.3e-3 from it).
const RGB_TOLERANCE_BAND_END: f64 = 1e-2;

/// What a material's RGB program is held to against native.
fn rgb_limit(name: &str, default: f64) -> f64 {
    if name == "tabulated index" {
        RGB_TOLERANCE_BAND_END
    } else {
        default
    }
}

/// 2000 f32 pairs on the orders' rainbows (u = n lambda / Lam for a random
/// lambda of the band, v within a peak width; a fifth on order 0, four
/// peak widths around the mirror direction), where the RGB value is large.
fn rgb_peak_pairs(period: f64, l: f64, seed: u64) -> Vec<(DVec3, DVec3)> {
    let mut rng = crate::benchmark::SplitMix64(seed);
    let mut pairs = Vec::new();
    while pairs.len() < 2000 {
        let [a, b2, c] = rng.three();
        let wi = DVec3::new(1.8 * b2 - 0.9, 0.4 * c - 0.2, 0.0);
        if wi.length_squared() > 0.995 {
            continue;
        }
        let wi = DVec3::new(wi.x, wi.y, (1.0 - wi.length_squared()).sqrt());
        let [d, e, f] = rng.three();
        let lambda = 380.0 + 400.0 * a;
        let k = crate::spectrum::wavenumber_per_um(lambda);
        let n_max = (2.0 * period * 1000.0 / lambda) as i64;
        let n = if d < 0.2 {
            0.0
        } else {
            ((2.0 * d - 1.0) * n_max as f64).round()
        };
        let spread = if n == 0.0 { 4.0 } else { 1.0 };
        let u = n * lambda / (1000.0 * period) + spread * (2.0 * e - 1.0) / (l * k);
        let v = spread * (2.0 * f - 1.0) / (l * k);
        let (x, y) = (-wi.x - u, -wi.y - v);
        if x * x + y * y > 0.999 {
            continue;
        }
        let wo = DVec3::new(x, y, (1.0 - x * x - y * y).sqrt());
        let (wi, wo) = (round(wi), round(wo));
        pairs.push((wi, wo));
    }
    pairs
}

/// Pairs on the orders' rainbows (u = n lambda / Lam for a random lambda of
/// the band, v within a peak width) and near the mirror direction, where
/// the RGB value is large: errors relative to each pair's largest channel.
fn rgb_peak_errors(brdf: &Brdf, seed: u64) -> (f64, f64, usize) {
    let program = exported(brdf, ProgramKind::EvalRgb).unwrap();
    rgb_peak_errors_of(brdf, &program, seed)
}

/// `rgb_peak_errors` of an RGB eval program of the material.
fn rgb_peak_errors_of(
    brdf: &Brdf,
    program: &crate::program::Program,
    seed: u64,
) -> (f64, f64, usize) {
    let crate::models::Surface::Periodic(m) = brdf.surface() else {
        unreachable!()
    };
    let (period, l) = (m.surface().period_um(), m.surface().coherence_um());
    let rows: Vec<_> = rgb_peak_pairs(period, l, seed)
        .into_iter()
        .map(|(wi, wo)| {
            let native = brdf.eval_rgb(wi, wo);
            (wi, wo, native, native[0].max(native[1]).max(native[2]))
        })
        .collect();
    let peak = rows.iter().map(|r| r.3).fold(0.0, f64::max);
    let (mut e32, mut e64, mut checked) = (0.0f64, 0.0f64, 0);
    for (wi, wo, native, scale) in rows {
        let (p32, p64) = run_both(program, &[wi.x, wi.y, wi.z, wo.x, wo.y, wo.z]);
        assert!(p32.iter().all(|v| v.is_finite() && *v >= 0.0));
        if scale < 1e-5 * peak {
            continue;
        }
        checked += 1;
        for ch in 0..3 {
            let err = (p32[ch] - native[ch]).abs() / scale;
            if err > e32 && std::env::var("SHOW").is_ok() {
                println!(
                    "  {err:.2e}: wi {wi} wo {wo} native {native:?} program {p32:?} f64 {p64:?}"
                );
            }
            e32 = e32.max(err);
            e64 = e64.max((p64[ch] - native[ch]).abs() / scale);
        }
    }
    (e32, e64, checked)
}

/// The RGB eval for the built parameters (`program_at_built`: the period
/// and the coherence length constants, the orders and levels planned for
/// them; the plain program plans for both to move, and reads the smoothed
/// weight C1 along those that carry gradients) holds the native path as
/// the plain one does, and is no larger.
#[test]
fn rgb_at_built_on_order_peaks() {
    for (name, brdf) in materials() {
        let Some(lean) = brdf.program_at_built(ProgramKind::EvalRgb) else {
            panic!("{name}: no RGB eval for the built parameters");
        };
        let plain = exported(&brdf, ProgramKind::EvalRgb).unwrap();
        let (e32, _, checked) = rgb_peak_errors_of(&brdf, &lean, 23);
        println!(
            "{name}: at-built RGB on peaks f32 {e32:.2e} ({checked} pairs); {} lane ops {} gathers, plain {} lane ops {} gathers",
            lean.lane_ops(),
            lean.lane_gathers(),
            plain.lane_ops(),
            plain.lane_gathers()
        );
        assert!(
            lean.lane_gathers() <= plain.lane_gathers() && lean.lane_ops() < plain.lane_ops(),
            "{name}"
        );
        assert!(e32 < RGB_TOLERANCE, "{name}: {e32}");
    }
}

#[test]
fn rgb_on_order_peaks() {
    for (name, brdf) in materials() {
        let (e32, e64, checked) = rgb_peak_errors(&brdf, 23);
        println!("{name}: RGB on peaks f32 {e32:.2e} f64 {e64:.2e} ({checked} pairs)");
        assert!(checked > 500, "{name}");
        assert!(e32 < rgb_limit(&name, RGB_TOLERANCE), "{name}: {e32}");
    }
}

/// The RGB program before gamut mapping (f / G, as `reflectance_rgb`)
/// against the native value at the same pairs as `rgb_peak_errors`.
fn rgb_pre_gamut_errors(brdf: &Brdf, seed: u64) -> (f64, usize) {
    use crate::models::{SurfaceModel, SurfacePrograms};
    use crate::optics::geometry::PairGeometry;
    use crate::optics::program::PairProgram;
    use crate::program::Builder;
    let crate::models::Surface::Periodic(m) = brdf.surface() else {
        unreachable!()
    };
    let b = Builder::new();
    let wi = [b.input(), b.input(), b.input()];
    let wo = [b.input(), b.input(), b.input()];
    let pair = PairProgram::new(&b, wi, wo);
    let shading = brdf.shading();
    let rgb = m
        .reflectance_rgb_program(&b, &shading, &pair, None)
        .unwrap();
    let program = b.finish(&rgb);
    let (period, l) = (m.surface().period_um(), m.surface().coherence_um());
    let rows: Vec<_> = rgb_peak_pairs(period, l, seed)
        .into_iter()
        .map(|(wi, wo)| {
            let g = PairGeometry::new(wi, wo).unwrap();
            let native = m.reflectance_rgb(&shading, &g);
            let scale = native.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            (wi, wo, native, scale)
        })
        .collect();
    let peak = rows.iter().map(|r| r.3).fold(0.0, f64::max);
    let (mut worst, mut checked) = (0.0f64, 0);
    for (wi, wo, native, scale) in rows {
        if scale < 1e-5 * peak {
            continue;
        }
        checked += 1;
        let x: Vec<f32> = [wi.x, wi.y, wi.z, wo.x, wo.y, wo.z]
            .map(|v| v as f32)
            .to_vec();
        let p = program.run(&x);
        for ch in 0..3 {
            let err = (p[ch] as f64 - native[ch]).abs() / scale;
            if err > worst && std::env::var("SHOW").is_ok() {
                let g = PairGeometry::new(wi, wo).unwrap();
                let truth = crate::spectrum::integrate_rgb_reference(
                    |l| brdf.eval_spectral(wi, wo, l) / g.geometric_factor,
                    0.02,
                );
                let rel = |x: [f64; 3]| {
                    (0..3).fold(0.0f64, |a, c| a.max((x[c] - truth[c]).abs())) / scale
                };
                let pp = [p[0] as f64, p[1] as f64, p[2] as f64];
                println!(
                    "  pre-gamut {err:.2e}: native vs truth {:.2e}, program vs truth {:.2e}; wi {wi} wo {wo} native {native:?}",
                    rel(native),
                    rel(pp)
                );
            }
            worst = worst.max(err);
        }
    }
    (worst, checked)
}

#[test]
fn rgb_before_gamut_mapping() {
    for (name, brdf) in materials() {
        let (e, checked) = rgb_pre_gamut_errors(&brdf, 23);
        println!("{name}: RGB before gamut mapping f32 {e:.2e} ({checked} pairs)");
        assert!(checked > 500, "{name}");
        // The shared list and the task's materials within RGB_TOLERANCE
        // (measured: within the documented 3.1e-3 but for compare_sine_gold,
        // 3.12e-3, on a dim peak where native and program err by 1.0e-2 and
        // 1.35e-2 against a 0.02 nm reference); the dim band-end peaks of
        // the tabulated test profile within RGB_TOLERANCE_BAND_END.
        assert!(e < rgb_limit(&name, RGB_TOLERANCE), "{name}: {e}");
    }
}

/// Incidences of the sampling tests: cos_i 1, 0.5, 0.1 (with azimuths).
fn incidences() -> [DVec3; 3] {
    let dir = |cos_t: f64, phi: f64| {
        let sin_t = (1.0 - cos_t * cos_t).sqrt();
        DVec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
    };
    [DVec3::Z, dir(0.5, 0.7), dir(0.1, 2.5)]
}

/// Chi-square fits of the sampling programs: p > 0.01, or a second run
/// with 4x the samples and another seed at p > 0.01 (as the native tests).
fn program_fits(label: &str, brdf: &Brdf, modes: &[Option<f64>], n: usize) {
    use crate::testing::chi2::chi2_fit;
    use crate::testing::programs::ProgramSampler;
    let mut failures = Vec::new();
    for (k, wi) in incidences().into_iter().enumerate() {
        for (m, &mode) in modes.iter().enumerate() {
            let sampler = ProgramSampler::new(brdf, wi, mode);
            let seed = 1000 * k as u64 + m as u64 + 31;
            let fit = chi2_fit(&sampler, seed, n);
            println!(
                "chi2 program {label} cos_i {:.2} {mode:?}: p = {:.4} (chi2 {:.1}, dof {}), integral {:.5}",
                wi.z, fit.p_value, fit.chi2, fit.dof, fit.integral
            );
            assert!(
                fit.integral <= 1.0 + 2e-3,
                "{label}: integral {}",
                fit.integral
            );
            if !(fit.p_value > 0.01) {
                let again = chi2_fit(&sampler, seed + 7_777_777, 4 * n);
                println!("    re-test: p = {:.4}", again.p_value);
                if !(again.p_value > 0.01) {
                    failures.push(format!("cos_i {} {mode:?}: p = {}", wi.z, again.p_value));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{label}: {failures:?}");
}

// One test per material, so that the harness runs them side by side.
#[test]
fn chi2_sampling_programs_cd() {
    let short_cd =
        Brdf::from_json(r#"{"surface": "cd", "coherence_um": 4, "fresnel": 0.9}"#).unwrap();
    program_fits("cd l=4", &short_cd, &[Some(550.0), None], 100_000);
}

#[test]
fn chi2_sampling_programs_sine() {
    let sine = Brdf::from_json(
        r#"{"surface":"periodic","period_um":1.6,"coherence_um":8,"profile":"sine","height_um":0.3,"fresnel":{"eta":1.5,"k":6}}"#,
    )
    .unwrap();
    program_fits("sine", &sine, &[Some(480.0), None], 100_000);
}

/// The plugin's chi-square materials of tests/materials.json (slow: run
/// with --ignored).
#[test]
#[ignore]
fn chi2_sampling_programs_shared_materials() {
    for (name, brdf) in materials() {
        if name.starts_with("chi2_") {
            program_fits(&name, &brdf, &[Some(450.0), None], 60_000);
        }
    }
}

/// Mean and variance of the directional-albedo estimator f cos / pdf (RGB:
/// the channels' sum) of `sample` at wi over n samples.
fn albedo_variance(
    brdf: &Brdf,
    wi: DVec3,
    mode: Option<f64>,
    n: usize,
    seed: u64,
    sample: &dyn Fn([f64; 3]) -> Option<(DVec3, f64)>,
) -> (f64, f64) {
    let mut rng = crate::benchmark::SplitMix64(seed);
    let (mut sum, mut sum2) = (0.0, 0.0);
    for _ in 0..n {
        let x = match sample(rng.three()) {
            Some((wo, pdf)) if pdf > 0.0 && wo.z > 0.0 => {
                let f = match mode {
                    Some(l) => brdf.eval_spectral(wi, wo, l),
                    None => brdf.eval_rgb(wi, wo).iter().sum(),
                };
                f * wo.z / pdf
            }
            _ => 0.0,
        };
        sum += x;
        sum2 += x * x;
    }
    let mean = sum / n as f64;
    (mean, sum2 / n as f64 - mean * mean)
}

/// The variance table of the sampling programs against the core's
/// strategies and cosine sampling (printed; run with --ignored).
#[test]
#[ignore]
fn sampling_variance_report() {
    use crate::testing::chi2::Sampler;
    use crate::testing::programs::ProgramSampler;
    let list = [
        ("compact disc", r#"{"surface": "cd", "fresnel": 0.9}"#),
        (
            "cd coherence 4",
            r#"{"surface": "cd", "coherence_um": 4, "fresnel": 0.9}"#,
        ),
        (
            "sine 1.2/0.12/20",
            r#"{"surface": "periodic", "period_um": 1.2, "profile": "sine", "height_um": 0.12, "coherence_um": 20, "fresnel": 0.9}"#,
        ),
    ];
    let n = 100_000;
    println!("| material | cos_i | mode | albedo program | albedo core | albedo cosine | Var program | Var core | Var cosine | core / program | cosine / program |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for (name, json) in list {
        let brdf = Brdf::from_json(json).unwrap();
        for wi in incidences() {
            for mode in [Some(550.0), None] {
                let program = ProgramSampler::new(&brdf, wi, mode);
                let (mp, vp) = albedo_variance(&brdf, wi, mode, n, 1, &|r| {
                    let s = program.sample(r);
                    Some((s.wo, s.pdf))
                });
                let strategy = brdf.sampler(wi, mode);
                let (mc, vc) = albedo_variance(&brdf, wi, mode, n, 2, &|r| {
                    let s = strategy.sample(r);
                    (!s.coherent).then_some((s.wo, s.pdf))
                });
                let (mk, vk) = albedo_variance(&brdf, wi, mode, n, 3, &|r| {
                    let wo = crate::sampling::warps::cosine_direction(r[1], r[2]);
                    Some((wo, wo.z / PI))
                });
                let mode_name = mode.map_or("RGB".to_string(), |l| format!("{l} nm"));
                println!(
                    "| {name} | {:.2} | {mode_name} | {mp:.4} | {mc:.4} | {mk:.4} | {vp:.3e} | {vc:.3e} | {vk:.3e} | {:.2} | {:.1} |",
                    wi.z,
                    vc / vp,
                    vk / vp
                );
            }
        }
    }
}

/// The coherent programs give the native values: gratings have no
/// coherent lobe (order 0 is a Gaussian lobe), so reflectance and
/// probability are 0, as natively.
#[test]
fn coherent_programs_match_native() {
    for (name, brdf) in materials() {
        let rgb = exported(&brdf, ProgramKind::CoherentRgb).unwrap();
        let spectral = exported(&brdf, ProgramKind::CoherentSpectral).unwrap();
        for (wi, _) in pairs(50, 3) {
            let wi = round(wi);
            let native = brdf.coherent_rgb(wi);
            let p = rgb.run(&[wi.x, wi.y, wi.z]);
            for c in 0..3 {
                assert_eq!(p[c], native[c], "{name}");
            }
            assert_eq!(p[3], brdf.coherent_probability(wi, None), "{name}");
            for lambda in [400.0, 550.0, 700.0] {
                let p = spectral.run(&[wi.x, wi.y, wi.z, lambda]);
                assert_eq!(p[0], brdf.coherent_spectral(wi, lambda), "{name}");
                assert_eq!(p[1], brdf.coherent_probability(wi, Some(lambda)), "{name}");
            }
        }
    }
}

/// Bad input (NaN, infinite, below the horizon, zero vectors, wavelength 0
/// or out of band, uniforms outside [0, 1)) gives finite non-negative
/// values of every program kind (sampled directions: finite, failed below
/// the horizon or unit above it).
#[test]
fn programs_are_finite_for_bad_input() {
    let bad = [
        f64::NAN,
        f64::INFINITY,
        -f64::INFINITY,
        -1.0,
        0.0,
        1e30,
        -1e-30,
        2.0,
    ];
    for (name, brdf) in materials().into_iter().take(6) {
        for kind in ProgramKind::ALL {
            let p = exported(&brdf, kind).unwrap();
            let mut rng = crate::benchmark::SplitMix64(9);
            for trial in 0..400 {
                let mut inputs: Vec<f64> = (0..p.n_inputs)
                    .map(|_| {
                        let [a, b, _] = rng.three();
                        if a < 0.3 {
                            bad[(b * bad.len() as f64) as usize % bad.len()]
                        } else {
                            2.0 * b - 1.0
                        }
                    })
                    .collect();
                if kind.spectral() && trial % 2 == 0 {
                    *inputs.last_mut().unwrap() = [0.0, 360.0, 830.0, 1e4, 550.0][trial % 5];
                }
                let (o32, o64) = run_both(&p, &inputs);
                for v in o32.iter().chain(&o64) {
                    assert!(v.is_finite(), "{name} {kind:?}: {v} for {inputs:?}");
                }
                let is_sample =
                    matches!(kind, ProgramKind::SampleRgb | ProgramKind::SampleSpectral);
                if !is_sample {
                    for v in o32.iter().chain(&o64) {
                        assert!(*v >= 0.0, "{name} {kind:?}: {v} for {inputs:?}");
                    }
                } else {
                    for o in [&o32, &o64] {
                        let len = (o[0] * o[0] + o[1] * o[1] + o[2] * o[2]).sqrt();
                        assert!(
                            o[2] <= 0.0 || (len - 1.0).abs() < 1e-3,
                            "{name} {kind:?}: {o:?}"
                        );
                    }
                }
            }
        }
    }
}

/// Op and gather counts of every program kind (printed for the report).
#[test]
fn program_sizes() {
    for (name, brdf) in materials() {
        let mut line = format!("{name}:");
        for kind in ProgramKind::ALL {
            let p = exported(&brdf, kind).unwrap();
            let gathers = p.lane_gathers();
            line += &format!(" {kind:?} {}/{}/{}", p.code.len(), gathers, p.table_len());
        }
        println!("{line}");
    }
}

/// Importance sampling worth having: the programs' estimator of the
/// directional albedo has less variance than cosine sampling's and is
/// within 2x of the core's strategies in spectral mode (RGB: within 4x; the
/// table of sampling_variance_report has the figures).
#[test]
fn sampling_variance_against_core_and_cosine() {
    use crate::testing::chi2::Sampler;
    use crate::testing::programs::ProgramSampler;
    for json in [
        r#"{"surface": "cd", "coherence_um": 4, "fresnel": 0.9}"#,
        r#"{"surface": "periodic", "period_um": 1.2, "profile": "sine", "height_um": 0.12, "coherence_um": 20, "fresnel": 0.9}"#,
    ] {
        let brdf = Brdf::from_json(json).unwrap();
        for wi in incidences() {
            for mode in [Some(550.0), None] {
                let n = 60_000;
                let program = ProgramSampler::new(&brdf, wi, mode);
                let (_, vp) = albedo_variance(&brdf, wi, mode, n, 1, &|r| {
                    let s = program.sample(r);
                    Some((s.wo, s.pdf))
                });
                let strategy = brdf.sampler(wi, mode);
                let (_, vc) = albedo_variance(&brdf, wi, mode, n, 2, &|r| {
                    let s = strategy.sample(r);
                    (!s.coherent).then_some((s.wo, s.pdf))
                });
                let (_, vk) = albedo_variance(&brdf, wi, mode, n, 3, &|r| {
                    let wo = crate::sampling::warps::cosine_direction(r[1], r[2]);
                    Some((wo, wo.z / PI))
                });
                println!(
                    "{json} cos_i {:.2} {mode:?}: program {vp:.3e} core {vc:.3e} cosine {vk:.3e}",
                    wi.z
                );
                assert!(vp < vk, "{json} {mode:?} cos_i {}: worse than cosine", wi.z);
                let limit = if mode.is_some() { 2.0 } else { 4.0 };
                assert!(
                    vp < limit * vc,
                    "{json} {mode:?} cos_i {}: {vp} vs core {vc}",
                    wi.z
                );
            }
        }
    }
}

/// "energy": "conserving" gratings (a sine and a rect grating, the compact
/// disc): the table is per wavelength, and its factor joins each order's
/// integration in the RGB program as natively (`FactorProgram`).
const CONSERVING: [(&str, &str); 3] = [
    (
        "sine conserving",
        r#"{"surface": "periodic", "period_um": 1.2, "profile": "sine", "height_um": 0.12, "coherence_um": 20, "energy": "conserving"}"#,
    ),
    (
        "rect gold conserving",
        r#"{"surface": "periodic", "period_um": 2.5, "profile": "rect", "height_um": 0.15, "width_um": 0.5, "coherence_um": 5.0, "fresnel": "gold", "energy": "conserving"}"#,
    ),
    (
        "cd conserving",
        r#"{"surface": "cd", "energy": "conserving"}"#,
    ),
];

/// The RGB program of conserving gratings against the native `eval_rgb`
/// at random, grazing and near-mirror pairs and on the orders' peaks,
/// held to the tolerance of the other gratings; the scaling matters at
/// these pairs (the native value differs from Stam's formula's by far
/// more than the tolerance), so that a program leaving it out fails; the
/// coherent RGB program exists and is 0, as natively.
#[test]
fn conserving_rgb_matches_native() {
    use crate::testing::programs::eval_rgb_errors;
    let pairs = pairs(3000, 29);
    for (name, json) in CONSERVING {
        let brdf = Brdf::from_json(json).unwrap();
        let stam = Brdf::from_json(&json.replace("conserving", "stam")).unwrap();
        assert!(!brdf.energy_table().unwrap().colour_neutral(), "{name}");
        let e = eval_rgb_errors(&brdf, &pairs);
        let (p32, p64, checked) = rgb_peak_errors(&brdf, 31);
        let (e_stam, (p_stam, ..)) = (eval_rgb_errors(&stam, &pairs), rgb_peak_errors(&stam, 31));
        let sizes = |p: &crate::program::Program| (p.code.len(), p.lane_gathers());
        let p = exported(&brdf, ProgramKind::EvalRgb).unwrap();
        let (ops, gathers) = sizes(&p);
        let (stam_ops, stam_gathers) = sizes(&exported(&stam, ProgramKind::EvalRgb).unwrap());
        // How much the scaling changes f at the pairs checked, above the
        // horizon taper (there it is the table's m alone).
        let effect = pairs
            .iter()
            .filter(|(wi, wo)| wi.z.min(wo.z) > 0.25)
            .map(|&(wi, wo)| {
                let (wi, wo) = (round(wi), round(wo));
                let (a, b) = (brdf.eval_rgb(wi, wo), stam.eval_rgb(wi, wo));
                let scale = b[0].max(b[1]).max(b[2]);
                (0..3)
                    .map(|c| (a[c] - b[c]).abs() / scale)
                    .filter(|x| x.is_finite())
                    .fold(0.0, f64::max)
            })
            .fold(0.0, f64::max);
        println!(
            "{name}: RGB f32 {:.2e} f64 {:.2e} ({} checked), on peaks f32 {p32:.2e} f64 {p64:.2e} ({checked}); the table's effect {effect:.2} (Stam's formula: f32 {:.2e}, on peaks {p_stam:.2e}); {ops} ops, {gathers} gathers, {} table values (Stam's formula: {stam_ops}, {stam_gathers})",
            e.max_rel_f32,
            e.max_rel_f64,
            e.checked,
            e_stam.max_rel_f32,
            p.table_len()
        );
        assert!(e.max_rel_f32 < RGB_TOLERANCE, "{name}: {e:?}");
        assert!(p32 < RGB_TOLERANCE, "{name}: on peaks {p32}");
        assert!(effect > 20.0 * RGB_TOLERANCE, "{name}: {effect}");
        let coherent = exported(&brdf, ProgramKind::CoherentRgb).unwrap();
        for &(wi, _) in &pairs[..50] {
            let wi = round(wi);
            let native = brdf.coherent_rgb(wi);
            let p = coherent.run(&[wi.x, wi.y, wi.z]);
            assert_eq!(&p[..3], &native[..], "{name}");
        }
    }
}

/// A grating whose RGB eval would unroll more than MAX_RGB_ORDERS orders
/// has no RGB eval program, so the JIT path cannot render it in RGB: its RGB
/// sampling programs are the cosine fallback, without the order table
/// (which would take about a second to make for such periods and be
/// unused); its spectral programs are all there. Within the limit the RGB
/// sampling programs read the table.
#[test]
fn rgb_order_table_only_with_an_rgb_eval() {
    let gathers = |brdf: &Brdf, kind| {
        let p = exported(brdf, kind).unwrap();
        p.lane_gathers()
    };
    for (period_um, has_rgb) in [(1.6, true), (60.0, false)] {
        let json = format!(
            r#"{{"surface": "periodic", "period_um": {period_um}, "profile": "sine", "height_um": 0.2, "coherence_um": 100, "energy": "stam"}}"#
        );
        let brdf = Brdf::from_json(&json).unwrap();
        assert_eq!(brdf.program(ProgramKind::EvalRgb).is_some(), has_rgb);
        for kind in [ProgramKind::PdfRgb, ProgramKind::SampleRgb] {
            assert_eq!(
                gathers(&brdf, kind) > 0,
                has_rgb,
                "{kind:?} at {period_um} um"
            );
        }
        for kind in [
            ProgramKind::EvalSpectral,
            ProgramKind::PdfSpectral,
            ProgramKind::SampleSpectral,
        ] {
            assert!(brdf.program(kind).is_some(), "{kind:?} at {period_um} um");
        }
    }
}

/// Differentiating its period and coherence length (an optimiser moving
/// them), a grating's programs are planned for their intervals on the
/// planning grid (`planning_interval`: the period's top, 1.587 um here,
/// and the coherence length's ends, 3.175 and 4 um): across the intervals
/// every kind exports the same code (the RGB eval: across the period's),
/// with tables of the same lengths, so that the rebuilds of an
/// optimisation reuse Dr.Jit's compiled kernels.
/// The orders planned beyond the material's own are never taken: the
/// spectral programs and the RGB sampling programs give what those of the
/// same material without gradients give (whose counts are its own: fewer
/// operations). The RGB eval planned so is held against the native path
/// by param_tests.rs, whose materials differentiate every parameter.
#[test]
fn a_differentiated_period_plans_for_its_interval() {
    let brdf_at = |period_um: f64, coherence_um: f64, gradients: &str| {
        Brdf::from_json(&format!(
            r#"{{"surface": "periodic", "period_um": {period_um}, "profile": "sine", "height_um": 0.2, "coherence_um": {coherence_um}, "fresnel": 0.9, "gradients": {gradients}}}"#
        ))
        .unwrap()
    };
    let brdf = |period_um: f64, gradients: &str| brdf_at(period_um, 4.0, gradients);
    let lengths =
        |p: &crate::program::Program| -> Vec<usize> { p.tables.iter().map(|t| t.len()).collect() };
    let (period, both) = (r#"["period_um"]"#, r#"["period_um", "coherence_um"]"#);
    let corners = [
        (brdf(1.27, period), brdf(1.55, period)),
        (brdf_at(1.27, 3.2, both), brdf_at(1.55, 3.95, both)),
    ];
    for (i, (low, high)) in corners.iter().enumerate() {
        // (The RGB eval plans the coherence length around its own value:
        // the interval's shortest would unroll two more broad orders.)
        for kind in ProgramKind::ALL
            .into_iter()
            .filter(|&k| i == 0 || k != ProgramKind::EvalRgb)
        {
            let (p, q) = (exported(low, kind).unwrap(), exported(high, kind).unwrap());
            assert!(
                p.code == q.code,
                "{i} {kind:?}: the code changed across the interval"
            );
            assert_eq!(lengths(&p), lengths(&q), "{i} {kind:?}'s tables");
        }
    }
    let [(low, _), _] = corners;
    // Across the grid's step at 1.26 um the sampling programs change.
    let below = exported(&brdf(1.25, period), ProgramKind::PdfSpectral).unwrap();
    let pdf = exported(&low, ProgramKind::PdfSpectral).unwrap();
    assert!(below.code.len() < pdf.code.len());

    let own = brdf(1.27, "false");
    let mut rng = crate::benchmark::SplitMix64(5);
    for kind in [
        ProgramKind::EvalSpectral,
        ProgramKind::PdfSpectral,
        ProgramKind::SampleSpectral,
        ProgramKind::PdfRgb,
        ProgramKind::SampleRgb,
    ] {
        let (planned, plain) = (exported(&low, kind).unwrap(), exported(&own, kind).unwrap());
        if kind != ProgramKind::EvalSpectral {
            assert!(
                planned.code.len() > plain.code.len(),
                "{kind:?}: no order planned"
            );
        }
        // The plain spectral sampling programs read the orders' weights
        // from the table made at the built period (`spectral_order_table`),
        // the planned ones compute them (they follow the period): two
        // strategies, each with its exact density, so only the others'
        // values are compared.
        let same_strategy = !matches!(kind, ProgramKind::PdfSpectral | ProgramKind::SampleSpectral);
        let mut nonzero = 0;
        for (i, (wi, wo)) in pairs(3000, 8).into_iter().enumerate() {
            let [a, b, c] = rng.three();
            let second = match kind {
                ProgramKind::SampleSpectral | ProgramKind::SampleRgb => [a, b, c],
                _ => [wo.x, wo.y, wo.z],
            };
            let mut inputs = vec![wi.x, wi.y, wi.z];
            inputs.extend(second);
            if kind.spectral() {
                inputs.push(380.0 + 400.0 * (i as f64 / 3000.0));
            }
            let (x, y) = (run_both(&planned, &inputs), run_both(&plain, &inputs));
            nonzero += (y.1[0] != 0.0) as usize;
            if !same_strategy {
                continue;
            }
            for (u, v) in x.0.iter().zip(&y.0).chain(x.1.iter().zip(&y.1)) {
                let scale = u.abs().max(v.abs()).max(1e-30);
                assert!(
                    (u - v).abs() <= 1e-6 * scale,
                    "{kind:?} at {inputs:?}: {u} against {v}"
                );
            }
        }
        assert!(nonzero > 100, "{kind:?}: {nonzero} non-zero values");
    }
}

/// The compact disc's spectral sampling programs read the orders' weights
/// from `spectral_order_table` (so their pdf takes none of the rect
/// profile's per-order powers), which took its render in
/// llvm_ad_spectral from 2.7x to 1.8x of roughconductor (a size cap had
/// once left its 27 orders out unnoticed); with a differentiated period
/// the weights are computed, following it.
#[test]
fn spectral_sampling_reads_the_order_table() {
    use crate::program::Op;
    let pdf = |json: &str| {
        let p = exported(&Brdf::from_json(json).unwrap(), ProgramKind::PdfSpectral).unwrap();
        p.code.iter().filter(|i| i.op == Op::Floor).count()
    };
    let (read, computed) = (
        pdf(r#"{"surface": "cd"}"#),
        pdf(r#"{"surface": "cd", "gradients": ["period_um"]}"#),
    );
    // A computed weight takes the rect profile's sin^2 (one floor in its
    // range reduction, `program::special::sin_squared`) per order: the
    // disc has 27; the table's reads take a handful.
    assert!(read < 10, "the disc computes its weights ({read} floors)");
    assert!(computed >= 27, "{computed} floors");
}

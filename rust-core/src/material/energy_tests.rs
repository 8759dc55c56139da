//! Tests of the energy-conserving material ("energy": "conserving"): the white furnace (directional
//! albedo of a white material at most 1 within its Monte Carlo error, for
//! every model, spectral and RGB luminance, down to grazing incidence),
//! reciprocity, the default, and Stam's formula where the parameter asks for it.

use super::*;
use crate::sampling::SplitMix64;
use std::f64::consts::PI;

/// White (fresnel = 1) test materials of every model.
const MATERIALS: [&str; 7] = [
    r#"{"surface":"cd","fresnel":1,"energy":"conserving"}"#,
    r#"{"surface":"periodic","period_um":1.2,"coherence_um":20,"profile":"sine","height_um":0.12,"fresnel":1,"energy":"conserving"}"#,
    r#"{"surface":"gaussian","sigma_um":0.3,"corr_um":2,"fresnel":1,"energy":"conserving"}"#,
    r#"{"surface":"gaussian","sigma_um":0.08,"corr_um":1.5,"fresnel":1,"energy":"conserving"}"#,
    r#"{"surface":"gaussian","sigma_um":0.1,"corr_x_um":4,"corr_y_um":0.8,"fresnel":1,"energy":"conserving"}"#,
    r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.1,"lag_um":2,"fresnel":1,"energy":"conserving"}"#,
    r#"{"surface":"fractal","hurst":0.4,"sigma_um":0.3,"lag_um":1,"fresnel":1,"energy":"conserving"}"#,
];

fn direction(cos: f64, phi: f64) -> DVec3 {
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    DVec3::new(sin * phi.cos(), sin * phi.sin(), cos)
}

/// Mean and standard error of the sample weight (spectral at `lambda`, or
/// the RGB luminance for None) of `n` samples of the material's strategy.
fn albedo(brdf: &Brdf, wi: DVec3, lambda: Option<f64>, n: usize, seed: u64) -> (f64, f64) {
    let strategy = brdf.sampler(wi, lambda);
    let y = |c: [f64; 3]| -> f64 {
        spectrum::SRGB_LUMINANCE
            .iter()
            .zip(c)
            .map(|(w, x)| w * x)
            .sum()
    };
    let mut rng = SplitMix64(seed);
    let (mut sum, mut sum2) = (0.0, 0.0);
    for _ in 0..n {
        let s = strategy.sample(rng.three());
        let w = if !(s.pdf > 0.0) {
            0.0
        } else if s.coherent {
            match lambda {
                Some(l) => brdf.coherent_spectral(wi, l),
                None => y(brdf.coherent_rgb(wi)),
            }
        } else {
            let f = match lambda {
                Some(l) => brdf.eval_spectral(wi, s.wo, l),
                None => y(brdf.eval_rgb(wi, s.wo)),
            };
            f * s.wo.z
        } / if s.pdf > 0.0 { s.pdf } else { 1.0 };
        sum += w;
        sum2 += w * w;
    }
    let mean = sum / n as f64;
    let se = ((sum2 / n as f64 - mean * mean).max(0.0) / n as f64).sqrt();
    (mean, se)
}

/// The conserving material reflects at most what it receives: albedo <= 1 + 3
/// standard errors at normal, oblique and grazing incidence (cos_i down to
/// 0.02), at three wavelengths and in RGB (luminance), for every model;
/// Stam's formula, on the same grid, does not (the test can fail).
#[test]
fn white_furnace_conserving_at_most_one() {
    let mut worst: f64 = 0.0;
    let mut stam_worst: f64 = 0.0;
    for (m, json) in MATERIALS.iter().enumerate() {
        let brdf = Brdf::from_json(json).unwrap();
        let stam = Brdf::from_json(&json.replace("conserving", "stam")).unwrap();
        for (k, &cos) in [0.9, 0.5, 0.2, 0.08, 0.02].iter().enumerate() {
            let wi = direction(cos, 0.4 + 1.3 * k as f64);
            for lambda in [Some(420.0), Some(560.0), Some(690.0), None] {
                let seed = (m * 16 + k) as u64;
                let (a, se) = albedo(&brdf, wi, lambda, 6000, seed);
                println!("{json} cos {cos} {lambda:?}: {a:.4} +- {se:.4}");
                assert!(
                    a <= 1.0 + 3.0 * se,
                    "{json} cos_i {cos} {lambda:?}: {a} +- {se}"
                );
                worst = worst.max(a);
                stam_worst = stam_worst.max(albedo(&stam, wi, lambda, 2000, seed).0);
            }
        }
    }
    println!("largest albedo: conserving {worst:.3}, Stam's formula {stam_worst:.3}");
    assert!(
        stam_worst > 1.5,
        "the grid reaches Stam's excess: {stam_worst}"
    );
}

/// Where a grating's albedo changes faster than the table's cells: the
/// compact disc at cos_i 0.4, azimuth atan2(0.6, 0.8) (the furnace
/// example's incidence), reached 1.026 +- 0.001 with the random surfaces'
/// target 0.995; gratings' target 0.97 keeps it at most 1 + 3 standard
/// errors at 400, 550 and 700 nm.
#[test]
fn compact_disc_stays_below_one_between_table_cells() {
    let brdf = Brdf::from_json(MATERIALS[0]).unwrap();
    let wi = direction(0.4, 0.6_f64.atan2(0.8));
    for (k, lambda) in [400.0, 550.0, 700.0].into_iter().enumerate() {
        let (a, se) = albedo(&brdf, wi, Some(lambda), 40_000, 70 + k as u64);
        println!("cd cos_i 0.4 at {lambda} nm: {a:.4} +- {se:.4}");
        assert!(a <= 1.0 + 3.0 * se, "{lambda} nm: {a} +- {se}");
    }
}

/// One wavelength's factor from its two nodes (`pair_at`, what a spectral
/// evaluation uses) equals the factor from the pair's products at all the
/// nodes (`pair(..).at`, made on its first wavelength, for several),
/// exactly, whichever wavelength a pair was asked for first, for a
/// per-wavelength (grating) and a colour-neutral (Gaussian) table, inside
/// and outside the band's nodes. (The values themselves are checked against
/// the exported program in `energy_table_program_matches_native`.)
#[test]
fn one_wavelength_factor_equals_the_all_node_one() {
    let mut rng = SplitMix64(4);
    for json in [MATERIALS[0], MATERIALS[4]] {
        let table = Brdf::from_json(json).unwrap();
        let table = table.energy_table().unwrap();
        for _ in 0..2000 {
            let wi = direction(rng.next_f64(), 6.3 * rng.next_f64());
            let wo = direction(rng.next_f64(), 6.3 * rng.next_f64());
            let lambdas = [
                300.0 + 600.0 * rng.next_f64(),
                380.0 + 400.0 * rng.next_f64(),
            ];
            let pair = table.pair(wi, wo);
            for lambda in lambdas {
                let all = pair.at(lambda);
                assert_eq!(table.pair_at(wi, wo, lambda), all, "{json} at {lambda} nm");
            }
        }
    }
}

/// f(wi, wo) = f(wo, wi) to 1e-5 relative for the conserving material, spectral and
/// RGB, over random pairs (grazing ones included); values below 1e-12 /sr
/// (the far tails, where the series is cut at a tolerance) are not
/// compared.
#[test]
fn conserving_is_reciprocal() {
    let mut rng = SplitMix64(9);
    let mut worst: f64 = 0.0;
    for json in MATERIALS {
        let brdf = Brdf::from_json(json).unwrap();
        for _ in 0..400 {
            let wi = direction(0.01 + 0.99 * rng.next_f64(), 6.3 * rng.next_f64());
            let wo = direction(0.01 + 0.99 * rng.next_f64(), 6.3 * rng.next_f64());
            let lambda = 360.0 + 470.0 * rng.next_f64();
            let pairs = [
                (
                    brdf.eval_spectral(wi, wo, lambda),
                    brdf.eval_spectral(wo, wi, lambda),
                ),
                (brdf.eval_rgb(wi, wo)[0], brdf.eval_rgb(wo, wi)[0]),
                (brdf.eval_rgb(wi, wo)[2], brdf.eval_rgb(wo, wi)[2]),
            ];
            for (a, b) in pairs {
                let scale = a.abs().max(b.abs());
                if scale > 1e-12 {
                    let e = (a - b).abs() / scale;
                    worst = worst.max(e);
                    assert!(e < 1e-5, "{json} {wi} {wo} {lambda}: {a} vs {b}");
                }
            }
        }
    }
    println!("reciprocity: worst relative difference {worst:.1e}");
}

/// The conserving material is the default and builds its table lazily
/// (counted in its memory); `"energy": "stam"` has no table; a sigma
/// texture's material (no one sigma to build a table for) defaults to
/// Stam's formula and refuses "conserving" by name; a bad value is refused
/// by name.
#[test]
fn conserving_is_the_default() {
    let brdf = Brdf::from_json(r#"{"surface":"cd"}"#).unwrap();
    let before = brdf.memory_bytes();
    let table = brdf.energy_table().unwrap();
    assert_eq!(brdf.memory_bytes(), before + table.memory_bytes());
    let stam = Brdf::from_json(r#"{"surface":"cd","energy":"stam"}"#).unwrap();
    assert!(stam.energy_table().is_none());
    let textured = r#"{"surface":"gaussian","sigma_um":0.1,"sigma_um_max":0.4,"corr_um":2}"#;
    assert!(Brdf::from_json(textured).unwrap().energy_table().is_none());
    let e = Brdf::from_json(&textured.replace('}', r#","energy":"conserving"}"#))
        .err()
        .unwrap();
    assert!(e.message.contains("'sigma_um_max'"), "{}", e.message);
    let e = Brdf::from_json(r#"{"surface":"cd","energy":"loud"}"#)
        .err()
        .unwrap();
    assert!(e.message.contains("'energy'"), "{}", e.message);
}

/// Materials with equal surface parameters share one table (built once per
/// process), whatever their Fresnel term.
#[test]
fn equal_surfaces_share_their_table() {
    let json = r#"{"surface":"gaussian","sigma_um":0.21,"corr_um":1.7}"#;
    let a = Brdf::from_json(json).unwrap();
    let b = Brdf::from_json(&json.replace('}', r#","fresnel":"gold"}"#)).unwrap();
    let c = Brdf::from_json(&json.replace("0.21", "0.22")).unwrap();
    let (ta, tb, tc) = (
        a.energy_table().unwrap(),
        b.energy_table().unwrap(),
        c.energy_table().unwrap(),
    );
    assert!(std::ptr::eq(ta, tb));
    assert!(!std::ptr::eq(ta, tc));
}

/// The table as a program (TableProgram::pair, what the JIT path
/// multiplies f by, and pair_factor, what a grating's RGB program
/// multiplies at many wavelengths: at a program's wavelength and at fixed
/// ones) against `pair(wi, wo).at(lambda)`: per-wavelength (the compact
/// disc) and colour-neutral (Gaussian, anisotropic), random and grazing
/// directions.
#[test]
fn energy_table_program_matches_native() {
    use crate::models::FactorProgram;
    use crate::program::Builder;
    // Fixed wavelengths: outside the table's range, on its nodes, between.
    let fixed = [360.0, 380.0, 396.25, 512.3, 555.0, 780.0, 830.0];
    for json in [MATERIALS[0], MATERIALS[2], MATERIALS[4]] {
        let brdf = Brdf::from_json(json).unwrap();
        let table = brdf.energy_table().unwrap();
        let b = Builder::new();
        let wi = [b.input(), b.input(), b.input()];
        let wo = [b.input(), b.input(), b.input()];
        let lambda = b.input();
        let out = table.program(&b, &[]).pair(wi, wo, Some(lambda)).unwrap();
        let factor = table.program(&b, &[]).pair_factor(wi, wo);
        let mut outputs = vec![out, factor.at(lambda)];
        outputs.extend(fixed.map(|l| factor.at_nm(l)));
        let program = b.finish(&outputs);
        // Without a wavelength: only colour-neutral tables have a program.
        let b2 = Builder::new();
        let up = [b2.c(0.0), b2.c(0.0), b2.c(1.0)];
        assert_eq!(
            table.program(&b2, &[]).pair(up, up, None).is_some(),
            table.colour_neutral()
        );
        let mut rng = SplitMix64(7);
        let mut worst: f64 = 0.0;
        for i in 0..20_000 {
            let r = rng.three();
            let cos_i = if i % 4 == 0 { 0.1 * r[0] } else { r[0] };
            let cos_o = if i % 4 == 1 { 0.1 * r[1] } else { r[1] };
            let wi = direction(cos_i.max(1e-4), 2.0 * PI * r[2]);
            let wo = direction(cos_o.max(1e-4), 2.0 * PI * rng.three()[0]);
            let lambda = 360.0 + 470.0 * rng.three()[1];
            let pair = table.pair(wi, wo);
            let got = program.run(&[wi.x, wi.y, wi.z, wo.x, wo.y, wo.z, lambda]);
            let native = [lambda, lambda]
                .into_iter()
                .chain(fixed)
                .map(|l| pair.at(l));
            for (g, n) in got.iter().zip(native) {
                worst = worst.max((g - n).abs());
            }
        }
        println!("{json}: worst |program - native| = {worst:.2e}");
        // The table is exported in f32.
        assert!(worst < 1e-6, "{json}: {worst}");
    }
}

/// A grating's table holds m on the grid of 1 / PACK_LEVELS within [0, 1],
/// and its packed copy (two nodes per f32, what the RGB programs gather)
/// decodes in f32 to exactly those levels.
#[test]
fn packed_pairs_hold_the_table_exactly() {
    use crate::program::lookup::PAIR_LEVELS as PACK_LEVELS;
    let brdf = Brdf::from_json(MATERIALS[0]).unwrap();
    let table = brdf.energy_table().unwrap();
    let (m, nodes) = table.values();
    assert!(nodes > 1 && !table.colour_neutral());
    assert!(
        m.iter().any(|&x| x < 1.0),
        "a grating's table scales somewhere"
    );
    for &x in m {
        let level = x * PACK_LEVELS;
        assert!(
            (0.0..=1.0).contains(&x) && (level - level.round()).abs() < 1e-9,
            "{x}"
        );
    }
    let packed = table.packed_pairs();
    let pairs = nodes.div_ceil(2);
    assert_eq!(packed.len(), m.len() / nodes * pairs);
    for (cell, row) in m.chunks(nodes).enumerate() {
        for p in 0..pairs {
            // Decoded in f32, as a program does.
            let v = packed[cell * pairs + p];
            let hi = v.floor();
            let lo = (v - hi) * 4096.0;
            assert_eq!(hi as f64, (row[2 * p] * PACK_LEVELS).round());
            let want = row
                .get(2 * p + 1)
                .map_or(0.0, |&x| (x * PACK_LEVELS).round());
            assert_eq!(lo as f64, want, "cell {cell} pair {p}");
        }
    }
}

/// At moderate angles (cos_i and cos_o at least 0.5) the conserving
/// Gaussian and fractal surfaces keep Stam's f within 2% (the issue's
/// bound; docs/energy.md): their albedo there is at most about 1, so only
/// the table's margin and noise change f. Measured as the table's own bound
/// (1 - the smallest m on a 64 x 64 grid there, squared) and at random
/// pairs against Stam's formula. Gratings are not held to it: their Stam
/// albedo exceeds 1 at moderate angles (docs/energy.md).
#[test]
fn random_surfaces_keep_stams_f_at_moderate_angles() {
    let mut rng = SplitMix64(21);
    for json in &MATERIALS[2..] {
        let brdf = Brdf::from_json(json).unwrap();
        let stam = Brdf::from_json(&json.replace("conserving", "stam")).unwrap();
        let bound = 1.0 - brdf.energy_table().unwrap().min_factor_within(0.5).powi(2);
        let mut sampled: f64 = 0.0;
        for _ in 0..2000 {
            let wi = direction(0.5 + 0.5 * rng.next_f64(), 6.3 * rng.next_f64());
            let wo = direction(0.5 + 0.5 * rng.next_f64(), 6.3 * rng.next_f64());
            let lambda = 380.0 + 400.0 * rng.next_f64();
            let (a, b) = (
                brdf.eval_spectral(wi, wo, lambda),
                stam.eval_spectral(wi, wo, lambda),
            );
            if b > 1e-12 {
                sampled = sampled.max(1.0 - a / b);
            }
        }
        println!("{json}: moderate-angle change: table bound {bound:.4}, sampled {sampled:.4}");
        assert!(bound <= 0.02 + 1e-12, "{json}: {bound}");
        assert!(sampled <= 0.02, "{json}: {sampled}");
    }
}

/// With `"gradients": true` a program's derivative along each
/// surface parameter it reads (what a renderer's AD sees) is the central
/// difference of the native conserving material, whose table is rebuilt at
/// each value: the aggregate error over random pairs (gratings: half on
/// their orders' flanks), against what the table held constant misses.
/// Where a 2% step moves a grating's peaks by more than their width (its
/// period) the full difference is no derivative; there (and for every
/// spectral eval) the table's own part is checked: the program's
/// derivative less the held table's is Stam's f times the derivative of
/// the pair's factor between the rebuilt tables.
#[test]
fn energy_derivatives_follow_rebuilt_tables() {
    use crate::material::program::ProgramKind::{self, *};
    use crate::program::{ParamId, Program};
    use crate::testing::params::{grating_lanes, lanes, native, run, Lane};
    let cases: [(&str, &[ProgramKind]); 4] = [
        (
            r#"{"surface":"gaussian","sigma_um":0.12,"corr_um":1.5,"fresnel":0.9}"#,
            &[EvalSpectral, EvalRgb, CoherentSpectral, CoherentRgb],
        ),
        (
            r#"{"surface":"gaussian","sigma_um":0.1,"corr_x_um":4,"corr_y_um":0.8,"fresnel":0.9}"#,
            &[EvalSpectral],
        ),
        (
            r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.1,"lag_um":2,"fresnel":0.9}"#,
            &[EvalSpectral, EvalRgb],
        ),
        (
            r#"{"surface":"periodic","period_um":1.2,"coherence_um":20,"profile":"sine","height_um":0.12,"fresnel":0.9}"#,
            &[EvalSpectral, EvalRgb],
        ),
    ];
    for (json, kinds) in cases {
        let base = MaterialParams::from_json(json).unwrap();
        let with = Brdf::new(MaterialParams {
            gradients: base.surface.table_params().iter().map(|p| p.0).collect(),
            ..base.clone()
        })
        .unwrap();
        let without = Brdf::new(base.clone()).unwrap();
        let stam = Brdf::new(MaterialParams {
            energy: EnergyMode::Stam,
            ..base.clone()
        })
        .unwrap();
        let ls = match &base.surface {
            SurfaceParams::Periodic(_) => grating_lanes(1.2, 20.0, 400, 7),
            _ => lanes(400, 7),
        };
        for &kind in kinds {
            let (p, p_held) = (with.program(kind).unwrap(), without.program(kind).unwrap());
            for (id, v) in base.surface.table_params() {
                if p.param_slot(id).is_none() {
                    continue;
                }
                let at = |x: f64| {
                    Brdf::new(MaterialParams {
                        surface: base.surface.with_param(id, x),
                        ..base.clone()
                    })
                    .unwrap()
                };
                let step = energy::derivative_step(id);
                let (up, down) = (at(v * step.exp()), at(v / step.exp()));
                // d f / d ln p of a program by a central difference of 1e-4.
                let h = 1e-4;
                let d_program = |prog: &Program, l: &Lane| -> Vec<f64> {
                    let vals = |x: f64| -> Vec<f64> {
                        prog.params
                            .iter()
                            .map(|&(pid, val)| if pid == id { x } else { val as f64 })
                            .collect()
                    };
                    let (a, b) = (
                        run(prog, kind, l, &vals(v * (1.0 + h)), true),
                        run(prog, kind, l, &vals(v * (1.0 - h)), true),
                    );
                    a.iter().zip(&b).map(|(a, b)| (a - b) / (2.0 * h)).collect()
                };
                let [mut err, mut err_held, mut total, mut err_term, mut total_term] = [0.0; 5];
                for l in &ls {
                    let (nu, nd) = (native(&up, kind, l), native(&down, kind, l));
                    let (d, d_held) = (d_program(&p, l), d_program(&p_held, l));
                    for c in 0..nu.len() {
                        let d_native = (nu[c] - nd[c]) / (2.0 * step);
                        total += d_native.abs();
                        err += (d[c] - d_native).abs();
                        err_held += (d_held[c] - d_native).abs();
                    }
                    if kind == EvalSpectral {
                        let m = |b: &Brdf| b.pair_energy(l.wi, l.wo).unwrap().at(l.lambda);
                        let dm = (m(&up) - m(&down)) / (2.0 * step);
                        let term = stam.eval_spectral(l.wi, l.wo, l.lambda) * dm;
                        total_term += term.abs();
                        err_term += (d[0] - d_held[0] - term).abs();
                    }
                }
                let (rel, rel_held) = (err / total, err_held / total);
                let rel_term = err_term / total_term.max(1e-300);
                println!(
                    "{json} {kind:?} {id:?}: derivative error {rel:.4} (table held: {rel_held:.4}){}",
                    if kind == EvalSpectral { format!("; table's part {rel_term:.4}") } else { String::new() }
                );
                if id != ParamId::PeriodUm {
                    assert!(rel < 0.03, "{json} {kind:?} {id:?}: {rel}");
                }
                if kind == EvalSpectral {
                    assert!(rel_term < 0.01, "{json} {kind:?} {id:?}: {rel_term}");
                }
            }
        }
    }
}

/// `"gradients"` builds only what it names (each costs two table
/// builds): a list, true for every parameter the table depends on, and
/// names the table does not depend on passed over.
#[test]
fn energy_derivatives_are_built_for_the_named_parameters() {
    use crate::program::ParamId;
    let ids = |json: &str| -> Vec<ParamId> {
        Brdf::from_json(json)
            .unwrap()
            .energy_derivatives()
            .iter()
            .map(|d| d.id)
            .collect()
    };
    let g = r#""surface":"gaussian","sigma_um":0.12,"corr_um":1.5,"fresnel":0.9"#;
    assert_eq!(
        ids(&format!(r#"{{{g},"gradients":["sigma_um","fresnel"]}}"#)),
        vec![ParamId::SigmaUm]
    );
    assert_eq!(
        ids(&format!(r#"{{{g},"gradients":true}}"#)),
        vec![ParamId::SigmaUm, ParamId::CorrUm]
    );
    assert!(ids(&format!("{{{g}}}")).is_empty());
    assert!(ids(&format!(r#"{{{g},"energy":"stam","gradients":true}}"#)).is_empty());
}

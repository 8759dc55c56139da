//! The material's programs: what every material exports, checked against
//! the native path where the model has programs (the models' own tests
//! go further: rust-core/src/models/*/program.rs).

use super::program::ProgramKind;
use crate::program::{decode, Builder};
use crate::testing::programs::{run_both, ProgramSampler};
use crate::Brdf;
use glam::DVec3;

#[test]
fn encode_decode_round_trip_and_dead_code_removed() {
    let b = Builder::new();
    let x = b.input();
    let y = b.input();
    let _unused = (x * y).exp();
    let t = b.table(vec![1.0, 2.0, 4.0]);
    let z = (x + 1.5).max(y) * b.gather(t, y);
    let p = b.finish(&[z, x.lt(y).select(x, 7.0)]);
    assert!(p.code.iter().all(|i| i.op != crate::program::Op::Exp));
    let q = decode(&p.encode()).unwrap();
    assert_eq!(q.code, p.code);
    assert_eq!(q.run(&[1.0f64, 2.0]), vec![(2.5f64).max(2.0) * 4.0, 1.0]);
    // Gathers stay inside their table whatever the index.
    assert_eq!(q.run(&[0.0f64, -5.0])[0], 1.5 * 1.0);
    assert_eq!(q.run(&[0.0f64, 1e9])[0], 1e9 * 4.0);
    assert_eq!(q.run(&[0.0f64, f64::NAN])[0], 1.0 * 1.5);
    // A corrupted array is refused, not run.
    let mut bad = p.encode();
    // The last instruction's first operand (a select's mask) out of range.
    bad[8 + 2 + 2 + 4 * (p.code.len() - 1) + 1] = 1e6;
    assert!(decode(&bad).is_none());
}

/// Every material exports every kind: each model, with Stam's formula and
/// with "energy": "conserving" (colour-neutral tables for Gaussian and
/// fractal surfaces, a table per wavelength for gratings).
#[test]
fn every_material_exports_every_program() {
    for json in [
        r#"{"surface": "gaussian", "sigma_um": 0.1, "corr_um": 2}"#,
        r#"{"surface": "cd"}"#,
        r#"{"surface": "fractal", "sigma_um": 0.1, "hurst": 0.7, "lag_um": 2}"#,
        r#"{"surface": "gaussian", "sigma_um": 0.1, "corr_um": 2, "energy": "conserving"}"#,
        r#"{"surface": "cd", "energy": "conserving"}"#,
        r#"{"surface": "fractal", "sigma_um": 0.1, "hurst": 0.7, "lag_um": 2, "energy": "conserving"}"#,
    ] {
        let brdf = Brdf::from_json(json).unwrap();
        let wi = DVec3::new(0.3, 0.1, 0.9).normalize();
        for lambda in [None, Some(500.0)] {
            let s = ProgramSampler::new(&brdf, wi, lambda);
            let _ = s;
        }
        // Bad input gives finite zeros.
        for kind in ProgramKind::ALL {
            let p = brdf
                .program(kind)
                .unwrap_or_else(|| panic!("{json} has no {kind:?} program"));
            // The kind's inputs and outputs (stam_program_io).
            assert_eq!(
                (p.n_inputs as usize, p.outputs.len()),
                kind.io(),
                "{kind:?}"
            );
            for bad in [f64::NAN, -1.0, 0.0] {
                let mut inputs = vec![0.1, 0.2, bad];
                inputs.resize(p.n_inputs as usize, bad);
                let (o32, o64) = run_both(&p, &inputs);
                for v in o32.iter().chain(&o64) {
                    assert!(v.is_finite(), "{kind:?} of {json} gave {v} for {bad}");
                }
            }
        }
    }
}

/// A material rebuilt for parameters 0.3% away exports the same code,
/// constants included, with tables of the same lengths: what follows the
/// parameters is in the tables (`Builder::built`), so that a renderer's
/// compiled kernels stay valid across such a rebuild (docs/jit.md,
/// "Parameters"). Every parameter the models' programs read, in each kind
/// and its program for the built values; the grating as an optimiser sees
/// it (differentiating its period). What may change the code (a grating's
/// count of orders, a table profile's RGB plan) does not change over 0.3%
/// at these values.
#[test]
fn a_nearby_material_exports_the_same_code() {
    let cases: [(&str, &[&str]); 9] = [
        (
            r#"{"surface": "gaussian", "sigma_um": 0.05, "corr_um": 2.0, "fresnel": 0.9}"#,
            &["sigma_um", "corr_um", "fresnel"],
        ),
        (
            r#"{"surface": "gaussian", "sigma_um": 0.5, "corr_um": 5.0}"#,
            &["sigma_um", "corr_um"],
        ),
        (
            r#"{"surface": "gaussian", "sigma_um": 0.1, "corr_x_um": 0.8, "corr_y_um": 6.0, "fresnel": "aluminium"}"#,
            &["sigma_um", "corr_x_um", "corr_y_um"],
        ),
        (
            r#"{"surface": "fractal", "sigma_um": 0.05, "hurst": 0.7, "lag_um": 1.0}"#,
            &["sigma_um", "lag_um"],
        ),
        (
            r#"{"surface": "periodic", "period_um": 1.56, "profile": "sine", "height_um": 0.2, "coherence_um": 4.0, "fresnel": 0.9, "gradients": ["period_um"]}"#,
            &["period_um", "height_um", "coherence_um"],
        ),
        (
            r#"{"surface": "periodic", "period_um": 2.5, "profile": "rect", "height_um": 0.15, "width_um": 0.5, "coherence_um": 5.0}"#,
            &["period_um", "height_um", "width_um", "coherence_um"],
        ),
        (
            r#"{"surface": "periodic", "period_um": 1.0, "profile": {"heights_um": [0.0, 0.05, 0.1, 0.15, 0.1, 0.05]}, "coherence_um": 5.0}"#,
            &["period_um"],
        ),
        (
            r#"{"surface": "cd", "period_um": 1.0, "width_um": 0.2, "coherence_um": 3.0}"#,
            &["period_um", "width_um"],
        ),
        (
            r#"{"surface": "periodic", "period_um": 1.6, "profile": "sine", "height_um": 0.25, "coherence_um": 8.0, "energy": "conserving"}"#,
            &["period_um", "height_um"],
        ),
    ];
    let kinds: Vec<(ProgramKind, bool)> = ProgramKind::ALL
        .iter()
        .flat_map(|&k| [(k, false), (k, true)])
        .collect();
    let export = |brdf: &Brdf, (kind, at_built): (ProgramKind, bool)| {
        if at_built {
            brdf.program_at_built(kind)
        } else {
            brdf.program(kind)
        }
    };
    for (json, keys) in cases {
        let base: serde_json::Value = serde_json::from_str(json).unwrap();
        let brdf = Brdf::from_json(json).unwrap();
        for key in keys {
            let mut moved = base.clone();
            let v = moved[*key].as_f64().unwrap();
            moved[*key] = serde_json::json!(v * 1.003);
            let near = Brdf::from_json(&moved.to_string()).unwrap();
            let mut tables_moved = false;
            for &k in &kinds {
                let (p, q) = (export(&brdf, k), export(&near, k));
                assert_eq!(p.is_some(), q.is_some(), "{json}, {key}: {k:?}");
                let (Some(p), Some(q)) = (p, q) else { continue };
                assert!(p.code == q.code, "{json}, {key}: the code of {k:?} changed");
                let lengths = |p: &crate::program::Program| -> Vec<usize> {
                    p.tables.iter().map(|t| t.len()).collect()
                };
                assert_eq!(lengths(&p), lengths(&q), "{json}, {key}: {k:?}'s tables");
                tables_moved |= p.tables != q.tables || p.params != q.params;
            }
            // The change reached the programs (through tables or parameters)
            assert!(tables_moved, "{json}, {key}: no program changed");
        }
    }
}

/// Materials of one model that differ only in numbers (not in structure:
/// the same metal, the same anisotropy, the same Hurst exponent) export
/// programs with the same code: their tables' values and sizes, the
/// parameters' values and the built constants are data, which a renderer
/// reads from memory. So a tracing renderer compiles their code once for
/// all of them (the plugin reads the tables' starts and sizes from memory
/// too, mitsuba-plugin/program.h; Dr.Jit then traces identical code for
/// each material alive and compiles it once; docs/jit.md).
#[test]
fn materials_differing_in_numbers_share_their_code() {
    let pairs = [
        (
            r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2.0}"#,
            r#"{"surface":"gaussian","sigma_um":0.3,"corr_um":5.0}"#,
        ),
        (
            r#"{"surface":"gaussian","sigma_um":0.05,"corr_um":1.0,"fresnel":"gold"}"#,
            r#"{"surface":"gaussian","sigma_um":0.2,"corr_um":3.0,"fresnel":"gold"}"#,
        ),
        (
            r#"{"surface":"fractal","sigma_um":0.1,"hurst":0.7,"lag_um":1.0}"#,
            r#"{"surface":"fractal","sigma_um":0.12,"hurst":0.7,"lag_um":1.3}"#,
        ),
    ];
    for (a, b) in pairs {
        let (ma, mb) = (Brdf::from_json(a).unwrap(), Brdf::from_json(b).unwrap());
        for kind in ProgramKind::ALL {
            for at_built in [false, true] {
                let export = |m: &Brdf| {
                    if at_built {
                        m.program_at_built(kind)
                    } else {
                        m.program(kind)
                    }
                };
                let (pa, pb) = (export(&ma), export(&mb));
                assert_eq!(pa.is_some(), pb.is_some(), "{a} / {b} {kind:?} {at_built}");
                let (Some(pa), Some(pb)) = (pa, pb) else {
                    continue;
                };
                assert_eq!(
                    pa.code, pb.code,
                    "{a} / {b}: {kind:?} (at built: {at_built})"
                );
                assert_eq!(pa.tables.len(), pb.tables.len());
                let ids =
                    |p: &crate::program::Program| p.params.iter().map(|q| q.0).collect::<Vec<_>>();
                assert_eq!(ids(&pa), ids(&pb));
            }
        }
    }
}

/// The mixture programs are the mixture of the spectral kinds' programs:
/// the pdf their mean, the sample the picked wavelength's at the remapped
/// uniform, the coherent outputs theirs and their probabilities' mean
/// (f64 runs to 1e-7, N = 1, 3, 4; in-band and out-of-band wavelengths; each
/// model, the disc's conserving table per wavelength included). The
/// spectral kinds' programs are checked against the native strategies in
/// the models' tests.
#[test]
fn mixture_programs_are_the_spectral_programs_mixed() {
    use super::program::{MixtureKind, MAX_MIXTURE_WAVELENGTHS};
    let mut rng = crate::benchmark::SplitMix64(17);
    for json in [
        r#"{"surface": "gaussian", "sigma_um": 0.02, "corr_um": 2, "fresnel": "gold"}"#,
        r#"{"surface": "fractal", "sigma_um": 0.05, "hurst": 0.7, "lag_um": 2}"#,
        r#"{"surface": "cd"}"#,
        r#"{"surface": "periodic", "period_um": 1.6, "profile": "sine", "height_um": 0.12, "coherence_um": 6, "energy": "stam"}"#,
    ] {
        let brdf = Brdf::from_json(json).unwrap();
        let single = |kind| brdf.program(kind).unwrap();
        let (pdf1, sample1, coherent1) = (
            single(ProgramKind::PdfSpectral),
            single(ProgramKind::SampleSpectral),
            single(ProgramKind::CoherentSpectral),
        );
        for n in [1usize, 3, 4] {
            let mixture = |kind| brdf.mixture_program(kind, n).unwrap();
            let (pdf, sample, coherent) = (
                mixture(MixtureKind::Pdf),
                mixture(MixtureKind::Sample),
                mixture(MixtureKind::Coherent),
            );
            for (p, kind) in [
                (&pdf, MixtureKind::Pdf),
                (&sample, MixtureKind::Sample),
                (&coherent, MixtureKind::Coherent),
            ] {
                assert_eq!(
                    (p.n_inputs as usize, p.outputs.len()),
                    kind.io(n),
                    "{kind:?} N {n}"
                );
            }
            for (trial, (wi, wo)) in crate::testing::programs::pairs(200, 5)
                .into_iter()
                .enumerate()
            {
                let lambdas: Vec<f64> = (0..n)
                    .map(|j| match (trial + j) % 9 {
                        0 => 300.0,
                        _ => 380.0 + 400.0 * rng.next_f64(),
                    })
                    .collect();
                let u = rng.three();
                let (wi3, wo3) = (wi.to_array(), wo.to_array());
                // (1 / N is an f32 constant in the array: 3e-8 off for N = 3.)
                let close =
                    |a: f64, b: f64| (a - b).abs() <= 1e-7 * a.abs().max(b.abs()).max(1e-300);
                // pdf: the mean of the wavelengths'
                let mean: f64 = lambdas
                    .iter()
                    .map(|&l| pdf1.run(&[&wi3[..], &wo3[..], &[l]].concat())[0])
                    .sum::<f64>()
                    / n as f64;
                let got = pdf.run(&[&wi3[..], &wo3[..], &lambdas[..]].concat())[0];
                assert!(close(got, mean), "{json} N {n}: pdf {got} against {mean}");
                // sample: the picked wavelength's
                let x = u[0] * n as f64;
                let j = x.floor().clamp(0.0, (n - 1) as f64);
                let u0 = (x - j).clamp(0.0, 1.0 - 1.0 / 16_777_216.0);
                let want =
                    sample1.run(&[&wi3[..], &[u0, u[1], u[2], lambdas[j as usize]]].concat());
                let got = sample.run(&[&wi3[..], &u[..], &lambdas[..]].concat());
                assert!(
                    got.iter().zip(&want).all(|(a, b)| close(*a, *b)),
                    "{json} N {n}: sample {got:?} against {want:?}"
                );
                // coherent: each wavelength's reflectance, the mean probability
                let each: Vec<Vec<f64>> = lambdas
                    .iter()
                    .map(|&l| coherent1.run(&[&wi3[..], &[l]].concat()))
                    .collect();
                let got = coherent.run(&[&wi3[..], &lambdas[..]].concat());
                let p_mean = each.iter().map(|o| o[1]).sum::<f64>() / n as f64;
                assert!(close(got[n], p_mean), "{json} N {n}: coherent probability");
                for (g, o) in got.iter().zip(&each) {
                    assert!(
                        close(*g, o[0]),
                        "{json} N {n}: coherent reflectance {g} against {}",
                        o[0]
                    );
                }
            }
        }
        // N out of range: none.
        for n in [0, MAX_MIXTURE_WAVELENGTHS + 1] {
            assert!(brdf.mixture_program(MixtureKind::Pdf, n).is_none());
        }
    }
}

/// The polarisation's program against `Brdf::polarization` at random pairs
/// and in-band wavelengths, run in f64 and in f32: a complex index (the
/// same generic formula; the half vector's cosine computed the programs'
/// way) within 1e-7 in f64 (1.4e-8 measured), 3e-7 in f32; a measured
/// metal (its index read linearly from whole nanometres, the native path
/// from the measured wavelengths) within 1e-3 (aluminium 2.7e-5, gold
/// 2.6e-4); a constant reflectance exactly; rigorous gratings have neither.
#[test]
fn polarization_program_follows_the_native_polarization() {
    let materials = [
        (
            r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2.0,"fresnel":{"eta":1.2,"k":6.9}}"#,
            1e-7,
        ),
        (
            r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2.0}"#,
            1e-3,
        ),
        (
            r#"{"surface":"fractal","sigma_um":0.1,"hurst":0.7,"lag_um":1.0,"fresnel":"gold"}"#,
            1e-3,
        ),
        (r#"{"surface":"cd"}"#, 1e-3),
        (
            r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2.0,"fresnel":0.8}"#,
            0.0,
        ),
    ];
    let mut rng = crate::sampling::SplitMix64(0x9e37_79b9_7f4a_7c15);
    let mut uniform = || rng.next_f64();
    for (json, bound) in materials {
        let brdf = Brdf::from_json(json).unwrap();
        let program = brdf.polarization_program().expect(json);
        let (mut worst64, mut worst32) = (0.0f64, 0.0f64);
        for _ in 0..4000 {
            let dir = |u: f64, v: f64| {
                let (t, p) = (u * 1.5, v * std::f64::consts::TAU);
                DVec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
            };
            let (wi, wo) = (dir(uniform(), uniform()), dir(uniform(), uniform()));
            let lambda = 360.0 + 470.0 * uniform();
            let native = brdf.polarization(wi, wo, lambda).unwrap();
            let input = [wi.x, wi.y, wi.z, wo.x, wo.y, wo.z, lambda];
            let run64 = program.run(&input);
            let input32: Vec<f32> = input.iter().map(|&x| x as f32).collect();
            let run32 = program.run(&input32);
            for c in 0..3 {
                worst64 = worst64.max((run64[c] - native[c]).abs());
                worst32 = worst32.max((run32[c] as f64 - native[c]).abs());
            }
        }
        println!("{json}: worst |program - native| {worst64:.1e} (f64), {worst32:.1e} (f32)");
        assert!(worst64 <= bound, "{json}: {worst64}");
        assert!(worst32 <= bound.max(1e-3), "{json}: {worst32}");
    }
    let rigorous = Brdf::from_json(
        r#"{"surface":"periodic","profile":"rect","period_um":1.6,"height_um":0.1,"width_um":0.8,"coherence_um":10.0,"orders":"rigorous","fresnel":{"eta":1.2,"k":6.9}}"#,
    )
    .unwrap();
    assert!(rigorous.polarization(DVec3::Z, DVec3::Z, 550.0).is_none());
    assert!(rigorous.polarization_program().is_none());
}

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

//! Checks of a material's exported programs (material::program) against
//! its native path: the programs are encoded and decoded as the ABI hands
//! them out, then run on the CPU in f32 (as a renderer's kernels) and in
//! f64 (the program's logic without f32 rounding).

use super::chi2::Sampler;
use crate::benchmark::SplitMix64 as Rng;
use crate::material::program::ProgramKind;
use crate::program::{decode, ParamId, Program};
use crate::sampling::SampleResult;
use crate::Brdf;
use glam::DVec3;

/// The program of `kind`, through the exported array.
pub fn exported(brdf: &Brdf, kind: ProgramKind) -> Option<Program> {
    let program = brdf.program(kind)?;
    let decoded = decode(&program.encode()).expect("the export decodes");
    assert_eq!(decoded.code, program.code);
    Some(decoded)
}

/// Worst errors of a comparison.
#[derive(Clone, Copy, Debug, Default)]
pub struct Errors {
    /// Largest |program - native| / native where native >= floor.
    pub max_rel_f32: f64,
    pub max_rel_f64: f64,
    /// Largest |program - native| / peak anywhere.
    pub max_abs_f32: f64,
    pub checked: usize,
}

/// A random unit direction above the horizon: a quarter of them grazing
/// (cos below 0.02).
fn direction(rng: &mut Rng) -> DVec3 {
    let [a, b, c] = rng.three();
    let z = if c < 0.25 {
        0.02 * a.max(1e-6)
    } else {
        a.max(1e-6)
    };
    let r = (1.0 - z * z).sqrt();
    let phi = 2.0 * std::f64::consts::PI * b;
    DVec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Pairs: random, grazing, and a quarter near the mirror direction.
pub fn pairs(n: usize, seed: u64) -> Vec<(DVec3, DVec3)> {
    let mut rng = Rng(seed);
    (0..n)
        .map(|i| {
            let wi = direction(&mut rng);
            let wo = if i % 4 == 0 {
                let [a, b, _] = rng.three();
                let m = DVec3::new(-wi.x, -wi.y, wi.z);
                let d = DVec3::new(a - 0.5, b - 0.5, 0.0) * 0.05;
                let wo = (m + d).normalize();
                if wo.z > 0.0 {
                    wo
                } else {
                    m
                }
            } else {
                direction(&mut rng)
            };
            (wi, wo)
        })
        .collect()
}

/// Runs `program` on `inputs` in f32 and f64.
pub fn run_both(program: &Program, inputs: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let x32: Vec<f32> = inputs.iter().map(|&v| v as f32).collect();
    let o32 = program.run(&x32).iter().map(|&v| v as f64).collect();
    (o32, program.run(inputs))
}

fn compare(errors: &mut Errors, native: f64, p32: f64, p64: f64, floor: f64, peak: f64) {
    assert!(p32.is_finite() && p32 >= 0.0, "program gave {p32}");
    errors.max_abs_f32 = errors.max_abs_f32.max((p32 - native).abs() / peak);
    if native >= floor {
        errors.checked += 1;
        errors.max_rel_f32 = errors.max_rel_f32.max((p32 - native).abs() / native);
        errors.max_rel_f64 = errors.max_rel_f64.max((p64 - native).abs() / native);
    }
}

/// The spectral eval program against `Brdf::eval_spectral` at `pairs` and
/// random in-band wavelengths; relative errors where f >= 1e-6 of its
/// largest value there.
pub fn eval_spectral_errors(brdf: &Brdf, pairs: &[(DVec3, DVec3)], seed: u64) -> Errors {
    let program = exported(brdf, ProgramKind::EvalSpectral).expect("a spectral eval program");
    let mut rng = Rng(seed);
    let rows: Vec<(DVec3, DVec3, f64, f64)> = pairs
        .iter()
        .map(|&(wi, wo)| {
            // The directions and the wavelength as the program sees them
            // (f32).
            let lambda = (360.0 + 470.0 * rng.three()[0]) as f32 as f64;
            let (wi, wo) = (round(wi), round(wo));
            (wi, wo, lambda, brdf.eval_spectral(wi, wo, lambda))
        })
        .collect();
    let peak = rows.iter().map(|r| r.3).fold(1e-300, f64::max);
    let mut errors = Errors::default();
    for &(wi, wo, lambda, native) in &rows {
        let inputs = [wi.x, wi.y, wi.z, wo.x, wo.y, wo.z, lambda];
        let (p32, p64) = run_both(&program, &inputs);
        compare(&mut errors, native, p32[0], p64[0], 1e-6 * peak, peak);
    }
    errors
}

/// The RGB eval program against `Brdf::eval_rgb`: errors relative to each
/// pair's largest channel (where that is >= 1e-6 of the peak).
pub fn eval_rgb_errors(brdf: &Brdf, pairs: &[(DVec3, DVec3)]) -> Errors {
    let program = exported(brdf, ProgramKind::EvalRgb).expect("an RGB eval program");
    let rows: Vec<(DVec3, DVec3, [f64; 3])> = pairs
        .iter()
        .map(|&(wi, wo)| {
            let (wi, wo) = (round(wi), round(wo));
            (wi, wo, brdf.eval_rgb(wi, wo))
        })
        .collect();
    let peak = rows
        .iter()
        .map(|r| r.2[0].max(r.2[1]).max(r.2[2]))
        .fold(1e-300, f64::max);
    let mut errors = Errors::default();
    for &(wi, wo, native) in &rows {
        let (p32, p64) = run_both(&program, &[wi.x, wi.y, wi.z, wo.x, wo.y, wo.z]);
        let scale = native[0].max(native[1]).max(native[2]);
        for c in 0..3 {
            assert!(
                p32[c].is_finite() && p32[c] >= 0.0,
                "program gave {}",
                p32[c]
            );
            errors.max_abs_f32 = errors.max_abs_f32.max((p32[c] - native[c]).abs() / peak);
            if scale >= 1e-6 * peak {
                errors.max_rel_f32 = errors.max_rel_f32.max((p32[c] - native[c]).abs() / scale);
                errors.max_rel_f64 = errors.max_rel_f64.max((p64[c] - native[c]).abs() / scale);
            }
        }
        if scale >= 1e-6 * peak {
            errors.checked += 1;
        }
    }
    errors
}

/// `d` rounded to f32, as a renderer hands it over.
pub fn round(d: DVec3) -> DVec3 {
    DVec3::new(d.x as f32 as f64, d.y as f32 as f64, d.z as f32 as f64)
}

/// A material's sampling programs at one wi (and wavelength, or RGB),
/// run in f64: what the chi-square test draws from.
pub struct ProgramSampler {
    sample: Program,
    pdf: Program,
    coherent: Program,
    wi: DVec3,
    lambda_nm: Option<f64>,
    /// A parameter's value in place of the stored one (a renderer's
    /// texture value at a point).
    param: Option<(ParamId, f64)>,
}

impl ProgramSampler {
    pub fn new(brdf: &Brdf, wi: DVec3, lambda_nm: Option<f64>) -> ProgramSampler {
        let (s, p, c) = match lambda_nm {
            None => (
                ProgramKind::SampleRgb,
                ProgramKind::PdfRgb,
                ProgramKind::CoherentRgb,
            ),
            Some(_) => (
                ProgramKind::SampleSpectral,
                ProgramKind::PdfSpectral,
                ProgramKind::CoherentSpectral,
            ),
        };
        ProgramSampler {
            sample: exported(brdf, s).expect("a sample program"),
            pdf: exported(brdf, p).expect("a pdf program"),
            coherent: exported(brdf, c).expect("a coherent program"),
            wi,
            lambda_nm,
            param: None,
        }
    }

    /// The sampler with the parameter `id` at `value` in every program.
    pub fn with_param(mut self, id: ParamId, value: f64) -> ProgramSampler {
        self.param = Some((id, value));
        self
    }

    fn run(&self, p: &Program, inputs: &[f64]) -> Vec<f64> {
        let params: Vec<f64> = p
            .params
            .iter()
            .map(|&(id, v)| match self.param {
                Some((pid, value)) if pid == id => value,
                _ => v as f64,
            })
            .collect();
        p.run_with_params(inputs, &params)
    }
}

impl Sampler for ProgramSampler {
    fn sample(&self, rnd: [f64; 3]) -> SampleResult {
        let mut inputs = vec![self.wi.x, self.wi.y, self.wi.z, rnd[0], rnd[1], rnd[2]];
        inputs.extend(self.lambda_nm);
        let out = self.run(&self.sample, &inputs);
        let wo = DVec3::new(out[0], out[1], out[2]);
        let coherent = out[3] > 0.5;
        if coherent {
            return SampleResult {
                wo,
                pdf: self.coherent_probability(),
                coherent,
            };
        }
        let wo = wo.normalize_or_zero();
        let pdf = if wo.z > 0.0 { self.pdf(wo) } else { 0.0 };
        SampleResult {
            wo,
            pdf,
            coherent: false,
        }
    }

    fn pdf(&self, wo: DVec3) -> f64 {
        let mut inputs = vec![self.wi.x, self.wi.y, self.wi.z, wo.x, wo.y, wo.z];
        inputs.extend(self.lambda_nm);
        self.run(&self.pdf, &inputs)[0]
    }

    fn coherent_probability(&self) -> f64 {
        let mut inputs = vec![self.wi.x, self.wi.y, self.wi.z];
        inputs.extend(self.lambda_nm);
        *self.run(&self.coherent, &inputs).last().unwrap()
    }

    /// `sample` runs the pdf program at its direction.
    fn sample_pdf_is_pdf(&self) -> bool {
        true
    }
}

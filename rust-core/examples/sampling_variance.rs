//! Variance of the directional-albedo estimate with the BRDF's importance
//! sampling against cosine-weighted sampling, at the same sample count, and
//! the cost per sample beside the cost per evaluation.
//!
//!   cargo run --release -p stam-core --example sampling_variance [samples] [material filter]
//!
//! Estimator per sample: f cos / pdf, plus, for the coherent lobe, its
//! reflectance / its probability when the sampler picks it. The cosine
//! baseline adds the coherent reflectance deterministically (it can never
//! hit the delta lobe), which favours the baseline. RGB mode scores the sum
//! of the three channels.
//!
//! The JIT columns: the material's sampling programs (what the plugin runs
//! with Dr.Jit in the llvm_ad / cuda_ad variants, docs/jit.md), executed
//! here in f32 on the CPU: sample, pdf and coherent programs, the same
//! estimator with the same native f. "JIT / core" is Var(JIT) / Var(core)
//! (goal: at most 2).
// `!(x > 0.0)` rejects NaN too, as in the core.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use glam::DVec3;
use stam::material::program::ProgramKind;
use stam::program::Program;
use stam::Brdf;
use std::f64::consts::PI;
use std::time::Instant;

use stam::benchmark::{mean_var, SplitMix64 as Rng, SAMPLING_MATERIALS};

/// The material's sampling programs for one mode.
struct JitSampler {
    sample: Program,
    pdf: Program,
    coherent: Program,
}

impl JitSampler {
    fn new(brdf: &Brdf, spectral: bool) -> Option<JitSampler> {
        let (s, p, c) = if spectral {
            (
                ProgramKind::SampleSpectral,
                ProgramKind::PdfSpectral,
                ProgramKind::CoherentSpectral,
            )
        } else {
            (
                ProgramKind::SampleRgb,
                ProgramKind::PdfRgb,
                ProgramKind::CoherentRgb,
            )
        };
        Some(JitSampler {
            sample: brdf.program(s)?,
            pdf: brdf.program(p)?,
            coherent: brdf.program(c)?,
        })
    }

    /// (wo, pdf, coherent) of one sample, run in f32 as a renderer does.
    fn draw(&self, wi: DVec3, lambda: Option<f64>, u: [f64; 3]) -> (DVec3, f64, bool) {
        let mut x: Vec<f32> = [wi.x, wi.y, wi.z, u[0], u[1], u[2]]
            .iter()
            .map(|&v| v as f32)
            .collect();
        x.extend(lambda.map(|l| l as f32));
        let o = self.sample.run(&x);
        let wo = DVec3::new(o[0] as f64, o[1] as f64, o[2] as f64);
        if o[3] > 0.5 {
            let mut c: Vec<f32> = vec![wi.x as f32, wi.y as f32, wi.z as f32];
            c.extend(lambda.map(|l| l as f32));
            return (wo, *self.coherent.run(&c).last().unwrap() as f64, true);
        }
        if !(wo.z > 0.0) {
            return (wo, 0.0, false);
        }
        let mut p: Vec<f32> = [wi.x, wi.y, wi.z, wo.x, wo.y, wo.z]
            .iter()
            .map(|&v| v as f32)
            .collect();
        p.extend(lambda.map(|l| l as f32));
        (wo, self.pdf.run(&p)[0] as f64, false)
    }
}

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(200_000);
    // Only materials whose name contains this text (all when absent).
    let filter = std::env::args().nth(2).unwrap_or_default();
    let materials = SAMPLING_MATERIALS;
    let incidences = [
        ("30 deg", 30.0f64),
        ("70 deg", 70.0),
        ("cos 0.08", 0.08f64.acos().to_degrees()),
    ];
    println!("{n} samples per estimate; ratio = Var(cosine) / Var(importance)");
    println!(
        "| material | incidence | mode | albedo (IS) | albedo (cos) | Var IS | Var cos | ratio | ns/sample | ns/eval | albedo (JIT) | Var JIT | ratio cos/JIT | JIT / core |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for (name, json) in materials {
        if !name.contains(filter.as_str()) {
            continue;
        }
        let brdf = Brdf::from_json(json).expect("material");
        for (inc_name, deg) in incidences {
            let th = deg.to_radians();
            let wi = DVec3::new(th.sin() * 0.8, th.sin() * 0.6, th.cos());
            for mode in [Some(550.0), None] {
                let f = |wo: DVec3| match mode {
                    Some(l) => brdf.eval_spectral(wi, wo, l),
                    None => brdf.eval_rgb(wi, wo).iter().sum(),
                };
                let coherent = match mode {
                    Some(l) => brdf.coherent_spectral(wi, l),
                    None => brdf.coherent_rgb(wi).iter().sum(),
                };
                let mut rng = Rng(12345);
                let mut is = Vec::with_capacity(n);
                let t0 = Instant::now();
                let mut samples = Vec::with_capacity(n);
                for _ in 0..n {
                    // Each call builds its strategy (from the material's
                    // tables, as every vertex of a render does).
                    samples.push(brdf.sample(wi, mode, rng.three()));
                }
                let ns_sample = t0.elapsed().as_nanos() as f64 / n as f64;
                let t1 = Instant::now();
                let mut evals = Vec::with_capacity(n);
                for s in &samples {
                    evals.push(if s.pdf > 0.0 && !s.coherent {
                        f(s.wo)
                    } else {
                        0.0
                    });
                }
                let ns_eval = t1.elapsed().as_nanos() as f64 / n as f64;
                for (s, fv) in samples.iter().zip(&evals) {
                    is.push(if s.pdf == 0.0 {
                        0.0
                    } else if s.coherent {
                        coherent / s.pdf
                    } else {
                        fv * s.wo.z / s.pdf
                    });
                }
                let mut cos = Vec::with_capacity(n);
                for _ in 0..n {
                    let (r1, r2) = (rng.next_f64(), rng.next_f64());
                    let r = r1.sqrt();
                    let phi = 2.0 * PI * r2;
                    let wo = DVec3::new(r * phi.cos(), r * phi.sin(), (1.0 - r1).max(1e-12).sqrt());
                    cos.push(coherent + PI * f(wo));
                }
                let (m_is, v_is) = mean_var(&is);
                let (m_cos, v_cos) = mean_var(&cos);
                let jit = JitSampler::new(&brdf, mode.is_some()).map(|j| {
                    let jit: Vec<f64> = (0..n)
                        .map(|_| {
                            let (wo, pdf, coh) = j.draw(wi, mode, rng.three());
                            if !(pdf > 0.0) {
                                0.0
                            } else if coh {
                                coherent / pdf
                            } else {
                                f(wo) * wo.z / pdf
                            }
                        })
                        .collect();
                    mean_var(&jit)
                });
                let jit_cols = match jit {
                    Some((m, v)) => {
                        format!("{m:.4} | {v:.3e} | {:.1} | {:.2}", v_cos / v, v / v_is)
                    }
                    None => "- | - | - | -".into(),
                };
                let mode_name = if mode.is_some() { "550 nm" } else { "RGB" };
                println!(
                    "| {name} | {inc_name} | {mode_name} | {m_is:.4} | {m_cos:.4} | {v_is:.3e} | {v_cos:.3e} | {:.1} | {ns_sample:.0} | {ns_eval:.0} | {jit_cols} |",
                    v_cos / v_is
                );
            }
        }
    }
}

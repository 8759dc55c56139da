//! Spectral variants' sampling of the Gaussian surfaces: what the strategy's
//! wavelength costs in variance (docs/jit.md, "Render time").
//!
//!   cargo run --release -p stam-core --example spectral_strategy [samples]
//!
//! The JIT path's spectral pdf is the mean of four strategies, one per path
//! wavelength (the sample draws with one of them), which is most of the
//! spectral Gaussians' render time. Per material and incidence:
//! - one wavelength lambda (400, 550, 700 nm): Var of f(lambda) cos / pdf with
//!   the SAMPLE/PDF programs at lambda and at fixed wavelengths, relative to
//!   the core's strategy at lambda;
//! - a path's four stratified wavelengths (the sum of their estimates):
//!   Var with the strategy at one fixed wavelength, at a mixture of two fixed
//!   ones, and at the first path wavelength alone, relative to the
//!   four-wavelength mixture the plugin runs.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use glam::DVec3;
use stam::benchmark::SplitMix64 as Rng;
use stam::material::program::ProgramKind;
use stam::program::Program;
use stam::Brdf;

fn mean_var(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0);
    (mean, var)
}

struct J {
    sample: Program,
    pdf: Program,
    coherent: Program,
}
impl J {
    fn pdf(&self, wi: DVec3, wo: DVec3, l: f64) -> f64 {
        let p: Vec<f32> = [wi.x, wi.y, wi.z, wo.x, wo.y, wo.z, l]
            .iter()
            .map(|&v| v as f32)
            .collect();
        self.pdf.run(&p)[0] as f64
    }
    fn pcoh(&self, wi: DVec3, l: f64) -> f64 {
        let c: Vec<f32> = [wi.x, wi.y, wi.z, l].iter().map(|&v| v as f32).collect();
        *self.coherent.run(&c).last().unwrap() as f64
    }
    fn draw(&self, wi: DVec3, l: f64, u: [f64; 3]) -> (DVec3, bool) {
        let x: Vec<f32> = [wi.x, wi.y, wi.z, u[0], u[1], u[2], l]
            .iter()
            .map(|&v| v as f32)
            .collect();
        let o = self.sample.run(&x);
        (
            DVec3::new(o[0] as f64, o[1] as f64, o[2] as f64),
            o[3] > 0.5,
        )
    }
}

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(20000);
    let materials = [
        (
            "smooth Gaussian",
            r#"{"surface":"gaussian","sigma_um":0.02,"corr_um":5,"fresnel":0.9}"#,
        ),
        (
            "medium Gaussian",
            r#"{"surface":"gaussian","sigma_um":0.14,"corr_um":2,"fresnel":0.9}"#,
        ),
        (
            "rough Gaussian",
            r#"{"surface":"gaussian","sigma_um":0.5,"corr_um":3,"fresnel":0.9}"#,
        ),
        (
            "anisotropic",
            r#"{"surface":"gaussian","sigma_um":0.08,"corr_x_um":2,"corr_y_um":10,"fresnel":0.9}"#,
        ),
        (
            "bench smooth",
            r#"{"surface":"gaussian","sigma_um":0.05,"corr_um":2,"fresnel":0.9}"#,
        ),
        (
            "bench rough",
            r#"{"surface":"gaussian","sigma_um":0.5,"corr_um":4,"fresnel":0.9}"#,
        ),
    ];
    let fixed = [550.0, 600.0, 650.0, 700.0];
    for (name, json) in materials {
        let brdf = Brdf::from_json(json).unwrap();
        let j = J {
            sample: brdf.program(ProgramKind::SampleSpectral).unwrap(),
            pdf: brdf.program(ProgramKind::PdfSpectral).unwrap(),
            coherent: brdf.program(ProgramKind::CoherentSpectral).unwrap(),
        };
        for deg in [0.0f64, 30.0, 70.0, 0.08f64.acos().to_degrees()] {
            let th = deg.to_radians();
            let wi = DVec3::new(th.sin() * 0.8, th.sin() * 0.6, th.cos());
            // Per wavelength: core, JIT at lambda, JIT with the strategy at fixed.
            let mut line = format!("{name} {deg:.0}deg:");
            for l in [400.0, 550.0, 700.0] {
                let coh = brdf.coherent_spectral(wi, l);
                let mut rng = Rng(7);
                let core: Vec<f64> = (0..n)
                    .map(|_| {
                        let s = brdf.sample(wi, Some(l), rng.three());
                        if s.pdf == 0.0 {
                            0.0
                        } else if s.coherent {
                            coh / s.pdf
                        } else {
                            brdf.eval_spectral(wi, s.wo, l) * s.wo.z / s.pdf
                        }
                    })
                    .collect();
                let (_, vc) = mean_var(&core);
                line += &format!(" | {l}: core {vc:.2e}");
                for ls in std::iter::once(l).chain(fixed) {
                    let xs: Vec<f64> = (0..n)
                        .map(|_| {
                            let (wo, c) = j.draw(wi, ls, rng.three());
                            if c {
                                return coh / j.pcoh(wi, ls);
                            }
                            if !(wo.z > 0.0) {
                                return 0.0;
                            }
                            let p = j.pdf(wi, wo, ls);
                            if !(p > 0.0) {
                                0.0
                            } else {
                                brdf.eval_spectral(wi, wo, l) * wo.z / p
                            }
                        })
                        .collect();
                    let (_, v) = mean_var(&xs);
                    line += &format!(" {:.0}:{:.2}", ls, v / vc);
                }
            }
            println!("{line}");
            // Path: 4 stratified wavelengths; mixture vs fixed.
            let mut rng = Rng(11);
            let mut mix = Vec::new();
            let mut fx: Vec<Vec<f64>> = vec![Vec::new(); fixed.len()];
            let mut corev = Vec::new();
            for _ in 0..n {
                let l0 = 380.0 + 400.0 * rng.next_f64();
                let ls: Vec<f64> = (0..4)
                    .map(|k| 380.0 + (l0 - 380.0 + 100.0 * k as f64) % 400.0)
                    .collect();
                let u = rng.three();
                // mixture
                let k = ((u[0] * 4.0) as usize).min(3);
                let u0 = u[0] * 4.0 - k as f64;
                let (wo, c) = j.draw(wi, ls[k], [u0, u[1], u[2]]);
                let est = if c {
                    let p: f64 = ls.iter().map(|&x| j.pcoh(wi, x)).sum::<f64>() / 4.0;
                    ls.iter()
                        .map(|&x| brdf.coherent_spectral(wi, x))
                        .sum::<f64>()
                        / p
                } else if wo.z > 0.0 {
                    let p: f64 = ls.iter().map(|&x| j.pdf(wi, wo, x)).sum::<f64>() / 4.0;
                    if p > 0.0 {
                        ls.iter()
                            .map(|&x| brdf.eval_spectral(wi, wo, x))
                            .sum::<f64>()
                            * wo.z
                            / p
                    } else {
                        0.0
                    }
                } else {
                    0.0
                };
                mix.push(est);
                // core sampling at hero, its own mixture? use core at each own lambda (ideal per-lambda)
                let mut s = 0.0;
                for &x in &ls {
                    let sm = brdf.sample(wi, Some(x), rng.three());
                    s += if sm.pdf == 0.0 {
                        0.0
                    } else if sm.coherent {
                        brdf.coherent_spectral(wi, x) / sm.pdf
                    } else {
                        brdf.eval_spectral(wi, sm.wo, x) * sm.wo.z / sm.pdf
                    };
                }
                corev.push(s);
                for (fi, &lf) in fixed.iter().enumerate() {
                    let (wo, c) = j.draw(wi, lf, u);
                    let est = if c {
                        ls.iter()
                            .map(|&x| brdf.coherent_spectral(wi, x))
                            .sum::<f64>()
                            / j.pcoh(wi, lf)
                    } else if wo.z > 0.0 {
                        let p = j.pdf(wi, wo, lf);
                        if p > 0.0 {
                            ls.iter()
                                .map(|&x| brdf.eval_spectral(wi, wo, x))
                                .sum::<f64>()
                                * wo.z
                                / p
                        } else {
                            0.0
                        }
                    } else {
                        0.0
                    };
                    fx[fi].push(est);
                }
            }
            let pairs = [
                (450.0, 650.0),
                (480.0, 620.0),
                (500.0, 650.0),
                (450.0, 600.0),
            ];
            let mut pv: Vec<Vec<f64>> = vec![Vec::new(); pairs.len() + 1];
            let mut rng = Rng(11);
            for _ in 0..n {
                let l0 = 380.0 + 400.0 * rng.next_f64();
                let ls: Vec<f64> = (0..4)
                    .map(|k| 380.0 + (l0 - 380.0 + 100.0 * k as f64) % 400.0)
                    .collect();
                let u = rng.three();
                for (pi, &(la, lb)) in pairs.iter().enumerate() {
                    let k = if u[0] < 0.5 { 0 } else { 1 };
                    let u0 = u[0] * 2.0 - k as f64;
                    let (wo, c) = j.draw(wi, [la, lb][k], [u0, u[1], u[2]]);
                    let est = if c {
                        ls.iter()
                            .map(|&x| brdf.coherent_spectral(wi, x))
                            .sum::<f64>()
                            / (0.5 * (j.pcoh(wi, la) + j.pcoh(wi, lb)))
                    } else if wo.z > 0.0 {
                        let p = 0.5 * (j.pdf(wi, wo, la) + j.pdf(wi, wo, lb));
                        if p > 0.0 {
                            ls.iter()
                                .map(|&x| brdf.eval_spectral(wi, wo, x))
                                .sum::<f64>()
                                * wo.z
                                / p
                        } else {
                            0.0
                        }
                    } else {
                        0.0
                    };
                    pv[pi].push(est);
                }
                let (wo, c) = j.draw(wi, ls[0], u);
                let est = if c {
                    ls.iter()
                        .map(|&x| brdf.coherent_spectral(wi, x))
                        .sum::<f64>()
                        / j.pcoh(wi, ls[0])
                } else if wo.z > 0.0 {
                    let p = j.pdf(wi, wo, ls[0]);
                    if p > 0.0 {
                        ls.iter()
                            .map(|&x| brdf.eval_spectral(wi, wo, x))
                            .sum::<f64>()
                            * wo.z
                            / p
                    } else {
                        0.0
                    }
                } else {
                    0.0
                };
                pv[pairs.len()].push(est);
            }
            let (_, vm) = mean_var(&mix);
            let (_, vco) = mean_var(&corev);
            let mut line =
                format!("   path: mixture {vm:.3e} (per-lambda core, 4 samples {vco:.3e})");
            for (fi, &lf) in fixed.iter().enumerate() {
                let (_, v) = mean_var(&fx[fi]);
                line += &format!(" {lf:.0}:{:.2}", v / vm);
            }
            for (pi, &(la, lb)) in pairs.iter().enumerate() {
                let (_, v) = mean_var(&pv[pi]);
                line += &format!(" {la:.0}+{lb:.0}:{:.2}", v / vm);
            }
            let (_, v) = mean_var(&pv[pairs.len()]);
            line += &format!(" hero:{:.2}", v / vm);
            println!("{line}");
        }
    }
}

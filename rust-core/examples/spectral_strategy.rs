//! Spectral variants' sampling of the Gaussian surfaces: what the strategy's
//! wavelength costs in variance (docs/jit_measured.md, "Render time").
//!
//!   cargo run --release -p stam-core --example spectral_strategy [samples]
//!
//! The JIT path's spectral pdf is the mean of four strategies, one per path
//! wavelength (the sample draws with one of them), which is most of the
//! spectral Gaussians' render time. Every strategy here is such a mixture
//! over a list of wavelengths (the SAMPLE, PDF and COHERENT programs run in
//! f32 at each), and the estimate of f cos / pdf (the coherent lobe: its
//! reflectance over its probability) is scored per material and incidence:
//! - at one wavelength lambda (400, 550, 700 nm): the strategy at lambda and
//!   at fixed wavelengths, Var relative to the core's strategy at lambda;
//! - over a path's four stratified wavelengths (the sum of their
//!   estimates): one fixed wavelength, two fixed ones, and the first path
//!   wavelength alone, Var relative to the four-wavelength mixture the
//!   plugin runs.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
use glam::DVec3;
use stam::benchmark::{mean_var, SplitMix64 as Rng, SAMPLING_MATERIALS};
use stam::material::program::ProgramKind;
use stam::program::Program;
use stam::Brdf;

/// The material's spectral sampling programs.
struct Programs {
    sample: Program,
    pdf: Program,
    coherent: Program,
}

fn f32s(values: &[f64]) -> Vec<f32> {
    values.iter().map(|&v| v as f32).collect()
}

impl Programs {
    fn new(brdf: &Brdf) -> Programs {
        let get = |kind| brdf.program(kind).expect("a Gaussian has every program");
        Programs {
            sample: get(ProgramKind::SampleSpectral),
            pdf: get(ProgramKind::PdfSpectral),
            coherent: get(ProgramKind::CoherentSpectral),
        }
    }

    /// One sample of the mixture of the strategies at `strategy` (picked
    /// by u[0]), scored for the wavelengths `lambdas`.
    fn estimate(
        &self,
        brdf: &Brdf,
        wi: DVec3,
        strategy: &[f64],
        lambdas: &[f64],
        u: [f64; 3],
    ) -> f64 {
        let n = strategy.len() as f64;
        let k = ((u[0] * n) as usize).min(strategy.len() - 1);
        let u0 = u[0] * n - k as f64;
        let o = self
            .sample
            .run(&f32s(&[wi.x, wi.y, wi.z, u0, u[1], u[2], strategy[k]]));
        let wo = DVec3::new(o[0] as f64, o[1] as f64, o[2] as f64);
        let mean = |f: &dyn Fn(f64) -> f64| strategy.iter().map(|&l| f(l)).sum::<f64>() / n;
        if o[3] > 0.5 {
            let p = mean(&|l| {
                *self
                    .coherent
                    .run(&f32s(&[wi.x, wi.y, wi.z, l]))
                    .last()
                    .unwrap() as f64
            });
            return lambdas
                .iter()
                .map(|&l| brdf.coherent_spectral(wi, l))
                .sum::<f64>()
                / p;
        }
        if !(wo.z > 0.0) {
            return 0.0;
        }
        let p = mean(&|l| {
            self.pdf
                .run(&f32s(&[wi.x, wi.y, wi.z, wo.x, wo.y, wo.z, l]))[0] as f64
        });
        if !(p > 0.0) {
            return 0.0;
        }
        lambdas
            .iter()
            .map(|&l| brdf.eval_spectral(wi, wo, l))
            .sum::<f64>()
            * wo.z
            / p
    }
}

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(20000);
    // The Gaussians of the sampling table, and bench_render.py's two.
    let materials = SAMPLING_MATERIALS
        .into_iter()
        .filter(|(_, json)| json.contains("gaussian"))
        .chain([
            (
                "bench smooth",
                r#"{"surface":"gaussian","sigma_um":0.05,"corr_um":2,"fresnel":0.9}"#,
            ),
            (
                "bench rough",
                r#"{"surface":"gaussian","sigma_um":0.5,"corr_um":4,"fresnel":0.9}"#,
            ),
        ]);
    let fixed = [550.0, 600.0, 650.0, 700.0];
    let pairs = [
        [450.0, 650.0],
        [480.0, 620.0],
        [500.0, 650.0],
        [450.0, 600.0],
    ];
    println!(
        "{n} samples per estimate; Var relative to the core at lambda, or to the path's mixture"
    );
    for (name, json) in materials {
        let brdf = Brdf::from_json(json).expect("material");
        let programs = Programs::new(&brdf);
        for deg in [0.0f64, 30.0, 70.0, 0.08f64.acos().to_degrees()] {
            let th = deg.to_radians();
            let wi = DVec3::new(th.sin() * 0.8, th.sin() * 0.6, th.cos());
            let mut line = format!("{name} {deg:.0} deg, one wavelength:");
            for lambda in [400.0, 550.0, 700.0] {
                let coherent = brdf.coherent_spectral(wi, lambda);
                let mut rng = Rng(7);
                let core: Vec<f64> = (0..n)
                    .map(|_| {
                        let s = brdf.sample(wi, Some(lambda), rng.three());
                        if s.pdf == 0.0 {
                            0.0
                        } else if s.coherent {
                            coherent / s.pdf
                        } else {
                            brdf.eval_spectral(wi, s.wo, lambda) * s.wo.z / s.pdf
                        }
                    })
                    .collect();
                let (_, v_core) = mean_var(&core);
                line += &format!(" | {lambda} nm:");
                for at in std::iter::once(lambda).chain(fixed) {
                    let xs: Vec<f64> = (0..n)
                        .map(|_| programs.estimate(&brdf, wi, &[at], &[lambda], rng.three()))
                        .collect();
                    line += &format!(" at {at:.0} {:.2}", mean_var(&xs).1 / v_core);
                }
            }
            println!("{line}");
            // A path's four wavelengths: the hero uniform over the band, the
            // others 100 nm apart (wrapped), as Mitsuba's spectral sampling.
            let mut strategies: Vec<(String, Vec<f64>)> = vec![("mixture".into(), vec![])];
            strategies.extend(fixed.map(|l| (format!("{l:.0}"), vec![l])));
            strategies.extend(pairs.map(|[a, b]| (format!("{a:.0}+{b:.0}"), vec![a, b])));
            strategies.push(("hero".into(), vec![]));
            let mut scores = vec![Vec::with_capacity(n); strategies.len()];
            let mut rng = Rng(11);
            for _ in 0..n {
                let l0 = 380.0 + 400.0 * rng.next_f64();
                let path: Vec<f64> = (0..4)
                    .map(|k| 380.0 + (l0 - 380.0 + 100.0 * k as f64) % 400.0)
                    .collect();
                let u = rng.three();
                for ((label, at), score) in strategies.iter().zip(&mut scores) {
                    let at: &[f64] = match label.as_str() {
                        "mixture" => &path,
                        "hero" => &path[..1],
                        _ => at,
                    };
                    score.push(programs.estimate(&brdf, wi, at, &path, u));
                }
            }
            let v_mix = mean_var(&scores[0]).1;
            let mut line = format!("   four path wavelengths: mixture Var {v_mix:.3e};");
            for ((label, _), score) in strategies.iter().zip(&scores).skip(1) {
                line += &format!(" {label} {:.2}", mean_var(score).1 / v_mix);
            }
            println!("{line}");
        }
    }
}

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
use glam::DVec3;
use stam::Brdf;
use std::f64::consts::PI;
use std::time::Instant;

use stam::benchmark::SplitMix64 as Rng;

fn mean_var(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0);
    (mean, var)
}

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(200_000);
    // Only materials whose name contains this text (all when absent).
    let filter = std::env::args().nth(2).unwrap_or_default();
    let materials = [
        ("compact disc", r#"{"surface":"cd","fresnel":0.9}"#),
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
            "fractal H=0.7",
            r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.05,"lag_um":1,"fresnel":0.9}"#,
        ),
        (
            "fractal H=0.35",
            r#"{"surface":"fractal","hurst":0.35,"sigma_um":0.2,"lag_um":1,"fresnel":0.9}"#,
        ),
    ];
    let incidences = [
        ("30 deg", 30.0f64),
        ("70 deg", 70.0),
        ("cos 0.08", 0.08f64.acos().to_degrees()),
    ];
    println!("{n} samples per estimate; ratio = Var(cosine) / Var(importance)");
    println!(
        "| material | incidence | mode | albedo (IS) | albedo (cos) | Var IS | Var cos | ratio | ns/sample | ns/eval |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
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
                let mode_name = if mode.is_some() { "550 nm" } else { "RGB" };
                println!(
                    "| {name} | {inc_name} | {mode_name} | {m_is:.4} | {m_cos:.4} | {v_is:.3e} | {v_cos:.3e} | {:.1} | {ns_sample:.0} | {ns_eval:.0} |",
                    v_cos / v_is
                );
            }
        }
    }
}

//! ns per BRDF evaluation for each surface model, spectral and RGB, beside a
//! Cook-Torrance/Beckmann evaluation in the same process as the baseline.
//! `make bench` runs it and writes docs/performance.md from the estimates
//! (scripts/bench_table.py).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use glam::DVec3;
use stam::fresnel::conductor_reflectance;
use stam::Brdf;
use std::f64::consts::PI;
use std::hint::black_box;

/// The materials benchmarked: (name, JSON). Names are the table's rows.
pub const MATERIALS: [(&str, &str); 6] = [
    (
        "gaussian_smooth",
        r#"{"surface":"gaussian","sigma_um":0.05,"corr_um":3.0}"#,
    ),
    (
        "gaussian_rough",
        r#"{"surface":"gaussian","sigma_um":0.6,"corr_um":4.0}"#,
    ),
    (
        "anisotropic",
        r#"{"surface":"gaussian","sigma_um":0.15,"corr_x_um":1.0,"corr_y_um":15.0}"#,
    ),
    (
        "fractal",
        r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.1,"lag_um":1.0}"#,
    ),
    ("cd", r#"{"surface":"cd"}"#),
    (
        "sine_grating",
        r#"{"surface":"periodic","period_um":1.6,"coherence_um":20,"profile":"sine","height_um":0.25}"#,
    ),
];

const BATCH: usize = 1024;

/// Deterministic pseudo-random directions around the specular lobe (where
/// renders spend their evaluations) plus uniform ones.
fn directions(seed: u64) -> Vec<(DVec3, DVec3, f64)> {
    let mut state = seed;
    let mut next = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64) / ((1u64 << 53) as f64)
    };
    (0..BATCH)
        .map(|i| {
            let ct = 0.1 + 0.9 * next();
            let phi = 2.0 * PI * next();
            let st = (1.0 - ct * ct).sqrt();
            let wi = DVec3::new(st * phi.cos(), st * phi.sin(), ct);
            let wo = if i % 2 == 0 {
                let jitter = DVec3::new(0.3 * (next() - 0.5), 0.3 * (next() - 0.5), 0.0);
                (DVec3::new(-wi.x, -wi.y, wi.z) + jitter).normalize()
            } else {
                let ct = 0.05 + 0.95 * next();
                let phi = 2.0 * PI * next();
                let st = (1.0 - ct * ct).sqrt();
                DVec3::new(st * phi.cos(), st * phi.sin(), ct)
            };
            let lambda = 380.0 + 400.0 * next();
            (wi, wo, lambda)
        })
        .collect()
}

/// Cook-Torrance with a Beckmann distribution, Smith shadowing and the same
/// conductor Fresnel as the core: the baseline a renderer already pays for.
fn cook_torrance_beckmann(wi: DVec3, wo: DVec3, alpha: f64, eta: f64, k: f64) -> f64 {
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return 0.0;
    }
    let h = (wi + wo).normalize();
    let cos2 = h.z * h.z;
    let tan2 = (1.0 - cos2) / cos2;
    let a2 = alpha * alpha;
    let d = (-tan2 / a2).exp() / (PI * a2 * cos2 * cos2);
    let smith_g1 = |w: DVec3| {
        let tan = (1.0 - w.z * w.z).max(0.0).sqrt() / w.z;
        let a = 1.0 / (alpha * tan);
        if a >= 1.6 {
            1.0
        } else {
            (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)
        }
    };
    let f = conductor_reflectance(wi.dot(h), eta, k);
    f * d * smith_g1(wi) * smith_g1(wo) / (4.0 * wi.z * wo.z)
}

fn bench(c: &mut Criterion) {
    let dirs = directions(7);
    let mut group = c.benchmark_group("eval");
    group.throughput(Throughput::Elements(BATCH as u64));
    group.bench_function("baseline_cook_torrance", |b| {
        b.iter(|| {
            let mut acc = 0.0;
            for &(wi, wo, _) in &dirs {
                acc += cook_torrance_beckmann(black_box(wi), black_box(wo), 0.3, 1.2, 7.0);
            }
            acc
        })
    });
    for (name, json) in MATERIALS {
        let brdf = match Brdf::from_json(json) {
            Ok(b) => b,
            Err(e) => {
                eprintln!("skipping {name}: {e}");
                continue;
            }
        };
        group.bench_function(format!("{name}/spectral"), |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for &(wi, wo, lambda) in &dirs {
                    acc += brdf.eval_spectral(black_box(wi), black_box(wo), lambda);
                }
                acc
            })
        });
        group.bench_function(format!("{name}/rgb"), |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for &(wi, wo, _) in &dirs {
                    acc += brdf.eval_rgb(black_box(wi), black_box(wo))[1];
                }
                acc
            })
        });
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(20)
        .warm_up_time(std::time::Duration::from_millis(300))
        .measurement_time(std::time::Duration::from_secs(1));
    targets = bench
}
criterion_main!(benches);

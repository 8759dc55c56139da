//! ns per BRDF evaluation for each surface model, spectral and RGB, beside a
//! Cook-Torrance/Beckmann evaluation in the same process as the baseline.
//! `make bench` runs it and writes docs/performance.md from the estimates
//! (scripts/bench_table.py).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use stam::benchmark::{
    cook_torrance_beckmann, direction_pairs, gaussian_psd, npy_bytes, synthetic_height_map,
};
use stam::Brdf;
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

fn bench(c: &mut Criterion) {
    let dirs = direction_pairs(7, BATCH);
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
    // A height map of gaussian_smooth's statistics (1024 x 1024, 0.08 um:
    // the model's cost against the closed form it reproduces).
    let map = std::env::temp_dir().join("stam-bench-heightmap.npy");
    let heights = synthetic_height_map(1024, 0.08, 3, gaussian_psd(0.05, 3.0), Some(0.05));
    std::fs::write(&map, npy_bytes(1024, 1024, &heights)).expect("the bench's map");
    let heightmap = format!(
        r#"{{"surface":"heightmap","file":{},"pixel_um":0.08}}"#,
        serde_json::Value::String(map.to_string_lossy().into())
    );
    let rows = MATERIALS
        .iter()
        .map(|&(name, json)| (name, json.to_string()))
        .chain([("heightmap", heightmap)]);
    for (name, json) in rows {
        let brdf = match Brdf::from_json(&json) {
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

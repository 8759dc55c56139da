//! ns per evaluation of every accuracy configuration of the survey
//! (stress::pareto::configs, named c000, c001, ... in that order) beside the
//! Cook-Torrance/Beckmann baseline in the same run. scripts/plot_pareto.py
//! joins these timings with the errors of the `pareto` binary.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;
use stress::pareto;

fn bench(c: &mut Criterion) {
    let pairs = pareto::directions();
    let mut group = c.benchmark_group("pareto");
    group.throughput(Throughput::Elements(pairs.len() as u64));
    group.bench_function("baseline", |b| {
        b.iter(|| {
            let mut acc = 0.0;
            for &(wi, wo, _) in &pairs {
                acc += pareto::cook_torrance_beckmann(black_box(wi), black_box(wo), 0.3, 1.2, 7.0);
            }
            acc
        })
    });
    // STRESS_PARETO_FILTER=c01 times only the ids containing it.
    let filter = std::env::var("STRESS_PARETO_FILTER").unwrap_or_default();
    for (index, config) in pareto::configs().iter().enumerate() {
        let id = format!("c{index:03}");
        if !id.contains(&filter) {
            continue;
        }
        let brdf = config.build();
        group.bench_function(id, |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for &(wi, wo, lambda) in &pairs {
                    acc += config.eval(&brdf, black_box(wi), black_box(wo), lambda)[0];
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
        .sample_size(10)
        .warm_up_time(std::time::Duration::from_millis(200))
        .measurement_time(std::time::Duration::from_millis(700));
    targets = bench
}
criterion_main!(benches);

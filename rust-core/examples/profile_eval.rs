//! Profiling aid: evaluates one material many times (for perf/callgrind).
//! Usage: cargo run --release -p stam-core --example profile_eval -- '<json>' [spectral|rgb|rgb-sampled] [count]
//! (rgb-sampled: wo drawn by the material's RGB strategy, where a render's
//! evaluations are: on a grating's orders, rather than uniformly.)
use glam::DVec3;
use std::f64::consts::PI;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let json = args
        .get(1)
        .map(String::as_str)
        .unwrap_or(r#"{"surface":"gaussian","sigma_um":0.05,"corr_um":3.0}"#);
    let mode = args.get(2).map(String::as_str).unwrap_or("spectral");
    let count: usize = args
        .get(3)
        .and_then(|s| s.parse().ok())
        .unwrap_or(1_000_000);
    let brdf = stam::Brdf::from_json(json).expect("material");
    // An energy-conserving material builds its table on first use (0.1-0.5
    // s): build it before the clock starts, so that only evaluations count.
    let _ = brdf.energy_table();
    let mut state = 1u64;
    let mut next = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64) / ((1u64 << 53) as f64)
    };
    let start = std::time::Instant::now();
    let mut acc = 0.0;
    for _ in 0..count {
        let ct = 0.1 + 0.9 * next();
        let phi = 2.0 * PI * next();
        let st = (1.0 - ct * ct).sqrt();
        let wi = DVec3::new(st * phi.cos(), st * phi.sin(), ct);
        let wo = if mode == "rgb-sampled" {
            brdf.sample(wi, None, [next(), next(), next()]).wo
        } else {
            let ct = 0.05 + 0.95 * next();
            let phi = 2.0 * PI * next();
            let st = (1.0 - ct * ct).sqrt();
            DVec3::new(st * phi.cos(), st * phi.sin(), ct)
        };
        let lambda = 380.0 + 400.0 * next();
        acc += if mode.starts_with("rgb") {
            brdf.eval_rgb(wi, wo)[1]
        } else {
            brdf.eval_spectral(wi, wo, lambda)
        };
    }
    let ns = start.elapsed().as_nanos() as f64 / count as f64;
    println!("{mode}: {ns:.1} ns per evaluation (checksum {acc:.6e})");
}

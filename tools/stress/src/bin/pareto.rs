//! `pareto`: errors of every accuracy configuration against the exhaustive
//! reference (see the library's `pareto` module). Writes JSON for
//! scripts/plot_pareto.py (default path target/pareto/errors.json); the
//! timings come from `cargo bench -p stress --bench pareto`.

use serde_json::json;
use stress::pareto;

fn main() {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "target/pareto/errors.json".to_string());
    let pairs = pareto::directions();
    let configs = pareto::configs();
    let mut rows = Vec::new();
    let mut convergence = Vec::new();
    for m in pareto::materials() {
        let (model, material, json) = (m.model.as_str(), m.label.as_str(), m.params.as_str());
        let t = std::time::Instant::now();
        let reference = pareto::reference(model, json, &pairs);
        // Convergence of the reference itself: the same at half the step.
        let brdf = pareto::reference_brdf(json);
        let step = if model == "periodic" {
            pareto::PERIODIC_REFERENCE_STEP_NM
        } else {
            pareto::REFERENCE_STEP_NM
        };
        let mut ref_change: f64 = 0.0;
        for (i, &(wi, wo, _)) in pairs.iter().enumerate().step_by(8) {
            let fine = brdf
                .eval_rgb_reference(wi, wo, 0.5 * step)
                .map(|c| c.max(0.0));
            let s = reference.rgb[i].iter().cloned().fold(0.0, f64::max);
            if s > 0.0 {
                for (f, r) in fine.iter().zip(reference.rgb[i]) {
                    ref_change = ref_change.max((f - r).abs() / s);
                }
            }
        }
        convergence.push(
            json!({"material": material, "step_nm": step, "change_at_half_step": ref_change}),
        );
        eprintln!(
            "{material}: reference in {:.1} s (step {step} nm; halving it changes it by {ref_change:.1e})",
            t.elapsed().as_secs_f64()
        );
        for (index, c) in configs.iter().enumerate() {
            if c.material != material {
                continue;
            }
            let (max, mean) = pareto::error(c, &pairs, &reference);
            eprintln!(
                "  c{index:03} {:<8} {:<55} max {max:.2e} mean {mean:.2e}",
                c.mode_name(),
                c.knob
            );
            rows.push(json!({
                "id": format!("c{index:03}"),
                "model": c.model,
                "material": c.material,
                "mode": c.mode_name(),
                "knob": c.knob,
                "default": c.is_default,
                "error_max": max,
                "error_mean": mean,
            }));
        }
    }
    // The fixed knobs: the Phi_alpha tables of the surveyed fractals.
    let mut profiles = Vec::new();
    for h in [0.7, 0.3] {
        let p = stam::fractal::StableProfile::new(2.0 * h).unwrap();
        let d = p.diagnostics();
        profiles.push(json!({
            "hurst": h,
            "nodes": d.nodes,
            "fft_windows": d.fft_windows,
            "node_error": d.node_error,
            "midpoint_error": d.midpoint_error,
            "normalisation_error": d.normalisation_error,
            "memory_bytes": p.memory_bytes(),
        }));
    }
    let out = json!({
        "pairs": pairs.len(),
        "configs": rows,
        "reference_convergence": convergence,
        "fractal_profiles": profiles,
    });
    if let Some(dir) = std::path::Path::new(&path).parent() {
        std::fs::create_dir_all(dir).expect("create the output directory");
    }
    std::fs::write(&path, serde_json::to_string_pretty(&out).unwrap()).expect("write errors");
    eprintln!("wrote {path}");
}

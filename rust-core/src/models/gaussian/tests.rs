//! Tests of the Gaussian model as a material uses it: its RGB table
//! against the per-node path it stands in for, and the table's memory.

use super::*;
use crate::material::Brdf;
use crate::models::Surface;
use crate::optics::geometry::PairGeometry;
use glam::DVec3;
use std::f64::consts::PI;

/// The Gaussian RGB table against the per-node path it stands in for,
/// at random pairs (uniform, near the mirror direction, grazing down to
/// cos = 1e-4): wherever the table serves the pair, the RGB agrees to
/// 1e-4 of the largest channel; everywhere else (grazing pairs below its
/// rows, tails beyond its columns) the result is the per-node path's,
/// bit for bit.
#[test]
fn gaussian_rgb_table_matches_per_node_path_and_falls_back_outside() {
    let materials = [
        r#"{"surface":"gaussian","sigma_um":0.03,"corr_um":2.0,"fresnel":"gold"}"#,
        r#"{"surface":"gaussian","sigma_um":0.6,"corr_um":4.0}"#,
        r#"{"surface":"gaussian","sigma_um":0.15,"corr_x_um":1.0,"corr_y_um":15.0,"fresnel":"silver"}"#,
        r#"{"surface":"gaussian","sigma_um":5.0,"corr_um":30.0,"fresnel":{"eta":1.5,"k":0}}"#,
        r#"{"surface":"gaussian","sigma_um":0.005,"corr_um":0.3,"rgb_nodes":16}"#,
    ];
    let mut rng = crate::benchmark::SplitMix64(3);
    let mut direction = |cos_lo: f64| {
        let ct = cos_lo + (1.0 - cos_lo) * rng.next_f64();
        let phi = 2.0 * PI * rng.next_f64();
        let st = (1.0 - ct * ct).sqrt();
        DVec3::new(st * phi.cos(), st * phi.sin(), ct)
    };
    let (mut served, mut missed) = (0, 0);
    let mut worst: f64 = 0.0;
    for json in materials {
        let brdf = Brdf::from_json(json).unwrap();
        let Surface::Gaussian(model) = brdf.surface() else {
            unreachable!()
        };
        let shading = brdf.shading();
        let table = model.rgb_table(&shading.rgb_rule.k_per_um).expect("table");
        let mut values = vec![0.0; shading.rgb_rule.len()];
        for i in 0..3000 {
            let wi = direction(if i % 3 == 0 { 1e-4 } else { 0.05 });
            let wo = if i % 3 == 1 {
                (DVec3::new(-wi.x, -wi.y, wi.z) + 0.2 * direction(0.0)).normalize()
            } else {
                direction(if i % 3 == 0 { 1e-4 } else { 0.0 })
            };
            let Some(geom) = PairGeometry::new(wi, wo) else {
                continue;
            };
            let fast = brdf.eval_rgb(wi, wo);
            let per_node = brdf.eval_rgb_by(wi, wo, |shading, geom| {
                model.kernel_at_nodes(shading, geom, false, &mut values);
                shading.integrate(geom.cos_half, &mut values)
            });
            if table.kernel(&model.surface, &geom, &mut values) {
                served += 1;
                let scale = per_node.iter().cloned().fold(0.0, f64::max);
                for c in 0..3 {
                    let e = (fast[c] - per_node[c]).abs() / scale.max(1e-300);
                    worst = worst.max(e);
                    assert!(e < 1e-4, "{json} {wi} {wo}: {fast:?} vs {per_node:?}");
                }
            } else {
                missed += 1;
                assert_eq!(fast, per_node, "{json} {wi} {wo}");
            }
        }
    }
    println!(
        "RGB table vs per-node path: {served} pairs served (worst {worst:.1e} of the largest channel), {missed} by the per-node path"
    );
    assert!(served > 10 * missed && missed > 50, "{served} {missed}");
}

/// The table is built on the first RGB evaluation only, not for exact
/// series settings, and counted in the memory of the material, which
/// stays under 4 MiB whatever the node count.
#[test]
fn gaussian_rgb_table_is_lazy_and_within_memory_limit() {
    let wi = DVec3::new(0.3, 0.1, 0.9).normalize();
    let wo = DVec3::new(-0.2, -0.1, 0.95).normalize();
    for nodes in [4, 12, 16, 24, 32, 64] {
        let json = format!(
            r#"{{"surface":"gaussian","sigma_um":0.2,"corr_x_um":2.0,"corr_y_um":9.0,"fresnel":"copper","rgb_nodes":{nodes}}}"#
        );
        let brdf = Brdf::from_json(&json).unwrap();
        // The energy table is built on the first evaluation too.
        brdf.energy_table();
        let before = brdf.memory_bytes();
        brdf.eval_spectral(wi, wo, 550.0);
        let Surface::Gaussian(model) = brdf.surface() else {
            unreachable!()
        };
        assert!(model.rgb_table.get().is_none(), "{json}");
        brdf.eval_rgb(wi, wo);
        let table = model.rgb_table.get().unwrap().as_ref().expect("table");
        let after = brdf.memory_bytes();
        println!("{nodes} nodes: {before} bytes, {after} with the RGB table");
        assert_eq!(after, before + table.memory_bytes());
        assert!(table.memory_bytes() <= super::rgb::MAX_TABLE_BYTES + 4096);
        assert!(after < 4 << 20, "{json}: {after} bytes");
    }
    let exact = Brdf::from_json(
        r#"{"surface":"gaussian","sigma_um":0.2,"corr_um":2.0,"series_tolerance":1e-7}"#,
    )
    .unwrap();
    exact.eval_rgb(wi, wo);
    let Surface::Gaussian(model) = exact.surface() else {
        unreachable!()
    };
    assert!(model.rgb_table.get().unwrap().is_none());
}

/// The tabulated diffuse albedo that sets the coherent probability
/// agrees with a brute-force midpoint quadrature of f cos over the
/// hemisphere (independent of the sampler), within its sampling noise.
#[test]
fn albedo_table_matches_quadrature() {
    let mut worst: f64 = 0.0;
    for (json, cos_i) in [
        (
            r#"{"surface":"gaussian","sigma_um":0.02,"corr_um":5,"fresnel":0.9}"#,
            0.08,
        ),
        (
            r#"{"surface":"gaussian","sigma_um":0.14,"corr_um":2,"fresnel":{"eta":1.2,"k":7}}"#,
            0.08,
        ),
        (
            r#"{"surface":"gaussian","sigma_um":0.14,"corr_um":2,"fresnel":{"eta":1.2,"k":7}}"#,
            0.5,
        ),
        (
            r#"{"surface":"gaussian","sigma_um":0.5,"corr_um":3,"fresnel":0.9}"#,
            0.08,
        ),
        (
            r#"{"surface":"gaussian","sigma_um":0.5,"corr_um":3,"fresnel":0.9}"#,
            0.3,
        ),
    ] {
        // The sampling aid tabulates Stam's f (the strategy's coherent share).
        let brdf =
            Brdf::from_json(&format!(r#"{},"energy":"stam"}}"#, &json[..json.len() - 1])).unwrap();
        let lambda = 550.0;
        let wi = DVec3::new(f64::sqrt(1.0 - cos_i * cos_i), 0.0, cos_i);
        let Surface::Gaussian(model) = brdf.surface() else {
            unreachable!()
        };
        let table = sampling::AlbedoTable::build(model, &brdf.shading());
        let tabulated =
            table.albedo(cos_i, lambda).unwrap() * brdf.fresnel().reflectance(cos_i, lambda);
        // Midpoint rule in (cos_o, phi_o).
        let (n_theta, n_phi) = (600, 1200);
        let mut quadrature = 0.0;
        for a in 0..n_theta {
            let c = (a as f64 + 0.5) / n_theta as f64;
            let s = (1.0 - c * c).sqrt();
            for b in 0..n_phi {
                let phi = 2.0 * PI * (b as f64 + 0.5) / n_phi as f64;
                let wo = DVec3::new(s * phi.cos(), s * phi.sin(), c);
                quadrature += brdf.eval_spectral(wi, wo, lambda) * c;
            }
        }
        quadrature *= 2.0 * PI / (n_theta * n_phi) as f64;
        let rel = (tabulated - quadrature).abs() / quadrature;
        println!(
            "{json} cos {cos_i}: table {tabulated:.4e}, quadrature {quadrature:.4e} ({rel:.1e})"
        );
        worst = worst.max(rel);
    }
    assert!(worst < 0.1, "worst relative error {worst}");
}

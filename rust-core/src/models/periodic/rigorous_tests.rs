//! `"orders": "rigorous"` against the solver it tabulates: each order's
//! lobe reflects the solver's efficiency, f is reciprocal, sampling is
//! consistent, RGB matches the spectral reference, bad parameters are
//! refused by name.

use std::sync::OnceLock;

use glam::DVec3;

use crate::material::Brdf;
use crate::rigorous::{solve, Grating, Incidence, Medium};
use crate::testing::chi2::chi2_fit;
use crate::testing::mean_var;

use super::params::{CD_BUMP_HEIGHT_UM, CD_BUMP_WIDTH_UM, CD_PERIOD_UM};
use super::Profile;

const DISC: &str = r#"{"surface":"cd","fresnel":"aluminium","orders":"rigorous"}"#;

/// The rigorous compact disc, built once for all the tests of this file
/// (its table takes seconds).
fn disc() -> &'static Brdf {
    static DISC_BRDF: OnceLock<Brdf> = OnceLock::new();
    DISC_BRDF.get_or_init(|| Brdf::from_json(DISC).unwrap())
}

fn disc_grating() -> Grating {
    Grating {
        period_um: CD_PERIOD_UM,
        profile: Profile::Rect {
            height_um: CD_BUMP_HEIGHT_UM,
            width_um: CD_BUMP_WIDTH_UM,
        },
        metal: Medium::Metal(crate::optics::fresnel::metal_by_name("aluminium").unwrap()),
        slices: 16,
    }
}

fn direction(theta_deg: f64, phi_deg: f64) -> DVec3 {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    DVec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
}

/// Distance in |k_t| from the nearest Rayleigh anomaly of the incidence
/// (where the table's error concentrates).
fn anomaly_distance(wi: DVec3, lambda_nm: f64) -> f64 {
    let step = lambda_nm * 1e-3 / CD_PERIOD_UM;
    (-30..=30)
        .map(|m| ((-wi.x + m as f64 * step).hypot(wi.y) - 1.0).abs())
        .fold(f64::INFINITY, f64::min)
}

/// Each order's lobe, f cos integrated over it (a midpoint rule over
/// +-6 sd in the projected plane), against the solver's efficiency.
#[test]
fn each_order_reflects_the_solvers_efficiency() {
    let brdf = disc();
    let l = super::params::CD_COHERENCE_UM;
    let (mut worst, mut worst_total, mut count) = (0.0f64, 0.0f64, 0);
    for &(lambda, theta, phi) in &[
        (450.0, 0.0, 0.0),
        (550.0, 30.0, 0.0),
        (650.0, 45.0, 180.0),
        (500.0, 20.0, 60.0),
        (600.0, 60.0, 30.0),
        (420.0, 10.0, 90.0),
        (700.0, 35.0, 150.0),
    ] {
        let wi = direction(theta, phi);
        let inc = Incidence {
            lambda_nm: lambda,
            theta_rad: wi.z.acos(),
            phi_rad: (-wi.y).atan2(-wi.x),
        };
        let d = solve(&disc_grating().stack(lambda, 1.0), &inc, 40).unwrap();
        let k = 2.0 * std::f64::consts::PI / (lambda * 1e-3);
        let sd = 1.0 / (std::f64::consts::SQRT_2 * k * l);
        let (mut total, mut total_solver) = (0.0, 0.0);
        for o in &d.reflected {
            let centre = (-wi.x + o.m as f64 * lambda * 1e-3 / CD_PERIOD_UM, -wi.y);
            total_solver += o.unpolarised();
            if centre.0.hypot(centre.1) > 1.0 - 8.0 * sd {
                continue;
            }
            let cells = 48;
            let h = 12.0 * sd / cells as f64;
            let mut sum = 0.0;
            for i in 0..cells {
                for j in 0..cells {
                    let x = centre.0 - 6.0 * sd + (i as f64 + 0.5) * h;
                    let y = centre.1 - 6.0 * sd + (j as f64 + 0.5) * h;
                    let z = (1.0 - x * x - y * y).sqrt();
                    // f cos_o d omega = f dx dy.
                    sum += brdf.eval_spectral(wi, DVec3::new(x, y, z), lambda) * h * h;
                }
            }
            let err = (sum - o.unpolarised()).abs();
            println!(
                "{lambda} nm, wi ({theta}, {phi}) deg, order {}: material {sum:.4}, solver {:.4}, anomaly distance {:.3}",
                o.m,
                o.unpolarised(),
                anomaly_distance(wi, lambda)
            );
            worst = worst.max(err);
            total += sum;
            count += 1;
        }
        worst_total = worst_total.max((total - total_solver).abs());
    }
    println!("{count} orders: worst |material - solver| {worst:.4}, worst total {worst_total:.4}");
    assert!(count > 40);
    assert!(worst < 0.03, "worst order error {worst}");
    assert!(worst_total < 0.03, "worst total error {worst_total}");
}

/// f(wi, wo) = f(wo, wi): exact by construction (both sides' tables).
#[test]
fn rigorous_orders_are_reciprocal() {
    let brdf = disc();
    let mut rng = crate::benchmark::SplitMix64(7);
    let mut checked = 0;
    for _ in 0..400 {
        let wi = direction(80.0 * rng.next_f64(), 360.0 * rng.next_f64());
        let lambda = 400.0 + 300.0 * rng.next_f64();
        // Near an order: the centre of a random propagating order.
        let step = lambda * 1e-3 / CD_PERIOD_UM;
        let m = (rng.next_f64() * 9.0) as i64 - 4;
        let (x, y) = (
            -wi.x + m as f64 * step + 2e-3 * (rng.next_f64() - 0.5),
            -wi.y,
        );
        if x.hypot(y) > 0.99 {
            continue;
        }
        let wo = DVec3::new(x, y, (1.0 - x * x - y * y).sqrt());
        let (a, b) = (
            brdf.eval_spectral(wi, wo, lambda),
            brdf.eval_spectral(wo, wi, lambda),
        );
        assert!((a - b).abs() <= 1e-12 * a.max(b), "{a} vs {b}");
        let (a, b) = (brdf.eval_rgb(wi, wo), brdf.eval_rgb(wo, wi));
        for c in 0..3 {
            assert!((a[c] - b[c]).abs() <= 1e-9 * a[c].abs().max(b[c].abs()).max(1e-6));
        }
        checked += usize::from(a.iter().any(|&c| c > 0.0));
    }
    assert!(checked > 100, "{checked}");
}

/// The albedo by importance sampling equals the solver's total reflectance
/// (a grating reflects at most 1), with every weight f cos / pdf finite.
#[test]
fn sampled_albedo_is_the_solvers_reflectance() {
    let brdf = disc();
    for &(lambda, theta, phi) in &[(550.0, 30.0, 0.0), (450.0, 60.0, 45.0), (650.0, 5.0, 90.0)] {
        let wi = direction(theta, phi);
        let s = brdf.sampler(wi, Some(lambda));
        let mut rng = crate::benchmark::SplitMix64(11);
        let weights: Vec<f64> = (0..20_000)
            .map(|_| {
                let r = s.sample([rng.next_f64(), rng.next_f64(), rng.next_f64()]);
                if r.pdf > 0.0 {
                    let w = brdf.eval_spectral(wi, r.wo, lambda) * r.wo.z / r.pdf;
                    assert!(w.is_finite() && w >= 0.0, "{w}");
                    w
                } else {
                    0.0
                }
            })
            .collect();
        let (mean, var) = mean_var(&weights);
        let se = (var / weights.len() as f64).sqrt();
        let inc = Incidence {
            lambda_nm: lambda,
            theta_rad: wi.z.acos(),
            phi_rad: (-wi.y).atan2(-wi.x),
        };
        let d = solve(&disc_grating().stack(lambda, 1.0), &inc, 40).unwrap();
        let r = 0.5 * (d.reflectance()[0] + d.reflectance()[1]);
        println!("{lambda} nm ({theta}, {phi}): sampled albedo {mean:.4} +- {se:.4}, solver {r:.4}, cv {:.3}", var.sqrt() / mean);
        assert!(mean <= 1.0 + 3.0 * se);
        assert!((mean - r).abs() < 0.03 + 4.0 * se, "{mean} vs {r}");
        // Sampling from the efficiencies: a low variance.
        assert!(var.sqrt() < 0.5 * mean, "cv {}", var.sqrt() / mean);
    }
}

/// The strategies' samples follow their pdf (spectral and RGB). A
/// coherence length of 5 um: the disc's 50 um lobes (sd 1e-3) are
/// narrower than the harness's cubature resolves, for Stam's orders too.
#[test]
fn rigorous_sampling_passes_chi_square() {
    let brdf = Brdf::from_json(
        r#"{"surface":"cd","fresnel":"aluminium","orders":"rigorous","coherence_um":5}"#,
    )
    .unwrap();
    for (i, &(lambda, theta, phi)) in [(550.0, 30.0, 0.0), (450.0, 60.0, 45.0)].iter().enumerate() {
        let wi = direction(theta, phi);
        let seed = 5 + 2 * i as u64;
        let fit = chi2_fit(&brdf.sampler(wi, Some(lambda)), seed, 40_000);
        println!("{lambda} nm ({theta}, {phi}): chi2 p {}", fit.p_value);
        assert!(fit.p_value > 1e-3, "chi2 p {}", fit.p_value);
        let fit = chi2_fit(&brdf.sampler(wi, None), seed + 1, 40_000);
        println!("RGB ({theta}, {phi}): chi2 p {}", fit.p_value);
        assert!(fit.p_value > 1e-3, "chi2 p (RGB) {}", fit.p_value);
    }
}

/// RGB equals the spectral reference integration near orders.
#[test]
fn rigorous_rgb_matches_the_spectral_reference() {
    let brdf = disc();
    let mut worst = 0.0f64;
    for &(theta, phi, m, dx) in &[
        (30.0, 0.0, 1, 0.0),
        (30.0, 0.0, -1, 0.01),
        (10.0, 90.0, 2, -0.02),
        (45.0, 180.0, 0, 0.0),
        (45.0, 180.0, 0, 3e-4),
        (20.0, 30.0, -3, 0.0),
    ] {
        let wi = direction(theta, phi);
        // The order's centre at 550 nm, moved by dx.
        let x = -wi.x + m as f64 * 0.55 / CD_PERIOD_UM + dx;
        let y = -wi.y;
        let wo = DVec3::new(x, y, (1.0 - x * x - y * y).sqrt());
        let fast = brdf.eval_rgb(wi, wo);
        let reference = crate::spectrum::gamut_map(brdf.eval_rgb_reference(wi, wo, 0.25));
        let scale = reference.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
        let err = (0..3)
            .map(|c| (fast[c] - reference[c]).abs())
            .fold(0.0, f64::max)
            / scale;
        println!("({theta}, {phi}) order {m} dx {dx}: {fast:?} vs {reference:?}: {err:.2e}");
        assert!(scale > 0.0);
        worst = worst.max(err);
    }
    assert!(worst < 1e-2, "worst relative RGB error {worst}");
}

/// RGB against the spectral reference (0.25 nm) at pairs drawn within two
/// sd of an order's centre at 550 nm, at the disc's coherence length
/// (50 um) and at 8 um (wider peaks). Measured 2026-12-06: worst 4.4e-3 at
/// 50 um, 7.5e-3 at 8 um; 1.0e-2 and 9.1e-2 before narrow peaks of given
/// powers took midpoints instead of a three-wavelength quadratic fit.
#[test]
fn rigorous_rgb_matches_the_reference_near_orders() {
    let short = Brdf::from_json(
        r#"{"surface":"cd","fresnel":"aluminium","orders":"rigorous","coherence_um":8}"#,
    )
    .unwrap();
    let mut rng = crate::benchmark::SplitMix64(21);
    for (brdf, coherence_um) in [(disc(), 50.0), (&short, 8.0)] {
        let sd_u = 0.55 / (2.0 * std::f64::consts::SQRT_2 * std::f64::consts::PI * coherence_um);
        let (mut worst, mut compared) = (0.0f64, 0);
        for _ in 0..40 {
            let (theta, phi) = (60.0 * rng.next_f64(), 360.0 * rng.next_f64());
            let m = (7.0 * rng.next_f64()) as i64 - 3;
            let dx = sd_u * (4.0 * rng.next_f64() - 2.0);
            let wi = direction(theta, phi);
            let x = -wi.x + m as f64 * 0.55 / CD_PERIOD_UM + dx;
            let y = -wi.y;
            if x * x + y * y > 0.95 {
                continue;
            }
            let wo = DVec3::new(x, y, (1.0 - x * x - y * y).sqrt());
            let fast = brdf.eval_rgb(wi, wo);
            let reference = crate::spectrum::gamut_map(brdf.eval_rgb_reference(wi, wo, 0.25));
            let scale = reference.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
            if !(scale > 0.0) {
                continue;
            }
            let err = (0..3)
                .map(|c| (fast[c] - reference[c]).abs())
                .fold(0.0, f64::max)
                / scale;
            worst = worst.max(err);
            compared += 1;
        }
        println!(
            "coherence {coherence_um} um: {compared} pairs, worst relative RGB error {worst:.2e}"
        );
        assert!(compared >= 24 && worst < 1e-2, "{coherence_um} um: {worst}");
    }
}

#[test]
fn rigorous_parameters_are_checked_by_name() {
    let err = |json: &str| Brdf::from_json(json).err().map(|e| e.to_string()).unwrap();
    let e = err(r#"{"surface":"cd","orders":"rigorous","fresnel":0.9}"#);
    assert!(e.contains("fresnel") && e.contains("rigorous"), "{e}");
    let e = err(r#"{"surface":"cd","orders":"rigorous","fresnel":"gold","energy":"conserving"}"#);
    assert!(e.contains("energy"), "{e}");
    let e = err(r#"{"surface":"cd","fourier_orders":30}"#);
    assert!(e.contains("fourier_orders"), "{e}");
    let e = err(r#"{"surface":"cd","orders":"maxwell"}"#);
    assert!(e.contains("orders") && e.contains("rigorous"), "{e}");
    let e = err(r#"{"surface":"cd","orders":"rigorous","fresnel":"gold","fourier_orders":2}"#);
    assert!(e.contains("fourier_orders"), "{e}");
    let e = err(
        r#"{"surface":"periodic","period_um":1.6,"coherence_um":6,"profile":"sine","height_um":0.1,"height_um_max":0.2,"orders":"rigorous","fresnel":"gold"}"#,
    );
    assert!(e.contains("height_um_max"), "{e}");
    // The resolved parameters name the mode and the truncation, and
    // read back to the same material.
    let resolved = crate::material::params::resolved_json_text(DISC).unwrap();
    let v: serde_json::Value = serde_json::from_str(&resolved).unwrap();
    assert_eq!(v["orders"], "rigorous");
    assert_eq!(v["fourier_orders"], 20);
    assert_eq!(v["energy"], "stam");
    let again = crate::material::params::MaterialParams::from_json(&resolved).unwrap();
    assert_eq!(
        again,
        crate::material::params::MaterialParams::from_json(DISC).unwrap()
    );
}

/// Measurement (docs/rigorous.md): the material's order efficiencies
/// against direct solves for gratings of three metals, both profiles,
/// periods 0.5-3 um and depths 0.05-0.3 um, at random incidences (0-80 deg,
/// any azimuth) and wavelengths (400-700 nm); each order read at its own
/// centre, as its lobe carries it.
#[test]
#[ignore = "measurement: cargo test --release -p stam-core --lib print_grating_sweep -- --ignored --nocapture"]
fn print_grating_sweep() {
    let gratings = [
        ("aluminium", 1.6, "rect", 0.10, 0.6),
        ("silver", 0.5, "sine", 0.05, 0.0),
        ("gold", 3.0, "rect", 0.30, 1.0),
        ("aluminium", 1.0, "sine", 0.20, 0.0),
        ("gold", 2.0, "sine", 0.15, 0.0),
        ("silver", 0.8, "rect", 0.08, 0.4),
    ];
    for (metal, period, profile, height, width) in gratings {
        let json = if profile == "rect" {
            format!(
                r#"{{"surface":"periodic","period_um":{period},"coherence_um":50,"profile":"rect","height_um":{height},"width_um":{width},"fresnel":"{metal}","orders":"rigorous"}}"#
            )
        } else {
            format!(
                r#"{{"surface":"periodic","period_um":{period},"coherence_um":50,"profile":"sine","height_um":{height},"fresnel":"{metal}","orders":"rigorous"}}"#
            )
        };
        let start = std::time::Instant::now();
        let brdf = Brdf::from_json(&json).unwrap();
        let build = start.elapsed().as_secs_f64();
        let crate::models::Surface::Periodic(model) = brdf.surface() else {
            unreachable!()
        };
        let r = model.rigorous().unwrap();
        let grating = Grating {
            period_um: period,
            profile: if profile == "rect" {
                Profile::Rect {
                    height_um: height,
                    width_um: width,
                }
            } else {
                Profile::Sine { height_um: height }
            },
            metal: Medium::Metal(crate::optics::fresnel::metal_by_name(metal).unwrap()),
            slices: 16,
        };
        let mut rng = crate::benchmark::SplitMix64(17);
        let mut errors = Vec::new();
        let mut one_side = Vec::new();
        let mut worst_total = 0.0f64;
        for _ in 0..40 {
            let lambda = 400.0 + 300.0 * rng.next_f64();
            let wi = direction(80.0 * rng.next_f64(), 360.0 * rng.next_f64());
            let inc = Incidence {
                lambda_nm: lambda,
                theta_rad: wi.z.acos(),
                phi_rad: (-wi.y).atan2(-wi.x),
            };
            let n = crate::rigorous::default_fourier_orders(period, 1.0);
            let d = solve(&grating.stack(lambda, 1.0), &inc, n).unwrap();
            let (mut total, mut total_solver) = (0.0, 0.0);
            for o in &d.reflected {
                let (x, y) = (-wi.x + o.m as f64 * lambda * 1e-3 / period, -wi.y);
                let wo = DVec3::new(x, y, (1.0 - x * x - y * y).max(0.0).sqrt());
                let e = r.efficiency(-o.m, lambda, wi, wo);
                errors.push((e - o.unpolarised()).abs());
                let e1 = r.table().efficiency(lambda, -wi.x, -wi.y, o.m);
                one_side.push((e1 - o.unpolarised()).abs());
                total += e;
                total_solver += o.unpolarised();
            }
            worst_total = worst_total.max((total - total_solver).abs());
        }
        errors.sort_by(f64::total_cmp);
        one_side.sort_by(f64::total_cmp);
        let rms1 = (one_side.iter().map(|e| e * e).sum::<f64>() / one_side.len() as f64).sqrt();
        println!(
            "  the table at wi alone: max {:.4}, rms {rms1:.4}",
            one_side.last().unwrap()
        );
        let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
        let p99 = errors[(0.99 * (errors.len() - 1) as f64) as usize];
        println!(
            "{metal} {profile} period {period} height {height}: table {build:.1} s, {} orders: max {:.4}, p99 {p99:.4}, rms {rms:.4}; worst total {worst_total:.4}",
            errors.len(),
            errors.last().unwrap()
        );
    }
}

/// A disc under polycarbonate (`cover_eta` 1.58): the cover reflects its
/// Fresnel reflectance as a mirror (the coherent lobe), and the albedo is
/// that plus, through both interfaces, the orders the solver (with the
/// cover as incidence medium) sends out of the cover.
#[test]
fn covered_disc_reflects_its_cover_and_the_orders_that_leave() {
    let eta = 1.58;
    let brdf = Brdf::from_json(&format!(
        r#"{{"surface":"cd","fresnel":"aluminium","orders":"rigorous","cover_eta":{eta},"coherence_um":10}}"#
    ))
    .unwrap();
    assert!(brdf.flags() & crate::models::FLAG_HAS_COHERENT != 0);
    let r = |c: f64| crate::optics::fresnel::conductor_reflectance(c, eta, 0.0);
    for &(lambda, theta, phi) in &[(550.0, 30.0, 0.0), (450.0, 55.0, 45.0)] {
        let wi = direction(theta, phi);
        let mirror = brdf.coherent_spectral(wi, lambda);
        assert!((mirror - r(wi.z)).abs() < 1e-12, "{mirror} vs {}", r(wi.z));
        assert!((brdf.coherent_rgb(wi)[1] - r(wi.z)).abs() < 1e-9);
        // The solver inside the cover: the same tangential wavevector.
        let sin_inside = (1.0 - wi.z * wi.z).sqrt() / eta;
        let inc = Incidence {
            lambda_nm: lambda,
            theta_rad: sin_inside.asin(),
            phi_rad: (-wi.y).atan2(-wi.x),
        };
        let n = crate::rigorous::default_fourier_orders(CD_PERIOD_UM, eta);
        let d = solve(&disc_grating().stack(lambda, eta), &inc, n).unwrap();
        let mut expected = r(wi.z);
        for o in &d.reflected {
            let (x, y) = (-wi.x + o.m as f64 * lambda * 1e-3 / CD_PERIOD_UM, -wi.y);
            if x * x + y * y < 1.0 {
                let cos_o = (1.0 - x * x - y * y).sqrt();
                expected += (1.0 - r(wi.z)) * o.unpolarised() * (1.0 - r(cos_o));
            }
        }
        let s = brdf.sampler(wi, Some(lambda));
        let mut rng = crate::benchmark::SplitMix64(23);
        let weights: Vec<f64> = (0..40_000)
            .map(|_| {
                let x = s.sample(rng.three());
                if !(x.pdf > 0.0) {
                    0.0
                } else if x.coherent {
                    brdf.coherent_spectral(wi, lambda) / x.pdf
                } else {
                    brdf.eval_spectral(wi, x.wo, lambda) * x.wo.z / x.pdf
                }
            })
            .collect();
        let (mean, var) = mean_var(&weights);
        let se = (var / weights.len() as f64).sqrt();
        println!("covered disc {lambda} nm ({theta}, {phi}): albedo {mean:.4} +- {se:.4}, expected {expected:.4}, mirror {mirror:.4}");
        assert!(mean <= 1.0 + 3.0 * se);
        assert!(
            (mean - expected).abs() < 0.03 + 4.0 * se,
            "{mean} vs {expected}"
        );
        // Reciprocity through the cover, and sampling against its pdf.
        let wo = DVec3::new(-wi.x + 0.22, -wi.y, 0.0);
        let wo = DVec3::new(wo.x, wo.y, (1.0 - wo.x * wo.x - wo.y * wo.y).sqrt());
        let (a, b) = (
            brdf.eval_spectral(wi, wo, lambda),
            brdf.eval_spectral(wo, wi, lambda),
        );
        assert!((a - b).abs() <= 1e-12 * a.max(b));
        let fit = chi2_fit(&s, 31, 40_000);
        assert!(fit.p_value > 1e-3, "chi2 p {}", fit.p_value);
    }
}

/// Measurement: the cost of a rigorous disc's evaluations and strategies
/// against the Kirchhoff disc's (the default, conserving).
#[test]
#[ignore = "measurement: cargo test --release -p stam-core --lib print_rigorous_costs -- --ignored --nocapture"]
fn print_rigorous_costs() {
    let kirchhoff = Brdf::from_json(r#"{"surface":"cd","fresnel":"aluminium"}"#).unwrap();
    let rigorous = disc();
    let mut rng = crate::benchmark::SplitMix64(3);
    let pairs: Vec<(DVec3, DVec3, f64)> = (0..20_000)
        .map(|_| {
            let wi = direction(70.0 * rng.next_f64(), 360.0 * rng.next_f64());
            let lambda = 400.0 + 300.0 * rng.next_f64();
            let m = (rng.next_f64() * 7.0) as i64 - 3;
            let x = (-wi.x + m as f64 * lambda * 1e-3 / CD_PERIOD_UM).clamp(-0.9, 0.9);
            let y = -wi.y * 0.9;
            (wi, DVec3::new(x, y, (1.0 - x * x - y * y).sqrt()), lambda)
        })
        .collect();
    let mirror = &pairs[..2000];
    for (name, b) in [("kirchhoff", &kirchhoff), ("rigorous", rigorous)] {
        let _ = b.eval_rgb(pairs[0].0, pairs[0].1);
        // Order 0's grid of spectra (built on the first pair near the mirror).
        let _ = b.eval_rgb(direction(30.0, 0.0), direction(30.0, 180.0));
        let _ = b.sampler(pairs[0].0, None).pdf(pairs[0].1);
        let t = std::time::Instant::now();
        let mut sink = 0.0;
        for &(wi, wo, lambda) in &pairs {
            sink += b.eval_spectral(wi, wo, lambda);
        }
        let spectral = t.elapsed().as_secs_f64() / pairs.len() as f64;
        let t = std::time::Instant::now();
        for &(wi, wo, _) in &pairs {
            sink += b.eval_rgb(wi, wo)[1];
        }
        let rgb = t.elapsed().as_secs_f64() / pairs.len() as f64;
        // Near the mirror direction (order 0's broad peak in wavelength).
        let t = std::time::Instant::now();
        for &(wi, _, _) in mirror {
            let wo = DVec3::new(-wi.x + 0.01, -wi.y, 0.0);
            let wo = DVec3::new(wo.x, wo.y, (1.0 - wo.x * wo.x - wo.y * wo.y).sqrt());
            sink += b.eval_rgb(wi, wo)[1];
        }
        let rgb_mirror = t.elapsed().as_secs_f64() / mirror.len() as f64;
        let t = std::time::Instant::now();
        for &(wi, wo, lambda) in &pairs {
            sink += b.sampler(wi, Some(lambda)).pdf(wo);
        }
        let strategy = t.elapsed().as_secs_f64() / pairs.len() as f64;
        let t = std::time::Instant::now();
        for &(wi, wo, _) in &pairs {
            sink += b.sampler(wi, None).pdf(wo);
        }
        let strategy_rgb = t.elapsed().as_secs_f64() / pairs.len() as f64;
        println!(
            "{name}: eval spectral {:.2} us, eval RGB {:.2} us (0.01 from the mirror {:.2} us), spectral strategy + pdf {:.2} us, RGB strategy + pdf {:.2} us ({sink:.1})",
            spectral * 1e6,
            rgb * 1e6,
            rgb_mirror * 1e6,
            strategy * 1e6,
            strategy_rgb * 1e6
        );
    }
}

/// Measurement: the spread of RGB sample weights f cos / pdf (green) of
/// the rigorous and the Kirchhoff disc over random incidences.
#[test]
#[ignore = "measurement: cargo test --release -p stam-core --lib print_rgb_weight_spread -- --ignored --nocapture"]
fn print_rgb_weight_spread() {
    let kirchhoff = Brdf::from_json(r#"{"surface":"cd","fresnel":"aluminium"}"#).unwrap();
    for (name, b) in [("kirchhoff", &kirchhoff), ("rigorous", disc())] {
        let mut rng = crate::benchmark::SplitMix64(9);
        let (mut worst, mut worst_at) = (0.0f64, DVec3::ZERO);
        let mut cvs = Vec::new();
        for _ in 0..200 {
            let wi = direction(85.0 * rng.next_f64().sqrt(), 360.0 * rng.next_f64());
            let s = b.sampler(wi, None);
            let w: Vec<f64> = (0..2000)
                .map(|_| {
                    let x = s.sample(rng.three());
                    if x.pdf > 0.0 && !x.coherent {
                        b.eval_rgb(wi, x.wo)[1] * x.wo.z / x.pdf
                    } else {
                        0.0
                    }
                })
                .collect();
            let (mean, var) = mean_var(&w);
            let max = w.iter().cloned().fold(0.0, f64::max);
            if mean > 0.0 {
                cvs.push(var.sqrt() / mean);
                if max / mean > worst {
                    worst = max / mean;
                    worst_at = wi;
                }
            }
        }
        cvs.sort_by(f64::total_cmp);
        println!(
            "{name}: cv median {:.2}, 90% {:.2}, max {:.2}; largest weight / mean {worst:.0} at wi {worst_at:?}",
            cvs[cvs.len() / 2],
            cvs[cvs.len() * 9 / 10],
            cvs.last().unwrap()
        );
    }
}

/// The compact disc's rigorous orders as the material makes them (the
/// table from the cache that `disc()` fills).
fn disc_orders() -> super::rigorous::RigorousOrders {
    use crate::optics::fresnel::{metal_by_name, Fresnel};
    super::rigorous::RigorousOrders::new(
        CD_PERIOD_UM,
        &disc_grating().profile,
        &Fresnel::metal(metal_by_name("aluminium").unwrap()),
        crate::rigorous::default_fourier_orders(CD_PERIOD_UM, 1.0),
        1.0,
    )
    .unwrap()
}

/// The RGB kernel of `surface` with the powers given per order.
fn given_rgb(
    surface: &super::PeriodicSurface,
    geom: &crate::optics::geometry::PairGeometry,
    power: &dyn Fn(i64, f64) -> f64,
    at_node: &dyn Fn(i64, usize) -> f64,
) -> [f64; 3] {
    surface.kernel_rgb_general(geom, super::OrderWeights::Given { power, at_node })
}

/// Order 0's spectra read from their grid (`order_zero_at_nodes`, what the
/// RGB broad rule takes near the mirror direction) against the table read
/// at each wavelength, at pairs around the mirror direction: per node, and
/// through the RGB kernel over coherence lengths that make the peak broad.
#[test]
fn order_zero_spectra_agree_with_the_table() {
    use super::PeriodicSurface;
    use crate::optics::geometry::PairGeometry;
    let orders = disc_orders();
    let lambdas = PeriodicSurface::given_broad_wavelengths();
    let mut rng = crate::benchmark::SplitMix64(11);
    let (mut worst, mut sum2, mut count) = (0.0f64, 0.0, 0usize);
    let mut rgb_errors = Vec::new();
    for i in 0..600 {
        let wi = direction(85.0 * rng.next_f64().sqrt(), 360.0 * rng.next_f64());
        // Around the mirror direction, up to 0.05 in the projected plane
        // (a third of them at the mirror direction, half of those in the
        // plane across the grooves).
        let (dx, dy) = if i % 3 == 0 {
            (0.0, 0.0)
        } else {
            (0.1 * rng.next_f64() - 0.05, 0.1 * rng.next_f64() - 0.05)
        };
        let wi = if i % 6 == 0 {
            direction(85.0 * rng.next_f64().sqrt(), 180.0 * (i % 12 / 6) as f64)
        } else {
            wi
        };
        let (x, y) = (-wi.x + dx, -wi.y + dy);
        if x * x + y * y > 0.999 {
            continue;
        }
        let wo = DVec3::new(x, y, (1.0 - x * x - y * y).sqrt());
        let read = orders.order_zero_at_nodes(wi, wo);
        for (j, &lambda) in lambdas.iter().enumerate() {
            let e = (read[j] - orders.power(0, lambda, wi, wo)).abs();
            worst = worst.max(e);
            sum2 += e * e;
            count += 1;
        }
        let coherence_um = 1.0 + 30.0 * rng.next_f64();
        let surface =
            PeriodicSurface::new(CD_PERIOD_UM, coherence_um, disc_grating().profile).unwrap();
        let geom = PairGeometry::new(wi, wo).unwrap();
        let power = |n: i64, lambda: f64| orders.power(n, lambda, wi, wo);
        let direct = |n: i64, j: usize| power(n, lambdas[j]);
        let gridded = |n: i64, j: usize| if n == 0 { read[j] } else { direct(n, j) };
        let kernel =
            |at_node: &dyn Fn(i64, usize) -> f64| given_rgb(&surface, &geom, &power, at_node);
        let (fast, slow) = (kernel(&gridded), kernel(&direct));
        // Relative to the lobe's peak: f at the mirror direction.
        let mirror = DVec3::new(-wi.x, -wi.y, wi.z);
        let peak_geom = PairGeometry::new(wi, mirror).unwrap();
        let peak_power = |n: i64, lambda: f64| orders.power(n, lambda, wi, mirror);
        let peak_at = |n: i64, j: usize| peak_power(n, lambdas[j]);
        let peak = given_rgb(&surface, &peak_geom, &peak_power, &peak_at);
        let scale = peak.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
        if scale > 0.0 {
            let e = (0..3)
                .map(|c| (fast[c] - slow[c]).abs())
                .fold(0.0, f64::max)
                / scale;
            let a = coherence_um * geom.u.hypot(geom.v);
            rgb_errors.push((e, a, 0.5 * (wo.x - wi.x).hypot(wo.y - wi.y)));
        }
    }
    let rms = (sum2 / count as f64).sqrt();
    rgb_errors.sort_by(|a, b| b.0.total_cmp(&a.0));
    println!("order 0 per node: worst {worst:.4}, rms {rms:.5} ({count} reads)");
    println!(
        "RGB error over the lobe's peak (error, l rho, |k|), worst first: {:?}",
        &rgb_errors[..8]
    );
    for band in [0.0, 0.8, 0.9, 0.95, 0.98] {
        let worst_in = rgb_errors
            .iter()
            .filter(|e| e.2 >= band)
            .fold(0.0f64, |a, e| a.max(e.0));
        let n = rgb_errors.iter().filter(|e| e.2 >= band).count();
        println!("|k| >= {band}: {n} pairs, worst {worst_in:.2e}");
    }
    let p90 = rgb_errors[rgb_errors.len() / 10].0;
    println!("RGB: {} pairs, p90 {p90:.2e}", rgb_errors.len());
    // Measured: rms 0.0027, RGB worst 2.0e-2 of the peak (at the mirror
    // direction itself, |k| 0.61), p90 1.0e-3.
    assert!(rms < 4e-3 && rgb_errors[0].0 < 3e-2 && p90 < 3e-3);
}

/// At the mirror direction (where order 0's broad peak is largest), RGB
/// from order 0's grid of spectra and from the table read at each node,
/// both against the solver itself at each node (N as the table's).
#[test]
fn order_zero_grid_and_table_against_the_solver_at_the_mirror() {
    use super::PeriodicSurface;
    use crate::optics::geometry::PairGeometry;
    let n_fourier = crate::rigorous::default_fourier_orders(CD_PERIOD_UM, 1.0);
    let orders = disc_orders();
    let g = disc_grating();
    let lambdas = PeriodicSurface::given_broad_wavelengths();
    let surface = PeriodicSurface::new(CD_PERIOD_UM, 50.0, disc_grating().profile).unwrap();
    let (mut worst_grid, mut worst_table, mut worst_added) = (0.0f64, 0.0f64, 0.0f64);
    let mut rng = crate::benchmark::SplitMix64(5);
    let mut incidences = vec![
        (10.0, 180.0),
        (37.3, 180.0),
        (45.0, 180.0),
        (52.0, 0.0),
        (20.0, 60.0),
        (35.0, 120.0),
        (50.0, 30.0),
        (60.0, 90.0),
    ];
    incidences.extend((0..8).map(|_| (60.0 * rng.next_f64(), 360.0 * rng.next_f64())));
    for &(theta, phi) in &incidences {
        let wi = direction(theta, phi);
        let wo = DVec3::new(-wi.x, -wi.y, wi.z);
        let geom = PairGeometry::new(wi, wo).unwrap();
        // The table is read at incidence (kx, ky) = -wi's tangential part.
        let inc = Incidence {
            lambda_nm: 0.0,
            theta_rad: f64::to_radians(theta),
            phi_rad: f64::to_radians(phi + 180.0),
        };
        let solved: Vec<f64> = lambdas
            .iter()
            .map(|&lambda| {
                let d = solve(
                    &g.stack(lambda, 1.0),
                    &Incidence {
                        lambda_nm: lambda,
                        ..inc
                    },
                    n_fourier,
                )
                .unwrap();
                d.reflected
                    .iter()
                    .find(|o| o.m == 0)
                    .map_or(0.0, |o| o.unpolarised())
            })
            .collect();
        let grid = orders.order_zero_at_nodes(wi, wo);
        let power = |n: i64, lambda: f64| orders.power(n, lambda, wi, wo);
        let kernel =
            |at_node: &dyn Fn(i64, usize) -> f64| given_rgb(&surface, &geom, &power, at_node);
        let from_solver = kernel(&|n: i64, j: usize| if n == 0 { solved[j] } else { 0.0 });
        let from_grid = kernel(&|n: i64, j: usize| if n == 0 { grid[j] } else { 0.0 });
        let from_table =
            kernel(&|n: i64, j: usize| if n == 0 { power(0, lambdas[j]) } else { 0.0 });
        let scale = from_solver.iter().fold(0.0f64, |a, &b| a.max(b.abs()));
        let err = |v: [f64; 3]| {
            (0..3)
                .map(|c| (v[c] - from_solver[c]).abs())
                .fold(0.0, f64::max)
                / scale
        };
        println!(
            "({theta}, {phi}): grid {:.2e}, table {:.2e} of the solver's",
            err(from_grid),
            err(from_table)
        );
        worst_grid = worst_grid.max(err(from_grid));
        worst_table = worst_table.max(err(from_table));
        worst_added = worst_added.max(err(from_grid) - err(from_table));
    }
    println!("worst: grid {worst_grid:.2e}, table {worst_table:.2e}; the grid adds at most {worst_added:.2e}");
    // The table's own error is issue 41's open accuracy item; the grid
    // must not add to it beyond 0.5% of the peak.
    assert!(worst_added < 5e-3 && worst_table < 0.1);
}

/// Errors of the programs' per-order grid (`rigorous_grid.rs`) against
/// the table's own lookup (`pair_efficiency`) at `cases` random exact
/// pairs: incidence uniform over the projected disc, a wavelength uniform
/// over the band, one propagating order: (max, rms, p99, count).
fn pair_grid_errors(
    orders: &super::rigorous::RigorousOrders,
    period_um: f64,
    cases: usize,
) -> (f64, f64, f64, usize) {
    use crate::sampling::SplitMix64;
    use crate::spectrum::{LAMBDA_MAX_NM, LAMBDA_MIN_NM};
    let grid = orders.pair_grid().expect("the disc's grid");
    let mut rng = SplitMix64(7);
    let mut errors = Vec::new();
    while errors.len() < cases {
        let (x, y): (f64, f64) = (2.0 * rng.next_f64() - 1.0, 2.0 * rng.next_f64() - 1.0);
        if x * x + y * y > 0.999 {
            continue;
        }
        let lambda = LAMBDA_MIN_NM + (LAMBDA_MAX_NM - LAMBDA_MIN_NM) * rng.next_f64();
        let du = lambda * 1e-3 / period_um;
        let half = (1.0 - y * y).sqrt();
        // Incident (kx, ky) = (-x, -y); order n leaves at -x - n du (Stam's
        // u_n = n du, wo.x = -x - u_n).
        let (lo, hi) = (
            ((-x - half) / du).ceil() as i64,
            ((-x + half) / du).floor() as i64,
        );
        if lo > hi {
            continue;
        }
        let n = lo + ((hi - lo + 1) as f64 * rng.next_f64()) as i64;
        let n = n.min(hi);
        let (wi_x, wo_x) = (x, -x - n as f64 * du);
        let (c, ky) = (0.5 * (wo_x - wi_x), y);
        let native = orders.pair_efficiency(n, lambda, c, ky);
        let read = grid.read(n as f64, lambda, c, ky, |i: f64| {
            grid.values[i as usize] as f64
        });
        errors.push((read - native).abs());
    }
    errors.sort_by(f64::total_cmp);
    let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    let p99 = errors[(errors.len() * 99) / 100];
    (*errors.last().unwrap(), rms, p99, errors.len())
}

#[test]
#[ignore = "measurement: cargo test --release -p stam-core --lib print_pair_grid_accuracy -- --ignored --nocapture"]
fn print_pair_grid_accuracy() {
    let orders = disc_orders();
    let t = std::time::Instant::now();
    let bytes = orders.pair_grid().expect("the disc's grid").memory_bytes();
    println!(
        "grid build {:.2} s, {:.1} MB",
        t.elapsed().as_secs_f64(),
        bytes as f64 / 1e6
    );
    let (max, rms, p99, n) = pair_grid_errors(&orders, CD_PERIOD_UM, 20_000);
    println!("pair grid against the table, {n} random exact pairs: max {max:.4} rms {rms:.5} p99 {p99:.4}");
    // A 3 um grating, whose grid takes fewer nodes per unit.
    use crate::optics::fresnel::{metal_by_name, Fresnel};
    let period_um = 3.0;
    let coarse = super::rigorous::RigorousOrders::new(
        period_um,
        &Profile::Rect {
            height_um: 0.1,
            width_um: 1.0,
        },
        &Fresnel::metal(metal_by_name("aluminium").unwrap()),
        crate::rigorous::default_fourier_orders(period_um, 1.0),
        1.0,
    )
    .unwrap();
    let grid = coarse.pair_grid().expect("the 3 um grid");
    let (max, rms, p99, n) = pair_grid_errors(&coarse, period_um, 20_000);
    println!(
        "3 um aluminium rect 0.1 x 1.0, {} per unit, {:.1} MB: {n} pairs, max {max:.4} rms {rms:.5} p99 {p99:.4}",
        grid.per_unit,
        grid.memory_bytes() as f64 / 1e6
    );
}

/// The grid's regression check: measured max 0.21, rms 0.0067, p99 0.024
/// at 20,000 pairs (`print_pair_grid_accuracy`).
#[test]
fn pair_grid_reads_the_table_within_its_measured_error() {
    let (max, rms, p99, n) = pair_grid_errors(&disc_orders(), CD_PERIOD_UM, 4000);
    println!("pair grid: {n} pairs, max {max:.4} rms {rms:.5} p99 {p99:.4}");
    assert!(
        rms < 0.0085 && p99 < 0.032 && max < 0.3,
        "{max} {rms} {p99}"
    );
}

/// The JIT programs of the rigorous disc: EVAL_SPECTRAL, run in f64, is
/// `kernel_given` with each order's power read from the pair grid (the
/// only difference from the native f, measured above), at pairs near
/// orders; every kind exists; the period
/// is no parameter of it (its efficiencies could not follow one).
#[test]
fn rigorous_spectral_program_is_the_kernel_with_the_grids_powers() {
    use crate::material::program::ProgramKind;
    use crate::optics::geometry::PairGeometry;
    use crate::program::ParamId;
    use crate::testing::programs::exported;
    let brdf = disc();
    for kind in ProgramKind::ALL {
        assert!(exported(brdf, kind).is_some(), "{kind:?}");
    }
    let program = exported(brdf, ProgramKind::EvalSpectral).unwrap();
    assert!(program.params.iter().all(|p| p.0 != ParamId::PeriodUm));
    let orders = disc_orders();
    let grid = orders.pair_grid().unwrap();
    let surface = super::PeriodicSurface::new(
        CD_PERIOD_UM,
        super::params::CD_COHERENCE_UM,
        disc_grating().profile,
    )
    .unwrap();
    let (mut worst, mut compared) = (0.0f64, 0);
    for (k, &(theta, phi, lambda, n)) in [
        (10.0, 20.0, 450.0, 1),
        (35.0, 100.0, 550.0, -2),
        (60.0, 200.0, 650.0, 3),
        (75.0, 300.0, 700.0, -1),
        (5.0, 45.0, 400.0, 0),
    ]
    .iter()
    .enumerate()
    {
        let wi = direction(theta, phi);
        for j in -20..=20 {
            let u_n = n as f64 * lambda * 1e-3 / CD_PERIOD_UM;
            let x = -wi.x - u_n + j as f64 * 4e-4;
            let y = -wi.y + (k as f64 - 2.0) * 3e-4;
            if x * x + y * y > 0.99 {
                continue;
            }
            let wo = DVec3::new(x, y, (1.0 - x * x - y * y).sqrt());
            let inputs = [wi.x, wi.y, wi.z, wo.x, wo.y, wo.z, lambda];
            let got = program.run(&inputs)[0];
            let geom = PairGeometry::new(wi, wo).unwrap();
            let (c, ky) = (0.5 * (wo.x - wi.x), 0.5 * (wi.y - wo.y));
            let power = |m: i64| {
                grid.read(m as f64, lambda, c, ky, |i: f64| {
                    grid.values[i as usize] as f64
                })
            };
            let want =
                surface.kernel_given(crate::spectrum::wavenumber_per_um(lambda), &geom, &power);
            if want > 1e-3 {
                compared += 1;
                worst = worst.max((got - want).abs() / want);
            }
        }
    }
    println!("rigorous EVAL_SPECTRAL against kernel_given on the grid: {compared} pairs, worst relative {worst:.2e}");
    assert!(compared > 100 && worst < 1e-6, "{compared} {worst}");
}

/// The rigorous disc's sampling programs: chi-square of the sampled
/// directions against the pdf program.
#[test]
fn chi2_rigorous_sampling_programs() {
    use crate::testing::chi2::chi2_fit;
    use crate::testing::programs::ProgramSampler;
    let brdf = Brdf::from_json(
        r#"{"surface":"cd","fresnel":"aluminium","orders":"rigorous","coherence_um":4}"#,
    )
    .unwrap();
    for (k, wi) in [DVec3::Z, direction(60.0, 40.0)].into_iter().enumerate() {
        let sampler = ProgramSampler::new(&brdf, wi, Some(550.0));
        let fit = chi2_fit(&sampler, 51 + k as u64, 100_000);
        println!(
            "chi2 rigorous program cos_i {:.2}: p = {:.4}, integral {:.5}",
            wi.z, fit.p_value, fit.integral
        );
        assert!(fit.integral <= 1.0 + 2e-3, "{}", fit.integral);
        let p = if fit.p_value > 0.01 {
            fit.p_value
        } else {
            chi2_fit(&sampler, 7_777_777 + k as u64, 400_000).p_value
        };
        assert!(p > 0.01, "cos_i {}: p = {p}", wi.z);
    }
}

/// The rigorous disc's EVAL_RGB program (f64) against the native RGB
/// integration of the same powers (the pair grid's), at pairs near orders
/// (within 2 sd of each order's peak): the program fits narrow peaks
/// through three wavelengths where the native rule takes midpoints, and
/// takes 32 nodes for broad ones where it takes 96; (worst, p90) of the
/// error relative to the pair's largest channel, and the pairs compared.
fn rigorous_rgb_program_errors(coherence_um: f64, seed: u64) -> (f64, f64, usize) {
    use crate::material::program::ProgramKind;
    use crate::optics::geometry::PairGeometry;
    use crate::sampling::SplitMix64;
    use crate::testing::programs::exported;
    let json = format!(
        r#"{{"surface":"cd","fresnel":"aluminium","orders":"rigorous","coherence_um":{coherence_um}}}"#
    );
    let brdf = Brdf::from_json(&json).unwrap();
    let program = exported(&brdf, ProgramKind::EvalRgb).unwrap();
    let orders = disc_orders();
    let grid = orders.pair_grid().unwrap();
    let surface =
        super::PeriodicSurface::new(CD_PERIOD_UM, coherence_um, disc_grating().profile).unwrap();
    let lambdas = super::PeriodicSurface::given_broad_wavelengths();
    let mut rng = SplitMix64(seed);
    let (mut errors, mut tries) = (Vec::new(), 0);
    while errors.len() < 300 && tries < 100_000 {
        tries += 1;
        let wi = direction(75.0 * rng.next_f64(), 360.0 * rng.next_f64());
        let lambda = 400.0 + 300.0 * rng.next_f64();
        let n = (rng.next_f64() * 9.0) as i64 - 4;
        let sd = 1.0
            / (std::f64::consts::SQRT_2
                * crate::spectrum::wavenumber_per_um(lambda)
                * coherence_um);
        let x = -wi.x - n as f64 * lambda * 1e-3 / CD_PERIOD_UM
            + 2.0 * sd * (2.0 * rng.next_f64() - 1.0);
        let y = -wi.y + 2.0 * sd * (2.0 * rng.next_f64() - 1.0);
        if x * x + y * y > 0.98 {
            continue;
        }
        let wo = DVec3::new(x, y, (1.0 - x * x - y * y).sqrt());
        let geom = PairGeometry::new(wi, wo).unwrap();
        let (c, ky) = (0.5 * (wo.x - wi.x), 0.5 * (wi.y - wo.y));
        let read =
            |m: i64, l: f64| grid.read(m as f64, l, c, ky, |i: f64| grid.values[i as usize] as f64);
        let want = crate::spectrum::gamut_map(given_rgb(&surface, &geom, &read, &|m, j| {
            read(m, lambdas[j])
        }));
        let got = program.run(&[wi.x, wi.y, wi.z, wo.x, wo.y, wo.z]);
        let peak = want.iter().cloned().fold(0.0, f64::max);
        if peak > 1e-2 {
            let e = (0..3)
                .map(|ch| (got[ch] - want[ch]).abs())
                .fold(0.0, f64::max)
                / peak;
            errors.push(e);
        }
    }
    errors.sort_by(f64::total_cmp);
    let p90 = errors[errors.len() * 9 / 10];
    (*errors.last().unwrap(), p90, errors.len())
}

/// Measured (docs/rigorous.md): worst 2.3e-2 and p90 2.9e-3 at 50 um,
/// worst 0.157 and p90 0.022 at 8 um (the three-wavelength fit misses an
/// efficiency's kinks inside peaks a few nm wide; the native rule takes
/// midpoints there).
#[test]
fn rigorous_rgb_program_is_the_native_rule_within_its_fit() {
    for (l, max_limit, p90_limit) in [(50.0, 0.035, 5e-3), (8.0, 0.2, 0.03)] {
        let (max, p90, n) = rigorous_rgb_program_errors(l, 11);
        println!("rigorous EVAL_RGB program against the native rule on the grid, coherence {l} um: {n} pairs, worst {max:.2e}, p90 {p90:.2e} of the largest channel");
        assert!(
            n > 200 && max < max_limit && p90 < p90_limit,
            "{l}: {max} {p90}"
        );
    }
}

/// The rigorous disc's RGB sampling programs: chi-square against the pdf
/// program.
#[test]
fn chi2_rigorous_rgb_sampling_programs() {
    use crate::testing::chi2::chi2_fit;
    use crate::testing::programs::ProgramSampler;
    let brdf = Brdf::from_json(
        r#"{"surface":"cd","fresnel":"aluminium","orders":"rigorous","coherence_um":4}"#,
    )
    .unwrap();
    let wi = direction(45.0, 70.0);
    let sampler = ProgramSampler::new(&brdf, wi, None);
    let fit = chi2_fit(&sampler, 77, 100_000);
    println!(
        "chi2 rigorous RGB program: p = {:.4}, integral {:.5}",
        fit.p_value, fit.integral
    );
    assert!(fit.integral <= 1.0 + 2e-3, "{}", fit.integral);
    let p = if fit.p_value > 0.01 {
        fit.p_value
    } else {
        chi2_fit(&sampler, 7_777_778, 400_000).p_value
    };
    assert!(p > 0.01, "p = {p}");
}

/// A covered disc's programs (`cover_eta` 1.58): the coherent programs
/// give the cover's reflectance and probability as natively (1e-6), f at
/// pairs near orders sums as the native f (through the cover both ways;
/// the grid's error aside: 3%), and sampling draws the mirror lobe with the
/// cover's reflectance (chi-square of the glossy part, spectral and RGB).
#[test]
fn covered_rigorous_programs() {
    use crate::material::program::ProgramKind;
    use crate::testing::chi2::chi2_fit;
    use crate::testing::programs::{exported, ProgramSampler};
    use crate::Brdf;
    let brdf = Brdf::from_json(
        r#"{"surface":"cd","fresnel":"aluminium","orders":"rigorous","cover_eta":1.58,"coherence_um":4}"#,
    )
    .unwrap();
    let coherent = exported(&brdf, ProgramKind::CoherentSpectral).unwrap();
    let coherent_rgb = exported(&brdf, ProgramKind::CoherentRgb).unwrap();
    for theta in [0.0, 30.0, 60.0, 80.0] {
        let wi = direction(theta, 25.0);
        let want = brdf.coherent_spectral(wi, 550.0);
        let out = coherent.run(&[wi.x, wi.y, wi.z, 550.0]);
        assert!(
            want > 0.03 && (out[0] - want).abs() < 1e-6 * want.max(1.0),
            "{theta}: {out:?} {want}"
        );
        assert!((out[1] - want).abs() < 1e-6, "{theta}: {out:?}");
        let rgb = coherent_rgb.run(&[wi.x, wi.y, wi.z]);
        let want_rgb = brdf.coherent_rgb(wi);
        assert!(
            (0..3).all(|c| (rgb[c] - want_rgb[c]).abs() < 1e-6),
            "{rgb:?} {want_rgb:?}"
        );
    }
    let eval = exported(&brdf, ProgramKind::EvalSpectral).unwrap();
    let (mut got, mut want) = (0.0, 0.0);
    for (k, &(theta, phi, lambda, n)) in [
        (10.0, 20.0, 450.0, 1),
        (35.0, 100.0, 550.0, -2),
        (50.0, 200.0, 650.0, 2),
    ]
    .iter()
    .enumerate()
    {
        let wi = direction(theta, phi);
        for j in -20..=20 {
            let x = -wi.x - n as f64 * lambda * 1e-3 / CD_PERIOD_UM + j as f64 * 2e-3;
            let y = -wi.y + (k as f64 - 1.0) * 1e-3;
            let wo = DVec3::new(x, y, (1.0 - x * x - y * y).sqrt());
            got += eval.run(&[wi.x, wi.y, wi.z, wo.x, wo.y, wo.z, lambda])[0];
            want += brdf.eval_spectral(wi, wo, lambda);
        }
    }
    println!("covered disc: EVAL_SPECTRAL program sum {got:.6e}, native {want:.6e}");
    assert!(
        want > 0.0 && (got / want - 1.0).abs() < 0.03,
        "{got} {want}"
    );
    for (k, mode) in [Some(550.0), None].into_iter().enumerate() {
        let sampler = ProgramSampler::new(&brdf, direction(40.0, 60.0), mode);
        let fit = chi2_fit(&sampler, 91 + k as u64, 100_000);
        println!(
            "chi2 covered rigorous program {mode:?}: p = {:.4}, integral {:.5}",
            fit.p_value, fit.integral
        );
        let p = if fit.p_value > 0.01 {
            fit.p_value
        } else {
            chi2_fit(&sampler, 7_777_779 + k as u64, 400_000).p_value
        };
        assert!(p > 0.01, "{mode:?}: p = {p}");
    }
}

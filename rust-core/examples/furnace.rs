//! White furnace: the directional albedo (mean sample weight f cos / pdf of
//! the material's own strategy, fresnel = 1) of every test material at a
//! set of incidence cosines, for the energy-conserving material (the
//! default) and Stam's formula, spectrally (the largest of 400, 550, 700 nm) and in
//! RGB (luminance, and the largest channel); and per material the energy
//! table's build time, the largest change of f at moderate angles and the
//! smallest factor.
//!
//! cargo run --release -p stam-core --example furnace [samples] [json-out]

use glam::DVec3;
use stam::benchmark::SplitMix64;
use stam::Brdf;

const MATERIALS: [(&str, &str); 7] = [
    ("cd (defaults)", r#"{"surface":"cd"}"#),
    (
        "sine grating (period 1.2, height 0.12, coherence 20 um)",
        r#"{"surface":"periodic","period_um":1.2,"coherence_um":20,"profile":"sine","height_um":0.12}"#,
    ),
    (
        "gaussian sigma 0.3, T 2 um",
        r#"{"surface":"gaussian","sigma_um":0.3,"corr_um":2}"#,
    ),
    (
        "gaussian sigma 0.08, T 1.5 um",
        r#"{"surface":"gaussian","sigma_um":0.08,"corr_um":1.5}"#,
    ),
    (
        "gaussian sigma 0.1, Tx 4, Ty 0.8 um",
        r#"{"surface":"gaussian","sigma_um":0.1,"corr_x_um":4,"corr_y_um":0.8}"#,
    ),
    (
        "fractal H 0.7, sigma 0.1, L 2 um",
        r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.1,"lag_um":2}"#,
    ),
    (
        "fractal H 0.4, sigma 0.3, L 1 um",
        r#"{"surface":"fractal","hurst":0.4,"sigma_um":0.3,"lag_um":1}"#,
    ),
];

const COSINES: [f64; 6] = [0.95, 0.7, 0.4, 0.2, 0.08, 0.02];

/// How a sample's value becomes one number.
#[derive(Clone, Copy)]
enum Channel {
    Spectral(f64),
    Luminance,
    Largest,
}

fn reduce(rgb: [f64; 3], channel: Channel) -> f64 {
    match channel {
        Channel::Luminance => stam::spectrum::SRGB_LUMINANCE
            .iter()
            .zip(rgb)
            .map(|(w, c)| w * c)
            .sum(),
        _ => rgb.iter().cloned().fold(0.0, f64::max),
    }
}

fn albedo(brdf: &Brdf, cos_i: f64, channel: Channel, n: usize) -> (f64, f64) {
    let lambda = match channel {
        Channel::Spectral(l) => Some(l),
        _ => None,
    };
    let wi = DVec3::new(
        (1.0 - cos_i * cos_i).sqrt() * 0.8,
        (1.0 - cos_i * cos_i).sqrt() * 0.6,
        cos_i,
    );
    let strategy = brdf.sampler(wi, lambda);
    let mut rng = SplitMix64(17);
    let (mut sum, mut sum2) = (0.0, 0.0);
    for _ in 0..n {
        let s = strategy.sample(rng.three());
        let w = if s.pdf.is_nan() || s.pdf <= 0.0 {
            0.0
        } else if s.coherent {
            match lambda {
                Some(l) => brdf.coherent_spectral(wi, l) / s.pdf,
                None => reduce(brdf.coherent_rgb(wi), channel) / s.pdf,
            }
        } else {
            let f = match lambda {
                Some(l) => brdf.eval_spectral(wi, s.wo, l),
                None => reduce(brdf.eval_rgb(wi, s.wo), channel),
            };
            f * s.wo.z / s.pdf
        };
        sum += w;
        sum2 += w * w;
    }
    let mean = sum / n as f64;
    let var = (sum2 / n as f64 - mean * mean).max(0.0);
    (mean, (var / n as f64).sqrt())
}

/// The largest relative change of f (spectral, at random wavelengths; RGB,
/// of the luminance) between the default and Stam's formula over random
/// pairs with both cosines at least 0.5.
fn moderate_change(conserving: &Brdf, stam: &Brdf) -> (f64, f64) {
    let mut rng = SplitMix64(5);
    let direction = |rng: &mut SplitMix64| {
        let c = 0.5 + 0.5 * rng.next_f64();
        let phi = 2.0 * std::f64::consts::PI * rng.next_f64();
        let s = (1.0 - c * c).sqrt();
        DVec3::new(s * phi.cos(), s * phi.sin(), c)
    };
    let luminance = |c: [f64; 3]| -> f64 {
        stam::spectrum::SRGB_LUMINANCE
            .iter()
            .zip(c)
            .map(|(w, x)| w * x)
            .sum()
    };
    let (mut spectral, mut rgb): (f64, f64) = (0.0, 0.0);
    for _ in 0..20_000 {
        let wi = direction(&mut rng);
        let wo = direction(&mut rng);
        let lambda = 360.0 + 470.0 * rng.next_f64();
        let (a, b) = (
            conserving.eval_spectral(wi, wo, lambda),
            stam.eval_spectral(wi, wo, lambda),
        );
        if b > 1e-12 {
            spectral = spectral.max((a / b - 1.0).abs());
        }
        let (a, b) = (
            luminance(conserving.eval_rgb(wi, wo)),
            luminance(stam.eval_rgb(wi, wo)),
        );
        if b > 1e-12 {
            rgb = rgb.max((a / b - 1.0).abs());
        }
    }
    (spectral, rgb)
}

/// The material's JSON with more fields (`extra`: `"key":value` pairs).
fn with_fields(json: &str, extra: &str) -> String {
    format!("{},{extra}}}", &json[..json.len() - 1])
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(200_000);
    let mut rows = Vec::new();
    println!("| material | table built in | largest change of f where cos_i, cos_o >= 0.5 (table bound; sampled spectral / RGB luminance) | smallest factor m(wi) m(wo) |");
    println!("|---|---|---|---|");
    for (name, json) in MATERIALS {
        let brdf =
            Brdf::from_json(&with_fields(json, r#""energy":"conserving""#)).expect("material");
        let t = std::time::Instant::now();
        let table = brdf
            .energy_table()
            .expect("a conserving material has a table");
        let built = t.elapsed().as_secs_f64();
        let stam = Brdf::from_json(&with_fields(json, r#""energy":"stam""#)).expect("material");
        let (spectral, rgb) = moderate_change(&brdf, &stam);
        let bound = 1.0 - table.min_factor_within(0.5).powi(2);
        println!(
            "| {name} | {built:.2} s | {:.2}% ({:.2}% / {:.2}%) | {:.3} |",
            100.0 * bound,
            100.0 * spectral,
            100.0 * rgb,
            table.min_factor().powi(2)
        );
    }
    for mode in ["conserving", "stam"] {
        for (label, channels) in [
            (
                "spectral, largest of 400, 550, 700 nm",
                vec![
                    Channel::Spectral(400.0),
                    Channel::Spectral(550.0),
                    Channel::Spectral(700.0),
                ],
            ),
            ("RGB luminance", vec![Channel::Luminance]),
            ("RGB largest channel", vec![Channel::Largest]),
        ] {
            let channel = label;
            println!("\n{mode}, {label}: directional albedo (fresnel = 1, {n} samples)\n");
            println!(
                "| material | {} |",
                COSINES.map(|c| format!("cos_i {c}")).join(" | ")
            );
            println!("|---|{}", "---|".repeat(COSINES.len()));
            for (name, json) in MATERIALS {
                let json = with_fields(json, &format!(r#""fresnel":1,"energy":"{mode}""#));
                let brdf = Brdf::from_json(&json).expect("material");
                let mut cells = Vec::new();
                for &c in &COSINES {
                    let (a, se) = channels.iter().map(|&ch| albedo(&brdf, c, ch, n)).fold(
                        (f64::MIN, 0.0),
                        |best, x| if x.0 > best.0 { x } else { best },
                    );
                    cells.push(format!("{a:.3} ± {se:.3}"));
                    rows.push(format!(
                        r#"{{"mode":"{mode}","channel":"{channel}","material":"{name}","cos_i":{c},"albedo":{a},"se":{se}}}"#
                    ));
                }
                println!("| {name} | {} |", cells.join(" | "));
            }
        }
    }
    if let Some(path) = args.get(2) {
        std::fs::write(path, format!("[{}]\n", rows.join(",\n"))).expect("write");
        println!("\nwrote {path}");
    }
}

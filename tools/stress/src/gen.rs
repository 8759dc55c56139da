//! Deterministic random generators: materials spanning the accepted
//! parameter ranges (their ends included), directions from the ordinary to
//! the hostile, wavelengths in and out of the band.

use glam::DVec3;
use std::f64::consts::PI;

/// SplitMix64: small, fast, good enough for test inputs, reproducible.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed ^ 0x9E37_79B9_7F4A_7C15)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Log-uniform in [lo, hi] (both > 0).
    pub fn log_range(&mut self, lo: f64, hi: f64) -> f64 {
        (lo.ln() + (hi.ln() - lo.ln()) * self.uniform()).exp()
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.uniform() * n as f64) as usize % n.max(1)
    }

    pub fn chance(&mut self, p: f64) -> bool {
        self.uniform() < p
    }

    pub fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[self.below(items.len())]
    }
}

/// Hurst exponents used for random fractal materials. Each distinct alpha
/// builds a Phi_alpha table (tens of ms); the core caches 16 of them, so
/// random hurst values are quantised to this set (which includes the ends
/// of the accepted range, near 0 and 1).
pub const HURST_SET: [f64; 10] = [1e-3, 0.01, 0.1, 0.25, 0.5, 0.7, 0.85, 0.97, 0.999, 1.0];

/// Surface kinds a material generator can produce (height maps last, so
/// that kinds 0..7 keep their surfaces).
pub const SURFACES: [&str; 8] = [
    "gaussian",
    "anisotropic",
    "fractal",
    "rect",
    "sine",
    "tabulated",
    "cd",
    "heightmap",
];

/// The hostile height maps the generator's height-map materials read,
/// written once per process as .npy files: flat (a mirror), a single
/// spike, heights of hundreds of micrometres, white noise, a sine with
/// a cusp, a 16 x 256 strip; heights in um.
pub fn height_maps() -> &'static [String] {
    static MAPS: std::sync::OnceLock<Vec<String>> = std::sync::OnceLock::new();
    MAPS.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("stam-stress-maps-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("a folder for the stress maps");
        let mut rng = Rng::new(99);
        let mut maps: Vec<(&str, usize, usize, Vec<f64>)> = vec![
            ("flat", 16, 16, vec![0.0; 256]),
            (
                "spike",
                32,
                32,
                (0..1024)
                    .map(|i| if i == 300 { 5.0 } else { 0.0 })
                    .collect(),
            ),
            (
                "huge",
                64,
                64,
                (0..4096).map(|_| rng.range(-300.0, 300.0)).collect(),
            ),
            (
                "noise",
                64,
                64,
                (0..4096).map(|_| rng.range(-0.05, 0.05)).collect(),
            ),
        ];
        let cusp = (0..64 * 64)
            .map(|i| ((i % 64) as f64 * 0.3).sin().abs() * 0.2)
            .collect();
        maps.push(("cusp", 64, 64, cusp));
        let strip = (0..16 * 256).map(|_| rng.range(0.0, 0.02)).collect();
        maps.push(("strip", 256, 16, strip));
        maps.into_iter()
            .map(|(name, nx, ny, h)| {
                let path = dir.join(format!("{name}.npy"));
                std::fs::write(&path, stam::benchmark::npy_bytes(nx, ny, &h))
                    .expect("a stress map");
                path.to_string_lossy().into_owned()
            })
            .collect()
    })
}

fn fresnel(rng: &mut Rng) -> Option<String> {
    Some(match rng.below(9) {
        0 => return None, // default (aluminium)
        1 => format!("{}", rng.log_range(1e-6, 1.0)),
        2 => "1".to_string(),
        3 => format!(
            "{{\"eta\":{},\"k\":{}}}",
            rng.log_range(1e-3, 100.0),
            if rng.chance(0.3) {
                0.0
            } else {
                rng.log_range(1e-3, 100.0)
            }
        ),
        4 => "\"silver\"".into(),
        5 => "\"gold\"".into(),
        6 => "\"copper\"".into(),
        7 => "\"chromium\"".into(),
        _ => "\"aluminium\"".into(),
    })
}

/// sigma in um: log-uniform over 1e-5..50 um, sometimes the accepted ends.
fn sigma(rng: &mut Rng) -> f64 {
    match rng.below(20) {
        0 => 1e-6,
        1 => 100.0,
        _ => rng.log_range(1e-5, 50.0),
    }
}

/// Correlation (or lag) length in um: 0.01..1e4 um, sometimes the ends.
fn length(rng: &mut Rng) -> f64 {
    match rng.below(20) {
        0 => 1e-3,
        1 => 1e5,
        _ => rng.log_range(0.01, 1e4),
    }
}

/// A random material description (JSON) of the given kind (an index into
/// [`SURFACES`]), valid by construction (within the documented ranges).
pub fn material(rng: &mut Rng, kind: usize) -> String {
    let mut fields: Vec<String> = Vec::new();
    match SURFACES[kind % SURFACES.len()] {
        "gaussian" => {
            fields.push("\"surface\":\"gaussian\"".into());
            fields.push(format!("\"sigma_um\":{}", sigma(rng)));
            fields.push(format!("\"corr_um\":{}", length(rng)));
        }
        "anisotropic" => {
            fields.push("\"surface\":\"gaussian\"".into());
            fields.push(format!("\"sigma_um\":{}", sigma(rng)));
            fields.push(format!("\"corr_x_um\":{}", length(rng)));
            fields.push(format!("\"corr_y_um\":{}", length(rng)));
        }
        "fractal" => {
            fields.push("\"surface\":\"fractal\"".into());
            fields.push(format!("\"hurst\":{}", rng.pick(&HURST_SET)));
            fields.push(format!("\"sigma_um\":{}", sigma(rng)));
            fields.push(format!("\"lag_um\":{}", length(rng)));
        }
        kind @ ("rect" | "sine" | "tabulated") => {
            let period = rng.log_range(0.3, 100.0);
            let coherence = match rng.below(10) {
                0 => 1.5 * period,
                1 => 5000.0,
                _ => rng.log_range(1.5 * period, 5000.0),
            };
            fields.push("\"surface\":\"periodic\"".into());
            fields.push(format!("\"period_um\":{period}"));
            fields.push(format!("\"coherence_um\":{coherence}"));
            let height = rng.log_range(1e-4, 3.0);
            match kind {
                "rect" => {
                    fields.push("\"profile\":\"rect\"".into());
                    fields.push(format!("\"height_um\":{height}"));
                    let width = if rng.chance(0.1) {
                        period
                    } else {
                        period * rng.log_range(1e-3, 1.0)
                    };
                    fields.push(format!("\"width_um\":{width}"));
                }
                "sine" => {
                    fields.push("\"profile\":\"sine\"".into());
                    fields.push(format!("\"height_um\":{height}"));
                }
                _ => {
                    let n = if rng.chance(0.1) {
                        rng.range(64.0, 1024.0) as usize
                    } else {
                        rng.range(2.0, 33.0) as usize
                    };
                    let hs: Vec<String> = (0..n)
                        .map(|_| format!("{}", height * rng.range(-1.0, 1.0)))
                        .collect();
                    fields.push(format!("\"profile\":{{\"heights_um\":[{}]}}", hs.join(",")));
                }
            }
        }
        "heightmap" => {
            let maps = height_maps();
            let file = serde_json::Value::String(maps[rng.below(maps.len())].clone());
            fields.push("\"surface\":\"heightmap\"".into());
            fields.push(format!("\"file\":{file}"));
            fields.push(format!("\"pixel_um\":{}", rng.log_range(1e-3, 10.0)));
            if rng.chance(0.3) {
                fields.push(format!("\"height_scale_um\":{}", rng.log_range(1e-3, 1e3)));
            }
            if rng.chance(0.2) {
                fields.push("\"tile_px\":16".into());
            }
        }
        _ => {
            fields.push("\"surface\":\"cd\"".into());
            if rng.chance(0.5) {
                let period: f64 = rng.log_range(0.3, 100.0);
                fields.push(format!("\"period_um\":{period}"));
                fields.push(format!(
                    "\"coherence_um\":{}",
                    rng.log_range(1.5 * period, 5000.0)
                ));
                fields.push(format!(
                    "\"width_um\":{}",
                    period * rng.log_range(1e-3, 1.0)
                ));
            }
        }
    }
    if let Some(f) = fresnel(rng) {
        fields.push(format!("\"fresnel\":{f}"));
    }
    // The accuracy knobs of the surfaces that read them (Gaussian: both;
    // fractal: the RGB rule); the others refuse them by name.
    let surface = SURFACES[kind % SURFACES.len()];
    if rng.chance(0.2) && matches!(surface, "gaussian" | "anisotropic") {
        fields.push(format!(
            "\"series_tolerance\":{}",
            rng.log_range(1e-12, 0.1)
        ));
    }
    // The default, energy-conserving material (a table built on the first
    // evaluation) for a tenth of the materials; Stam's formula for the rest
    // (a table per random material would make the runs several times
    // longer).
    if !rng.chance(0.1) {
        fields.push("\"energy\":\"stam\"".to_string());
    }
    if rng.chance(0.2)
        && matches!(
            surface,
            "gaussian" | "anisotropic" | "fractal" | "heightmap"
        )
    {
        fields.push(format!("\"rgb_nodes\":{}", rng.range(4.0, 65.0) as usize));
    }
    // Every third round's disc has rigorous orders instead: the paper's
    // disc in aluminium or gold at three coherence lengths (two tables,
    // each built once per process and kept on disk), chosen by `kind` and
    // made after the random draws, so that the stream of the other
    // materials is unchanged.
    if surface == "cd" && kind / SURFACES.len() % 3 == 1 {
        let round = kind / SURFACES.len() / 3;
        return format!(
            "{{\"surface\":\"cd\",\"orders\":\"rigorous\",\"coherence_um\":{},\"fresnel\":\"{}\"}}",
            [5.0, 50.0, 500.0][round % 3],
            ["aluminium", "gold"][round % 2]
        );
    }
    format!("{{{}}}", fields.join(","))
}

fn unit(theta_cos: f64, phi: f64) -> DVec3 {
    let s = (1.0 - theta_cos * theta_cos).max(0.0).sqrt();
    DVec3::new(s * phi.cos(), s * phi.sin(), theta_cos)
}

/// A random direction: mostly above the horizon, also grazing (cos down to
/// 1e-8 and exactly 0), below the horizon, NaN and infinite components, zero
/// and non-unit lengths.
pub fn direction(rng: &mut Rng) -> DVec3 {
    let phi = rng.range(0.0, 2.0 * PI);
    match rng.below(40) {
        0..=17 => unit(rng.uniform(), phi),
        18..=23 => unit(rng.log_range(1e-8, 1e-2), phi),
        24..=26 => unit(-rng.uniform(), phi),
        27 => unit(0.0, phi),
        28 => unit(1.0, 0.0),
        29 => unit(-rng.log_range(1e-8, 1e-2), phi),
        30 => DVec3::new(f64::NAN, 0.0, 1.0),
        31 => DVec3::new(0.0, 0.0, f64::NAN),
        32 => DVec3::new(f64::INFINITY, 0.0, 1.0),
        33 => DVec3::new(0.0, 0.0, f64::INFINITY),
        34 => DVec3::ZERO,
        35 => DVec3::new(1e-30, 0.0, 1e-30),
        _ => unit(rng.uniform(), phi) * rng.log_range(1e-3, 1e3),
    }
}

/// A direction for wo given wi: near the mirror direction of wi at a random
/// angular scale (the narrow lobes of smooth, long-correlation or highly
/// coherent surfaces live within 1e-5 of it), or independent.
pub fn direction_near_mirror(rng: &mut Rng, wi: DVec3) -> DVec3 {
    if !wi.is_finite() || rng.chance(0.5) {
        return direction(rng);
    }
    let m = DVec3::new(-wi.x, -wi.y, wi.z);
    if rng.chance(0.05) {
        return m;
    }
    let scale = 10f64.powf(-rng.range(0.0, 7.0)) * m.length().max(1e-30);
    let jitter = DVec3::new(
        rng.range(-1.0, 1.0),
        rng.range(-1.0, 1.0),
        rng.range(-1.0, 1.0),
    );
    m + scale * jitter
}

/// A random wavelength in nm: mostly in the visible band, also its ends, 0,
/// negative, out of range, NaN, infinite and subnormal.
pub fn wavelength(rng: &mut Rng) -> f64 {
    match rng.below(30) {
        0..=19 => rng.range(360.0, 830.0),
        20 => 360.0,
        21 => 830.0,
        22 => 0.0,
        23 => -rng.log_range(1e-3, 1e3),
        24 => rng.range(0.0, 360.0),
        25 => rng.log_range(830.0, 1e30),
        26 => f64::NAN,
        27 => f64::INFINITY,
        28 => f64::NEG_INFINITY,
        _ => 1e-40,
    }
}

/// Three "uniform" random numbers for sampling: in [0, 1) as the header
/// asks, with the ends and (rarely) out-of-contract values: 1, NaN, negative.
pub fn uniforms(rng: &mut Rng) -> [f64; 3] {
    let mut r = [0.0; 3];
    for x in &mut r {
        *x = match rng.below(100) {
            0 => 0.0,
            1 => 1.0 - f32::EPSILON as f64 / 2.0,
            2 => 1.0,
            3 => f64::NAN,
            4 => -0.25,
            5 => rng.log_range(1e-30, 1e-3),
            _ => rng.uniform(),
        };
    }
    r
}

//! Run time against error: the accuracy knobs of the core, one
//! configuration per knob value, and the error of each against the
//! exhaustive f64 reference.
//!
//! Reference ("exhaustive f64"): the spectral path with the Gaussian series
//! summed exactly (no table, no saddle or asymptotic forms) to a relative
//! tolerance of 1e-13, integrated against the sRGB weights on a 1 nm grid
//! (`Brdf::eval_rgb_reference`); for periodic surfaces, whose diffraction
//! peaks are narrower than 1 nm, on a 0.01 nm grid. Spectral configurations
//! are compared with the exact spectral value at the same wavelength.
//!
//! Error of a configuration: over a fixed set of 256 direction pairs (half
//! around the specular lobe, half uniform, the set `benches/brdf.rs` times),
//! max and mean of |value - reference| / (the reference's largest RGB
//! channel) for RGB, |value - reference| / reference for spectral; pairs
//! whose reference is below 1e-10 of the set's largest are skipped.
//!
//! The `pareto` binary writes the errors (target/pareto/errors.json), the
//! `pareto` criterion bench times the same configurations beside the
//! Cook-Torrance baseline, scripts/plot_pareto.py joins them.

use crate::materials::Material;
use glam::DVec3;
use stam::gaussian::SeriesSettings;
use stam::Brdf;

/// Direction pairs of the survey (timing and error).
pub const PAIRS: usize = 256;
/// Reference wavelength step for spectrally smooth models (nm).
pub const REFERENCE_STEP_NM: f64 = 1.0;
/// Reference wavelength step for periodic surfaces (nm).
pub const PERIODIC_REFERENCE_STEP_NM: f64 = 0.01;
/// Tolerance of the reference series (below the JSON range's 1e-12).
pub const REFERENCE_SERIES_TOLERANCE: f64 = 1e-13;

/// The materials surveyed: those tagged `pareto` in tests/materials.json, in
/// file order, shown by their labels (the first six are those of
/// rust-core/benches/brdf.rs).
pub fn materials() -> Vec<&'static Material> {
    crate::materials::tagged("pareto")
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Mode {
    /// `eval_spectral` at the pair's wavelength.
    Spectral,
    /// `eval_rgb` (the core's RGB path).
    Rgb,
    /// Uniform wavelength sampling of the spectral path at this step (nm),
    /// the naive alternative to the core's RGB rules.
    RgbSampled(f64),
}

#[derive(Clone, Debug)]
pub struct Config {
    pub model: &'static str,
    pub material: &'static str,
    pub json: String,
    /// The knob and its value, human-readable.
    pub knob: String,
    pub mode: Mode,
    /// The configuration a material gets by default (per mode).
    pub is_default: bool,
    /// Override of the Gaussian series settings (None: from the JSON).
    pub series: Option<SeriesSettings>,
}

impl Config {
    pub fn mode_name(&self) -> &'static str {
        match self.mode {
            Mode::Spectral => "spectral",
            _ => "rgb",
        }
    }

    pub fn build(&self) -> Brdf {
        let brdf = Brdf::from_json(&self.json).expect("survey material");
        match self.series {
            Some(series) => brdf.with_series(series),
            None => brdf,
        }
    }

    /// The configuration's value at a pair: spectral f in channel 0, or RGB.
    #[inline]
    pub fn eval(&self, brdf: &Brdf, wi: DVec3, wo: DVec3, lambda: f64) -> [f64; 3] {
        match self.mode {
            Mode::Spectral => [brdf.eval_spectral(wi, wo, lambda), 0.0, 0.0],
            Mode::Rgb => brdf.eval_rgb(wi, wo),
            Mode::RgbSampled(step) => brdf.eval_rgb_reference(wi, wo, step),
        }
    }
}

/// Exact series settings: no table, no saddle, no asymptotic form.
pub fn exact_series(tolerance: f64) -> SeriesSettings {
    SeriesSettings {
        tolerance,
        asymptotic_min_g: f64::INFINITY,
        use_table: false,
    }
}

fn with_nodes(json: &str, nodes: usize) -> String {
    format!("{},\"rgb_nodes\":{nodes}}}", &json[..json.len() - 1])
}

/// Every configuration of the survey, in a fixed order (the criterion bench
/// names them c000, c001, ... by this order).
pub fn configs() -> Vec<Config> {
    let mut out = Vec::new();
    let default_nodes = stam::params::DEFAULT_RGB_NODES;
    let default_tol = stam::gaussian::DEFAULT_SERIES_TOLERANCE;
    for m in materials() {
        let (model, material, json) = (m.model.as_str(), m.label.as_str(), m.params.as_str());
        let mut push = |knob: String, mode: Mode, is_default: bool, json: String, series| {
            out.push(Config {
                model,
                material,
                json,
                knob,
                mode,
                is_default,
                series,
            })
        };
        let j = json.to_string();
        match model {
            "gaussian" => {
                push(
                    format!("series: table/saddle/asymptotic forms, tol {default_tol:e}"),
                    Mode::Spectral,
                    true,
                    j.clone(),
                    None,
                );
                for tol in [1e-3, 1e-1] {
                    push(
                        format!("series: table/saddle/asymptotic forms, tol {tol:e}"),
                        Mode::Spectral,
                        false,
                        j.clone(),
                        Some(SeriesSettings::with_tolerance(tol)),
                    );
                }
                push(
                    "series: table/saddle forms, no asymptotic, tol 1e-5".into(),
                    Mode::Spectral,
                    false,
                    j.clone(),
                    Some(SeriesSettings {
                        asymptotic_min_g: f64::INFINITY,
                        ..SeriesSettings::with_tolerance(1e-5)
                    }),
                );
                push(
                    "series: exact + asymptotic (g >= 30), tol 1e-5".into(),
                    Mode::Spectral,
                    false,
                    j.clone(),
                    Some(SeriesSettings {
                        use_table: false,
                        ..SeriesSettings::with_tolerance(1e-5)
                    }),
                );
                for tol in [1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-7, 1e-9, 1e-12] {
                    push(
                        format!("series: exact only, tol {tol:e}"),
                        Mode::Spectral,
                        false,
                        j.clone(),
                        Some(exact_series(tol)),
                    );
                }
                for nodes in [4, 6, 8, 10, 12, 16, 20, 24, 32] {
                    push(
                        format!("rgb_nodes {nodes}"),
                        Mode::Rgb,
                        nodes == default_nodes,
                        with_nodes(json, nodes),
                        None,
                    );
                }
                push(
                    format!("rgb_nodes {default_nodes}, series exact tol 1e-12"),
                    Mode::Rgb,
                    false,
                    j.clone(),
                    Some(exact_series(1e-12)),
                );
                for step in [10.0, 5.0] {
                    push(
                        format!("uniform {step} nm sampling"),
                        Mode::RgbSampled(step),
                        false,
                        j.clone(),
                        None,
                    );
                }
            }
            "fractal" => {
                for nodes in [4, 6, 8, 10, 12, 16, 20, 24, 32] {
                    push(
                        format!("rgb_nodes {nodes}"),
                        Mode::Rgb,
                        nodes == stam::params::DEFAULT_RGB_NODES_FRACTAL,
                        with_nodes(json, nodes),
                        None,
                    );
                }
                for step in [10.0, 5.0] {
                    push(
                        format!("uniform {step} nm sampling"),
                        Mode::RgbSampled(step),
                        false,
                        j.clone(),
                        None,
                    );
                }
            }
            _ => {
                push(
                    "per-order analytic integration".into(),
                    Mode::Rgb,
                    true,
                    j.clone(),
                    None,
                );
                for step in [10.0, 5.0, 2.0, 1.0, 0.5] {
                    push(
                        format!("uniform {step} nm sampling"),
                        Mode::RgbSampled(step),
                        false,
                        j.clone(),
                        None,
                    );
                }
            }
        }
    }
    out
}

/// Deterministic direction pairs and wavelengths: those of benches/brdf.rs.
pub fn directions() -> Vec<(DVec3, DVec3, f64)> {
    stam::benchmark::direction_pairs(7, PAIRS)
}

pub use stam::benchmark::cook_torrance_beckmann;

/// The reference material of a survey material: exact series at 1e-13.
pub fn reference_brdf(json: &str) -> Brdf {
    Brdf::from_json(json)
        .expect("survey material")
        .with_series(exact_series(REFERENCE_SERIES_TOLERANCE))
}

/// Reference values of one material at the survey's pairs: (spectral, RGB).
pub struct Reference {
    pub spectral: Vec<f64>,
    pub rgb: Vec<[f64; 3]>,
}

pub fn reference(model: &str, json: &str, pairs: &[(DVec3, DVec3, f64)]) -> Reference {
    let brdf = reference_brdf(json);
    let step = if model == "periodic" {
        PERIODIC_REFERENCE_STEP_NM
    } else {
        REFERENCE_STEP_NM
    };
    Reference {
        spectral: pairs
            .iter()
            .map(|&(wi, wo, l)| brdf.eval_spectral(wi, wo, l))
            .collect(),
        // The core maps out-of-gamut colours into the gamut at constant
        // luminance (stam::spectrum::gamut_map); so does the reference.
        rgb: pairs
            .iter()
            .map(|&(wi, wo, _)| stam::spectrum::gamut_map(brdf.eval_rgb_reference(wi, wo, step)))
            .collect(),
    }
}

/// (max, mean) error of a configuration against the reference.
pub fn error(config: &Config, pairs: &[(DVec3, DVec3, f64)], reference: &Reference) -> (f64, f64) {
    let brdf = config.build();
    let spectral = config.mode == Mode::Spectral;
    let scale = |i: usize| -> f64 {
        if spectral {
            reference.spectral[i]
        } else {
            reference.rgb[i].iter().cloned().fold(0.0, f64::max)
        }
    };
    let top = (0..pairs.len()).map(scale).fold(0.0, f64::max);
    let mut worst: f64 = 0.0;
    let mut sum = 0.0;
    let mut n = 0usize;
    for (i, &(wi, wo, l)) in pairs.iter().enumerate() {
        let s = scale(i);
        if !(s > 1e-10 * top) {
            continue;
        }
        let v = config.eval(&brdf, wi, wo, l);
        let e = if spectral {
            (v[0] - reference.spectral[i]).abs() / s
        } else {
            let v = stam::spectrum::gamut_map(v);
            (0..3)
                .map(|c| (v[c] - reference.rgb[i][c]).abs() / s)
                .fold(0.0, f64::max)
        };
        worst = worst.max(e);
        sum += e;
        n += 1;
    }
    (worst, sum / n.max(1) as f64)
}

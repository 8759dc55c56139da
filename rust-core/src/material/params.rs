//! Material parameters from JSON, validated with messages that name the key
//! and its accepted range: the material's own keys (surface, fresnel) here,
//! each surface model's in its `params` module. The Mitsuba plugin passes
//! the same names. Lengths are micrometres, wavelengths nanometres. See
//! docs/parameters.md.

use super::energy::EnergyMode;
use crate::error::StamError;
use crate::json::{doc_number, format_bound, type_name, KeyDoc, Reader};
pub use crate::models::fractal::params::DEFAULT_RGB_NODES as DEFAULT_RGB_NODES_FRACTAL;
pub use crate::models::gaussian::params::DEFAULT_RGB_NODES;
pub use crate::models::periodic::params::{
    CD_BUMP_HEIGHT_UM, CD_BUMP_WIDTH_UM, CD_COHERENCE_UM, CD_PERIOD_UM,
};
pub use crate::models::SurfaceParams;
use crate::optics::fresnel::{metal_by_name, metal_names, Fresnel};
use crate::program::ParamId;
use serde_json::{json, Map, Value};

/// Accepted ranges of the material's own keys.
pub mod range {
    /// A constant reflectance F^2 (the lower end exclusive).
    pub const REFLECTANCE: (f64, f64) = (0.0, 1.0);
    pub const ETA: (f64, f64) = (1e-3, 100.0);
    pub const K: (f64, f64) = (0.0, 100.0);
}

/// The metal that `fresnel` defaults to.
pub const DEFAULT_METAL: &str = "aluminium";

/// The keys the material reads whatever its surface.
const MATERIAL_KEYS: [&str; 4] = ["surface", "fresnel", "energy", "gradients"];

#[derive(Clone, Debug, PartialEq)]
pub struct MaterialParams {
    pub surface: SurfaceParams,
    pub fresnel: Fresnel,
    /// "conserving" (default: no direction reflects more than it receives;
    /// docs/energy.md) or "stam" (the paper's formula). A sigma texture's
    /// default is "stam".
    pub energy: EnergyMode,
    /// The parameters a renderer differentiates (`"gradients"`: a list of
    /// names, or true for all): with "conserving", the energy table's
    /// derivatives are built along those it depends on (each costs two
    /// table builds) and the programs follow them; a grating's RGB program
    /// reads its smoothed weight C1 along the period and the coherence
    /// length only where they are listed (docs/inverse.md).
    pub gradients: Vec<ParamId>,
}

fn err(msg: String) -> StamError {
    StamError::new(msg)
}

/// The JSON object of a material's parameters, or why `text` is not one.
pub(crate) fn json_object(text: &str) -> Result<Map<String, Value>, StamError> {
    let value: Value = serde_json::from_str(text)
        .map_err(|e| err(format!("parameters are not valid JSON: {e}")))?;
    match value {
        Value::Object(obj) => Ok(obj),
        other => Err(err(format!(
            "parameters must be a JSON object, got {}",
            type_name(&other)
        ))),
    }
}

impl MaterialParams {
    pub fn from_json(text: &str) -> Result<MaterialParams, StamError> {
        Self::from_object(&json_object(text)?)
    }

    /// The parameters of a JSON object (`from_json` after parsing).
    pub fn from_object(obj: &Map<String, Value>) -> Result<MaterialParams, StamError> {
        let surface = SurfaceParams::parse(obj, &MATERIAL_KEYS)?;
        let fresnel = parse_fresnel(obj.get("fresnel"))?;
        // A sigma texture's material has no one sigma to build the energy
        // table for, so its default is Stam's formula (docs/energy.md).
        let sigma_texture =
            matches!(&surface, SurfaceParams::Gaussian(g) if g.sigma_um_max.is_some());
        // Rigorous gratings conserve energy by themselves (Maxwell's
        // equations): no table to apply.
        let rigorous = matches!(&surface, SurfaceParams::Periodic(p) if p.orders != crate::models::periodic::OrderPowers::Kirchhoff);
        let energy = match obj.get("energy") {
            None if sigma_texture || rigorous => EnergyMode::Stam,
            None => EnergyMode::Conserving,
            Some(Value::String(s)) if s == "conserving" => EnergyMode::Conserving,
            Some(Value::String(s)) if s == "stam" => EnergyMode::Stam,
            Some(other) => {
                return Err(err(format!(
                    "parameter 'energy' = {other} is not accepted: \"conserving\" (default: no direction reflects more than it receives) or \"stam\" (the paper's formula)"
                )))
            }
        };
        if energy == EnergyMode::Conserving && sigma_texture {
            // The energy table is built for one sigma.
            return Err(err(
                "parameter 'sigma_um_max' (a sigma texture) cannot be used with \"energy\": \"conserving\" (its table is built for one sigma); leave 'energy' out or set it to \"stam\"".to_string(),
            ));
        }
        if energy == EnergyMode::Conserving && rigorous {
            return Err(err(
                "parameter 'energy' does not apply to \"orders\": \"rigorous\": Maxwell's equations conserve energy by themselves; leave 'energy' out".to_string(),
            ));
        }
        let gradients = parse_gradients(obj.get("gradients"))?;
        Ok(MaterialParams {
            surface,
            fresnel,
            energy,
            gradients,
        })
    }
}

impl MaterialParams {
    /// Every key the material reads, with the value it took (defaults
    /// filled in): `from_json` of it gives these parameters
    /// (`stam_brdf_params_json`). `given`: the object they were read from
    /// (the surface's name as given, the form of keys that have two).
    pub fn resolved_json(&self, given: &Map<String, Value>) -> Map<String, Value> {
        let mut out = Map::new();
        if let Some(surface) = given.get("surface") {
            out.insert("surface".into(), surface.clone());
        }
        self.surface.resolved(given, &mut out);
        let fresnel = match &self.fresnel {
            Fresnel::Constant(r) => json!(r),
            Fresnel::ComplexIndex { eta, k } => json!({ "eta": eta, "k": k }),
            Fresnel::Metal { table, .. } => json!(table.name),
        };
        out.insert("fresnel".into(), fresnel);
        let energy = match self.energy {
            EnergyMode::Conserving => "conserving",
            EnergyMode::Stam => "stam",
        };
        out.insert("energy".into(), json!(energy));
        let gradients = match self.gradients.is_empty() {
            true => json!(false),
            false => json!(self.gradients.iter().map(|p| p.name()).collect::<Vec<_>>()),
        };
        out.insert("gradients".into(), gradients);
        out
    }
}

/// `MaterialParams::resolved_json` of a JSON parameter object, as JSON
/// text; None when it does not parse (the readers report that).
pub fn resolved_json_text(text: &str) -> Option<String> {
    let Ok(Value::Object(given)) = serde_json::from_str::<Value>(text) else {
        return None;
    };
    let params = MaterialParams::from_json(text).ok()?;
    Some(Value::Object(params.resolved_json(&given)).to_string())
}

/// The keys every surface reads (the material's own), for the reference.
fn material_reference() -> Vec<KeyDoc> {
    let surfaces = SurfaceParams::surface_names()
        .iter()
        .map(|n| format!("\"{n}\""))
        .collect::<Vec<_>>()
        .join(", ");
    let metals = metal_names()
        .iter()
        .map(|n| format!("\"{n}\""))
        .collect::<Vec<_>>()
        .join(", ");
    let (lo, hi) = range::REFLECTANCE;
    let fresnel = KeyDoc::number(
        "fresnel",
        "Fresnel term: a constant reflectance F^2, a metal with a measured spectral index, or a constant complex index",
        "",
        range::REFLECTANCE,
        true,
    );
    let params = ParamId::ALL
        .iter()
        .map(|p| p.name())
        .collect::<Vec<_>>()
        .join(", ");
    vec![
        KeyDoc::text("surface", "microsurface model", surfaces).required(),
        KeyDoc {
            accepted: format!(
                "a reflectance in ({}, {}]; a metal: {metals}; or {{\"eta\": n, \"k\": k}}",
                doc_number(lo),
                doc_number(hi)
            ),
            ..fresnel
        }
        .default(json!(DEFAULT_METAL)),
        KeyDoc::number(
            "fresnel.eta",
            "real part of a constant complex index (fresnel = {\"eta\": n, \"k\": k}; the plugin's 'eta')",
            "",
            range::ETA,
            false,
        )
        .note("required in a complex index"),
        KeyDoc::number(
            "fresnel.k",
            "imaginary part of a constant complex index (the plugin's 'k')",
            "",
            range::K,
            false,
        )
        .default(json!(0.0))
        .note("with eta; 0 is a dielectric"),
        KeyDoc::text(
            "energy",
            "\"conserving\": no direction reflects more than it receives; \"stam\": the paper's formula",
            "\"conserving\", \"stam\"".into(),
        )
        .default(json!("conserving"))
        .note("\"stam\" with sigma_um_max (a sigma texture)"),
        KeyDoc::text(
            "gradients",
            "the parameters a renderer differentiates, which the programs follow smoothly",
            format!("true, false, or a list of names: {params}"),
        )
        .default(json!(false)),
    ]
}

/// The parameter reference (`stam_parameter_reference`): the material's
/// own keys and each surface's, with units, ranges and defaults from the
/// constants the readers check.
pub fn parameter_reference() -> Value {
    let keys = |docs: Vec<KeyDoc>| docs.iter().map(KeyDoc::to_json).collect::<Vec<_>>();
    let surfaces = SurfaceParams::reference()
        .into_iter()
        .map(|(name, docs)| json!({ "surface": name, "keys": keys(docs) }))
        .collect::<Vec<_>>();
    json!({
        "version": env!("CARGO_PKG_VERSION"),
        "units": "lengths in micrometres (um), wavelengths in nanometres",
        "material": keys(material_reference()),
        "surfaces": surfaces,
    })
}

/// `"gradients"`: true (every parameter), false, or a list of parameter
/// names (ParamId::name).
fn parse_gradients(value: Option<&Value>) -> Result<Vec<ParamId>, StamError> {
    let names = || {
        ParamId::ALL
            .iter()
            .map(|p| p.name())
            .collect::<Vec<_>>()
            .join(", ")
    };
    match value {
        None | Some(Value::Bool(false)) => Ok(Vec::new()),
        Some(Value::Bool(true)) => Ok(ParamId::ALL.to_vec()),
        Some(Value::Array(list)) => list
            .iter()
            .map(|v| {
                v.as_str()
                    .and_then(|s| ParamId::ALL.into_iter().find(|p| p.name() == s))
                    .ok_or_else(|| {
                        err(format!(
                            "parameter 'gradients' lists {v}, not a parameter name (accepted: {})",
                            names()
                        ))
                    })
            })
            .collect(),
        Some(other) => Err(err(format!(
            "parameter 'gradients' must be true, false or a list of parameter names, got {}",
            type_name(other)
        ))),
    }
}

fn parse_fresnel(value: Option<&Value>) -> Result<Fresnel, StamError> {
    let names = metal_names().join(", ");
    match value {
        None => Ok(Fresnel::metal(
            metal_by_name(DEFAULT_METAL).expect("aluminium table is built in"),
        )),
        Some(Value::Number(n)) => match n.as_f64() {
            Some(r) if r > range::REFLECTANCE.0 && r <= range::REFLECTANCE.1 => {
                Ok(Fresnel::Constant(r))
            }
            _ => Err(err(format!(
                "parameter 'fresnel' = {n} is out of range: a constant reflectance must be in (0, 1] (or a metal name: {names}; or {{\"eta\": n, \"k\": k}})"
            ))),
        },
        Some(Value::String(s)) => metal_by_name(s).map(Fresnel::metal).ok_or_else(|| {
            err(format!(
                "unknown metal '{s}' for parameter 'fresnel' (accepted: {names}; or a reflectance in (0, 1]; or {{\"eta\": n, \"k\": k}})"
            ))
        }),
        Some(Value::Object(obj)) => {
            for key in obj.keys() {
                if key != "eta" && key != "k" {
                    return Err(err(format!(
                        "unknown key '{key}' in parameter 'fresnel' (a complex index is {{\"eta\": n, \"k\": k}})"
                    )));
                }
            }
            let reader = Reader::new(obj, "fresnel", &[]);
            let eta = reader
                .ranged("eta", range::ETA, false, "")?
                .ok_or_else(|| {
                    err(format!(
                        "missing key 'eta' in parameter 'fresnel' (accepted range [{}, {}])",
                        format_bound(range::ETA.0),
                        format_bound(range::ETA.1)
                    ))
                })?;
            let k = reader.ranged("k", range::K, false, "")?.unwrap_or(0.0);
            Ok(Fresnel::ComplexIndex { eta, k })
        }
        Some(other) => Err(err(format!(
            "parameter 'fresnel' must be a reflectance in (0, 1], a metal name ({names}) or {{\"eta\": n, \"k\": k}}, got {}",
            type_name(other)
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::gaussian::GaussianParams;
    use crate::models::periodic::{PeriodicParams, Profile};

    fn message(json: &str) -> String {
        MaterialParams::from_json(json).unwrap_err().message
    }

    #[test]
    fn accepts_each_surface() {
        let p = MaterialParams::from_json(r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2}"#)
            .unwrap();
        assert!(matches!(
            p.surface,
            SurfaceParams::Gaussian(GaussianParams {
                anisotropic: false,
                ..
            })
        ));
        let p = MaterialParams::from_json(
            r#"{"surface":"gaussian","sigma_um":0.1,"corr_x_um":2,"corr_y_um":20,"fresnel":0.9}"#,
        )
        .unwrap();
        assert!(matches!(
            p.surface,
            SurfaceParams::Gaussian(GaussianParams {
                anisotropic: true,
                ..
            })
        ));
        assert_eq!(p.fresnel, Fresnel::Constant(0.9));
        MaterialParams::from_json(r#"{"surface":"fractal","hurst":0.5,"sigma_um":0.1,"lag_um":1}"#)
            .unwrap();
        let cd = MaterialParams::from_json(r#"{"surface":"cd"}"#).unwrap();
        assert_eq!(
            cd.surface,
            SurfaceParams::Periodic(PeriodicParams {
                period_um: CD_PERIOD_UM,
                coherence_um: CD_COHERENCE_UM,
                profile: Profile::Rect {
                    height_um: CD_BUMP_HEIGHT_UM,
                    width_um: CD_BUMP_WIDTH_UM
                },
                height_um_max: None,
                orders: crate::models::periodic::OrderPowers::Kirchhoff,
            })
        );
        let cd = MaterialParams::from_json(
            r#"{"surface":"cd","coherence_um":10,"fresnel":{"eta":1.5}}"#,
        )
        .unwrap();
        assert!(
            matches!(cd.surface, SurfaceParams::Periodic(PeriodicParams { coherence_um, .. }) if coherence_um == 10.0)
        );
        MaterialParams::from_json(
            r#"{"surface":"periodic","period_um":1,"coherence_um":20,"profile":{"heights_um":[0,0.1,0.2,0.1]},"fresnel":"gold"}"#,
        )
        .unwrap();
        MaterialParams::from_json(
            r#"{"surface":"periodic","period_um":1,"coherence_um":20,"profile":"sine","height_um":0.2}"#,
        )
        .unwrap();
    }

    #[test]
    fn refusals_name_the_key_and_range() {
        let m = message(r#"{"surface":"gaussian","sigma_um":-1,"corr_um":2}"#);
        assert!(
            m.contains("'sigma_um'") && m.contains("[0.000001, 100]"),
            "{m}"
        );
        let m = message(r#"{"surface":"gaussian","sigma_um":0.1}"#);
        assert!(m.contains("'corr_um'"), "{m}");
        let m = message(r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2,"colour":1}"#);
        assert!(m.contains("unknown parameter 'colour'"), "{m}");
        let m = message(r#"{"surface":"fractal","hurst":0,"sigma_um":0.1,"lag_um":1}"#);
        assert!(m.contains("'hurst'") && m.contains("[0.001, 1]"), "{m}");
        let m = message(r#"{"surface":"fractal","hurst":1e-4,"sigma_um":0.1,"lag_um":1}"#);
        assert!(m.contains("'hurst'") && m.contains("[0.001, 1]"), "{m}");
        let m = message(r#"{"surface":"cd","coherence_um":1}"#);
        assert!(m.contains("'coherence_um'") && m.contains("3.75"), "{m}");
        let m = message(
            r#"{"surface":"periodic","period_um":1,"coherence_um":20,"profile":"rect","height_um":0.1}"#,
        );
        assert!(m.contains("'width_um'"), "{m}");
        let m = message(r#"{"surface":"cd","width_um":3}"#);
        assert!(m.contains("'width_um'") && m.contains("2.5"), "{m}");
        let m = message(r#"{"surface":"cd","fresnel":"unobtainium"}"#);
        assert!(m.contains("'fresnel'") && m.contains("aluminium"), "{m}");
        let m = message(r#"{"surface":"cd","fresnel":1.5}"#);
        assert!(m.contains("'fresnel'") && m.contains("(0, 1]"), "{m}");
        let m = message(r#"{"surface":"glass"}"#);
        assert!(m.contains("'surface'"), "{m}");
        let m = message(r#"{"sigma_um":1}"#);
        assert!(m.contains("missing parameter 'surface'"), "{m}");
        let m = message("not json");
        assert!(m.contains("JSON"), "{m}");
        let m = message(r#"{"surface":"cd","rgb_nodes":2.5}"#);
        assert!(m.contains("'rgb_nodes'"), "{m}");
        let m = message(
            r#"{"surface":"periodic","period_um":1,"coherence_um":20,"profile":{"heights_um":[0]}}"#,
        );
        assert!(m.contains("'profile.heights_um'"), "{m}");
    }

    /// Keys a surface does not read are refused by name, with the list of
    /// what it accepts; computed bounds print as a person would write them.
    #[test]
    fn keys_a_surface_does_not_use_are_refused() {
        let m = message(r#"{"surface":"cd","series_tolerance":1e-6}"#);
        assert!(
            m.contains("unknown parameter 'series_tolerance' for surface 'cd'"),
            "{m}"
        );
        assert!(
            m.contains("surface, fresnel, energy, gradients, period_um"),
            "{m}"
        );
        let m = message(r#"{"surface":"cd","gradients":1}"#);
        assert!(
            m.contains("'gradients' must be true, false or a list"),
            "{m}"
        );
        let m = message(r#"{"surface":"cd","gradients":["period"]}"#);
        assert!(m.contains("\"period\", not a parameter name"), "{m}");
        let p =
            MaterialParams::from_json(r#"{"surface":"cd","gradients":["period_um","fresnel"]}"#)
                .unwrap();
        assert_eq!(p.gradients, vec![ParamId::PeriodUm, ParamId::Fresnel]);
        let m = message(r#"{"surface":"cd","rgb_nodes":16}"#);
        assert!(m.contains("unknown parameter 'rgb_nodes'"), "{m}");
        let m = message(
            r#"{"surface":"fractal","hurst":0.5,"sigma_um":0.1,"lag_um":1,"series_tolerance":1e-6}"#,
        );
        assert!(m.contains("unknown parameter 'series_tolerance'"), "{m}");
        MaterialParams::from_json(
            r#"{"surface":"fractal","hurst":0.5,"sigma_um":0.1,"lag_um":1,"rgb_nodes":16}"#,
        )
        .unwrap();
        MaterialParams::from_json(
            r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2,"rgb_nodes":16,"series_tolerance":1e-6}"#,
        )
        .unwrap();
        let m = message(
            r#"{"surface":"periodic","period_um":1.2,"coherence_um":1,"profile":"sine","height_um":0.1}"#,
        );
        assert!(m.contains("[1.8, 10000]"), "{m}");
    }

    /// Out-of-range lengths that read as nanometres get the hint that an
    /// accepted but implausible one gets (plausibility.rs); others none.
    #[test]
    fn out_of_range_nanometres_get_the_hint() {
        let m = message(r#"{"surface":"gaussian","sigma_um":250,"corr_um":2}"#);
        assert!(m.contains("'sigma_um' = 250 is out of range"), "{m}");
        let hint = crate::json::nanometre_hint("sigma_um", 250.0);
        assert!(m.ends_with(&hint), "{m}");
        assert!(hint.contains("sigma_um = 0.25 (micrometres)"), "{hint}");
        let m = message(r#"{"surface":"cd","period_um":1600}"#);
        assert!(m.contains("period_um = 1.6 (micrometres)"), "{m}");
        let m = message(r#"{"surface":"cd","coherence_um":20000}"#);
        assert!(m.contains("coherence_um = 20 (micrometres)"), "{m}");
        let m = message(r#"{"surface":"cd","height_um":150}"#);
        assert!(m.contains("height_um = 0.15 (micrometres)"), "{m}");
        let m = message(r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2e5}"#);
        assert!(m.contains("corr_um = 200 (micrometres)"), "{m}");
        // Not nanometres: too large either way, below the range, no length
        for json in [
            r#"{"surface":"gaussian","sigma_um":1e6,"corr_um":2}"#,
            r#"{"surface":"gaussian","sigma_um":-1,"corr_um":2}"#,
            r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2,"series_tolerance":5}"#,
            r#"{"surface":"cd","coherence_um":1}"#,
        ] {
            let m = message(json);
            assert!(!m.contains("nanometres"), "{json}: {m}");
        }
    }

    /// The resolved parameters name every key with the value taken
    /// (defaults filled in), and build the same material.
    #[test]
    fn resolved_parameters_fill_the_defaults_and_round_trip() {
        let resolved = |json: &str| -> Map<String, Value> {
            let text = resolved_json_text(json).unwrap();
            let Value::Object(m) = serde_json::from_str(&text).unwrap() else {
                panic!("{text}")
            };
            assert_eq!(
                MaterialParams::from_json(&text).unwrap(),
                MaterialParams::from_json(json).unwrap(),
                "{json} -> {text}"
            );
            m
        };
        let cd = resolved(r#"{"surface":"cd"}"#);
        for (key, value) in [
            ("surface", json!("cd")),
            ("period_um", json!(CD_PERIOD_UM)),
            ("coherence_um", json!(CD_COHERENCE_UM)),
            ("profile", json!("rect")),
            ("height_um", json!(CD_BUMP_HEIGHT_UM)),
            ("width_um", json!(CD_BUMP_WIDTH_UM)),
            ("fresnel", json!("aluminium")),
            ("energy", json!("conserving")),
            ("gradients", json!(false)),
            ("orders", json!("kirchhoff")),
        ] {
            assert_eq!(cd.get(key), Some(&value), "{key}: {cd:?}");
        }
        assert_eq!(cd.len(), 10, "{cd:?}");
        // Defaults that follow other keys
        let cd = resolved(r#"{"surface":"cd","period_um":40}"#);
        assert_eq!(cd["coherence_um"], json!(60.0));
        let cd = resolved(r#"{"surface":"cd","period_um":0.4,"profile":"sine"}"#);
        assert_eq!(cd["height_um"], json!(CD_BUMP_HEIGHT_UM));
        assert!(!cd.contains_key("width_um"), "{cd:?}");
        let g = resolved(r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2}"#);
        assert_eq!(g["series_tolerance"], json!(1e-5));
        assert_eq!(g["rgb_nodes"], json!(DEFAULT_RGB_NODES));
        assert!(!g.contains_key("corr_x_um"), "{g:?}");
        // The form given: equal x and y stay x and y
        let g = resolved(r#"{"surface":"gaussian","sigma_um":0.1,"corr_x_um":2,"corr_y_um":2}"#);
        assert!(
            g.contains_key("corr_x_um") && !g.contains_key("corr_um"),
            "{g:?}"
        );
        let f = resolved(r#"{"surface":"fractal","hurst":0.5,"sigma_um":0.1,"lag_um":1}"#);
        assert_eq!(f["rgb_nodes"], json!(DEFAULT_RGB_NODES_FRACTAL));
        let f = resolved(
            r#"{"surface":"fractal","hurst":0.5,"sigma_um":0.1,"lag_um":1,"fresnel":{"eta":1.5}}"#,
        );
        assert_eq!(f["fresnel"], json!({"eta": 1.5, "k": 0.0}));
        let t = resolved(
            r#"{"surface":"gaussian","sigma_um":0.1,"sigma_um_max":0.4,"corr_um":2,"fresnel":0.5,"gradients":["sigma_um"]}"#,
        );
        assert_eq!(t["energy"], json!("stam"));
        assert_eq!(t["sigma_um_max"], json!(0.4));
        assert_eq!(t["gradients"], json!(["sigma_um"]));
        resolved(
            r#"{"surface":"periodic","period_um":1,"coherence_um":20,"profile":{"heights_um":[0,0.1,0.2,0.1]},"fresnel":"au"}"#,
        );
        resolved(
            r#"{"surface":"periodic","period_um":1.2,"coherence_um":6,"profile":"sine","height_um":0.2,"height_um_max":0.5}"#,
        );
        assert_eq!(resolved_json_text(r#"{"surface":"gaussian"}"#), None);
        assert_eq!(resolved_json_text("[1]"), None);
    }

    /// A valid material of `surface` in which `key` can take any value of
    /// its range (the keys it depends on set so that they do not refuse it).
    fn base_for(surface: &str, key: &str) -> Map<String, Value> {
        let v = match (surface, key) {
            ("periodic", "fourier_orders" | "cover_eta") => {
                json!({"surface": "periodic", "period_um": 1,
                "coherence_um": 1e4, "profile": "sine", "height_um": 1e-12, "orders": "rigorous"})
            }
            ("cd", "fourier_orders" | "cover_eta") => {
                json!({"surface": "cd", "orders": "rigorous"})
            }
            ("gaussian", "corr_x_um" | "corr_y_um") => {
                json!({"surface": "gaussian", "sigma_um": 1e-6, "corr_x_um": 2, "corr_y_um": 2})
            }
            ("gaussian", _) => json!({"surface": "gaussian", "sigma_um": 1e-6, "corr_um": 2}),
            ("fractal", _) => {
                json!({"surface": "fractal", "hurst": 0.5, "sigma_um": 0.1, "lag_um": 1})
            }
            ("periodic", "width_um") => json!({"surface": "periodic", "period_um": 1000,
                "coherence_um": 1e4, "profile": "rect", "height_um": 0.1, "width_um": 0.5}),
            ("periodic", _) => json!({"surface": "periodic", "period_um": 1, "coherence_um": 1e4,
                "profile": "sine", "height_um": 1e-12}),
            ("cd", "height_um_max") => {
                json!({"surface": "cd", "profile": "sine", "height_um": 1e-12})
            }
            ("cd", "width_um") => json!({"surface": "cd", "period_um": 1000}),
            // The parameters alone: the map is read when the surface is made.
            ("heightmap", _) => {
                json!({"surface": "heightmap", "file": "map.npy", "pixel_um": 0.08})
            }
            _ => json!({"surface": surface}),
        };
        let Value::Object(m) = v else { unreachable!() };
        m
    }

    fn with_key(base: &Map<String, Value>, key: &str, value: Value) -> String {
        let mut m = base.clone();
        match key.split_once('.') {
            Some((outer, inner)) => {
                let mut obj = json!({"eta": 1.5});
                obj[inner] = value;
                m.insert(outer.into(), obj);
            }
            None => {
                m.insert(key.into(), value);
            }
        }
        Value::Object(m).to_string()
    }

    /// The parameter reference (stam_parameter_reference) says what the
    /// readers do: each numeric bound is where they accept and refuse, a
    /// required key is refused when missing, a default is the value taken
    /// when a key is left out.
    #[test]
    fn reference_agrees_with_the_readers() {
        let reference = parameter_reference();
        let material = reference["material"].as_array().unwrap();
        let surfaces = reference["surfaces"].as_array().unwrap();
        let names: Vec<&str> = surfaces
            .iter()
            .map(|s| s["surface"].as_str().unwrap())
            .collect();
        assert_eq!(
            names,
            ["gaussian", "fractal", "periodic", "cd", "heightmap"]
        );
        let mut checked_bounds = 0;
        for s in surfaces {
            let surface = s["surface"].as_str().unwrap();
            let keys = s["keys"].as_array().unwrap();
            for doc in material.iter().chain(keys) {
                let key = doc["key"].as_str().unwrap();
                let base = base_for(surface, key);
                let accepts = |v: f64| {
                    let v = if doc["integer"].as_bool().unwrap() {
                        json!(v as i64)
                    } else {
                        json!(v)
                    };
                    let json = with_key(&base, key, v);
                    (MaterialParams::from_json(&json), json)
                };
                let leaf = key.rsplit('.').next().unwrap();
                let refused = |v: f64| {
                    let (r, json) = accepts(v);
                    match r {
                        Ok(_) => panic!("{surface}: {json} accepted"),
                        Err(e) => assert!(
                            e.message.contains(&format!("'{leaf}'")),
                            "{surface}: {json}: {}",
                            e.message
                        ),
                    }
                };
                let ok = |v: f64| {
                    let (r, json) = accepts(v);
                    assert!(r.is_ok(), "{surface}: {json}: {:?}", r.err());
                };
                let step = if doc["integer"].as_bool().unwrap() {
                    |x: f64| 1.0f64.max(x * 0.0)
                } else {
                    |x: f64| x.abs() * 1e-9 + 1e-300
                };
                if let Some(lo) = doc["min"].as_f64() {
                    if doc["min_open"].as_bool().unwrap() {
                        refused(lo);
                        ok(lo + step(lo).max(1e-12));
                    } else {
                        ok(lo);
                        refused(lo - step(lo));
                    }
                    checked_bounds += 1;
                }
                if let Some(hi) = doc["max"].as_f64() {
                    ok(hi);
                    refused(hi + step(hi));
                    checked_bounds += 1;
                }
                if doc["required"].as_bool().unwrap() && !key.contains('.') {
                    let mut m = base.clone();
                    m.remove(key);
                    let e = MaterialParams::from_json(&Value::Object(m).to_string()).unwrap_err();
                    assert!(
                        e.message.contains(&format!("missing parameter '{key}'")),
                        "{surface} without {key}: {}",
                        e.message
                    );
                }
                if let Some(default) = doc.get("default").filter(|d| !d.is_null()) {
                    if key.contains('.') {
                        continue;
                    }
                    let mut m = base_for(surface, key);
                    m.remove(key);
                    let text = Value::Object(m).to_string();
                    let resolved = resolved_json_text(&text).unwrap();
                    let resolved: Value = serde_json::from_str(&resolved).unwrap();
                    assert_eq!(&resolved[key], default, "{surface}: {key}");
                }
            }
        }
        assert!(checked_bounds >= 40, "{checked_bounds}");
        // The relative bounds, in words
        let cd = &surfaces[3]["keys"];
        let find = |k: &str| {
            cd.as_array()
                .unwrap()
                .iter()
                .find(|d| d["key"] == k)
                .unwrap()
                .clone()
        };
        assert_eq!(
            find("coherence_um")["accepted"],
            json!("[1.5 period_um, 1e4]")
        );
        assert_eq!(find("width_um")["accepted"], json!("(0, period_um]"));
        let m = message(r#"{"surface":"cd","period_um":2,"coherence_um":2.9}"#);
        assert!(m.contains("[3, 10000]"), "{m}");
        let m = message(r#"{"surface":"cd","period_um":2,"width_um":2.1}"#);
        assert!(m.contains("(0, 2]"), "{m}");
    }

    #[test]
    fn sigma_um_max_is_checked() {
        let m = message(r#"{"surface":"gaussian","sigma_um":0.2,"sigma_um_max":0.1,"corr_um":2}"#);
        assert!(
            m.contains("'sigma_um_max'") && m.contains("below 'sigma_um'"),
            "{m}"
        );
        let m = message(
            r#"{"surface":"gaussian","sigma_um":0.1,"sigma_um_max":0.5,"corr_um":2,"energy":"conserving"}"#,
        );
        assert!(
            m.contains("'sigma_um_max'") && m.contains("conserving"),
            "{m}"
        );
        let m = message(
            r#"{"surface":"fractal","hurst":0.5,"sigma_um":0.1,"lag_um":1,"sigma_um_max":0.5}"#,
        );
        assert!(m.contains("sigma_um_max"), "{m}");
        MaterialParams::from_json(
            r#"{"surface":"gaussian","sigma_um":0.1,"sigma_um_max":0.5,"corr_um":2}"#,
        )
        .unwrap();
    }

    #[test]
    fn height_um_max_is_checked() {
        let sine = r#"{"surface":"periodic","period_um":1.2,"coherence_um":6,"profile":"sine","height_um":0.2"#;
        let m = message(&format!("{sine},\"height_um_max\":0.1}}"));
        assert!(
            m.contains("'height_um_max'") && m.contains("below 'height_um'"),
            "{m}"
        );
        let m = message(&format!("{sine},\"height_um_max\":-1}}"));
        assert!(m.contains("'height_um_max'"), "{m}");
        let m = message(r#"{"surface":"cd","height_um_max":0.5}"#);
        assert!(m.contains("'height_um_max'") && m.contains("sine"), "{m}");
        MaterialParams::from_json(&format!("{sine},\"height_um_max\":0.5}}")).unwrap();
    }
}

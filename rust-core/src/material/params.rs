//! Material parameters from JSON, validated with messages that name the key
//! and its accepted range: the material's own keys (surface, fresnel) here,
//! each surface model's in its `params` module. The Mitsuba plugin passes
//! the same names. Lengths are micrometres, wavelengths nanometres. See
//! docs/parameters.md.

use super::energy::EnergyMode;
use crate::error::StamError;
use crate::json::{format_bound, type_name, Reader};
pub use crate::models::fractal::params::DEFAULT_RGB_NODES as DEFAULT_RGB_NODES_FRACTAL;
pub use crate::models::gaussian::params::DEFAULT_RGB_NODES;
pub use crate::models::periodic::params::{
    CD_BUMP_HEIGHT_UM, CD_BUMP_WIDTH_UM, CD_COHERENCE_UM, CD_PERIOD_UM,
};
pub use crate::models::SurfaceParams;
use crate::optics::fresnel::{metal_by_name, metal_names, Fresnel};
use crate::program::ParamId;
use serde_json::Value;

/// Accepted ranges of the material's own keys.
pub mod range {
    pub const ETA: (f64, f64) = (1e-3, 100.0);
    pub const K: (f64, f64) = (0.0, 100.0);
}

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

impl MaterialParams {
    pub fn from_json(text: &str) -> Result<MaterialParams, StamError> {
        let value: Value = serde_json::from_str(text)
            .map_err(|e| err(format!("parameters are not valid JSON: {e}")))?;
        let Value::Object(obj) = &value else {
            return Err(err(format!(
                "parameters must be a JSON object, got {}",
                type_name(&value)
            )));
        };
        let surface = SurfaceParams::parse(obj, &MATERIAL_KEYS)?;
        let fresnel = parse_fresnel(obj.get("fresnel"))?;
        // A sigma texture's material has no one sigma to build the energy
        // table for, so its default is Stam's formula (docs/energy.md).
        let sigma_texture =
            matches!(&surface, SurfaceParams::Gaussian(g) if g.sigma_um_max.is_some());
        let energy = match obj.get("energy") {
            None if sigma_texture => EnergyMode::Stam,
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
        let gradients = parse_gradients(obj.get("gradients"))?;
        Ok(MaterialParams {
            surface,
            fresnel,
            energy,
            gradients,
        })
    }
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
            metal_by_name("aluminium").expect("aluminium table is built in"),
        )),
        Some(Value::Number(n)) => match n.as_f64() {
            Some(r) if r > 0.0 && r <= 1.0 => Ok(Fresnel::Constant(r)),
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

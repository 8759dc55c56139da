//! Material parameters from JSON, validated with messages that name the key
//! and its accepted range. The Mitsuba plugin passes the same names.
//!
//! Lengths are micrometres, wavelengths nanometres. See docs/parameters.md.

use crate::error::StamError;
use crate::fresnel::{metal_by_name, metal_names, Fresnel};
use crate::periodic::Profile;
use serde_json::{Map, Value};

/// The compact disc of the paper (Stam's "Used physical dimensions").
pub const CD_PERIOD_UM: f64 = 2.5;
pub const CD_BUMP_HEIGHT_UM: f64 = 0.15;
pub const CD_BUMP_WIDTH_UM: f64 = 0.5;
/// Spatial coherence of ordinary illumination: about lambda / (angular size
/// of the source); a 1 cm lamp at 1 m or the sun give ~50 um at 550 nm.
pub const CD_COHERENCE_UM: f64 = 50.0;

/// Accepted ranges, shared by the validator, the docs and the stress tests.
pub mod range {
    pub const SIGMA_UM: (f64, f64) = (1e-6, 100.0);
    pub const CORR_UM: (f64, f64) = (1e-3, 1e5);
    pub const LAG_UM: (f64, f64) = (1e-3, 1e5);
    /// Below 1e-3 the stable-law profile (alpha = 2 hurst) takes minutes to
    /// tabulate (from about 3e-4) or cannot be tabulated at all; such surfaces
    /// are flat to within r^0.002 and are refused.
    pub const HURST: (f64, f64) = (1e-3, 1.0); // [0.001, 1]
    pub const PERIOD_UM: (f64, f64) = (0.05, 1000.0);
    /// As a multiple of the period (lower end) and in um (upper end).
    pub const COHERENCE_MIN_PERIODS: f64 = 1.5;
    pub const COHERENCE_MAX_UM: f64 = 1e4;
    pub const HEIGHT_UM: (f64, f64) = (0.0, 100.0);
    pub const HEIGHTS_LEN: (usize, usize) = (2, 65536);
    pub const ETA: (f64, f64) = (1e-3, 100.0);
    pub const K: (f64, f64) = (0.0, 100.0);
    pub const SERIES_TOLERANCE: (f64, f64) = (1e-12, 0.1);
    pub const RGB_NODES: (usize, usize) = (4, 64);
}

/// Default node count of the RGB rule for Gaussian surfaces (and their
/// coherent lobe); fractal spectra are smoother: 8 nodes reach the same
/// 2-3e-5 error at two thirds of the cost (docs/accuracy_speed.md).
pub const DEFAULT_RGB_NODES: usize = 12;
pub const DEFAULT_RGB_NODES_FRACTAL: usize = 8;

#[derive(Clone, Debug, PartialEq)]
pub enum SurfaceParams {
    Gaussian {
        sigma_um: f64,
        corr_x_um: f64,
        corr_y_um: f64,
        anisotropic: bool,
    },
    Fractal {
        hurst: f64,
        sigma_um: f64,
        lag_um: f64,
    },
    Periodic {
        period_um: f64,
        coherence_um: f64,
        profile: Profile,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub struct AccuracyParams {
    pub series_tolerance: f64,
    pub rgb_nodes: usize,
}

#[derive(Clone, Debug, PartialEq)]
pub struct MaterialParams {
    pub surface: SurfaceParams,
    pub fresnel: Fresnel,
    pub accuracy: AccuracyParams,
}

const COMMON_KEYS: [&str; 4] = ["surface", "fresnel", "series_tolerance", "rgb_nodes"];

fn err(msg: String) -> StamError {
    StamError::new(msg)
}

struct Reader<'a> {
    obj: &'a Map<String, Value>,
    surface: &'a str,
}

impl Reader<'_> {
    fn check_keys(&self, allowed: &[&str]) -> Result<(), StamError> {
        for key in self.obj.keys() {
            if !COMMON_KEYS.contains(&key.as_str()) && !allowed.contains(&key.as_str()) {
                let mut accepted: Vec<&str> = COMMON_KEYS.to_vec();
                accepted.extend_from_slice(allowed);
                return Err(err(format!(
                    "unknown parameter '{key}' for surface '{}' (accepted: {})",
                    self.surface,
                    accepted.join(", ")
                )));
            }
        }
        Ok(())
    }

    fn number(&self, key: &str) -> Result<Option<f64>, StamError> {
        match self.obj.get(key) {
            None => Ok(None),
            Some(Value::Number(n)) => match n.as_f64() {
                Some(x) if x.is_finite() => Ok(Some(x)),
                _ => Err(err(format!("parameter '{key}' must be a finite number"))),
            },
            Some(other) => Err(err(format!(
                "parameter '{key}' must be a number, got {}",
                type_name(other)
            ))),
        }
    }

    /// A number in [lo, hi] (lo exclusive when `lo_open`).
    fn ranged(
        &self,
        key: &str,
        (lo, hi): (f64, f64),
        lo_open: bool,
        unit: &str,
    ) -> Result<Option<f64>, StamError> {
        let Some(x) = self.number(key)? else {
            return Ok(None);
        };
        let below = if lo_open { x <= lo } else { x < lo };
        if below || x > hi {
            let open = if lo_open { "(" } else { "[" };
            return Err(err(format!(
                "parameter '{key}' = {x} is out of range: accepted {open}{lo}, {hi}]{unit}"
            )));
        }
        Ok(Some(x))
    }

    fn required(
        &self,
        key: &str,
        range: (f64, f64),
        lo_open: bool,
        unit: &str,
    ) -> Result<f64, StamError> {
        self.ranged(key, range, lo_open, unit)?.ok_or_else(|| {
            err(format!(
                "missing parameter '{key}' for surface '{}' (accepted range [{}, {}]{unit})",
                self.surface, range.0, range.1
            ))
        })
    }
}

fn type_name(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
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
        let surface = match obj.get("surface") {
            None => {
                return Err(err(
                    "missing parameter 'surface' (accepted: \"gaussian\", \"fractal\", \"periodic\", \"cd\")"
                        .into(),
                ))
            }
            Some(Value::String(s)) => s.as_str(),
            Some(other) => {
                return Err(err(format!(
                    "parameter 'surface' must be a string (\"gaussian\", \"fractal\", \"periodic\", \"cd\"), got {}",
                    type_name(other)
                )))
            }
        };
        let reader = Reader { obj, surface };
        let surface_params = match surface {
            "gaussian" => parse_gaussian(&reader)?,
            "fractal" => parse_fractal(&reader)?,
            "periodic" => parse_periodic(&reader, false)?,
            "cd" => parse_periodic(&reader, true)?,
            other => {
                return Err(err(format!(
                    "unknown surface '{other}' for parameter 'surface' (accepted: \"gaussian\", \"fractal\", \"periodic\", \"cd\")"
                )))
            }
        };
        let fresnel = parse_fresnel(obj.get("fresnel"))?;
        let series_tolerance = reader
            .ranged("series_tolerance", range::SERIES_TOLERANCE, false, "")?
            .unwrap_or(crate::gaussian::DEFAULT_SERIES_TOLERANCE);
        let rgb_nodes = match reader.number("rgb_nodes")? {
            None if matches!(surface_params, SurfaceParams::Fractal { .. }) => {
                DEFAULT_RGB_NODES_FRACTAL
            }
            None => DEFAULT_RGB_NODES,
            Some(x) => {
                let (lo, hi) = range::RGB_NODES;
                if x.fract() != 0.0 || x < lo as f64 || x > hi as f64 {
                    return Err(err(format!(
                        "parameter 'rgb_nodes' = {x} is out of range: accepted an integer in [{lo}, {hi}]"
                    )));
                }
                x as usize
            }
        };
        Ok(MaterialParams {
            surface: surface_params,
            fresnel,
            accuracy: AccuracyParams {
                series_tolerance,
                rgb_nodes,
            },
        })
    }
}

fn parse_gaussian(r: &Reader) -> Result<SurfaceParams, StamError> {
    r.check_keys(&["sigma_um", "corr_um", "corr_x_um", "corr_y_um"])?;
    let sigma_um = r.required("sigma_um", range::SIGMA_UM, false, " um")?;
    let corr = r.ranged("corr_um", range::CORR_UM, false, " um")?;
    let corr_x = r.ranged("corr_x_um", range::CORR_UM, false, " um")?;
    let corr_y = r.ranged("corr_y_um", range::CORR_UM, false, " um")?;
    let (corr_x_um, corr_y_um, anisotropic) = match (corr, corr_x, corr_y) {
        (Some(t), None, None) => (t, t, false),
        (None, Some(tx), Some(ty)) => (tx, ty, tx != ty),
        (Some(_), _, _) => {
            return Err(err(
                "give either 'corr_um' (isotropic) or 'corr_x_um' and 'corr_y_um' (anisotropic), not both"
                    .into(),
            ))
        }
        (None, Some(_), None) => return Err(err(format!(
            "missing parameter 'corr_y_um' (anisotropic surfaces need both 'corr_x_um' and 'corr_y_um', each in [{}, {}] um)",
            range::CORR_UM.0, range::CORR_UM.1
        ))),
        (None, None, Some(_)) => return Err(err(format!(
            "missing parameter 'corr_x_um' (anisotropic surfaces need both 'corr_x_um' and 'corr_y_um', each in [{}, {}] um)",
            range::CORR_UM.0, range::CORR_UM.1
        ))),
        (None, None, None) => return Err(err(format!(
            "missing parameter 'corr_um' for surface 'gaussian' (accepted range [{}, {}] um; or 'corr_x_um' and 'corr_y_um' for an anisotropic surface)",
            range::CORR_UM.0, range::CORR_UM.1
        ))),
    };
    Ok(SurfaceParams::Gaussian {
        sigma_um,
        corr_x_um,
        corr_y_um,
        anisotropic,
    })
}

fn parse_fractal(r: &Reader) -> Result<SurfaceParams, StamError> {
    r.check_keys(&["hurst", "sigma_um", "lag_um"])?;
    let hurst = r.required("hurst", range::HURST, false, "")?;
    let sigma_um = r.required("sigma_um", range::SIGMA_UM, false, " um")?;
    let lag_um = r.required("lag_um", range::LAG_UM, false, " um")?;
    Ok(SurfaceParams::Fractal {
        hurst,
        sigma_um,
        lag_um,
    })
}

fn parse_periodic(r: &Reader, compact_disc: bool) -> Result<SurfaceParams, StamError> {
    r.check_keys(&[
        "period_um",
        "coherence_um",
        "profile",
        "height_um",
        "width_um",
    ])?;
    let defaults = |v: f64| if compact_disc { Some(v) } else { None };
    let period_um = match r.ranged("period_um", range::PERIOD_UM, false, " um")? {
        Some(p) => p,
        None => defaults(CD_PERIOD_UM).ok_or_else(|| {
            err(format!(
                "missing parameter 'period_um' for surface 'periodic' (accepted range [{}, {}] um)",
                range::PERIOD_UM.0,
                range::PERIOD_UM.1
            ))
        })?,
    };
    let coherence_lo = range::COHERENCE_MIN_PERIODS * period_um;
    let coherence_range = (coherence_lo, range::COHERENCE_MAX_UM);
    let coherence_um = match r.number("coherence_um")? {
        Some(l) if l < coherence_lo || l > range::COHERENCE_MAX_UM => {
            return Err(err(format!(
                "parameter 'coherence_um' = {l} is out of range: accepted [{coherence_lo}, {}] um (at least {} periods: the finite-coherence model needs coherence >> period)",
                range::COHERENCE_MAX_UM,
                range::COHERENCE_MIN_PERIODS
            )))
        }
        Some(l) => l,
        None => defaults(CD_COHERENCE_UM.max(coherence_lo)).ok_or_else(|| {
            err(format!(
                "missing parameter 'coherence_um' for surface 'periodic' (accepted range [{}, {}] um)",
                coherence_range.0, coherence_range.1
            ))
        })?,
    };
    let height = r.ranged("height_um", range::HEIGHT_UM, true, " um")?;
    let width = r.ranged(
        "width_um",
        (0.0, period_um),
        true,
        " um (0 < width <= period_um)",
    )?;
    let profile_value = r.obj.get("profile");
    let kind = match profile_value {
        None if compact_disc => "rect",
        None => {
            return Err(err(
                "missing parameter 'profile' for surface 'periodic' (accepted: \"rect\", \"sine\", {\"heights_um\": [...]})".into(),
            ))
        }
        Some(Value::String(s)) => s.as_str(),
        Some(Value::Object(_)) => "tabulated",
        Some(other) => {
            return Err(err(format!(
                "parameter 'profile' must be \"rect\", \"sine\" or {{\"heights_um\": [...]}}, got {}",
                type_name(other)
            )))
        }
    };
    let need_height = |what: &str| -> Result<f64, StamError> {
        height.or(defaults(CD_BUMP_HEIGHT_UM)).ok_or_else(|| {
            err(format!(
                "missing parameter 'height_um' for profile '{what}' (accepted range [{}, {}] um)",
                range::HEIGHT_UM.0,
                range::HEIGHT_UM.1
            ))
        })
    };
    let profile = match kind {
        "rect" => {
            let height_um = need_height("rect")?;
            let width_um = match width.or(defaults(CD_BUMP_WIDTH_UM.min(period_um))) {
                Some(w) => w,
                None => {
                    return Err(err(format!(
                        "missing parameter 'width_um' for profile 'rect' (accepted range (0, {period_um}] um, at most the period)"
                    )))
                }
            };
            Profile::Rect {
                height_um,
                width_um,
            }
        }
        "sine" => {
            if width.is_some() {
                return Err(err(
                    "parameter 'width_um' does not apply to profile 'sine' (only 'height_um')".into(),
                ));
            }
            Profile::Sine {
                height_um: need_height("sine")?,
            }
        }
        "tabulated" => {
            if height.is_some() || width.is_some() {
                return Err(err(
                    "parameters 'height_um' and 'width_um' do not apply to a tabulated profile (its heights are given in 'heights_um')".into(),
                ));
            }
            Profile::Tabulated {
                heights_um: parse_heights(profile_value.unwrap())?,
            }
        }
        other => {
            return Err(err(format!(
                "unknown profile '{other}' for parameter 'profile' (accepted: \"rect\", \"sine\", {{\"heights_um\": [...]}})"
            )))
        }
    };
    Ok(SurfaceParams::Periodic {
        period_um,
        coherence_um,
        profile,
    })
}

fn parse_heights(value: &Value) -> Result<Vec<f64>, StamError> {
    let Value::Object(obj) = value else {
        unreachable!("caller matched an object")
    };
    for key in obj.keys() {
        if key != "heights_um" {
            return Err(err(format!(
                "unknown key '{key}' in parameter 'profile' (a tabulated profile is {{\"heights_um\": [...]}})"
            )));
        }
    }
    let Some(Value::Array(items)) = obj.get("heights_um") else {
        return Err(err(
            "parameter 'profile.heights_um' must be an array of heights in um (one period, uniformly spaced)".into(),
        ));
    };
    let (lo, hi) = range::HEIGHTS_LEN;
    if items.len() < lo || items.len() > hi {
        return Err(err(format!(
            "parameter 'profile.heights_um' has {} samples: accepted {lo} to {hi}",
            items.len()
        )));
    }
    let mut heights = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        match item.as_f64() {
            Some(h) if h.is_finite() && h.abs() <= range::HEIGHT_UM.1 => heights.push(h),
            _ => {
                return Err(err(format!(
                    "parameter 'profile.heights_um[{i}]' must be a finite number in [-{}, {}] um",
                    range::HEIGHT_UM.1,
                    range::HEIGHT_UM.1
                )))
            }
        }
    }
    Ok(heights)
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
            let reader = Reader {
                obj,
                surface: "fresnel",
            };
            let eta = reader
                .ranged("eta", range::ETA, false, "")?
                .ok_or_else(|| {
                    err(format!(
                        "missing key 'eta' in parameter 'fresnel' (accepted range [{}, {}])",
                        range::ETA.0,
                        range::ETA.1
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

    fn message(json: &str) -> String {
        MaterialParams::from_json(json).unwrap_err().message
    }

    #[test]
    fn accepts_each_surface() {
        let p = MaterialParams::from_json(r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2}"#)
            .unwrap();
        assert!(matches!(
            p.surface,
            SurfaceParams::Gaussian {
                anisotropic: false,
                ..
            }
        ));
        let p = MaterialParams::from_json(
            r#"{"surface":"gaussian","sigma_um":0.1,"corr_x_um":2,"corr_y_um":20,"fresnel":0.9}"#,
        )
        .unwrap();
        assert!(matches!(
            p.surface,
            SurfaceParams::Gaussian {
                anisotropic: true,
                ..
            }
        ));
        assert_eq!(p.fresnel, Fresnel::Constant(0.9));
        MaterialParams::from_json(r#"{"surface":"fractal","hurst":0.5,"sigma_um":0.1,"lag_um":1}"#)
            .unwrap();
        let cd = MaterialParams::from_json(r#"{"surface":"cd"}"#).unwrap();
        assert_eq!(
            cd.surface,
            SurfaceParams::Periodic {
                period_um: CD_PERIOD_UM,
                coherence_um: CD_COHERENCE_UM,
                profile: Profile::Rect {
                    height_um: CD_BUMP_HEIGHT_UM,
                    width_um: CD_BUMP_WIDTH_UM
                }
            }
        );
        let cd = MaterialParams::from_json(
            r#"{"surface":"cd","coherence_um":10,"fresnel":{"eta":1.5}}"#,
        )
        .unwrap();
        assert!(
            matches!(cd.surface, SurfaceParams::Periodic { coherence_um, .. } if coherence_um == 10.0)
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
}

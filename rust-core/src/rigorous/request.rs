//! The solver as text: a JSON request (a grating, a wavelength, an incidence)
//! and a JSON answer (every propagating order), for the C ABI
//! (`stam_rigorous_solve`), the Python binding and the comparison tests.
//!
//! Request keys: `period_um`; `profile` ("rect", "sine" or "tabulated") with
//! `height_um`, `width_um` (rect) or `heights_um` (tabulated); `slices`
//! (staircase layers, default 16); `fresnel` (a metal's name or
//! {"eta", "k"}); `cover_eta` (index of the incidence medium, default 1);
//! `lambda_nm`; `theta_deg`, `phi_deg` (azimuth from the grating vector,
//! default 0); `orders` (N: orders -N..N, default 40); `rule` ("li" or
//! "laurent", default "li").

use serde_json::{json, Map, Value};

use super::layers::{Grating, Medium};
use super::solver::{solve_with, Diffraction, Factorisation, Incidence, Order};
use crate::optics::fresnel::metal_by_name;
use crate::optics::profile::Profile;
use crate::StamError;

fn number(obj: &Map<String, Value>, key: &str, default: Option<f64>) -> Result<f64, StamError> {
    match obj.get(key) {
        Some(v) => v
            .as_f64()
            .ok_or_else(|| StamError::new(format!("{key}: expected a number, got {v}"))),
        None => default.ok_or_else(|| StamError::new(format!("{key} is required"))),
    }
}

fn count(obj: &Map<String, Value>, key: &str, default: usize) -> Result<usize, StamError> {
    match obj.get(key) {
        Some(v) => v
            .as_u64()
            .map(|n| n as usize)
            .ok_or_else(|| StamError::new(format!("{key}: expected a whole number >= 0, got {v}"))),
        None => Ok(default),
    }
}

fn medium(value: Option<&Value>) -> Result<Medium, StamError> {
    match value {
        Some(Value::String(name)) => metal_by_name(name).map(Medium::Metal).ok_or_else(|| {
            StamError::new(format!(
                "fresnel: unknown metal {name:?} (accepted: {})",
                crate::optics::fresnel::metal_names().join(", ")
            ))
        }),
        Some(Value::Object(o)) => {
            let eta = number(o, "eta", None)?;
            let k = number(o, "k", Some(0.0))?;
            if !(eta > 0.0 && eta.is_finite() && k >= 0.0 && k.is_finite()) {
                return Err(StamError::new(format!(
                    "fresnel: eta must be > 0 and k >= 0, got eta {eta}, k {k}"
                )));
            }
            Ok(Medium::Index { eta, k })
        }
        Some(v) => Err(StamError::new(format!(
            "fresnel: expected a metal's name or {{\"eta\", \"k\"}}, got {v}"
        ))),
        None => Err(StamError::new("fresnel is required")),
    }
}

/// Parse a request, solve, and answer.
pub fn solve_json(text: &str) -> Result<String, StamError> {
    let value: Value =
        serde_json::from_str(text).map_err(|e| StamError::new(format!("request: {e}")))?;
    let obj = value
        .as_object()
        .ok_or_else(|| StamError::new("request: expected a JSON object"))?;
    let positive = |key: &str, x: f64| {
        if x > 0.0 && x.is_finite() {
            Ok(x)
        } else {
            Err(StamError::new(format!("{key} must be > 0, got {x}")))
        }
    };
    let period_um = positive("period_um", number(obj, "period_um", None)?)?;
    let profile = match obj.get("profile").and_then(Value::as_str).unwrap_or("rect") {
        "rect" => {
            let width_um = number(obj, "width_um", None)?;
            if !(width_um >= 0.0 && width_um <= period_um) {
                return Err(StamError::new(format!(
                    "width_um must be in [0, period_um], got {width_um}"
                )));
            }
            Profile::Rect {
                height_um: positive("height_um", number(obj, "height_um", None)?)?,
                width_um,
            }
        }
        "sine" => Profile::Sine {
            height_um: positive("height_um", number(obj, "height_um", None)?)?,
        },
        "tabulated" => {
            let heights: Option<Vec<f64>> = obj
                .get("heights_um")
                .and_then(Value::as_array)
                .map(|a| a.iter().filter_map(Value::as_f64).collect());
            match heights {
                Some(h) if h.len() >= 2 && h.iter().all(|x| x.is_finite()) => {
                    Profile::Tabulated { heights_um: h }
                }
                _ => {
                    return Err(StamError::new(
                        "heights_um: expected at least 2 finite heights",
                    ))
                }
            }
        }
        other => {
            return Err(StamError::new(format!(
                "profile: expected \"rect\", \"sine\" or \"tabulated\", got {other:?}"
            )))
        }
    };
    let slices = count(obj, "slices", 16)?;
    if !(1..=1000).contains(&slices) {
        return Err(StamError::new(format!(
            "slices must be in 1..=1000, got {slices}"
        )));
    }
    let grating = Grating {
        period_um,
        profile,
        metal: medium(obj.get("fresnel"))?,
        slices,
    };
    let cover_eta = number(obj, "cover_eta", Some(1.0))?;
    let lambda_nm = positive("lambda_nm", number(obj, "lambda_nm", None)?)?;
    let inc = Incidence {
        lambda_nm,
        theta_rad: number(obj, "theta_deg", None)?.to_radians(),
        phi_rad: number(obj, "phi_deg", Some(0.0))?.to_radians(),
    };
    let rule = match obj.get("rule").and_then(Value::as_str).unwrap_or("li") {
        "li" => Factorisation::Li,
        "laurent" => Factorisation::Laurent,
        other => {
            return Err(StamError::new(format!(
                "rule: expected \"li\" or \"laurent\", got {other:?}"
            )))
        }
    };
    let orders = count(obj, "orders", 40)?;
    let d = solve_with(&grating.stack(lambda_nm, cover_eta), &inc, orders, rule)?;
    Ok(answer(&d).to_string())
}

fn order_json(o: &Order) -> Value {
    let c = |z: faer::c64| json!([z.re, z.im]);
    json!({
        "m": o.m,
        "direction": o.direction,
        "efficiency": o.efficiency,
        "jones": [[c(o.jones[0][0]), c(o.jones[0][1])], [c(o.jones[1][0]), c(o.jones[1][1])]],
    })
}

fn answer(d: &Diffraction) -> Value {
    json!({
        "orders": d.n_orders,
        "reflected": d.reflected.iter().map(order_json).collect::<Vec<_>>(),
        "transmitted": d.transmitted.iter().map(order_json).collect::<Vec<_>>(),
        "reflectance": d.reflectance(),
        "transmittance": d.transmittance(),
    })
}

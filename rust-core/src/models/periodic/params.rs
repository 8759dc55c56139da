//! Parameters of a periodic surface and of the compact disc
//! (docs/parameters.md).

use super::Profile;
use crate::error::StamError;
use crate::json::{doc_number, format_bound, nanometre_hint_above, type_name, KeyDoc, Reader};
use crate::program::ParamId;
use serde_json::{json, Map, Value};

/// The compact disc of the paper (Stam's "Used physical dimensions").
pub const CD_PERIOD_UM: f64 = 2.5;
pub const CD_BUMP_HEIGHT_UM: f64 = 0.15;
pub const CD_BUMP_WIDTH_UM: f64 = 0.5;
/// Spatial coherence of ordinary illumination: about lambda / (angular size
/// of the source); a 1 cm lamp at 1 m or the sun give ~50 um at 550 nm.
pub const CD_COHERENCE_UM: f64 = 50.0;

/// Accepted ranges, shared by the validator, the docs and the stress tests.
pub mod range {
    pub const PERIOD_UM: (f64, f64) = (0.05, 1000.0);
    /// As a multiple of the period (lower end) and in um (upper end).
    pub const COHERENCE_MIN_PERIODS: f64 = 1.5;
    pub const COHERENCE_MAX_UM: f64 = 1e4;
    pub const HEIGHT_UM: (f64, f64) = (0.0, 100.0);
    pub const HEIGHTS_LEN: (usize, usize) = (2, 65536);
    /// Fourier orders each side of the rigorous solver (`fourier_orders`).
    pub const FOURIER_ORDERS: (usize, usize) = (5, crate::rigorous::solver::MAX_ORDERS);
    /// Index of a transparent cover over a rigorous grating (`cover_eta`).
    pub const COVER_ETA: (f64, f64) = (1.0, 3.0);
}

/// Where each order's power comes from (`orders`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OrderPowers {
    /// Stam's formula: scalar (Kirchhoff) theory, times Fresnel.
    Kirchhoff,
    /// Maxwell's equations: each order's efficiency from the rigorous
    /// solver (crate::rigorous), tabulated once per grating, with
    /// `fourier_orders` each side (`rigorous::default_fourier_orders` when
    /// not given), under a transparent cover of index `cover_eta` (1: none).
    Rigorous {
        fourier_orders: usize,
        cover_eta: f64,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub struct PeriodicParams {
    pub period_um: f64,
    pub coherence_um: f64,
    pub profile: Profile,
    /// A height texture's largest value (`height_um_max`, sine profile):
    /// the programs then read the height per point and serve every height
    /// up to this.
    pub height_um_max: Option<f64>,
    /// Where each order's power comes from (`orders`).
    pub orders: OrderPowers,
}

fn err(msg: String) -> StamError {
    StamError::new(msg)
}

impl crate::models::ModelParams for PeriodicParams {
    /// "cd": the paper's compact disc, whose keys default to its values.
    const SURFACE_NAMES: &'static [&'static str] = &["periodic", "cd"];

    fn parse(surface: &str, r: &Reader) -> Result<PeriodicParams, StamError> {
        parse_periodic(r, surface == "cd")
    }

    /// The period, the coherence length and the profile's height (not from
    /// a texture) and width; a tabulated profile's heights are not
    /// program parameters.
    fn table_params(&self) -> Vec<(ParamId, f64)> {
        let mut out = vec![
            (ParamId::PeriodUm, self.period_um),
            (ParamId::CoherenceUm, self.coherence_um),
        ];
        let textured = self.height_um_max.is_some();
        match &self.profile {
            Profile::Rect {
                height_um,
                width_um,
            } => {
                if !textured {
                    out.push((ParamId::HeightUm, *height_um));
                }
                out.push((ParamId::WidthUm, *width_um));
            }
            Profile::Sine { height_um } if !textured => out.push((ParamId::HeightUm, *height_um)),
            _ => {}
        }
        out
    }

    /// "cd" gives the disc's defaults; "periodic" requires the keys.
    fn reference(surface: &str) -> Vec<KeyDoc> {
        let cd = surface == "cd";
        let default = |v: Value| cd.then_some(v);
        let coherence = KeyDoc::number(
            "coherence_um",
            "Gaussian coherence length of the illumination",
            "um",
            (range::COHERENCE_MIN_PERIODS, range::COHERENCE_MAX_UM),
            false,
        )
        .min_relative(format!(
            "[{} period_um, {}]",
            range::COHERENCE_MIN_PERIODS,
            doc_number(range::COHERENCE_MAX_UM)
        ))
        .default_or_required(default(json!(CD_COHERENCE_UM)));
        let width = KeyDoc::number("width_um", "bump width per period", "um", (0.0, 0.0), true)
            .max_relative("(0, period_um]".into())
            .default_or_required(default(json!(CD_BUMP_WIDTH_UM)));
        vec![
            KeyDoc::number(
                "period_um",
                "grating period (track pitch)",
                "um",
                range::PERIOD_UM,
                false,
            )
            .default_or_required(default(json!(CD_PERIOD_UM))),
            if cd {
                coherence.note(format!(
                    "at least {} periods",
                    range::COHERENCE_MIN_PERIODS
                ))
            } else {
                coherence
            },
            KeyDoc {
                // (the heights of a tabulated profile)
                unit: "um",
                ..KeyDoc::text(
                "profile",
                "one period of the height profile",
                format!(
                    "\"rect\", \"sine\" or {{\"heights_um\": [...]}} ({} to {} heights over one period, |h| <= {} um)",
                    range::HEIGHTS_LEN.0,
                    range::HEIGHTS_LEN.1,
                    doc_number(range::HEIGHT_UM.1)
                ),
            )
            }
            .default_or_required(default(json!("rect"))),
            KeyDoc::number(
                "height_um",
                "bump height (rect); peak-to-peak height (sine)",
                "um",
                range::HEIGHT_UM,
                true,
            )
            .default_or_required(default(json!(CD_BUMP_HEIGHT_UM)))
            .note("rect and sine profiles"),
            width.note(if cd {
                "rect profile; at most the period"
            } else {
                "rect profile"
            }),
            KeyDoc::number(
                "height_um_max",
                "the largest value of a height texture: the programs serve every height up to it",
                "um",
                range::HEIGHT_UM,
                true,
            )
            .note("sine profile; at least height_um; the plugin sets it from a height_um texture"),
            KeyDoc::text(
                "orders",
                "where each diffraction order's power comes from",
                "\"kirchhoff\" (Stam's formula) or \"rigorous\" (Maxwell's equations, docs/rigorous.md)".into(),
            )
            .default(json!("kirchhoff"))
            .note("rigorous: fresnel a metal or {eta, k}; energy-exact, so 'energy' does not apply; scalar variants"),
            KeyDoc::integer(
                "fourier_orders",
                "Fourier orders each side that the rigorous solver retains",
                range::FOURIER_ORDERS,
            )
            .note("orders \"rigorous\"; default 20, more for periods above 2.5 um / cover_eta"),
            KeyDoc::number(
                "cover_eta",
                "refractive index of a transparent cover over the grating (a real disc's polycarbonate: 1.58)",
                "",
                range::COVER_ETA,
                false,
            )
            .default(json!(1.0))
            .note("orders \"rigorous\"; 1: no cover"),
        ]
    }

    fn resolved(&self, _given: &Map<String, Value>, out: &mut Map<String, Value>) {
        out.insert("period_um".into(), json!(self.period_um));
        out.insert("coherence_um".into(), json!(self.coherence_um));
        match &self.profile {
            Profile::Rect {
                height_um,
                width_um,
            } => {
                out.insert("profile".into(), json!("rect"));
                out.insert("height_um".into(), json!(height_um));
                out.insert("width_um".into(), json!(width_um));
            }
            Profile::Sine { height_um } => {
                out.insert("profile".into(), json!("sine"));
                out.insert("height_um".into(), json!(height_um));
            }
            Profile::Tabulated { heights_um } => {
                out.insert("profile".into(), json!({ "heights_um": heights_um }));
            }
        }
        if let Some(max) = self.height_um_max {
            out.insert("height_um_max".into(), json!(max));
        }
        match self.orders {
            OrderPowers::Kirchhoff => {
                out.insert("orders".into(), json!("kirchhoff"));
            }
            OrderPowers::Rigorous {
                fourier_orders,
                cover_eta,
            } => {
                out.insert("orders".into(), json!("rigorous"));
                out.insert("fourier_orders".into(), json!(fourier_orders));
                out.insert("cover_eta".into(), json!(cover_eta));
            }
        }
    }

    fn with_param(&self, id: ParamId, value: f64) -> PeriodicParams {
        let mut p = self.clone();
        match (id, &mut p.profile) {
            (ParamId::PeriodUm, _) => p.period_um = value,
            (ParamId::CoherenceUm, _) => p.coherence_um = value,
            (ParamId::HeightUm, Profile::Rect { height_um, .. })
            | (ParamId::HeightUm, Profile::Sine { height_um }) => *height_um = value,
            (ParamId::WidthUm, Profile::Rect { width_um, .. }) => *width_um = value,
            _ => {}
        }
        p
    }
}

fn parse_periodic(r: &Reader, compact_disc: bool) -> Result<PeriodicParams, StamError> {
    r.check_keys(&[
        "period_um",
        "coherence_um",
        "profile",
        "height_um",
        "width_um",
        "height_um_max",
        "orders",
        "fourier_orders",
        "cover_eta",
    ])?;
    let defaults = |v: f64| if compact_disc { Some(v) } else { None };
    let period_um = match r.ranged("period_um", range::PERIOD_UM, false, " um")? {
        Some(p) => p,
        None => defaults(CD_PERIOD_UM).ok_or_else(|| {
            err(format!(
                "missing parameter 'period_um' for surface 'periodic' (accepted range [{}, {}] um)",
                format_bound(range::PERIOD_UM.0),
                format_bound(range::PERIOD_UM.1)
            ))
        })?,
    };
    let coherence_lo = range::COHERENCE_MIN_PERIODS * period_um;
    let coherence_range = (coherence_lo, range::COHERENCE_MAX_UM);
    let coherence_um = match r.number("coherence_um")? {
        Some(l) if l < coherence_lo || l > range::COHERENCE_MAX_UM => {
            let hint = nanometre_hint_above("coherence_um", l, coherence_range, false);
            return Err(err(format!(
                "parameter 'coherence_um' = {l} is out of range: accepted [{}, {}] um (at least {} periods: the finite-coherence model needs coherence >> period){}{hint}",
                format_bound(coherence_lo),
                format_bound(range::COHERENCE_MAX_UM),
                range::COHERENCE_MIN_PERIODS,
                if hint.is_empty() { "" } else { "." }
            )))
        }
        Some(l) => l,
        None => defaults(CD_COHERENCE_UM.max(coherence_lo)).ok_or_else(|| {
            err(format!(
                "missing parameter 'coherence_um' for surface 'periodic' (accepted range [{}, {}] um)",
                format_bound(coherence_range.0),
                format_bound(coherence_range.1)
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
    let height_um_max = r.ranged("height_um_max", range::HEIGHT_UM, true, " um")?;
    if let Some(max) = height_um_max {
        match &profile {
            Profile::Sine { height_um } if max < *height_um => {
                return Err(err(format!(
                    "parameter 'height_um_max' ({max}) is below 'height_um' ({height_um}): it is the largest value a height texture gives"
                )))
            }
            Profile::Sine { .. } => {}
            _ => {
                return Err(err(
                    "parameter 'height_um_max' applies to profile 'sine' only (a rect profile's powers are a closed form in the height; a tabulated profile has no height parameter)".into(),
                ))
            }
        }
    }
    let orders = parse_orders(r, period_um, height_um_max)?;
    Ok(PeriodicParams {
        period_um,
        coherence_um,
        profile,
        height_um_max,
        orders,
    })
}

fn parse_orders(
    r: &Reader,
    period_um: f64,
    height_um_max: Option<f64>,
) -> Result<OrderPowers, StamError> {
    let given = r.integer("fourier_orders", range::FOURIER_ORDERS)?;
    let cover = r.ranged("cover_eta", range::COVER_ETA, false, "")?;
    let cover_eta = cover.unwrap_or(1.0);
    let rigorous = match r.obj.get("orders") {
        None => false,
        Some(Value::String(s)) if s == "kirchhoff" => false,
        Some(Value::String(s)) if s == "rigorous" => true,
        Some(other) => {
            return Err(err(format!(
                "parameter 'orders' = {other} is not accepted: \"kirchhoff\" (default: Stam's formula) or \"rigorous\" (Maxwell's equations)"
            )))
        }
    };
    if !rigorous {
        for (key, set) in [
            ("fourier_orders", given.is_some()),
            ("cover_eta", cover.is_some()),
        ] {
            if set {
                return Err(err(format!(
                    "parameter '{key}' applies to \"orders\": \"rigorous\" only"
                )));
            }
        }
        return Ok(OrderPowers::Kirchhoff);
    }
    if height_um_max.is_some() {
        return Err(err(
            "parameter 'height_um_max' (a height texture) cannot be used with \"orders\": \"rigorous\" (its efficiencies are tabulated for one profile)".into(),
        ));
    }
    Ok(OrderPowers::Rigorous {
        fourier_orders: given
            .unwrap_or_else(|| crate::rigorous::default_fourier_orders(period_um, cover_eta)),
        cover_eta,
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

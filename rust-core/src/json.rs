//! Reading parameters from a JSON object, with messages that name the key
//! and its accepted range. Knows no surface model: each model's `params`
//! module says which keys it reads.

use crate::error::{StamError, UnknownKey};
use serde_json::{json, Map, Value};

/// The keys of one surface's parameters.
pub struct Reader<'a> {
    pub obj: &'a Map<String, Value>,
    /// The surface's name, for messages.
    pub surface: &'a str,
    /// Keys every surface accepts (the material's own).
    material_keys: &'a [&'a str],
}

/// A bound as a reader expects it: 1.8 for a computed 1.7999999999999998
/// (12 significant digits; the check itself uses the exact bound).
pub fn format_bound(x: f64) -> String {
    let short = format!("{x:.12e}").parse::<f64>().unwrap_or(x);
    format!("{short}")
}

/// A value as a person would write it (4 significant digits).
pub fn show(x: f64) -> String {
    let short = format!("{x:.3e}").parse::<f64>().unwrap_or(x);
    format!("{short}")
}

/// The hint for a length that may have been meant in nanometres: the same
/// sentence for a refused value (the readers) and an accepted but
/// implausible one (`material::plausibility`).
pub fn nanometre_hint(key: &str, x: f64) -> String {
    format!(
        " If {key} was meant in nanometres, it is {key} = {} (micrometres).",
        show(x / 1000.0)
    )
}

/// `nanometre_hint` for a length `x` above its range [lo, hi] (lo
/// exclusive when `lo_open`) that would lie in it read as nanometres; ""
/// otherwise.
pub fn nanometre_hint_above(key: &str, x: f64, (lo, hi): (f64, f64), lo_open: bool) -> String {
    let um = x / 1000.0;
    let in_range = if lo_open { um > lo } else { um >= lo } && um <= hi;
    if x > hi && in_range {
        nanometre_hint(key, x)
    } else {
        String::new()
    }
}

/// A bound as the reference writes it: 1e-6 and 1e5 rather than 0.000001
/// and 100000 (the readers' messages use `format_bound`).
pub fn doc_number(x: f64) -> String {
    let plain = format_bound(x);
    if x != 0.0 && (x.abs() < 1e-3 || x.abs() >= 1e4) {
        let short = format!("{x:.12e}").parse::<f64>().unwrap_or(x);
        format!("{short:e}")
    } else {
        plain
    }
}

/// One key of the parameter reference (`stam_parameter_reference`, what
/// `python -m stam_diffraction --help` lists), made from the same range
/// constants as the readers' checks.
#[derive(Clone, Debug)]
pub struct KeyDoc {
    pub key: &'static str,
    /// What it is, in a few words.
    pub meaning: &'static str,
    /// "um" (micrometres) or "" (dimensionless, a name).
    pub unit: &'static str,
    /// The numeric bounds (None: no number, or a bound relative to another
    /// key, which `accepted` states).
    pub min: Option<f64>,
    pub max: Option<f64>,
    /// Whether `min` itself is refused.
    pub min_open: bool,
    pub integer: bool,
    /// What is accepted, in words.
    pub accepted: String,
    /// Whether the key must be given.
    pub required: bool,
    /// The value taken when the key is left out (None: required, or none).
    pub default: Option<Value>,
    /// More about the default or where the key applies ("" for nothing).
    pub note: String,
}

impl KeyDoc {
    /// A number in [lo, hi] (lo exclusive when `lo_open`), as `Reader::ranged`
    /// checks it; not required and without a default until said.
    pub fn number(
        key: &'static str,
        meaning: &'static str,
        unit: &'static str,
        (lo, hi): (f64, f64),
        lo_open: bool,
    ) -> KeyDoc {
        let open = if lo_open { "(" } else { "[" };
        KeyDoc {
            key,
            meaning,
            unit,
            min: Some(lo),
            max: Some(hi),
            min_open: lo_open,
            integer: false,
            accepted: format!("{open}{}, {}]", doc_number(lo), doc_number(hi)),
            required: false,
            default: None,
            note: String::new(),
        }
    }

    /// An integer in [lo, hi], as `Reader::integer` checks it.
    pub fn integer(key: &'static str, meaning: &'static str, (lo, hi): (usize, usize)) -> KeyDoc {
        KeyDoc {
            integer: true,
            accepted: format!("an integer in [{lo}, {hi}]"),
            ..KeyDoc::number(key, meaning, "", (lo as f64, hi as f64), false)
        }
    }

    /// A key whose values are words (or a form `accepted` describes).
    pub fn text(key: &'static str, meaning: &'static str, accepted: String) -> KeyDoc {
        KeyDoc {
            key,
            meaning,
            unit: "",
            min: None,
            max: None,
            min_open: false,
            integer: false,
            accepted,
            required: false,
            default: None,
            note: String::new(),
        }
    }

    pub fn required(self) -> KeyDoc {
        KeyDoc {
            required: true,
            ..self
        }
    }

    pub fn default(self, value: Value) -> KeyDoc {
        KeyDoc {
            default: Some(value),
            ..self
        }
    }

    /// `required` or `default(value)`: a key that some surfaces default.
    pub fn default_or_required(self, value: Option<Value>) -> KeyDoc {
        match value {
            Some(v) => self.default(v),
            None => self.required(),
        }
    }

    pub fn note(self, note: impl Into<String>) -> KeyDoc {
        KeyDoc {
            note: note.into(),
            ..self
        }
    }

    /// The lower bound as a multiple of another key (`min` then None).
    pub fn min_relative(self, accepted: String) -> KeyDoc {
        KeyDoc {
            min: None,
            accepted,
            ..self
        }
    }

    /// The upper bound as another key (`max` then None).
    pub fn max_relative(self, accepted: String) -> KeyDoc {
        KeyDoc {
            max: None,
            accepted,
            ..self
        }
    }

    pub fn to_json(&self) -> Value {
        json!({
            "key": self.key,
            "meaning": self.meaning,
            "unit": self.unit,
            "min": self.min,
            "max": self.max,
            "min_open": self.min_open,
            "integer": self.integer,
            "accepted": self.accepted,
            "required": self.required,
            "default": self.default,
            "note": self.note,
        })
    }
}

impl<'a> Reader<'a> {
    pub fn new(
        obj: &'a Map<String, Value>,
        surface: &'a str,
        material_keys: &'a [&'a str],
    ) -> Self {
        Reader {
            obj,
            surface,
            material_keys,
        }
    }

    /// Refuses, by name, any key that is neither the material's nor in
    /// `allowed`, listing every accepted key.
    pub fn check_keys(&self, allowed: &[&str]) -> Result<(), StamError> {
        for key in self.obj.keys() {
            if !self.material_keys.contains(&key.as_str()) && !allowed.contains(&key.as_str()) {
                let accepted = self.material_keys.iter().chain(allowed);
                return Err(StamError::unknown_key(UnknownKey {
                    key: key.clone(),
                    surface: self.surface.to_string(),
                    accepted: accepted.map(|k| k.to_string()).collect(),
                }));
            }
        }
        Ok(())
    }

    pub fn number(&self, key: &str) -> Result<Option<f64>, StamError> {
        match self.obj.get(key) {
            None => Ok(None),
            Some(Value::Number(n)) => match n.as_f64() {
                Some(x) if x.is_finite() => Ok(Some(x)),
                _ => Err(StamError::new(format!(
                    "parameter '{key}' must be a finite number"
                ))),
            },
            Some(other) => Err(StamError::new(format!(
                "parameter '{key}' must be a number, got {}",
                type_name(other)
            ))),
        }
    }

    /// A number in [lo, hi] (lo exclusive when `lo_open`).
    pub fn ranged(
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
            // A length far above its range may be nanometres written as
            // micrometres: the same hint as for an accepted one.
            let hint = match unit.starts_with(" um") {
                true => nanometre_hint_above(key, x, (lo, hi), lo_open),
                false => String::new(),
            };
            let stop = if hint.is_empty() { "" } else { "." };
            return Err(StamError::new(format!(
                "parameter '{key}' = {x} is out of range: accepted {open}{}, {}]{unit}{stop}{hint}",
                format_bound(lo),
                format_bound(hi)
            )));
        }
        Ok(Some(x))
    }

    pub fn required(
        &self,
        key: &str,
        range: (f64, f64),
        lo_open: bool,
        unit: &str,
    ) -> Result<f64, StamError> {
        self.ranged(key, range, lo_open, unit)?.ok_or_else(|| {
            StamError::new(format!(
                "missing parameter '{key}' for surface '{}' (accepted range [{}, {}]{unit})",
                self.surface,
                format_bound(range.0),
                format_bound(range.1)
            ))
        })
    }

    /// A string, refused by name when it is another type or empty.
    pub fn string(&self, key: &str) -> Result<Option<String>, StamError> {
        match self.obj.get(key) {
            None => Ok(None),
            Some(Value::String(s)) if !s.is_empty() => Ok(Some(s.clone())),
            Some(Value::String(_)) => Err(StamError::new(format!(
                "parameter '{key}' must not be empty"
            ))),
            Some(other) => Err(StamError::new(format!(
                "parameter '{key}' must be a string, got {}",
                type_name(other)
            ))),
        }
    }

    /// An integer in [lo, hi].
    pub fn integer(&self, key: &str, (lo, hi): (usize, usize)) -> Result<Option<usize>, StamError> {
        match self.number(key)? {
            None => Ok(None),
            Some(x) if x.fract() != 0.0 || x < lo as f64 || x > hi as f64 => {
                Err(StamError::new(format!(
                    "parameter '{key}' = {x} is out of range: accepted an integer in [{lo}, {hi}]"
                )))
            }
            Some(x) => Ok(Some(x as usize)),
        }
    }
}

pub fn type_name(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

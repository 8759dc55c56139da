//! Reading parameters from a JSON object, with messages that name the key
//! and its accepted range. Knows no surface model: each model's `params`
//! module says which keys it reads.

use crate::error::StamError;
use serde_json::{Map, Value};

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
                let mut accepted: Vec<&str> = self.material_keys.to_vec();
                accepted.extend_from_slice(allowed);
                return Err(StamError::new(format!(
                    "unknown parameter '{key}' for surface '{}' (accepted: {})",
                    self.surface,
                    accepted.join(", ")
                )));
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
            return Err(StamError::new(format!(
                "parameter '{key}' = {x} is out of range: accepted {open}{}, {}]{unit}",
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

//! The project's shared list of test materials, tests/materials.json: a JSON
//! array of entries {name, label (optional), model, tags, params, note
//! (optional)}, described in scripts/stam_materials.py. The Pareto survey
//! takes the entries tagged `pareto`, the JSON fuzz test those tagged `fuzz`,
//! each in file order.

use serde_json::Value;
use std::sync::OnceLock;

/// The file's text, compiled in.
pub const JSON: &str = include_str!("../../../tests/materials.json");

/// One entry of the list.
#[derive(Clone, Debug)]
pub struct Material {
    /// Unique identifier.
    pub name: String,
    /// The short name its users show: `label` where given, else `name`.
    pub label: String,
    /// Surface model family: gaussian, fractal or periodic (cd included).
    pub model: String,
    pub tags: Vec<String>,
    /// The core's JSON parameters, as text for `stam_brdf_new` /
    /// `Brdf::from_json`.
    pub params: String,
}

fn text(entry: &Value, key: &str) -> String {
    entry[key]
        .as_str()
        .unwrap_or_else(|| panic!("tests/materials.json: {key} of {entry} is not a string"))
        .to_string()
}

/// Every entry, in file order (parsed once).
pub fn all() -> &'static [Material] {
    static LIST: OnceLock<Vec<Material>> = OnceLock::new();
    LIST.get_or_init(|| {
        let entries: Vec<Value> =
            serde_json::from_str(JSON).expect("tests/materials.json is a JSON array");
        entries
            .iter()
            .map(|e| {
                let name = text(e, "name");
                Material {
                    label: e["label"]
                        .as_str()
                        .map_or_else(|| name.clone(), String::from),
                    name,
                    model: text(e, "model"),
                    tags: e["tags"]
                        .as_array()
                        .expect("tests/materials.json: tags is an array")
                        .iter()
                        .map(|t| t.as_str().expect("a tag is a string").to_string())
                        .collect(),
                    params: e["params"].to_string(),
                }
            })
            .collect()
    })
}

/// The entries carrying `tag`, in file order.
pub fn tagged(tag: &str) -> Vec<&'static Material> {
    all()
        .iter()
        .filter(|m| m.tags.iter().any(|t| t == tag))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_unique_and_labels_unique_per_tag() {
        let mut names: Vec<&str> = all().iter().map(|m| m.name.as_str()).collect();
        let n = names.len();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), n, "a name used twice");
        for tag in all().iter().flat_map(|m| m.tags.iter()) {
            let mut labels: Vec<&str> = tagged(tag).iter().map(|m| m.label.as_str()).collect();
            let n = labels.len();
            labels.sort();
            labels.dedup();
            assert_eq!(labels.len(), n, "a label used twice in tag {tag}");
        }
    }

    #[test]
    fn every_material_is_accepted_by_the_core() {
        for m in all() {
            if let Err(e) = stam::Brdf::from_json(&m.params) {
                panic!("{}: {e}", m.name);
            }
        }
    }
}

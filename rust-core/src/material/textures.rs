//! Textures on a material's numbers (JIT hosts): which parameters take one,
//! what the material is then built for, and the range each point's value is
//! clamped into. The host reads its texture (the largest finite value, the
//! mean) and passes a value per point to the programs (`Op::Param`); the
//! policy is the core's, so that the plugin and Python hold no copy of it
//! (`stam_param_takes_texture`, `stam_texture_plan`).

use serde_json::{json, Map, Value};

use super::params::{json_object, MaterialParams};
use crate::error::StamError;
use crate::models::periodic::params::range::HEIGHT_UM;
use crate::models::SurfaceParams;
use crate::optics::profile::Profile;
use crate::program::ParamId;

/// The parameters that take a texture, each with where it may.
const TEXTURED: [(ParamId, &str); 2] = [
    (ParamId::SigmaUm, "only on surface \"gaussian\"; other surfaces take a number"),
    (
        ParamId::HeightUm,
        "only with the rect and sine profiles (surface \"cd\", or \"periodic\" with profile \"rect\" or \"sine\")",
    ),
];

/// A sigma texture's floor: zero, negative and NaN values read as a mirror.
const SIGMA_FLOOR_UM: f64 = 1e-6;

/// How a host applies a texture on one parameter.
#[derive(Clone, Debug, PartialEq)]
pub struct TexturePlan {
    pub param: ParamId,
    /// Keys to add to the material's parameters: the parameter itself (the
    /// texture's mean, clamped into range: where one value is needed, such
    /// as the sampling's constants) and the largest value the programs are
    /// built for (`sigma_um_max`, `height_um_max`) unless given.
    pub add: Map<String, Value>,
    /// Each point's value is clamped into [range.0, range.1]; NaN reads as
    /// range.0.
    pub range: (f64, f64),
}

/// Whether the parameter `name` takes a texture on some material.
pub fn takes_texture(name: &str) -> bool {
    TEXTURED.iter().any(|(id, _)| id.name() == name)
}

/// The texture plan of parameter `name` on the material `params_json`
/// (the textured key left out) for a texture whose largest finite value is
/// `largest` and whose mean is `mean`: refused, naming the parameter, where
/// the material cannot take it.
pub fn texture_plan(
    params_json: &str,
    name: &str,
    largest: f64,
    mean: f64,
) -> Result<TexturePlan, StamError> {
    let Some(&(param, scope)) = TEXTURED.iter().find(|(id, _)| id.name() == name) else {
        let names: Vec<String> = TEXTURED
            .iter()
            .map(|(id, _)| format!("'{}'", id.name()))
            .collect();
        return Err(StamError::new(format!(
            "parameter '{name}' cannot take a texture (of the core's parameters only {} can)",
            names.join(" and ")
        )));
    };
    if !(largest > 0.0 && largest.is_finite()) {
        return Err(StamError::new(format!(
            "parameter '{name}': the texture's largest value is {largest}; it must be positive somewhere"
        )));
    }
    let given = json_object(params_json)?;
    let parse = |extra: &Map<String, Value>| {
        let mut obj = given.clone();
        obj.extend(extra.clone());
        MaterialParams::from_object(&obj)
    };
    // The material as if the largest value were given as a number; where
    // that is refused, the material without the key tells whether the
    // texture is out of place (then that is the message) or its value is.
    // (A given bound below the largest value clamps the texture.)
    let bound_key = format!("{name}_max");
    let given_bound = given.get(&bound_key).and_then(Value::as_f64);
    let probe = given_bound.map_or(largest, |bound| largest.min(bound));
    let out_of_place = StamError::new(format!("parameter '{name}' takes a texture {scope}"));
    let surface = match parse(&Map::from_iter([(name.to_string(), json!(probe))])) {
        Ok(p) => p.surface,
        Err(e) if e.unknown_key.as_ref().is_some_and(|u| u.key == name) => {
            return Err(out_of_place)
        }
        Err(e) => match parse(&Map::new()) {
            Ok(p) if !fits(param, &p.surface) => p.surface,
            _ => return Err(e),
        },
    };
    if !fits(param, &surface) {
        return Err(out_of_place);
    }
    // The programs serve every value up to `max`: a sigma's and a sine's
    // height's (given or the texture's largest); a rect's powers are a
    // closed form in the height, served up to the core's bound.
    let rect =
        matches!(&surface, SurfaceParams::Periodic(p) if matches!(p.profile, Profile::Rect { .. }));
    let mut add = Map::new();
    let max = match (rect, given_bound) {
        (true, _) => largest,
        (false, Some(bound)) => bound,
        (false, None) => {
            add.insert(bound_key, json!(largest));
            largest
        }
    };
    let floor = match param {
        ParamId::SigmaUm => SIGMA_FLOOR_UM,
        _ => 0.0,
    };
    // The parameter itself is at least SIGMA_FLOOR_UM (the core refuses a
    // zero sigma or height).
    let value = if mean.is_finite() && mean > 0.0 {
        mean.clamp(SIGMA_FLOOR_UM, max.max(SIGMA_FLOOR_UM))
    } else {
        max
    };
    add.insert(name.to_string(), json!(value));
    // Refused here, by the core's own checks, rather than at the build.
    parse(&add)?;
    let top = if rect { HEIGHT_UM.1 } else { max };
    Ok(TexturePlan {
        param,
        add,
        range: (floor, top),
    })
}

/// Whether `surface` takes a texture on `param`.
fn fits(param: ParamId, surface: &SurfaceParams) -> bool {
    match (param, surface) {
        (ParamId::SigmaUm, SurfaceParams::Gaussian(_)) => true,
        (ParamId::HeightUm, SurfaceParams::Periodic(p)) => {
            matches!(p.profile, Profile::Rect { .. } | Profile::Sine { .. })
        }
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GAUSSIAN: &str = r#"{"surface":"gaussian","corr_um":2,"fresnel":0.9}"#;
    const ROUGH: &str = r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2,"fresnel":0.9}"#;

    fn plan(params: &str, name: &str, largest: f64, mean: f64) -> Result<TexturePlan, String> {
        texture_plan(params, name, largest, mean).map_err(|e| e.to_string())
    }

    #[test]
    fn a_sigma_map_builds_for_its_largest_value() {
        let p = plan(GAUSSIAN, "sigma_um", 0.3, 0.1).unwrap();
        assert_eq!(p.param, ParamId::SigmaUm);
        assert_eq!(p.add["sigma_um"], json!(0.1));
        assert_eq!(p.add["sigma_um_max"], json!(0.3));
        assert_eq!(p.range, (SIGMA_FLOOR_UM, 0.3));
        // A given bound is kept (and clamps the mean).
        let given = r#"{"surface":"gaussian","corr_um":2,"fresnel":0.9,"sigma_um_max":0.05}"#;
        let p = plan(given, "sigma_um", 0.3, 0.1).unwrap();
        assert!(!p.add.contains_key("sigma_um_max"));
        assert_eq!(p.add["sigma_um"], json!(0.05));
        assert_eq!(p.range, (SIGMA_FLOOR_UM, 0.05));
        // No mean (NaN or zero): the largest value.
        assert_eq!(
            plan(GAUSSIAN, "sigma_um", 0.3, f64::NAN).unwrap().add["sigma_um"],
            json!(0.3)
        );
    }

    #[test]
    fn a_height_map_on_rect_and_sine() {
        let rect = plan(r#"{"surface":"cd"}"#, "height_um", 0.2, 0.12).unwrap();
        assert_eq!(
            rect.add,
            Map::from_iter([("height_um".into(), json!(0.12))])
        );
        assert_eq!(rect.range, (0.0, HEIGHT_UM.1));
        let sine = r#"{"surface":"periodic","profile":"sine","period_um":1.6,"coherence_um":6}"#;
        let p = plan(sine, "height_um", 0.2, 0.12).unwrap();
        assert_eq!(p.add["height_um_max"], json!(0.2));
        assert_eq!(p.range, (0.0, 0.2));
    }

    #[test]
    fn misplaced_textures_are_refused_by_name() {
        let m = plan(GAUSSIAN, "corr_x_um", 1.0, 1.0).unwrap_err();
        assert!(m.contains("'corr_x_um' cannot take a texture"), "{m}");
        let m = plan(r#"{"surface":"cd"}"#, "sigma_um", 0.1, 0.1).unwrap_err();
        assert!(
            m.contains("'sigma_um' takes a texture only on surface \"gaussian\""),
            "{m}"
        );
        let tabulated = r#"{"surface":"periodic","period_um":1.2,"coherence_um":6,"profile":{"heights_um":[0,0.1,0.05]}}"#;
        let m = plan(tabulated, "height_um", 0.1, 0.1).unwrap_err();
        assert!(
            m.contains("'height_um' takes a texture only with the rect and sine profiles"),
            "{m}"
        );
        let m = plan(ROUGH, "height_um", 0.1, 0.1).unwrap_err();
        assert!(
            m.contains("'height_um' takes a texture only with the rect"),
            "{m}"
        );
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let m = plan(GAUSSIAN, "sigma_um", bad, 0.1).unwrap_err();
            assert!(m.contains("must be positive somewhere"), "{m}");
        }
    }

    #[test]
    fn the_materials_own_checks_still_apply() {
        // A sigma texture has no one sigma for the energy table.
        let conserving =
            r#"{"surface":"gaussian","corr_um":2,"fresnel":0.9,"energy":"conserving"}"#;
        let m = plan(conserving, "sigma_um", 0.3, 0.1).unwrap_err();
        assert!(m.contains("'sigma_um_max' (a sigma texture)"), "{m}");
        // A value out of the parameter's range is the parameter's message.
        let m = plan(GAUSSIAN, "sigma_um", 250.0, 100.0).unwrap_err();
        assert!(m.contains("sigma_um"), "{m}");
        assert!(plan("[1]", "sigma_um", 0.1, 0.1)
            .unwrap_err()
            .contains("JSON object"));
    }

    #[test]
    fn takes_texture_names_the_two() {
        assert!(takes_texture("sigma_um") && takes_texture("height_um"));
        assert!(!takes_texture("corr_um") && !takes_texture("twist") && !takes_texture(""));
    }
}

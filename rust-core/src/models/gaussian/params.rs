//! Parameters of a Gaussian surface (docs/parameters.md).

use super::series::DEFAULT_SERIES_TOLERANCE;
use crate::error::StamError;
use crate::json::{format_bound, KeyDoc, Reader};
use crate::models::MAX_RGB_NODES;
use crate::program::ParamId;
use serde_json::{json, Map, Value};

/// Accepted ranges, shared by the validator, the docs and the stress tests.
pub mod range {
    pub const SIGMA_UM: (f64, f64) = (1e-6, 100.0);
    pub const CORR_UM: (f64, f64) = (1e-3, 1e5);
    pub const SERIES_TOLERANCE: (f64, f64) = (1e-12, 0.1);
    pub const RGB_NODES: (usize, usize) = (4, crate::models::MAX_RGB_NODES);
}

/// Default node count of the RGB rule (and of the coherent lobe's).
pub const DEFAULT_RGB_NODES: usize = 12;

#[derive(Clone, Debug, PartialEq)]
pub struct GaussianParams {
    pub sigma_um: f64,
    pub corr_x_um: f64,
    pub corr_y_um: f64,
    pub anisotropic: bool,
    /// Relative truncation tolerance of the exact series.
    pub series_tolerance: f64,
    /// Wavelength nodes of the RGB rule.
    pub rgb_nodes: usize,
    /// The largest sigma a renderer's texture gives (per point, through the
    /// programs' parameter): the programs serve every sigma up to it.
    pub sigma_um_max: Option<f64>,
}

const _: () = assert!(range::RGB_NODES.1 <= MAX_RGB_NODES);

impl crate::models::ModelParams for GaussianParams {
    const SURFACE_NAMES: &'static [&'static str] = &["gaussian"];

    fn rgb_nodes(&self) -> usize {
        self.rgb_nodes
    }

    /// sigma (not from a texture) and the correlation lengths, as
    /// `GaussianSurface::params_program` reads them.
    fn table_params(&self) -> Vec<(ParamId, f64)> {
        let mut out = Vec::new();
        if self.sigma_um_max.is_none() {
            out.push((ParamId::SigmaUm, self.sigma_um));
        }
        if self.anisotropic {
            out.push((ParamId::CorrXUm, self.corr_x_um));
            out.push((ParamId::CorrYUm, self.corr_y_um));
        } else {
            out.push((ParamId::CorrUm, self.corr_x_um));
        }
        out
    }

    fn with_param(&self, id: ParamId, value: f64) -> GaussianParams {
        let mut p = self.clone();
        match id {
            ParamId::SigmaUm => p.sigma_um = value,
            ParamId::CorrUm => (p.corr_x_um, p.corr_y_um) = (value, value),
            ParamId::CorrXUm => p.corr_x_um = value,
            ParamId::CorrYUm => p.corr_y_um = value,
            _ => {}
        }
        p
    }

    fn reference(_surface: &str) -> Vec<KeyDoc> {
        let corr = "give 'corr_um' (isotropic), or both 'corr_x_um' and 'corr_y_um' (anisotropic)";
        vec![
            KeyDoc::number("sigma_um", "rms height", "um", range::SIGMA_UM, false).required(),
            KeyDoc::number(
                "corr_um",
                "correlation length T (isotropic)",
                "um",
                range::CORR_UM,
                false,
            )
            .note(corr),
            KeyDoc::number(
                "corr_x_um",
                "correlation length along the tangent (x: the tracks' direction; anisotropic, brushed metal)",
                "um",
                range::CORR_UM,
                false,
            )
            .note(corr),
            KeyDoc::number(
                "corr_y_um",
                "correlation length along the bitangent (y; anisotropic)",
                "um",
                range::CORR_UM,
                false,
            )
            .note(corr),
            KeyDoc::number(
                "series_tolerance",
                "relative truncation tolerance of the Poisson series",
                "",
                range::SERIES_TOLERANCE,
                false,
            )
            .default(json!(DEFAULT_SERIES_TOLERANCE)),
            KeyDoc::integer(
                "rgb_nodes",
                "wavelength nodes of the RGB rule",
                range::RGB_NODES,
            )
            .default(json!(DEFAULT_RGB_NODES)),
            KeyDoc::number(
                "sigma_um_max",
                "the largest value of a sigma texture: the programs serve every sigma up to it",
                "um",
                range::SIGMA_UM,
                false,
            )
            .note("at least sigma_um; the plugin sets it from a sigma_um texture"),
        ]
    }

    fn resolved(&self, given: &Map<String, Value>, out: &mut Map<String, Value>) {
        out.insert("sigma_um".into(), json!(self.sigma_um));
        // Equal corr_x_um and corr_y_um are an isotropic surface given in
        // the anisotropic form: kept in the form given.
        if self.anisotropic || given.contains_key("corr_x_um") || given.contains_key("corr_y_um") {
            out.insert("corr_x_um".into(), json!(self.corr_x_um));
            out.insert("corr_y_um".into(), json!(self.corr_y_um));
        } else {
            out.insert("corr_um".into(), json!(self.corr_x_um));
        }
        out.insert("series_tolerance".into(), json!(self.series_tolerance));
        out.insert("rgb_nodes".into(), json!(self.rgb_nodes));
        if let Some(max) = self.sigma_um_max {
            out.insert("sigma_um_max".into(), json!(max));
        }
    }

    fn parse(_surface: &str, r: &Reader) -> Result<GaussianParams, StamError> {
        r.check_keys(&[
            "sigma_um",
            "corr_um",
            "corr_x_um",
            "corr_y_um",
            "series_tolerance",
            "rgb_nodes",
            "sigma_um_max",
        ])?;
        let sigma_um = r.required("sigma_um", range::SIGMA_UM, false, " um")?;
        let sigma_um_max = r.ranged("sigma_um_max", range::SIGMA_UM, false, " um")?;
        if let Some(max) = sigma_um_max {
            if max < sigma_um {
                return Err(StamError::new(format!(
                    "parameter 'sigma_um_max' ({max}) is below 'sigma_um' ({sigma_um}): it is the largest value a sigma texture gives"
                )));
            }
        }
        let corr = r.ranged("corr_um", range::CORR_UM, false, " um")?;
        let corr_x = r.ranged("corr_x_um", range::CORR_UM, false, " um")?;
        let corr_y = r.ranged("corr_y_um", range::CORR_UM, false, " um")?;
        let (lo, hi) = (
            format_bound(range::CORR_UM.0),
            format_bound(range::CORR_UM.1),
        );
        let (corr_x_um, corr_y_um, anisotropic) = match (corr, corr_x, corr_y) {
            (Some(t), None, None) => (t, t, false),
            (None, Some(tx), Some(ty)) => (tx, ty, tx != ty),
            (Some(_), _, _) => {
                return Err(StamError::new(
                    "give either 'corr_um' (isotropic) or 'corr_x_um' and 'corr_y_um' (anisotropic), not both"
                        .to_string(),
                ))
            }
            (None, Some(_), None) => return Err(StamError::new(format!(
                "missing parameter 'corr_y_um' (anisotropic surfaces need both 'corr_x_um' and 'corr_y_um', each in [{lo}, {hi}] um)"
            ))),
            (None, None, Some(_)) => return Err(StamError::new(format!(
                "missing parameter 'corr_x_um' (anisotropic surfaces need both 'corr_x_um' and 'corr_y_um', each in [{lo}, {hi}] um)"
            ))),
            (None, None, None) => return Err(StamError::new(format!(
                "missing parameter 'corr_um' for surface 'gaussian' (accepted range [{lo}, {hi}] um; or 'corr_x_um' and 'corr_y_um' for an anisotropic surface)"
            ))),
        };
        Ok(GaussianParams {
            sigma_um,
            corr_x_um,
            corr_y_um,
            anisotropic,
            series_tolerance: r
                .ranged("series_tolerance", range::SERIES_TOLERANCE, false, "")?
                .unwrap_or(DEFAULT_SERIES_TOLERANCE),
            rgb_nodes: r
                .integer("rgb_nodes", range::RGB_NODES)?
                .unwrap_or(DEFAULT_RGB_NODES),
            sigma_um_max,
        })
    }
}

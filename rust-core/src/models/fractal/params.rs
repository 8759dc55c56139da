//! Parameters of a fractal surface (docs/parameters.md).

use crate::error::StamError;
use crate::json::{KeyDoc, Reader};
use crate::program::ParamId;
use serde_json::{json, Map, Value};

/// Accepted ranges, shared by the validator, the docs and the stress tests.
pub mod range {
    pub const SIGMA_UM: (f64, f64) = (1e-6, 100.0);
    pub const LAG_UM: (f64, f64) = (1e-3, 1e5);
    /// Below 1e-3 the stable-law profile (alpha = 2 hurst) takes minutes to
    /// tabulate (from about 3e-4) or cannot be tabulated at all; such surfaces
    /// are flat to within r^0.002 and are refused.
    pub const HURST: (f64, f64) = (1e-3, 1.0);
    pub const RGB_NODES: (usize, usize) = (4, crate::models::MAX_RGB_NODES);
}

/// Default node count of the RGB rule: fractal spectra are smoother than
/// Gaussian ones, and 8 nodes reach the same 2-3e-5 error at two thirds of
/// the cost of 12 (docs/accuracy_speed.md).
pub const DEFAULT_RGB_NODES: usize = 8;

#[derive(Clone, Debug, PartialEq)]
pub struct FractalParams {
    pub hurst: f64,
    pub sigma_um: f64,
    pub lag_um: f64,
    /// Wavelength nodes of the RGB rule.
    pub rgb_nodes: usize,
}

impl crate::models::ModelParams for FractalParams {
    const SURFACE_NAMES: &'static [&'static str] = &["fractal"];

    fn rgb_nodes(&self) -> usize {
        self.rgb_nodes
    }

    /// sigma and the lag (hurst is not a program parameter).
    fn table_params(&self) -> Vec<(ParamId, f64)> {
        vec![
            (ParamId::SigmaUm, self.sigma_um),
            (ParamId::LagUm, self.lag_um),
        ]
    }

    fn with_param(&self, id: ParamId, value: f64) -> FractalParams {
        let mut p = self.clone();
        match id {
            ParamId::SigmaUm => p.sigma_um = value,
            ParamId::LagUm => p.lag_um = value,
            _ => {}
        }
        p
    }

    fn reference(_surface: &str) -> Vec<KeyDoc> {
        vec![
            KeyDoc::number(
                "hurst",
                "Hurst exponent H (fractal dimension 3 - H)",
                "",
                range::HURST,
                false,
            )
            .required(),
            KeyDoc::number(
                "sigma_um",
                "rms height difference over lag_um",
                "um",
                range::SIGMA_UM,
                false,
            )
            .required(),
            KeyDoc::number(
                "lag_um",
                "lag at which the rms height difference is sigma_um",
                "um",
                range::LAG_UM,
                false,
            )
            .required(),
            KeyDoc::integer(
                "rgb_nodes",
                "wavelength nodes of the RGB rule",
                range::RGB_NODES,
            )
            .default(json!(DEFAULT_RGB_NODES)),
        ]
    }

    fn resolved(&self, _given: &Map<String, Value>, out: &mut Map<String, Value>) {
        out.insert("hurst".into(), json!(self.hurst));
        out.insert("sigma_um".into(), json!(self.sigma_um));
        out.insert("lag_um".into(), json!(self.lag_um));
        out.insert("rgb_nodes".into(), json!(self.rgb_nodes));
    }

    fn parse(_surface: &str, r: &Reader) -> Result<FractalParams, StamError> {
        r.check_keys(&["hurst", "sigma_um", "lag_um", "rgb_nodes"])?;
        Ok(FractalParams {
            hurst: r.required("hurst", range::HURST, false, "")?,
            sigma_um: r.required("sigma_um", range::SIGMA_UM, false, " um")?,
            lag_um: r.required("lag_um", range::LAG_UM, false, " um")?,
            rgb_nodes: r
                .integer("rgb_nodes", range::RGB_NODES)?
                .unwrap_or(DEFAULT_RGB_NODES),
        })
    }
}

//! The core side of the comparison: f / G with fresnel = 1, i.e. the core's
//! kernel K = k^2 / (4 pi^2 w^2) <|P|^2>/A.
//!
//! Preferred route: `stam::Brdf::from_json(..).eval_spectral(wi, wo, lambda)`
//! divided by G. While the core's colour module is still a stand-in that
//! panics when a `Brdf` is built (spectrum branch not merged), the same
//! kernel is reached through the surface model that `Brdf::new` would build
//! (`MaterialParams::from_json` -> the model's `kernel(k, &PairGeometry)`):
//! identical numbers with F^2 = 1, minus the final non-negative guard.

use glam::DVec3;
use stam::geometry::PairGeometry;
use stam::params::{MaterialParams, SurfaceParams};

/// Prefix of the route of an unavailable core.
pub const UNAVAILABLE: &str = "core unavailable";

pub enum Core {
    Brdf(Box<stam::Brdf>),
    Gaussian(stam::gaussian::GaussianSurface),
    Fractal(stam::fractal::FractalSurface),
    Periodic(stam::periodic::PeriodicSurface),
    /// The core refused the parameters (e.g. a model still a stand-in): the
    /// ground truth is still computed and reported, without a comparison.
    Unavailable(String),
}

/// Whether `Brdf::new` works (the colour module's rule is implemented).
fn brdf_available() -> bool {
    static OK: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *OK.get_or_init(|| {
        let hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(|_| {}));
        let ok = std::panic::catch_unwind(|| {
            stam::spectrum::smooth_rule(stam::params::DEFAULT_RGB_NODES);
        })
        .is_ok();
        std::panic::set_hook(hook);
        ok
    })
}

/// The material's JSON with `"energy": "stam"` (unless it says otherwise).
fn with_stam_energy(json: &str) -> String {
    match serde_json::from_str::<serde_json::Value>(json) {
        Ok(serde_json::Value::Object(mut obj)) => {
            obj.entry("energy")
                .or_insert_with(|| serde_json::Value::String("stam".into()));
            serde_json::Value::Object(obj).to_string()
        }
        _ => json.to_string(),
    }
}

impl Core {
    /// The core for these parameters, or `Unavailable` with the core's message.
    pub fn new(json: &str) -> Core {
        Core::from_json(json).unwrap_or_else(Core::Unavailable)
    }

    pub fn from_json(json: &str) -> Result<Core, String> {
        // The ground truth is for the paper's formula (Kirchhoff), not for
        // the energy-conserving default (docs/energy.md).
        let json = &with_stam_energy(json);
        if brdf_available() {
            return stam::Brdf::from_json(json)
                .map(|b| Core::Brdf(Box::new(b)))
                .map_err(|e| e.message);
        }
        let params = MaterialParams::from_json(json).map_err(|e| e.message)?;
        Ok(match params.surface {
            SurfaceParams::Gaussian(p) => Core::Gaussian(if p.anisotropic {
                stam::gaussian::GaussianSurface::anisotropic(p.sigma_um, p.corr_x_um, p.corr_y_um)
            } else {
                stam::gaussian::GaussianSurface::isotropic(p.sigma_um, p.corr_x_um)
            }),
            SurfaceParams::Fractal(p) => Core::Fractal(stam::fractal::FractalSurface::new(
                p.hurst, p.sigma_um, p.lag_um,
            )?),
            SurfaceParams::Periodic(p) => Core::Periodic(stam::periodic::PeriodicSurface::new(
                p.period_um,
                p.coherence_um,
                p.profile,
            )?),
            SurfaceParams::HeightMap(_) => {
                return Err("a height map is read by Brdf::from_json only".into())
            }
        })
    }

    /// Which route is in use (for the report).
    pub fn route(&self) -> String {
        match self {
            Core::Brdf(_) => "Brdf::eval_spectral / G".into(),
            Core::Unavailable(m) => format!("{UNAVAILABLE}: {m}"),
            _ => "surface kernel (Brdf stand-in)".into(),
        }
    }

    pub fn available(&self) -> bool {
        !matches!(self, Core::Unavailable(_))
    }

    /// The coherent lobe's reflectance at the mirror of wi (F^2 = 1); NaN
    /// where only a surface kernel is at hand.
    pub fn coherent(&self, wi: DVec3, lambda_nm: f64) -> f64 {
        match self {
            Core::Brdf(b) => b.coherent_spectral(wi, lambda_nm),
            _ => f64::NAN,
        }
    }

    /// f / G with F^2 = 1 at (wi, wo, lambda).
    pub fn f_over_g(&self, wi: DVec3, wo: DVec3, lambda_nm: f64) -> f64 {
        if let Core::Brdf(b) = self {
            let f = b.eval_spectral(wi, wo, lambda_nm);
            return f / crate::optics::geometric_factor(wi, wo);
        }
        let Some(geom) = PairGeometry::new(wi, wo) else {
            return 0.0;
        };
        let k = crate::optics::wavenumber(lambda_nm);
        match self {
            Core::Gaussian(s) => s.kernel(k, &geom),
            Core::Fractal(s) => s.kernel(k, &geom),
            Core::Periodic(s) => s.kernel(k, &geom),
            Core::Unavailable(_) => f64::NAN,
            Core::Brdf(_) => unreachable!(),
        }
    }
}

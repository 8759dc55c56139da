//! The material: a plan built once from parameters, evaluated many times.
//!
//! f(wi, wo; lambda) = F^2(wi . h, lambda) * G(wi, wo) * K(k; u, v, w), with K
//! the surface model's kernel (docs/physics.md). The plan holds only what
//! the parameters need: the one surface model, its tables, the Fresnel kind
//! and, for the RGB path, the wavelength rule.

use crate::error::StamError;
use crate::fractal::FractalSurface;
use crate::fresnel::Fresnel;
use crate::gaussian::{GaussianSurface, SeriesSettings};
use crate::geometry::PairGeometry;
use crate::params::{MaterialParams, SurfaceParams};
use crate::periodic::PeriodicSurface;
use crate::spectrum::{self, SmoothRule, LAMBDA_MAX_NM, LAMBDA_MIN_NM};
use glam::DVec3;
use std::f64::consts::PI;

/// Material flags (mirrors STAM_FLAG_* in stam.h).
pub const FLAG_HAS_COHERENT: u32 = 1;
pub const FLAG_ANISOTROPIC: u32 = 2;
pub const FLAG_SPECTRALLY_VARYING: u32 = 4;

/// Largest roughness exponent g for which the coherent lobe is evaluated:
/// beyond it e^-g < 1e-300, nothing a renderer can see.
pub(crate) const COHERENT_MAX_G: f64 = 690.0;

pub enum Surface {
    Gaussian(GaussianSurface),
    Fractal(FractalSurface),
    Periodic(PeriodicSurface),
}

pub struct Brdf {
    pub params: MaterialParams,
    pub surface: Surface,
    pub fresnel: Fresnel,
    /// Wavelength rule of the RGB path for spectrally smooth surfaces.
    rgb_rule: &'static SmoothRule,
}

/// Wavenumber k = 2 pi / lambda in 1/um.
#[inline]
pub fn wavenumber_per_um(lambda_nm: f64) -> f64 {
    2.0 * PI * 1000.0 / lambda_nm
}

#[inline]
pub(crate) fn in_band(lambda_nm: f64) -> bool {
    (LAMBDA_MIN_NM..=LAMBDA_MAX_NM).contains(&lambda_nm)
}

/// Final guard of every output: NaN or negative -> 0, +inf -> f64::MAX.
#[inline]
pub fn finite_non_negative(x: f64) -> f64 {
    if x > 0.0 {
        x.min(f64::MAX)
    } else {
        0.0
    }
}

impl Brdf {
    pub fn from_json(text: &str) -> Result<Brdf, StamError> {
        Brdf::new(MaterialParams::from_json(text)?)
    }

    pub fn new(params: MaterialParams) -> Result<Brdf, StamError> {
        let surface = match &params.surface {
            SurfaceParams::Gaussian {
                sigma_um,
                corr_x_um,
                corr_y_um,
                anisotropic,
            } => {
                let mut s = if *anisotropic {
                    GaussianSurface::anisotropic(*sigma_um, *corr_x_um, *corr_y_um)
                } else {
                    GaussianSurface::isotropic(*sigma_um, *corr_x_um)
                };
                s.series = SeriesSettings {
                    tolerance: params.accuracy.series_tolerance,
                    ..SeriesSettings::default()
                };
                Surface::Gaussian(s)
            }
            SurfaceParams::Fractal {
                hurst,
                sigma_um,
                lag_um,
            } => Surface::Fractal(
                FractalSurface::new(*hurst, *sigma_um, *lag_um).map_err(StamError::new)?,
            ),
            SurfaceParams::Periodic {
                period_um,
                coherence_um,
                profile,
            } => Surface::Periodic(
                PeriodicSurface::new(*period_um, *coherence_um, profile.clone())
                    .map_err(StamError::new)?,
            ),
        };
        let rgb_rule = spectrum::smooth_rule(params.accuracy.rgb_nodes);
        Ok(Brdf {
            fresnel: params.fresnel.clone(),
            params,
            surface,
            rgb_rule,
        })
    }

    pub fn flags(&self) -> u32 {
        let mut flags = 0;
        match &self.surface {
            Surface::Gaussian(g) => {
                flags |= FLAG_HAS_COHERENT | FLAG_SPECTRALLY_VARYING;
                if !g.isotropic {
                    flags |= FLAG_ANISOTROPIC;
                }
            }
            Surface::Fractal(_) => flags |= FLAG_SPECTRALLY_VARYING,
            Surface::Periodic(_) => flags |= FLAG_ANISOTROPIC | FLAG_SPECTRALLY_VARYING,
        }
        flags
    }

    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Brdf>()
            + match &self.surface {
                Surface::Gaussian(_) => 0,
                Surface::Fractal(f) => f.memory_bytes(),
                Surface::Periodic(p) => p.memory_bytes(),
            }
    }

    /// The surface model's kernel K at wavenumber k.
    #[inline]
    fn kernel(&self, k_per_um: f64, geom: &PairGeometry) -> f64 {
        match &self.surface {
            Surface::Gaussian(s) => s.kernel(k_per_um, geom),
            Surface::Fractal(s) => s.kernel(k_per_um, geom),
            Surface::Periodic(s) => s.kernel(k_per_um, geom),
        }
    }

    /// f(wi, wo; lambda) in 1/sr without the coherent lobe and without cos.
    pub fn eval_spectral(&self, wi: DVec3, wo: DVec3, lambda_nm: f64) -> f64 {
        if !in_band(lambda_nm) {
            return 0.0;
        }
        let Some(geom) = PairGeometry::new(wi, wo) else {
            return 0.0;
        };
        let k = wavenumber_per_um(lambda_nm);
        let f = self.fresnel.reflectance(geom.cos_half, lambda_nm)
            * geom.geometric_factor
            * self.kernel(k, &geom);
        finite_non_negative(f)
    }

    /// f projected to linear sRGB (D65-weighted), without the coherent lobe.
    pub fn eval_rgb(&self, wi: DVec3, wo: DVec3) -> [f64; 3] {
        let Some(geom) = PairGeometry::new(wi, wo) else {
            return [0.0; 3];
        };
        let rgb = match &self.surface {
            Surface::Periodic(s) => {
                let fresnel = &self.fresnel;
                let reflectance = |lambda_nm: f64| fresnel.reflectance(geom.cos_half, lambda_nm);
                s.kernel_rgb(&geom, &reflectance)
            }
            _ => {
                let rule = self.rgb_rule;
                let mut acc = [0.0; 3];
                for j in 0..rule.nu_per_um.len() {
                    let k = 2.0 * PI * rule.nu_per_um[j];
                    let value = self.fresnel.reflectance(geom.cos_half, rule.lambda_nm[j])
                        * self.kernel(k, &geom);
                    let w = &rule.weights[j];
                    acc[0] += w[0] * value;
                    acc[1] += w[1] * value;
                    acc[2] += w[2] * value;
                }
                acc
            }
        };
        rgb.map(|c| finite_non_negative(c * geom.geometric_factor))
    }

    /// The same RGB projection by the project's reference: spectral
    /// evaluations on a `step_nm` grid (1 nm = the reference integration).
    pub fn eval_rgb_reference(&self, wi: DVec3, wo: DVec3, step_nm: f64) -> [f64; 3] {
        spectrum::integrate_rgb_reference(|lambda| self.eval_spectral(wi, wo, lambda), step_nm)
    }

    /// Reflectance of the coherent delta lobe at the mirror direction of wi.
    pub fn coherent_spectral(&self, wi: DVec3, lambda_nm: f64) -> f64 {
        let Surface::Gaussian(s) = &self.surface else {
            return 0.0;
        };
        if !in_band(lambda_nm) {
            return 0.0;
        }
        let Some(cos_i) = incidence_cosine(wi) else {
            return 0.0;
        };
        let k = wavenumber_per_um(lambda_nm);
        if s.roughness_exponent(k, 2.0 * cos_i) > COHERENT_MAX_G {
            return 0.0;
        }
        finite_non_negative(
            self.fresnel.reflectance(cos_i, lambda_nm) * s.coherent_attenuation(k, cos_i),
        )
    }

    /// Coherent-lobe reflectance in linear sRGB.
    pub fn coherent_rgb(&self, wi: DVec3) -> [f64; 3] {
        let Surface::Gaussian(s) = &self.surface else {
            return [0.0; 3];
        };
        let Some(cos_i) = incidence_cosine(wi) else {
            return [0.0; 3];
        };
        let rule = self.rgb_rule;
        // Skip the integration when the lobe is gone at the shortest wavelength
        // that matters (the bluest rule node has the largest g).
        let k_max = 2.0 * PI * rule.nu_per_um.iter().cloned().fold(0.0, f64::max);
        if s.roughness_exponent(k_max, 2.0 * cos_i) > COHERENT_MAX_G
            && s.roughness_exponent(wavenumber_per_um(LAMBDA_MAX_NM), 2.0 * cos_i) > COHERENT_MAX_G
        {
            return [0.0; 3];
        }
        let mut acc = [0.0; 3];
        for j in 0..rule.nu_per_um.len() {
            let k = 2.0 * PI * rule.nu_per_um[j];
            let value = self.fresnel.reflectance(cos_i, rule.lambda_nm[j])
                * s.coherent_attenuation(k, cos_i);
            let w = &rule.weights[j];
            acc[0] += w[0] * value;
            acc[1] += w[1] * value;
            acc[2] += w[2] * value;
        }
        acc.map(finite_non_negative)
    }
}

/// cos(theta_i) of a direction above the horizon, else None.
fn incidence_cosine(wi: DVec3) -> Option<f64> {
    let wi = crate::geometry::normalize_direction(wi)?;
    if wi.z > crate::geometry::MIN_COS {
        Some(wi.z)
    } else {
        None
    }
}

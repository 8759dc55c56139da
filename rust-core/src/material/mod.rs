//! The material: a plan built once from parameters, evaluated many times.
//!
//! f(wi, wo; lambda) = F^2(wi . h, lambda) * G(wi, wo) * K(k; u, v, w), with K
//! the surface model's kernel (docs/physics.md). The plan holds only what
//! the parameters need: the one surface model (with its tables), the
//! Fresnel term and, for spectrally smooth models, the RGB rule. Sampling
//! goes through the model's strategy (`Strategy`); `vertex` answers a path
//! vertex's queries in one call.

pub mod params;
pub mod plausibility;
#[cfg(test)]
mod sampling_tests;
#[cfg(test)]
mod tests;
mod vertex;

pub use crate::models::{
    Strategy, Surface, FLAG_ANISOTROPIC, FLAG_HAS_COHERENT, FLAG_SPECTRALLY_VARYING,
};
pub use crate::sampling::SampleResult;
pub use vertex::Channels;

use crate::error::StamError;
use crate::models::gaussian::SeriesSettings;
use crate::models::{f_spectral, RgbRule, Shading};
use crate::optics::fresnel::{Fresnel, FresnelAtCos};
use crate::optics::geometry::{normalize_direction, PairGeometry, MIN_COS};
use crate::special::finite_non_negative;
use crate::spectrum::{self, gamut_map, in_band};
use glam::DVec3;
use params::MaterialParams;

pub struct Brdf {
    surface: Surface,
    fresnel: Fresnel,
    /// Wavelength rule of the RGB path for spectrally smooth surfaces.
    rgb_rule: RgbRule,
}

impl Brdf {
    pub fn from_json(text: &str) -> Result<Brdf, StamError> {
        Brdf::new(MaterialParams::from_json(text)?)
    }

    pub fn new(params: MaterialParams) -> Result<Brdf, StamError> {
        let surface = Surface::new(&params.surface, &params.fresnel)?;
        let rgb_rule = RgbRule::new(params.surface.rgb_nodes(), &params.fresnel);
        Ok(Brdf {
            surface,
            fresnel: params.fresnel,
            rgb_rule,
        })
    }

    /// The surface model (read-only: tools that look at its physics).
    pub fn surface(&self) -> &Surface {
        &self.surface
    }

    /// The material with other series settings for a Gaussian surface (the
    /// accuracy survey's knobs); other surfaces are unchanged.
    pub fn with_series(mut self, series: SeriesSettings) -> Brdf {
        if let Some(g) = self.surface.gaussian_mut() {
            g.set_series(series);
        }
        self
    }

    pub fn flags(&self) -> u32 {
        self.surface.flags()
    }

    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Brdf>() + self.rgb_rule.memory_bytes() + self.surface.memory_bytes()
    }

    #[inline]
    pub(crate) fn shading(&self) -> Shading<'_> {
        Shading {
            fresnel: &self.fresnel,
            rgb_rule: &self.rgb_rule,
        }
    }

    pub fn fresnel(&self) -> &Fresnel {
        &self.fresnel
    }

    /// The Fresnel term at a pair's half-vector cosine.
    #[inline]
    pub fn fresnel_at(&self, geom: &PairGeometry) -> FresnelAtCos<'_> {
        self.fresnel.at_cos(geom.cos_half)
    }

    /// f(wi, wo; lambda) in 1/sr without the coherent lobe and without cos.
    pub fn eval_spectral(&self, wi: DVec3, wo: DVec3, lambda_nm: f64) -> f64 {
        if !in_band(lambda_nm) {
            return 0.0;
        }
        let Some(geom) = PairGeometry::new(wi, wo) else {
            return 0.0;
        };
        self.eval_spectral_at(&geom, lambda_nm)
    }

    /// `eval_spectral` for a pair whose geometry is known (several
    /// wavelengths of one pair share it).
    pub fn eval_spectral_at(&self, geom: &PairGeometry, lambda_nm: f64) -> f64 {
        self.eval_spectral_with(geom, lambda_nm, &self.fresnel_at(geom))
    }

    /// `eval_spectral_at` with the Fresnel term at the pair's cosine given.
    #[inline]
    pub fn eval_spectral_with(
        &self,
        geom: &PairGeometry,
        lambda_nm: f64,
        fresnel: &FresnelAtCos,
    ) -> f64 {
        f_spectral(geom, lambda_nm, fresnel, |k| self.surface.kernel(k, geom))
    }

    /// f projected to linear sRGB (D65-weighted), without the coherent lobe.
    pub fn eval_rgb(&self, wi: DVec3, wo: DVec3) -> [f64; 3] {
        self.eval_rgb_by(wi, wo, |shading, geom| {
            self.surface.reflectance_rgb(shading, geom)
        })
    }

    /// `eval_rgb` with the model's F^2 K in RGB given by `reflectance` (the
    /// tests compare a model's fast paths with its plain ones through it).
    #[inline]
    pub(crate) fn eval_rgb_by(
        &self,
        wi: DVec3,
        wo: DVec3,
        reflectance: impl FnOnce(&Shading, &PairGeometry) -> [f64; 3],
    ) -> [f64; 3] {
        let Some(geom) = PairGeometry::new(wi, wo) else {
            return [0.0; 3];
        };
        let rgb = reflectance(&self.shading(), &geom);
        gamut_map(rgb.map(|c| c * geom.geometric_factor)).map(finite_non_negative)
    }

    /// The same RGB projection by the project's reference: spectral
    /// evaluations on a `step_nm` grid (1 nm = the reference integration).
    pub fn eval_rgb_reference(&self, wi: DVec3, wo: DVec3, step_nm: f64) -> [f64; 3] {
        spectrum::integrate_rgb_reference(|lambda| self.eval_spectral(wi, wo, lambda), step_nm)
    }

    /// Reflectance of the coherent delta lobe at the mirror direction of wi.
    pub fn coherent_spectral(&self, wi: DVec3, lambda_nm: f64) -> f64 {
        if !in_band(lambda_nm) {
            return 0.0;
        }
        let Some(cos_i) = incidence_cosine(wi) else {
            return 0.0;
        };
        finite_non_negative(
            self.surface
                .coherent_spectral(&self.shading(), cos_i, lambda_nm),
        )
    }

    /// Coherent-lobe reflectance in linear sRGB.
    pub fn coherent_rgb(&self, wi: DVec3) -> [f64; 3] {
        let Some(cos_i) = incidence_cosine(wi) else {
            return [0.0; 3];
        };
        let rgb = self.surface.coherent_rgb(&self.shading(), cos_i);
        gamut_map(rgb).map(finite_non_negative)
    }

    /// The sampling strategy for incident direction wi; lambda_nm = None is
    /// RGB mode.
    pub fn sampler(&self, wi: DVec3, lambda_nm: Option<f64>) -> Strategy<'_> {
        self.surface.strategy(&self.shading(), wi, lambda_nm)
    }

    /// The equally weighted mixture of the one-wavelength strategies of
    /// `lambdas` (each is a single component): the first uniform picks the
    /// wavelength, and the pdf is the mean of theirs.
    pub fn mixture_sampler(&self, wi: DVec3, lambdas: &[f64]) -> Strategy<'_> {
        self.surface.mixture_strategy(&self.shading(), wi, lambdas)
    }

    /// Draw wo for incident wi (lambda_nm = None: RGB mode) from 3 uniforms.
    pub fn sample(&self, wi: DVec3, lambda_nm: Option<f64>, rnd: [f64; 3]) -> SampleResult {
        self.sampler(wi, lambda_nm).sample(rnd)
    }

    /// Solid-angle pdf of `sample` at wo (non-coherent part).
    pub fn pdf(&self, wi: DVec3, wo: DVec3, lambda_nm: Option<f64>) -> f64 {
        self.sampler(wi, lambda_nm).pdf(wo)
    }

    /// Discrete probability that `sample` picks the coherent lobe.
    pub fn coherent_probability(&self, wi: DVec3, lambda_nm: Option<f64>) -> f64 {
        self.sampler(wi, lambda_nm).coherent_probability()
    }
}

/// cos(theta_i) of a direction above the horizon, else None.
fn incidence_cosine(wi: DVec3) -> Option<f64> {
    let wi = normalize_direction(wi)?;
    if wi.z > MIN_COS {
        Some(wi.z)
    } else {
        None
    }
}

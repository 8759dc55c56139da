//! The surface models: a closed set, dispatched here and nowhere else.
//!
//! Each model is a folder holding everything that is that model's: its
//! kernel K (the BRDF without F^2 and G), its RGB path, its coherent lobe,
//! its sampling lobes and their tables, its parameters and its tests. It
//! implements `SurfaceModel`; `Surface` and `Strategy` are the tagged
//! unions the material holds, and the only `match` on the model is in this
//! file. Adding a model: a folder, one arm in each of `Surface`, `Strategy`
//! and `SurfaceParams` (and their `dispatch!` lists), and its name in
//! `SurfaceParams::parse`.

pub mod fractal;
pub mod gaussian;
pub mod periodic;
mod rgb_rule;

pub use rgb_rule::{RgbRule, MAX_RGB_NODES};

use crate::error::StamError;
use crate::json::{type_name, Reader};
use crate::optics::fresnel::{Fresnel, FresnelAtCos};
use crate::optics::geometry::{normalize_direction, PairGeometry, MIN_COS};
use crate::sampling::{rgb_sampling_nodes, Component, Components, Lobe, Mixture, SampleResult};
use crate::special::finite_non_negative;
use crate::spectrum::{in_band, wavenumber_per_um};
use fractal::Fractal;
use gaussian::Gaussian;
use glam::DVec3;
use periodic::Periodic;
use serde_json::{Map, Value};
use smallvec::smallvec;

/// Material flags (mirror STAM_FLAG_* in stam.h).
pub const FLAG_HAS_COHERENT: u32 = 1;
pub const FLAG_ANISOTROPIC: u32 = 2;
pub const FLAG_SPECTRALLY_VARYING: u32 = 4;

/// What a material gives its surface model besides the geometry: the
/// Fresnel term, the RGB rule of spectrally smooth kernels and a factor of
/// the pair's f per wavelength (the material's energy scaling), which the
/// RGB paths apply inside their wavelength integration.
pub struct Shading<'a> {
    pub fresnel: &'a Fresnel,
    pub rgb_rule: &'a RgbRule,
    pub pair_factor: Option<&'a dyn Fn(f64) -> f64>,
}

impl Shading<'_> {
    /// The RGB rule's sum of `values` (K at its nodes) with F^2 and the
    /// pair's factor at the nodes.
    #[inline]
    pub fn integrate(&self, cos: f64, values: &mut [f64]) -> [f64; 3] {
        if let Some(factor) = self.pair_factor {
            for (v, &lambda) in values.iter_mut().zip(self.rgb_rule.lambda_nm()) {
                *v *= factor(lambda);
            }
        }
        self.rgb_rule.integrate(self.fresnel, cos, values)
    }

    /// The pair's factor at lambda_nm (1 without one).
    #[inline]
    pub fn factor(&self, lambda_nm: f64) -> f64 {
        self.pair_factor.map_or(1.0, |f| f(lambda_nm))
    }
}

/// f(lambda) = F^2 G K(k) for a pair, with the Fresnel term at the pair's
/// cosine given and `kernel` the model's K at wavenumber k (1/um); 0
/// outside the visible band, finite and non-negative.
#[inline]
pub fn f_spectral(
    geom: &PairGeometry,
    lambda_nm: f64,
    fresnel: &FresnelAtCos,
    kernel: impl FnOnce(f64) -> f64,
) -> f64 {
    if !in_band(lambda_nm) {
        return 0.0;
    }
    let k = wavenumber_per_um(lambda_nm);
    finite_non_negative(fresnel.reflectance(lambda_nm) * geom.geometric_factor * kernel(k))
}

/// How a model's energy-conserving table is made (`material::energy`).
#[derive(Clone, Copy, Debug)]
pub struct EnergyHint {
    /// Wavelength nodes at which the table bounds the white material's
    /// albedo.
    pub wavelength_nodes: usize,
    /// Whether the table keeps the nodes apart (albedos that change fast
    /// with wavelength) or one colour-neutral factor (smooth ones).
    pub per_wavelength: bool,
    /// Below this cosine the horizon taper goes smoothly to 0.
    pub horizon_taper_cos: f64,
}

/// What each surface model provides to the material.
pub trait SurfaceModel: Sized {
    /// The lobes of its sampling strategies.
    type Lobe: Lobe<Model = Self>;

    /// STAM_FLAG_* bits.
    fn flags(&self) -> u32;

    /// Bytes held: the surface and the tables built so far.
    fn memory_bytes(&self) -> usize;

    /// The diffuse kernel K at wavenumber k (1/um): f = F^2 G K.
    fn kernel(&self, k_per_um: f64, geom: &PairGeometry) -> f64;

    /// sum over the band of F^2 K weighted by the linear sRGB matching
    /// functions (f / G in RGB), before gamut mapping.
    fn reflectance_rgb(&self, shading: &Shading, geom: &PairGeometry) -> [f64; 3];

    /// Reflectance of the coherent (mirror) lobe at incidence cosine cos_i
    /// (above the horizon) and an in-band wavelength; 0 for models without.
    fn coherent_spectral(&self, _shading: &Shading, _cos_i: f64, _lambda_nm: f64) -> f64 {
        0.0
    }

    /// The coherent lobe's reflectance in linear sRGB, before gamut mapping.
    fn coherent_rgb(&self, _shading: &Shading, _cos_i: f64) -> [f64; 3] {
        [0.0; 3]
    }

    /// How the energy-conserving material's table suits this model.
    fn energy_hint(&self) -> EnergyHint {
        EnergyHint {
            wavelength_nodes: 5,
            per_wavelength: false,
            horizon_taper_cos: 0.1,
        }
    }

    /// The one-wavelength strategy's component at unit wi above the horizon.
    fn spectral_component(
        &self,
        shading: &Shading,
        wi: DVec3,
        lambda_nm: f64,
    ) -> Component<Self::Lobe>;

    /// The RGB strategy's components: by default the one-wavelength
    /// components at the RGB mixture's wavelengths, equally weighted.
    fn rgb_components<'a>(&'a self, shading: &Shading, wi: DVec3) -> Components<'a, Self::Lobe> {
        Components::Local(
            rgb_sampling_nodes()
                .iter()
                .map(|&lambda| self.spectral_component(shading, wi, lambda))
                .collect(),
        )
    }

    /// The strategy at wi: RGB mode's (`lambda_nm` None) or one wavelength's.
    fn strategy<'a>(
        &'a self,
        shading: &Shading,
        wi: DVec3,
        lambda_nm: Option<f64>,
    ) -> Mixture<'a, Self::Lobe> {
        let Some(wi) = normalize_direction(wi).filter(|d| d.z > MIN_COS) else {
            return Mixture::empty(self);
        };
        let components = match lambda_nm {
            Some(lambda) => {
                Components::Local(smallvec![self.spectral_component(shading, wi, lambda)])
            }
            None => self.rgb_components(shading, wi),
        };
        Mixture::new(self, wi, components)
    }

    /// The equally weighted mixture of the one-wavelength strategies of
    /// `lambdas`: the first uniform picks the wavelength, the pdf is the
    /// mean of theirs.
    fn mixture_strategy<'a>(
        &'a self,
        shading: &Shading,
        wi: DVec3,
        lambdas: &[f64],
    ) -> Mixture<'a, Self::Lobe> {
        let Some(wi) = normalize_direction(wi).filter(|d| d.z > MIN_COS) else {
            return Mixture::empty(self);
        };
        let components = lambdas
            .iter()
            .map(|&lambda| self.spectral_component(shading, wi, lambda))
            .collect();
        Mixture::new(self, wi, Components::Local(components))
    }
}

/// `match` on a model-tagged value, the same expression in every arm.
macro_rules! dispatch {
    ($value:expr, $enum:ident, $m:ident => $body:expr) => {
        match $value {
            $enum::Gaussian($m) => $body,
            $enum::Fractal($m) => $body,
            $enum::Periodic($m) => $body,
        }
    };
}

/// A material's surface model.
pub enum Surface {
    Gaussian(Gaussian),
    Fractal(Fractal),
    Periodic(Periodic),
}

impl Surface {
    /// The model of `params`, with the tables it needs from the Fresnel
    /// term and the RGB rule.
    pub fn new(params: &SurfaceParams, fresnel: &Fresnel) -> Result<Surface, StamError> {
        Ok(match params {
            SurfaceParams::Gaussian(p) => Surface::Gaussian(Gaussian::new(p)),
            SurfaceParams::Fractal(p) => Surface::Fractal(Fractal::new(p)?),
            SurfaceParams::Periodic(p) => Surface::Periodic(Periodic::new(p, fresnel)?),
        })
    }

    pub fn flags(&self) -> u32 {
        dispatch!(self, Surface, m => m.flags())
    }

    pub fn memory_bytes(&self) -> usize {
        dispatch!(self, Surface, m => m.memory_bytes())
    }

    #[inline]
    pub fn kernel(&self, k_per_um: f64, geom: &PairGeometry) -> f64 {
        dispatch!(self, Surface, m => m.kernel(k_per_um, geom))
    }

    #[inline]
    pub fn reflectance_rgb(&self, shading: &Shading, geom: &PairGeometry) -> [f64; 3] {
        dispatch!(self, Surface, m => m.reflectance_rgb(shading, geom))
    }

    pub fn energy_hint(&self) -> EnergyHint {
        dispatch!(self, Surface, m => m.energy_hint())
    }

    pub fn coherent_spectral(&self, shading: &Shading, cos_i: f64, lambda_nm: f64) -> f64 {
        dispatch!(self, Surface, m => m.coherent_spectral(shading, cos_i, lambda_nm))
    }

    pub fn coherent_rgb(&self, shading: &Shading, cos_i: f64) -> [f64; 3] {
        dispatch!(self, Surface, m => m.coherent_rgb(shading, cos_i))
    }

    pub fn strategy<'a>(
        &'a self,
        shading: &Shading,
        wi: DVec3,
        lambda_nm: Option<f64>,
    ) -> Strategy<'a> {
        dispatch!(self, Surface, m => m.strategy(shading, wi, lambda_nm).into())
    }

    pub fn mixture_strategy<'a>(
        &'a self,
        shading: &Shading,
        wi: DVec3,
        lambdas: &[f64],
    ) -> Strategy<'a> {
        dispatch!(self, Surface, m => m.mixture_strategy(shading, wi, lambdas).into())
    }

    /// The Gaussian model, if this is one (tests and the accuracy survey).
    pub fn gaussian_mut(&mut self) -> Option<&mut Gaussian> {
        match self {
            Surface::Gaussian(g) => Some(g),
            _ => None,
        }
    }
}

/// The sampling strategy for one incident direction and one mode, built once
/// and used for any number of samples and pdf evaluations.
pub enum Strategy<'a> {
    Gaussian(Mixture<'a, gaussian::Lobe>),
    Fractal(Mixture<'a, fractal::Lobe>),
    Periodic(Mixture<'a, periodic::Lobe>),
}

impl<'a> From<Mixture<'a, gaussian::Lobe>> for Strategy<'a> {
    fn from(m: Mixture<'a, gaussian::Lobe>) -> Self {
        Strategy::Gaussian(m)
    }
}

impl<'a> From<Mixture<'a, fractal::Lobe>> for Strategy<'a> {
    fn from(m: Mixture<'a, fractal::Lobe>) -> Self {
        Strategy::Fractal(m)
    }
}

impl<'a> From<Mixture<'a, periodic::Lobe>> for Strategy<'a> {
    fn from(m: Mixture<'a, periodic::Lobe>) -> Self {
        Strategy::Periodic(m)
    }
}

impl Strategy<'_> {
    /// Discrete probability of choosing the coherent lobe.
    pub fn coherent_probability(&self) -> f64 {
        dispatch!(self, Strategy, s => s.coherent_probability())
    }

    /// Solid-angle pdf of the non-coherent part at wo (0 below the horizon).
    pub fn pdf(&self, wo: DVec3) -> f64 {
        dispatch!(self, Strategy, s => s.pdf(wo))
    }

    pub fn sample(&self, rnd: [f64; 3]) -> SampleResult {
        dispatch!(self, Strategy, s => s.sample(rnd))
    }

    /// `sample`, with a glossy direction mapped by `map` (e.g. rounded to
    /// the caller's precision) before its pdf is taken.
    pub fn sample_mapped(&self, rnd: [f64; 3], map: impl Fn(DVec3) -> DVec3) -> SampleResult {
        dispatch!(self, Strategy, s => s.sample_mapped(rnd, map))
    }
}

/// The surface parameters of a material, by model.
#[derive(Clone, Debug, PartialEq)]
pub enum SurfaceParams {
    Gaussian(gaussian::GaussianParams),
    Fractal(fractal::FractalParams),
    Periodic(periodic::PeriodicParams),
}

/// The accepted values of the key 'surface'.
const SURFACE_NAMES: &str = "\"gaussian\", \"fractal\", \"periodic\", \"cd\"";

impl SurfaceParams {
    /// The surface named by the object's 'surface' key, with its model's
    /// keys; `material_keys` are the keys the material itself reads, which
    /// every surface accepts.
    pub fn parse(
        obj: &Map<String, Value>,
        material_keys: &[&str],
    ) -> Result<SurfaceParams, StamError> {
        let surface = match obj.get("surface") {
            None => {
                return Err(StamError::new(format!(
                    "missing parameter 'surface' (accepted: {SURFACE_NAMES})"
                )))
            }
            Some(Value::String(s)) => s.as_str(),
            Some(other) => {
                return Err(StamError::new(format!(
                    "parameter 'surface' must be a string ({SURFACE_NAMES}), got {}",
                    type_name(other)
                )))
            }
        };
        let reader = Reader::new(obj, surface, material_keys);
        Ok(match surface {
            "gaussian" => SurfaceParams::Gaussian(gaussian::GaussianParams::parse(&reader)?),
            "fractal" => SurfaceParams::Fractal(fractal::FractalParams::parse(&reader)?),
            "periodic" => SurfaceParams::Periodic(periodic::PeriodicParams::parse(&reader, false)?),
            "cd" => SurfaceParams::Periodic(periodic::PeriodicParams::parse(&reader, true)?),
            other => {
                return Err(StamError::new(format!(
                    "unknown surface '{other}' for parameter 'surface' (accepted: {SURFACE_NAMES})"
                )))
            }
        })
    }

    /// Node count of the RGB rule for spectrally smooth kernels (0: the
    /// model integrates its spectrum itself).
    pub fn rgb_nodes(&self) -> usize {
        match self {
            SurfaceParams::Gaussian(p) => p.rgb_nodes,
            SurfaceParams::Fractal(p) => p.rgb_nodes,
            SurfaceParams::Periodic(_) => 0,
        }
    }
}

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
pub mod heightmap;
pub mod periodic;
pub mod program;
mod rgb_rule;

pub use program::{FactorMaker, FactorProgram, SampleProgram, SurfacePrograms};
pub use rgb_rule::{RgbRule, MAX_RGB_NODES};

use crate::error::StamError;
use crate::json::{type_name, KeyDoc, Reader};
use crate::optics::fresnel::{Fresnel, FresnelAtCos};
use crate::optics::geometry::{normalize_direction, PairGeometry, MIN_COS};
use crate::program::ParamId;
use crate::sampling::{rgb_sampling_nodes, Component, Components, Lobe, Mixture, SampleResult};
use crate::special::finite_non_negative;
use crate::spectrum::{in_band, wavenumber_per_um};
use gaussian::Gaussian;
use glam::DVec3;
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
    /// Samples per cell (of an isotropic table; an azimuthal one has 12
    /// times the cells and takes half as many) and wavelength node. Their
    /// noise is what the table mistakes for excess albedo.
    pub samples_per_cell: usize,
    /// The albedo every cell is scaled to at most (at the cells' centres
    /// and the wavelength nodes; between them the albedo may rise by as
    /// much as it changes across a cell).
    pub target_albedo: f64,
}

impl EnergyHint {
    /// What a material may reflect from any direction, below 1 by the
    /// table's margin: its transfer rows are Monte Carlo estimates (about
    /// 0.2% of noise for the random surfaces' 4096 samples per cell), and m
    /// is interpolated between the cells and wavelength nodes the bound
    /// holds for. The margin is also what the default changes at moderate
    /// angles where Stam's albedo is already about 1 (smooth surfaces near
    /// normal incidence): 0.99 changed them by 1.2-3%, 0.995 by 0.3-2.1%
    /// (docs/energy.md).
    pub const TARGET_ALBEDO: f64 = 0.995;
}

/// A model's parameters as the material reads them.
pub trait ModelParams: Sized {
    /// The values of the key 'surface' that name this model.
    const SURFACE_NAMES: &'static [&'static str];

    /// The parameters of the surface named `surface` (one of
    /// SURFACE_NAMES), from the reader's keys.
    fn parse(surface: &str, reader: &Reader) -> Result<Self, StamError>;

    /// Node count of the RGB rule for spectrally smooth kernels (0: the
    /// model integrates its spectrum itself).
    fn rgb_nodes(&self) -> usize {
        0
    }

    /// The continuous parameters that the model's programs read
    /// (`Op::Param`) and that its energy table depends on, with their
    /// values: the table's derivatives are taken along these
    /// (`material::energy::TableDerivative`). None for a parameter whose
    /// value comes from a texture (it varies by far more than a
    /// derivative's reach).
    fn table_params(&self) -> Vec<(ParamId, f64)>;

    /// A copy with the parameter `id` (one of `table_params`) at `value`.
    fn with_param(&self, id: ParamId, value: f64) -> Self;

    /// The keys that the surface named `surface` (one of SURFACE_NAMES)
    /// reads, with units, ranges and defaults, for the parameter reference
    /// (`stam_parameter_reference`): made from the range constants `parse`
    /// checks.
    fn reference(surface: &str) -> Vec<KeyDoc>;

    /// Every key the surface reads, with the value it took (defaults
    /// filled in), into `out` (`stam_brdf_params_json`): `parse` of them
    /// gives these parameters. `given`: the keys as given, for the form
    /// where two are accepted (corr_um, or corr_x_um and corr_y_um).
    fn resolved(&self, given: &Map<String, Value>, out: &mut Map<String, Value>);
}

/// What each surface model provides to the material.
pub trait SurfaceModel: Sized + SurfacePrograms {
    /// Its parameters.
    type Params: ModelParams;
    /// The lobes of its sampling strategies.
    type Lobe: Lobe<Model = Self>;

    /// The model of `params`, with the tables it needs from the Fresnel term.
    fn from_params(params: &Self::Params, fresnel: &Fresnel) -> Result<Self, StamError>;

    /// STAM_FLAG_* bits.
    fn flags(&self) -> u32;

    /// Bytes held: the surface and the tables built so far.
    fn memory_bytes(&self) -> usize;

    /// The diffuse kernel K at wavenumber k (1/um): f = F^2 G K.
    fn kernel(&self, k_per_um: f64, geom: &PairGeometry) -> f64;

    /// sum over the band of F^2 K weighted by the linear sRGB matching
    /// functions (f / G in RGB), before gamut mapping.
    fn reflectance_rgb(&self, shading: &Shading, geom: &PairGeometry) -> [f64; 3];

    /// Whether f is the model's own, not F^2 G K: a grating whose orders'
    /// powers come from Maxwell's equations (`"orders": "rigorous"`), which
    /// include the metal's reflection and conserve energy by themselves (the
    /// material then applies no Fresnel term, no G and no energy table).
    fn is_unfactored(&self) -> bool {
        false
    }

    /// f itself (1/sr, without cos) at an in-band wavelength, where
    /// `is_unfactored`; else None.
    fn unfactored_spectral(&self, _geom: &PairGeometry, _lambda_nm: f64) -> Option<f64> {
        None
    }

    /// f in linear sRGB before gamut mapping, where `is_unfactored`.
    fn unfactored_rgb(&self, _geom: &PairGeometry) -> Option<[f64; 3]> {
        None
    }

    /// Whether `unfactored_mueller` gives matrices (without building what
    /// they need).
    fn has_unfactored_mueller(&self) -> bool {
        false
    }

    /// Where `is_unfactored`, the model's own Mueller matrix for light
    /// arriving from `from` and leaving along `to`, over its [0][0], with
    /// the Stokes basis vectors of the directions of travel -from and to
    /// (`Brdf::mueller`); None where it has none.
    fn unfactored_mueller(
        &self,
        _from: DVec3,
        _to: DVec3,
        _lambda_nm: f64,
    ) -> Option<([f64; 16], [DVec3; 2])> {
        None
    }

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
            // Smooth albedos near 1 at moderate angles: noise in the rows
            // would be taken for excess (512 samples changed a rough
            // Gaussian by 3% at moderate angles, 4096 by 0.5%).
            samples_per_cell: 4096,
            target_albedo: EnergyHint::TARGET_ALBEDO,
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

/// The closed set of models: one line each. It defines `Surface` (a
/// material's model), `Strategy` (its sampling strategy at one incident
/// direction), `SurfaceParams` (its parameters) and `dispatch!`, the one
/// `match` on the model that every method of those types goes through.
macro_rules! surface_models {
    ($d:tt $($name:ident => $module:ident :: $model:ident),+ $(,)?) => {
        /// A material's surface model.
        pub enum Surface {
            $($name($module::$model),)+
        }

        /// The sampling strategy for one incident direction and one mode,
        /// built once and used for any number of samples and pdf
        /// evaluations.
        pub enum Strategy<'a> {
            $($name(Mixture<'a, <$module::$model as SurfaceModel>::Lobe>),)+
        }

        /// The surface parameters of a material, by model.
        #[derive(Clone, Debug, PartialEq)]
        pub enum SurfaceParams {
            $($name(<$module::$model as SurfaceModel>::Params),)+
        }

        $(
            impl<'a> From<Mixture<'a, <$module::$model as SurfaceModel>::Lobe>> for Strategy<'a> {
                fn from(m: Mixture<'a, <$module::$model as SurfaceModel>::Lobe>) -> Self {
                    Strategy::$name(m)
                }
            }
        )+

        /// `match` on a model-tagged value, the same expression in every arm.
        macro_rules! dispatch {
            ($d value:expr, $d tag:ident, $d m:ident => $d body:expr) => {
                match $d value {
                    $($d tag::$name($d m) => $d body,)+
                }
            };
        }

        impl Surface {
            /// The model of `params`, with the tables it needs from the
            /// Fresnel term.
            pub fn new(params: &SurfaceParams, fresnel: &Fresnel) -> Result<Surface, StamError> {
                Ok(match params {
                    $(SurfaceParams::$name(p) => Surface::$name($module::$model::from_params(p, fresnel)?),)+
                })
            }
        }

        impl SurfaceParams {
            /// Every value of the key 'surface', in the models' order.
            pub fn surface_names() -> Vec<&'static str> {
                let mut names = Vec::new();
                $(names.extend_from_slice(
                    <<$module::$model as SurfaceModel>::Params as ModelParams>::SURFACE_NAMES,
                );)+
                names
            }

            /// The keys of each value of 'surface', in the models' order
            /// (`ModelParams::reference`).
            pub fn reference() -> Vec<(&'static str, Vec<KeyDoc>)> {
                let mut out = Vec::new();
                $({
                    type P = <$module::$model as SurfaceModel>::Params;
                    for &name in <P as ModelParams>::SURFACE_NAMES {
                        out.push((name, <P as ModelParams>::reference(name)));
                    }
                })+
                out
            }

            /// The parameters of the model that `surface` names.
            fn parse_named(surface: &str, reader: &Reader) -> Option<Result<SurfaceParams, StamError>> {
                $({
                    type P = <$module::$model as SurfaceModel>::Params;
                    if <P as ModelParams>::SURFACE_NAMES.contains(&surface) {
                        return Some(<P as ModelParams>::parse(surface, reader).map(SurfaceParams::$name));
                    }
                })+
                None
            }
        }
    };
}

surface_models! {
    $
    Gaussian => gaussian::Gaussian,
    Fractal => fractal::Fractal,
    Periodic => periodic::Periodic,
    HeightMap => heightmap::HeightMap,
}

impl Surface {
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

    pub fn is_unfactored(&self) -> bool {
        dispatch!(self, Surface, m => m.is_unfactored())
    }

    #[inline]
    pub fn unfactored_spectral(&self, geom: &PairGeometry, lambda_nm: f64) -> Option<f64> {
        dispatch!(self, Surface, m => m.unfactored_spectral(geom, lambda_nm))
    }

    pub fn unfactored_rgb(&self, geom: &PairGeometry) -> Option<[f64; 3]> {
        dispatch!(self, Surface, m => m.unfactored_rgb(geom))
    }

    pub fn has_unfactored_mueller(&self) -> bool {
        dispatch!(self, Surface, m => m.has_unfactored_mueller())
    }

    pub fn unfactored_mueller(
        &self,
        from: DVec3,
        to: DVec3,
        lambda_nm: f64,
    ) -> Option<([f64; 16], [DVec3; 2])> {
        dispatch!(self, Surface, m => m.unfactored_mueller(from, to, lambda_nm))
    }

    /// The model's programs (`program::SurfacePrograms`).
    pub fn programs(&self) -> &dyn SurfacePrograms {
        dispatch!(self, Surface, m => m as &dyn SurfacePrograms)
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

    /// The Gaussian model, if this is one (tests, the accuracy survey, the
    /// JIT export).
    pub fn gaussian(&self) -> Option<&Gaussian> {
        match self {
            Surface::Gaussian(g) => Some(g),
            _ => None,
        }
    }

    /// The height-map model, if this is one (tests, the RGB survey).
    pub fn height_map(&self) -> Option<&heightmap::HeightMap> {
        match self {
            Surface::HeightMap(m) => Some(m),
            _ => None,
        }
    }

    /// The same, mutable.
    pub fn gaussian_mut(&mut self) -> Option<&mut Gaussian> {
        match self {
            Surface::Gaussian(g) => Some(g),
            _ => None,
        }
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

impl SurfaceParams {
    /// The surface named by the object's 'surface' key, with its model's
    /// keys; `material_keys` are the keys the material itself reads, which
    /// every surface accepts.
    pub fn parse(
        obj: &Map<String, Value>,
        material_keys: &[&str],
    ) -> Result<SurfaceParams, StamError> {
        let names = Self::surface_names()
            .iter()
            .map(|n| format!("\"{n}\""))
            .collect::<Vec<_>>()
            .join(", ");
        let surface = match obj.get("surface") {
            None => {
                return Err(StamError::new(format!(
                    "missing parameter 'surface' (accepted: {names})"
                )))
            }
            Some(Value::String(s)) => s.as_str(),
            Some(other) => {
                return Err(StamError::new(format!(
                    "parameter 'surface' must be a string ({names}), got {}",
                    type_name(other)
                )))
            }
        };
        let reader = Reader::new(obj, surface, material_keys);
        Self::parse_named(surface, &reader).unwrap_or_else(|| {
            Err(StamError::new(format!(
                "unknown surface '{surface}' for parameter 'surface' (accepted: {names})"
            )))
        })
    }

    /// Node count of the RGB rule for spectrally smooth kernels (0: the
    /// model integrates its spectrum itself).
    pub fn rgb_nodes(&self) -> usize {
        dispatch!(self, SurfaceParams, p => p.rgb_nodes())
    }

    /// `ModelParams::resolved`.
    pub fn resolved(&self, given: &Map<String, Value>, out: &mut Map<String, Value>) {
        dispatch!(self, SurfaceParams, p => p.resolved(given, out))
    }

    /// `ModelParams::table_params`.
    pub fn table_params(&self) -> Vec<(ParamId, f64)> {
        dispatch!(self, SurfaceParams, p => p.table_params())
    }

    /// `ModelParams::with_param`.
    pub fn with_param(&self, id: ParamId, value: f64) -> SurfaceParams {
        match self {
            SurfaceParams::Gaussian(p) => SurfaceParams::Gaussian(p.with_param(id, value)),
            SurfaceParams::Fractal(p) => SurfaceParams::Fractal(p.with_param(id, value)),
            SurfaceParams::Periodic(p) => SurfaceParams::Periodic(p.with_param(id, value)),
            SurfaceParams::HeightMap(p) => SurfaceParams::HeightMap(p.with_param(id, value)),
        }
    }
}

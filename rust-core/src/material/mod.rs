//! The material: a plan built once from parameters, evaluated many times.
//!
//! f(wi, wo; lambda) = F^2(wi . h, lambda) * G(wi, wo) * K(k; u, v, w), with K
//! the surface model's kernel (docs/physics.md). The plan holds only what
//! the parameters need: the one surface model (with its tables), the
//! Fresnel term and, for spectrally smooth models, the RGB rule. Sampling
//! goes through the model's strategy (`Strategy`); `vertex` answers a path
//! vertex's queries in one call.

pub mod energy;
#[cfg(test)]
mod energy_tests;
pub mod params;
pub mod plausibility;
pub mod program;
#[cfg(test)]
mod program_tests;
#[cfg(test)]
mod sampling_tests;
#[cfg(test)]
mod tests;
pub mod textures;
mod vertex;

pub use crate::models::{
    Strategy, Surface, FLAG_ANISOTROPIC, FLAG_HAS_COHERENT, FLAG_SPECTRALLY_VARYING,
};
pub use crate::sampling::SampleResult;
pub use vertex::Channels;

use crate::error::StamError;
use crate::models::gaussian::SeriesSettings;
use crate::models::SurfaceParams;
use crate::models::{f_spectral, RgbRule, Shading};
use crate::optics::fresnel::{Fresnel, FresnelAtCos};
use crate::optics::geometry::{normalize_direction, reflect, PairGeometry, MIN_COS};
use crate::program::ParamId;
use crate::special::finite_non_negative;
use crate::spectrum::{self, gamut_map, in_band};
use energy::{EnergyMode, EnergyTable, PairEnergy, TableDerivative};
use glam::DVec3;
use params::MaterialParams;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

pub struct Brdf {
    surface: Surface,
    fresnel: Fresnel,
    /// Wavelength rule of the RGB path for spectrally smooth surfaces.
    rgb_rule: RgbRule,
    /// The energy-conserving scaling ("energy": "conserving"; None: Stam's
    /// formula), built from the surface's parameters on the first
    /// evaluation.
    energy: Option<Energy>,
    /// The parameters a renderer differentiates (`"gradients"`), which the
    /// programs follow smoothly.
    gradients: Vec<ParamId>,
}

/// What the energy table is built from, and the table once built; with
/// `"gradients"`, its derivatives along them too.
struct Energy {
    surface: SurfaceParams,
    table: OnceLock<Arc<EnergyTable>>,
    /// The derivatives along the material's `gradients`, once built.
    derivatives: OnceLock<Vec<TableDerivative>>,
}

/// Energy tables built in this process, by their surface parameters (the
/// table depends on nothing else: it is built from the white twin). A scene
/// or a test suite often builds one material more than once (the scalar and
/// JIT paths, a parameter update that comes back), and a table takes
/// 0.1-0.4 s. At most TABLE_CACHE_ENTRIES are kept (2-60 kB each).
fn cached_energy_table(
    surface: &SurfaceParams,
    build: impl FnOnce() -> EnergyTable,
) -> Arc<EnergyTable> {
    const TABLE_CACHE_ENTRIES: usize = 64;
    static CACHE: OnceLock<Mutex<HashMap<String, Arc<EnergyTable>>>> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    // Debug prints every f64 exactly (shortest round trip), so equal keys
    // mean equal parameters.
    let key = format!("{surface:?}");
    let lock = || {
        cache
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    };
    if let Some(table) = lock().get(&key) {
        return table.clone();
    }
    // Built without the lock: another material's table may build meanwhile.
    let table = Arc::new(build());
    let mut map = lock();
    if map.len() >= TABLE_CACHE_ENTRIES {
        map.clear();
    }
    map.entry(key).or_insert(table).clone()
}

/// The energy table of the surface `surface` (cached), from its white twin
/// (F = 1, Stam's formula); None where the parameters are not a valid
/// material (a derivative's neighbour beyond a parameter's range).
fn energy_table_of(surface: &SurfaceParams) -> Option<Arc<EnergyTable>> {
    let white = Brdf::new(MaterialParams {
        surface: surface.clone(),
        fresnel: Fresnel::Constant(1.0),
        energy: EnergyMode::Stam,
        gradients: Vec::new(),
    })
    .ok()?;
    Some(cached_energy_table(surface, || {
        let azimuthal = white.flags() & FLAG_ANISOTROPIC != 0;
        EnergyTable::build(
            &white,
            azimuthal,
            (spectrum::LAMBDA_MIN_NM, spectrum::LAMBDA_MAX_NM),
            white.surface.energy_hint(),
        )
    }))
}

impl Brdf {
    pub fn from_json(text: &str) -> Result<Brdf, StamError> {
        Brdf::new(MaterialParams::from_json(text)?)
    }

    pub fn new(params: MaterialParams) -> Result<Brdf, StamError> {
        let surface = Surface::new(&params.surface, &params.fresnel)?;
        let rgb_rule = RgbRule::new(params.surface.rgb_nodes(), &params.fresnel);
        // A model with its own f (rigorous gratings) conserves energy by
        // itself: no table.
        let conserving = params.energy == EnergyMode::Conserving && !surface.is_unfactored();
        let energy = conserving.then(|| Energy {
            surface: params.surface.clone(),
            table: OnceLock::new(),
            derivatives: OnceLock::new(),
        });
        Ok(Brdf {
            surface,
            fresnel: params.fresnel,
            rgb_rule,
            energy,
            gradients: params.gradients,
        })
    }

    /// The energy table of a conserving material, built on first use from
    /// its white twin (F = 1, Stam's formula).
    pub fn energy_table(&self) -> Option<&EnergyTable> {
        let energy = self.energy.as_ref()?;
        Some(
            energy
                .table
                .get_or_init(|| energy_table_of(&energy.surface).expect("a valid material")),
        )
    }

    /// The energy table's derivatives along the surface's program
    /// parameters that `"gradients"` names (else empty), built on first
    /// use.
    pub fn energy_derivatives(&self) -> &[TableDerivative] {
        let Some(energy) = self.energy.as_ref() else {
            return &[];
        };
        if self.gradients.is_empty() {
            return &[];
        }
        energy.derivatives.get_or_init(|| {
            let centre = self.energy_table().expect("a conserving material");
            let at = |id, value| energy_table_of(&energy.surface.with_param(id, value));
            energy
                .surface
                .table_params()
                .into_iter()
                .filter(|(id, _)| self.gradients.contains(id))
                .filter_map(|(id, p0)| {
                    let step = energy::derivative_step(id).exp();
                    let (below, above) = (at(id, p0 / step), at(id, p0 * step));
                    TableDerivative::new(id, p0, centre, below.as_deref(), above.as_deref())
                })
                .collect()
        })
    }

    /// The energy scaling m(wi, lambda) m(wo, lambda) of a pair (None for
    /// Stam's formula).
    #[inline]
    pub fn pair_energy(&self, wi: DVec3, wo: DVec3) -> Option<PairEnergy<'_>> {
        self.energy_table().map(|t| t.pair(wi, wo))
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
        std::mem::size_of::<Brdf>()
            + self.rgb_rule.memory_bytes()
            + self.surface.memory_bytes()
            + self
                .energy
                .as_ref()
                .and_then(|e| e.table.get())
                .map_or(0, |t| t.memory_bytes())
    }

    /// What the surface model needs besides the geometry, without a
    /// pair factor.
    #[inline]
    pub(crate) fn shading(&self) -> Shading<'_> {
        self.shading_with(None)
    }

    #[inline]
    fn shading_with<'a>(&'a self, pair_factor: Option<&'a dyn Fn(f64) -> f64>) -> Shading<'a> {
        Shading {
            fresnel: &self.fresnel,
            rgb_rule: &self.rgb_rule,
            pair_factor,
        }
    }

    /// The material's RGB rule (its nodes, F^2 folded in).
    pub fn rgb_rule(&self) -> &RgbRule {
        &self.rgb_rule
    }

    pub fn fresnel(&self) -> &Fresnel {
        &self.fresnel
    }

    /// The Fresnel term at a pair's half-vector cosine.
    #[inline]
    pub fn fresnel_at(&self, geom: &PairGeometry) -> FresnelAtCos<'_> {
        self.fresnel.at_cos(geom.cos_half)
    }

    /// Whether the material has a polarisation (`polarization`): every
    /// surface whose f is F^2 G K, not one whose f is its own (rigorous
    /// gratings).
    pub fn polarizes(&self) -> bool {
        !self.surface.is_unfactored()
    }

    /// The polarisation of the reflection from wi to wo at lambda: the
    /// Fresnel reflection's at the pair's half vector
    /// (`Fresnel::polarization`), (b, c, s) of its Mueller matrix over the
    /// unpolarised value, in Mitsuba's conventions. None for a model whose
    /// f is its own (rigorous gratings: their orders' matrices are
    /// `mueller`'s). A pair without a geometry (a direction below
    /// the horizon, where f is 0) takes normal incidence's.
    pub fn polarization(&self, wi: DVec3, wo: DVec3, lambda_nm: f64) -> Option<[f64; 3]> {
        if !self.polarizes() {
            return None;
        }
        let cos_half = PairGeometry::new(wi, wo).map_or(1.0, |g| g.cos_half);
        Some(self.fresnel.polarization(cos_half, lambda_nm))
    }

    /// Whether `mueller` gives matrices (all but rigorous gratings with a
    /// cover).
    pub fn has_mueller(&self) -> bool {
        if self.surface.is_unfactored() {
            return self.surface.has_unfactored_mueller();
        }
        self.polarizes()
    }

    /// The Mueller matrix of the reflection of light arriving from `from`
    /// and leaving along `to` at `lambda_nm`, over its [0][0] (which is the
    /// unpolarised value), and the Stokes basis vectors it is given in: of
    /// the incident direction of travel -from and of `to`, each
    /// perpendicular to its direction, the second basis vector of each
    /// being d x (the first) (Mitsuba's conventions). Surfaces whose value
    /// is F^2 G K: `polarization`'s matrix, its bases normal to the plane of
    /// reflection on the half vector h (h x -from, h x to, normalised; any
    /// perpendicular axis where that plane is undefined). Rigorous
    /// gratings: their orders' matrices from the solver's amplitudes, in
    /// bases tied to the grooves (`Periodic::rigorous_mueller`). None for a
    /// rigorous grating with a cover, and for directions that are zero or
    /// not finite.
    pub fn mueller(
        &self,
        from: DVec3,
        to: DVec3,
        lambda_nm: f64,
    ) -> Option<([f64; 16], [DVec3; 2])> {
        // Directions the core cannot take (zero, not finite): none.
        let (from, to) = (from.normalize_or_zero(), to.normalize_or_zero());
        if from == DVec3::ZERO || to == DVec3::ZERO || !lambda_nm.is_finite() {
            return None;
        }
        if self.surface.is_unfactored() {
            return self.surface.unfactored_mueller(from, to, lambda_nm);
        }
        let [b, c, s] = self.polarization(from, to, lambda_nm)?;
        let m = [
            1.0, b, 0.0, 0.0, b, 1.0, 0.0, 0.0, 0.0, 0.0, c, s, 0.0, 0.0, -s, c,
        ];
        let h = (from + to).normalize_or_zero();
        let axis = |d: DVec3| {
            let a = h.cross(d);
            if a.length_squared() > 1e-24 {
                a.normalize()
            } else {
                d.any_orthonormal_vector()
            }
        };
        Some((m, [axis(-from), axis(to)]))
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
    /// One wavelength: the energy factor from the table's two nodes around
    /// it (`eval_spectral_scaled` takes all the nodes, for several).
    #[inline]
    pub fn eval_spectral_with(
        &self,
        geom: &PairGeometry,
        lambda_nm: f64,
        fresnel: &FresnelAtCos,
    ) -> f64 {
        if let Some(f) = self.unfactored(geom, lambda_nm) {
            return f;
        }
        let f = f_spectral(geom, lambda_nm, fresnel, |k| self.surface.kernel(k, geom));
        match self.energy_table() {
            Some(t) if f > 0.0 => f * t.pair_at(geom.wi, geom.wo, lambda_nm),
            _ => f,
        }
    }

    /// f of a model with its own (`SurfaceModel::is_unfactored`): 0 outside
    /// the band, finite and non-negative; None for F^2 G K models.
    #[inline]
    fn unfactored(&self, geom: &PairGeometry, lambda_nm: f64) -> Option<f64> {
        if !self.surface.is_unfactored() {
            return None;
        }
        if !in_band(lambda_nm) {
            return Some(0.0);
        }
        let f = self.surface.unfactored_spectral(geom, lambda_nm)?;
        Some(finite_non_negative(f))
    }

    /// `eval_spectral_with` with the pair's energy scaling given (several
    /// wavelengths of one pair share it).
    #[inline]
    pub fn eval_spectral_scaled(
        &self,
        geom: &PairGeometry,
        lambda_nm: f64,
        fresnel: &FresnelAtCos,
        energy: &Option<PairEnergy>,
    ) -> f64 {
        if let Some(f) = self.unfactored(geom, lambda_nm) {
            return f;
        }
        let f = f_spectral(geom, lambda_nm, fresnel, |k| self.surface.kernel(k, geom));
        match energy {
            Some(e) if f > 0.0 => f * e.at(lambda_nm),
            _ => f,
        }
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
        if let Some(rgb) = self.surface.unfactored_rgb(&geom) {
            return gamut_map(rgb).map(finite_non_negative);
        }
        let energy = self.pair_energy(geom.wi, geom.wo);
        let factor = energy.as_ref().map(|e| move |lambda: f64| e.at(lambda));
        let shading = self.shading_with(factor.as_ref().map(|f| f as &dyn Fn(f64) -> f64));
        let rgb = reflectance(&shading, &geom);
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
        let Some(wi) = incidence_direction(wi) else {
            return 0.0;
        };
        let r = self
            .surface
            .coherent_spectral(&self.shading(), wi.z, lambda_nm);
        match self.pair_energy(wi, reflect(wi)) {
            Some(e) if r > 0.0 => finite_non_negative(r * e.at(lambda_nm)),
            _ => finite_non_negative(r),
        }
    }

    /// Coherent-lobe reflectance in linear sRGB.
    pub fn coherent_rgb(&self, wi: DVec3) -> [f64; 3] {
        let Some(wi) = incidence_direction(wi) else {
            return [0.0; 3];
        };
        let energy = self.pair_energy(wi, reflect(wi));
        let factor = energy.as_ref().map(|e| move |lambda: f64| e.at(lambda));
        let shading = self.shading_with(factor.as_ref().map(|f| f as &dyn Fn(f64) -> f64));
        let rgb = self.surface.coherent_rgb(&shading, wi.z);
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

/// The unit direction of wi when it is above the horizon, else None.
fn incidence_direction(wi: DVec3) -> Option<DVec3> {
    normalize_direction(wi).filter(|d| d.z > MIN_COS)
}

//! Gaussian random surfaces: isotropic (smooth metals) and anisotropic
//! (brushed metal). See docs/physics.md, "Gaussian random surfaces".
//!
//! With g = (k sigma w)^2 and x = k^2 (Tx^2 u^2 + Ty^2 v^2) / 4, the diffuse
//! kernel (the BRDF without F^2 and G) is
//!
//!   K = k^2 Tx Ty / (4 pi w^2) * S(g, x),
//!   S(g, x) = sum_{m >= 1} e^-g g^m / m! * exp(-x / m) / m,
//!
//! i.e. the expectation of phi(m) = exp(-x/m)/m over a Poisson(g) count m
//! (phi(0) = 0). The coherent lobe carries e^-g of the energy and is kept
//! out of K. Five ways to evaluate S, tried in this order per call:
//! - a universal table of ln S over (ln g, sqrt(x / (1 + g))), bicubic
//!   B-spline (1e-4 <= g < 1e4, rho < 60);
//! - asymptotic (g >= `asymptotic_min_g`, near the specular peak): the
//!   Poisson expectation by Gauss-Hermite quadrature with Edgeworth
//!   corrections up to O(g^-3/2), 8 nodes whatever g is;
//! - windowed sum (far tails beyond the table, g <= 40): the terms within 6
//!   standard deviations of the largest, summed in one vectorised pass;
//! - saddle-point quadrature: the terms as a smooth bell in m integrated by
//!   10-node Gauss-Hermite around its mode (large g off-specular, far tails);
//! - exact: the terms summed outward from the largest one by their ratios,
//!   stopping when a geometric bound on the tails falls below `tolerance`
//!   times the partial sum. Used for `series_tolerance` below 1e-5 (which
//!   also skips the table, windowed sum and saddle rule) and wherever the
//!   faster forms do not apply.
//!
//! Each form's accuracy against a plain log-space summation is measured in
//! the tests (all below 4e-5 relative).

pub mod params;
mod program;
mod program_rgb;
mod rgb;
mod sampling;
mod series;
#[cfg(test)]
mod tests;

pub use params::GaussianParams;
pub(crate) use rgb::RgbNodeTable;
pub use sampling::Lobe;
pub use series::{
    poisson_series, poisson_series_asymptotic, poisson_series_exact, poisson_series_reference,
    poisson_series_saddle, series_table_export, SeriesSettings, SeriesTableExport,
    DEFAULT_SERIES_TOLERANCE,
};

use crate::error::StamError;
use crate::models::{
    Shading, SurfaceModel, FLAG_ANISOTROPIC, FLAG_HAS_COHERENT, FLAG_SPECTRALLY_VARYING,
    MAX_RGB_NODES,
};
use crate::optics::fresnel::Fresnel;
use crate::optics::geometry::PairGeometry;
use crate::sampling::{Component, StrategyTable};
use crate::spectrum::{wavenumber_per_um, LAMBDA_MAX_NM};
use sampling::AlbedoTable;
use series::series_table;
use std::f64::consts::PI;
use std::sync::OnceLock;

/// Largest roughness exponent g for which the coherent lobe is evaluated:
/// beyond it e^-g < 1e-300, nothing a renderer can see.
pub(crate) const COHERENT_MAX_G: f64 = 690.0;

/// The Gaussian model of a material: the surface and the tables its
/// evaluation and sampling build on first use.
pub struct Gaussian {
    surface: GaussianSurface,
    /// The kernel at every node of the RGB rule over the pair variables,
    /// built on the first RGB evaluation (spectral-only use never pays for
    /// it); None when the material does not use tables.
    rgb_table: OnceLock<Option<RgbNodeTable>>,
    /// Diffuse albedo of isotropic surfaces for the coherent probability,
    /// built on the first sample.
    albedo: OnceLock<AlbedoTable>,
    /// Sampling strategies over the incidence cosine and the wavelength,
    /// made on the first sample.
    strategies: OnceLock<StrategyTable<Lobe>>,
    /// The RGB program's table (`program.rs`), built on the first export
    /// of the RGB eval program.
    rgb_program: OnceLock<Option<Box<program::RgbProgramTable>>>,
    /// The sampling programs' iterative fits over the incidence cosine and
    /// the wavelength (`program::FitTable`), made on the first export of a
    /// sampling program; None where they cannot use one.
    fit_table: OnceLock<Option<program::FitTable>>,
    /// A sigma texture's largest value (`sigma_um_max`): the programs then
    /// read sigma as a parameter everywhere (the renderer gives it per
    /// point) and their tables serve every sigma up to it.
    sigma_um_max: Option<f64>,
}

impl Gaussian {
    pub fn new(p: &GaussianParams) -> Gaussian {
        let mut surface = if p.anisotropic {
            GaussianSurface::anisotropic(p.sigma_um, p.corr_x_um, p.corr_y_um)
        } else {
            GaussianSurface::isotropic(p.sigma_um, p.corr_x_um)
        };
        surface.series = SeriesSettings::with_tolerance(p.series_tolerance);
        Gaussian {
            sigma_um_max: p.sigma_um_max,
            ..Gaussian::from_surface(surface)
        }
    }

    fn from_surface(surface: GaussianSurface) -> Gaussian {
        Gaussian {
            surface,
            rgb_table: OnceLock::new(),
            albedo: OnceLock::new(),
            strategies: OnceLock::new(),
            rgb_program: OnceLock::new(),
            fit_table: OnceLock::new(),
            sigma_um_max: None,
        }
    }

    pub fn surface(&self) -> &GaussianSurface {
        &self.surface
    }

    /// The model with other series settings (the accuracy survey); the
    /// tables built from the old ones are dropped.
    pub fn set_series(&mut self, series: SeriesSettings) {
        let mut surface = self.surface.clone();
        surface.series = series;
        *self = Gaussian::from_surface(surface);
    }

    /// The RGB table for the rule's wavenumbers, built on first use.
    #[inline]
    fn rgb_table(&self, k_per_um: &[f64]) -> Option<&RgbNodeTable> {
        self.rgb_table
            .get_or_init(|| RgbNodeTable::build(&self.surface, k_per_um))
            .as_ref()
    }

    /// K at the RGB rule's nodes into `values`: from the table where it
    /// serves the pair (`use_table`), else per node.
    pub(crate) fn kernel_at_nodes(
        &self,
        shading: &Shading,
        geom: &PairGeometry,
        use_table: bool,
        values: &mut [f64],
    ) {
        let rule = shading.rgb_rule;
        let from_table = use_table
            && self
                .rgb_table(&rule.k_per_um)
                .is_some_and(|t| t.kernel(&self.surface, geom, values));
        if !from_table {
            self.surface
                .kernel_at_wavenumbers(&rule.k_per_um, &rule.ln_k_per_um, geom, values);
        }
    }
}

impl SurfaceModel for Gaussian {
    type Params = GaussianParams;
    type Lobe = Lobe;

    fn from_params(p: &GaussianParams, _: &Fresnel) -> Result<Gaussian, StamError> {
        Ok(Gaussian::new(p))
    }

    fn flags(&self) -> u32 {
        let anisotropic = if self.surface.isotropic {
            0
        } else {
            FLAG_ANISOTROPIC
        };
        FLAG_HAS_COHERENT | FLAG_SPECTRALLY_VARYING | anisotropic
    }

    fn memory_bytes(&self) -> usize {
        self.albedo.get().map_or(0, |t| t.memory_bytes())
            + self.strategies.get().map_or(0, |t| t.memory_bytes())
            + self
                .rgb_table
                .get()
                .and_then(|t| t.as_ref())
                .map_or(0, |t| t.memory_bytes())
            + self
                .rgb_program
                .get()
                .and_then(|t| t.as_ref())
                .map_or(0, |t| t.memory_bytes())
    }

    #[inline]
    fn kernel(&self, k_per_um: f64, geom: &PairGeometry) -> f64 {
        self.surface.kernel(k_per_um, geom)
    }

    fn reflectance_rgb(&self, shading: &Shading, geom: &PairGeometry) -> [f64; 3] {
        let mut values = [0.0; MAX_RGB_NODES];
        let values = &mut values[..shading.rgb_rule.len()];
        self.kernel_at_nodes(shading, geom, true, values);
        shading.integrate(geom.cos_half, values)
    }

    fn coherent_spectral(&self, shading: &Shading, cos_i: f64, lambda_nm: f64) -> f64 {
        let k = wavenumber_per_um(lambda_nm);
        if self.surface.roughness_exponent(k, 2.0 * cos_i) > COHERENT_MAX_G {
            return 0.0;
        }
        shading.fresnel.reflectance(cos_i, lambda_nm) * self.surface.coherent_attenuation(k, cos_i)
    }

    fn coherent_rgb(&self, shading: &Shading, cos_i: f64) -> [f64; 3] {
        // Skip the integration when the lobe is gone even at the red end of
        // the band (g grows with k).
        let k_red = wavenumber_per_um(LAMBDA_MAX_NM);
        if self.surface.roughness_exponent(k_red, 2.0 * cos_i) > COHERENT_MAX_G {
            return [0.0; 3];
        }
        let rule = shading.rgb_rule;
        let mut values = [0.0; MAX_RGB_NODES];
        let values = &mut values[..rule.len()];
        for (v, &k) in values.iter_mut().zip(&rule.k_per_um) {
            *v = self.surface.coherent_attenuation(k, cos_i);
        }
        shading.integrate(cos_i, values)
    }

    fn spectral_component(
        &self,
        shading: &Shading,
        wi: glam::DVec3,
        lambda_nm: f64,
    ) -> Component<Lobe> {
        self.component(shading, wi, lambda_nm)
    }
}

/// A Gaussian-correlated height field: C(x, y) = sigma^2 exp(-x^2/Tx^2 - y^2/Ty^2).
#[derive(Clone, Debug, PartialEq)]
pub struct GaussianSurface {
    pub sigma_um: f64,
    pub corr_x_um: f64,
    pub corr_y_um: f64,
    /// Tx == Ty: the plan skips the per-axis weighting.
    pub isotropic: bool,
    pub series: SeriesSettings,
}

impl GaussianSurface {
    pub fn isotropic(sigma_um: f64, corr_um: f64) -> GaussianSurface {
        GaussianSurface {
            sigma_um,
            corr_x_um: corr_um,
            corr_y_um: corr_um,
            isotropic: true,
            series: SeriesSettings::default(),
        }
    }

    pub fn anisotropic(sigma_um: f64, corr_x_um: f64, corr_y_um: f64) -> GaussianSurface {
        GaussianSurface {
            sigma_um,
            corr_x_um,
            corr_y_um,
            isotropic: corr_x_um == corr_y_um,
            series: SeriesSettings::default(),
        }
    }

    /// Roughness exponent g = (k sigma w)^2.
    #[inline]
    pub fn roughness_exponent(&self, k_per_um: f64, w: f64) -> f64 {
        let a = k_per_um * self.sigma_um * w;
        a * a
    }

    /// x = k^2 (Tx^2 u^2 + Ty^2 v^2) / 4, the exponent of the lobes.
    #[inline]
    pub fn lobe_exponent(&self, k_per_um: f64, u: f64, v: f64) -> f64 {
        let k2 = k_per_um * k_per_um;
        if self.isotropic {
            0.25 * k2 * self.corr_x_um * self.corr_x_um * (u * u + v * v)
        } else {
            let tu = self.corr_x_um * u;
            let tv = self.corr_y_um * v;
            0.25 * k2 * (tu * tu + tv * tv)
        }
    }

    /// Diffuse kernel K (1/sr before F^2 and G) at wavenumber k.
    pub fn kernel(&self, k_per_um: f64, geom: &PairGeometry) -> f64 {
        let g = self.roughness_exponent(k_per_um, geom.w);
        let x = self.lobe_exponent(k_per_um, geom.u, geom.v);
        let s = poisson_series(g, x, &self.series);
        let prefactor =
            k_per_um * k_per_um * self.corr_x_um * self.corr_y_um / (4.0 * PI * geom.w * geom.w);
        prefactor * s
    }

    /// K at several wavenumbers (the RGB rule's nodes), sharing the
    /// geometry work: g and x scale as k^2, so ln g and sqrt(x) (the table's
    /// coordinates) are offsets and scalings of per-pair values.
    pub fn kernel_at_wavenumbers(
        &self,
        k_per_um: &[f64],
        ln_k_per_um: &[f64],
        geom: &PairGeometry,
        out: &mut [f64],
    ) {
        let g0 = self.roughness_exponent(1.0, geom.w);
        let x0 = self.lobe_exponent(1.0, geom.u, geom.v);
        let ln_g0 = g0.ln();
        let root_x0 = x0.sqrt();
        let prefactor0 = self.corr_x_um * self.corr_y_um / (4.0 * PI * geom.w * geom.w);
        for ((o, &k), &ln_k) in out.iter_mut().zip(k_per_um).zip(ln_k_per_um) {
            let k2 = k * k;
            let g = g0 * k2;
            let x = x0 * k2;
            let s = if self.series.use_table {
                match series_table().lookup_parts(g, ln_g0 + 2.0 * ln_k, root_x0 * k) {
                    Some(s) => s,
                    None => poisson_series(g, x, &self.series),
                }
            } else {
                poisson_series(g, x, &self.series)
            };
            *o = prefactor0 * k2 * s;
        }
    }

    /// Fraction e^-g of the energy left in the mirror lobe at incidence
    /// cosine cos_i (w = -2 cos_i there).
    pub fn coherent_attenuation(&self, k_per_um: f64, cos_i: f64) -> f64 {
        let g = self.roughness_exponent(k_per_um, 2.0 * cos_i);
        (-g).exp()
    }
}

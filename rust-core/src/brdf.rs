//! The material: a plan built once from parameters, evaluated many times.
//!
//! f(wi, wo; lambda) = F^2(wi . h, lambda) * G(wi, wo) * K(k; u, v, w), with K
//! the surface model's kernel (docs/physics.md). The plan holds only what
//! the parameters need: the one surface model, its tables, the Fresnel kind
//! and, for the RGB path, the wavelength rule.

use crate::error::StamError;
use crate::fractal::FractalSurface;
use crate::fresnel::{Fresnel, FresnelAtCos};
use crate::gaussian::{GaussianSurface, SeriesSettings};
use crate::gaussian_rgb::RgbNodeTable;
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

/// Largest node count of the RGB rule (params::range::RGB_NODES).
const MAX_RGB_NODES: usize = crate::params::range::RGB_NODES.1;

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
    /// The surface model. It may be adjusted (e.g. its series settings)
    /// before the first evaluation; the Gaussian RGB table is built from it
    /// on the first RGB evaluation and not rebuilt after later changes.
    pub surface: Surface,
    pub fresnel: Fresnel,
    /// Wavelength rule of the RGB path for spectrally smooth surfaces.
    rgb_rule: RgbRule,
    /// Diffuse albedo table of the sampling strategy (isotropic Gaussian
    /// surfaces), built on the first sample.
    pub(crate) sampling_albedo: std::sync::OnceLock<crate::sampling::AlbedoTable>,
    /// Periodic surfaces: the sampling strategy's order weights over the
    /// incident direction, made on the first sample.
    pub(crate) grating_table: std::sync::OnceLock<Option<crate::sampling::GratingTable>>,
    /// Gaussian and fractal surfaces: sampling strategies over the incidence
    /// cosine and the wavelength, made on the first sample.
    pub(crate) component_table: std::sync::OnceLock<crate::sampling::ComponentTable>,
    /// Periodic surfaces with a metal's Fresnel: its reflectance at the
    /// wavelengths of the RGB rule for broad peaks (9 kB).
    broad_reflectance: Option<crate::fresnel::NodeReflectance>,
    /// Gaussian surfaces: the kernel at every node of the rule over the
    /// pair variables, built on the first RGB evaluation (spectral-only use
    /// never pays for it); None when the material does not use tables.
    rgb_table: std::sync::OnceLock<Option<RgbNodeTable>>,
}

/// Cosine bins of the Fresnel-weighted RGB rule.
const FRESNEL_COS_BINS: usize = 256;

/// The RGB path for kernels smooth in wavelength (Gaussian, fractal, the
/// coherent lobe): f_c = sum_j K(nu_j) w_jc(cos). A metal's Fresnel spectrum
/// is not smooth enough to interpolate from a dozen nodes, so it is folded
/// into the weights instead: w_jc(cos) integrates the rule's basis against
/// F^2(cos, lambda) W_c(lambda) on the 1 nm grid, tabulated over the cosine
/// and interpolated linearly. Wavelength-independent Fresnel keeps the plain
/// weights (no table).
struct RgbRule {
    rule: &'static SmoothRule,
    k_per_um: Vec<f64>,
    ln_k_per_um: Vec<f64>,
    /// (FRESNEL_COS_BINS + 1) rows of one weight triple per node; empty when
    /// the Fresnel term does not depend on wavelength.
    fresnel_weights: Vec<[f64; 3]>,
}

impl RgbRule {
    fn new(node_count: usize, fresnel: &Fresnel) -> RgbRule {
        let rule = spectrum::smooth_rule(node_count);
        let fresnel_weights = if fresnel.is_spectrally_flat() {
            Vec::new()
        } else {
            (0..=FRESNEL_COS_BINS)
                .flat_map(|b| {
                    let cos = b as f64 / FRESNEL_COS_BINS as f64;
                    rule.weights_with_factor(|lambda| fresnel.reflectance(cos, lambda))
                })
                .collect()
        };
        let k_per_um: Vec<f64> = rule.nu_per_um.iter().map(|nu| 2.0 * PI * nu).collect();
        RgbRule {
            ln_k_per_um: k_per_um.iter().map(|k| k.ln()).collect(),
            k_per_um,
            rule,
            fresnel_weights,
        }
    }

    fn len(&self) -> usize {
        self.k_per_um.len()
    }

    fn memory_bytes(&self) -> usize {
        self.k_per_um.len() * 8 + self.fresnel_weights.len() * 24
    }

    /// sum_j values[j] F^2(cos, lambda_j) w_jc, with F^2 folded as above.
    #[inline]
    fn integrate(&self, fresnel: &Fresnel, cos: f64, values: &[f64]) -> [f64; 3] {
        let n = self.len();
        let mut acc = [0.0; 3];
        if self.fresnel_weights.is_empty() {
            let r = fresnel.reflectance(cos, 550.0);
            for (v, w) in values.iter().zip(&self.rule.weights) {
                acc[0] += v * w[0];
                acc[1] += v * w[1];
                acc[2] += v * w[2];
            }
            return acc.map(|a| a * r);
        }
        let t = cos.clamp(0.0, 1.0) * FRESNEL_COS_BINS as f64;
        let b = (t as usize).min(FRESNEL_COS_BINS - 1);
        let frac = t - b as f64;
        let row0 = &self.fresnel_weights[b * n..(b + 1) * n];
        let row1 = &self.fresnel_weights[(b + 1) * n..(b + 2) * n];
        for ((v, w0), w1) in values.iter().zip(row0).zip(row1) {
            for c in 0..3 {
                acc[c] += v * (w0[c] + frac * (w1[c] - w0[c]));
            }
        }
        acc
    }
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
                s.series = SeriesSettings::with_tolerance(params.accuracy.series_tolerance);
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
        // Periodic surfaces integrate their orders against the matching
        // functions themselves and never use the smooth rule.
        let node_count = match surface {
            Surface::Periodic(_) => 0,
            _ => params.accuracy.rgb_nodes,
        };
        let rgb_rule = if node_count == 0 {
            RgbRule {
                rule: spectrum::smooth_rule(1),
                k_per_um: Vec::new(),
                ln_k_per_um: Vec::new(),
                fresnel_weights: Vec::new(),
            }
        } else {
            RgbRule::new(node_count, &params.fresnel)
        };
        let broad_reflectance = match surface {
            Surface::Periodic(_) => crate::fresnel::NodeReflectance::new(
                &params.fresnel,
                PeriodicSurface::broad_rule_wavelengths(),
            ),
            _ => None,
        };
        Ok(Brdf {
            fresnel: params.fresnel.clone(),
            params,
            surface,
            rgb_rule,
            sampling_albedo: std::sync::OnceLock::new(),
            grating_table: std::sync::OnceLock::new(),
            component_table: std::sync::OnceLock::new(),
            broad_reflectance,
            rgb_table: std::sync::OnceLock::new(),
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
            + self.rgb_rule.memory_bytes()
            + self.sampling_albedo.get().map_or(0, |t| t.memory_bytes())
            + self.component_table.get().map_or(0, |t| t.memory_bytes())
            + self
                .broad_reflectance
                .as_ref()
                .map_or(0, |t| t.memory_bytes())
            + self
                .grating_table
                .get()
                .and_then(|t| t.as_ref())
                .map_or(0, |t| t.memory_bytes())
            + self
                .rgb_table
                .get()
                .and_then(|t| t.as_ref())
                .map_or(0, |t| t.memory_bytes())
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

    /// The Gaussian RGB table, built on first use.
    #[inline]
    fn gaussian_rgb_table(&self, s: &GaussianSurface) -> Option<&RgbNodeTable> {
        self.rgb_table
            .get_or_init(|| RgbNodeTable::build(s, &self.rgb_rule.k_per_um))
            .as_ref()
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
        self.eval_spectral_with(geom, lambda_nm, &self.fresnel.at_cos(geom.cos_half))
    }

    /// `eval_spectral_at` with the Fresnel term at the pair's cosine given.
    #[inline]
    pub fn eval_spectral_with(
        &self,
        geom: &PairGeometry,
        lambda_nm: f64,
        fresnel: &FresnelAtCos,
    ) -> f64 {
        if !in_band(lambda_nm) {
            return 0.0;
        }
        let k = wavenumber_per_um(lambda_nm);
        let f = fresnel.reflectance(lambda_nm) * geom.geometric_factor * self.kernel(k, geom);
        finite_non_negative(f)
    }

    /// f projected to linear sRGB (D65-weighted), without the coherent lobe.
    pub fn eval_rgb(&self, wi: DVec3, wo: DVec3) -> [f64; 3] {
        self.eval_rgb_with(wi, wo, true)
    }

    /// `eval_rgb`, optionally without the Gaussian RGB table (the per-node
    /// path it stands in for).
    fn eval_rgb_with(&self, wi: DVec3, wo: DVec3, gaussian_table: bool) -> [f64; 3] {
        let Some(geom) = PairGeometry::new(wi, wo) else {
            return [0.0; 3];
        };
        let rgb = match &self.surface {
            Surface::Periodic(s) => {
                let fresnel = self.fresnel.at_cos(geom.cos_half);
                let reflectance = |lambda_nm: f64| fresnel.reflectance(lambda_nm);
                let nodes = PeriodicSurface::broad_rule_wavelengths();
                let at_node =
                    |j: usize| fresnel.at_node(self.broad_reflectance.as_ref(), j, nodes[j]);
                s.kernel_rgb_with(&geom, &reflectance, &at_node)
            }
            _ => {
                let mut values = [0.0; MAX_RGB_NODES];
                let values = &mut values[..self.rgb_rule.len()];
                let rule = &self.rgb_rule;
                if let Surface::Gaussian(s) = &self.surface {
                    let from_table = gaussian_table
                        && self
                            .gaussian_rgb_table(s)
                            .is_some_and(|t| t.kernel(s, &geom, values));
                    if !from_table {
                        s.kernel_at_wavenumbers(&rule.k_per_um, &rule.ln_k_per_um, &geom, values);
                    }
                } else if let Surface::Fractal(s) = &self.surface {
                    s.kernel_at_wavenumbers(&rule.k_per_um, &rule.ln_k_per_um, &geom, values);
                }
                self.rgb_rule
                    .integrate(&self.fresnel, geom.cos_half, values)
            }
        };
        gamut_map(rgb.map(|c| c * geom.geometric_factor)).map(finite_non_negative)
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
        // Skip the integration when the lobe is gone even at the red end of
        // the band (g grows with k).
        if s.roughness_exponent(wavenumber_per_um(LAMBDA_MAX_NM), 2.0 * cos_i) > COHERENT_MAX_G {
            return [0.0; 3];
        }
        let mut values = [0.0; MAX_RGB_NODES];
        let values = &mut values[..self.rgb_rule.len()];
        for (v, &k) in values.iter_mut().zip(&self.rgb_rule.k_per_um) {
            *v = s.coherent_attenuation(k, cos_i);
        }
        let rgb = self.rgb_rule.integrate(&self.fresnel, cos_i, values);
        gamut_map(rgb).map(finite_non_negative)
    }
}

/// Luminance weights of linear sRGB (the Y row of sRGB -> XYZ).
pub const SRGB_LUMINANCE: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// Brings an RGB value into the sRGB gamut without changing its luminance.
///
/// The sharp spectral peaks of gratings are purer than any sRGB primary:
/// their exact projection has a negative channel (the compact disc's green
/// arcs project to about (-0.59, 1, -0.08)). Outputs must be non-negative,
/// and clamping the negative channel would add light (+47% red over the
/// compact disc). Instead the colour is desaturated towards the grey of the
/// same luminance, just enough for the most negative channel to reach 0: Y
/// (and so the brightness of a render) is exact and the hue is kept; only
/// the saturation beyond the gamut is lost. In-gamut values are unchanged.
#[inline]
pub fn gamut_map(rgb: [f64; 3]) -> [f64; 3] {
    let min = rgb[0].min(rgb[1]).min(rgb[2]);
    if min >= 0.0 || min.is_nan() {
        return rgb;
    }
    let y = SRGB_LUMINANCE[0] * rgb[0] + SRGB_LUMINANCE[1] * rgb[1] + SRGB_LUMINANCE[2] * rgb[2];
    if !(y > 0.0) {
        return [0.0; 3];
    }
    let s = min / (min - y);
    rgb.map(|c| c + s * (y - c))
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

#[cfg(test)]
mod tests {
    use super::*;

    fn directions() -> Vec<(DVec3, DVec3)> {
        let mut out = Vec::new();
        for &(ti, phi_i) in &[(0.05, 0.0), (0.5, 0.3), (1.1, 1.0), (1.45, 2.0)] {
            let wi = DVec3::new(
                f64::sin(ti) * f64::cos(phi_i),
                f64::sin(ti) * f64::sin(phi_i),
                f64::cos(ti),
            );
            for &(to, dphi) in &[(0.0, 0.0), (0.1, 0.2), (0.3, 0.5), (0.6, 2.5), (1.2, 3.0)] {
                // Around the mirror direction of wi.
                let m = DVec3::new(-wi.x, -wi.y, wi.z);
                let tilt = DVec3::new(
                    f64::sin(to) * f64::cos(dphi),
                    f64::sin(to) * f64::sin(dphi),
                    0.0,
                );
                let wo = (m + tilt).normalize();
                if wo.z > 0.01 {
                    out.push((wi, wo));
                }
            }
        }
        out
    }

    /// The RGB path against the 1 nm reference integration of the spectral
    /// path, for the spectrally smooth models and each Fresnel kind. The
    /// error is relative to the largest channel.
    #[test]
    fn rgb_matches_1nm_reference_for_smooth_models() {
        let materials = [
            r#"{"surface":"gaussian","sigma_um":0.03,"corr_um":2.0,"fresnel":"gold"}"#,
            r#"{"surface":"gaussian","sigma_um":0.12,"corr_um":3.0,"fresnel":"copper"}"#,
            r#"{"surface":"gaussian","sigma_um":0.5,"corr_um":4.0}"#,
            r#"{"surface":"gaussian","sigma_um":2.0,"corr_um":10.0,"fresnel":{"eta":1.5,"k":0}}"#,
            r#"{"surface":"gaussian","sigma_um":0.1,"corr_x_um":1.0,"corr_y_um":12.0,"fresnel":"silver"}"#,
            r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.1,"lag_um":1.0,"fresnel":"gold"}"#,
            r#"{"surface":"fractal","hurst":0.3,"sigma_um":0.05,"lag_um":2.0,"fresnel":0.8}"#,
        ];
        let mut worst: f64 = 0.0;
        for json in materials {
            let brdf = Brdf::from_json(json).unwrap();
            for (wi, wo) in directions() {
                let fast = brdf.eval_rgb(wi, wo);
                // Saturated spectral colours fall outside the sRGB gamut; the
                // outputs are gamut-mapped and so is the reference.
                let reference = gamut_map(brdf.eval_rgb_reference(wi, wo, 1.0));
                let scale = reference.iter().cloned().fold(0.0, f64::max);
                if scale < 1e-12 {
                    continue;
                }
                for c in 0..3 {
                    let e = (fast[c] - reference[c]).abs() / scale;
                    if e > worst {
                        worst = e;
                    }
                    assert!(
                        e < 5e-3,
                        "{json} wi {wi:?} wo {wo:?}: {fast:?} vs {reference:?}"
                    );
                }
            }
        }
        println!(
            "RGB vs 1 nm reference, smooth models: worst error {worst:.2e} of the largest channel"
        );
    }

    /// The Gaussian RGB table against the per-node path it stands in for,
    /// at random pairs (uniform, near the mirror direction, grazing down to
    /// cos = 1e-4): wherever the table serves the pair, the RGB agrees to
    /// 1e-4 of the largest channel; everywhere else (grazing pairs below its
    /// rows, tails beyond its columns) the result is the per-node path's,
    /// bit for bit.
    #[test]
    fn gaussian_rgb_table_matches_per_node_path_and_falls_back_outside() {
        let materials = [
            r#"{"surface":"gaussian","sigma_um":0.03,"corr_um":2.0,"fresnel":"gold"}"#,
            r#"{"surface":"gaussian","sigma_um":0.6,"corr_um":4.0}"#,
            r#"{"surface":"gaussian","sigma_um":0.15,"corr_x_um":1.0,"corr_y_um":15.0,"fresnel":"silver"}"#,
            r#"{"surface":"gaussian","sigma_um":5.0,"corr_um":30.0,"fresnel":{"eta":1.5,"k":0}}"#,
            r#"{"surface":"gaussian","sigma_um":0.005,"corr_um":0.3,"rgb_nodes":16}"#,
        ];
        let mut rng = crate::benchmark::SplitMix64(3);
        let mut direction = |cos_lo: f64| {
            let ct = cos_lo + (1.0 - cos_lo) * rng.next_f64();
            let phi = 2.0 * PI * rng.next_f64();
            let st = (1.0 - ct * ct).sqrt();
            DVec3::new(st * phi.cos(), st * phi.sin(), ct)
        };
        let (mut served, mut missed) = (0, 0);
        let mut worst: f64 = 0.0;
        for json in materials {
            let brdf = Brdf::from_json(json).unwrap();
            let Surface::Gaussian(s) = &brdf.surface else {
                unreachable!()
            };
            let table = brdf.gaussian_rgb_table(s).expect("table");
            let mut values = vec![0.0; brdf.rgb_rule.len()];
            for i in 0..3000 {
                let wi = direction(if i % 3 == 0 { 1e-4 } else { 0.05 });
                let wo = if i % 3 == 1 {
                    (DVec3::new(-wi.x, -wi.y, wi.z) + 0.2 * direction(0.0)).normalize()
                } else {
                    direction(if i % 3 == 0 { 1e-4 } else { 0.0 })
                };
                let Some(geom) = PairGeometry::new(wi, wo) else {
                    continue;
                };
                let fast = brdf.eval_rgb(wi, wo);
                let per_node = brdf.eval_rgb_with(wi, wo, false);
                if table.kernel(s, &geom, &mut values) {
                    served += 1;
                    let scale = per_node.iter().cloned().fold(0.0, f64::max);
                    for c in 0..3 {
                        let e = (fast[c] - per_node[c]).abs() / scale.max(1e-300);
                        worst = worst.max(e);
                        assert!(e < 1e-4, "{json} {wi} {wo}: {fast:?} vs {per_node:?}");
                    }
                } else {
                    missed += 1;
                    assert_eq!(fast, per_node, "{json} {wi} {wo}");
                }
            }
        }
        println!(
            "RGB table vs per-node path: {served} pairs served (worst {worst:.1e} of the largest channel), {missed} by the per-node path"
        );
        assert!(served > 10 * missed && missed > 50, "{served} {missed}");
    }

    /// The table is built on the first RGB evaluation only, not for exact
    /// series settings, and counted in the memory of the material, which
    /// stays under 4 MiB whatever the node count.
    #[test]
    fn gaussian_rgb_table_is_lazy_and_within_memory_limit() {
        let wi = DVec3::new(0.3, 0.1, 0.9).normalize();
        let wo = DVec3::new(-0.2, -0.1, 0.95).normalize();
        for nodes in [4, 12, 16, 24, 32, 64] {
            let json = format!(
                r#"{{"surface":"gaussian","sigma_um":0.2,"corr_x_um":2.0,"corr_y_um":9.0,"fresnel":"copper","rgb_nodes":{nodes}}}"#
            );
            let brdf = Brdf::from_json(&json).unwrap();
            let before = brdf.memory_bytes();
            brdf.eval_spectral(wi, wo, 550.0);
            assert!(brdf.rgb_table.get().is_none(), "{json}");
            brdf.eval_rgb(wi, wo);
            let table = brdf.rgb_table.get().unwrap().as_ref().expect("table");
            let after = brdf.memory_bytes();
            println!("{nodes} nodes: {before} bytes, {after} with the RGB table");
            assert_eq!(after, before + table.memory_bytes());
            assert!(table.memory_bytes() <= crate::gaussian_rgb::MAX_TABLE_BYTES + 4096);
            assert!(after < 4 << 20, "{json}: {after} bytes");
        }
        let exact = Brdf::from_json(
            r#"{"surface":"gaussian","sigma_um":0.2,"corr_um":2.0,"series_tolerance":1e-7}"#,
        )
        .unwrap();
        exact.eval_rgb(wi, wo);
        assert!(exact.rgb_table.get().unwrap().is_none());
    }

    #[test]
    fn gamut_mapping_keeps_luminance_and_in_gamut_colours() {
        let luminance = |c: [f64; 3]| {
            SRGB_LUMINANCE[0] * c[0] + SRGB_LUMINANCE[1] * c[1] + SRGB_LUMINANCE[2] * c[2]
        };
        assert_eq!(gamut_map([0.2, 0.5, 0.1]), [0.2, 0.5, 0.1]);
        for rgb in [[-0.59, 1.0, -0.08], [2.0, -0.3, 0.1], [-1e-3, 0.2, 3.0]] {
            let m = gamut_map(rgb);
            assert!(m.iter().all(|&c| c >= -1e-15), "{m:?}");
            assert!(
                m.iter().any(|&c| c.abs() < 1e-12),
                "{m:?} touches the gamut"
            );
            assert!((luminance(m) - luminance(rgb)).abs() < 1e-12);
            // Hue kept: the mapped colour lies on the segment from the
            // original towards its grey.
            let y = luminance(rgb);
            let t = (m[1] - rgb[1]) / (y - rgb[1]);
            for c in 0..3 {
                assert!((m[c] - (rgb[c] + t * (y - rgb[c]))).abs() < 1e-12);
            }
        }
        assert_eq!(gamut_map([-1.0, 0.1, 0.1]), [0.0; 3]);
    }

    /// The compact disc's RGB keeps the luminance of the exact projection
    /// (a reference fine enough to resolve its peaks) within 1%.
    /// The broad-peak rule's reflectance from the node table equals the
    /// metal's reflectance at those wavelengths (the table has exact rows
    /// there; the grid interpolates between 1 nm rows): RGB of compact discs
    /// of two metals, through both, within 1e-4 of the largest channel.
    #[test]
    fn broad_rule_node_reflectance_matches_grid() {
        for metal in ["aluminium", "gold"] {
            let brdf = Brdf::from_json(&format!(
                r#"{{"surface":"cd","coherence_um":3.75,"fresnel":"{metal}"}}"#
            ))
            .unwrap();
            let Surface::Periodic(s) = &brdf.surface else {
                panic!("periodic");
            };
            assert!(brdf.broad_reflectance.is_some());
            let mut worst: f64 = 0.0;
            for (wi, wo) in directions() {
                let Some(geom) = PairGeometry::new(wi, wo) else {
                    continue;
                };
                let fresnel = brdf.fresnel.at_cos(geom.cos_half);
                let nodes = PeriodicSurface::broad_rule_wavelengths();
                let with_table = s.kernel_rgb_with(&geom, &|l| fresnel.reflectance(l), &|j| {
                    fresnel.at_node(brdf.broad_reflectance.as_ref(), j, nodes[j])
                });
                let plain = s.kernel_rgb(&geom, &|l| brdf.fresnel.reflectance(geom.cos_half, l));
                let m = plain.iter().fold(0.0f64, |a, c| a.max(c.abs()));
                if m > 0.0 {
                    for c in 0..3 {
                        worst = worst.max((with_table[c] - plain[c]).abs() / m);
                    }
                }
            }
            println!(
                "{metal}: node table against the grid, worst {worst:.1e} of the largest channel"
            );
            assert!(worst < 1e-4, "{metal}: {worst}");
        }
    }

    #[test]
    fn compact_disc_rgb_keeps_luminance() {
        let brdf = Brdf::from_json(r#"{"surface":"cd","coherence_um":10}"#).unwrap();
        let wi = DVec3::new(0.3, 0.0, 0.954).normalize();
        let mut checked = 0;
        for i in 0..40 {
            let t = -0.9 + 1.8 * i as f64 / 39.0;
            let wo = DVec3::new(t, 0.02, (1.0 - t * t - 0.0004).sqrt());
            let exact = brdf.eval_rgb_reference(wi, wo, 0.02);
            let y_exact = SRGB_LUMINANCE
                .iter()
                .zip(exact)
                .map(|(w, c)| w * c)
                .sum::<f64>();
            if y_exact < 1e-6 {
                continue;
            }
            let fast = brdf.eval_rgb(wi, wo);
            let y_fast = SRGB_LUMINANCE
                .iter()
                .zip(fast)
                .map(|(w, c)| w * c)
                .sum::<f64>();
            assert!(
                (y_fast - y_exact).abs() < 1e-2 * y_exact,
                "{fast:?} vs {exact:?}"
            );
            checked += 1;
        }
        assert!(checked > 5);
    }

    #[test]
    fn flat_spectrum_maps_to_equal_rgb() {
        // Fresnel constant and a kernel with no wavelength dependence: the
        // H = 1 fractal is the geometric-optics (Beckmann) limit.
        let brdf = Brdf::from_json(
            r#"{"surface":"fractal","hurst":1.0,"sigma_um":0.2,"lag_um":1.0,"fresnel":0.5}"#,
        )
        .unwrap();
        let wi = DVec3::new(0.3, 0.1, 0.9).normalize();
        let wo = DVec3::new(-0.25, -0.05, 0.95).normalize();
        let spectral = brdf.eval_spectral(wi, wo, 550.0);
        let rgb = brdf.eval_rgb(wi, wo);
        for c in rgb {
            assert!(
                (c - spectral).abs() < 1e-6 * spectral,
                "{rgb:?} vs {spectral}"
            );
        }
    }

    #[test]
    fn coherent_rgb_matches_reference() {
        let brdf = Brdf::from_json(
            r#"{"surface":"gaussian","sigma_um":0.06,"corr_um":2.0,"fresnel":"gold"}"#,
        )
        .unwrap();
        for &ct in &[1.0, 0.7, 0.3, 0.05] {
            let wi = DVec3::new((1.0f64 - ct * ct).sqrt(), 0.0, ct);
            let fast = brdf.coherent_rgb(wi);
            let reference =
                spectrum::integrate_rgb_reference(|l| brdf.coherent_spectral(wi, l), 1.0)
                    .map(|c| c.max(0.0));
            let scale = reference.iter().cloned().fold(0.0, f64::max);
            for c in 0..3 {
                assert!(
                    (fast[c] - reference[c]).abs() < 2e-3 * scale,
                    "{fast:?} vs {reference:?}"
                );
            }
        }
    }
}

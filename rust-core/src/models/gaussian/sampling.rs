//! Sampling of Gaussian surfaces. The diffuse kernel is (1/w^2) times a
//! normalised density in the projected plane (u, v) = -(wi + wo)_xy:
//! sum_m Poisson(m; g) N2(u, v; var_u = 2m/(k Tx)^2, var_v = 2m/(k Ty)^2).
//! The strategy freezes g at the mirror configuration (g0), which keeps the
//! density exact and normalised; the model's actual variation across the
//! lobe only costs variance. Smooth surfaces get the series lobe (or its
//! solid-angle twin near the horizon), rough ones (g0 >= BECKMANN_MIN_G)
//! Beckmann half-vector sampling; the coherent lobe's probability follows
//! its share of the albedo (`AlbedoTable`).

use super::{Gaussian, COHERENT_MAX_G};
use crate::models::{f_spectral, Shading};
use crate::optics::geometry::{normalize_direction, PairGeometry, MIN_COS};
use crate::program::{Builder, Value};
use crate::sampling::warps::{inverse_normal, normal_cdf, radical_inverse, uv_to_direction};
use crate::sampling::{
    Component, Components, Mixture, SplitMix64, DEFENSIVE_FRACTION, RGB_BAND_NM,
};
use crate::special::fast_exp;
use crate::spectrum::wavenumber_per_um;
use glam::DVec3;
use smallvec::smallvec;
use std::f64::consts::PI;

use super::series::{poisson_series, SeriesSettings};

/// Mirror roughness exponent g0 from which Gaussian surfaces are sampled with
/// the Beckmann asymptote (alpha = 2 sigma / T) instead of the series terms.
pub const BECKMANN_MIN_G: f64 = 30.0;
/// The series lobe is replaced by its solid-angle twin (`HorizonLobe`) when
/// the mirror point is within this many lobe sds of the rim of the projected
/// disk (measured: the twin alone beats an equal mixture with the plane
/// lobe at grazing incidence, 10x against 3x for the smooth test surface).
const HORIZON_REACH_SD: f64 = 2.0;
/// Defensive (cosine) share of the non-coherent probability for such lobes
/// on surfaces that are rough at w ~ 1 (DEFENSIVE_FRACTION for smooth ones).
const NEAR_HORIZON_DEFENSIVE_FRACTION: f64 = 0.5;
/// Cap on the Poisson term index when inverting its CDF.
const SERIES_MAX_TERMS: usize = 4096;

/// The lobes of a Gaussian surface's strategy.
#[derive(Clone)]
pub enum Lobe {
    Series(SeriesLobe),
    /// Instead of the series lobe when it reaches the horizon: its
    /// solid-angle twin (`HorizonLobe`).
    Horizon(HorizonLobe),
    /// Beckmann half-vector sampling with slopes' sd alpha / sqrt(2) per axis.
    Beckmann {
        ax: f64,
        ay: f64,
    },
}

impl crate::sampling::Lobe for Lobe {
    type Model = Gaussian;

    fn sample(&self, _: &Gaussian, wi: DVec3, t: f64, r1: f64, r2: f64) -> Option<DVec3> {
        match self {
            Lobe::Series(s) => {
                let (u, v) = s.sample(t, r1, r2);
                uv_to_direction(wi, u, v)
            }
            Lobe::Horizon(horizon) => horizon.sample(r1, r2),
            Lobe::Beckmann { ax, ay } => {
                let sx = ax * std::f64::consts::FRAC_1_SQRT_2 * inverse_normal(r1);
                let sy = ay * std::f64::consts::FRAC_1_SQRT_2 * inverse_normal(r2);
                let h = DVec3::new(-sx, -sy, 1.0).normalize();
                let wo = 2.0 * wi.dot(h) * h - wi;
                if wo.z > MIN_COS && wi.dot(h) > 0.0 {
                    normalize_direction(wo)
                } else {
                    None
                }
            }
        }
    }

    fn pdf(&self, _: &Gaussian, wi: DVec3, wo: DVec3, negligible: f64) -> f64 {
        match self {
            Lobe::Series(s) => {
                let (u, v) = (-(wi.x + wo.x), -(wi.y + wo.y));
                s.pdf_uv(u, v, negligible / wo.z) * wo.z
            }
            Lobe::Horizon(horizon) => horizon.pdf(wo),
            Lobe::Beckmann { ax, ay } => {
                let sum = wi + wo;
                let len = sum.length();
                if !(len > 0.0) {
                    return 0.0;
                }
                let h = sum / len;
                let cos_ih = wi.dot(h);
                if !(h.z > 0.0 && cos_ih > 0.0) {
                    return 0.0;
                }
                let (sx, sy) = (h.x / h.z, h.y / h.z);
                let e = sx * sx / (ax * ax) + sy * sy / (ay * ay);
                let p22 = fast_exp(-e) / (PI * ax * ay);
                let d = p22 / h.z.powi(4);
                d * h.z / (4.0 * cos_ih)
            }
        }
    }
}

/// Gaussian series: term m ~ Poisson(g0) conditioned on m >= 1, then an
/// axis-aligned Gaussian in (u, v) of variances 2m/(k Tx)^2, 2m/(k Ty)^2.
/// The mixture's density is k^2 Tx Ty S(g0, x) / (4 pi (1 - e^-g0)) with
/// x = k^2 (Tx^2 u^2 + Ty^2 v^2) / 4: the diffuse kernel's own series, so
/// the pdf costs one evaluation of S (the universal table) whatever the
/// number of terms, and nothing is allocated.
#[derive(Clone)]
pub struct SeriesLobe {
    pub(crate) g0: f64,
    pub(crate) k: f64,
    pub(crate) tx: f64,
    pub(crate) ty: f64,
    /// P(m = 1) = g0 / (e^g0 - 1).
    pub(crate) p_first: f64,
    /// k^2 Tx Ty / (4 pi (1 - e^-g0)).
    pub(crate) norm: f64,
}

impl SeriesLobe {
    fn new(g0: f64, k: f64, tx: f64, ty: f64) -> Option<SeriesLobe> {
        if !(g0 > 0.0 && g0.is_finite() && k > 0.0 && tx > 0.0 && ty > 0.0) {
            return None;
        }
        let p_first = g0 / g0.exp_m1();
        let norm = k * k * tx * ty / (4.0 * PI * -(-g0).exp_m1());
        if !(p_first > 0.0 && norm.is_finite() && norm > 0.0) {
            return None;
        }
        Some(SeriesLobe {
            g0,
            k,
            tx,
            ty,
            p_first,
            norm,
        })
    }

    /// Term index by inversion of the conditioned Poisson CDF from m = 1
    /// (g0 < BECKMANN_MIN_G, so at most a few dozen steps).
    fn term(&self, t: f64) -> f64 {
        let (mut m, mut p, mut acc) = (1.0, self.p_first, self.p_first);
        while t >= acc && m < SERIES_MAX_TERMS as f64 {
            m += 1.0;
            p *= self.g0 / m;
            acc += p;
            // Past the mode with nothing left to add: rounding left t above
            // the total; stay at the last term that carried weight.
            if p < 1e-300 {
                break;
            }
        }
        m
    }

    fn sample(&self, t: f64, r1: f64, r2: f64) -> (f64, f64) {
        let m = self.term(t);
        let s = (2.0 * m).sqrt() / self.k;
        (
            s / self.tx * inverse_normal(r1),
            s / self.ty * inverse_normal(r2),
        )
    }

    /// Density in (u, v); 0 when it is certainly below `negligible` (the
    /// far tails, where the series is slow and adds nothing to the mixture).
    fn pdf_uv(&self, u: f64, v: f64, negligible: f64) -> f64 {
        let (tu, tv) = (self.tx * u, self.ty * v);
        let x = 0.25 * self.k * self.k * (tu * tu + tv * tv);
        // S(g0, x) <= e^(-x / m_hi) + P(M > m_hi), the Poisson tail beyond
        // g0 + 10 sd + 15 being far below 1e-20.
        let m_hi = self.g0 + 10.0 * self.g0.sqrt() + 15.0;
        if self.norm * (fast_exp(-x / m_hi) + 1e-20) < negligible {
            return 0.0;
        }
        self.norm * poisson_series(self.g0, x, &SeriesSettings::default())
    }
}

/// A Gaussian lobe of sd `s` around the mirror point c0 = -wi_xy of the
/// projected disk, sampled in solid angle instead of in the plane. Near the
/// rim of the disk (grazing directions) the kernel's G / w^2 grows as
/// 1 / cos_o, so f cos_o is proportional to the plane density itself per
/// unit solid angle, while a plane-sampled lobe has pdf_omega = density x
/// cos_o: its weights diverge at the horizon. Here, with (x', y') the plane
/// coordinates along and across c0 and x' = R cos(alpha), R = sqrt(1 - y'^2),
/// the solid angle is d omega = d alpha dy' exactly, y' is drawn from the
/// Gaussian's marginal N(0, s) and alpha from a normal truncated to
/// [0, pi] fitted to exp(-(R cos(alpha) - |c0|)^2 / (2 s^2)): the density
/// stays finite and lobe-shaped up to the horizon.
#[derive(Clone)]
pub struct HorizonLobe {
    /// Unit vector of c0 in the plane (x axis when c0 = 0).
    pub(crate) along: [f64; 2],
    /// sd of y', across c0.
    pub(crate) s: f64,
    /// The truncated normal in alpha (fitted once, on the chord y' = 0:
    /// R = sqrt(1 - y'^2) differs from 1 by ~s^2 / 2 across the lobe).
    pub(crate) alpha_mean: f64,
    pub(crate) alpha_sd: f64,
    /// Its CDF at 0 and its mass over [0, pi].
    pub(crate) cdf_lo: f64,
    pub(crate) mass: f64,
}

impl HorizonLobe {
    /// `sd_x`, `sd_y`: the plane lobe's sds along the tangent axes (the
    /// twin takes its widths along and across the mirror point from them,
    /// ignoring their correlation: it is a proposal, its own pdf is exact).
    /// Used for isotropic surfaces only: on the brushed test material at
    /// 70 degrees it cut the variance gain from 220x to 64x.
    /// `tilt` in [0, 1] scales the (1 + wi.wo)^2 factor of the fit (1 for
    /// smooth surfaces, towards 0 where the Poisson terms m >= 2 dominate).
    fn new(wi: DVec3, sd_x: f64, sd_y: f64, tilt: f64) -> Option<HorizonLobe> {
        let rho0 = (wi.x * wi.x + wi.y * wi.y).sqrt();
        let along = horizon_axis(wi);
        let var = |[a, b]: [f64; 2]| (a * sd_x).powi(2) + (b * sd_y).powi(2);
        let s_along = var(along).sqrt();
        let s = var([-along[1], along[0]]).sqrt();
        if !(s > 0.0 && s.is_finite() && s_along > 0.0 && s_along.is_finite()) {
            return None;
        }
        let (alpha_mean, alpha_sd) = alpha_law(rho0, wi.z, s_along, tilt);
        let cdf_lo = normal_cdf(-alpha_mean / alpha_sd);
        let mass = normal_cdf((PI - alpha_mean) / alpha_sd) - cdf_lo;
        (mass > 0.0 && mass.is_finite()).then_some(HorizonLobe {
            along,
            s,
            alpha_mean,
            alpha_sd,
            cdf_lo,
            mass,
        })
    }

    fn sample(&self, r1: f64, r2: f64) -> Option<DVec3> {
        let y = self.s * inverse_normal(r1);
        if !(y.abs() < 1.0) {
            return None;
        }
        let r = (1.0 - y * y).sqrt();
        let (mu, sd) = (self.alpha_mean, self.alpha_sd);
        let alpha = (mu + sd * inverse_normal(self.cdf_lo + r2 * self.mass)).clamp(0.0, PI);
        let x = r * alpha.cos();
        let z = r * alpha.sin();
        if !(z > MIN_COS) {
            return None;
        }
        let [ax, ay] = self.along;
        normalize_direction(DVec3::new(x * ax - y * ay, x * ay + y * ax, z))
    }

    /// Solid-angle density at wo (unit, above the horizon).
    fn pdf(&self, wo: DVec3) -> f64 {
        let [ax, ay] = self.along;
        let x = wo.x * ax + wo.y * ay;
        let y = -wo.x * ay + wo.y * ax;
        let r = (1.0 - y * y).max(0.0).sqrt();
        if !(r > 0.0) {
            return 0.0;
        }
        let alpha = wo.z.atan2(x);
        let ty = y / self.s;
        let ta = (alpha - self.alpha_mean) / self.alpha_sd;
        let density =
            fast_exp(-0.5 * (ty * ty + ta * ta)) / (2.0 * PI * self.s * self.alpha_sd * self.mass);
        if density.is_finite() {
            density
        } else {
            0.0
        }
    }
}

/// Unit vector in the plane from the origin towards the mirror point
/// -wi_xy (the x axis at normal incidence).
fn horizon_axis(wi: DVec3) -> [f64; 2] {
    let rho0 = (wi.x * wi.x + wi.y * wi.y).sqrt();
    if rho0 > 1e-12 {
        [-wi.x / rho0, -wi.y / rho0]
    } else {
        [1.0, 0.0]
    }
}

/// Mean and sd of the truncated normal in alpha for the chord at R: a
/// Laplace fit to ln[(1 + wi.wo)^2 exp(-(R cos alpha - |c0|)^2 / (2 s^2))].
/// The factor (1 + wi.wo)^2 is what remains of f cos_o per unit solid
/// angle once G's 1/cos_o and the 1/w^2 of the kernel cancel against
/// g ~ w^2 (smooth surfaces); at grazing incidence it varies a
/// hundredfold across the lobe and pushes it away from the horizon.
fn alpha_law(rho0: f64, cos_i: f64, s: f64, tilt: f64) -> (f64, f64) {
    let (r, s2) = (1.0, s * s);
    let mut alpha = if r > rho0 {
        (rho0 / r).clamp(-1.0, 1.0).acos()
    } else {
        0.0
    };
    let mut curvature = -1.0;
    for _ in 0..4 {
        let (sin_a, cos_a) = alpha.sin_cos();
        let q = r * cos_a - rho0;
        let h = (1.0 - r * (rho0 * cos_a - cos_i * sin_a)).max(1e-300);
        let dh = r * (rho0 * sin_a + cos_i * cos_a);
        let d1 = 2.0 * tilt * dh / h + q * r * sin_a / s2;
        curvature = 2.0 * tilt * ((1.0 - h) / h - (dh / h) * (dh / h))
            - (r * r * sin_a * sin_a - q * r * cos_a) / s2;
        if !(curvature < 0.0) {
            break;
        }
        let next = (alpha - d1 / curvature).clamp(0.0, PI);
        let done = (next - alpha).abs() < 1e-9;
        alpha = next;
        if done {
            break;
        }
    }
    let laplace = if curvature < 0.0 {
        (-1.0 / curvature).sqrt()
    } else {
        PI
    };
    // The quartic regime at the rim bounds the width.
    let quartic = (2.0 * s / r).sqrt();
    (alpha, laplace.min(quartic).clamp(1e-9, PI))
}

impl Gaussian {
    /// The one-wavelength strategy at unit wi above the horizon: from the
    /// strategy table for in-band wavelengths, a cosine-only component
    /// for any other.
    pub(super) fn component(
        &self,
        shading: &Shading,
        wi: DVec3,
        lambda_nm: f64,
    ) -> Component<Lobe> {
        if !(lambda_nm.is_finite() && crate::spectrum::in_band(lambda_nm)) {
            return Component::cosine_only();
        }
        let table = self.strategies.get_or_init(Default::default);
        let mut c = table
            .get(wi.z, lambda_nm, |cos, lambda| {
                let centre = DVec3::new((1.0 - cos * cos).sqrt(), 0.0, cos);
                self.build_component(shading, centre, lambda, true)
            })
            .clone();
        // The table's cell is built at azimuth 0; an isotropic lobe's
        // (the horizon twin's) azimuth is wi's.
        if let Some(Lobe::Horizon(h)) = &mut c.lobe {
            h.along = horizon_axis(wi);
        }
        c
    }

    /// The strategy at wi and an in-band lambda_nm, built (what the table
    /// holds); `use_albedo_table` false for the albedo table's own estimates.
    fn build_component(
        &self,
        shading: &Shading,
        wi: DVec3,
        lambda_nm: f64,
        use_albedo_table: bool,
    ) -> Component<Lobe> {
        let s = &self.surface;
        let k = wavenumber_per_um(lambda_nm);
        let g0 = s.roughness_exponent(k, 2.0 * wi.z);
        let (mut p_coh, mut rest) = if g0 <= COHERENT_MAX_G {
            ((-g0).exp(), -(-g0).exp_m1())
        } else {
            (0.0, 1.0)
        };
        // The coherent lobe's share of the albedo is e^-g0 / (e^-g0 +
        // D), D the diffuse albedo over F^2. D = 1 - e^-g0 only when
        // the whole diffuse lobe is above the horizon and G / w^2 ~ 1
        // across it; towards grazing incidence neither holds (D is
        // 2-3x that at cos 0.08 for smooth surfaces), and a
        // coherent probability that ignores it costs variance in both
        // branches. Isotropic surfaces tabulate D / (1 - e^-g0).
        if use_albedo_table && s.isotropic && p_coh > 0.0 && g0 < BECKMANN_MIN_G {
            let table = self
                .albedo
                .get_or_init(|| AlbedoTable::build(self, shading));
            if let Some(diffuse) = table.albedo(wi.z, lambda_nm) {
                p_coh /= p_coh + diffuse;
                rest = 1.0 - p_coh;
            }
        }
        let lobe = if g0 >= BECKMANN_MIN_G {
            Some(Lobe::Beckmann {
                ax: 2.0 * s.sigma_um / s.corr_x_um,
                ay: 2.0 * s.sigma_um / s.corr_y_um,
            })
        } else {
            SeriesLobe::new(g0, k, s.corr_x_um, s.corr_y_um).map(|series| {
                // Plane sds of the mean term E[m | m >= 1].
                let mean_term = g0 / -(-g0).exp_m1();
                let sd_x = (2.0 * mean_term).sqrt() / (k * s.corr_x_um);
                let sd_y = (2.0 * mean_term).sqrt() / (k * s.corr_y_um);
                let to_rim = 1.0 - (1.0 - wi.z * wi.z).max(0.0).sqrt();
                // The (1 + wi.wo)^2 tilt belongs to the m = 1 term.
                let tilt = (-g0).exp();
                // Isotropic surfaces only; the twin is built (a
                // small fit) only when the lobe reaches the rim.
                let near_rim = s.isotropic && to_rim < HORIZON_REACH_SD * sd_x;
                match near_rim.then(|| HorizonLobe::new(wi, sd_x, sd_y, tilt)) {
                    Some(Some(horizon)) => Lobe::Horizon(horizon),
                    _ => Lobe::Series(series),
                }
            })
        };
        let mut c = Component::new(p_coh, rest, lobe);
        if matches!(c.lobe, Some(Lobe::Horizon(_))) {
            // g grows as w^2 away from the grazing mirror direction:
            // for a surface that is rough at w ~ 1 the real lobe is
            // much wider than the one frozen there, and a larger
            // cosine share covers the difference.
            let g_far = s.roughness_exponent(k, 1.0);
            let fraction = DEFENSIVE_FRACTION
                + (NEAR_HORIZON_DEFENSIVE_FRACTION - DEFENSIVE_FRACTION) * -(-g_far).exp_m1();
            let p_def = fraction * rest;
            c.p_lobe += c.p_def - p_def;
            c.p_def = p_def;
        }
        c
    }
}

/// Diffuse directional albedo D of an isotropic Gaussian surface over
/// F^2(cos_i), tabulated as ln D on a grid uniform in ln cos_i (towards
/// grazing D falls like a power of cos_i for smooth surfaces: ln-ln
/// interpolation follows it) and in wavelength; bilinear. Each entry is an
/// importance-sampling estimate with the strategy whose coherent
/// share is the plain e^-g0 (so the table does not depend on itself): a few
/// percent of noise, which only moves the coherent probability, never the
/// exactness of the pdf.
pub(super) struct AlbedoTable {
    ln_albedo: Vec<f64>,
}

const ALBEDO_COS_NODES: usize = 17;
/// Smallest tabulated incidence cosine (clamped below).
const ALBEDO_MIN_COS: f64 = 1e-3;
const ALBEDO_LAMBDA_NODES: usize = 9;
const ALBEDO_SAMPLES: usize = 512;

impl AlbedoTable {
    fn lambda_node(j: usize) -> f64 {
        let (lo, hi) = RGB_BAND_NM;
        lo + (hi - lo) * j as f64 / (ALBEDO_LAMBDA_NODES - 1) as f64
    }

    fn cos_node(i: usize) -> f64 {
        let t = i as f64 / (ALBEDO_COS_NODES - 1) as f64;
        (ALBEDO_MIN_COS.ln() * (1.0 - t)).exp()
    }

    pub(super) fn build(model: &Gaussian, shading: &Shading) -> AlbedoTable {
        let mut ln_albedo = Vec::with_capacity(ALBEDO_COS_NODES * ALBEDO_LAMBDA_NODES);
        for i in 0..ALBEDO_COS_NODES {
            let cos_i = AlbedoTable::cos_node(i);
            let wi = DVec3::new((1.0 - cos_i * cos_i).sqrt(), 0.0, cos_i);
            for j in 0..ALBEDO_LAMBDA_NODES {
                let lambda = AlbedoTable::lambda_node(j);
                let c = model.build_component(shading, wi, lambda, false);
                let rest = c.p_def + c.p_lobe;
                if !(rest > 0.0) {
                    ln_albedo.push(f64::NEG_INFINITY);
                    continue;
                }
                // The diffuse part alone, renormalised.
                let sampler = Mixture::new(
                    model,
                    wi,
                    Components::Local(smallvec![Component {
                        p_coh: 0.0,
                        p_def: c.p_def / rest,
                        p_lobe: c.p_lobe / rest,
                        lobe: c.lobe,
                    }]),
                );
                let mut sum = 0.0;
                let mut rng = SplitMix64((i * 64 + j) as u64);
                let shift = (rng.next_f64(), rng.next_f64());
                for s in 0..ALBEDO_SAMPLES {
                    // The component choice stratified; the direction's own
                    // numbers a Halton (2, 3) point of a permuted index, so
                    // that they are not correlated with it (strata shared
                    // with r0 would bias each component towards part of its
                    // domain), Cranley-Patterson rotated per entry.
                    let r0 = (s as f64 + rng.next_f64()) / ALBEDO_SAMPLES as f64;
                    let index = (s * 97 + 13) % ALBEDO_SAMPLES;
                    let r1 = (radical_inverse(index, 2) + shift.0).fract();
                    let r2 = (radical_inverse(index, 3) + shift.1).fract();
                    let sample = sampler.sample([r0, r1, r2]);
                    if sample.pdf > 0.0 {
                        let f = PairGeometry::new(wi, sample.wo).map_or(0.0, |geom| {
                            let fresnel = shading.fresnel.at_cos(geom.cos_half);
                            f_spectral(&geom, lambda, &fresnel, |k| model.surface.kernel(k, &geom))
                        });
                        sum += f * sample.wo.z / sample.pdf;
                    }
                }
                let albedo =
                    sum / ALBEDO_SAMPLES as f64 / shading.fresnel.reflectance(cos_i, lambda);
                ln_albedo.push(if albedo > 0.0 && albedo.is_finite() {
                    albedo.ln()
                } else {
                    f64::NEG_INFINITY
                });
            }
        }
        AlbedoTable { ln_albedo }
    }

    /// D / F^2 at incidence cosine cos_i and wavelength lambda_nm; None when
    /// not tabulated.
    pub(super) fn albedo(&self, cos_i: f64, lambda_nm: f64) -> Option<f64> {
        if self.ln_albedo.len() != ALBEDO_COS_NODES * ALBEDO_LAMBDA_NODES {
            return None;
        }
        let t = (1.0 - cos_i.clamp(ALBEDO_MIN_COS, 1.0).ln() / ALBEDO_MIN_COS.ln())
            * (ALBEDO_COS_NODES - 1) as f64;
        let i = (t as usize).min(ALBEDO_COS_NODES - 2);
        let fi = t - i as f64;
        let (lo, hi) = RGB_BAND_NM;
        let x = ((lambda_nm - lo) / (hi - lo)).clamp(0.0, 1.0) * (ALBEDO_LAMBDA_NODES - 1) as f64;
        let j = (x as usize).min(ALBEDO_LAMBDA_NODES - 2);
        let fj = x - j as f64;
        let at = |i: usize, j: usize| self.ln_albedo[i * ALBEDO_LAMBDA_NODES + j];
        let ln = (1.0 - fi) * ((1.0 - fj) * at(i, j) + fj * at(i, j + 1))
            + fi * ((1.0 - fj) * at(i + 1, j) + fj * at(i + 1, j + 1));
        let d = ln.exp();
        (d > 0.0 && d.is_finite()).then_some(d)
    }

    pub fn memory_bytes(&self) -> usize {
        self.ln_albedo.len() * 8
    }

    /// `albedo` as program operations (crate::program): D / F^2 at cos_i
    /// and lambda_nm by the same bilinear rule in (ln cos_i, lambda) on the
    /// same values. Where `albedo` gives None this gives 0 or NaN, which the
    /// caller tests (`d > 0 & finite`).
    pub(super) fn program<'a>(
        &self,
        b: &'a Builder,
        cos_i: Value<'a>,
        lambda_nm: Value<'a>,
    ) -> Value<'a> {
        if self.ln_albedo.len() != ALBEDO_COS_NODES * ALBEDO_LAMBDA_NODES {
            return b.c(0.0);
        }
        let table = b.table(self.ln_albedo.iter().map(|&v| v as f32).collect());
        let t = (1.0 - cos_i.clamp(ALBEDO_MIN_COS, 1.0).ln() * (1.0 / ALBEDO_MIN_COS.ln()))
            * (ALBEDO_COS_NODES - 1) as f64;
        let i = t.floor().min((ALBEDO_COS_NODES - 2) as f64);
        let fi = t - i;
        let (lo, hi) = RGB_BAND_NM;
        let x = ((lambda_nm - lo) * (1.0 / (hi - lo))).clamp(0.0, 1.0)
            * (ALBEDO_LAMBDA_NODES - 1) as f64;
        let j = x.floor().min((ALBEDO_LAMBDA_NODES - 2) as f64);
        let fj = x - j;
        let base = i * ALBEDO_LAMBDA_NODES as f64 + j;
        let at =
            |di: usize, dj: usize| b.gather(table, base + (di * ALBEDO_LAMBDA_NODES + dj) as f64);
        let row = |di: usize| (1.0 - fj) * at(di, 0) + fj * at(di, 1);
        let ln = (1.0 - fi) * row(0) + fi * row(1);
        ln.exp()
    }
}

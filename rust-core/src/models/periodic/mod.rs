//! Periodic surfaces: gratings and the compact disc. See docs/physics.md,
//! "Periodic surfaces" and "Colour".
//!
//! The height h(x) is periodic along the tangent x with period `Lam`; its
//! Fourier coefficients `c_n(beta) = (1/Lam) int_0^Lam exp(i beta h) exp(-i 2 pi n x / Lam) dx`
//! with `beta = k w` give, for a Gaussian coherence window of length `l`,
//!
//! ```text
//! <|P(q)|^2>/A = sum_n |c_n|^2 4 pi l^2 exp(-l^2 [(q_x - 2 pi n / Lam)^2 + q_y^2]),  q = k (u, v)
//! K = k^2 / (4 pi^2 w^2) <|P(k u, k v)|^2> / A = k^2 l^2 / (pi w^2) sum_n |c_n|^2 exp(...)
//! ```
//!
//! `K` is the "kernel": the BRDF without Fresnel and without the geometric
//! factor, f = F^2 G K. There is no coherent delta lobe: order 0 is a Gaussian
//! lobe like the others.
//!
//! Profiles and how |c_n(beta)|^2 is obtained:
//! - `Rect`: closed form, evaluated per call (one `sin` per call; sinc^2(n d/Lam)
//!   is tabulated per material for the orders visible in the band).
//! - `Sine`: |c_n|^2 = J_n(beta b / 2)^2. J_n comes from a Miller backward
//!   recurrence (normalised by J_0 + 2 sum J_2k = 1); per material a table of
//!   J_n over beta in [-2 k_max, 0] is interpolated with quintic Hermite
//!   polynomials, the derivatives coming from the Bessel recurrences.
//! - `Tabulated`: the N heights are SAMPLES of one period at x_j = j Lam / N
//!   and c_n is their DFT, c_n = (1/N) sum_j exp(i beta h_j) exp(-2 pi i n j / N)
//!   for -N/2 <= n <= N/2 (for even N the Nyquist coefficient is split equally
//!   between +N/2 and -N/2, so that Parseval's sum is exactly 1); orders beyond
//!   N/2 are 0. This is the "FFT of exp(i k w h) over one period" of the
//!   physics notes; a step sampled this way keeps its edges at sample
//!   positions (see the tests for the resulting discretisation error). Per
//!   material, c_n, dc_n/dbeta and d^2c_n/dbeta^2 (three FFTs per beta sample)
//!   are tabulated over beta in [-2 k_max, 0] and interpolated with quintic
//!   Hermite polynomials.
//!
//! Table accuracy: after removing the mean height, |d^m c_n / d beta^m| <= R^m
//! with R the half range of the heights, and quintic Hermite interpolation
//! errs by at most (h R)^6 / 46080 for a beta step h. The step is chosen as
//! h = 0.2 / R (at least 32 samples), so the interpolated c_n errs by less
//! than 1.4e-9 (absolute; typically 10x less). Orders kept: |n| <=
//! 2 Lam / 0.36 um plus the Gaussian-tail margin, and only those whose
//! |c_n|^2 exceeds `ORDER_POWER_TOL` = 1e-12 somewhere on the beta grid. The
//! table may take at most `MAX_TABLE_BYTES` (3 MiB); beyond that `new`
//! refuses. Outside the tabulated beta range (k > 2 pi / 0.36 um) or for
//! orders outside the table, `order_power` computes c_n directly (slow but
//! exact); `kernel` treats the filtered orders as 0.

// `!(x < y)` is deliberate throughout: it is true for NaN, which must fail
// the same way as an out-of-range value.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod hermite;
mod orders;
#[cfg(test)]
mod param_tests;
pub mod params;
mod program;
mod program_rgb;
mod program_sampling;
#[cfg(test)]
mod program_tests;
mod rgb;
pub mod rigorous;
mod rigorous_grid;
#[cfg(test)]
mod rigorous_polarisation_tests;
#[cfg(test)]
mod rigorous_tests;
mod sampling;
mod smoothed_weight;
#[cfg(test)]
mod tests;

pub use crate::optics::profile::Profile;
pub use params::{OrderPowers, PeriodicParams};
pub(crate) use rgb::OrderWeights;
pub use sampling::Lobe;

use crate::error::StamError;
use crate::models::{
    Shading, SurfaceModel, FLAG_ANISOTROPIC, FLAG_HAS_COHERENT, FLAG_SPECTRALLY_VARYING,
};
use crate::optics::fresnel::{Fresnel, NodeReflectance};
use crate::optics::geometry::PairGeometry;
use crate::sampling::{Component, Components};
use crate::special::{fast_exp, sin_squared};
use hermite::quintic_hermite_basis;
use num_complex::Complex64;
use orders::{bessel_j_row, dft_coefficient, sine_table, tabulated_table};
use std::f64::consts::PI;
use std::sync::OnceLock;

/// The periodic model of a material: the surface and its tables.
pub struct Periodic {
    surface: PeriodicSurface,
    /// With a metal's Fresnel: its reflectance at the wavelengths of the
    /// RGB rule for broad peaks (9 kB).
    broad_reflectance: Option<NodeReflectance>,
    /// The sampling strategy's order weights over the incident direction,
    /// made on the first sample.
    grating: OnceLock<Option<sampling::GratingTable>>,
    /// The RGB sampling programs' order weights and tilts over the
    /// incident direction (program_sampling.rs), made on the first build,
    /// with its n_max.
    rgb_orders: OnceLock<(usize, Vec<f32>)>,
    /// The spectral sampling programs' order weights over the incident
    /// direction and the wavelength, with its n_max (None: none made).
    spectral_orders: OnceLock<Option<(usize, Vec<f32>)>>,
    /// `"orders": "rigorous"`: the orders' powers from Maxwell's equations
    /// (rigorous.rs); None: Stam's formula.
    rigorous: Option<rigorous::RigorousOrders>,
}

impl Periodic {
    pub fn new(p: &PeriodicParams, fresnel: &Fresnel) -> Result<Periodic, StamError> {
        let mut surface = PeriodicSurface::new(p.period_um, p.coherence_um, p.profile.clone())
            .map_err(StamError::new)?;
        if let Some(max) = p.height_um_max {
            surface = surface.with_height_texture(max).map_err(StamError::new)?;
        }
        let rigorous = match p.orders {
            OrderPowers::Kirchhoff => None,
            OrderPowers::Rigorous {
                fourier_orders,
                cover_eta,
            } => Some(rigorous::RigorousOrders::new(
                p.period_um,
                &p.profile,
                fresnel,
                fourier_orders,
                cover_eta,
            )?),
        };
        Ok(Periodic {
            surface,
            broad_reflectance: NodeReflectance::new(
                fresnel,
                PeriodicSurface::broad_rule_wavelengths(),
            ),
            grating: OnceLock::new(),
            rgb_orders: OnceLock::new(),
            spectral_orders: OnceLock::new(),
            rigorous,
        })
    }

    /// The rigorous orders of `"orders": "rigorous"` (None: Stam's formula).
    pub fn rigorous(&self) -> Option<&rigorous::RigorousOrders> {
        self.rigorous.as_ref()
    }

    /// A rigorous grating's Mueller matrix for light arriving from `from`
    /// and leaving along `to` at `lambda_nm`, over its [0][0]: the orders'
    /// matrices (`RigorousOrders::order_mueller`) weighted as f weights
    /// them (each order's Gaussian), with the Stokes basis vectors of the
    /// two directions of travel (-from, to) it is given in. None for
    /// Stam's formula or a grating with a cover; an ideal depolarizer
    /// where no order reaches the pair (f is 0 there).
    pub fn rigorous_mueller(
        &self,
        from: glam::DVec3,
        to: glam::DVec3,
        lambda_nm: f64,
    ) -> Option<(crate::rigorous::polarisation::Mueller, [glam::DVec3; 2])> {
        use crate::rigorous::polarisation::groove_basis;
        use glam::DVec3;
        let r = self.rigorous.as_ref().filter(|r| r.polarizes())?;
        let basis = |d: DVec3| DVec3::from_array(groove_basis(d.normalize_or_zero().to_array()));
        let bases = [basis(-from), basis(to)];
        let mut sum = [0.0f64; 16];
        let mut missing = false;
        if let Some(geom) = PairGeometry::new(from, to) {
            let k = spectrum::wavenumber_per_um(lambda_nm);
            self.surface.for_each_order(k, &geom, |n, g| {
                match r.order_mueller(n, lambda_nm, geom.wi, geom.wo) {
                    Some(m) => sum.iter_mut().zip(m).for_each(|(s, v)| *s += g * v),
                    None => missing = true,
                }
            });
        }
        if missing {
            return None;
        }
        let mut out = [0.0; 16];
        if sum[0] > 0.0 && sum.iter().all(|v| v.is_finite()) {
            for (o, v) in out.iter_mut().zip(sum) {
                *o = v / sum[0];
            }
            out = crate::rigorous::polarisation::realisable(&out);
        } else {
            out[0] = 1.0;
        }
        Some((out, bases))
    }

    /// What a rigorous grating's cover reflects as a mirror at an incidence
    /// cosine: the coherent lobe's value and its sampling probability (0
    /// without a cover or for Stam's orders).
    pub(super) fn cover_reflectance(&self, cos_i: f64) -> f64 {
        self.rigorous
            .as_ref()
            .map_or(0.0, |r| r.cover_reflectance(cos_i))
    }

    pub fn surface(&self) -> &PeriodicSurface {
        &self.surface
    }

    /// RGB of F^2 K with the Fresnel term at the pair's cosine, its
    /// broad-rule nodes from the node table where the material has one.
    pub(crate) fn reflectance_rgb_with(
        &self,
        shading: &Shading,
        geom: &PairGeometry,
        node_table: bool,
    ) -> [f64; 3] {
        let fresnel = shading.fresnel.at_cos(geom.cos_half);
        let nodes = PeriodicSurface::broad_rule_wavelengths();
        let table = self.broad_reflectance.as_ref().filter(|_| node_table);
        match shading.pair_factor {
            None => {
                let reflectance = |lambda_nm: f64| fresnel.reflectance(lambda_nm);
                let at_node = |j: usize| fresnel.at_node(table, j, nodes[j]);
                self.surface.kernel_rgb_with(geom, &reflectance, &at_node)
            }
            // The pair's factor (smooth in wavelength) joins the Fresnel
            // term inside each order's integration.
            Some(factor) => {
                let reflectance =
                    |lambda_nm: f64| fresnel.reflectance(lambda_nm) * factor(lambda_nm);
                let at_node = |j: usize| fresnel.at_node(table, j, nodes[j]) * factor(nodes[j]);
                self.surface.kernel_rgb_with(geom, &reflectance, &at_node)
            }
        }
    }
}

impl SurfaceModel for Periodic {
    type Params = PeriodicParams;
    type Lobe = Lobe;

    fn from_params(p: &PeriodicParams, fresnel: &Fresnel) -> Result<Periodic, StamError> {
        Periodic::new(p, fresnel)
    }

    fn flags(&self) -> u32 {
        // A rigorous grating's cover is a mirror: the coherent lobe.
        let cover = self.rigorous.as_ref().is_some_and(|r| r.has_cover());
        FLAG_ANISOTROPIC | FLAG_SPECTRALLY_VARYING | if cover { FLAG_HAS_COHERENT } else { 0 }
    }

    fn memory_bytes(&self) -> usize {
        self.surface.memory_bytes()
            + self
                .broad_reflectance
                .as_ref()
                .map_or(0, |t| t.memory_bytes())
            + self
                .grating
                .get()
                .and_then(|t| t.as_ref())
                .map_or(0, |t| t.memory_bytes())
            + self.rigorous.as_ref().map_or(0, |r| r.memory_bytes())
    }

    #[inline]
    fn kernel(&self, k_per_um: f64, geom: &PairGeometry) -> f64 {
        self.surface.kernel(k_per_um, geom)
    }

    fn reflectance_rgb(&self, shading: &Shading, geom: &PairGeometry) -> [f64; 3] {
        self.reflectance_rgb_with(shading, geom, true)
    }

    fn is_unfactored(&self) -> bool {
        self.rigorous.is_some()
    }

    fn unfactored_spectral(&self, geom: &PairGeometry, lambda_nm: f64) -> Option<f64> {
        let r = self.rigorous.as_ref()?;
        let eta = |n: i64| r.power(n, lambda_nm, geom.wi, geom.wo);
        Some(
            self.surface
                .kernel_given(spectrum::wavenumber_per_um(lambda_nm), geom, &eta),
        )
    }

    fn has_unfactored_mueller(&self) -> bool {
        self.rigorous.as_ref().is_some_and(|r| r.polarizes())
    }

    fn unfactored_mueller(
        &self,
        from: glam::DVec3,
        to: glam::DVec3,
        lambda_nm: f64,
    ) -> Option<([f64; 16], [glam::DVec3; 2])> {
        self.rigorous_mueller(from, to, lambda_nm)
    }

    fn unfactored_rgb(&self, geom: &PairGeometry) -> Option<[f64; 3]> {
        let r = self.rigorous.as_ref()?;
        let power = |n: i64, lambda_nm: f64| r.power(n, lambda_nm, geom.wi, geom.wo);
        let lambdas = PeriodicSurface::given_broad_wavelengths();
        // Order 0's spectrum at the broad rule's nodes in one read.
        let order_zero = std::cell::OnceCell::new();
        let at_node = |n: i64, j: usize| {
            if n == 0 {
                order_zero.get_or_init(|| r.order_zero_at_nodes(geom.wi, geom.wo))[j]
            } else {
                power(n, lambdas[j])
            }
        };
        Some(self.surface.kernel_rgb_general(
            geom,
            OrderWeights::Given {
                power: &power,
                at_node: &at_node,
            },
        ))
    }

    /// Orders appear and disappear at the horizon as the wavelength
    /// changes, and the albedo with them: a factor per wavelength, and a
    /// wider horizon taper (an order just above the horizon, a Rayleigh
    /// anomaly, spikes the albedo over a few nm).
    fn energy_hint(&self) -> crate::models::EnergyHint {
        crate::models::EnergyHint {
            wavelength_nodes: 25,
            per_wavelength: true,
            horizon_taper_cos: 0.25,
            // A grating's excess is real (its orders' albedo), not noise,
            // and its 25 nodes make samples expensive.
            samples_per_cell: 512,
            // A grating's albedo changes faster than the table's cells
            // and nodes (the compact disc at cos_i 0.4 reached 1.026 with
            // 0.995): a wider margin.
            target_albedo: GRATING_TARGET_ALBEDO,
        }
    }

    /// A rigorous grating's cover reflects like a mirror (0 without one).
    fn coherent_spectral(&self, _shading: &Shading, cos_i: f64, _lambda_nm: f64) -> f64 {
        self.cover_reflectance(cos_i)
    }

    /// The cover's reflectance is flat in wavelength: the same in R, G, B.
    fn coherent_rgb(&self, _shading: &Shading, cos_i: f64) -> [f64; 3] {
        [self.cover_reflectance(cos_i); 3]
    }

    fn spectral_component(
        &self,
        shading: &Shading,
        wi: glam::DVec3,
        lambda_nm: f64,
    ) -> Component<Lobe> {
        self.component(shading, wi, lambda_nm)
    }

    fn rgb_components<'a>(&'a self, shading: &Shading, wi: glam::DVec3) -> Components<'a, Lobe> {
        self.rgb_strategy(shading, wi)
    }
}

/// The spectrum module the RGB path integrates against.
use crate::spectrum;

/// Shortest wavelength the tables cover (the visible band's lower end), um.
const LAMBDA_MIN_UM: f64 = spectrum::LAMBDA_MIN_NM / 1000.0;
/// Largest wavenumber covered by the tables, 1/um (2 pi / 0.36 um).
const K_MAX: f64 = 2.0 * PI / LAMBDA_MIN_UM;
/// The tables cover beta = k w in [-BETA_MAX, 0] (w >= -2).
const BETA_MAX: f64 = 2.0 * K_MAX;
/// Orders whose |c_n|^2 never exceeds this on the beta grid are dropped.
pub const ORDER_POWER_TOL: f64 = 1e-12;
/// The energy table's target albedo for gratings (EnergyHint): 0.97
/// instead of the random surfaces' 0.995, because a grating's albedo
/// changes faster with the direction and the wavelength than the table
/// resolves (docs/energy.md).
const GRATING_TARGET_ALBEDO: f64 = 0.97;
/// Memory cap of the per-material |c_n|^2 table.
pub const MAX_TABLE_BYTES: usize = 3 << 20;
/// Target beta step times the height half range (see the module doc).
const HERMITE_STEP_TIMES_RANGE: f64 = 0.2;
/// Below exp(-745) an f64 exponential is 0.
const EXP_UNDERFLOW: f64 = 745.0;
/// Spectral kernel: orders whose Gaussian exponent exceeds the nearest
/// order's by more than this (factor e^-100 = 4e-44) are not evaluated.
pub const KERNEL_TAIL_EXPONENT: f64 = 100.0;
/// RGB: orders (and broad-peak parts) whose exponent over the whole band is
/// above this (factor e^-40 = 4e-18) are skipped.
const RGB_TAIL_EXPONENT: f64 = 40.0;
/// RGB: half width, in standard deviations, of the part of a peak that the
/// quadratic fit of the slowly varying factor has to represent.
const RGB_PEAK_HALF_WIDTH_SIGMAS: f64 = 4.0;
/// RGB: a peak whose standard deviation in wavenumber exceeds this (1/um) is
/// integrated with the smooth rule instead of the quadratic fit.
const RGB_BROAD_SIGMA: f64 = 0.1;
/// RGB: node count of the smooth rule used for broad peaks.
const RGB_SMOOTH_NODES: usize = 32;

/// A periodic microsurface: profile, period and coherence length.
#[derive(Clone, Debug)]
pub struct PeriodicSurface {
    period_um: f64,
    coherence_um: f64,
    profile: Profile,
    model: Model,
    /// A sine profile with a height texture (`height_um_max`): the order
    /// table at that largest height, which the programs read at beta
    /// scaled by h / h_max for every height up to it (the native path
    /// keeps `model`, built at the material's height).
    texture_table: Option<(f64, OrderTable)>,
}

#[derive(Clone, Debug)]
enum Model {
    Rect {
        height_um: f64,
        /// d / Lam.
        fill: f64,
        /// sinc^2(n d / Lam) for n = 0..len.
        sinc2: Vec<f64>,
    },
    Table(OrderTable),
}

/// Quintic-Hermite table of c_n(beta) (up to a beta-dependent phase) on a
/// uniform grid beta_j = -BETA_MAX + j step, j = 0..n_beta.
#[derive(Clone, Debug)]
struct OrderTable {
    step: f64,
    n_beta: usize,
    /// Stored orders n_lo..=n_hi (for a symmetric table, |n| is looked up).
    n_lo: i64,
    n_hi: i64,
    symmetric: bool,
    /// [value, d/dbeta, d^2/dbeta^2] per (beta sample, order), beta-major.
    data: Vec<[Complex64; 3]>,
}

impl OrderTable {
    fn orders(&self) -> usize {
        (self.n_hi - self.n_lo + 1) as usize
    }

    /// Interpolated |c_n(beta)|^2, or None outside the table.
    #[inline]
    fn power(&self, n: i64, beta: f64) -> Option<f64> {
        let n = if self.symmetric { n.abs() } else { n };
        if n < self.n_lo || n > self.n_hi {
            return None;
        }
        let pos = (beta + BETA_MAX) / self.step;
        if !(pos >= 0.0) || pos > (self.n_beta - 1) as f64 {
            return None;
        }
        let j = (pos as usize).min(self.n_beta - 2);
        let t = pos - j as f64;
        let stride = self.orders();
        let col = (n - self.n_lo) as usize;
        let a = &self.data[j * stride + col];
        let b = &self.data[(j + 1) * stride + col];
        let h = self.step;
        let [h0, h1, h2, h3, h4, h5] = quintic_hermite_basis(t, 1.0 - t);
        let (h1, h4) = (h1 * h, h4 * h);
        let (h2, h5) = (0.5 * h2 * h * h, 0.5 * h5 * h * h);
        let c = a[0] * h0 + a[1] * h1 + a[2] * h2 + b[0] * h3 + b[1] * h4 + b[2] * h5;
        Some(c.norm_sqr())
    }

    fn bytes(&self) -> usize {
        self.data.len() * std::mem::size_of::<[Complex64; 3]>()
    }
}

/// Number of beta samples for a profile of height half range `half_range`.
fn beta_samples(half_range: f64) -> usize {
    let by_range = (BETA_MAX * half_range / HERMITE_STEP_TIMES_RANGE).ceil();
    (by_range as usize).max(31) + 1
}

/// The interval (lo, hi] of a geometric grid of ratio 2^(1/3) (..., 1,
/// 1.26, 1.587, 2, ...) that holds x > 0: what order counts and table rows
/// are planned for (the top for a period, the bottom for a coherence
/// length: more orders reach the band as either moves so). The values of
/// one interval give tables of the same rows and, where a renderer
/// differentiates the parameter, programs of the same shape, so that an
/// optimiser moving it reuses the kernels Dr.Jit compiled for the last
/// rebuild (each shape's forward and adjoint kernels take minutes to compile
/// on a small CPU). The orders planned beyond a material's own are never
/// taken. (x itself where the grid's arithmetic fails.)
pub(super) fn planning_interval(x: f64) -> (f64, f64) {
    let hi = ((3.0 * x.log2()).ceil() / 3.0).exp2();
    let lo = hi * (-1.0f64 / 3.0).exp2();
    if hi.is_finite() && lo > 0.0 && lo <= x && x <= hi {
        (lo, hi)
    } else {
        (x, x)
    }
}

/// `build` of a table with rows up to the order limit planned for the
/// period's and the coherence length's `planning_interval` (the period's
/// top, the coherence length's bottom), or, where that table is refused
/// (its size limit), up to their own order limit.
fn with_planned_rows<T>(
    period_um: f64,
    coherence_um: f64,
    build: impl Fn(i64) -> Result<T, String>,
) -> Result<T, String> {
    let planned = physical_order_limit(
        planning_interval(period_um).1,
        planning_interval(coherence_um).0,
    );
    build(planned).or_else(|_| build(physical_order_limit(period_um, coherence_um)))
}

/// Largest |n| whose peak can reach the visible band at some direction
/// (|u| <= 2, lambda >= 0.36 um), plus the Gaussian-tail margin of the
/// spectral kernel for the shortest coherence length.
fn physical_order_limit(period_um: f64, coherence_um: f64) -> i64 {
    let margin = (KERNEL_TAIL_EXPONENT + 25.0).sqrt() * period_um / (2.0 * PI * coherence_um);
    (2.0 * period_um / LAMBDA_MIN_UM + margin).floor() as i64 + 1
}

fn check_positive(name: &str, value: f64) -> Result<(), String> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(format!("{name} must be finite and > 0 (got {value})"))
    }
}

impl PeriodicSurface {
    /// Validates the parameters and builds the per-material tables.
    pub fn new(
        period_um: f64,
        coherence_um: f64,
        profile: Profile,
    ) -> Result<PeriodicSurface, String> {
        check_positive("period_um", period_um)?;
        check_positive("coherence_um", coherence_um)?;
        let model = with_planned_rows(period_um, coherence_um, |n_phys| {
            Self::model(period_um, &profile, n_phys)
        })?;
        Ok(PeriodicSurface {
            period_um,
            coherence_um,
            profile,
            model,
            texture_table: None,
        })
    }

    /// The profile's model with orders up to `n_phys`.
    fn model(period_um: f64, profile: &Profile, n_phys: i64) -> Result<Model, String> {
        Ok(match profile {
            Profile::Rect {
                height_um,
                width_um,
            } => {
                check_positive("height_um", *height_um)?;
                check_positive("width_um", *width_um)?;
                if *width_um > period_um {
                    return Err(format!(
                        "width_um ({width_um}) must not exceed period_um ({period_um})"
                    ));
                }
                let fill = width_um / period_um;
                let sinc2 = (0..=n_phys)
                    .map(|n| sinc(n as f64 * fill).powi(2))
                    .collect();
                Model::Rect {
                    height_um: *height_um,
                    fill,
                    sinc2,
                }
            }
            Profile::Sine { height_um } => {
                check_positive("height_um", *height_um)?;
                if *height_um > 1e3 {
                    return Err(format!(
                        "height_um ({height_um}) is too large for a sine grating (at most 1000 um)"
                    ));
                }
                Model::Table(sine_table(*height_um, n_phys)?)
            }
            Profile::Tabulated { heights_um } => {
                if heights_um.len() < 2 {
                    return Err(format!(
                        "heights_um needs at least 2 samples per period (got {})",
                        heights_um.len()
                    ));
                }
                if let Some(bad) = heights_um.iter().find(|h| !h.is_finite()) {
                    return Err(format!("heights_um must be finite (found {bad})"));
                }
                Model::Table(tabulated_table(heights_um, period_um, n_phys)?)
            }
        })
    }

    /// The surface whose programs serve a sine profile's heights up to
    /// `height_um_max` (a height texture's largest value).
    pub fn with_height_texture(mut self, height_um_max: f64) -> Result<PeriodicSurface, String> {
        let Profile::Sine { height_um } = self.profile else {
            return Err("height_um_max applies to the sine profile only".into());
        };
        check_positive("height_um_max", height_um_max)?;
        if height_um_max < height_um || height_um_max > 1e3 {
            return Err(format!(
                "height_um_max ({height_um_max}) must be at least height_um ({height_um}) and at most 1000 um"
            ));
        }
        let table = with_planned_rows(self.period_um, self.coherence_um, |n_phys| {
            sine_table(height_um_max, n_phys)
        })?;
        self.texture_table = Some((height_um_max, table));
        Ok(self)
    }

    pub fn period_um(&self) -> f64 {
        self.period_um
    }

    pub fn coherence_um(&self) -> f64 {
        self.coherence_um
    }

    pub fn profile(&self) -> &Profile {
        &self.profile
    }

    /// |c_n(beta)|^2 for any integer n and any finite beta (table
    /// interpolation inside the tabulated range, direct evaluation outside).
    pub fn order_power(&self, n: i64, beta: f64) -> f64 {
        if !beta.is_finite() {
            return 0.0;
        }
        match &self.model {
            Model::Rect {
                height_um,
                fill,
                sinc2,
            } => rect_power(n, sin_squared(0.5 * beta * height_um), *fill, sinc2),
            Model::Table(table) => {
                // |c_n(beta)|^2 = |c_-n(-beta)|^2 for real heights.
                let (n_t, b_t) = if beta > 0.0 { (-n, -beta) } else { (n, beta) };
                if let Some(p) = table.power(n_t, b_t) {
                    return p;
                }
                self.direct_power(n, beta)
            }
        }
    }

    /// |c_n(beta)|^2 without tables (slow for tabulated profiles: O(N)).
    fn direct_power(&self, n: i64, beta: f64) -> f64 {
        match &self.profile {
            Profile::Rect { height_um, .. } => {
                rect_power(n, sin_squared(0.5 * beta * height_um), self.fill(), &[])
            }
            Profile::Sine { height_um } => {
                let x = (0.5 * beta * height_um).abs();
                let order = n.unsigned_abs() as usize;
                let j = bessel_j_row(x, order)[order];
                j * j
            }
            Profile::Tabulated { heights_um } => dft_coefficient(heights_um, n, beta).norm_sqr(),
        }
    }

    fn fill(&self) -> f64 {
        match &self.profile {
            Profile::Rect { width_um, .. } => width_um / self.period_um,
            _ => 0.0,
        }
    }

    /// Heap and inline bytes held by this surface.
    pub fn memory_bytes(&self) -> usize {
        let inline = std::mem::size_of::<PeriodicSurface>();
        let profile = match &self.profile {
            Profile::Tabulated { heights_um } => heights_um.capacity() * 8,
            _ => 0,
        };
        let model = match &self.model {
            Model::Rect { sinc2, .. } => sinc2.capacity() * 8,
            Model::Table(t) => t.bytes(),
        };
        inline + profile + model
    }

    /// The orders n whose Gaussian factor exp(-l^2 (k u - 2 pi n / Lam)^2)
    /// is within `KERNEL_TAIL_EXPONENT` of the nearest order's and does not
    /// underflow: the orders the spectral kernel evaluates at (k, u). Empty
    /// (lo > hi) when no order qualifies. Typically one order (l >> Lam), at
    /// most three for l >= 1.5 Lam.
    pub fn orders_near(&self, k_per_um: f64, u: f64) -> (i64, i64) {
        let x = k_per_um * u * self.period_um / (2.0 * PI);
        if !x.is_finite() || x.abs() > 1e15 {
            return (1, 0);
        }
        let scale = 2.0 * PI * self.coherence_um / self.period_um;
        let frac = x - x.round();
        let e_min = (scale * frac).powi(2);
        let reach = (e_min + KERNEL_TAIL_EXPONENT).min(EXP_UNDERFLOW).sqrt() / scale;
        ((x - reach).ceil() as i64, (x + reach).floor() as i64)
    }

    /// The spectral kernel K(k) (BRDF without F^2 and G), 1/sr. Finite and
    /// >= 0 for every input; 0 for k <= 0 or a non-finite geometry.
    pub fn kernel(&self, k_per_um: f64, geom: &PairGeometry) -> f64 {
        let beta = k_per_um * geom.w;
        let s2 = self.rect_s2(beta);
        let sum = self.gaussian_sum(k_per_um, geom, |n| self.power_fast(n, beta, s2));
        let k = (k_per_um * self.coherence_um / geom.w).powi(2) / PI * sum;
        if k.is_finite() && k > 0.0 {
            k
        } else {
            0.0
        }
    }

    /// f of a grating whose order n has the power `power(n)` (rigorous.rs):
    /// each order's Gaussian normalised over the projected hemisphere,
    /// sum_n power(n) (k^2 l^2 / pi) exp(-E_n). Finite and >= 0.
    pub fn kernel_given(
        &self,
        k_per_um: f64,
        geom: &PairGeometry,
        power: &dyn Fn(i64) -> f64,
    ) -> f64 {
        let sum = self.gaussian_sum(k_per_um, geom, power);
        let f = (k_per_um * self.coherence_um).powi(2) / PI * sum;
        if f.is_finite() && f > 0.0 {
            f
        } else {
            0.0
        }
    }

    /// sum over the orders near the pair of power(n) exp(-E_n(k)) (see
    /// `order_sum`); 0 for k <= 0 or a non-finite geometry.
    fn gaussian_sum(&self, k_per_um: f64, geom: &PairGeometry, power: impl Fn(i64) -> f64) -> f64 {
        let mut sum = 0.0;
        self.for_each_order(k_per_um, geom, |n, g| sum += power(n) * g);
        sum
    }

    /// Each order n near the pair with its Gaussian exp(-E_n(k)), the terms
    /// of `gaussian_sum`; none for k <= 0 or a non-finite geometry.
    pub fn for_each_order(&self, k_per_um: f64, geom: &PairGeometry, visit: impl FnMut(i64, f64)) {
        let (u, v, w) = (geom.u, geom.v, geom.w);
        if !(k_per_um > 0.0 && k_per_um.is_finite() && w < 0.0 && u.is_finite() && v.is_finite()) {
            return;
        }
        let e_v = (self.coherence_um * k_per_um * v).powi(2);
        if !(e_v < EXP_UNDERFLOW) {
            return;
        }
        let (lo, hi) = self.orders_near(k_per_um, u);
        if lo <= hi {
            self.order_terms(k_per_um, u, v, lo..=hi, visit);
        }
    }

    /// Table power for the kernels: orders filtered out of the table count
    /// as 0; beta outside the table is evaluated directly.
    #[inline]
    fn table_power(&self, table: &OrderTable, n: i64, beta: f64) -> f64 {
        let (n_t, b_t) = if beta > 0.0 { (-n, -beta) } else { (n, beta) };
        match table.power(n_t, b_t) {
            Some(p) => p,
            None => {
                let pos = (b_t + BETA_MAX) / table.step;
                if pos >= 0.0 {
                    0.0 // inside the beta range: a filtered order
                } else {
                    self.direct_power(n, beta)
                }
            }
        }
    }

    /// |c_n(beta)|^2 as the kernels use it.
    #[inline]
    fn power_fast(&self, n: i64, beta: f64, s2_rect: f64) -> f64 {
        match &self.model {
            Model::Rect { fill, sinc2, .. } => rect_power(n, s2_rect, *fill, sinc2),
            Model::Table(table) => self.table_power(table, n, beta),
        }
    }

    /// `rect_s2` at beta_c - d, beta_c, beta_c + d, by the angle-addition
    /// formulas (two sine-cosine pairs instead of three sines).
    fn rect_s2_three(&self, beta_c: f64, d: f64) -> [f64; 3] {
        match &self.model {
            Model::Rect { height_um, .. } => {
                let (sa, ca) = (0.5 * beta_c * height_um).sin_cos();
                let (sd, cd) = (0.5 * d * height_um).sin_cos();
                let (lo, hi) = (sa * cd - ca * sd, sa * cd + ca * sd);
                [lo * lo, sa * sa, hi * hi]
            }
            Model::Table(_) => [0.0; 3],
        }
    }

    fn rect_s2(&self, beta: f64) -> f64 {
        match &self.model {
            Model::Rect { height_um, .. } => sin_squared(0.5 * beta * height_um),
            Model::Table(_) => 0.0,
        }
    }

    /// Sum over `orders` of power(n) exp(-E_n(k)), E_n = l^2 [(k u - 2 pi
    /// n / Lam)^2 + k^2 v^2], terms that underflow left out: the spectral
    /// kernel's sum (power |c_n(k w)|^2), and the broad-peak rule's per
    /// node where its vectorised loop does not apply.
    fn order_sum(
        &self,
        k: f64,
        u: f64,
        v: f64,
        orders: impl Iterator<Item = i64>,
        power: impl Fn(i64) -> f64,
    ) -> f64 {
        let mut sum = 0.0;
        self.order_terms(k, u, v, orders, |n, g| sum += power(n) * g);
        sum
    }

    /// `order_sum`'s terms: each order with its exp(-E_n(k)) above underflow.
    #[inline]
    fn order_terms(
        &self,
        k: f64,
        u: f64,
        v: f64,
        orders: impl Iterator<Item = i64>,
        mut visit: impl FnMut(i64, f64),
    ) {
        let l = self.coherence_um;
        let g = 2.0 * PI / self.period_um;
        let e_v = (l * k * v).powi(2);
        for n in orders {
            let d = l * (k * u - g * n as f64);
            let e = d * d + e_v;
            if e < EXP_UNDERFLOW {
                visit(n, fast_exp(-e));
            }
        }
    }
}

/// sin(pi x) / (pi x).
fn sinc(x: f64) -> f64 {
    if x == 0.0 {
        1.0
    } else {
        (PI * x).sin() / (PI * x)
    }
}

/// `rect_power(n, s2, ..)` = max(c0 + c1 s2, 0) with (c0, c1) from here.
#[inline]
fn rect_power_coefficients(n: i64, fill: f64, sinc2: &[f64]) -> (f64, f64) {
    if n == 0 {
        return (1.0, -4.0 * fill * (1.0 - fill));
    }
    (0.0, rect_power(n, 1.0, fill, sinc2))
}

/// |c_n|^2 of the rectangular profile given s2 = sin^2(beta b / 2).
#[inline]
fn rect_power(n: i64, s2: f64, fill: f64, sinc2: &[f64]) -> f64 {
    if n == 0 {
        // |1 + (e^{i theta} - 1) f|^2 = 1 - 4 f (1 - f) sin^2(theta / 2)
        return (1.0 - 4.0 * fill * (1.0 - fill) * s2).max(0.0);
    }
    let idx = n.unsigned_abs() as usize;
    let sc2 = match sinc2.get(idx) {
        Some(v) => *v,
        None => sinc(n as f64 * fill).powi(2),
    };
    4.0 * s2 * fill * fill * sc2
}

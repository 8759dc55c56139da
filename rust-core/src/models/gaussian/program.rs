//! The gaussian model's programs for tracing renderers (crate::program,
//! docs/jit.md): the same physics as its native path, as array operations.
//!
//! - Spectral kernel: S(g, x) from the universal table (`series.rs`, the
//!   same B-spline coefficients and the same lookup), below its g range the
//!   first four terms of the series, above it the Poisson expectation
//!   expanded to O(1/g^2); beyond its rho range S is below e^-270 of its
//!   peak and the program gives 0.
//! - RGB: a per-material table over the pair variables (ln g0, rho0) of
//!   `rgb.rs` (g0 = (sigma w)^2, x0 = (Tx^2 u^2 + Ty^2 v^2) / 4: every node
//!   of the rule is a function of these two), sampled from the same series
//!   values as the native node table and extended down to both-grazing
//!   pairs (below its rows ln(S / g0) is constant to ~g e^(x/2)). Where the
//!   Fresnel-weighted rule allows it (a wavelength-flat Fresnel term, or an
//!   isotropic surface, whose half-vector cosine is a function of (g0,
//!   x0)), each grid point holds the rule's sum itself, as ln(N / g0) (N =
//!   sum_j K_j m_j, m_j > 0) and the three channels over N: one lookup of
//!   4 values serves every node (64 gathers). Anisotropic surfaces with a
//!   metal's Fresnel keep ln(k_j^2 S_j / g0) of every node (the native node
//!   table's layout: 16 N gathers) and the Fresnel-weighted rule in its
//!   low-rank form (`weighted_sum`).
//! - Coherent lobe: F^2 e^-g as native, RGB by the rule at the nodes.
//! - Sampling: a defensive mixture (cosine and uniform, as the core's) and
//!   lobes in the half-vector slopes: for g0 (the roughness exponent at the
//!   mirror direction) below `SERIES_MAX_G`, the series' mixture of
//!   Gaussians (term m ~ Poisson(g0 | m >= 1), variances m times a base) as
//!   two Gaussians (m = 1 and the mean of m >= 2: `TermMixture`; two
//!   exponentials per density where a lookup of S was), with a base fitted
//!   to the law (see
//!   `slope_lobes`) and one frozen at the mirror; above it the Beckmann
//!   asymptote (alpha = 2 sigma / T per axis). Slopes are reflected about
//!   their normal, so the lobes live in solid angle and stay finite at the
//!   horizon. Isotropic surfaces near the rim add the core's horizon twin.
//!   The coherent probability follows the model's own albedo table
//!   (isotropic surfaces) as native.

use super::sampling::{AlbedoTable, BECKMANN_MIN_G};
use super::series::{series_table_export, SeriesTableExport};
use super::{Gaussian, GaussianSurface, COHERENT_MAX_G};
use crate::models::{FactorMaker, FactorProgram, SampleProgram, Shading, SurfacePrograms};
use crate::optics::geometry::MIN_COS;
use crate::optics::program::{PairProgram, Vec3};
use crate::program::lookup::bspline_weights;
use crate::program::{Builder, Mask, ParamId, Table, Value};
use crate::sampling::program::{cosine_density_program, cosine_direction_program};
use crate::spectrum::{wavenumber_per_um, LAMBDA_MAX_NM, LAMBDA_MIN_NM, WAVENUMBER_TIMES_NM};
use std::f64::consts::PI;

/// Mirror roughness exponent below which the sampling lobe is the series'
/// mixture (above: Beckmann).
pub const SERIES_MAX_G: f64 = 12.0;
/// The wavelength of the RGB strategy's lobe (nm).
pub const RGB_SAMPLING_NM: f64 = 550.0;
/// Share of the lobe probability of the lobe frozen at the mirror (the
/// rest: the fitted lobe).
const MIRROR_LOBE: f64 = 0.3;
/// Share of the lobe probability of the horizon twin (isotropic surfaces,
/// near the rim) for smooth surfaces (times e^-g_far).
const TWIN_SHARE: f64 = 0.8;
/// The twin's largest share below which the programs leave it out (it
/// then changes the lobes' density by less than this fraction).
const TWIN_NEGLIGIBLE: f64 = 1e-4;
/// Share of the non-coherent probability of the defensive part (half
/// cosine, half uniform), as the core's strategies.
const DEFENSIVE: f64 = crate::sampling::DEFENSIVE_FRACTION;

/// The universal table of ln S as a program table.
struct SeriesLookup {
    table: Table,
    e: SeriesTableExport,
}

impl SeriesLookup {
    fn new(b: &Builder) -> SeriesLookup {
        let e = series_table_export();
        SeriesLookup {
            table: b.table(e.coefficients.to_vec()),
            e,
        }
    }
}

/// The bicubic B-spline sums of `count` interleaved values per grid point:
/// value l is sum_ab wu_a wv_b table[base + a row_len + b stride + l].
#[allow(clippy::too_many_arguments)]
pub(super) fn bicubic<'a>(
    b: &'a Builder,
    table: Table,
    base: Value<'a>,
    row_len: usize,
    stride: usize,
    count: usize,
    wu: [Value<'a>; 4],
    wv: [Value<'a>; 4],
) -> Vec<Value<'a>> {
    (0..count)
        .map(|l| {
            let row = |a: usize| {
                let at = |c: usize| b.gather(table, base + (a * row_len + c * stride + l) as f64);
                let mut acc = at(0) * wv[0];
                for (c, &w) in wv.iter().enumerate().skip(1) {
                    acc = at(c).fma(w, acc);
                }
                acc
            };
            let mut acc = row(0) * wu[0];
            for (a, &w) in wu.iter().enumerate().skip(1) {
                acc = row(a).fma(w, acc);
            }
            acc
        })
        .collect()
}

/// S(g, x) as `poisson_series` gives it: the universal table where it
/// covers (g, rho); the first four terms below its g range (the fifth is
/// below 1e-5 of the first wherever S is above e^-25 of its peak); the
/// Poisson expectation to O(1/g^2) above it (g >= 1e4: the next term is
/// ~y^6 / (48 g^3), 1e-7 at y = x / g = 14); 0 beyond its rho range (S
/// below e^-270 of its peak). `ln_g` is ln g (computed by the caller
/// without forming g where g may underflow).
fn series<'a>(
    b: &'a Builder,
    lk: &SeriesLookup,
    g: Value<'a>,
    ln_g: Value<'a>,
    x: Value<'a>,
) -> Value<'a> {
    let e = &lk.e;
    // The table: the native lookup.
    let rho = (x / (g + 1.0)).sqrt();
    let fg = (ln_g - e.ln_g_min) * (1.0 / e.d_ln_g) + 1.0;
    let fx = rho * (1.0 / e.d_rho) + 1.0;
    let ig = fg.floor().clamp(1.0, (e.n_g - 3) as f64);
    let ix = fx.floor().clamp(1.0, (e.n_rho - 3) as f64);
    let wg = bspline_weights(fg - ig);
    let wx = bspline_weights(fx - ix);
    let base = (ig - 1.0) * e.n_rho as f64 + (ix - 1.0);
    let ln_table = bicubic(b, lk.table, base, e.n_rho, 1, 1, wg, wx)[0];
    let in_table = g.ge(e.g_min) & g.lt(e.g_max) & rho.lt(e.rho_max);
    // Small g: sum_{m=1..4} e^-g g^m / m! e^(-x/m) / m, with e^(-x/m) as
    // powers of q = e^(-x/12), divided by g.
    let q = (x * (-1.0 / 12.0)).exp();
    let q3 = q * q * q;
    let q4 = q3 * q;
    let q6 = q3 * q3;
    let q12 = q6 * q6;
    let terms = q12 + g * (q6 * 0.25 + g * (q4 * (1.0 / 18.0) + g * (q3 * (1.0 / 96.0))));
    let s_over_g = (1.0 - g + g * g * 0.5) * terms;
    // Large g: (1/g) e^-y (1 + c1 / g + c2 / g^2).
    let inv = 1.0 / g;
    let y = x * inv;
    let c1 = (y * y - y * 4.0 + 2.0) * 0.5;
    let c2 = (((y * 0.125 - 11.0 / 6.0) * y + 7.5) * y - 9.0) * y + 2.0;
    let corr = ((c1 + c2 * inv) * inv).clamp(-0.5, 0.5);
    let ln_large = corr * (1.0 - corr * (0.5 - corr * (1.0 / 3.0))) - y - ln_g;
    let ln_s = in_table.select(ln_table, g.ge(e.g_max).select(ln_large, -1e4));
    g.lt(e.g_min).select(g * s_over_g, ln_s.exp())
}

/// expm1(g) for g >= 0 (f32's exp(g) - 1 loses the digits of small g).
fn expm1<'a>(g: Value<'a>) -> Value<'a> {
    let series = g
        * (1.0
            + g * (0.5
                + g * (1.0 / 6.0
                    + g * (1.0 / 24.0
                        + g * (1.0 / 120.0 + g * (1.0 / 720.0 + g * (1.0 / 5040.0)))))));
    g.lt(0.5).select(series, g.exp() - 1.0)
}

/// The sampling strategy's parameters at one wi and wavelength.
struct Strategy<'a> {
    /// Coherent probability.
    p_coh: Value<'a>,
    /// The series' terms as two Gaussians (`TermMixture`; Beckmann: one).
    terms: TermMixture<'a>,
    /// The fitted lobe and the lobe frozen at the mirror, and the
    /// probability of the second.
    lobes: [SlopeLobe<'a>; 2],
    mix: Value<'a>,
    /// Isotropic surfaces: the horizon twin and its probability (0 away
    /// from the rim).
    twin: Option<(TwinLobe<'a>, Value<'a>)>,
}

/// The series' terms m ~ Poisson(g0 | m >= 1), whose Gaussians have the
/// covariance m / m_mean times the lobe's base, as two Gaussians: m = 1
/// with its probability g0 / (e^g0 - 1), and the terms m >= 2 as one
/// Gaussian at their mean E[m | m >= 2] (Beckmann: one Gaussian, the base).
/// Sample and pdf read the same mixture, so the pdf is exact; against the
/// whole Poisson mixture (a lookup of S per density, 48 terms unrolled to
/// sample) it costs two exponentials, and the defensive part bounds the
/// weights where the heavier terms' tails reach (docs/sampling.md).
#[derive(Clone, Copy)]
struct TermMixture<'a> {
    /// Probability of the first Gaussian.
    first: Value<'a>,
    /// Covariance factors of the two (relative to the base).
    scale: [Value<'a>; 2],
}

impl<'a> TermMixture<'a> {
    fn new(series: Mask<'a>, g0: Value<'a>, m_mean: Value<'a>) -> TermMixture<'a> {
        // E[m | m >= 2] = g (1 - e^-g) / (1 - e^-g (1 + g)); below g = 0.25
        // its series 2 + g / 3 + g^2 / 18 (f32 loses the quotient's digits).
        let e = (-g0).exp();
        let exact = g0 * (1.0 - e) / (1.0 - e * (g0 + 1.0)).max(1e-30);
        let small = g0 * (g0 * (1.0 / 18.0) + 1.0 / 3.0) + 2.0;
        let m_rest = g0.lt(0.25).select(small, exact);
        let inv_mean = 1.0 / m_mean;
        TermMixture {
            first: series.select(g0 / expm1(g0), 1.0),
            scale: [
                series.select(inv_mean, 1.0),
                series.select(m_rest * inv_mean, 1.0),
            ],
        }
    }

    /// The mixture's density at quad (the base's quadratic form) for a
    /// base of normalisation `norm`.
    fn density(&self, norm: Value<'a>, quad: Value<'a>) -> Value<'a> {
        let one = |v: Value<'a>| (quad * -0.5 / v).exp() / v;
        let [a, bb] = self.scale;
        norm * (one(a) * self.first + one(bb) * (1.0 - self.first))
    }

    /// The spread (sqrt of the covariance factor) of the Gaussian that t
    /// (uniform) picks.
    fn spread(&self, t: Value<'a>) -> Value<'a> {
        t.lt(self.first).select(self.scale[0], self.scale[1]).sqrt()
    }
}

/// The sampling strategy's iterative fits of an isotropic surface, which
/// are functions of the incidence cosine and the wavenumber alone: the
/// mode of `slope_lobes`' Laplace fit (three Newton steps) and the horizon
/// twin's alpha law (four Newton steps, eight sines and cosines), made by
/// running those steps on the CPU at FIT_COS_NODES x FIT_LAMBDA_NODES
/// nodes (uniform in ln cos_i and in lambda). The programs read them
/// bilinearly (4 gathers per value) in place of the steps, which a
/// spectral strategy runs at each of a path's four wavelengths. Sample and
/// pdf read the same values, so the pdf stays exact; the fits only steer.
/// Anisotropic surfaces (the fit depends on the azimuth) and sigma
/// textures (sigma varies per point) keep the steps.
pub(crate) struct FitTable {
    /// Per node (cos_i major): the mode, then the twin's mean and sd where
    /// the material has a twin.
    values: Vec<f32>,
    width: usize,
}

const FIT_COS_NODES: usize = 33;
const FIT_MIN_COS: f64 = 1e-3;
const FIT_LAMBDA_NODES: usize = 17;
const FIT_BAND_NM: (f64, f64) = (LAMBDA_MIN_NM, LAMBDA_MAX_NM);

impl FitTable {
    fn build(model: &Gaussian) -> Option<FitTable> {
        let s = &model.surface;
        if !s.isotropic || model.sigma_um_max.is_some() {
            return None;
        }
        let twin = model.twin_matters();
        // The strategy's own code with the steps, at wi = (sin, 0, cos).
        let b = Builder::at_built_values();
        let (cos_i, lambda) = (b.input(), b.input());
        let wi = [(1.0 - cos_i * cos_i).max(0.0).sqrt(), b.c(0.0), cos_i];
        let k = wavenumber_per_um(lambda);
        let a = k * model.sigma_times(&b, 2.0) * cos_i;
        let g0 = a * a;
        let series = g0.lt(SERIES_MAX_G);
        let (_, m_mean, mode) = model.slope_lobes(&b, wi, k, g0, series, None);
        let mut outputs = vec![mode];
        if twin {
            let sd = (m_mean * 2.0).sqrt() / (k * b.built(s.corr_x_um));
            let t = TwinLobe::new(wi, sd, (-g0).exp());
            outputs.extend([t.mean, t.sd]);
        }
        let program = b.finish(&outputs);
        let width = outputs.len();
        let mut values = Vec::with_capacity(FIT_COS_NODES * FIT_LAMBDA_NODES * width);
        let (mut regs, mut out) = (Vec::new(), vec![0.0; width]);
        let (lo, hi) = FIT_BAND_NM;
        for i in 0..FIT_COS_NODES {
            let t = i as f64 / (FIT_COS_NODES - 1) as f64;
            let c = (FIT_MIN_COS.ln() * (1.0 - t)).exp();
            for j in 0..FIT_LAMBDA_NODES {
                let l = lo + (hi - lo) * j as f64 / (FIT_LAMBDA_NODES - 1) as f64;
                program.run_into(&[c, l], &mut regs, &mut out);
                values.extend(
                    out.iter()
                        .map(|&v| if v.is_finite() { v as f32 } else { 0.0 }),
                );
            }
        }
        Some(FitTable { values, width })
    }
}

/// The core's horizon twin (`sampling::HorizonLobe`): with (x', y') the
/// plane coordinates along and across the mirror point and x' = R cos
/// alpha, R = sqrt(1 - y'^2), z = R sin alpha, d omega = d alpha dy'; y' ~
/// N(0, s), alpha ~ N(mean, sd) (a Laplace fit with the (1 + wi.wo)^2
/// tilt). Here alpha is not truncated: a draw outside (0, pi) fails, so the
/// density is the plain product of the normals.
struct TwinLobe<'a> {
    along: [Value<'a>; 2],
    s: Value<'a>,
    mean: Value<'a>,
    sd: Value<'a>,
}

impl<'a> TwinLobe<'a> {
    /// `sampling::HorizonLobe::new` for an isotropic lobe of plane sd `s`
    /// (`alpha_law` with four Newton steps).
    fn new(wi: Vec3<'a>, s: Value<'a>, tilt: Value<'a>) -> TwinLobe<'a> {
        let (rho0, along) = Self::frame(wi);
        let cos_i = wi[2];
        let s2 = s * s;
        // alpha from acos(rho0) (r = 1 > rho0 above the horizon).
        let mut alpha = cos_i.atan2(rho0);
        let mut active = s.gt(0.0);
        let mut curvature = s * 0.0 - 1.0;
        for _ in 0..4 {
            let (sin_a, cos_a) = (alpha.sin(), alpha.cos());
            let q = cos_a - rho0;
            let h = (1.0 - (rho0 * cos_a - cos_i * sin_a)).max(1e-30);
            let dh = rho0 * sin_a + cos_i * cos_a;
            let d1 = tilt * dh / h * 2.0 + q * sin_a / s2;
            let c = tilt * ((1.0 - h) / h - (dh / h) * (dh / h)) * 2.0
                - (sin_a * sin_a - q * cos_a) / s2;
            let concave = c.lt(0.0);
            active = active & concave;
            curvature = active.select(c, curvature);
            let next = (alpha - d1 / c).clamp(0.0, PI);
            let moved = (next - alpha).abs().ge(1e-9);
            alpha = active.select(next, alpha);
            active = active & moved;
        }
        let laplace = curvature.lt(0.0).select((-1.0 / curvature).sqrt(), PI);
        let quartic = (s * 2.0).sqrt();
        let sd = laplace.min(quartic).clamp(1e-9, PI);
        TwinLobe {
            along,
            s,
            mean: alpha,
            sd,
        }
    }

    /// The twin with its alpha law's mean and sd given (the fit table's).
    fn fitted(wi: Vec3<'a>, s: Value<'a>, mean: Value<'a>, sd: Value<'a>) -> TwinLobe<'a> {
        TwinLobe {
            along: Self::frame(wi).1,
            s,
            mean,
            sd: sd.clamp(1e-9, PI),
        }
    }

    /// |wi_xy| and the unit vector along the mirror point (-wi_xy).
    fn frame(wi: Vec3<'a>) -> (Value<'a>, [Value<'a>; 2]) {
        let rho0 = (wi[0] * wi[0] + wi[1] * wi[1]).sqrt();
        let off = rho0.gt(1e-12);
        let inv = 1.0 / rho0.max(1e-12);
        (
            rho0,
            [off.select(-wi[0] * inv, 1.0), off.select(-wi[1] * inv, 0.0)],
        )
    }

    /// The direction from two standard normals; below the horizon when the
    /// draw fails.
    fn direction(&self, n1: Value<'a>, n2: Value<'a>) -> Vec3<'a> {
        let y = self.s * n1;
        let alpha = self.mean + self.sd * n2;
        let r = (1.0 - y * y).max(0.0).sqrt();
        let (x, z) = (r * alpha.cos(), r * alpha.sin());
        let ok = y.abs().lt(1.0) & alpha.gt(0.0) & alpha.lt(PI) & z.gt(MIN_COS);
        let [ax, ay] = self.along;
        [
            ok.select(x * ax - y * ay, 0.0),
            ok.select(x * ay + y * ax, 0.0),
            ok.select(z, -1.0),
        ]
    }

    /// The solid-angle density at unit wo.
    fn pdf(&self, wo: Vec3<'a>) -> Value<'a> {
        let [ax, ay] = self.along;
        let x = wo[0] * ax + wo[1] * ay;
        let y = wo[1] * ax - wo[0] * ay;
        let alpha = wo[2].atan2(x);
        let (ty, ta) = (y / self.s, (alpha - self.mean) / self.sd);
        ((ty * ty + ta * ta) * -0.5).exp() / (self.s * self.sd * (2.0 * PI))
    }
}

/// A lobe in slope space: its centre, the precision matrix of its base
/// Gaussian (xx, xy, yy) and the Cholesky factor of its covariance (l11,
/// l21, l22). The series' term m has the covariance m / m_mean times the
/// base's, Beckmann the base's.
struct SlopeLobe<'a> {
    centre: [Value<'a>; 2],
    precision: [Value<'a>; 3],
    chol: [Value<'a>; 3],
}

impl<'a> SlopeLobe<'a> {
    fn new(centre: [Value<'a>; 2], precision: [Value<'a>; 3]) -> SlopeLobe<'a> {
        let [pxx, pxy, pyy] = precision;
        let inv_det = 1.0 / (pxx * pyy - pxy * pxy);
        let (sxx, sxy, syy) = (pyy * inv_det, -pxy * inv_det, pxx * inv_det);
        let l11 = sxx.sqrt();
        let l21 = sxy / l11;
        let l22 = (syy - l21 * l21).max(0.0).sqrt();
        SlopeLobe {
            centre,
            precision,
            chol: [l11, l21, l22],
        }
    }
}

impl Gaussian {
    /// sigma times `c` for the sampling programs: a constant, or with a
    /// sigma texture (`sigma_um_max`) the parameter, whose value the
    /// renderer gives per point (the strategy, above all the coherent
    /// lobe's share, must follow the point's sigma; sample and pdf read the
    /// same value, so they stay consistent).
    fn sigma_times<'a>(&self, b: &'a Builder, c: f64) -> Value<'a> {
        match self.sigma_um_max {
            Some(_) => b.param(ParamId::SigmaUm, self.surface.sigma_um) * c,
            None => b.built(self.surface.sigma_um * c),
        }
    }

    /// The RGB program's table, built on first use.
    fn rgb_program_table(&self, shading: &Shading) -> Option<&RgbProgramTable> {
        self.rgb_program
            .get_or_init(|| {
                RgbProgramTable::build(
                    &self.surface,
                    shading.rgb_rule,
                    shading.fresnel,
                    false,
                    self.sigma_um_max,
                )
                .map(Box::new)
            })
            .as_deref()
    }

    /// The coherent probability at unit wi (above the horizon) and
    /// wavelength lambda: the coherent lobe's share of the albedo
    /// (`build_component`): e^-g0, or for isotropic surfaces below the
    /// Beckmann regime e^-g0 / (e^-g0 + D) with D the model's tabulated
    /// diffuse albedo.
    fn coherent_probability<'a>(
        &self,
        b: &'a Builder,
        shading: &Shading,
        cos_i: Value<'a>,
        lambda: Value<'a>,
    ) -> Value<'a> {
        let s = &self.surface;
        let a = self.sigma_times(b, WAVENUMBER_TIMES_NM * 2.0) / lambda * cos_i;
        let g0 = a * a;
        let mut p_coh = g0.gt(COHERENT_MAX_G).select(0.0, (-g0).exp());
        if s.isotropic {
            let table = self
                .albedo
                .get_or_init(|| AlbedoTable::build(self, shading));
            let d = table.program(b, cos_i, lambda);
            let usable = d.gt(0.0) & d.finite() & g0.lt(BECKMANN_MIN_G) & p_coh.gt(0.0);
            p_coh = usable.select(p_coh / (p_coh + d), p_coh);
        }
        // e^-g0 rounds to 1 in f32 for g0 below 6e-8 (very smooth or
        // grazing), which would leave the glossy part, and so the pdf where
        // f > 0, at 0: keep a share of at least 1e-6 (sample and pdf both
        // read this value, so they stay consistent).
        p_coh.min(1.0 - 1e-6)
    }

    /// The fit table's values at cos_i and lambda (the mode of
    /// `slope_lobes`, the twin's mean and sd), bilinear in (ln cos_i,
    /// lambda); None where the material has no table.
    fn fit_values<'a>(
        &self,
        b: &'a Builder,
        cos_i: Value<'a>,
        lambda: Value<'a>,
    ) -> Option<[Value<'a>; 3]> {
        let t = self
            .fit_table
            .get_or_init(|| FitTable::build(self))
            .as_ref()?;
        let table = b.table(t.values.clone());
        let u = (1.0 - cos_i.clamp(FIT_MIN_COS, 1.0).ln() * (1.0 / FIT_MIN_COS.ln()))
            * (FIT_COS_NODES - 1) as f64;
        let i = u.floor().min((FIT_COS_NODES - 2) as f64);
        let fi = u - i;
        let (lo, hi) = FIT_BAND_NM;
        let x = ((lambda - lo) * (1.0 / (hi - lo))).clamp(0.0, 1.0) * (FIT_LAMBDA_NODES - 1) as f64;
        let j = x.floor().min((FIT_LAMBDA_NODES - 2) as f64);
        let fj = x - j;
        let width = t.width as f64;
        let base = (i * FIT_LAMBDA_NODES as f64 + j) * width;
        let values = std::array::from_fn(|l| {
            if l >= t.width {
                return b.c(0.0);
            }
            let at = |di: usize, dj: usize| {
                b.gather(
                    table,
                    base + ((di * FIT_LAMBDA_NODES + dj) * t.width + l) as f64,
                )
            };
            let row = |di: usize| {
                let v0 = at(di, 0);
                v0 + (at(di, 1) - v0) * fj
            };
            let r0 = row(0);
            r0 + (row(1) - r0) * fi
        });
        Some(values)
    }

    /// Whether the horizon twin can take a share of TWIN_NEGLIGIBLE or
    /// more anywhere in the band: its share is TWIN_SHARE e^-(k sigma)^2,
    /// largest at the longest wavelength; with a sigma texture sigma may be
    /// anything, so the twin stays. Where it cannot, the programs leave it
    /// out, sample and pdf alike (for the rough benchmark surface in
    /// llvm_ad_spectral it cost 0.35x of roughconductor's render time,
    /// docs/jit_measured.md "Render time").
    fn twin_matters(&self) -> bool {
        let kf = wavenumber_per_um(LAMBDA_MAX_NM) * self.surface.sigma_um;
        self.sigma_um_max.is_some() || TWIN_SHARE * (-(kf * kf)).exp() >= TWIN_NEGLIGIBLE
    }

    /// The strategy at unit wi (above the horizon) for the wavelength
    /// `lambda_nm`; RGB (None): the lobe at RGB_SAMPLING_NM, the coherent
    /// probability the mean over the RGB band (as the core's RGB
    /// strategy).
    fn strategy_program<'a>(
        &self,
        b: &'a Builder,
        shading: &Shading,
        wi: Vec3<'a>,
        lambda_nm: Option<Value<'a>>,
    ) -> Strategy<'a> {
        let s = &self.surface;
        let p_coh = match lambda_nm {
            Some(lambda) => self.coherent_probability(b, shading, wi[2], lambda),
            None => {
                // The core averages its four RGB sampling wavelengths; the
                // probability is smooth in lambda: two midpoints serve.
                let n = crate::sampling::rgb_sampling_nodes();
                let (lo, hi) = (0.5 * (n[0] + n[1]), 0.5 * (n[2] + n[3]));
                (self.coherent_probability(b, shading, wi[2], b.c(lo))
                    + self.coherent_probability(b, shading, wi[2], b.c(hi)))
                    * 0.5
            }
        };
        let lambda = lambda_nm.unwrap_or_else(|| b.c(RGB_SAMPLING_NM));
        let k = wavenumber_per_um(lambda);
        let a = k * self.sigma_times(b, 2.0) * wi[2];
        let g0 = a * a;
        let series = g0.lt(SERIES_MAX_G);
        let fits = self.fit_values(b, wi[2], lambda);
        let (lobes, m_mean, _) = self.slope_lobes(b, wi, k, g0, series, fits.map(|f| f[0]));
        let terms = TermMixture::new(series, g0, m_mean);
        // The twin (isotropic surfaces, the series regime) where the mirror
        // point is within 2 plane sds of the rim (as `build_component`).
        // Its share TWIN_SHARE e^-g_far, g_far = (k sigma)^2 the roughness
        // at w = 1: a twin frozen at the mirror fits smooth surfaces, but
        // where g grows tenfold inwards the real lobe is much wider (the
        // core widens its defensive share there instead); the lobe frozen
        // at the mirror keeps the rest of its share.
        let (twin, frozen_share) = if s.isotropic && self.twin_matters() {
            let sd = (m_mean * 2.0).sqrt() / (k * b.built(s.corr_x_um));
            let to_rim = 1.0 - (wi[0] * wi[0] + wi[1] * wi[1]).sqrt();
            let near = series & to_rim.lt(sd * 2.0);
            let kf = k * self.sigma_times(b, 1.0);
            let smooth = near.select((-(kf * kf)).exp(), 0.0);
            let twin = match fits {
                Some([_, mean, alpha_sd]) => TwinLobe::fitted(wi, sd, mean, alpha_sd),
                None => TwinLobe::new(wi, sd, (-g0).exp()),
            };
            (
                Some((twin, smooth * TWIN_SHARE)),
                (1.0 - smooth) * MIRROR_LOBE,
            )
        } else {
            (None, b.c(MIRROR_LOBE))
        };
        let mix = frozen_share;
        Strategy {
            p_coh,
            terms,
            lobes,
            mix,
            twin,
        }
    }

    /// The two lobes in slope space (s = -h_xy / h_z of the half vector h)
    /// and E[m | m >= 1].
    ///
    /// Beckmann (g0 >= SERIES_MAX_G): both centred at 0, slopes' variances
    /// alpha^2 / 2 per axis (alpha = 2 sigma / T). The series: f cos per
    /// unit slope area is, per term m, ~ w^p (1 + s^2) e^(-x / m) (the w^3
    /// of the half-vector map and of G, and S ~ g^e with e = d ln S / d ln
    /// g, p = 3 + 2 e: 5 for smooth surfaces), with w = cos_i + cos_o and x
    /// = k^2 w^2 (Tx^2 sx^2 + Ty^2 sy^2) / 4: near normal incidence a
    /// Gaussian around s = 0 of variances 2 m / (k T w0)^2 (the lobe frozen
    /// at the mirror, w0 = 2 cos_i), but towards grazing incidence w grows
    /// several-fold inwards across the lobe, which moves its mass away from
    /// the mirror direction and narrows it. The fitted lobe is the Laplace
    /// fit of the mean term: its mode along the plane of incidence by
    /// Newton's method, the precision the curvature there. The law is skewed
    /// (heavier towards the mirror), so the mixture keeps MIRROR_LOBE of the
    /// frozen lobe (measured, sampling_report: smooth surface at cos_i 0.08,
    /// 2.6x the core's variance against 29x with the frozen lobe alone).
    fn slope_lobes<'a>(
        &self,
        b: &'a Builder,
        wi: Vec3<'a>,
        k: Value<'a>,
        g0: Value<'a>,
        series: Mask<'a>,
        mode: Option<Value<'a>>,
    ) -> ([SlopeLobe<'a>; 2], Value<'a>, Value<'a>) {
        let s = &self.surface;
        let (tx2, ty2) = (s.corr_x_um * s.corr_x_um, s.corr_y_um * s.corr_y_um);
        // The correlation lengths' terms as built constants
        let (tx2_v, ty2_v, dt2) = (b.built(tx2), b.built(ty2), b.built(tx2 - ty2));
        let m_mean = series.select(g0 * g0.exp() / expm1(g0), 1.0);
        let e = 2.0 / (g0 * 0.79 + 1.0) - 1.0;
        let p = e * 2.0 + 3.0;
        // The plane of incidence: d along wi_xy (s = -a d + y d_perp).
        let (c, sin_i) = (wi[2], (wi[0] * wi[0] + wi[1] * wi[1]).sqrt());
        let flat = sin_i.gt(1e-6);
        let inv_sin = 1.0 / sin_i.max(1e-6);
        let dx = flat.select(wi[0] * inv_sin, 1.0);
        let dy = flat.select(wi[1] * inv_sin, 0.0);
        let q = k * k * 0.25 / m_mean;
        let kappa_a = q * (dx * dx * tx2_v + dy * dy * ty2_v);
        let kappa_y = q * (dy * dy * tx2_v + dx * dx * ty2_v);
        let kappa_c = q * (dx * dy * dt2);
        // phi(a) = p ln w + ln D - kappa_a w^2 a^2 along the plane, with w =
        // 2 N / D, N = c + sin_i a, D = 1 + a^2; y = w a = 2 P / D, P = N a.
        let derivatives = |a: Value<'a>| {
            let n = c + sin_i * a;
            let d = a * a + 1.0;
            let inv_d = 1.0 / d;
            let pp = n * a;
            let p1 = c + sin_i * a * 2.0;
            let num1 = p1 * d - a * pp * 2.0;
            let y = pp * inv_d * 2.0;
            let y1 = num1 * inv_d * inv_d * 2.0;
            let y2 = ((sin_i * d - pp) * 2.0 * inv_d * inv_d
                - num1 * a * 4.0 * inv_d * inv_d * inv_d)
                * 2.0;
            let lw1 = sin_i / n - a * inv_d * 2.0;
            let one_a2 = (1.0 - a * a) * 2.0 * inv_d * inv_d;
            let lw2 = -(sin_i * sin_i) / (n * n) - one_a2;
            let d1 = p * lw1 + a * inv_d * 2.0 - kappa_a * y * y1 * 2.0;
            let d2 = p * lw2 + one_a2 - kappa_a * (y1 * y1 + y * y2) * 2.0;
            (d1, d2, n, d, lw1)
        };
        // From the mode of p ln(c + a) - 4 kappa_a (c + a)^2 a^2 with c -> 0
        // (the grazing limit), three steps converge (checked on a model of
        // the law from cos_i 0.001 to 0.9; from a = 0 the most grazing need
        // 30).
        // (An isotropic surface's mode is a function of cos_i and k: the
        // fit table's, where it has one.)
        let a = mode.unwrap_or_else(|| {
            let mut a = ((p / (kappa_a * 8.0)).sqrt().sqrt() - c).max(0.0);
            for _ in 0..3 {
                let (d1, d2, ..) = derivatives(a);
                a = (a - d1 / d2.min(-1e-6)).clamp(0.0, 10.0);
            }
            a
        });
        let (_, d2, n, d, lw1) = derivatives(a);
        let w = n / d * 2.0;
        let w2 = w * w;
        // Precision in the (a, y) frame.
        let p_aa = (-d2).max(1e-6);
        let p_yy =
            ((p - 1.0) * 2.0 / d + kappa_y * w2 * 2.0 - kappa_a * w2 * a * a * 4.0 / d).max(1e-6);
        let p_ay = kappa_c * (w2 + a * w2 * lw1 * 2.0) * 2.0;
        let p_ay = p_ay.clamp(-(p_aa * p_yy).sqrt() * 0.95, (p_aa * p_yy).sqrt() * 0.95);
        let (ea, ey) = ([-dx, -dy], [-dy, dx]);
        let fit = |i: usize, j: usize| {
            p_aa * ea[i] * ea[j] + p_yy * ey[i] * ey[j] + p_ay * (ea[i] * ey[j] + ey[i] * ea[j])
        };
        // The lobe frozen at the mirror (w = 2 cos_i, centre 0).
        let w0 = c * 2.0;
        let (two_tx2, two_ty2) = (b.built(2.0 * tx2), b.built(2.0 * ty2));
        let frozen = [q * w0 * w0 * two_tx2, b.c(0.0), q * w0 * w0 * two_ty2];
        // The fitted lobe is the frozen one while the mode is within half
        // an sd of the mirror, the Laplace fit from 2 sds on, linear between.
        let r = a * p_aa.sqrt();
        let beta = ((r - 0.5) * (1.0 / 1.5)).clamp(0.0, 1.0);
        let laplace: [Value; 3] = std::array::from_fn(|i| {
            let (ii, jj) = [(0, 0), (0, 1), (1, 1)][i];
            fit(ii, jj) * beta + frozen[i] * (1.0 - beta)
        });
        let beckmann = match self.sigma_um_max {
            Some(_) => {
                let four_s2 = self.sigma_times(b, 2.0) * self.sigma_times(b, 2.0);
                [two_tx2 / four_s2, b.c(0.0), two_ty2 / four_s2]
            }
            None => [
                b.built(2.0 * tx2 / (4.0 * s.sigma_um * s.sigma_um)),
                b.c(0.0),
                b.built(2.0 * ty2 / (4.0 * s.sigma_um * s.sigma_um)),
            ],
        };
        let fitted = std::array::from_fn(|i| series.select(laplace[i], beckmann[i]));
        let mirror = std::array::from_fn(|i| series.select(frozen[i], beckmann[i]));
        let shift = a * beta;
        let centre = [
            series.select(shift * -dx, 0.0),
            series.select(shift * -dy, 0.0),
        ];
        let zero = [b.c(0.0), b.c(0.0)];
        (
            [SlopeLobe::new(centre, fitted), SlopeLobe::new(zero, mirror)],
            m_mean,
            a,
        )
    }

    /// The lobes' solid-angle density at unit wo (both above the horizon).
    fn lobe_pdf<'a>(&self, st: &Strategy<'a>, wi: Vec3<'a>, wo: Vec3<'a>) -> Value<'a> {
        let h: Vec3 = std::array::from_fn(|i| wi[i] + wo[i]);
        let len = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
        let hz = h[2] / len;
        let cos_ih = (wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]) / len;
        // Slopes (the sampler's h = (-sx, -sy, 1) / |.|).
        let (sx, sy) = (-h[0] / h[2], -h[1] / h[2]);
        let density = |lobe: &SlopeLobe<'a>| {
            let (dx, dy) = (sx - lobe.centre[0], sy - lobe.centre[1]);
            let [pxx, pxy, pyy] = lobe.precision;
            let quad = pxx * dx * dx + pxy * dx * dy * 2.0 + pyy * dy * dy;
            let norm = (pxx * pyy - pxy * pxy).max(0.0).sqrt() * (0.5 / PI);
            st.terms.density(norm, quad)
        };
        let to_omega = 1.0 / (hz * hz * hz * cos_ih * 4.0);
        let half_vector = hz.gt(0.0) & cos_ih.gt(0.0);
        let fitted = half_vector.select(density(&st.lobes[0]) * to_omega, 0.0);
        let frozen = half_vector.select(density(&st.lobes[1]) * to_omega, 0.0);
        let slopes = fitted * (1.0 - st.mix) + frozen * st.mix;
        match &st.twin {
            // The twin's share comes first; the slope lobes share the rest.
            Some((twin, share)) => twin.pdf(wo) * *share + slopes * (1.0 - *share),
            None => slopes,
        }
    }
}

impl GaussianSurface {
    /// sigma, Tx and Ty as the program's parameters (`Op::Param`: a
    /// renderer may change them): sigma_um, and corr_um for both axes of
    /// an isotropic surface, else corr_x_um and corr_y_um.
    pub(super) fn params_program<'a>(&self, b: &'a Builder) -> (Value<'a>, Value<'a>, Value<'a>) {
        let sigma = b.param(ParamId::SigmaUm, self.sigma_um);
        if self.isotropic {
            let t = b.param(ParamId::CorrUm, self.corr_x_um);
            (sigma, t, t)
        } else {
            (
                sigma,
                b.param(ParamId::CorrXUm, self.corr_x_um),
                b.param(ParamId::CorrYUm, self.corr_y_um),
            )
        }
    }
}

/// A uniform number usable as such: finite, in [0, 1).
fn uniform(u: Value) -> Value {
    u.finite().select(u, 0.0).clamp(0.0, 1.0 - 1e-7)
}

impl SurfacePrograms for Gaussian {
    fn kernel_program<'a>(
        &self,
        b: &'a Builder,
        pair: &PairProgram<'a>,
        k_per_um: Value<'a>,
    ) -> Option<Value<'a>> {
        let lk = SeriesLookup::new(b);
        let (sigma, tx, ty) = self.surface.params_program(b);
        let a = (k_per_um * sigma * pair.w).abs();
        let g = a * a;
        let ln_g = a.ln() * 2.0;
        let (qx, qy) = (tx * tx * 0.25, ty * ty * 0.25);
        let x = k_per_um * k_per_um * (pair.u * pair.u * qx + pair.v * pair.v * qy);
        let series = series(b, &lk, g, ln_g, x);
        let prefactor = k_per_um * k_per_um * (tx * ty * (1.0 / (4.0 * PI))) / (pair.w * pair.w);
        Some(prefactor * series)
    }

    /// Gaussian tables are colour-neutral (the material scales outside):
    /// no per-wavelength factor.
    fn reflectance_rgb_program<'a>(
        &self,
        b: &'a Builder,
        shading: &Shading,
        pair: &PairProgram<'a>,
        factor: Option<FactorMaker<'_, 'a>>,
    ) -> Option<[Value<'a>; 3]> {
        if factor.is_some() {
            return None;
        }
        let t = self.rgb_program_table(shading)?;
        Some(rgb_from_table(b, t, &self.surface, shading, pair))
    }

    fn coherent_spectral_program<'a>(
        &self,
        b: &'a Builder,
        shading: &Shading,
        cos_i: Value<'a>,
        lambda_nm: Value<'a>,
    ) -> Option<Value<'a>> {
        let k = wavenumber_per_um(lambda_nm);
        let sigma = b.param(ParamId::SigmaUm, self.surface.sigma_um);
        let a = k * (sigma * 2.0) * cos_i;
        let g = a * a;
        let r = shading.fresnel.program(b, cos_i, lambda_nm) * (-g).exp();
        Some(g.gt(COHERENT_MAX_G).select(0.0, r))
    }

    fn coherent_rgb_program<'a>(
        &self,
        b: &'a Builder,
        shading: &Shading,
        cos_i: Value<'a>,
        factor: Option<&dyn FactorProgram<'a>>,
    ) -> Option<[Value<'a>; 3]> {
        if factor.is_some() {
            return None;
        }
        let rule = shading.rgb_rule;
        let sigma = b.param(ParamId::SigmaUm, self.surface.sigma_um);
        let c2 = cos_i * cos_i * (sigma * sigma * 4.0);
        let values: Vec<Value> = rule
            .k_per_um
            .iter()
            .map(|&k| (c2 * (-k * k)).exp())
            .collect();
        let rgb = weighted_sum(b, shading, cos_i, &values);
        let k_red = wavenumber_per_um(LAMBDA_MAX_NM);
        let gone = (c2 * (k_red * k_red)).gt(COHERENT_MAX_G);
        Some(rgb.map(|c| gone.select(0.0, c)))
    }

    fn coherent_probability_program<'a>(
        &self,
        b: &'a Builder,
        shading: &Shading,
        wi: Vec3<'a>,
        lambda_nm: Option<Value<'a>>,
    ) -> Option<Value<'a>> {
        Some(self.strategy_program(b, shading, wi, lambda_nm).p_coh)
    }

    fn sample_program<'a>(
        &self,
        b: &'a Builder,
        shading: &Shading,
        wi: Vec3<'a>,
        lambda_nm: Option<Value<'a>>,
        u: [Value<'a>; 3],
    ) -> Option<SampleProgram<'a>> {
        let st = self.strategy_program(b, shading, wi, lambda_nm);
        let [u0, u1, u2] = u.map(uniform);
        // u0 picks the coherent lobe, then the defensive part (cosine or
        // uniform), then the lobe and, remapped, its term.
        let coherent = u0.lt(st.p_coh);
        let rest = (1.0 - st.p_coh).max(1e-30);
        let t = ((u0 - st.p_coh) / rest).clamp(0.0, 1.0 - 1e-7);
        let defensive = t.lt(DEFENSIVE);
        let cosine = t.lt(0.5 * DEFENSIVE);
        let t_lobe = ((t - DEFENSIVE) * (1.0 / (1.0 - DEFENSIVE))).clamp(0.0, 1.0 - 1e-7);
        // The twin's share of it first (remapped), then the mirror lobe's
        // `mix` of the rest, then the term.
        let (use_twin, t_lobe) = match &st.twin {
            Some((_, share)) => {
                let use_twin = t_lobe.lt(*share);
                let rest = ((t_lobe - *share) / (1.0 - *share).max(1e-30)).clamp(0.0, 1.0 - 1e-7);
                (Some(use_twin), rest)
            }
            None => (None, t_lobe),
        };
        let mirror_lobe = t_lobe.lt(st.mix);
        let t_lobe = mirror_lobe
            .select(t_lobe / st.mix, (t_lobe - st.mix) / (1.0 - st.mix))
            .clamp(0.0, 1.0 - 1e-7);
        // The term's Gaussian.
        let spread = st.terms.spread(t_lobe);
        // Box-Muller: two normals from u1, u2, then the lobe's Gaussian.
        let r = (-(1.0 - u1).ln()).sqrt() * std::f64::consts::SQRT_2;
        let phi = u2 * (2.0 * PI);
        let (b1, b2) = (r * phi.cos(), r * phi.sin());
        let (n1, n2) = (b1 * spread, b2 * spread);
        let pick = |i: usize| mirror_lobe.select(st.lobes[1].chol[i], st.lobes[0].chol[i]);
        let (l11, l21, l22) = (pick(0), pick(1), pick(2));
        let centre = |i: usize| mirror_lobe.select(st.lobes[1].centre[i], st.lobes[0].centre[i]);
        let sx = centre(0) + l11 * n1;
        let sy = centre(1) + l21 * n1 + l22 * n2;
        let inv = 1.0 / (sx * sx + sy * sy + 1.0).sqrt();
        let h = [-sx * inv, -sy * inv, inv];
        let dot = wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2];
        let lobe: Vec3 = std::array::from_fn(|i| h[i] * (2.0 * dot) - wi[i]);
        let lobe_ok = dot.gt(0.0) & lobe[2].gt(MIN_COS) & lobe[2].finite();
        let mut lobe = [
            lobe_ok.select(lobe[0], 0.0),
            lobe_ok.select(lobe[1], 0.0),
            lobe_ok.select(lobe[2], -1.0),
        ];
        if let (Some((twin, _)), Some(use_twin)) = (&st.twin, use_twin) {
            let d = twin.direction(b1, b2);
            lobe = std::array::from_fn(|i| use_twin.select(d[i], lobe[i]));
        }
        let cos_dir = cosine_direction_program(b, u1, u2);
        let z = (1.0 - u1).max(2.0 * MIN_COS);
        let ring = (1.0 - z * z).max(0.0).sqrt();
        let uniform_dir = [ring * phi.cos(), ring * phi.sin(), z];
        let mirror = [-wi[0], -wi[1], wi[2]];
        let wo = std::array::from_fn(|i| {
            let def = cosine.select(cos_dir[i], uniform_dir[i]);
            let glossy = defensive.select(def, lobe[i]);
            coherent.select(mirror[i], glossy)
        });
        Some(SampleProgram { wo, coherent })
    }

    fn pdf_program<'a>(
        &self,
        b: &'a Builder,
        shading: &Shading,
        wi: Vec3<'a>,
        wo: Vec3<'a>,
        lambda_nm: Option<Value<'a>>,
    ) -> Option<Value<'a>> {
        let st = self.strategy_program(b, shading, wi, lambda_nm);
        let defensive = (cosine_density_program(wo) + 0.5 / PI) * 0.5;
        let lobe = self.lobe_pdf(&st, wi, wo);
        let glossy = defensive * DEFENSIVE + lobe * (1.0 - DEFENSIVE);
        Some((1.0 - st.p_coh) * glossy)
    }
}

pub(crate) use super::program_rgb::{rgb_from_table, weighted_sum, RgbProgramTable};

#[cfg(test)]
#[path = "program_tests.rs"]
mod tests;

#[cfg(test)]
#[path = "param_tests.rs"]
mod param_tests;

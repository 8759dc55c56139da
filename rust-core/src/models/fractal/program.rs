//! The fractal model's programs for tracing renderers (crate::program,
//! docs/jit.md): the same physics as its native path, as array operations.
//!
//! - Parameters (`Op::Param`): sigma_um and lag_um in the eval programs,
//!   through ln a's constant ln(sigma^2 / 2) - alpha ln(lag) (two logs);
//!   hurst selects the profile's table and stays a constant, as do the
//!   sampling programs' scales.
//! - K (`kernel_program`) as `FractalSurface::kernel`: y = ln(k r s), ln Phi(e^y)
//!   from the profile's own table (the Hermite cubic of `ln_phi_at_ln`, one
//!   cell's four coefficients: 4 gathers) and its two run-time series
//!   outside it, all in log space and one exp at the end. A series enters
//!   as its factor 1 + p times the exp rather than as ln(1 + p) (one log
//!   less, the same value).
//! - RGB (`reflectance_rgb_program`) as `reflectance_rgb`: K at the RGB
//!   rule's nodes sharing the pair's logarithms (`kernel_at_wavenumbers`:
//!   y and ln K are affine in ln k), and the series' exponentials (the
//!   nodes' differ by constant factors), then the rule with the Fresnel
//!   term folded in (`RgbRule::integrate_program`).
//! - No coherent lobe: the fractal kernel has none (docs/physics.md); the
//!   trait's defaults (0) stand.
//! - Sampling: the core's strategy (`sampling.rs`: a defensive part, half
//!   cosine and half uniform, and the radial lobe of the profile in the
//!   projected plane, frozen at the mirror configuration, with the lobe's
//!   share 0.9 times the cube of its mass inside the unit disc; RGB: the equal
//!   mixture of the four RGB sampling wavelengths). The lobe's radius is
//!   drawn from `RadialProposal`, the profile's radial law interpolated
//!   linearly in ln x between cell edges and drawn with an alias table
//!   (four gathers, no search) instead of the native inverse CDF (a search
//!   and Newton steps), and the pdf is that law's density (two gathers per
//!   component), so that sampling and pdf agree exactly. The incidence cosine and the wavelength are used as
//!   they are (the native table quantises them: 128 cosine bins, 17
//!   wavelengths).

use super::math::{LN_2PI, LN_PI};
use super::profile::ProfileParts;
use super::sampling::{RadialProposal, LOBE_SHARE_POWER};
use super::{Fractal, FractalSurface, LN_4PI2};
use crate::models::{FactorMaker, SampleProgram, Shading, SurfacePrograms};
use crate::optics::geometry::MIN_COS;
use crate::optics::program::{PairProgram, Vec3};
use crate::program::{Builder, ParamId, Table, Value};
use crate::sampling::program::{
    component_choice, defensive_density_program, defensive_direction_program, pick,
    unit_interval_program, U_MAX,
};
use crate::sampling::{rgb_sampling_nodes, DEFENSIVE_FRACTION};
use crate::spectrum::wavenumber_per_um;
use std::f64::consts::PI;

/// Largest ln K (and ln pdf) a program keeps: e^87 times a series factor
/// (at most 3) stays finite in f32.
const LN_MAX: f64 = 87.0;

/// Spread in y (times 2 or alpha) up to which the RGB nodes share the
/// series' exponentials through constant factors (f32-safe).
const SHARED_SPREAD: f64 = 40.0;

/// Phi(e^y) = exp(e) m as registers (m None: 1).
struct LnPhi<'a> {
    e: Value<'a>,
    m: Option<Value<'a>>,
}

impl<'a> LnPhi<'a> {
    /// exp(l + e) m, l + e clamped to LN_MAX.
    fn exp_plus(&self, l: Value<'a>) -> Value<'a> {
        let x = (l + self.e).min(LN_MAX).exp();
        match self.m {
            Some(m) => x * m,
            None => x,
        }
    }
}

/// The series variables before clamping: e^(2 (y - y0)) and
/// e^(-alpha (y - y_last)) (Gaussian profile: e^(2y), y0 = 0).
#[derive(Clone, Copy)]
struct SeriesVars<'a> {
    v: Value<'a>,
    u: Value<'a>,
}

/// The stable profile in one program: its parts and its cell table.
struct ProfileProgram<'a> {
    b: &'a Builder,
    parts: ProfileParts,
    cells: Option<Table>,
}

impl<'a> ProfileProgram<'a> {
    fn new(b: &'a Builder, surface: &FractalSurface) -> ProfileProgram<'a> {
        let parts = surface.profile.program_parts();
        let cells = (!parts.gaussian).then(|| {
            b.table(
                parts
                    .cells
                    .iter()
                    .flat_map(|c| c.map(|x| x as f32))
                    .collect(),
            )
        });
        ProfileProgram { b, parts, cells }
    }

    fn y0(&self) -> f64 {
        if self.parts.gaussian {
            0.0
        } else {
            self.parts.y0
        }
    }

    fn vars(&self, y: Value<'a>) -> SeriesVars<'a> {
        let p = &self.parts;
        SeriesVars {
            v: ((y - self.y0()) * 2.0).exp(),
            u: ((y - p.y_last) * -p.alpha).exp(),
        }
    }

    /// The variables at y + d from those at y (d a constant).
    fn shifted(&self, vars: SeriesVars<'a>, d: f64) -> SeriesVars<'a> {
        SeriesVars {
            v: vars.v * (2.0 * d).exp(),
            u: vars.u * (-self.parts.alpha * d).exp(),
        }
    }

    /// ln Phi(e^y) as `ln_phi_at_ln`, with the series variables at y.
    fn ln_phi(&self, y: Value<'a>, vars: SeriesVars<'a>) -> LnPhi<'a> {
        let p = &self.parts;
        let b = self.b;
        let Some(table) = self.cells else {
            // alpha = 2: ln pi - x^2 / 4.
            return LnPhi {
                e: LN_PI - vars.v * 0.25,
                m: None,
            };
        };
        let s = (y - p.y0) * p.inv_h;
        let sc = s.clamp(0.0, p.last_s);
        let i = sc.floor().min((p.cells.len() - 1) as f64);
        let t = sc - i;
        let base = i * 4.0;
        let c = |j: usize| b.gather(table, base + j as f64);
        let cubic = c(3).fma(t, c(2)).fma(t, c(1)).fma(t, c(0));
        // Horner as `small_ln_phi` / `tail_ln_phi`: v (c1 + v (c2 + ...)).
        let series = |coefs: &[f64], x: Value<'a>| {
            let x = x.min(1.0);
            let (last, rest) = coefs.split_last().expect("series terms");
            let acc = rest.iter().rev().fold(b.c(*last), |acc, &c| acc.fma(x, c));
            acc.fma(x, 1.0)
        };
        let small = s.lt(0.0);
        let tail = s.ge(p.last_s);
        LnPhi {
            e: small.select(
                p.ln_phi0,
                tail.select(y * -(p.alpha + 2.0) + p.ln_a1, cubic),
            ),
            m: Some(small.select(
                series(&p.small_c, vars.v),
                tail.select(series(&p.large_r, vars.u), 1.0),
            )),
        }
    }
}

impl FractalSurface {
    /// `ln_a_const` = ln(sigma^2 / 2) - alpha ln(lag) from the material's
    /// parameters sigma_um and lag_um (`Op::Param`, which a renderer can
    /// differentiate: K depends on them through this constant only, the
    /// profile's table on alpha = 2 hurst only, which stays a constant).
    fn ln_a_const_program<'a>(&self, b: &'a Builder) -> Value<'a> {
        let sigma = b.param(ParamId::SigmaUm, self.sigma_um);
        let lag = b.param(ParamId::LagUm, self.lag_um);
        sigma.ln() * 2.0 - lag.ln().fma(self.alpha, std::f64::consts::LN_2)
    }

    /// ln of the lobe's scale c = k times the projected scale at the
    /// mirror (w = 2 cos_i), `build_component`'s ln_c, as
    /// `ln_k (1 - 2/alpha) + shared`, shared from `lobe_scale_shared`.
    fn lobe_scale_shared<'a>(&self, cos_i: Value<'a>) -> Value<'a> {
        let b = cos_i.builder();
        (cos_i * 2.0).ln() * (-2.0 * self.inv_alpha) - b.built(self.inv_alpha * self.ln_a_const)
    }

    /// The lobe's share of a component (`sampling::lobe_share` of its mass
    /// inside the unit disc, in the proposal's closed form) at ln c.
    fn lobe_share<'a>(&self, proposal: &RadialProposal, ln_c: Value<'a>) -> Value<'a> {
        let z = (ln_c * 2.0 - proposal.ln_inside_b).exp();
        let outside = ((z + 1.0).ln() * (-0.5 * self.alpha)).exp();
        let inside = 1.0 - outside;
        let power = (1..LOBE_SHARE_POWER).fold(inside, |p, _| p * inside);
        power * (1.0 - DEFENSIVE_FRACTION)
    }
}

/// The terms ln k (1 - 2/alpha) of the components: the wavelength's, or
/// the RGB strategy's four.
fn component_terms<'a>(
    b: &'a Builder,
    f: &FractalSurface,
    lambda_nm: Option<Value<'a>>,
) -> Vec<Value<'a>> {
    let slope = 1.0 - 2.0 * f.inv_alpha;
    match lambda_nm {
        Some(lambda) => vec![wavenumber_per_um(lambda).ln() * slope],
        None => rgb_sampling_nodes()
            .iter()
            .map(|&l| b.c(wavenumber_per_um(l).ln() * slope))
            .collect(),
    }
}

impl SurfacePrograms for Fractal {
    fn kernel_program<'a>(
        &self,
        b: &'a Builder,
        pair: &PairProgram<'a>,
        k_per_um: Value<'a>,
    ) -> Option<Value<'a>> {
        let f = &self.surface;
        let profile = ProfileProgram::new(b, f);
        let ln_k = k_per_um.ln();
        let ln_w = pair.w.abs().ln();
        // ln s = -(2 ln(k |w|) + ln_a_const) / alpha; y = ln(k r) + ln s.
        let ln_a_const = f.ln_a_const_program(b);
        let ln_s = (ln_k + ln_w) * (-2.0 * f.inv_alpha) - ln_a_const * f.inv_alpha;
        let ln_r2 = (pair.u * pair.u + pair.v * pair.v).ln();
        let y = ln_r2 * 0.5 + ln_k + ln_s;
        let phi = profile.ln_phi(y, profile.vars(y));
        // K = k^2 / (4 pi^2 w^2) s^2 Phi.
        Some(phi.exp_plus((ln_k - ln_w + ln_s) * 2.0 - LN_4PI2))
    }

    /// Fractal tables are colour-neutral (the material scales outside): no
    /// per-wavelength factor.
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
        let f = &self.surface;
        let rule = shading.rgb_rule;
        let profile = ProfileProgram::new(b, f);
        let ln_w = pair.w.abs().ln();
        let ln_a_const = f.ln_a_const_program(b);
        let ln_s0 = ln_w * (-2.0 * f.inv_alpha) - ln_a_const * f.inv_alpha;
        let y_base = (pair.u * pair.u + pair.v * pair.v).ln() * 0.5 + ln_s0;
        // Node j: y_j = y_base + d_j and ln K_j = a + 2 d_j + ln Phi(y_j),
        // d_j = ln k_j (1 - 2/alpha).
        let a = (ln_s0 - ln_w) * 2.0 - LN_4PI2;
        let d: Vec<f64> = rule
            .ln_k_per_um
            .iter()
            .map(|l| l * (1.0 - 2.0 * f.inv_alpha))
            .collect();
        let d_ref = d.iter().sum::<f64>() / d.len().max(1) as f64;
        let spread = d.iter().map(|x| (x - d_ref).abs()).fold(0.0, f64::max);
        let shared = spread * f.alpha.max(2.0) < SHARED_SPREAD;
        let vars_ref = profile.vars(y_base + d_ref);
        let values: Vec<Value> = d
            .iter()
            .map(|&dj| {
                let y = y_base + dj;
                let vars = if shared {
                    profile.shifted(vars_ref, dj - d_ref)
                } else {
                    profile.vars(y)
                };
                profile.ln_phi(y, vars).exp_plus(a + 2.0 * dj)
            })
            .collect();
        Some(rule.integrate_program(b, shading.fresnel, pair.cos_half, &values))
    }

    fn sample_program<'a>(
        &self,
        b: &'a Builder,
        _shading: &Shading,
        wi: Vec3<'a>,
        lambda_nm: Option<Value<'a>>,
        u: [Value<'a>; 3],
    ) -> Option<SampleProgram<'a>> {
        let f = &self.surface;
        let proposal = RadialProposal::new(&f.profile);
        let [r0, r1, r2] = u.map(unit_interval_program);
        // The component (RGB: one of four wavelengths), then its part.
        let terms = component_terms(b, f, lambda_nm);
        let (j, r) = component_choice(r0, terms.len());
        let ln_c = pick(j, &terms) + f.lobe_scale_shared(wi[2]);
        let p_lobe = f.lobe_share(&proposal, ln_c);
        let p_def = 1.0 - p_lobe;
        let phi = r2 * (2.0 * PI);
        let (cos_phi, sin_phi) = (phi.cos(), phi.sin());
        // Defensive: half cosine-weighted, half uniform.
        let defensive = defensive_direction_program(r.lt(p_def * 0.5), r1, cos_phi, sin_phi);
        // The lobe: an entry of the alias table from r1, the position
        // inside it from the rest of r0.
        let t = ((r - p_def) / p_lobe).clamp(0.0, U_MAX);
        let entries = (proposal.alias.len() / 2) as f64;
        let alias = b.table(proposal.alias.clone());
        let density = b.table(proposal.density.clone());
        let x = r1 * entries;
        let i = x.floor().min(entries - 1.0);
        let keep = b.gather(alias, i * 2.0);
        let e = (x - i).lt(keep).select(i, b.gather(alias, i * 2.0 + 1.0));
        // Inside a cell: the density runs linearly from a to b, and
        // t' = t (a + b) / (a + sqrt((1 - t) a^2 + t b^2)) inverts its cdf.
        let (lo, hi) = (b.gather(density, e * 2.0), b.gather(density, e * 2.0 + 1.0));
        let root = ((1.0 - t) * lo * lo + t * hi * hi).sqrt();
        let inside = t * (lo + hi) / (lo + root);
        let cells = proposal.cells as f64;
        let ln_rest = (1.0 - t).ln();
        let y_hi = proposal.y_lo + cells * proposal.h;
        let y = e.eq(cells).select(
            ln_rest * 0.5 + proposal.y_lo,
            e.eq(cells + 1.0).select(
                ln_rest * (-1.0 / proposal.alpha) + y_hi,
                (e + inside).fma(proposal.h, proposal.y_lo),
            ),
        );
        let radius = (y - ln_c).exp();
        let lx = -wi[0] - radius * cos_phi;
        let ly = -wi[1] - radius * sin_phi;
        let rr = lx * lx + ly * ly;
        let lz = (1.0 - rr).max(0.0).sqrt();
        let lobe_ok = radius.lt(2.0) & rr.lt(1.0) & lz.gt(MIN_COS);
        let lobe = [
            lobe_ok.select(lx, 0.0),
            lobe_ok.select(ly, 0.0),
            lobe_ok.select(lz, -1.0),
        ];
        let is_def = r.lt(p_def);
        Some(SampleProgram {
            wo: std::array::from_fn(|c| is_def.select(defensive[c], lobe[c])),
            coherent: !b.always(),
        })
    }

    fn pdf_program<'a>(
        &self,
        b: &'a Builder,
        _shading: &Shading,
        wi: Vec3<'a>,
        wo: Vec3<'a>,
        lambda_nm: Option<Value<'a>>,
    ) -> Option<Value<'a>> {
        let f = &self.surface;
        let proposal = RadialProposal::new(&f.profile);
        let table = b.table(proposal.density.clone());
        let cells = proposal.cells as f64;
        let y_hi = proposal.y_lo + cells * proposal.h;
        let (u, v) = (-(wi[0] + wo[0]), -(wi[1] + wo[1]));
        let ln_r2 = (u * u + v * v).ln();
        let defensive = defensive_density_program(wo[2]);
        let shared = f.lobe_scale_shared(wi[2]);
        let terms = component_terms(b, f, lambda_nm);
        let count = terms.len();
        let sum = terms
            .iter()
            .map(|&term| {
                let ln_c = term + shared;
                let p_lobe = f.lobe_share(&proposal, ln_c);
                // The density of y = ln(c r) per unit y, then per unit
                // area of (u, v): rho(y) / (2 pi r^2).
                let y = ln_r2 * 0.5 + ln_c;
                let s = (y - proposal.y_lo) * (1.0 / proposal.h);
                let sc = s.clamp(0.0, cells);
                let i = sc.floor().min(cells - 1.0);
                let t = sc - i;
                let lo = b.gather(table, i * 2.0);
                let hi = b.gather(table, i * 2.0 + 1.0);
                let ln_rho = s.ge(cells).select(
                    (y - y_hi) * -proposal.alpha + proposal.ln_above,
                    (lo + (hi - lo) * t).ln(),
                );
                // Below y_lo, 2 P e^(2 (y - y_lo)) / (2 pi r^2) has no r.
                let ln_below = (ln_c - proposal.y_lo) * 2.0 + proposal.ln_below;
                let ln_p = s.lt(0.0).select(ln_below, ln_rho - ln_r2) - LN_2PI;
                let p_uv = ln_p.min(LN_MAX).exp();
                (1.0 - p_lobe) * defensive + p_lobe * p_uv * wo[2]
            })
            .reduce(|a, x| a + x)
            .expect("a component");
        Some(sum * (1.0 / count as f64))
    }
}

//! A grating's RGB: each order's peak integrated against the linear sRGB
//! matching functions over the band (`PeriodicSurface::kernel_rgb_general`),
//! for Stam's order powers or powers given per order and wavelength
//! (rigorous.rs).

use super::{
    rect_power_coefficients, Model, PeriodicSurface, RGB_BROAD_SIGMA, RGB_PEAK_HALF_WIDTH_SIGMAS,
    RGB_SMOOTH_NODES, RGB_TAIL_EXPONENT,
};
use crate::optics::geometry::PairGeometry;
use crate::special::{fast_exp, fast_exp_vectorisable, sin_squared};
use crate::spectrum;
use std::f64::consts::PI;

/// Nodes of the broad-peak rule for powers given per order (rigorous.rs).
pub(crate) const GIVEN_BROAD_NODES: usize = 96;

/// Narrow peaks of a power given per order wider than this (sd in
/// wavenumber, 1 / um) take midpoints GIVEN_PEAK_SPACING apart over the
/// peak's +-4 sd (GIVEN_PEAK_NODES at least and at most) instead of a
/// quadratic fit through three wavelengths, which misses an efficiency's
/// kinks (print_rgb_against_the_reference: 9.1% at a coherence length of
/// 8 um, 1.0% at 50 um with the fit; 16 midpoints 0.77%, 0.44%; 8 midpoints
/// 3.8% at 8 um).
const GIVEN_FIT_SIGMA: f64 = 0.005;
const GIVEN_PEAK_SPACING: f64 = 0.03;
const GIVEN_PEAK_NODES: (f64, f64) = (8.0, 24.0);

impl PeriodicSurface {
    /// Linear-sRGB kernel: integral over the visible band of
    /// reflectance(lambda_nm) K(lambda) W_c(lambda) d lambda. No fixed
    /// wavelength grid (no banding). In wavenumber nu, order n's factor is
    /// exp(-A_n) exp(-(nu - mu_n)^2 / (2 s^2)) with rho^2 = u^2 + v^2,
    /// mu_n = u n / (Lam rho^2), s = 1 / (2 sqrt 2 pi l rho) and
    /// A_n = 4 pi^2 l^2 n^2 v^2 / (Lam^2 rho^2). Per order:
    /// - skipped if its exponent exceeds 40 everywhere in the band;
    /// - s <= 0.1 /um: the rest S_n = R nu^2 |c_n(2 pi nu w)|^2 (times
    ///   4 pi l^2 / w^2) is fitted by a quadratic through 3 evaluations
    ///   (Gauss-Hermite nodes mu +- sqrt 3 s, moved inside the significant
    ///   in-band part of the peak when it is cut by the band edge) and
    ///   integrated against the Gaussian moments of W_c (`peak_moments`);
    /// - s > 0.1 /um (order 0 near the mirror direction, short l): the whole
    ///   term goes through the 32-node `spectrum::smooth_rule`.
    ///
    /// Measured (tests): max channel error / max channel below 3.1e-3 against
    /// fine-grid references for the compact disc (l = 3.75..5000 um), a sine
    /// and a tabulated grating, flat and gold-like reflectance. Channels can
    /// be negative (sRGB matching functions have negative lobes); the result
    /// is always finite.
    pub fn kernel_rgb(&self, geom: &PairGeometry, reflectance: &dyn Fn(f64) -> f64) -> [f64; 3] {
        let rule = spectrum::smooth_rule(RGB_SMOOTH_NODES);
        self.kernel_rgb_with(geom, reflectance, &|j| reflectance(rule.lambda_nm[j]))
    }

    /// The wavelengths of the broad-peak rule for powers given per order
    /// (`OrderWeights::Given`'s at_node).
    pub(crate) fn given_broad_wavelengths() -> &'static [f64] {
        &spectrum::smooth_rule(GIVEN_BROAD_NODES).lambda_nm
    }

    /// The wavelengths of the rule for broad peaks (see `kernel_rgb`).
    pub fn broad_rule_wavelengths() -> &'static [f64] {
        &spectrum::smooth_rule(RGB_SMOOTH_NODES).lambda_nm
    }

    /// `kernel_rgb` with the reflectance at the broad rule's nodes given by
    /// node index (`broad_rule_wavelengths`), which a caller may tabulate.
    pub fn kernel_rgb_with(
        &self,
        geom: &PairGeometry,
        reflectance: &dyn Fn(f64) -> f64,
        node_reflectance: &dyn Fn(usize) -> f64,
    ) -> [f64; 3] {
        self.kernel_rgb_general(
            geom,
            OrderWeights::Kirchhoff {
                reflectance,
                node_reflectance,
            },
        )
    }

    /// The RGB integration of `kernel_rgb_with` with each order's power
    /// given by `weights`: Stam's (F^2 K) or one per order and wavelength
    /// (`kernel_given`'s f, rigorous.rs).
    pub(crate) fn kernel_rgb_general(
        &self,
        geom: &PairGeometry,
        weights: OrderWeights,
    ) -> [f64; 3] {
        let mut out = [0.0; 3];
        let (u, v, w) = (geom.u, geom.v, geom.w);
        if !(w < 0.0 && u.is_finite() && v.is_finite()) {
            return out;
        }
        let nu_lo = 1000.0 / spectrum::LAMBDA_MAX_NM;
        let nu_hi = 1000.0 / spectrum::LAMBDA_MIN_NM;
        let l = self.coherence_um;
        let lam = self.period_um;
        let two_pi_l = 2.0 * PI * l;
        // exp(-4 pi^2 l^2 nu^2 v^2) <= its value at nu_lo for every order.
        if (two_pi_l * nu_lo * v).powi(2) > RGB_TAIL_EXPONENT {
            return out;
        }
        let rho2 = u * u + v * v;
        // k^2 l^2 / (pi w^2) = c_const nu^2 (Stam), k^2 l^2 / pi (given).
        let c_const = match weights {
            OrderWeights::Kirchhoff { .. } => 4.0 * PI * l * l / (w * w),
            OrderWeights::Given { .. } => 4.0 * PI * l * l,
        };
        let (n_lo, n_hi) = orders_in_band(u, lam, l, nu_lo, nu_hi);
        // Orders handled by the smooth rule (broad peaks).
        let mut broad: [i64; 8] = [0; 8];
        let mut n_broad = 0usize;
        let mut broad_overflow = false;
        for n in n_lo..=n_hi {
            // Exponent E_n(nu) = 4 pi^2 l^2 [(nu u - n/Lam)^2 + nu^2 v^2]
            //                  = A_n + (nu - mu)^2 / (2 s^2).
            let nf = n as f64;
            let a_n;
            let mu;
            let s;
            if rho2 > 0.0 {
                a_n = (two_pi_l * nf * v / lam).powi(2) / rho2;
                mu = u * nf / (lam * rho2);
                s = 1.0 / (2.0 * std::f64::consts::SQRT_2 * PI * l * rho2.sqrt());
            } else {
                a_n = (two_pi_l * nf / lam).powi(2);
                mu = 0.0;
                s = f64::INFINITY;
            }
            if !(a_n <= RGB_TAIL_EXPONENT) {
                continue;
            }
            let nearest = mu.clamp(nu_lo, nu_hi);
            let gap = ((nearest - mu) / s).powi(2) * 0.5;
            if !(a_n + gap <= RGB_TAIL_EXPONENT) {
                continue;
            }
            // Significant part [a, b] of the peak inside the band.
            let reach = RGB_PEAK_HALF_WIDTH_SIGMAS * s;
            let (a, b) = if mu < nu_lo {
                let d0 = nu_lo - mu;
                (nu_lo, (mu + (d0 * d0 + reach * reach).sqrt()).min(nu_hi))
            } else if mu > nu_hi {
                let d0 = mu - nu_hi;
                ((mu - (d0 * d0 + reach * reach).sqrt()).max(nu_lo), nu_hi)
            } else {
                ((mu - reach).max(nu_lo), (mu + reach).min(nu_hi))
            };
            if !(s <= RGB_BROAD_SIGMA) {
                if n_broad < broad.len() {
                    broad[n_broad] = n;
                    n_broad += 1;
                } else {
                    broad_overflow = true;
                }
                continue;
            }
            // A given power (a rigorous efficiency) has kinks in wavelength
            // where another order meets the horizon, which a quadratic fit
            // of a peak wider than a few nm misses: a midpoint rule over
            // the peak's significant part instead.
            if let OrderWeights::Given { power, .. } = weights {
                if s > GIVEN_FIT_SIGMA && b > a {
                    let nodes = ((b - a) / GIVEN_PEAK_SPACING)
                        .ceil()
                        .clamp(GIVEN_PEAK_NODES.0, GIVEN_PEAK_NODES.1)
                        as usize;
                    let h = (b - a) / nodes as f64;
                    let scale = c_const * fast_exp(-a_n) * h;
                    for j in 0..nodes {
                        let nu = a + (j as f64 + 0.5) * h;
                        let g = fast_exp(-0.5 * ((nu - mu) / s).powi(2));
                        let val = scale * g * power(n, 1000.0 / nu) * nu * nu;
                        let weight = spectrum::srgb_weight_per_wavenumber(nu);
                        for (o, w) in out.iter_mut().zip(weight) {
                            *o += val * w;
                        }
                    }
                    continue;
                }
            }
            // Quadratic fit of S(nu) = R nu^2 |c_n(2 pi nu w)|^2 at c, c +- delta
            // (Gauss-Hermite nodes mu +- sqrt(3) s for a peak inside the band).
            let delta = (3.0f64.sqrt() * s).min(0.5 * (b - a)).max(1e-9);
            let c = mu.clamp(a + delta, b - delta);
            let s2 = self.rect_s2_three(2.0 * PI * c * w, 2.0 * PI * delta * w);
            let s_at = |nu: f64, s2: f64| -> f64 {
                match weights {
                    OrderWeights::Kirchhoff { reflectance, .. } => {
                        let beta = 2.0 * PI * nu * w;
                        let p = self.power_fast(n, beta, s2);
                        reflectance(1000.0 / nu) * nu * nu * p
                    }
                    OrderWeights::Given { power, .. } => power(n, 1000.0 / nu) * nu * nu,
                }
            };
            let sm = s_at(c - delta, s2[0]);
            let s0 = s_at(c, s2[1]);
            let sp = s_at(c + delta, s2[2]);
            let d1 = (sp - sm) / (2.0 * delta);
            let d2 = (sp - 2.0 * s0 + sm) / (2.0 * delta * delta);
            let e = c - mu;
            let a0 = s0 - d1 * e + d2 * e * e;
            let a1 = d1 - 2.0 * d2 * e;
            let a2 = d2;
            let m = peak_moments(mu, s, nu_lo, nu_hi);
            let scale = c_const * fast_exp(-a_n);
            for (ch, o) in out.iter_mut().enumerate() {
                *o += scale * (a0 * m[0][ch] + a1 * m[1][ch] + a2 * m[2][ch]);
            }
        }
        if n_broad > 0 || broad_overflow {
            let orders = (!broad_overflow).then_some(&broad[..n_broad]);
            match weights {
                OrderWeights::Kirchhoff {
                    node_reflectance, ..
                } => {
                    let rule = spectrum::smooth_rule(RGB_SMOOTH_NODES);
                    let sums = self.broad_sums(&rule.nu_per_um, u, v, w, orders);
                    for (j, (&nu, sum)) in rule.nu_per_um.iter().zip(sums).enumerate() {
                        let val = node_reflectance(j) * nu * nu * c_const * sum;
                        for (o, wt) in out.iter_mut().zip(rule.weights[j]) {
                            *o += wt * val;
                        }
                    }
                }
                // Rigorous efficiencies have kinks in wavelength (an order
                // appearing at the horizon): a finer rule (order 0 at the
                // mirror of (45, 180) deg on the disc, against a 0.25 nm
                // reference: 32 nodes 4.0e-2, 64 2.6e-2, 96 5.6e-3).
                OrderWeights::Given { at_node, .. } => {
                    let rule = spectrum::smooth_rule(GIVEN_BROAD_NODES);
                    for (j, &nu) in rule.nu_per_um.iter().enumerate() {
                        let power = |n| at_node(n, j);
                        let sum = self.node_sum(2.0 * PI * nu, u, v, orders, power);
                        let val = nu * nu * c_const * sum;
                        for (o, wt) in out.iter_mut().zip(rule.weights[j]) {
                            *o += wt * val;
                        }
                    }
                }
            }
        }
        for o in out.iter_mut() {
            if !o.is_finite() {
                *o = 0.0;
            }
        }
        out
    }

    /// Per node nu of the broad-peak rule, sum over `orders` (None: every
    /// order the spectral kernel would take at that node) of |c_n|^2
    /// exp(-E_n(nu)). For rectangular profiles, whose |c_n|^2 is linear in
    /// sin^2(beta h / 2), the loop over the nodes has no branches and no
    /// library calls and vectorises: this is most of an RGB evaluation near
    /// a grating's mirror direction.
    pub(super) fn broad_sums(
        &self,
        nu_per_um: &[f64],
        u: f64,
        v: f64,
        w: f64,
        orders: Option<&[i64]>,
    ) -> [f64; RGB_SMOOTH_NODES] {
        let mut sums = [0.0; RGB_SMOOTH_NODES];
        let l = self.coherence_um;
        let g = 2.0 * PI / self.period_um;
        if let (
            Model::Rect {
                height_um,
                fill,
                sinc2,
            },
            Some(orders),
            Some(nu),
        ) = (
            &self.model,
            orders,
            nu_per_um.first_chunk::<RGB_SMOOTH_NODES>(),
        ) {
            // Below exp(-700) a term is dropped (fast_exp_vectorisable does
            // not underflow to 0 by itself).
            const EXP_FLOOR: f64 = 700.0;
            let s2: [f64; RGB_SMOOTH_NODES] =
                std::array::from_fn(|j| sin_squared(PI * height_um * w * nu[j]));
            let lk: [f64; RGB_SMOOTH_NODES] = std::array::from_fn(|j| 2.0 * PI * l * nu[j]);
            for &n in orders {
                let (c0, c1) = rect_power_coefficients(n, *fill, sinc2);
                let lg = l * g * n as f64;
                for j in 0..RGB_SMOOTH_NODES {
                    let d = lk[j].mul_add(u, -lg);
                    let ev = lk[j] * v;
                    let e = d.mul_add(d, ev * ev);
                    let power = c1.mul_add(s2[j], c0).max(0.0);
                    let term = power * fast_exp_vectorisable(-e);
                    sums[j] += if e < EXP_FLOOR { term } else { 0.0 };
                }
            }
            return sums;
        }
        for (sum, &nu) in sums.iter_mut().zip(nu_per_um) {
            let k = 2.0 * PI * nu;
            let beta = k * w;
            let s2 = self.rect_s2(beta);
            *sum = self.node_sum(k, u, v, orders, |n| self.power_fast(n, beta, s2));
        }
        sums
    }

    /// The broad-peak rule's sum at one node (wavenumber k): over `orders`,
    /// or, where there were more broad orders than slots (None), every
    /// order the spectral kernel would take at that node (the peak width
    /// does not depend on n, so none of them is narrow).
    fn node_sum(
        &self,
        k: f64,
        u: f64,
        v: f64,
        orders: Option<&[i64]>,
        power: impl Fn(i64) -> f64,
    ) -> f64 {
        match orders {
            Some(orders) => self.order_sum(k, u, v, orders.iter().copied(), power),
            None => {
                let (lo, hi) = self.orders_near(k, u);
                self.order_sum(k, u, v, lo..=hi, power)
            }
        }
    }
}

/// What weighs each order's Gaussian in the RGB integration
/// (`PeriodicSurface::kernel_rgb_general`).
#[derive(Clone, Copy)]
pub(crate) enum OrderWeights<'a> {
    /// Stam's: F^2(lambda) |c_n(k w)|^2 / w^2, F^2 at any wavelength and at
    /// the broad rule's nodes (which a caller may tabulate).
    Kirchhoff {
        reflectance: &'a dyn Fn(f64) -> f64,
        node_reflectance: &'a dyn Fn(usize) -> f64,
    },
    /// f's own weight of order n (rigorous.rs): power(n, lambda_nm), and
    /// at_node(n, j) = power(n, lambda_j) at the nodes of the broad rule
    /// (`given_broad_wavelengths`), which a caller may tabulate.
    Given {
        power: &'a dyn Fn(i64, f64) -> f64,
        at_node: &'a dyn Fn(i64, usize) -> f64,
    },
}

/// Gaussian moments of the sRGB weight for one peak. Peaks narrower than a
/// quarter of a 1 nm cell of the weight table (in wavenumber, mu^2 / 1000)
/// and inside the band use the 3-point Gauss-Hermite rule (nodes mu and
/// mu +- sqrt(3) s) on the weight itself: exact for a weight that is a
/// quintic across the peak, and off by at most ~0.11 s |slope jump| where
/// the piecewise-linear weight has a kink under the peak (below 2e-3 of M0
/// for D65's 1 nm structure at this width). This avoids the per-cell erf
/// integration of `spectrum::gaussian_moments` (several hundred ns) for the
/// many narrow peaks of long coherence lengths. Everything else goes to
/// `spectrum::gaussian_moments`.
fn peak_moments(mu: f64, s: f64, nu_lo: f64, nu_hi: f64) -> [[f64; 3]; 3] {
    let narrow = s <= 0.25e-3 * mu * mu && mu - 8.0 * s > nu_lo && mu + 8.0 * s < nu_hi;
    if !narrow {
        return spectrum::gaussian_moments(mu, s);
    }
    let r = 3.0f64.sqrt() * s;
    let w0 = spectrum::srgb_weight_per_wavenumber(mu);
    let wp = spectrum::srgb_weight_per_wavenumber(mu + r);
    let wm = spectrum::srgb_weight_per_wavenumber(mu - r);
    let norm = (2.0 * PI).sqrt() * s;
    let mut m = [[0.0; 3]; 3];
    for c in 0..3 {
        m[0][c] = norm * (2.0 / 3.0 * w0[c] + (wp[c] + wm[c]) / 6.0);
        m[1][c] = norm * r / 6.0 * (wp[c] - wm[c]);
        m[2][c] = norm * s * s * 0.5 * (wp[c] + wm[c]);
    }
    m
}

/// Orders n whose peak can touch the band [nu_lo, nu_hi] (in wavenumber) for
/// a given u: n / Lam within sqrt(RGB_TAIL_EXPONENT) / (2 pi l) of
/// [u nu_lo, u nu_hi].
fn orders_in_band(u: f64, lam: f64, l: f64, nu_lo: f64, nu_hi: f64) -> (i64, i64) {
    let slack = RGB_TAIL_EXPONENT.sqrt() / (2.0 * PI * l);
    let (x0, x1) = if u >= 0.0 {
        (u * nu_lo, u * nu_hi)
    } else {
        (u * nu_hi, u * nu_lo)
    };
    let lo = ((x0 - slack) * lam).ceil();
    let hi = ((x1 + slack) * lam).floor();
    if !(lo.is_finite() && hi.is_finite()) || hi - lo > 1e6 {
        return (1, 0);
    }
    (lo as i64, hi as i64)
}

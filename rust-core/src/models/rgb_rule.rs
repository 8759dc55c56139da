//! The RGB rule of spectrally smooth kernels (Gaussian, fractal, the
//! coherent lobe), shared by the models that use it.

use crate::optics::fresnel::Fresnel;
use crate::program::{lookup, Builder, Value};
use crate::spectrum::{self, SmoothRule};
use std::f64::consts::PI;

/// Largest node count of the rule.
pub const MAX_RGB_NODES: usize = 64;

/// Cosine bins of the Fresnel-weighted RGB rule.
const FRESNEL_COS_BINS: usize = 256;

/// The RGB path for kernels smooth in wavelength (Gaussian, fractal, the
/// coherent lobe): f_c = sum_j K(nu_j) w_jc(cos). A metal's Fresnel spectrum
/// is not smooth enough to interpolate from a dozen nodes, so it is folded
/// into the weights instead: w_jc(cos) integrates the rule's basis against
/// F^2(cos, lambda) W_c(lambda) on the 1 nm grid, tabulated over the cosine
/// and interpolated linearly. Wavelength-independent Fresnel keeps the plain
/// weights (no table).
pub struct RgbRule {
    rule: &'static SmoothRule,
    /// Wavenumbers of the nodes (1/um) and their logarithms.
    pub k_per_um: Vec<f64>,
    pub ln_k_per_um: Vec<f64>,
    /// (FRESNEL_COS_BINS + 1) rows of one weight triple per node; empty when
    /// the Fresnel term does not depend on wavelength.
    fresnel_weights: Vec<[f64; 3]>,
}

impl RgbRule {
    /// The rule of `node_count` nodes with `fresnel` folded in (0 nodes:
    /// an empty rule, for models that integrate their spectrum themselves).
    pub fn new(node_count: usize, fresnel: &Fresnel) -> RgbRule {
        if node_count == 0 {
            return RgbRule {
                rule: spectrum::smooth_rule(1),
                k_per_um: Vec::new(),
                ln_k_per_um: Vec::new(),
                fresnel_weights: Vec::new(),
            };
        }
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

    /// The node wavelengths (nm).
    pub fn lambda_nm(&self) -> &[f64] {
        &self.rule.lambda_nm[..self.len()]
    }

    pub fn is_empty(&self) -> bool {
        self.k_per_um.is_empty()
    }

    pub fn len(&self) -> usize {
        self.k_per_um.len()
    }

    pub fn memory_bytes(&self) -> usize {
        self.k_per_um.len() * 8 + self.fresnel_weights.len() * 24
    }

    /// The rule's weights with F^2 folded in, as the JIT export hands them
    /// out (docs/jit.md): `FRESNEL_COS_BINS` + 1 rows (cos = b / bins) of
    /// one triple per node, linear in cos between rows; for a wavelength-flat
    /// Fresnel term, the plain weights times F^2 at the row's cosine (where
    /// `integrate` takes F^2 at the exact cosine). Returns (bins, rows).
    pub fn export_weights(&self, fresnel: &Fresnel) -> (usize, Vec<[f64; 3]>) {
        if !self.fresnel_weights.is_empty() {
            return (FRESNEL_COS_BINS, self.fresnel_weights.clone());
        }
        let rows = (0..=FRESNEL_COS_BINS)
            .flat_map(|b| {
                let r = fresnel.reflectance(b as f64 / FRESNEL_COS_BINS as f64, 550.0);
                self.rule.weights[..self.len()]
                    .iter()
                    .map(move |w| w.map(|c| c * r))
            })
            .collect();
        (FRESNEL_COS_BINS, rows)
    }

    /// sum_j values[j] F^2(cos, lambda_j) w_jc, with F^2 folded as above.
    #[inline]
    pub fn integrate(&self, fresnel: &Fresnel, cos: f64, values: &[f64]) -> [f64; 3] {
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

    /// `integrate` as program operations: sum_j values[j] w_jc(cos) with
    /// F^2 folded in as there (a wavelength-flat Fresnel term at the exact
    /// cosine times the plain weights; otherwise the folded weights, linear
    /// between the cosine rows).
    pub fn integrate_program<'a>(
        &self,
        b: &'a Builder,
        fresnel: &Fresnel,
        cos: Value<'a>,
        values: &[Value<'a>],
    ) -> [Value<'a>; 3] {
        let n = self.len();
        let acc = |weight: &dyn Fn(usize, usize) -> Value<'a>| -> [Value<'a>; 3] {
            std::array::from_fn(|c| {
                lookup::sum(b, values.iter().enumerate().map(|(j, &v)| v * weight(j, c)))
            })
        };
        if self.fresnel_weights.is_empty() {
            let r = fresnel.program(b, cos, b.c(550.0));
            let w = &self.rule.weights;
            return acc(&|j, c| b.c(w[j][c])).map(|a| a * r);
        }
        let table = b.table(
            self.fresnel_weights
                .iter()
                .flat_map(|w| w.map(|c| c as f32))
                .collect(),
        );
        let cos = cos.finite().select(cos, 0.0);
        let t = cos.clamp(0.0, 1.0) * FRESNEL_COS_BINS as f64;
        let row = t.floor().min((FRESNEL_COS_BINS - 1) as f64);
        let frac = t - row;
        let base = row * (3 * n) as f64;
        acc(&|j, c| {
            let at = base + (3 * j + c) as f64;
            let w0 = b.gather(table, at);
            let w1 = b.gather(table, at + (3 * n) as f64);
            w0 + (w1 - w0) * frac
        })
    }
}

//! The Gaussian model's RGB program (see program.rs): the per-material
//! table over the pair variables (ln g0, rho0) and the rule that reads it,
//! and the Fresnel-weighted RGB rule in low-rank form for anisotropic metals.

use super::program::bicubic;
use super::rgb::{column_limits, node_samples, D_U, D_V, MAP_R};
use super::series::{prefilter_2d, SPLINE_MARGIN};
use super::GaussianSurface;
use crate::models::{RgbRule, Shading};
use crate::optics::fresnel::Fresnel;
use crate::optics::program::PairProgram;
use crate::program::lookup::{bspline_weights, low_rank};
use crate::program::{Builder, Value};
use std::f64::consts::PI;

/// g at the bluest node of the RGB program table's lowest row: below it the
/// first term of the series carries all but ~g e^(x/2) / 4 of S (5e-6 at
/// S = e^-12 of its peak), so the rows below repeat the lowest one (ln(S /
/// g0) constant).
const RGB_G_LO: f64 = 2e-8;
/// Columns of the RGB program table reach where ln S of every node is below
/// this: beyond it f is below f32's range whatever G and 1/w^2 are.
const RGB_CUT: f64 = -250.0;
/// Largest RGB program table (bytes; 8M values, which an f32 index
/// addresses exactly). Anisotropic metals with many RGB nodes and long
/// correlation lengths take the per-node layout: the stress run's took
/// 9.5-16.2 MB, above the 8 MB this was before (they had no RGB program).
const RGB_MAX_BYTES: usize = 32 << 20;

/// The RGB program's per-material table (see the module documentation).
pub(crate) struct RgbProgramTable {
    /// Values per grid point: 4 (ln N - ln g0 and the three channels over
    /// N), 7 folded (and the channels' derivatives along the half-vector
    /// cosine) or one per node (ln(k_j^2 S_j) - ln g0).
    pub(super) values: usize,
    /// The grid holds the rule's sum (else the nodes).
    pub(super) combined: bool,
    /// Channels hold the Fresnel-weighted rule (else the plain weights, to
    /// be multiplied by F^2 at the pair's cosine); unused per node.
    pub(super) folded: bool,
    /// The correlation length and sigma the folded channels' cosine was
    /// computed with (cos_h^2 = x0 / T^2 + g0 / (4 sigma^2)).
    pub(super) corr_um: f64,
    pub(super) sigma_um: f64,
    /// B0 of the folded channels: the program adds `cone_term`(cos_h) B0.
    pub(super) cos_slope: [f64; 3],
    ln_g0_lo: f64,
    pub(super) rows: usize,
    pub(super) cols: usize,
    inv_k_ref2: f64,
    pub(super) row_len: usize,
    pub(super) coef: Vec<f32>,
}

impl RgbProgramTable {
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<RgbProgramTable>() + self.coef.len() * 4
    }

    /// The table of `surface` for `rule` and `fresnel`; `per_node` forces the
    /// per-node layout (tests). `sigma_um_max` (a sigma texture's largest
    /// value): the table serves every sigma up to it (its rows are in g0 =
    /// (sigma w)^2 and its columns in rho, both universal; only the folded
    /// layout depends on the build's sigma, so it is not used then). None
    /// when the rule is empty or the table would not fit RGB_MAX_BYTES.
    pub(super) fn build(
        surface: &GaussianSurface,
        rule: &RgbRule,
        fresnel: &Fresnel,
        per_node: bool,
        sigma_um_max: Option<f64>,
    ) -> Option<RgbProgramTable> {
        let n = rule.len();
        let k = &rule.k_per_um;
        let sigma = surface.sigma_um;
        if n == 0 || !(sigma > 0.0 && surface.corr_x_um > 0.0 && surface.corr_y_um > 0.0) {
            return None;
        }
        let k_min = k.iter().cloned().fold(f64::INFINITY, f64::min);
        let k_max = k.iter().cloned().fold(0.0, f64::max);
        let k_ref2 = k_min * k_max;
        let flat = fresnel.is_spectrally_flat();
        let combined = !per_node && (flat || (surface.isotropic && sigma_um_max.is_none()));
        let folded = combined && !flat;
        let sigma_rows = sigma_um_max.unwrap_or(sigma).max(sigma);
        let values = match (combined, folded) {
            (true, true) => 7,
            (true, false) => 4,
            _ => n,
        };
        // |w| <= 2, so g0 <= 4 sigma^2; down to g = RGB_G_LO at the bluest
        // node, and at least 8 rows.
        let ln_g0_hi = (4.0 * sigma_rows * sigma_rows).ln();
        let ln_g0_lo = (RGB_G_LO / (k_max * k_max)).ln().min(ln_g0_hi - 8.0 * D_U);
        let rows = ((ln_g0_hi - ln_g0_lo) / D_U).ceil() as usize + 2;
        let limits = column_limits(surface, k, ln_g0_lo, rows, k_ref2, RGB_CUT);
        let v_max = limits.iter().cloned().fold(0.0, f64::max);
        let cols = (v_max.ceil() as usize + 2).max(4);
        if 4 * values * (rows + 2) * (cols + 2) > RGB_MAX_BYTES {
            return None;
        }
        let samples = node_samples(surface, k, ln_g0_lo, rows, cols, k_ref2, n);
        let m = SPLINE_MARGIN;
        let (ext_rows, ext_cols) = (rows + 2 * m, cols + 2 * m);
        let mut grid = vec![0.0; ext_rows * ext_cols * values];
        // The plain rule (F = 1) and the positive node weights of N.
        let plain = RgbRule::new(n, &Fresnel::Constant(1.0));
        let one = Fresnel::Constant(1.0);
        let ln_m: Vec<f64> = (0..n)
            .map(|j| {
                let mut e = vec![0.0; n];
                e[j] = 1.0;
                let w = plain.integrate(&one, 1.0, &e);
                (w[0].abs() + w[1].abs() + w[2].abs()).max(1e-12).ln()
            })
            .collect();
        // The folded weights are linear in cos near 0, and cos_h = sqrt(x0 /
        // T^2 + g0 / (4 sigma^2)) has a cone's point at the grid's bottom
        // left (both directions grazing, near the mirror), which a spline
        // cannot follow: the table holds the channels less `cone_term`(cos_h)
        // B0, the program adds it back. B0 is the weights' slope at cos 0 for
        // the spectrum there (g << 1, x0 -> 0: K_j ~ k_j^4), so what is left
        // is even in cos_h near the point (up to a cos^3 term).
        let cos_slope = if folded {
            let ln_n0 = k
                .iter()
                .zip(&ln_m)
                .map(|(k, w)| (4.0 * k.ln() + w).exp())
                .sum::<f64>()
                .ln();
            let rel0: Vec<f64> = k.iter().map(|k| (4.0 * k.ln() - ln_n0).exp()).collect();
            let (at0, at1) = (
                rule.integrate(fresnel, 0.0, &rel0),
                rule.integrate(fresnel, 1.0 / 256.0, &rel0),
            );
            std::array::from_fn(|c| (at1[c] - at0[c]) * 256.0)
        } else {
            [0.0; 3]
        };
        let (t2, sigma2) = (surface.corr_x_um * surface.corr_x_um, sigma * sigma);
        // The folded channels at cosine `cos` for the nodes' shares `rel`,
        // less `cone_term`(cos) B0. Past 1 (outside the pairs, inside the
        // splines' reach) the weights continue as w(1 - d) + 2 d w'(1),
        // which keeps their first two derivatives at 1 (a kink or a jump of
        // curvature there costs 1e-3 at the rows of w ~ 2), with d
        // saturating smoothly below 0.5.
        let fold_at = |cos: f64, rel: &[f64]| -> [f64; 3] {
            let at = |c: f64| rule.integrate(fresnel, c, rel);
            let folded: [f64; 3] = if cos <= 1.0 {
                at(cos)
            } else {
                let d = 0.5 * ((cos - 1.0) / 0.5).tanh();
                let h = 1.0 / 256.0;
                let (w0, w1, w2) = (at(1.0), at(1.0 - h), at(1.0 - 2.0 * h));
                let back = at(1.0 - d);
                let slope: [f64; 3] =
                    std::array::from_fn(|i| (3.0 * w0[i] - 4.0 * w1[i] + w2[i]) / (2.0 * h));
                std::array::from_fn(|i| back[i] + 2.0 * d * slope[i])
            };
            let cone = cone_term(cos);
            std::array::from_fn(|i| folded[i] - cone * cos_slope[i])
        };
        let mut rel = vec![0.0; n];
        for r in 0..ext_rows {
            let ln_g0 = ln_g0_lo + (r as f64 - m as f64) * D_U;
            let g0 = ln_g0.exp();
            for c in 0..ext_cols {
                let point = &samples[(r * ext_cols + c) * n..][..n];
                let out = &mut grid[(r * ext_cols + c) * values..][..values];
                if !combined {
                    for (o, &l) in out.iter_mut().zip(point) {
                        *o = l - ln_g0;
                    }
                    continue;
                }
                let top = point
                    .iter()
                    .zip(&ln_m)
                    .map(|(l, w)| l + w)
                    .fold(f64::NEG_INFINITY, f64::max);
                let total: f64 = point
                    .iter()
                    .zip(&ln_m)
                    .map(|(l, w)| (l + w - top).exp())
                    .sum();
                let ln_n = top + total.ln();
                for (o, &l) in rel.iter_mut().zip(point) {
                    *o = (l - ln_n).exp();
                }
                if folded {
                    // cos_h^2 = (u^2 + v^2 + w^2) / 4 = x0 / T^2 + g0 / (4
                    // sigma^2): the channels at this cosine, and their
                    // derivative along it, with which the program follows
                    // the cosine where the parameters it reads differ from
                    // the ones the table was built with.
                    let vv = (c as f64 - m as f64).abs() * D_V;
                    let x0 = rho2_at(vv) * (1.0 / k_ref2 + g0);
                    let cos = (x0 / t2 + g0 / (4.0 * sigma2)).sqrt();
                    let at = |c: f64| fold_at(c, &rel);
                    let h = 1.0 / 256.0;
                    let (lo, hi) = ((cos - h).max(0.0), cos + h);
                    let (a, z) = (at(lo), at(hi));
                    out[1..4].copy_from_slice(&at(cos));
                    for i in 0..3 {
                        out[4 + i] = (z[i] - a[i]) / (hi - lo);
                    }
                } else {
                    out[1..4].copy_from_slice(&plain.integrate(&one, 1.0, &rel));
                }
                out[0] = ln_n - ln_g0;
            }
        }
        prefilter_2d(&mut grid, ext_rows, ext_cols, values);
        // One coefficient beyond each end of the rows and columns.
        let row_len = (cols + 2) * values;
        let mut coef = Vec::with_capacity((rows + 2) * row_len);
        for r in m - 1..m + rows + 1 {
            let src = &grid[(r * ext_cols + m - 1) * values..][..row_len];
            coef.extend(src.iter().map(|&v| v as f32));
        }
        Some(RgbProgramTable {
            values,
            combined,
            folded,
            corr_um: surface.corr_x_um,
            sigma_um: sigma,
            cos_slope,
            ln_g0_lo,
            rows,
            cols,
            inv_k_ref2: 1.0 / k_ref2,
            row_len,
            coef,
        })
    }
}

/// cos e^(-4 cos^2): cos near the cone's point (cos = 0), nothing at the
/// rows of w ~ 2 (whose neighbours beyond cos = 1 only the table's splines
/// see), smooth everywhere.
fn cone_term(cos: f64) -> f64 {
    cos * (-4.0 * cos * cos).exp()
}

/// rho0^2 at column coordinate vv = v D_V (`rgb.rs`'s map, inverted).
fn rho2_at(vv: f64) -> f64 {
    let v4 = vv * vv * vv * vv;
    let a = v4 / (MAP_R * MAP_R);
    0.5 * (a + (a * a + 4.0 * v4).sqrt())
}

/// f / G in linear sRGB from the RGB program table.
pub(crate) fn rgb_from_table<'a>(
    b: &'a Builder,
    t: &RgbProgramTable,
    s: &GaussianSurface,
    shading: &Shading,
    pair: &PairProgram<'a>,
) -> [Value<'a>; 3] {
    let table = b.table(t.coef.clone());
    let (sigma, tx, ty) = s.params_program(b);
    let sw = (pair.w * sigma).abs();
    let g0 = sw * sw;
    let ln_g0 = sw.ln() * 2.0;
    let x0 = pair.u * pair.u * (tx * tx * 0.25) + pair.v * pair.v * (ty * ty * 0.25);
    // Rows: below the lowest the values repeat it (ln(S / g0) constant).
    // Their range is the material's: built values, so that materials whose
    // tables differ only in rows share the program's code.
    let fu = ((ln_g0 - b.built(t.ln_g0_lo)) * (1.0 / D_U)).clamp(0.0, b.built((t.rows - 1) as f64));
    let iu = fu.floor().min(b.built((t.rows - 2) as f64));
    let rho2 = x0 / (g0 + t.inv_k_ref2);
    let fv = (rho2 / (rho2 * (1.0 / (MAP_R * MAP_R)) + 1.0).sqrt()).sqrt() * (1.0 / D_V);
    let inside = fv.lt((t.cols - 1) as f64);
    let fv = fv.min((t.cols - 1) as f64);
    let iv = fv.floor().min((t.cols - 2) as f64);
    let base = iu * t.row_len as f64 + iv * t.values as f64;
    let wu = bspline_weights(fu - iu);
    let wv = bspline_weights(fv - iv);
    // At the built parameters the pair's cosine is the table point's: the
    // derivative channels (the last three of a folded point) are not read.
    let lean = t.folded && b.at_built();
    let count = if lean { 4 } else { t.values };
    let v = bicubic(b, table, base, t.row_len, t.values, count, wu, wv);
    // K_j = Tx Ty / (4 pi w^2) k_j^2 S_j = sigma^2 Tx Ty / (4 pi g0) k_j^2 S_j.
    let ln_scale = (sigma * sigma * tx * ty * (1.0 / (4.0 * PI))).ln();
    let rgb = if t.combined {
        let n = (v[0] + ln_scale).exp();
        if t.folded {
            let c = pair.cos_half;
            let cone = c * (c * c * -4.0).exp();
            // The cosine the table's point had at the parameters it was
            // built with; where the program's parameters differ, the
            // channels follow the pair's cosine to first order (not at the
            // built parameters, where the cosines are equal).
            let dc = (!lean).then(|| {
                let cos_table = (x0 * b.built(1.0 / (t.corr_um * t.corr_um))
                    + g0 * b.built(1.0 / (4.0 * t.sigma_um * t.sigma_um)))
                .sqrt();
                c - cos_table
            });
            std::array::from_fn(|i| {
                // The metal's slope: a built value (materials of other
                // metals share the code)
                let at_table = cone.fma(b.built(t.cos_slope[i]), v[1 + i]);
                match dc {
                    Some(dc) => dc.fma(v[4 + i], at_table) * n,
                    None => at_table * n,
                }
            })
        } else {
            let scale = n * shading.fresnel.program(b, pair.cos_half, b.c(550.0));
            [v[1] * scale, v[2] * scale, v[3] * scale]
        }
    } else {
        let kernel: Vec<Value> = v.iter().map(|&l| (l + ln_scale).exp()).collect();
        weighted_sum(b, shading, pair.cos_half, &kernel)
    };
    rgb.map(|c| inside.select(c, 0.0))
}

/// The RGB rule's Fresnel-weighted sum of `values` (the nodes') at `cos`,
/// as `RgbRule::integrate_program`. For a metal's folded weights w_jc(cos)
/// (257 cosine rows, linear between them) in their low-rank form: with the
/// rows' singular vectors, w_jc(cos) = sum_p phi_p(cos) A_pjc to 1e-6 of
/// the largest weight in P ~ 6 terms (the rows of every metal are nearly
/// combinations of a few cosine profiles), so the sum is sum_p phi_p(cos)
/// (sum_j values_j A_pjc): 2 P gathers of phi instead of 6 N of the
/// weights.
pub(crate) fn weighted_sum<'a>(
    b: &'a Builder,
    shading: &Shading,
    cos: Value<'a>,
    values: &[Value<'a>],
) -> [Value<'a>; 3] {
    let rule = shading.rgb_rule;
    let fresnel = shading.fresnel;
    if fresnel.is_spectrally_flat() {
        return rule.integrate_program(b, fresnel, cos, values);
    }
    let (bins, rows) = rule.export_weights(fresnel);
    let n = rule.len();
    let Some((phi, a)) = low_rank(rows.as_flattened(), bins + 1, 3 * n, 1e-6) else {
        return rule.integrate_program(b, fresnel, cos, values);
    };
    let rank = a.len();
    let table = b.table(phi.iter().map(|&v| v as f32).collect());
    let cos = cos.finite().select(cos, 0.0);
    let t = cos.clamp(0.0, 1.0) * bins as f64;
    let row = t.floor().min((bins - 1) as f64);
    let frac = t - row;
    let base = row * rank as f64;
    let profile: Vec<Value> = (0..rank)
        .map(|p| {
            let lo = b.gather(table, base + p as f64);
            let hi = b.gather(table, base + (rank + p) as f64);
            lo + (hi - lo) * frac
        })
        .collect();
    std::array::from_fn(|c| {
        let per_rank = (0..rank).map(|p| {
            let mut acc = values[0] * a[p][c];
            for (j, &v) in values.iter().enumerate().skip(1) {
                acc = v.fma(a[p][3 * j + c], acc);
            }
            acc * profile[p]
        });
        per_rank.reduce(|x, y| x + y).unwrap_or_else(|| b.c(0.0))
    })
}

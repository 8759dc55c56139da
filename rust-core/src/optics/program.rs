//! The optics of a direction pair as program operations (crate::program):
//! the same quantities as `geometry::PairGeometry` and the same Fresnel
//! lookups as `fresnel::Fresnel::reflectance`, for a renderer's traced
//! kernels. Knows no surface model.

use super::fresnel::{conductor_polarization, conductor_reflectance, metal_index, Fresnel};
use super::geometry::MIN_COS;
use crate::program::lookup::{self, catmull_rom_weights};
use crate::program::{Builder, Mask, ParamId, Value};

/// A direction as three registers.
pub type Vec3<'a> = [Value<'a>; 3];

/// `d` normalised, and whether it is a direction above the horizon (finite,
/// not zero, z > MIN_COS; as `normalize_direction` then the horizon test).
/// Where it is not, the direction is the normal (so that what follows stays
/// finite) and the mask false.
pub fn upper_direction<'a>(b: &'a Builder, d: Vec3<'a>) -> (Vec3<'a>, Mask<'a>) {
    let len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    let inv = 1.0 / len2.sqrt();
    let n = d.map(|c| c * inv);
    // Lengths below 1e-30 (f32: 1e-15 and a squared 1e-30) are zero.
    let ok = len2.gt(1e-30) & len2.finite() & n[2].gt(MIN_COS) & n[2].finite();
    let unit = [
        ok.select(n[0], 0.0),
        ok.select(n[1], 0.0),
        ok.select(n[2], 1.0),
    ];
    let _ = b;
    (unit, ok)
}

/// `geometry::PairGeometry` as registers.
pub struct PairProgram<'a> {
    pub wi: Vec3<'a>,
    pub wo: Vec3<'a>,
    /// u, v, w = -(wi + wo).
    pub u: Value<'a>,
    pub v: Value<'a>,
    pub w: Value<'a>,
    /// 1 + wi.wo, computed as (u^2 + v^2 + w^2) / 2: the same value, which
    /// the dot product loses in f32 near the grazing mirror.
    pub one_plus_dot: Value<'a>,
    pub geometric_factor: Value<'a>,
    pub cos_half: Value<'a>,
    /// Both directions above the horizon (else f = 0).
    pub valid: Mask<'a>,
}

impl<'a> PairProgram<'a> {
    pub fn new(b: &'a Builder, wi: Vec3<'a>, wo: Vec3<'a>) -> PairProgram<'a> {
        let (wi_unit, ok_i) = upper_direction(b, wi);
        let (wo_unit, ok_o) = upper_direction(b, wo);
        // -(wi + wo) from the vectors as given: per component inv_m (di +
        // do) + (inv_i - inv_o) (di - do) / 2 (inv = 1 / length, inv_m their
        // mean), with inv_i - inv_o from |di|^2 - |do|^2 = sum (di + do)(di -
        // do). Where the directions nearly cancel (both grazing, near the
        // mirror) di + do is exact and so is the result to f32 rounding,
        // while the sum of the normalised components would carry their
        // rounding (3e-8 each: 1e-4 of 1 + wi.wo at cos 1e-4).
        let raw = |d: Vec3<'a>, ok: Mask<'a>| {
            [
                ok.select(d[0], 0.0),
                ok.select(d[1], 0.0),
                ok.select(d[2], 1.0),
            ]
        };
        let (di, d_o) = (raw(wi, ok_i), raw(wo, ok_o));
        let inv = |d: Vec3<'a>| 1.0 / (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let (inv_i, inv_o) = (inv(di), inv(d_o));
        let sums: Vec3 = std::array::from_fn(|c| di[c] + d_o[c]);
        let diffs: Vec3 = std::array::from_fn(|c| di[c] - d_o[c]);
        let len2_diff = sums[0] * diffs[0] + sums[1] * diffs[1] + sums[2] * diffs[2];
        let inv_io = inv_i * inv_o;
        let half_delta = -(len2_diff * inv_io * inv_io) / ((inv_i + inv_o) * 2.0);
        let inv_mean = (inv_i + inv_o) * 0.5;
        let minus = |c: usize| -(sums[c].fma(inv_mean, diffs[c] * half_delta));
        let (u, v, w) = (minus(0), minus(1), minus(2));
        let (wi, wo) = (wi_unit, wo_unit);
        let one_plus_dot = (u * u + v * v + w * w) * 0.5;
        let geometric_factor = one_plus_dot * one_plus_dot / (wi[2] * wo[2]);
        let cos_half = (one_plus_dot * 0.5).max(0.0).sqrt();
        PairProgram {
            wi,
            wo,
            u,
            v,
            w,
            one_plus_dot,
            geometric_factor,
            cos_half,
            valid: ok_i & ok_o,
        }
    }
}

impl Fresnel {
    /// The reflectance at `cos` and `lambda_nm` as `reflectance` computes
    /// it: a constant; a complex index's formula; a metal's grid
    /// (Catmull-Rom over sqrt(cos), linear between wavelength rows). The
    /// constant and the complex index are the material's parameters
    /// (`Op::Param`: ParamId::Fresnel; ParamId::Eta and ParamId::K), which a
    /// renderer can differentiate; a measured metal's tables are not.
    pub fn program<'a>(&self, b: &'a Builder, cos: Value<'a>, lambda_nm: Value<'a>) -> Value<'a> {
        match self {
            Fresnel::Constant(r) => b.param(ParamId::Fresnel, *r),
            Fresnel::ComplexIndex { eta, k } => {
                let (eta, k) = (b.param(ParamId::Eta, *eta), b.param(ParamId::K, *k));
                conductor_reflectance(cos, eta, k)
            }
            Fresnel::Metal { .. } => self.grid_program(b, cos, lambda_nm),
        }
    }

    /// The polarisation (b, c, s) at `cos` and `lambda_nm` as
    /// `polarization` computes it (`conductor_polarization`, the same
    /// generic source): a complex index from the material's parameters
    /// (ParamId::Eta and ParamId::K); a measured metal's index, linear in
    /// wavelength, from its values at every whole nanometre of the band
    /// (the native path is linear between the measured wavelengths, which
    /// differ inside the nanometres that hold one); a constant reflectance,
    /// a perfect conductor's.
    pub fn polarization_program<'a>(
        &self,
        b: &'a Builder,
        cos: Value<'a>,
        lambda_nm: Value<'a>,
    ) -> [Value<'a>; 3] {
        match self {
            Fresnel::Constant(_) => [b.c(0.0), b.c(-1.0), b.c(0.0)],
            Fresnel::ComplexIndex { eta, k } => {
                let (eta, k) = (b.param(ParamId::Eta, *eta), b.param(ParamId::K, *k));
                conductor_polarization(cos, eta, k)
            }
            Fresnel::Metal { table, .. } => {
                let (lo, hi) = (
                    crate::spectrum::LAMBDA_MIN_NM,
                    crate::spectrum::LAMBDA_MAX_NM,
                );
                let n = (hi - lo).round() as usize + 1;
                let (etas, ks): (Vec<f32>, Vec<f32>) = (0..n)
                    .map(|i| {
                        let (eta, k) = metal_index(table, lo + i as f64);
                        (eta as f32, k as f32)
                    })
                    .unzip();
                let lambda = lambda_nm.finite().select(lambda_nm, lo);
                let tables = [(b.table(etas), 0), (b.table(ks), 0)];
                let [eta, k] = lookup::uniform_linear(b, tables, n, lo, 1.0, lambda);
                conductor_polarization(cos, eta, k)
            }
        }
    }

    fn grid_program<'a>(&self, b: &'a Builder, cos: Value<'a>, lambda_nm: Value<'a>) -> Value<'a> {
        let grid = self.export_grid((
            crate::spectrum::LAMBDA_MIN_NM,
            crate::spectrum::LAMBDA_MAX_NM,
        ));
        let steps = grid.rows[0].len() - 1;
        let n_rows = grid.rows.len();
        let rows = b.table(
            grid.rows
                .iter()
                .flat_map(|r| r.iter().map(|&v| v as f32))
                .collect(),
        );
        let xs = b.table(grid.lambda_nm.iter().map(|&v| v as f32).collect());
        let row_of_nm = b.table(grid.row_of_nm.iter().map(|&v| v as f32).collect());
        // Columns: Catmull-Rom at sqrt(cos), the end columns repeated.
        let cos = cos.finite().select(cos, 0.0);
        let q = cos.clamp(0.0, 1.0).sqrt() * steps as f64;
        let i = q.floor().min((steps - 1) as f64);
        let wts = catmull_rom_weights(q - i);
        let cols: Vec<Value> = (0..4)
            .map(|j| (i + (j as f64 - 1.0)).clamp(0.0, steps as f64))
            .collect();
        // Rows: the row of the whole nanometre, then the rows inside it.
        let x0 = grid.lambda_nm[0];
        let lam = lambda_nm.finite().select(lambda_nm, x0);
        let lam = lam.clamp(x0, grid.lambda_nm[n_rows - 1]);
        let mut r = b.gather(row_of_nm, (lam - x0).floor());
        for _ in 0..grid.max_row_steps() {
            let next = b.gather(xs, r + 1.0);
            r = ((r + 2.0).lt(n_rows as f64) & next.le(lam)).select(r + 1.0, r);
        }
        let row = |r: Value<'a>| {
            let base = r * (steps + 1) as f64;
            crate::program::lookup::sum(b, (0..4).map(|j| wts[j] * b.gather(rows, base + cols[j])))
        };
        let (x_lo, x_hi) = (b.gather(xs, r), b.gather(xs, r + 1.0));
        let t = ((lam - x_lo) / (x_hi - x_lo)).clamp(0.0, 1.0);
        let (lo, hi) = (row(r), row(r + 1.0));
        lo + (hi - lo) * t
    }
}

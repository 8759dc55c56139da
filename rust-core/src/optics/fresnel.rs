//! Fresnel reflectance F^2 of the mean surface, evaluated at the local
//! incidence angle of the specular microfacet (Kirchhoff): cos = wi . h.
//!
//! Three kinds: a constant reflectance, a constant complex index, or a
//! metal's measured spectral index (tabulated, linear in wavelength).

use super::metals::{MetalTable, METALS};
use crate::program::Real;
use std::ops::Sub;

#[derive(Clone)]
pub enum Fresnel {
    /// Reflectance F^2 independent of angle and wavelength, in (0, 1].
    Constant(f64),
    /// Conductor (or dielectric for k = 0) with a wavelength-independent
    /// complex index eta + i k.
    ComplexIndex { eta: f64, k: f64 },
    /// A metal with a measured spectral index, and its reflectance grid
    /// (built once per metal and process; None only for a table that is not
    /// one of the built-in metals). Made by `Fresnel::metal`.
    Metal {
        table: &'static MetalTable,
        grid: Option<&'static MetalGrid>,
    },
}

/// Names accepted for `fresnel`, in the order documented.
pub fn metal_names() -> Vec<&'static str> {
    METALS.iter().map(|m| m.name).collect()
}

pub fn metal_by_name(name: &str) -> Option<&'static MetalTable> {
    let wanted = match name {
        "aluminum" | "al" | "Al" => "aluminium",
        "ag" | "Ag" => "silver",
        "au" | "Au" => "gold",
        "cu" | "Cu" => "copper",
        "cr" | "Cr" => "chromium",
        other => other,
    };
    METALS.iter().find(|m| m.name == wanted)
}

impl std::fmt::Debug for Fresnel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fresnel::Constant(r) => write!(f, "Constant({r})"),
            Fresnel::ComplexIndex { eta, k } => write!(f, "ComplexIndex {{ eta: {eta}, k: {k} }}"),
            Fresnel::Metal { table, .. } => write!(f, "Metal({})", table.name),
        }
    }
}

impl PartialEq for Fresnel {
    fn eq(&self, other: &Fresnel) -> bool {
        match (self, other) {
            (Fresnel::Constant(a), Fresnel::Constant(b)) => a == b,
            (Fresnel::ComplexIndex { eta: a, k: b }, Fresnel::ComplexIndex { eta: c, k: d }) => {
                a == c && b == d
            }
            (Fresnel::Metal { table: a, .. }, Fresnel::Metal { table: b, .. }) => a.name == b.name,
            _ => false,
        }
    }
}

impl Fresnel {
    /// Reflectance at local incidence cosine `cos_theta` and wavelength.
    #[inline]
    pub fn reflectance(&self, cos_theta: f64, lambda_nm: f64) -> f64 {
        match self {
            Fresnel::Constant(r) => *r,
            Fresnel::ComplexIndex { eta, k } => conductor_reflectance(cos_theta, *eta, *k),
            Fresnel::Metal { table, grid } => match grid {
                Some(grid) => grid.reflectance(cos_theta, lambda_nm),
                None => metal_reflectance_exact(table, cos_theta, lambda_nm),
            },
        }
    }

    /// The polarisation of the reflection at local incidence cosine
    /// `cos_theta` and wavelength (`conductor_polarization`): (b, c, s) of
    /// its Mueller matrix over the unpolarised reflectance. A constant
    /// reflectance has no index: it reflects as a perfect conductor.
    pub fn polarization(&self, cos_theta: f64, lambda_nm: f64) -> [f64; 3] {
        match self {
            Fresnel::Constant(_) => [0.0, -1.0, 0.0],
            Fresnel::ComplexIndex { eta, k } => conductor_polarization(cos_theta, *eta, *k),
            Fresnel::Metal { table, .. } => {
                let (eta, k) = metal_index(table, lambda_nm);
                conductor_polarization(cos_theta, eta, k)
            }
        }
    }

    /// True when the reflectance does not depend on wavelength.
    pub fn is_spectrally_flat(&self) -> bool {
        !matches!(self, Fresnel::Metal { .. })
    }

    /// A measured metal, with its shared reflectance grid resolved here
    /// rather than on every evaluation.
    pub fn metal(table: &'static MetalTable) -> Fresnel {
        Fresnel::Metal {
            table,
            grid: metal_grid(table),
        }
    }
}

/// A metal's reflectance from its measured index, without the grid.
pub fn metal_reflectance_exact(table: &MetalTable, cos_theta: f64, lambda_nm: f64) -> f64 {
    let (eta, k) = metal_index(table, lambda_nm);
    conductor_reflectance(cos_theta, eta, k)
}

/// A metal's reflectance tabulated over the incidence cosine at wavelength
/// rows every nanometre plus one at each measured wavelength (where the
/// linearly interpolated index has kinks): linear in wavelength, Catmull-Rom
/// over 64 columns uniform in sqrt(cos). The renderer's hot paths (every
/// evaluation, each grating order) call it, and the direct form costs a
/// search of the measured wavelengths plus two square roots and two
/// divisions. A 1 nm index finds the bracketing measured wavelengths without
/// a search. Interpolation error below 2.5e-5 absolute (measured in the
/// tests). 140 kB per metal in use, shared by every material of that metal:
/// small enough to stay in cache during a render (the 512 linear columns of
/// an earlier version, 1.1 MB, made every lookup a cache miss there).
pub struct MetalGrid {
    lambda_nm: Vec<f64>,
    /// Row i: F at sqrt(cos) = 0, 1/GRID_COS_STEPS, ..., 1 for lambda_nm[i],
    /// stored from index 1 with the end columns repeated once before and
    /// twice after, so that a Catmull-Rom stencil is four contiguous values.
    rows: Vec<[f32; GRID_ROW]>,
    /// For each whole nanometre from the first row: the index of the last
    /// row at or below it.
    row_of_nm: Vec<u16>,
}

const GRID_COS_STEPS: usize = 64;
/// Stored values per row: the GRID_COS_STEPS + 1 columns and 3 of padding.
const GRID_ROW: usize = GRID_COS_STEPS + 4;

impl MetalGrid {
    fn build(table: &'static MetalTable) -> MetalGrid {
        let (first, end) = (
            table.lambda_nm[0],
            table.lambda_nm[table.lambda_nm.len() - 1],
        );
        let mut xs: Vec<f64> = table.lambda_nm.to_vec();
        let mut lambda = first;
        while lambda < end {
            xs.push(lambda);
            lambda += 1.0;
        }
        xs.sort_by(f64::total_cmp);
        xs.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
        let rows = xs.iter().map(|&lambda| grid_row(table, lambda)).collect();
        let first = xs[0];
        let span = (xs[xs.len() - 1] - first).ceil() as usize;
        let row_of_nm = (0..=span)
            .map(|d| {
                let lambda = first + d as f64;
                (xs.partition_point(|&x| x <= lambda).clamp(1, xs.len() - 1) - 1) as u16
            })
            .collect();
        MetalGrid {
            lambda_nm: xs,
            rows,
            row_of_nm,
        }
    }

    #[inline]
    pub fn reflectance(&self, cos_theta: f64, lambda_nm: f64) -> f64 {
        let columns = GridColumns::new(cos_theta);
        let (interval, lo, hi) = self.row_pair(&columns, lambda_nm);
        interval.lerp(lo, hi, lambda_nm)
    }

    /// The rows bracketing lambda_nm (clamped at the table ends; NaN to the
    /// first: callers zero it) and F of both at the columns' cosine.
    #[inline]
    fn row_pair(&self, columns: &GridColumns, lambda_nm: f64) -> (Interval, f64, f64) {
        let xs = &self.lambda_nm;
        let last = xs.len() - 1;
        let lambda = if lambda_nm >= xs[0] {
            lambda_nm.min(xs[last])
        } else {
            xs[0]
        };
        let mut r =
            self.row_of_nm[((lambda - xs[0]) as usize).min(self.row_of_nm.len() - 1)] as usize;
        while r + 1 < last && xs[r + 1] <= lambda {
            r += 1;
        }
        let interval = Interval {
            lo_nm: xs[r],
            hi_nm: xs[r + 1],
        };
        (
            interval,
            columns.apply(&self.rows[r]),
            columns.apply(&self.rows[r + 1]),
        )
    }
}

/// A Fresnel term as a reflectance grid (`Fresnel::export_grid`), in the
/// layout the JIT export (docs/jit.md) hands to renderers: rows at
/// increasing wavelengths, each F at sqrt(cos) = 0, 1/`EXPORT_COS_STEPS`,
/// ..., 1 (Catmull-Rom over the columns with the end columns repeated,
/// linear between rows), and for each whole nanometre from the first row
/// the index of the last row at or below it.
pub struct FresnelGridExport {
    pub lambda_nm: Vec<f64>,
    pub rows: Vec<[f64; EXPORT_COS_STEPS + 1]>,
    pub row_of_nm: Vec<u16>,
}

/// Column intervals of an exported Fresnel row (the grid's).
pub const EXPORT_COS_STEPS: usize = GRID_COS_STEPS;

impl FresnelGridExport {
    /// The most rows past `row_of_nm` that a lookup steps over (the
    /// rows at measured wavelengths inside one nanometre).
    pub fn max_row_steps(&self) -> usize {
        let xs = &self.lambda_nm;
        let mut most = 0;
        for (d, &r) in self.row_of_nm.iter().enumerate() {
            // The largest wavelength mapped to this entry.
            let top = (xs[0] + d as f64 + 1.0).min(xs[xs.len() - 1]);
            let mut r = r as usize;
            let mut steps = 0;
            while r + 2 < xs.len() && xs[r + 1] <= top {
                r += 1;
                steps += 1;
            }
            most = most.max(steps);
        }
        most
    }
}

impl Fresnel {
    /// This Fresnel term as a grid: a metal's own grid exactly (the one
    /// `reflectance` reads); a constant reflectance as two equal rows at
    /// 360 and 830 nm (exact); a constant complex index as two rows of its
    /// reflectance at the columns' cosines (Catmull-Rom between them: below
    /// 2.5e-5 absolute, as the metals' grids).
    /// `band` is the wavelength range (nm) the rows of a term without a
    /// grid cover (every whole nanometre when it varies with wavelength).
    pub fn export_grid(&self, band: (f64, f64)) -> FresnelGridExport {
        let to_f64 = |row: &[f32; GRID_ROW]| -> [f64; EXPORT_COS_STEPS + 1] {
            std::array::from_fn(|j| row[j + 1] as f64)
        };
        if let Fresnel::Metal {
            grid: Some(grid), ..
        } = self
        {
            return FresnelGridExport {
                lambda_nm: grid.lambda_nm.clone(),
                rows: grid.rows.iter().map(to_f64).collect(),
                row_of_nm: grid.row_of_nm.clone(),
            };
        }
        let (lo, hi) = band;
        let row = |lambda: f64| -> [f64; EXPORT_COS_STEPS + 1] {
            std::array::from_fn(|j| {
                let root = j as f64 / GRID_COS_STEPS as f64;
                self.reflectance(root * root, lambda) as f32 as f64
            })
        };
        let span = (hi - lo).ceil() as usize;
        let lambda_nm: Vec<f64> = if self.is_spectrally_flat() {
            vec![lo, hi]
        } else {
            (0..=span).map(|d| (lo + d as f64).min(hi)).collect()
        };
        let last = lambda_nm.len() - 2;
        FresnelGridExport {
            rows: lambda_nm.iter().map(|&l| row(l)).collect(),
            row_of_nm: (0..=span)
                .map(|d| {
                    if lambda_nm.len() == 2 {
                        0
                    } else {
                        d.min(last) as u16
                    }
                })
                .collect(),
            lambda_nm,
        }
    }
}

/// One grid row: F at sqrt(cos) = 0, 1/GRID_COS_STEPS, ..., 1 for the
/// metal's index at lambda_nm, padded as MetalGrid::rows describes.
fn grid_row(table: &MetalTable, lambda_nm: f64) -> [f32; GRID_ROW] {
    let (eta, k) = metal_index(table, lambda_nm);
    let column = |i: usize| {
        let root = i.min(GRID_COS_STEPS) as f64 / GRID_COS_STEPS as f64;
        conductor_reflectance(root * root, eta, k) as f32
    };
    std::array::from_fn(|j| column(j.saturating_sub(1)))
}

/// The wavelengths of two adjacent grid rows.
#[derive(Clone, Copy, Debug)]
pub struct Interval {
    lo_nm: f64,
    hi_nm: f64,
}

impl Interval {
    #[inline]
    fn contains(&self, lambda_nm: f64) -> bool {
        lambda_nm >= self.lo_nm && lambda_nm <= self.hi_nm
    }

    /// Linear interpolation of the rows' values (clamped to the interval).
    #[inline]
    fn lerp(&self, lo: f64, hi: f64, lambda_nm: f64) -> f64 {
        let t = ((lambda_nm - self.lo_nm) / (self.hi_nm - self.lo_nm)).clamp(0.0, 1.0);
        let t = if t.is_nan() { 0.0 } else { t };
        lo + t * (hi - lo)
    }
}

/// The Catmull-Rom stencil of one incidence cosine over the grid columns
/// (uniform in sqrt(cos): F is steepest towards grazing).
#[derive(Clone, Copy, Debug)]
pub struct GridColumns {
    /// First of the four stored values (see MetalGrid::rows).
    first: usize,
    weights: [f64; 4],
}

impl GridColumns {
    #[inline]
    fn new(cos_theta: f64) -> GridColumns {
        let x = cos_theta.clamp(0.0, 1.0).sqrt() * GRID_COS_STEPS as f64;
        let x = if x.is_nan() { 0.0 } else { x };
        let i = (x as usize).min(GRID_COS_STEPS - 1);
        let t = x - i as f64;
        let t2 = t * t;
        let t3 = t2 * t;
        GridColumns {
            // Column i - 1 is stored at index i.
            first: i,
            weights: [
                0.5 * (-t3 + 2.0 * t2 - t),
                0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
                0.5 * (-3.0 * t3 + 4.0 * t2 + t),
                0.5 * (t3 - t2),
            ],
        }
    }

    #[inline]
    fn apply(&self, row: &[f32; GRID_ROW]) -> f64 {
        let first = self.first.min(GRID_ROW - 4);
        let v = &row[first..first + 4];
        let w = &self.weights;
        w[0] * v[0] as f64 + w[1] * v[1] as f64 + w[2] * v[2] as f64 + w[3] * v[3] as f64
    }
}

/// The reflectance at one incidence cosine for any number of wavelengths
/// (an RGB evaluation of a grating takes a dozen or more, often several in
/// one interval of the grid): what depends on the cosine alone is done once,
/// and the last pair of grid rows is kept.
pub enum FresnelAtCos<'a> {
    Constant(f64),
    Direct {
        fresnel: &'a Fresnel,
        cos_theta: f64,
    },
    Grid {
        grid: &'a MetalGrid,
        columns: GridColumns,
        last: std::cell::Cell<Option<(Interval, f64, f64)>>,
    },
}

impl FresnelAtCos<'_> {
    #[inline]
    pub fn reflectance(&self, lambda_nm: f64) -> f64 {
        match self {
            FresnelAtCos::Constant(r) => *r,
            FresnelAtCos::Direct { fresnel, cos_theta } => {
                fresnel.reflectance(*cos_theta, lambda_nm)
            }
            FresnelAtCos::Grid {
                grid,
                columns,
                last,
            } => {
                let (interval, lo, hi) = match last.get() {
                    Some(kept) if kept.0.contains(lambda_nm) => kept,
                    _ => {
                        let pair = grid.row_pair(columns, lambda_nm);
                        last.set(Some(pair));
                        pair
                    }
                };
                interval.lerp(lo, hi, lambda_nm)
            }
        }
    }
}

/// A metal's reflectance at a fixed set of wavelengths (a quadrature rule's
/// nodes) over the grid's cosine columns, from the measured index at exactly
/// those wavelengths: with the cosine's stencil (`FresnelAtCos`) a node's
/// value is four loads, where the grid needs its row search and two rows.
pub struct NodeReflectance {
    rows: Vec<[f32; GRID_ROW]>,
}

impl NodeReflectance {
    /// None unless `fresnel` is a tabulated metal.
    pub fn new(fresnel: &Fresnel, lambdas_nm: &[f64]) -> Option<NodeReflectance> {
        let Fresnel::Metal {
            table,
            grid: Some(_),
        } = fresnel
        else {
            return None;
        };
        let rows = lambdas_nm
            .iter()
            .map(|&lambda| grid_row(table, lambda))
            .collect();
        Some(NodeReflectance { rows })
    }

    pub fn memory_bytes(&self) -> usize {
        self.rows.len() * GRID_ROW * 4
    }
}

impl FresnelAtCos<'_> {
    /// The reflectance at node j (wavelength lambda_nm) of `nodes`.
    #[inline]
    pub fn at_node(&self, nodes: Option<&NodeReflectance>, j: usize, lambda_nm: f64) -> f64 {
        match (self, nodes) {
            (FresnelAtCos::Grid { columns, .. }, Some(nodes)) if j < nodes.rows.len() => {
                columns.apply(&nodes.rows[j])
            }
            _ => self.reflectance(lambda_nm),
        }
    }
}

impl Fresnel {
    /// `reflectance` at a fixed cosine, for many wavelengths.
    #[inline]
    pub fn at_cos(&self, cos_theta: f64) -> FresnelAtCos<'_> {
        match self {
            Fresnel::Constant(r) => FresnelAtCos::Constant(*r),
            Fresnel::Metal {
                grid: Some(grid), ..
            } => FresnelAtCos::Grid {
                grid,
                columns: GridColumns::new(cos_theta),
                last: std::cell::Cell::new(None),
            },
            _ => FresnelAtCos::Direct {
                fresnel: self,
                cos_theta,
            },
        }
    }
}

/// The grid of one of the built-in metals (None for other tables).
fn metal_grid(table: &MetalTable) -> Option<&'static MetalGrid> {
    static GRIDS: [std::sync::OnceLock<MetalGrid>; METALS.len()] =
        [const { std::sync::OnceLock::new() }; METALS.len()];
    let index = METALS.iter().position(|m| m.name == table.name)?;
    Some(GRIDS[index].get_or_init(|| MetalGrid::build(&METALS[index])))
}

/// Linear interpolation of a metal's index, clamped at the table ends.
pub fn metal_index(table: &MetalTable, lambda_nm: f64) -> (f64, f64) {
    let xs = table.lambda_nm;
    let n = xs.len();
    if !(lambda_nm > xs[0]) {
        return (table.eta[0], table.k[0]);
    }
    if lambda_nm >= xs[n - 1] {
        return (table.eta[n - 1], table.k[n - 1]);
    }
    let i = xs.partition_point(|&x| x <= lambda_nm).clamp(1, n - 1);
    let t = (lambda_nm - xs[i - 1]) / (xs[i] - xs[i - 1]);
    (
        table.eta[i - 1] + t * (table.eta[i] - table.eta[i - 1]),
        table.k[i - 1] + t * (table.k[i] - table.k[i - 1]),
    )
}

/// Unpolarised Fresnel reflectance of a conductor with index eta + i k
/// (k = 0: a dielectric seen from outside), in real arithmetic, written
/// once for native code (f64) and programs (`Value`: eta and k the
/// material's `Op::Param`s, which a renderer can differentiate; the formula
/// is smooth in both away from the clamps at 0 and 1, which a physical
/// index never reaches). A cosine that is not finite reads as 0 (grazing,
/// where r is 1); r that is not finite (a NaN index) as 1.
#[inline]
pub fn conductor_reflectance<T: Real>(cos_theta: T, eta: T, k: T) -> T
where
    f64: Sub<T, Output = T>,
{
    let c = T::select(cos_theta.finite(), cos_theta, cos_theta.constant(0.0)).clamp(0.0, 1.0);
    let c2 = c * c;
    let s2 = 1.0 - c2;
    let (eta2, k2) = (eta * eta, k * k);
    let t0 = (eta2 - k2) - s2;
    let a2_plus_b2 = (t0 * t0 + eta2 * k2 * 4.0).sqrt();
    let a = ((a2_plus_b2 + t0) * 0.5).max(0.0).sqrt();
    let t1 = a2_plus_b2 + c2;
    let t2 = a * c * 2.0;
    let rs = (t1 - t2) / (t1 + t2);
    let t3 = c2 * a2_plus_b2 + s2 * s2;
    let t4 = t2 * s2;
    let rp = rs * (t3 - t4) / (t3 + t4);
    let r = (rs + rp) * 0.5;
    T::select(r.finite(), r.clamp(0.0, 1.0), r.constant(1.0))
}

/// The polarisation of specular reflection at a conductor with index
/// eta + i k (k = 0: a dielectric seen from outside): the Mueller matrix of
/// the reflection, in the conventions of Mitsuba's
/// `mueller::specular_reflection` (Stokes bases perpendicular to the plane
/// of incidence), divided by its [0][0] element (the unpolarised
/// reflectance, `conductor_reflectance`). Returns (b, c, s) of
/// [[1, b, 0, 0], [b, 1, 0, 0], [0, 0, c, s], [0, 0, -s, c]].
///
/// With w = sqrt(n^2 - sin^2) (principal root), the amplitudes
/// r_s = (cos - w) / (cos + w) and r_p = (n^2 cos - w) / (n^2 cos + w), and
/// X = r_s conj(r_p): b = (|r_s|^2 - |r_p|^2) / D, c = 2 Re X / D and
/// s = -2 Im X / D with D = |r_s|^2 + |r_p|^2, so that b^2 + c^2 + s^2 = 1
/// (a reflection does not depolarise). Each amplitude is kept as its
/// numerator over its denominator, both scaled by the product of the
/// denominators' norms, so that nothing is divided but D. In real
/// arithmetic, written once for native code and programs. A cosine that is
/// not finite reads as 0; where D is 0 or not finite (an index of 1, a NaN
/// index), a perfect conductor's (0, -1, 0), which is also what a
/// reflectance without an index (`Fresnel::Constant`) takes.
pub fn conductor_polarization<T: Real>(cos_theta: T, eta: T, k: T) -> [T; 3]
where
    f64: Sub<T, Output = T>,
{
    let c = T::select(cos_theta.finite(), cos_theta, cos_theta.constant(0.0)).clamp(0.0, 1.0);
    let s2 = 1.0 - c * c;
    // n^2 = nr + i ni; z = n^2 - sin^2 and w = sqrt(z) = wr + i wi (ni >= 0)
    let (nr, ni) = (eta * eta - k * k, eta * k * 2.0);
    let zr = nr - s2;
    let z_abs = (zr * zr + ni * ni).sqrt();
    let wr = ((z_abs + zr) * 0.5).max(0.0).sqrt();
    let wi = ((z_abs - zr) * 0.5).max(0.0).sqrt();
    // r_s = Ns / Ds, r_p = Np / Dp
    let (ns_r, ns_i) = (c - wr, wi * -1.0);
    let (ds_r, ds_i) = (c + wr, wi);
    let (np_r, np_i) = (nr * c - wr, ni * c - wi);
    let (dp_r, dp_i) = (nr * c + wr, ni * c + wi);
    let norm = |re: T, im: T| re * re + im * im;
    let (ds2, dp2) = (norm(ds_r, ds_i), norm(dp_r, dp_i));
    // |r_s|^2, |r_p|^2 and X times |Ds|^2 |Dp|^2: X = Ns conj(Np) conj(Ds) Dp
    let rs2 = norm(ns_r, ns_i) * dp2;
    let rp2 = norm(np_r, np_i) * ds2;
    let (a_r, a_i) = (ns_r * np_r + ns_i * np_i, ns_i * np_r - ns_r * np_i);
    let (e_r, e_i) = (ds_r * dp_r + ds_i * dp_i, ds_r * dp_i - ds_i * dp_r);
    let (x_r, x_i) = (a_r * e_r - a_i * e_i, a_r * e_i + a_i * e_r);
    let d = rs2 + rp2;
    // Where D is 0 or not finite, the division reads 1 instead; the
    // fallback below replaces what it gives.
    let d_ok = d.finite() & d.gt(0.0);
    let inv = d.constant(1.0) / T::select(d_ok, d, d.constant(1.0));
    let b = (rs2 - rp2) * inv;
    let cc = x_r * inv * 2.0;
    let ss = x_i * inv * -2.0;
    let zero = b.constant(0.0);
    let ok = d_ok & b.finite() & cc.finite() & ss.finite();
    [
        T::select(ok, b, zero),
        T::select(ok, cc, zero.constant(-1.0)),
        T::select(ok, ss, zero),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_complex::Complex64;

    /// Independent form: complex amplitude coefficients.
    fn complex_reference(cos_i: f64, eta: f64, k: f64) -> f64 {
        let n = Complex64::new(eta, k);
        let sin2 = 1.0 - cos_i * cos_i;
        let cos_t = (Complex64::new(1.0, 0.0) - sin2 / (n * n)).sqrt();
        let rs = (cos_i - n * cos_t) / (cos_i + n * cos_t);
        let rp = (n * cos_i - cos_t) / (n * cos_i + cos_t);
        0.5 * (rs.norm_sqr() + rp.norm_sqr())
    }

    /// Written once (`Real`): the program built from the formula and run
    /// in f64 gives the native values bit for bit, NaN and out-of-range
    /// cosines included.
    #[test]
    fn conductor_program_is_the_native_formula() {
        use crate::program::Builder;
        let b = Builder::new();
        let (cos, eta, k) = (b.input(), b.input(), b.input());
        let program = b.finish(&[conductor_reflectance(cos, eta, k)]);
        let cosines = [
            -0.5,
            0.0,
            1e-9,
            0.01,
            0.3,
            0.7,
            0.99,
            1.0,
            1.5,
            f64::NAN,
            f64::INFINITY,
        ];
        for &(eta, k) in &[
            (1.5, 0.0),
            (0.2, 3.9),
            (1.1, 6.7),
            (2.5, 0.3),
            (1e-3, 100.0),
            (f64::NAN, 1.0),
        ] {
            for &c in &cosines {
                let native = conductor_reflectance(c, eta, k);
                let run = program.run(&[c, eta, k])[0];
                assert_eq!(
                    native.to_bits(),
                    run.to_bits(),
                    "cos {c} eta {eta} k {k}: {native} {run}"
                );
            }
        }
    }

    #[test]
    fn real_form_matches_complex_amplitudes() {
        for &(eta, k) in &[(1.5, 0.0), (0.2, 3.9), (1.1, 6.7), (2.5, 0.3)] {
            for i in 0..=50 {
                let c = (i as f64 / 50.0).max(1e-6);
                let a = conductor_reflectance(c, eta, k);
                let b = complex_reference(c, eta, k);
                assert!((a - b).abs() < 1e-10, "eta {eta} k {k} cos {c}: {a} vs {b}");
            }
        }
        // Normal incidence closed form ((n-1)^2 + k^2)/((n+1)^2 + k^2).
        let r = conductor_reflectance(1.0, 1.2, 7.0);
        assert!((r - (0.04 + 49.0) / (4.84 + 49.0)).abs() < 1e-12);
    }

    /// The polarisation (b, c, s) against the complex amplitudes r_s and
    /// r_p written directly (num_complex; the conventions of Mitsuba's
    /// `mueller::specular_reflection`, checked against it in
    /// tests/test_polarization.py), over cosines and indices of metals and
    /// dielectrics: within 1e-9; b^2 + c^2 + s^2 = 1 within 1e-12 (a
    /// reflection does not depolarise); the reference's [0][0] is
    /// `conductor_reflectance`.
    #[test]
    fn polarization_matches_complex_amplitudes() {
        let mut rng = crate::sampling::SplitMix64(0x2545_f491_4f6c_dd1d);
        let mut uniform = || rng.next_f64();
        let mut worst = 0.0f64;
        for i in 0..20_000 {
            let c = if i % 100 == 0 { 0.0 } else { uniform() };
            let eta = 0.05 + 4.0 * uniform();
            let k = if i % 5 == 0 { 0.0 } else { 12.0 * uniform() };
            let n = Complex64::new(eta, k);
            let w = (n * n - (1.0 - c * c)).sqrt();
            let rs = (c - w) / (c + w);
            let rp = (n * n * c - w) / (n * n * c + w);
            let d = rs.norm_sqr() + rp.norm_sqr();
            let x = rs * rp.conj();
            let want = [
                (rs.norm_sqr() - rp.norm_sqr()) / d,
                2.0 * x.re / d,
                -2.0 * x.im / d,
            ];
            let got = conductor_polarization(c, eta, k);
            for (g, w) in got.iter().zip(want) {
                worst = worst.max((g - w).abs());
            }
            let sum: f64 = got.iter().map(|v| v * v).sum();
            assert!(
                (sum - 1.0).abs() < 1e-12,
                "cos {c} eta {eta} k {k}: {got:?}"
            );
            let a = 0.5 * d;
            assert!((a - conductor_reflectance(c, eta, k)).abs() < 1e-10);
        }
        assert!(worst < 1e-9, "worst {worst}");
        // No index to speak of, or none at all: a perfect conductor's.
        for (c, eta, k) in [
            (0.5, 1.0, 0.0),
            (0.5, f64::NAN, 1.0),
            (0.5, 1.0, f64::INFINITY),
        ] {
            assert_eq!(conductor_polarization(c, eta, k), [0.0, -1.0, 0.0]);
        }
        assert_eq!(
            Fresnel::Constant(0.9).polarization(0.3, 500.0),
            [0.0, -1.0, 0.0]
        );
        // A cosine that is not finite reads as grazing.
        assert_eq!(
            conductor_polarization(f64::NAN, 1.2, 6.9),
            conductor_polarization(0.0, 1.2, 6.9)
        );
    }

    /// Written once (`Real`): the polarisation's program, run in f64, gives
    /// the native values bit for bit.
    #[test]
    fn polarization_program_is_the_native_formula() {
        use crate::program::Builder;
        let b = Builder::new();
        let (cos, eta, k) = (b.input(), b.input(), b.input());
        let program = b.finish(&conductor_polarization(cos, eta, k));
        for &(eta, k) in &[
            (1.5, 0.0),
            (0.2, 3.9),
            (1.1, 6.7),
            (1.0, 0.0),
            (f64::NAN, 1.0),
        ] {
            for c in [-0.5, 0.0, 1e-9, 0.3, 0.99, 1.0, 1.5, f64::NAN] {
                let native = conductor_polarization(c, eta, k);
                let run = program.run(&[c, eta, k]);
                for (x, y) in native.iter().zip(&run) {
                    assert_eq!(x.to_bits(), y.to_bits(), "cos {c} eta {eta} k {k}");
                }
            }
        }
    }

    /// The tabulated metal reflectance against the direct evaluation from
    /// the measured index, densely over cos and the visible band.
    #[test]
    fn metal_grid_matches_direct_evaluation() {
        let mut worst: f64 = 0.0;
        for table in METALS.iter() {
            let fresnel = Fresnel::metal(metal_by_name(table.name).unwrap());
            for a in 0..=997 {
                let cos = a as f64 / 997.0;
                for b in 0..=311 {
                    let lambda = 360.0 + 470.0 * b as f64 / 311.0;
                    let grid = fresnel.reflectance(cos, lambda);
                    let exact = metal_reflectance_exact(table, cos, lambda);
                    worst = worst.max((grid - exact).abs());
                }
            }
        }
        println!("metal reflectance grid: worst absolute error {worst:.2e}");
        assert!(worst < 5e-5, "{worst}");
    }

    /// The fixed-cosine form (with its kept row pair) gives the plain
    /// reflectance, for wavelengths in and out of order and out of range.
    #[test]
    fn at_cos_matches_reflectance() {
        for fresnel in [
            Fresnel::metal(metal_by_name("gold").unwrap()),
            Fresnel::metal(metal_by_name("aluminium").unwrap()),
            Fresnel::ComplexIndex { eta: 1.5, k: 3.0 },
            Fresnel::Constant(0.7),
        ] {
            for cos in [0.0, 0.013, 0.5, 0.97, 1.0] {
                let at = fresnel.at_cos(cos);
                let mut lambda = 300.0;
                for step in [0.3, 0.05, 2.7, -1.1, 0.0, 13.0, -40.0, 0.01] {
                    for _ in 0..20 {
                        lambda += step;
                        let direct = fresnel.reflectance(cos, lambda);
                        let kept = at.reflectance(lambda);
                        assert!(
                            (direct - kept).abs() <= 1e-14,
                            "{cos} {lambda}: {direct} {kept}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn metals_are_reflective_and_named() {
        for name in ["aluminium", "silver", "gold", "copper", "chromium"] {
            let table = metal_by_name(name).expect(name);
            let f = Fresnel::metal(table);
            for lambda in [360.0, 450.0, 550.0, 650.0, 830.0] {
                let r = f.reflectance(1.0, lambda);
                assert!(r > 0.3 && r <= 1.0, "{name} {lambda}: {r}");
            }
        }
        // Gold is yellow: much more reflective in the red than the blue.
        let gold = Fresnel::metal(metal_by_name("gold").unwrap());
        assert!(gold.reflectance(1.0, 650.0) > gold.reflectance(1.0, 450.0) + 0.3);
        assert!(metal_by_name("unobtainium").is_none());
    }
}

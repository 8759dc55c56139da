//! Measured or synthetic surfaces: the diffraction BRDF of a height map
//! (docs/heightmap.md), Stam's general result on the map itself rather
//! than on a statistical model of it.
//!
//! The map (`map.rs`: .npy, .exr, .tif, .png or .csv, detrended) gives two tables
//! (`welch.rs`): the coherent lobe's |chi(kappa)|^2 and the diffuse
//! spectrum T(kappa, nu), with kappa = k |w| and nu = (u, v) / lambda:
//!
//! ```text
//! K = k^4 T(k |w|, k (u, v) / 2 pi) / (4 pi^2),   f = F^2 G K,
//! coherent reflectance F^2 |chi(2 k cos_i)|^2.
//! ```
//!
//! Reads are written once, generic over `program::Real` with a `fetch` of
//! a table entry: natively an index, in the JIT programs a gather
//! (`program.rs`). Sampling (`sampling.rs`) draws a cell of T at the
//! mirror's kappa from an alias table. Tables are shared by every
//! material made from the same map file and parameters while one holds
//! them (`cache`).

mod cache;
pub(crate) mod map;
pub mod params;
mod program;
#[cfg(test)]
mod program_tests;
pub(crate) mod rgb;
mod sampling;
#[cfg(test)]
mod tests;
mod welch;

pub use params::HeightMapParams;
pub use rgb::RgbTable;
pub use sampling::Lobe;
pub use welch::SpectrumTable;

use crate::error::StamError;
use crate::models::{
    Shading, SurfaceModel, FLAG_ANISOTROPIC, FLAG_HAS_COHERENT, FLAG_SPECTRALLY_VARYING,
    MAX_RGB_NODES,
};
use crate::optics::geometry::PairGeometry;
use crate::program::Real;
use crate::sampling::Component;
use crate::spectrum::wavenumber_per_um;
use std::f64::consts::PI;
use std::sync::{Arc, OnceLock};

/// 1 / (4 pi^2).
const INV_4PI2: f64 = 1.0 / (4.0 * PI * PI);

/// The height-map model of a material: the map's tables.
pub struct HeightMap {
    table: Arc<SpectrumTable>,
    /// The RGB rule's sum over (|w|, u, v), built on the first RGB
    /// evaluation (`rgb.rs`).
    rgb: OnceLock<Option<RgbTable>>,
}

impl HeightMap {
    pub fn new(p: &HeightMapParams) -> Result<HeightMap, StamError> {
        Ok(HeightMap {
            table: cache::table(p)?,
            rgb: OnceLock::new(),
        })
    }

    pub fn table(&self) -> &SpectrumTable {
        &self.table
    }

    /// The material's RGB table, built on its first RGB evaluation from
    /// the shading's rule and Fresnel term (one material has one of each);
    /// None when it failed its build's check (`rgb::CHECK_P90`: the map is
    /// too sharp for it), and the rule's nodes serve.
    pub(crate) fn rgb_table(&self, shading: &Shading) -> Option<&RgbTable> {
        self.rgb
            .get_or_init(|| RgbTable::build_checked(&self.table, shading.rgb_rule, shading.fresnel))
            .as_ref()
    }

    /// Bytes of the RGB table, 0 before the first RGB evaluation.
    pub fn rgb_table_bytes(&self) -> usize {
        self.rgb
            .get()
            .and_then(Option::as_ref)
            .map_or(0, RgbTable::memory_bytes)
    }

    /// The RGB table's grid (w nodes, u and v points, u and v extents),
    /// None before the first RGB evaluation.
    pub fn rgb_table_shape(&self) -> Option<(usize, usize, usize, f64, f64)> {
        self.rgb.get().and_then(Option::as_ref).map(RgbTable::shape)
    }

    /// F^2 K in RGB by the rule's nodes, one read of T each (what the RGB
    /// table tabulates; the tests compare the two).
    pub(crate) fn reflectance_rgb_by_nodes(
        &self,
        shading: &Shading,
        geom: &PairGeometry,
    ) -> [f64; 3] {
        let rule = shading.rgb_rule;
        let mut values = [0.0; MAX_RGB_NODES];
        let values = &mut values[..rule.len()];
        for (v, &k) in values.iter_mut().zip(&rule.k_per_um) {
            *v = self.kernel(k, geom);
        }
        shading.integrate(geom.cos_half, values)
    }

    /// |chi(2 k cos_i)|^2, any `Real`.
    #[inline]
    pub(crate) fn coherent_with<R: Real>(
        &self,
        k_per_um: R,
        cos_i: R,
        fetch: impl Fn(R) -> R,
    ) -> R {
        self.table.chi2_read(k_per_um * cos_i * 2.0, fetch)
    }

    fn fetch_value(&self) -> impl Fn(f64) -> f64 + '_ {
        |at: f64| self.table.values[at as usize] as f64
    }

    fn fetch_chi2(&self) -> impl Fn(f64) -> f64 + '_ {
        |at: f64| self.table.chi2[at as usize] as f64
    }
}

/// The bilinear read of the 2 x 2 entries at `at`, `at + dx`, `at + dy`
/// and `at + dx + dy`, weights `tx` along x and `ty` along y (the tables'
/// (u, v) cells), any `Real`.
#[inline]
pub(crate) fn bilinear<R: Real>(
    fetch: &impl Fn(R) -> R,
    at: R,
    dx: f64,
    dy: f64,
    tx: R,
    ty: R,
) -> R {
    let (v00, v01) = (fetch(at), fetch(at + dx));
    let (v10, v11) = (fetch(at + dy), fetch(at + (dy + dx)));
    let lo = v00 + (v01 - v00) * tx;
    let hi = v10 + (v11 - v10) * tx;
    lo + (hi - lo) * ty
}

/// e0^(1 - t) e1^t to 0.2% (for e1 / e0 within 1/2.2 to 2.2), or e0 +
/// (e1 - e0) t where either is not positive.
///
/// Between nodes a cell of T changes by a power of kappa, not linearly: a
/// grating's order n as kappa^(2n - 2) where the map is optically smooth,
/// that is T (1 + kappa / kappa_0)^4 as exp(m s) with m up to 2n + 2. A
/// linear blend overestimates that by up to (m h)^2 / 8 at the node step h
/// = 0.08: 5% for the third order, which the Kirchhoff tool measured on the
/// demo grating map (docs/kirchhoff.md, "Height maps"). The geometric
/// blend is exact for it, and equal to the linear one where T is flat in s.
/// It is computed without exp and ln (which cost 24 of each per RGB
/// evaluation by the nodes): the geometric midpoint sqrt(e0) sqrt(e1) is
/// exact, and within the half that t falls in, the [1/1] Pade approximant
/// of a^(1 - u) b^u in b / a, which stays between a and b. Denominators
/// stay positive in both branches, so that a program's gradients (which
/// flow through both) stay finite.
#[inline]
fn geometric_blend<R: Real>(e0: R, e1: R, t: R) -> R {
    let positive = e0.gt(0.0) & e1.gt(0.0);
    let one = t.constant(1.0);
    let (p0, p1) = (R::select(positive, e0, one), R::select(positive, e1, one));
    let mid = p0.sqrt() * p1.sqrt();
    let upper = t.gt(0.5);
    let (a, b) = (R::select(upper, mid, p0), R::select(upper, p1, mid));
    let u = R::select(upper, t * 2.0 - 1.0, t * 2.0);
    let (up, down) = (u + 1.0, one - u);
    let pade = a * (a * down + b * up) / (a * up + b * down);
    R::select(positive, pade, e0 + (e1 - e0) * t)
}

impl SpectrumTable {
    /// K at wavenumber k for the pair's (u, v, |w|), any `Real`.
    #[inline]
    pub(crate) fn kernel<R: Real>(
        &self,
        k_per_um: R,
        w_abs: R,
        u: R,
        v: R,
        fetch: impl Fn(R) -> R,
    ) -> R {
        let nu_scale = k_per_um * (0.5 / PI);
        let t = self.read(k_per_um * w_abs, u * nu_scale, v * nu_scale, fetch);
        let k2 = k_per_um * k_per_um;
        t * (k2 * k2) * INV_4PI2
    }

    /// T at (kappa, nu): geometric in s = ln(1 + kappa / kappa_0) between
    /// nodes (`geometric_blend`), bilinear in nu on the frequency grid (8
    /// fetches), 0 beyond the grid's Nyquist frequency.
    #[inline]
    pub(crate) fn read<R: Real>(&self, kappa: R, nu_x: R, nu_y: R, fetch: impl Fn(R) -> R) -> R {
        let (a, i, t) = self.place_in_s(kappa, self.nodes);
        let n = self.tile as f64;
        let half = (self.tile / 2) as f64;
        let fx = nu_x * self.tile_um + half;
        let fy = nu_y * self.tile_um + half;
        let inside = fx.ge(0.0) & fx.le(n - 1.0) & fy.ge(0.0) & fy.le(n - 1.0);
        let (fx, fy) = (fx.clamp(0.0, n - 1.0), fy.clamp(0.0, n - 1.0));
        let (ix, iy) = (fx.floor().min(n - 2.0), fy.floor().min(n - 2.0));
        let (tx, ty) = (fx - ix, fy - iy);
        let base = (i * n + iy) * n + ix;
        let plane = |at: R| bilinear(&fetch, at, 1.0, n, tx, ty);
        let (e0, e1) = (plane(base), plane(base + n * n));
        let e = geometric_blend(e0, e1, t);
        // The table holds T (1 + kappa / kappa_0)^4.
        let a2 = a * a;
        R::select(inside, e / (a2 * a2), kappa.constant(0.0))
    }

    /// Where kappa lies among `entries` entries uniform in s = ln(1 +
    /// kappa / kappa_0) over [0, s_max] (the nodes of T, the |chi|^2
    /// table): 1 + kappa / kappa_0, the lower entry and the upper one's
    /// weight.
    #[inline]
    pub(crate) fn place_in_s<R: Real>(&self, kappa: R, entries: usize) -> (R, R, R) {
        let a = kappa * (1.0 / self.kappa0) + 1.0;
        let last = (entries - 1) as f64;
        let x = (a.ln() * (last / self.s_max)).clamp(0.0, last);
        let i = x.floor().min(last - 1.0);
        (a, i, x - i)
    }

    /// |chi(kappa)|^2, linear in s between the table's entries.
    #[inline]
    pub(crate) fn chi2_read<R: Real>(&self, kappa: R, fetch: impl Fn(R) -> R) -> R {
        let (_, i, t) = self.place_in_s(kappa, welch::CHI_NODES);
        let (c0, c1) = (fetch(i), fetch(i + 1.0));
        c0 + (c1 - c0) * t
    }
}

impl SurfaceModel for HeightMap {
    type Params = HeightMapParams;
    type Lobe = Lobe;

    fn from_params(
        p: &HeightMapParams,
        _: &crate::optics::fresnel::Fresnel,
    ) -> Result<HeightMap, StamError> {
        HeightMap::new(p)
    }

    fn flags(&self) -> u32 {
        FLAG_HAS_COHERENT | FLAG_ANISOTROPIC | FLAG_SPECTRALLY_VARYING
    }

    fn memory_bytes(&self) -> usize {
        self.table.memory_bytes() + self.rgb_table_bytes()
    }

    #[inline]
    fn kernel(&self, k_per_um: f64, geom: &PairGeometry) -> f64 {
        self.table
            .kernel(k_per_um, geom.w.abs(), geom.u, geom.v, self.fetch_value())
    }

    /// The RGB table's read; the energy factor is colour-neutral for
    /// height maps (`energy_hint`), so one of its values scales the sum.
    fn reflectance_rgb(&self, shading: &Shading, geom: &PairGeometry) -> [f64; 3] {
        let Some(rgb_table) = self.rgb_table(shading) else {
            return self.reflectance_rgb_by_nodes(shading, geom);
        };
        let rgb = rgb_table.read(geom.w.abs(), geom.u, geom.v, |at| {
            rgb_table.values[at as usize] as f64
        });
        let factor = shading
            .pair_factor
            .map_or(1.0, |f| f(shading.rgb_rule.lambda_nm()[0]));
        rgb.map(|c| c * factor)
    }

    fn coherent_spectral(&self, shading: &Shading, cos_i: f64, lambda_nm: f64) -> f64 {
        let k = wavenumber_per_um(lambda_nm);
        shading.fresnel.reflectance(cos_i, lambda_nm)
            * self.coherent_with(k, cos_i, self.fetch_chi2())
    }

    fn coherent_rgb(&self, shading: &Shading, cos_i: f64) -> [f64; 3] {
        let rule = shading.rgb_rule;
        let mut values = [0.0; MAX_RGB_NODES];
        let values = &mut values[..rule.len()];
        for (v, &k) in values.iter_mut().zip(&rule.k_per_um) {
            *v = self.coherent_with(k, cos_i, self.fetch_chi2());
        }
        shading.integrate(cos_i, values)
    }

    fn spectral_component(&self, _: &Shading, wi: glam::DVec3, lambda_nm: f64) -> Component<Lobe> {
        self.component(wi, lambda_nm)
    }
}

//! Strategies tabulated over the incidence cosine and the wavelength.

use super::band::RGB_BAND_NM;
use super::mixture::Component;
use std::sync::OnceLock;

/// Incidence cosine bins (uniform in cos: the smooth models' parameters
/// vary with g0 ~ cos^2, and the horizon twin's elevation with cos itself
/// near grazing).
const COS_BINS: usize = 128;
/// Wavelength nodes: every 25 nm over the RGB band.
const LAMBDA_NODES: usize = 17;

/// Strategies of the smooth models (Gaussian, fractal) tabulated over the
/// incidence cosine and the wavelength, the two things they depend on (an
/// isotropic lobe's azimuth, the horizon twin's, is set per call by the
/// model). Built exactly at a cosine bin's centre and the nearest
/// wavelength node on first use, so the strategy is a deterministic
/// function of (wi, lambda) and its pdf stays exact; what the quantisation
/// moves (g0 by at most dcos / cos, the lobe widths by 12.5 nm / lambda,
/// 3%) only costs variance. A spectral path needs 4 strategies per vertex
/// and an RGB one 4 nodes: building them (the albedo table lookup, the
/// horizon twin's fit: sines, erfcs) was most of the cost of a sample. The
/// cells are inline and the table small (2176 cells, about 200 kB) so that
/// a render's lookups hit the cache: a first version with a cell per 5 nm
/// and 256 cosines, boxed, missed it on most lookups and saved nothing.
pub struct StrategyTable<L> {
    cells: Vec<OnceLock<Component<L>>>,
}

impl<L> Default for StrategyTable<L> {
    fn default() -> Self {
        StrategyTable {
            cells: (0..COS_BINS * LAMBDA_NODES)
                .map(|_| OnceLock::new())
                .collect(),
        }
    }
}

impl<L> StrategyTable<L> {
    fn lambda_node(j: usize) -> f64 {
        let (lo, hi) = RGB_BAND_NM;
        lo + (hi - lo) * j as f64 / (LAMBDA_NODES - 1) as f64
    }

    /// The cell of incidence cosine `cos_i` (of a unit direction above the
    /// horizon) and the in-band `lambda_nm`, built on first use by
    /// `build(cos, lambda)` at the cell's centre cosine and wavelength node.
    pub fn get(
        &self,
        cos_i: f64,
        lambda_nm: f64,
        build: impl FnOnce(f64, f64) -> Component<L>,
    ) -> &Component<L> {
        let i = ((cos_i * COS_BINS as f64) as usize).min(COS_BINS - 1);
        let (lo, hi) = RGB_BAND_NM;
        let x = (lambda_nm - lo) / (hi - lo) * (LAMBDA_NODES - 1) as f64;
        let j = (x.max(0.0).round() as usize).min(LAMBDA_NODES - 1);
        self.cells[i * LAMBDA_NODES + j].get_or_init(|| {
            let cos = (i as f64 + 0.5) / COS_BINS as f64;
            build(cos, Self::lambda_node(j))
        })
    }

    pub fn memory_bytes(&self) -> usize {
        self.cells.len() * std::mem::size_of::<OnceLock<Component<L>>>()
    }
}

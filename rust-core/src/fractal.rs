//! Fractal (fractional Brownian) surfaces through the universal 2-D stable
//! profile Phi_alpha. See docs/physics.md, "Fractal surfaces".
// TEMPORARY STAND-IN (replaced by the fractal branch): signatures only.
use crate::geometry::PairGeometry;
pub struct FractalSurface;
impl FractalSurface {
    pub fn new(_hurst: f64, _sigma_um: f64, _lag_um: f64) -> Result<FractalSurface, String> {
        Err("fractal surfaces are not implemented yet".into())
    }
    pub fn kernel(&self, _k_per_um: f64, _geom: &PairGeometry) -> f64 {
        0.0
    }
    pub fn memory_bytes(&self) -> usize {
        0
    }
}

//! Periodic surfaces: gratings and the compact disc. See docs/physics.md,
//! "Periodic surfaces".
// TEMPORARY STAND-IN (replaced by the periodic branch): signatures only.
use crate::geometry::PairGeometry;
#[derive(Clone, Debug, PartialEq)]
pub enum Profile {
    Rect { height_um: f64, width_um: f64 },
    Sine { height_um: f64 },
    Tabulated { heights_um: Vec<f64> },
}
pub struct PeriodicSurface;
impl PeriodicSurface {
    pub fn new(
        _period_um: f64,
        _coherence_um: f64,
        _profile: Profile,
    ) -> Result<PeriodicSurface, String> {
        Err("periodic surfaces are not implemented yet".into())
    }
    pub fn kernel(&self, _k_per_um: f64, _geom: &PairGeometry) -> f64 {
        0.0
    }
    pub fn kernel_rgb(&self, _geom: &PairGeometry, _reflectance: &dyn Fn(f64) -> f64) -> [f64; 3] {
        [0.0; 3]
    }
    pub fn memory_bytes(&self) -> usize {
        0
    }
}

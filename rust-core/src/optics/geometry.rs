//! Direction pairs in the local shading frame and the quantities every
//! surface model shares: Stam's (u, v, w), the geometric factor G and the
//! half-vector cosine at which Fresnel is evaluated.
//!
//! Frame: z = normal, x = tangent (the periodic direction), y = bitangent.
//! Both directions point away from the surface.

use glam::DVec3;

/// Smallest cosine treated as above the horizon. Below it (and for NaN) the
/// BRDF is 0; the grazing limit is 1e-8, so this leaves headroom.
pub const MIN_COS: f64 = 1e-12;

/// Everything a surface model needs to know about one (wi, wo) pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PairGeometry {
    /// u = -(wi.x + wo.x): projected direction difference along the tangent.
    pub u: f64,
    /// v = -(wi.y + wo.y).
    pub v: f64,
    /// w = -(wi.z + wo.z) < 0.
    pub w: f64,
    pub cos_i: f64,
    pub cos_o: f64,
    /// G = (1 + wi.wo)^2 / (cos_i cos_o).
    pub geometric_factor: f64,
    /// wi . h with h the half vector: the local incidence cosine of the
    /// specular microfacet, where Fresnel is evaluated (Kirchhoff).
    pub cos_half: f64,
    /// The directions, normalised.
    pub wi: DVec3,
    pub wo: DVec3,
}

impl PairGeometry {
    /// None when either direction is below the horizon, not finite, or the
    /// pair is degenerate. Inputs need not be exactly unit length; they are
    /// normalised so that small caller rounding does not bias u, v, w.
    pub fn new(wi: DVec3, wo: DVec3) -> Option<PairGeometry> {
        let wi = normalize_direction(wi)?;
        let wo = normalize_direction(wo)?;
        let cos_i = wi.z;
        let cos_o = wo.z;
        if !(cos_i > MIN_COS && cos_o > MIN_COS) {
            return None;
        }
        let sum = wi + wo;
        let one_plus_dot = 1.0 + wi.dot(wo);
        let geometric_factor = one_plus_dot * one_plus_dot / (cos_i * cos_o);
        let cos_half = (0.5 * one_plus_dot).max(0.0).sqrt();
        Some(PairGeometry {
            u: -sum.x,
            v: -sum.y,
            w: -sum.z,
            cos_i,
            cos_o,
            geometric_factor,
            cos_half,
            wi,
            wo,
        })
    }

    /// Squared projected distance from the mirror configuration, u^2 + v^2.
    pub fn uv_length_sq(&self) -> f64 {
        self.u * self.u + self.v * self.v
    }
}

/// Unit vector, or None for non-finite or zero input.
pub fn normalize_direction(d: DVec3) -> Option<DVec3> {
    if !d.is_finite() {
        return None;
    }
    let len = d.length();
    if !(len > 1e-30) {
        return None;
    }
    Some(d / len)
}

/// Mirror direction of wi about the normal.
pub fn reflect(wi: DVec3) -> DVec3 {
    DVec3::new(-wi.x, -wi.y, wi.z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mirror_configuration_has_zero_uv() {
        let wi = DVec3::new(0.3, -0.2, 0.5).normalize();
        let g = PairGeometry::new(wi, reflect(wi)).unwrap();
        assert!(g.u.abs() < 1e-15 && g.v.abs() < 1e-15);
        assert!((g.w + 2.0 * wi.z).abs() < 1e-15);
        assert!((g.cos_half - wi.z).abs() < 1e-12);
    }

    #[test]
    fn below_horizon_and_nan_are_rejected() {
        let up = DVec3::Z;
        assert!(PairGeometry::new(up, DVec3::new(0.0, 0.0, -1.0)).is_none());
        assert!(PairGeometry::new(DVec3::new(f64::NAN, 0.0, 1.0), up).is_none());
        assert!(PairGeometry::new(DVec3::ZERO, up).is_none());
    }
}

//! The link between the FFT's variables and a physical (wi, wo, lambda)
//! at which the core is evaluated, and the closed-form approximations whose
//! range of validity the report shows (never used as ground truth).

use glam::DVec3;
use std::f64::consts::PI;

/// Wavenumber (1/um) of a wavelength in nm.
pub fn wavenumber(lambda_nm: f64) -> f64 {
    2.0 * PI * 1000.0 / lambda_nm
}

/// Incidence direction at polar angle theta (degrees) in the xz plane.
pub fn incidence(theta_deg: f64) -> DVec3 {
    let t = theta_deg.to_radians();
    DVec3::new(t.sin(), 0.0, t.cos())
}

/// A physical configuration that realises the Kirchhoff arguments.
#[derive(Clone, Copy, Debug)]
pub struct Pair {
    pub wo: DVec3,
    pub k: f64,
    pub lambda_nm: f64,
}

/// Smallest cos(theta_o) and the wavelength band accepted for a comparison
/// point (the core is 0 outside 360..830 nm).
pub const MIN_COS_O: f64 = 0.1;
pub const LAMBDA_BAND_NM: (f64, f64) = (370.0, 820.0);

/// The Kirchhoff average depends on (k w, k u, k v) only. One FFT is done at a
/// fixed a = k w (< 0); for a grid frequency q and a fixed incidence wi this
/// solves for the wavenumber k and the outgoing direction wo with
/// -(wi + wo) = (q_x, q_y, a) / k, wo a unit vector:
/// t = 1/k = -2 (q . wi_xy + a wi_z) / (|q|^2 + a^2).
pub fn solve_pair(wi: DVec3, a: f64, qx: f64, qy: f64) -> Option<Pair> {
    let t = -2.0 * (qx * wi.x + qy * wi.y + a * wi.z) / (qx * qx + qy * qy + a * a);
    // (also rejects NaN)
    if t.is_nan() || t <= 0.0 {
        return None;
    }
    let wo = DVec3::new(-qx * t - wi.x, -qy * t - wi.y, -a * t - wi.z);
    if wo.z < MIN_COS_O {
        return None;
    }
    let k = 1.0 / t;
    let lambda_nm = 2.0 * PI * 1000.0 * t;
    if !(LAMBDA_BAND_NM.0..=LAMBDA_BAND_NM.1).contains(&lambda_nm) {
        return None;
    }
    Some(Pair { wo, k, lambda_nm })
}

/// G = (1 + wi.wo)^2 / (cos_i cos_o).
pub fn geometric_factor(wi: DVec3, wo: DVec3) -> f64 {
    let d = 1.0 + wi.dot(wo);
    d * d / (wi.z * wo.z)
}

/// <|P|^2>/A from K = f / G (F^2 = 1): K = k^2 / (4 pi^2 w^2) <|P|^2>/A.
pub fn kernel_to_spectrum(kernel: f64, wi: DVec3, pair: &Pair) -> f64 {
    let w = -(wi.z + pair.wo.z);
    kernel * 4.0 * PI * PI * w * w / (pair.k * pair.k)
}

/// <|P|^2>/A from a BRDF value f with F^2 = 1.
pub fn brdf_to_spectrum(f: f64, wi: DVec3, pair: &Pair) -> f64 {
    kernel_to_spectrum(f / geometric_factor(wi, pair.wo), wi, pair)
}

/// Large-g limit (physics.md): f = D_Beckmann(h; ax = 2 sigma / Tx, ay = 2 sigma / Ty)
/// / (4 cos_i cos_o), returned as <|P|^2>/A.
pub fn beckmann_spectrum(sigma: f64, tx: f64, ty: f64, wi: DVec3, pair: &Pair) -> f64 {
    let h = (wi + pair.wo).normalize();
    let (ax, ay) = (2.0 * sigma / tx, 2.0 * sigma / ty);
    let c2 = h.z * h.z;
    let d =
        (-(h.x * h.x / (ax * ax) + h.y * h.y / (ay * ay)) / c2).exp() / (PI * ax * ay * c2 * c2);
    let f = d / (4.0 * wi.z * pair.wo.z);
    brdf_to_spectrum(f, wi, pair)
}

/// Small-g limit: the m = 1 term, e^-g g pi Tx Ty exp(-(qx^2 Tx^2 + qy^2 Ty^2) / 4), g = (sigma a)^2.
pub fn first_order_spectrum(sigma: f64, tx: f64, ty: f64, a: f64, qx: f64, qy: f64) -> f64 {
    let g = (sigma * a).powi(2);
    (-g).exp() * g * PI * tx * ty * (-(qx * qx * tx * tx + qy * qy * ty * ty) / 4.0).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solved_pair_reproduces_the_fft_arguments() {
        let wi = incidence(40.0);
        let k0 = wavenumber(550.0);
        let a = -2.0 * k0 * wi.z;
        for &(qx, qy) in &[(0.0, 0.0), (3.0, -2.0), (-5.0, 1.0), (0.5, 7.0)] {
            let p = solve_pair(wi, a, qx, qy).unwrap();
            assert!((p.wo.length() - 1.0).abs() < 1e-12);
            let s = -(wi + p.wo) * p.k;
            assert!((s.x - qx).abs() < 1e-9 && (s.y - qy).abs() < 1e-9 && (s.z - a).abs() < 1e-9);
        }
        // q = 0 is the mirror direction at the nominal wavelength.
        let p = solve_pair(wi, a, 0.0, 0.0).unwrap();
        assert!((p.lambda_nm - 550.0).abs() < 1e-9);
        assert!((p.wo - DVec3::new(-wi.x, 0.0, wi.z)).length() < 1e-12);
    }
}

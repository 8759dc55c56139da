//! The wavelength band of the RGB strategies and their density over it.

use std::sync::OnceLock;

/// Representative wavelengths of the RGB mixture for spectrally smooth models.
pub const RGB_SAMPLING_NODES: usize = 4;
/// Band of the RGB mixtures (outside it the sRGB weights are negligible).
pub const RGB_BAND_NM: (f64, f64) = (
    crate::spectrum::RGB_BAND_MIN_NM,
    crate::spectrum::RGB_BAND_MAX_NM,
);

/// Density over wavelength of the RGB mixtures: xbar + ybar + zbar by the
/// multi-lobe fit of Wyman, Sloan and Shirley (JCGT 2013). Only a heuristic
/// (any positive density keeps the estimators unbiased); with equal-energy
/// normalised matching functions it weights the three channels alike.
pub fn band_density(lambda_nm: f64) -> f64 {
    let g = |mu: f64, s1: f64, s2: f64| {
        let t = (lambda_nm - mu) / if lambda_nm < mu { s1 } else { s2 };
        (-0.5 * t * t).exp()
    };
    let x =
        1.056 * g(599.8, 37.9, 31.0) + 0.362 * g(442.0, 16.0, 26.7) - 0.065 * g(501.1, 20.4, 26.2);
    let y = 0.821 * g(568.8, 46.9, 40.5) + 0.286 * g(530.9, 16.3, 31.1);
    let z = 1.217 * g(437.0, 11.8, 36.0) + 0.681 * g(459.0, 26.0, 13.8);
    (x + y + z).max(0.0)
}

/// The RGB mixture's wavelengths for spectrally smooth models: the midpoint
/// quantiles (j + 1/2) / N of `band_density` over RGB_BAND_NM.
pub fn rgb_sampling_nodes() -> &'static [f64; RGB_SAMPLING_NODES] {
    static NODES: OnceLock<[f64; RGB_SAMPLING_NODES]> = OnceLock::new();
    NODES.get_or_init(|| {
        let (lo, hi) = RGB_BAND_NM;
        let steps = 4000;
        let h = (hi - lo) / steps as f64;
        let mut cdf = vec![0.0; steps + 1];
        for i in 0..steps {
            let a = lo + i as f64 * h;
            cdf[i + 1] = cdf[i] + 0.5 * h * (band_density(a) + band_density(a + h));
        }
        let total = cdf[steps];
        let mut nodes = [0.0; RGB_SAMPLING_NODES];
        for (j, node) in nodes.iter_mut().enumerate() {
            let target = (j as f64 + 0.5) / RGB_SAMPLING_NODES as f64 * total;
            let i = cdf.partition_point(|&c| c < target).clamp(1, steps);
            let frac = (target - cdf[i - 1]) / (cdf[i] - cdf[i - 1]);
            *node = lo + (i as f64 - 1.0 + frac) * h;
        }
        nodes
    })
}

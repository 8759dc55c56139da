//! Fixtures shared by the benchmarks (benches/brdf.rs), the run-time/error
//! survey (tools/stress) and the sampling measurements: one deterministic set
//! of direction pairs and the Cook-Torrance baseline, so that every ratio in
//! the docs is against the same work.

use crate::optics::fresnel::conductor_reflectance;
use glam::DVec3;
use std::f64::consts::PI;

pub use crate::sampling::SplitMix64;

/// `count` deterministic (wi, wo, lambda_nm) triples: half around the mirror
/// direction (where renders spend their evaluations), half uniform over the
/// hemisphere, wavelengths uniform over 380-780 nm.
pub fn direction_pairs(seed: u64, count: usize) -> Vec<(DVec3, DVec3, f64)> {
    let mut state = seed;
    let mut next = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64) / ((1u64 << 53) as f64)
    };
    (0..count)
        .map(|i| {
            let ct = 0.1 + 0.9 * next();
            let phi = 2.0 * PI * next();
            let st = (1.0 - ct * ct).sqrt();
            let wi = DVec3::new(st * phi.cos(), st * phi.sin(), ct);
            let wo = if i % 2 == 0 {
                let jitter = DVec3::new(0.3 * (next() - 0.5), 0.3 * (next() - 0.5), 0.0);
                (DVec3::new(-wi.x, -wi.y, wi.z) + jitter).normalize()
            } else {
                let ct = 0.05 + 0.95 * next();
                let phi = 2.0 * PI * next();
                let st = (1.0 - ct * ct).sqrt();
                DVec3::new(st * phi.cos(), st * phi.sin(), ct)
            };
            let lambda = 380.0 + 400.0 * next();
            (wi, wo, lambda)
        })
        .collect()
}

/// Cook-Torrance with a Beckmann distribution, Smith shadowing and the same
/// conductor Fresnel as the core: the baseline a renderer already pays for.
pub fn cook_torrance_beckmann(wi: DVec3, wo: DVec3, alpha: f64, eta: f64, k: f64) -> f64 {
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return 0.0;
    }
    let h = (wi + wo).normalize();
    let cos2 = h.z * h.z;
    let tan2 = (1.0 - cos2) / cos2;
    let a2 = alpha * alpha;
    let d = (-tan2 / a2).exp() / (PI * a2 * cos2 * cos2);
    let smith_g1 = |w: DVec3| {
        let tan = (1.0 - w.z * w.z).max(0.0).sqrt() / w.z;
        let a = 1.0 / (alpha * tan);
        if a >= 1.6 {
            1.0
        } else {
            (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)
        }
    };
    let f = conductor_reflectance(wi.dot(h), eta, k);
    f * d * smith_g1(wi) * smith_g1(wo) / (4.0 * wi.z * wo.z)
}

/// Mean and unbiased variance of estimates (the sampling measurements').
pub fn mean_var(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0);
    (mean, var)
}

/// The sampling measurements' materials (examples sampling_variance and
/// spectral_strategy; docs/sampling.md's tables): name and JSON, fresnel
/// 0.9.
pub const SAMPLING_MATERIALS: [(&str, &str); 7] = [
    ("compact disc", r#"{"surface":"cd","fresnel":0.9}"#),
    (
        "smooth Gaussian",
        r#"{"surface":"gaussian","sigma_um":0.02,"corr_um":5,"fresnel":0.9}"#,
    ),
    (
        "medium Gaussian",
        r#"{"surface":"gaussian","sigma_um":0.14,"corr_um":2,"fresnel":0.9}"#,
    ),
    (
        "rough Gaussian",
        r#"{"surface":"gaussian","sigma_um":0.5,"corr_um":3,"fresnel":0.9}"#,
    ),
    (
        "anisotropic",
        r#"{"surface":"gaussian","sigma_um":0.08,"corr_x_um":2,"corr_y_um":10,"fresnel":0.9}"#,
    ),
    (
        "fractal H=0.7",
        r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.05,"lag_um":1,"fresnel":0.9}"#,
    ),
    (
        "fractal H=0.35",
        r#"{"surface":"fractal","hurst":0.35,"sigma_um":0.2,"lag_um":1,"fresnel":0.9}"#,
    ),
];

/// A standard normal deviate (Box-Muller).
fn normal(rng: &mut SplitMix64) -> f64 {
    let [a, b, _] = rng.three();
    (-2.0 * (1.0 - a).ln()).sqrt() * (2.0 * PI * b).cos()
}

/// An n x n height map (um, rows along y) of stationary Gaussian heights
/// with the radial power spectrum `psd(|q|)` (q in rad/um: the 2-D Fourier
/// transform of the correlation function), by filtering white noise on
/// the torus; rescaled to rms `sigma` when given. The height-map model's
/// tests and benchmarks draw their maps from it.
pub fn synthetic_height_map(
    n: usize,
    pixel_um: f64,
    seed: u64,
    psd: impl Fn(f64) -> f64,
    sigma: Option<f64>,
) -> Vec<f64> {
    use num_complex::Complex;
    let mut rng = SplitMix64(seed);
    let mut data: Vec<Complex<f64>> = (0..n * n)
        .map(|_| Complex::new(normal(&mut rng), 0.0))
        .collect();
    let mut planner = rustfft::FftPlanner::<f64>::new();
    let (fft, ifft) = (planner.plan_fft_forward(n), planner.plan_fft_inverse(n));
    fft2(&mut data, n, |d| fft.process(d));
    let side = n as f64 * pixel_um;
    let freq = |i: usize| if i < n / 2 { i as f64 } else { i as f64 - n as f64 } / side;
    for j in 0..n {
        for i in 0..n {
            let q = 2.0 * PI * (freq(i).powi(2) + freq(j).powi(2)).sqrt();
            // White noise of unit variance per sample has the spectral
            // density pixel^2; the filter makes it psd.
            data[j * n + i] *= (psd(q) / (pixel_um * pixel_um)).sqrt();
        }
    }
    fft2(&mut data, n, |d| ifft.process(d));
    let mut h: Vec<f64> = data.iter().map(|z| z.re / (n * n) as f64).collect();
    let mean = h.iter().sum::<f64>() / h.len() as f64;
    h.iter_mut().for_each(|x| *x -= mean);
    if let Some(sigma) = sigma {
        let rms = (h.iter().map(|x| x * x).sum::<f64>() / h.len() as f64).sqrt();
        h.iter_mut().for_each(|x| *x *= sigma / rms);
    }
    h
}

/// The 2-D FFT of an n x n array, rows then columns.
fn fft2(
    data: &mut [num_complex::Complex<f64>],
    n: usize,
    fft: impl Fn(&mut [num_complex::Complex<f64>]),
) {
    fft(data);
    let mut t = data.to_vec();
    for j in 0..n {
        for i in 0..n {
            t[i * n + j] = data[j * n + i];
        }
    }
    fft(&mut t);
    for j in 0..n {
        for i in 0..n {
            data[i * n + j] = t[j * n + i];
        }
    }
}

/// The spectrum of the Gaussian correlation sigma^2 exp(-r^2 / T^2).
pub fn gaussian_psd(sigma_um: f64, t_um: f64) -> impl Fn(f64) -> f64 {
    move |q| PI * t_um * t_um * sigma_um * sigma_um * (-q * q * t_um * t_um / 4.0).exp()
}

/// An ny x nx map (rows along y) as a little-endian f8 .npy file's bytes.
pub fn npy_bytes(nx: usize, ny: usize, values: &[f64]) -> Vec<u8> {
    let mut header = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({ny}, {nx}), }}");
    // The data starts at a multiple of 64 bytes, the header ends with '\n'.
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend((header.len() as u16).to_le_bytes());
    bytes.extend(header.as_bytes());
    for v in values {
        bytes.extend(v.to_le_bytes());
    }
    bytes
}

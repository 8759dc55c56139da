//! Height-field synthesis on a periodic nx x ny grid of spacing dx (um) by
//! filtering complex white noise with the square root of a target power
//! spectrum, and the exact ensemble covariance of what is synthesised.
//!
//! h_j = Re or Im of sum_m a_m xi_m exp(i K_m . x_j), xi_m complex normal with
//! independent N(0, 1) real and imaginary parts, a_m = sqrt(S_h(K_m) / (Lx Ly)).
//! Re and Im are two independent realisations with covariance
//! C(r) = sum_m a_m^2 cos(K_m . r) (for S_h(K) = S_h(-K)).

use crate::fft2::Fft2;
use crate::rng::Rng;
use num_complex::Complex64;
use std::f64::consts::PI;

#[derive(Clone, Copy, Debug)]
pub struct Grid {
    pub nx: usize,
    pub ny: usize,
    pub dx: f64,
}

impl Grid {
    pub fn len(&self) -> usize {
        self.nx * self.ny
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn lx(&self) -> f64 {
        self.nx as f64 * self.dx
    }
    pub fn ly(&self) -> f64 {
        self.ny as f64 * self.dx
    }
    /// Signed frequency index of FFT bin i of n.
    pub fn signed(i: usize, n: usize) -> i64 {
        if 2 * i < n {
            i as i64
        } else {
            i as i64 - n as i64
        }
    }
    /// Angular spatial frequency (1/um) of FFT bin (ix, iy).
    pub fn q(&self, ix: usize, iy: usize) -> (f64, f64) {
        (
            2.0 * PI * Grid::signed(ix, self.nx) as f64 / self.lx(),
            2.0 * PI * Grid::signed(iy, self.ny) as f64 / self.ly(),
        )
    }
    /// Nyquist frequency pi / dx.
    pub fn q_nyquist(&self) -> f64 {
        PI / self.dx
    }
    /// Signed lag (um) of grid offset (ix, iy) on the torus.
    pub fn lag(&self, ix: usize, iy: usize) -> (f64, f64) {
        (
            Grid::signed(ix, self.nx) as f64 * self.dx,
            Grid::signed(iy, self.ny) as f64 * self.dx,
        )
    }
}

/// Target statistics of a random surface.
#[derive(Clone, Copy, Debug)]
pub enum RandomModel {
    /// C(x, y) = sigma^2 exp(-x^2/Tx^2 - y^2/Ty^2).
    Gaussian { sigma: f64, tx: f64, ty: f64 },
    /// Fractional Brownian: D(r) = s^2 (r / lag)^(2H), by the power law
    /// S_h(K) = c |K|^-(2H+2) with the continuum constant c (checked by
    /// measurement, not trusted).
    Fbm { hurst: f64, s: f64, lag: f64 },
}

pub use stam::special::ln_gamma;

impl RandomModel {
    /// Power spectrum S_h(K) (um^4), Fourier convention S = int C exp(-i K.r) d^2r.
    pub fn power(&self, kx: f64, ky: f64) -> f64 {
        match *self {
            RandomModel::Gaussian { sigma, tx, ty } => {
                sigma
                    * sigma
                    * PI
                    * tx
                    * ty
                    * (-(kx * kx * tx * tx + ky * ky * ty * ty) / 4.0).exp()
            }
            RandomModel::Fbm { hurst, s, lag } => {
                let k2 = kx * kx + ky * ky;
                if k2 == 0.0 {
                    return 0.0;
                }
                // D(r) = (c / pi) r^(2H) I_H with
                // I_H = int_0^inf (1 - J0(x)) x^(-1-2H) dx = Gamma(1-H) / (2H 4^H Gamma(1+H)).
                let ln_i = ln_gamma(1.0 - hurst)
                    - ln_gamma(1.0 + hurst)
                    - (2.0 * hurst).ln()
                    - hurst * 4f64.ln();
                let c = PI * s * s * lag.powf(-2.0 * hurst) / ln_i.exp();
                c * k2.powf(-(hurst + 1.0))
            }
        }
    }
}

/// A synthesiser: the filter amplitudes a_m on the grid and an FFT plan.
pub struct Synth {
    pub grid: Grid,
    pub amp: Vec<f64>,
    buf: Vec<Complex64>,
}

impl Synth {
    pub fn new(grid: Grid, model: &RandomModel) -> Synth {
        let norm = 1.0 / (grid.lx() * grid.ly());
        let mut amp = vec![0.0; grid.len()];
        for iy in 0..grid.ny {
            for ix in 0..grid.nx {
                let (kx, ky) = grid.q(ix, iy);
                amp[iy * grid.nx + ix] = (model.power(kx, ky) * norm).sqrt();
            }
        }
        Synth {
            grid,
            amp,
            buf: vec![Complex64::new(0.0, 0.0); grid.len()],
        }
    }

    /// Two independent realisations (real and imaginary part of one transform).
    pub fn pair(&mut self, rng: &mut Rng, fft: &mut Fft2) -> (Vec<f64>, Vec<f64>) {
        for (z, a) in self.buf.iter_mut().zip(&self.amp) {
            *z = Complex64::new(a * rng.normal(), a * rng.normal());
        }
        fft.inverse(&mut self.buf);
        (
            self.buf.iter().map(|z| z.re).collect(),
            self.buf.iter().map(|z| z.im).collect(),
        )
    }

    /// Exact covariance of the synthesised process, C(r_j) = sum a_m^2 cos(K_m r_j),
    /// on the lag grid (same indexing as the field).
    pub fn ensemble_covariance(&self, fft: &mut Fft2) -> Vec<f64> {
        let mut b: Vec<Complex64> = self
            .amp
            .iter()
            .map(|a| Complex64::new(a * a, 0.0))
            .collect();
        fft.inverse(&mut b);
        b.iter().map(|z| z.re).collect()
    }
}

/// Circular sample autocovariance of one field: C_s(r) = mean_x h(x) h(x + r).
pub fn sample_covariance(h: &[f64], fft: &mut Fft2) -> Vec<f64> {
    let n = h.len() as f64;
    let mut b: Vec<Complex64> = h.iter().map(|&x| Complex64::new(x, 0.0)).collect();
    fft.forward(&mut b);
    for z in b.iter_mut() {
        *z = Complex64::new(z.norm_sqr(), 0.0);
    }
    fft.inverse(&mut b);
    b.iter().map(|z| z.re / (n * n)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ln_gamma_values() {
        assert!((ln_gamma(1.0)).abs() < 1e-13);
        assert!((ln_gamma(0.5) - PI.sqrt().ln()).abs() < 1e-13);
        assert!((ln_gamma(5.0) - 24f64.ln()).abs() < 1e-12);
        assert!((ln_gamma(0.3) - 1.095_797_994_818_075_2).abs() < 1e-12);
    }
}

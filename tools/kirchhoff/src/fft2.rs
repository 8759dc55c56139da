//! 2-D complex FFT on a row-major nx x ny grid (index iy * nx + ix) with
//! rustfft: batched row transforms, a transpose, batched column transforms.
//! Unnormalised in both directions, rustfft's sign convention
//! (forward: sum_j x_j exp(-2 pi i m j / n)).

use num_complex::Complex64;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

pub struct Fft2 {
    pub nx: usize,
    pub ny: usize,
    fwd_x: Arc<dyn Fft<f64>>,
    fwd_y: Arc<dyn Fft<f64>>,
    inv_x: Arc<dyn Fft<f64>>,
    inv_y: Arc<dyn Fft<f64>>,
    transposed: Vec<Complex64>,
    scratch: Vec<Complex64>,
}

impl Fft2 {
    pub fn new(nx: usize, ny: usize) -> Fft2 {
        let mut planner = FftPlanner::new();
        let fwd_x = planner.plan_fft_forward(nx);
        let fwd_y = planner.plan_fft_forward(ny);
        let inv_x = planner.plan_fft_inverse(nx);
        let inv_y = planner.plan_fft_inverse(ny);
        let scratch_len = [&fwd_x, &fwd_y, &inv_x, &inv_y]
            .iter()
            .map(|f| f.get_inplace_scratch_len())
            .max()
            .unwrap_or(0);
        Fft2 {
            nx,
            ny,
            fwd_x,
            fwd_y,
            inv_x,
            inv_y,
            transposed: vec![Complex64::new(0.0, 0.0); nx * ny],
            scratch: vec![Complex64::new(0.0, 0.0); scratch_len],
        }
    }

    pub fn forward(&mut self, data: &mut [Complex64]) {
        self.run(data, false)
    }

    pub fn inverse(&mut self, data: &mut [Complex64]) {
        self.run(data, true)
    }

    fn run(&mut self, data: &mut [Complex64], inverse: bool) {
        let (nx, ny) = (self.nx, self.ny);
        assert_eq!(data.len(), nx * ny);
        let (fx, fy) = if inverse {
            (&self.inv_x, &self.inv_y)
        } else {
            (&self.fwd_x, &self.fwd_y)
        };
        fx.process_with_scratch(data, &mut self.scratch);
        transpose(data, &mut self.transposed, nx, ny);
        fy.process_with_scratch(&mut self.transposed, &mut self.scratch);
        transpose(&self.transposed, data, ny, nx);
    }
}

/// out[x * rows + y] = inp[y * cols + x] for an input of `rows` rows of `cols`.
fn transpose(inp: &[Complex64], out: &mut [Complex64], cols: usize, rows: usize) {
    const B: usize = 32;
    for y0 in (0..rows).step_by(B) {
        for x0 in (0..cols).step_by(B) {
            for y in y0..(y0 + B).min(rows) {
                for x in x0..(x0 + B).min(cols) {
                    out[x * rows + y] = inp[y * cols + x];
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn matches_direct_dft_and_inverts() {
        let (nx, ny) = (6, 10);
        let data: Vec<Complex64> = (0..nx * ny)
            .map(|j| Complex64::new((j as f64 * 0.37).sin(), (j as f64 * 0.11).cos()))
            .collect();
        let mut f = data.clone();
        let mut plan = Fft2::new(nx, ny);
        plan.forward(&mut f);
        for my in 0..ny {
            for mx in 0..nx {
                let mut acc = Complex64::new(0.0, 0.0);
                for y in 0..ny {
                    for x in 0..nx {
                        let ph =
                            -2.0 * PI * ((mx * x) as f64 / nx as f64 + (my * y) as f64 / ny as f64);
                        acc += data[y * nx + x] * Complex64::from_polar(1.0, ph);
                    }
                }
                assert!((acc - f[my * nx + mx]).norm() < 1e-10);
            }
        }
        plan.inverse(&mut f);
        for (a, b) in f.iter().zip(&data) {
            assert!((a / (nx * ny) as f64 - b).norm() < 1e-12);
        }
    }
}

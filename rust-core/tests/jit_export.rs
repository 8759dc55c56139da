//! The JIT export (docs/jit.md, prototype): the rule "gaussian-v1" run on
//! the CPU from the exported floats alone (no other access to the core)
//! against `Brdf::eval_spectral`, at random and grazing directions and
//! random wavelengths, for Gaussian materials from very smooth to very
//! rough, isotropic and anisotropic, with a constant reflectance, a
//! constant complex index and measured metals. The same rule is what
//! scripts/jit_prototype.py executes with Dr.Jit.

// `!(x < y)` rejects NaN along with the out-of-range values, as in the core.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use glam::DVec3;
use stam::material::jit::slot;
use stam::Brdf;
use std::f64::consts::PI;

/// The rule "gaussian-v1" of docs/jit.md, spelled out on plain f64.
struct Rule<'a> {
    e: &'a [f32],
}

impl Rule<'_> {
    fn h(&self, slot: usize) -> f64 {
        self.e[slot] as f64
    }

    fn at(&self, slot: usize) -> usize {
        self.e[slot] as usize
    }

    /// Cubic B-spline weights at fraction t (coefficients i-1 .. i+2).
    fn bspline(t: f64) -> [f64; 4] {
        let s = 1.0 - t;
        [
            s * s * s / 6.0,
            0.5 * t * t * t - t * t + 2.0 / 3.0,
            -0.5 * t * t * t + 0.5 * (t * t + t) + 1.0 / 6.0,
            t * t * t / 6.0,
        ]
    }

    /// S(g, x): the table, the small-g sum below it, the 1/g expansion
    /// above it, 0 beyond its rho range.
    fn series(&self, g: f64, x: f64) -> f64 {
        let (g_min, g_max) = (self.h(slot::SERIES_G_MIN), self.h(slot::SERIES_G_MAX));
        if g < g_min {
            let ln_g = g.ln();
            let mut s = 0.0;
            let mut ln_fact = 0.0;
            for m in 1..=self.at(slot::SMALL_G_TERMS) {
                let m = m as f64;
                ln_fact += m.ln();
                s += (-g + m * ln_g - ln_fact - x / m - m.ln()).exp();
            }
            return s;
        }
        if g >= g_max {
            let y = x / g;
            return (-y).exp() / g * (1.0 + (y * y - 4.0 * y + 2.0) / (2.0 * g));
        }
        let rho = (x / (1.0 + g)).sqrt();
        if !(rho < self.h(slot::SERIES_RHO_MAX)) {
            return 0.0;
        }
        let (n_g, n_rho) = (self.at(slot::SERIES_N_G), self.at(slot::SERIES_N_RHO));
        let fg = (g.ln() - self.h(slot::SERIES_LN_G_MIN)) / self.h(slot::SERIES_D_LN_G) + 1.0;
        let fx = rho / self.h(slot::SERIES_D_RHO) + 1.0;
        let ig = (fg.floor().max(0.0) as usize).clamp(1, n_g - 3);
        let ix = (fx.floor().max(0.0) as usize).clamp(1, n_rho - 3);
        let wg = Self::bspline(fg - ig as f64);
        let wx = Self::bspline(fx - ix as f64);
        let base = self.at(slot::SERIES_OFFSET);
        let mut ln_s = 0.0;
        for (a, wa) in wg.iter().enumerate() {
            for (b, wb) in wx.iter().enumerate() {
                let c = self.e[base + (ig - 1 + a) * n_rho + ix - 1 + b] as f64;
                ln_s += wa * wb * c;
            }
        }
        ln_s.exp()
    }

    /// F^2 at the half-vector cosine: Catmull-Rom over sqrt(cos), linear
    /// between the wavelength rows.
    fn fresnel(&self, cos: f64, lambda: f64) -> f64 {
        let steps = self.at(slot::FRESNEL_COS_STEPS);
        let q = cos.clamp(0.0, 1.0).sqrt() * steps as f64;
        let i = (q.floor() as usize).min(steps - 1);
        let t = q - i as f64;
        let (t2, t3) = (t * t, t * t * t);
        let w = [
            0.5 * (-t3 + 2.0 * t2 - t),
            0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
            0.5 * (-3.0 * t3 + 4.0 * t2 + t),
            0.5 * (t3 - t2),
        ];
        let rows = self.at(slot::FRESNEL_ROWS);
        let xs = &self.e[self.at(slot::FRESNEL_LAMBDA_OFFSET)..][..rows];
        let x = |r: usize| xs[r] as f64;
        let lam = lambda.clamp(x(0), x(rows - 1));
        let row_of_nm = &self.e[self.at(slot::FRESNEL_ROW_OF_NM_OFFSET)..]
            [..self.at(slot::FRESNEL_ROW_OF_NM_LEN)];
        let mut r = row_of_nm[((lam - x(0)).floor() as usize).min(row_of_nm.len() - 1)] as usize;
        for _ in 0..self.at(slot::FRESNEL_MAX_ROW_STEPS) {
            if r + 2 < rows && x(r + 1) <= lam {
                r += 1;
            }
        }
        let row = |r: usize| -> f64 {
            let base = self.at(slot::FRESNEL_OFFSET) + r * (steps + 1);
            (0..4)
                .map(|j| {
                    let col = (i as i64 - 1 + j as i64).clamp(0, steps as i64) as usize;
                    w[j] * self.e[base + col] as f64
                })
                .sum()
        };
        let tl = ((lam - x(r)) / (x(r + 1) - x(r))).clamp(0.0, 1.0);
        let (lo, hi) = (row(r), row(r + 1));
        lo + tl * (hi - lo)
    }

    /// f(wi, wo; lambda) without the coherent lobe and the cosine.
    fn eval(&self, wi: DVec3, wo: DVec3, lambda: f64) -> f64 {
        if !(lambda >= self.h(slot::LAMBDA_MIN_NM) && lambda <= self.h(slot::LAMBDA_MAX_NM)) {
            return 0.0;
        }
        let (wi, wo) = (wi.normalize(), wo.normalize());
        if !(wi.z > 1e-12 && wo.z > 1e-12) {
            return 0.0;
        }
        let (u, v, w) = (-(wi.x + wo.x), -(wi.y + wo.y), -(wi.z + wo.z));
        // 1 + wi . wo as |wi + wo|^2 / 2 (no cancellation near the grazing
        // mirror in f32 executors).
        let d = 0.5 * (u * u + v * v + w * w);
        let geometric = d * d / (wi.z * wo.z);
        let cos_half = (0.5 * d).max(0.0).sqrt();
        let k = 2.0 * PI * 1000.0 / lambda;
        let (sigma, tx, ty) = (
            self.h(slot::SIGMA_UM),
            self.h(slot::CORR_X_UM),
            self.h(slot::CORR_Y_UM),
        );
        let g = (k * sigma * w).powi(2);
        let x = 0.25 * k * k * ((tx * u).powi(2) + (ty * v).powi(2));
        let kernel = k * k * tx * ty / (4.0 * PI * w * w) * self.series(g, x);
        let f = self.fresnel(cos_half, lambda) * geometric * kernel;
        if f > 0.0 {
            f
        } else {
            0.0
        }
    }
}

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn direction(&mut self, min_z: f64, max_z: f64) -> DVec3 {
        let z = min_z + (max_z - min_z) * self.next();
        let phi = 2.0 * PI * self.next();
        let r = (1.0 - z * z).max(0.0).sqrt();
        DVec3::new(r * phi.cos(), r * phi.sin(), z)
    }
}

#[test]
fn exported_rule_matches_the_core() {
    let materials = [
        r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2.0}"#,
        r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2.0,"fresnel":0.8}"#,
        r#"{"surface":"gaussian","sigma_um":0.5,"corr_um":5.0,"fresnel":"gold"}"#,
        r#"{"surface":"gaussian","sigma_um":0.02,"corr_um":1.0,"fresnel":"copper"}"#,
        r#"{"surface":"gaussian","sigma_um":0.001,"corr_um":0.5,"fresnel":"silver"}"#,
        r#"{"surface":"gaussian","sigma_um":0.15,"corr_x_um":1.0,"corr_y_um":15.0}"#,
        r#"{"surface":"gaussian","sigma_um":1.2,"corr_um":6.0,"fresnel":{"eta":1.5,"k":3.0}}"#,
        r#"{"surface":"gaussian","sigma_um":8.0,"corr_um":40.0,"fresnel":0.9}"#,
        r#"{"surface":"gaussian","sigma_um":0.3,"corr_um":0.2,"series_tolerance":1e-8}"#,
    ];
    let mut rng = Rng(7);
    for json in materials {
        let brdf = Brdf::from_json(json).unwrap();
        let e = brdf.jit_export().expect("Gaussian materials export");
        assert_eq!(e[slot::FORMAT], 1.0);
        assert_eq!(e[slot::MODEL], 1.0);
        assert_eq!(e[slot::TOTAL_LEN] as usize, e.len());
        let rule = Rule { e: &e };
        let mut cases = Vec::new();
        for i in 0..40_000 {
            // Random pairs, grazing ones (either direction below 5 degrees
            // of the horizon) and pairs near the mirror direction.
            let wi = if i % 4 == 1 {
                rng.direction(1e-4, 0.09)
            } else {
                rng.direction(0.0, 1.0)
            };
            let wo = match i % 4 {
                2 => rng.direction(1e-4, 0.09),
                3 => (DVec3::new(-wi.x, -wi.y, wi.z) + 0.05 * rng.direction(-1.0, 1.0)).normalize(),
                _ => rng.direction(0.0, 1.0),
            };
            let lambda = 360.0 + 470.0 * rng.next();
            cases.push((wi, wo, lambda, brdf.eval_spectral(wi, wo, lambda)));
        }
        let peak = cases.iter().map(|c| c.3).fold(0.0, f64::max);
        assert!(peak > 0.0);
        let (mut worst, mut checked, mut worst_at) = (0.0f64, 0, None);
        for &(wi, wo, lambda, core) in &cases {
            let got = rule.eval(wi, wo, lambda);
            assert!(got.is_finite() && got >= 0.0);
            if core < 1e-6 * peak {
                // Below the threshold: only no spurious value above it.
                assert!(got < 2e-6 * peak, "{json}: {got} where the core has {core}");
                continue;
            }
            checked += 1;
            let err = (got - core).abs() / core;
            if err > worst {
                worst = err;
                worst_at = Some((wi, wo, lambda));
            }
        }
        println!("{json}: {checked} pairs above 1e-6 of the peak, worst relative error {worst:.2e} at {worst_at:?}");
        assert!(checked > 1000, "{json}: only {checked} pairs checked");
        assert!(worst < 1e-4, "{json}: worst {worst:.3e} at {worst_at:?}");
        // Bad input behaves as in the core: 0.
        let up = DVec3::Z;
        assert_eq!(rule.eval(up, DVec3::new(0.0, 0.0, -1.0), 500.0), 0.0);
        assert_eq!(rule.eval(up, up, 0.0), 0.0);
        assert_eq!(rule.eval(DVec3::new(f64::NAN, 0.0, 1.0), up, 500.0), 0.0);
    }
    // What the prototype does not cover has no export.
    for json in [
        r#"{"surface":"fractal","hurst":0.5,"sigma_um":0.1,"lag_um":1.0}"#,
        r#"{"surface":"gaussian","sigma_um":0.1,"corr_um":2.0,"energy":"conserving"}"#,
    ] {
        assert!(
            Brdf::from_json(json).unwrap().jit_export().is_none(),
            "{json}"
        );
    }
}

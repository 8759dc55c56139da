//! Tests of the periodic-surface model. Oracles are closed forms, direct
//! numerical integrals written here independently of the module, literature
//! values of Bessel functions and fine-grid wavelength integration.

use super::*;
use glam::DVec3;
use std::time::Instant;

/// CPU time of this thread in ns (from /proc/thread-self/schedstat), so that
/// timings are not inflated by other processes on a busy machine; falls back
/// to wall time.
fn cpu_ns() -> f64 {
    static START: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
    if let Ok(s) = std::fs::read_to_string("/proc/thread-self/schedstat") {
        if let Some(Ok(v)) = s.split_whitespace().next().map(|t| t.parse::<f64>()) {
            return v;
        }
    }
    START.get_or_init(Instant::now).elapsed().as_nanos() as f64
}

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.next()
    }
}

fn cd(l: f64) -> PeriodicSurface {
    PeriodicSurface::new(
        2.5,
        l,
        Profile::Rect {
            height_um: 0.15,
            width_um: 0.5,
        },
    )
    .unwrap()
}

/// Closed form of the physics notes for the rectangular bump.
fn rect_closed(n: i64, beta: f64, b: f64, d: f64, lam: f64) -> f64 {
    let f = d / lam;
    if n == 0 {
        let re = 1.0 + ((beta * b).cos() - 1.0) * f;
        let im = (beta * b).sin() * f;
        return re * re + im * im;
    }
    let x = n as f64 * f;
    let sinc = (PI * x).sin() / (PI * x);
    4.0 * (beta * b / 2.0).sin().powi(2) * f * f * sinc * sinc
}

/// Composite Simpson of a complex integrand on [a, b].
fn simpson(a: f64, b: f64, m: usize, f: impl Fn(f64) -> Complex64) -> Complex64 {
    let m = m + m % 2;
    let h = (b - a) / m as f64;
    let mut s = f(a) + f(b);
    for i in 1..m {
        let w = if i % 2 == 1 { 4.0 } else { 2.0 };
        s += f(a + i as f64 * h) * w;
    }
    s * (h / 3.0)
}

/// c_n by direct numerical integration over the smooth pieces of h.
fn c_numeric(
    h: &dyn Fn(usize, f64) -> f64,
    breaks: &[f64],
    lam: f64,
    n: i64,
    beta: f64,
) -> Complex64 {
    let mut acc = Complex64::new(0.0, 0.0);
    for (i, p) in breaks.windows(2).enumerate() {
        acc += simpson(p[0], p[1], 4000, |x| {
            Complex64::from_polar(1.0, beta * h(i, x) - 2.0 * PI * n as f64 * x / lam)
        });
    }
    acc / lam
}

/// J_n(x) = (1 / 2 pi) int_0^{2 pi} cos(n t - x sin t) dt, trapezoid rule
/// (exponentially convergent for this periodic integrand).
fn bessel_integral(n: i64, x: f64) -> f64 {
    let m = 4096;
    let mut s = 0.0;
    for i in 0..m {
        let t = 2.0 * PI * i as f64 / m as f64;
        s += (n as f64 * t - x * t.sin()).cos();
    }
    s / m as f64
}

#[test]
fn bessel_matches_literature_values_and_integral() {
    // Abramowitz & Stegun / standard tables.
    let cases = [
        (0usize, 1.0, 0.765_197_686_557_966_6),
        (1, 1.0, 0.440_050_585_744_933_5),
        (5, 10.0, -0.234_061_528_186_793_6),
        (0, 100.0, 0.019_985_850_304_223_12),
        (100, 100.0, 0.096_366_673_295_861_55),
    ];
    for (n, x, want) in cases {
        let got = bessel_j_row(x, n)[n];
        println!("J_{n}({x}) = {got:.16} (table {want})");
        assert!(
            (got - want).abs() < 1e-13,
            "J_{n}({x}) = {got}, want {want}"
        );
    }
    let mut worst: f64 = 0.0;
    for &x in &[0.0, 1e-6, 0.3, 2.6, 17.0, 55.5, 120.0] {
        let row = bessel_j_row(x, 300);
        for n in [0usize, 1, 2, 7, 30, 99, 150, 300] {
            worst = worst.max((row[n] - bessel_integral(n as i64, x)).abs());
        }
    }
    println!("Bessel row vs integral: worst abs error {worst:.2e}");
    assert!(worst < 1e-13);
}

#[test]
fn rect_power_matches_closed_form_and_integration() {
    let (b, d, lam) = (0.15, 0.5, 2.5);
    let s = cd(10.0);
    let h = |piece: usize, _x: f64| if piece == 0 { b } else { 0.0 };
    let mut worst_closed: f64 = 0.0;
    let mut worst_num: f64 = 0.0;
    for &beta in &[-34.9, -20.0, -7.3, -1.0, -1e-3, 0.0, 3.0] {
        for n in -12..=12 {
            let got = s.order_power(n, beta);
            let closed = rect_closed(n, beta, b, d, lam);
            let num = c_numeric(&h, &[0.0, d, lam], lam, n, beta).norm_sqr();
            worst_closed = worst_closed.max((got - closed).abs());
            worst_num = worst_num.max((got - num).abs());
        }
    }
    println!("rect |c_n|^2: vs closed form {worst_closed:.2e}, vs integration {worst_num:.2e}");
    assert!(worst_closed < 1e-14);
    assert!(worst_num < 1e-12);
}

#[test]
fn sine_power_matches_bessel_and_integration() {
    let lam = 1.6;
    let mut worst_closed: f64 = 0.0;
    let mut worst_num: f64 = 0.0;
    for &b in &[0.1, 0.4, 1.3] {
        let s = PeriodicSurface::new(lam, 40.0, Profile::Sine { height_um: b }).unwrap();
        let h = move |x: f64| 0.5 * b * (1.0 + (2.0 * PI * x / lam).cos());
        let mut rng = Rng(0x1234_5678 + (b * 1000.0) as u64);
        for _ in 0..40 {
            let beta = rng.range(-BETA_MAX, 0.0);
            for n in -10..=10 {
                let got = s.order_power(n, beta);
                let closed = bessel_integral(n, beta * b / 2.0).powi(2);
                // Smooth periodic integrand: the trapezoid rule is spectrally accurate.
                let m = 2048;
                let mut c = Complex64::new(0.0, 0.0);
                for i in 0..m {
                    let x = lam * i as f64 / m as f64;
                    c += Complex64::from_polar(1.0, beta * h(x) - 2.0 * PI * n as f64 * x / lam);
                }
                let num = (c / m as f64).norm_sqr();
                worst_closed = worst_closed.max((got - closed).abs());
                worst_num = worst_num.max((got - num).abs());
            }
        }
    }
    println!("sine |c_n|^2 (table): vs J_n^2 {worst_closed:.2e}, vs integration {worst_num:.2e}");
    assert!(worst_closed < 2e-9);
    assert!(worst_num < 2e-9);
}

fn wavy_profile(n: usize) -> Vec<f64> {
    // Asymmetric, non-trivial: a blazed-like profile with a harmonic.
    (0..n)
        .map(|j| {
            let x = j as f64 / n as f64;
            0.3 * x * x * (1.0 - x) * 4.0 + 0.05 * (6.0 * PI * x).sin()
        })
        .collect()
}

#[test]
fn parseval_for_all_profiles() {
    let surfaces = [
        cd(5.0),
        PeriodicSurface::new(3.0, 20.0, Profile::Sine { height_um: 0.8 }).unwrap(),
        PeriodicSurface::new(
            4.0,
            20.0,
            Profile::Tabulated {
                heights_um: wavy_profile(64),
            },
        )
        .unwrap(),
        PeriodicSurface::new(
            2.0,
            20.0,
            Profile::Tabulated {
                heights_um: wavy_profile(33),
            },
        )
        .unwrap(),
    ];
    for (i, s) in surfaces.iter().enumerate() {
        let mut worst: f64 = 0.0;
        for &beta in &[0.0, -0.7, -5.0, -17.0, -34.0, -50.0, 4.0] {
            // Rect: slow 1/n^2 tail, sum far; the others decay fast (sine:
            // J_n(x) for n >> x; samples model: 0 beyond N/2).
            let reach = if i == 0 { 20000 } else { 2000 };
            let total: f64 = (-reach..=reach).map(|n| s.order_power(n, beta)).sum();
            worst = worst.max((total - 1.0).abs());
        }
        println!("profile {i}: Parseval worst |sum - 1| = {worst:.2e}");
        // Rect: the closed-form tail beyond |n| = 20000 is ~ 1 / (pi^2 n f) ~ 5e-6 of
        // 4 f^2 sin^2; the table profiles: interpolation error of the table.
        assert!(worst < 2e-5, "profile {i}: {worst}");
    }
}

#[test]
fn tabulated_reproduces_rect_and_sine() {
    // Rect sampled at N points with the edges on samples: |DFT_n|^2 / |c_n|^2 =
    // (pi n / N)^2 / sin^2(pi n / N) ~ 1 + (pi n / N)^2 / 3 for n != 0 (Dirichlet
    // kernel instead of sinc); order 0 is exact.
    let (b, d, lam) = (0.15, 0.5, 2.5);
    let big_n = 1000;
    let heights: Vec<f64> = (0..big_n)
        .map(|j| {
            if (j as f64) < d / lam * big_n as f64 {
                b
            } else {
                0.0
            }
        })
        .collect();
    let tab = PeriodicSurface::new(
        lam,
        30.0,
        Profile::Tabulated {
            heights_um: heights,
        },
    )
    .unwrap();
    let mut worst: f64 = 0.0;
    for &beta in &[-30.0, -12.0, -3.3, -0.5] {
        for n in -13..=13i64 {
            let want = rect_closed(n, beta, b, d, lam);
            let got = tab.order_power(n, beta);
            let bound = 1e-9 + want * 1.1 * (PI * n as f64 / big_n as f64).powi(2) / 3.0;
            worst = worst.max((got - want).abs() / bound.max(1e-300));
            assert!(
                (got - want).abs() <= bound,
                "n {n} beta {beta}: {got} vs {want}"
            );
        }
    }
    println!("tabulated rect: worst error / documented bound = {worst:.3}");
    // Sine sampled at 128 points: the DFT aliases c_{n +- 128}, negligible here.
    let bs = 0.6;
    let lam = 1.7;
    let heights: Vec<f64> = (0..128)
        .map(|j| 0.5 * bs * (1.0 + (2.0 * PI * j as f64 / 128.0).cos()))
        .collect();
    let tab = PeriodicSurface::new(
        lam,
        30.0,
        Profile::Tabulated {
            heights_um: heights,
        },
    )
    .unwrap();
    let mut worst: f64 = 0.0;
    for &beta in &[-34.0, -21.0, -8.0, -1.0] {
        for n in -9..=9 {
            let want = bessel_integral(n, beta * bs / 2.0).powi(2);
            worst = worst.max((tab.order_power(n, beta) - want).abs());
        }
    }
    println!("tabulated sine: worst abs error {worst:.2e}");
    assert!(worst < 2e-9);
}

#[test]
fn table_interpolation_matches_direct_evaluation() {
    let surfaces = [
        PeriodicSurface::new(10.0, 40.0, Profile::Sine { height_um: 2.0 }).unwrap(),
        PeriodicSurface::new(
            6.0,
            40.0,
            Profile::Tabulated {
                heights_um: wavy_profile(200),
            },
        )
        .unwrap(),
    ];
    let mut rng = Rng(99);
    for (i, s) in surfaces.iter().enumerate() {
        let mut worst: f64 = 0.0;
        for _ in 0..300 {
            let beta = rng.range(-BETA_MAX, 0.0);
            let n = (rng.range(-30.0, 30.0)) as i64;
            let got = s.order_power(n, beta);
            let want = s.direct_power(n, beta);
            worst = worst.max((got - want).abs());
        }
        println!(
            "surface {i}: table vs direct worst abs {worst:.2e}, memory {} bytes",
            s.memory_bytes()
        );
        assert!(worst < 1e-9);
    }
}

/// A pair in the x-z plane: incidence angle th_i (wi.x = sin th_i > 0), outgoing
/// with tangent component x_o.
fn plane_pair(th_i: f64, x_o: f64) -> PairGeometry {
    let wi = DVec3::new(th_i.sin(), 0.0, th_i.cos());
    let wo = DVec3::new(x_o, 0.0, (1.0 - x_o * x_o).sqrt());
    PairGeometry::new(wi, wo).unwrap()
}

#[test]
fn grating_equation_peaks() {
    let lam = 2.5;
    let s = cd(500.0);
    let lambda_um = 0.55;
    let k = 2.0 * PI / lambda_um;
    let th_i = 0.4f64;
    for n in [-3i64, -1, 1, 2] {
        // u = -(sin th_i + x_o) = n lambda / Lam
        let x_pred = -(th_i.sin()) - n as f64 * lambda_um / lam;
        // golden-section search for the maximum of the kernel around it.
        let (mut a, mut b) = (x_pred - 2e-3, x_pred + 2e-3);
        let gr = 0.5 * (5f64.sqrt() - 1.0);
        for _ in 0..80 {
            let c = b - gr * (b - a);
            let d = a + gr * (b - a);
            if s.kernel(k, &plane_pair(th_i, c)) > s.kernel(k, &plane_pair(th_i, d)) {
                b = d;
            } else {
                a = c;
            }
        }
        let x_peak = 0.5 * (a + b);
        let u_peak = plane_pair(th_i, x_peak).u;
        let err = u_peak - n as f64 * lambda_um / lam;
        println!(
            "order {n}: u_peak {u_peak:.8}, n lambda / Lam {:.8}, diff {err:.1e}",
            n as f64 * lambda_um / lam
        );
        // Lobe width in u is 1 / (k l) = 1.8e-4; the slowly varying prefactor
        // shifts the maximum by far less than 1e-6.
        assert!(err.abs() < 2e-6, "order {n}: {err}");
    }
}

/// Direct sum over all orders (std exp, no tolerance), oracle for `kernel`.
fn kernel_direct(
    s: &PeriodicSurface,
    k: f64,
    g: &PairGeometry,
    power: &dyn Fn(i64, f64) -> f64,
) -> f64 {
    let l = s.coherence_um();
    let lam = s.period_um();
    let beta = k * g.w;
    let m = (2.0 * lam / 0.3) as i64 + 200;
    let mut sum = 0.0;
    for n in -m..=m {
        let e = l * l * ((k * g.u - 2.0 * PI * n as f64 / lam).powi(2) + (k * g.v).powi(2));
        sum += power(n, beta) * (-e).exp();
    }
    k * k / (4.0 * PI * PI * g.w * g.w) * sum * 4.0 * PI * l * l
}

/// Random pairs, most of them near the plane of incidence (|v| ~ 1 / (k l))
/// so that the kernel is not trivially 0.
fn random_pair(rng: &mut Rng, k: f64, l: f64) -> PairGeometry {
    loop {
        let ct = rng.range(0.02, 1.0);
        let ph = rng.range(0.0, 2.0 * PI);
        let st = (1.0 - ct * ct).sqrt();
        let wi = DVec3::new(st * ph.cos(), st * ph.sin(), ct);
        let v = if rng.next() < 0.8 {
            rng.range(-3.0, 3.0) / (k * l)
        } else {
            rng.range(-0.5, 0.5)
        };
        let yo = -wi.y - v;
        let xo = rng.range(-1.0, 1.0);
        let r2 = xo * xo + yo * yo;
        if r2 >= 0.9999 {
            continue;
        }
        let wo = DVec3::new(xo, yo, (1.0 - r2).sqrt());
        if let Some(g) = PairGeometry::new(wi, wo) {
            return g;
        }
    }
}

#[test]
fn kernel_matches_direct_sum_over_all_orders() {
    let cases: Vec<(&str, PeriodicSurface)> = vec![
        ("cd l=3.75", cd(3.75)),
        ("cd l=200", cd(200.0)),
        (
            "sine",
            PeriodicSurface::new(1.2, 1.8, Profile::Sine { height_um: 0.3 }).unwrap(),
        ),
        (
            "tab",
            PeriodicSurface::new(
                4.0,
                6.0,
                Profile::Tabulated {
                    heights_um: wavy_profile(96),
                },
            )
            .unwrap(),
        ),
    ];
    let mut rng = Rng(7);
    for (name, s) in &cases {
        let mut worst: f64 = 0.0;
        let mut nonzero = 0;
        for _ in 0..3000 {
            let lambda = rng.range(0.36, 0.83);
            let k = 2.0 * PI / lambda;
            let g = random_pair(&mut rng, k, s.coherence_um());
            let got = s.kernel(k, &g);
            let want = match s.profile() {
                Profile::Rect {
                    height_um,
                    width_um,
                } => {
                    let (b, d) = (*height_um, *width_um);
                    kernel_direct(s, k, &g, &|n, beta| rect_closed(n, beta, b, d, 2.5))
                }
                _ => kernel_direct(s, k, &g, &|n, beta| s.order_power(n, beta)),
            };
            // Scale of the kernel's peaks for this geometry: omitted orders are
            // below e^-100 of it (and filtered orders below 1e-12 of it).
            let scale = (k * s.coherence_um() / g.w).powi(2) / PI;
            let err = (got - want).abs() / (want + 1e-11 * scale);
            if want > 0.0 {
                nonzero += 1;
            }
            worst = worst.max(err);
        }
        println!("{name}: kernel vs all-order sum, worst relative error {worst:.2e} ({nonzero} non-zero of 3000)");
        assert!(worst < 1e-6, "{name}: {worst}");
    }
}

#[test]
fn extreme_inputs_are_finite_and_non_negative() {
    let mut rng = Rng(2024);
    let dirs = |rng: &mut Rng| -> DVec3 {
        let z = match (rng.next() * 3.0) as u32 {
            0 => 1e-8,
            1 => rng.range(1e-8, 1e-3),
            _ => rng.range(1e-8, 1.0),
        };
        let ph = rng.range(0.0, 2.0 * PI);
        let r = (1.0 - z * z).sqrt();
        DVec3::new(r * ph.cos(), r * ph.sin(), z)
    };
    let mut checked = 0;
    for &lam in &[0.3, 1.0, 2.5, 30.0, 100.0] {
        for &lf in &[1.5, 10.0, -5000.0] {
            let l = if lf < 0.0 { -lf } else { lf * lam };
            let profiles = [
                Profile::Rect {
                    height_um: 0.15,
                    width_um: 0.5 * lam,
                },
                Profile::Sine { height_um: 0.2 },
                Profile::Tabulated {
                    heights_um: wavy_profile(64),
                },
            ];
            for p in profiles {
                let s = PeriodicSurface::new(lam, l, p).unwrap();
                for n in [-3i64, 0, 1, 7] {
                    let p0 = s.order_power(n, 0.0);
                    assert!(p0.is_finite() && p0 >= 0.0);
                    // beta = 0 is a flat mirror (FFT round-off aside).
                    let want = if n == 0 { 1.0 } else { 0.0 };
                    assert!((p0 - want).abs() < 1e-12, "order {n}: {p0}");
                }
                for _ in 0..300 {
                    let wi = dirs(&mut rng);
                    let wo = if rng.next() < 0.3 {
                        crate::geometry::reflect(wi)
                    } else {
                        dirs(&mut rng)
                    };
                    let g = PairGeometry::new(wi, wo).unwrap();
                    let k = 2.0 * PI / rng.range(0.36, 0.83);
                    let val = s.kernel(k, &g);
                    assert!(val.is_finite() && val >= 0.0, "{val} at {g:?}");
                    let rgb = s.kernel_rgb(&g, &|_| 0.9);
                    assert!(rgb.iter().all(|c| c.is_finite()), "{rgb:?} at {g:?}");
                    checked += 1;
                }
            }
        }
    }
    // Degenerate inputs.
    let s = cd(10.0);
    let g = plane_pair(0.3, 0.1);
    for k in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e9] {
        let v = s.kernel(k, &g);
        assert!(v.is_finite() && v >= 0.0);
    }
    println!("extreme inputs: {checked} pairs finite and >= 0");
}

#[test]
fn invalid_parameters_are_refused_with_names() {
    let rect = |h: f64, w: f64| Profile::Rect {
        height_um: h,
        width_um: w,
    };
    let err = |r: Result<PeriodicSurface, String>| r.unwrap_err();
    assert!(err(PeriodicSurface::new(0.0, 5.0, rect(0.1, 0.1))).contains("period_um"));
    assert!(err(PeriodicSurface::new(f64::NAN, 5.0, rect(0.1, 0.1))).contains("period_um"));
    assert!(err(PeriodicSurface::new(2.0, -1.0, rect(0.1, 0.1))).contains("coherence_um"));
    assert!(err(PeriodicSurface::new(2.0, 5.0, rect(0.1, 3.0))).contains("width_um"));
    assert!(err(PeriodicSurface::new(2.0, 5.0, rect(f64::INFINITY, 1.0))).contains("height_um"));
    assert!(err(PeriodicSurface::new(
        2.0,
        5.0,
        Profile::Sine { height_um: 0.0 }
    ))
    .contains("height_um"));
    let tab = |h: Vec<f64>| Profile::Tabulated { heights_um: h };
    assert!(err(PeriodicSurface::new(2.0, 5.0, tab(vec![0.1]))).contains("heights_um"));
    assert!(err(PeriodicSurface::new(2.0, 5.0, tab(vec![0.1, f64::NAN]))).contains("heights_um"));
    // Too much table: 100 um period, rough 4 um profile with sharp features.
    let rough: Vec<f64> = (0..4096)
        .map(|j| if j % 7 < 3 { 4.0 } else { 0.0 })
        .collect();
    let e = err(PeriodicSurface::new(100.0, 500.0, tab(rough)));
    println!("refusal message: {e}");
    assert!(e.contains("heights_um") && e.contains("period_um"));
}

#[test]
fn memory_is_bounded() {
    let cases = [
        ("cd", cd(10.0)),
        (
            "sine b=0.3 Lam=2",
            PeriodicSurface::new(2.0, 10.0, Profile::Sine { height_um: 0.3 }).unwrap(),
        ),
        (
            "sine b=5 Lam=100",
            PeriodicSurface::new(100.0, 500.0, Profile::Sine { height_um: 5.0 }).unwrap(),
        ),
        (
            "tab 1024 Lam=20",
            PeriodicSurface::new(
                20.0,
                100.0,
                Profile::Tabulated {
                    heights_um: wavy_profile(1024),
                },
            )
            .unwrap(),
        ),
    ];
    for (name, s) in &cases {
        println!("{name}: {} bytes", s.memory_bytes());
        assert!(s.memory_bytes() <= MAX_TABLE_BYTES + 64 * 1024);
    }
}

// A measurement, not a check (it asserts nothing): speed is benchmarked by
// `make bench`; run it with `cargo test -p stam-core -- --ignored timing_spectral_kernel --nocapture`.
#[test]
#[ignore = "measurement; run with --ignored"]
fn timing_spectral_kernel() {
    let surfaces = [
        ("cd l=20", cd(20.0)),
        (
            "sine",
            PeriodicSurface::new(1.5, 20.0, Profile::Sine { height_um: 0.25 }).unwrap(),
        ),
        (
            "tab",
            PeriodicSurface::new(
                3.0,
                20.0,
                Profile::Tabulated {
                    heights_um: wavy_profile(128),
                },
            )
            .unwrap(),
        ),
    ];
    let mut rng = Rng(31337);
    let pairs: Vec<(f64, PairGeometry)> = (0..4096)
        .map(|_| {
            let k = 2.0 * PI / rng.range(0.38, 0.78);
            (k, random_pair(&mut rng, k, 20.0))
        })
        .collect();
    for (name, s) in &surfaces {
        let t = cpu_ns();
        let wall = Instant::now();
        let mut acc = 0.0;
        let mut reps = 0;
        while wall.elapsed().as_secs_f64() < 0.5 {
            for (k, g) in &pairs {
                acc += s.kernel(*k, g);
            }
            reps += 1;
        }
        let ns = (cpu_ns() - t) / (reps * pairs.len()) as f64;
        println!("{name}: kernel {ns:.1} ns/call (80% near-plane pairs), checksum {acc:.3e}");
    }
}

fn gold_like(lambda_nm: f64) -> f64 {
    0.35 + 0.6 / (1.0 + (-(lambda_nm - 520.0) / 25.0).exp())
}

/// Reference RGB by the composite rule on a grid fine enough for the
/// narrowest peak: the peak's standard deviation in wavelength is
/// lambda^2 s / 1000 nm with s = 1 / (2 sqrt 2 pi l rho) (1/um); the step is a
/// quarter of it at 360 nm, at most 1 nm.
fn rgb_reference(
    s: &PeriodicSurface,
    g: &PairGeometry,
    refl: &dyn Fn(f64) -> f64,
) -> ([f64; 3], f64) {
    let rho = (g.u * g.u + g.v * g.v).sqrt().max(1e-12);
    let s_nu = 1.0 / (2.0 * 2f64.sqrt() * PI * s.coherence_um() * rho);
    let step = (360.0f64.powi(2) / 1000.0 * s_nu / 4.0).min(1.0);
    let f = |lambda_nm: f64| refl(lambda_nm) * s.kernel(2.0 * PI * 1000.0 / lambda_nm, g);
    (spectrum::integrate_rgb_reference(f, step), step)
}

#[test]
fn rgb_matches_fine_reference() {
    let cases: Vec<(&str, PeriodicSurface, usize)> = vec![
        ("cd l=3.75", cd(3.75), 300),
        ("cd l=20", cd(20.0), 300),
        ("cd l=200", cd(200.0), 120),
        ("cd l=5000", cd(5000.0), 12),
        (
            "sine Lam=1.6 l=12",
            PeriodicSurface::new(1.6, 12.0, Profile::Sine { height_um: 0.3 }).unwrap(),
            300,
        ),
        (
            "tab Lam=4 l=30",
            PeriodicSurface::new(
                4.0,
                30.0,
                Profile::Tabulated {
                    heights_um: wavy_profile(96),
                },
            )
            .unwrap(),
            300,
        ),
    ];
    let mut rng = Rng(4242);
    for (name, s, count) in &cases {
        for (rname, refl) in [
            ("flat", &(|_: f64| 1.0) as &dyn Fn(f64) -> f64),
            ("gold-like", &gold_like),
        ] {
            let mut results = Vec::new();
            let mut scale: f64 = 0.0;
            let mut finest: f64 = 1.0;
            let mut coarse_worst: f64 = 0.0;
            for _ in 0..*count {
                let g = random_pair(&mut rng, 2.0 * PI * 1.8, s.coherence_um());
                let got = s.kernel_rgb(&g, refl);
                let (want, step) = rgb_reference(s, &g, refl);
                // How wrong the plain 1 nm reference is for this pair.
                let coarse = spectrum::integrate_rgb_reference(
                    |lambda_nm| refl(lambda_nm) * s.kernel(2.0 * PI * 1000.0 / lambda_nm, &g),
                    1.0,
                );
                let mref = want.iter().fold(0.0f64, |a, c| a.max(c.abs()));
                if mref > 0.0 {
                    let ec = (0..3).fold(0.0f64, |a, c| a.max((coarse[c] - want[c]).abs()));
                    coarse_worst = coarse_worst.max(ec / mref);
                }
                finest = finest.min(step);
                let m = want.iter().fold(0.0f64, |a, c| a.max(c.abs()));
                scale = scale.max(m);
                let e = (0..3).fold(0.0f64, |a, c| a.max((got[c] - want[c]).abs()));
                results.push((m, e, g));
            }
            let mut worst: f64 = 0.0;
            let mut worst_abs: f64 = 0.0;
            let mut used = 0;
            for (m, e, _) in &results {
                worst_abs = worst_abs.max(e / scale);
                if *m > 1e-4 * scale {
                    used += 1;
                    worst = worst.max(e / m);
                }
            }
            if let Some((m, e, g)) = results
                .iter()
                .filter(|r| r.0 > 1e-4 * scale)
                .max_by(|a, b| (a.1 / a.0).partial_cmp(&(b.1 / b.0)).unwrap())
            {
                let rho2 = g.u * g.u + g.v * g.v;
                let s_nu = 1.0 / (2.0 * 2f64.sqrt() * PI * s.coherence_um() * rho2.sqrt());
                println!(
                    "  worst pair: u {:.4} v {:.2e} w {:.3} rho {:.4} s_nu {:.4} rel {:.2e}; mu_n = {:?}",
                    g.u, g.v, g.w, rho2.sqrt(), s_nu, e / m,
                    (-6..=6).map(|n| (n as f64 * g.u / (s.period_um() * rho2) * 1000.0).round() / 1000.0).collect::<Vec<_>>()
                );
            }
            println!(
                "{name} {rname}: worst error / max channel {worst:.2e} over {used} visible pairs; worst error / sample max {worst_abs:.1e}; finest ref step {finest:.4} nm (the 1 nm reference errs by up to {coarse_worst:.1e} here)"
            );
            assert!(worst < 0.01, "{name} {rname}: {worst}");
        }
    }
}

// A measurement, not a check (it asserts nothing): speed is benchmarked by
// `make bench`; run it with `cargo test -p stam-core -- --ignored timing_rgb_kernel --nocapture`.
#[test]
#[ignore = "measurement; run with --ignored"]
fn timing_rgb_kernel() {
    let surfaces = [
        ("cd l=3.75", cd(3.75)),
        ("cd l=20", cd(20.0)),
        ("cd l=200", cd(200.0)),
        (
            "sine",
            PeriodicSurface::new(1.6, 12.0, Profile::Sine { height_um: 0.3 }).unwrap(),
        ),
        (
            "tab",
            PeriodicSurface::new(
                4.0,
                30.0,
                Profile::Tabulated {
                    heights_um: wavy_profile(96),
                },
            )
            .unwrap(),
        ),
    ];
    let mut rng = Rng(777);
    for (name, s) in &surfaces {
        let pairs: Vec<PairGeometry> = (0..2048)
            .map(|_| random_pair(&mut rng, 2.0 * PI * 1.8, s.coherence_um()))
            .collect();
        let mut uniform = Rng(778);
        let pairs_uniform: Vec<PairGeometry> = (0..2048)
            .map(|_| {
                let d = |r: &mut Rng| {
                    let z = r.range(0.01, 1.0);
                    let ph = r.range(0.0, 2.0 * PI);
                    let q = (1.0 - z * z).sqrt();
                    DVec3::new(q * ph.cos(), q * ph.sin(), z)
                };
                PairGeometry::new(d(&mut uniform), d(&mut uniform)).unwrap()
            })
            .collect();
        for (label, set) in [("near-plane", &pairs), ("uniform", &pairs_uniform)] {
            let t = cpu_ns();
            let wall = Instant::now();
            let mut acc = 0.0;
            let mut reps = 0;
            while wall.elapsed().as_secs_f64() < 0.3 {
                for g in set.iter() {
                    acc += s.kernel_rgb(g, &gold_like)[1];
                }
                reps += 1;
            }
            let ns = (cpu_ns() - t) / (reps * set.len()) as f64;
            println!("{name}: kernel_rgb {ns:.0} ns/call ({label} pairs), checksum {acc:.3e}");
        }
    }
}

/// The broad-peak rule's vectorised loop for rectangular profiles (|c_n|^2
/// linear in sin^2, fast_exp_vectorisable, the e^-700 floor) against the
/// plain per-node sum with order_power and libm's exp.
#[test]
fn broad_sums_match_the_plain_sum() {
    let rule = spectrum::smooth_rule(RGB_SMOOTH_NODES);
    let mut rng = Rng(0x5eed);
    let mut worst: f64 = 0.0;
    for l in [3.75, 20.0, 50.0] {
        let p = cd(l);
        for _ in 0..2000 {
            let u = rng.range(-0.05, 0.05);
            let v = rng.range(-0.05, 0.05);
            let w = rng.range(-2.0, -0.1);
            let orders = [0, 1, -1, 2];
            let got = p.broad_sums(&rule.nu_per_um, u, v, w, Some(&orders));
            for (j, &nu) in rule.nu_per_um.iter().enumerate() {
                let k = 2.0 * PI * nu;
                let g = 2.0 * PI / p.period_um;
                let plain: f64 = orders
                    .iter()
                    .map(|&n| {
                        let d = l * (k * u - g * n as f64);
                        let e = d * d + (l * k * v).powi(2);
                        p.order_power(n, k * w) * (-e).exp()
                    })
                    .sum();
                // Sums of e^-700 = 1e-304 and below may be dropped.
                let scale = plain.max(1e-290);
                worst = worst.max((got[j] - plain).abs() / scale);
            }
        }
    }
    // fast_exp's 2e-10 and sin^2's 1e-14; terms below e^-700 dropped.
    assert!(worst < 1e-9, "worst relative difference {worst}");
}

/// The broad-peak rule's reflectance from the node table equals the
/// metal's reflectance at those wavelengths (the table has exact rows
/// there; the grid interpolates between 1 nm rows): RGB of compact discs
/// of two metals, through both, within 1e-4 of the largest channel.
#[test]
fn broad_rule_node_reflectance_matches_grid() {
    for metal in ["aluminium", "gold"] {
        let brdf = crate::material::Brdf::from_json(&format!(
            r#"{{"surface":"cd","coherence_um":3.75,"fresnel":"{metal}"}}"#
        ))
        .unwrap();
        let crate::models::Surface::Periodic(model) = brdf.surface() else {
            panic!("periodic");
        };
        assert!(model.broad_reflectance.is_some());
        let mut worst: f64 = 0.0;
        for (wi, wo) in crate::testing::directions() {
            let Some(geom) = PairGeometry::new(wi, wo) else {
                continue;
            };
            let with_table = model.reflectance_rgb_with(&brdf.shading(), &geom, true);
            let plain = model
                .surface
                .kernel_rgb(&geom, &|l| brdf.fresnel().reflectance(geom.cos_half, l));
            let m = plain.iter().fold(0.0f64, |a, c| a.max(c.abs()));
            if m > 0.0 {
                for c in 0..3 {
                    worst = worst.max((with_table[c] - plain[c]).abs() / m);
                }
            }
        }
        println!("{metal}: node table against the grid, worst {worst:.1e} of the largest channel");
        assert!(worst < 1e-4, "{metal}: {worst}");
    }
}

/// A grating table with every cell built stays within its budget, for
/// the compact disc and for a grating of a thousand orders.
#[test]
fn grating_table_stays_within_budget() {
    for json in [
        r#"{"surface":"cd"}"#,
        r#"{"surface":"periodic","period_um":100,"coherence_um":200,"profile":"sine","height_um":5}"#,
    ] {
        let brdf = crate::material::Brdf::from_json(json).unwrap();
        let crate::models::Surface::Periodic(model) = brdf.surface() else {
            panic!("periodic");
        };
        let steps = 120;
        for a in 0..steps {
            for b in 0..steps {
                let x = -1.0 + 2.0 * (a as f64 + 0.5) / steps as f64;
                let y = -1.0 + 2.0 * (b as f64 + 0.5) / steps as f64;
                if x * x + y * y < 0.999 {
                    let wi = DVec3::new(x, y, (1.0 - x * x - y * y).sqrt());
                    let _ = brdf.sampler(wi, None);
                }
            }
        }
        let table = model.grating_table().unwrap();
        let built = table.cells.iter().filter(|c| c.get().is_some()).count();
        let bytes = table.memory_bytes();
        println!(
            "{json}: {} cells per axis, {built} built, {bytes} bytes",
            table.cells_per_axis
        );
        assert!(built > table.cells.len() / 2, "{built}");
        assert!(
            bytes <= sampling::GRATING_TABLE_BYTES + (64 << 10),
            "{bytes}"
        );
    }
}

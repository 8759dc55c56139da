//! The order powers |c_n(beta)|^2 of the sine and tabulated profiles:
//! Bessel rows and DFTs, tabulated over beta (see the module documentation
//! of `models::periodic`).

use super::*;

/// J_0(x) ..= J_{n_max}(x) for x >= 0 by Miller's backward recurrence,
/// normalised with J_0 + 2 sum_k J_2k = 1. Accurate to ~1e-15 absolute for
/// x up to a few hundred and any order.
pub(super) fn bessel_j_row(x: f64, n_max: usize) -> Vec<f64> {
    let mut out = vec![0.0; n_max + 1];
    if x == 0.0 {
        out[0] = 1.0;
        return out;
    }
    let top = (n_max as f64).max(x);
    let mut m = (top + 30.0 + 2.0 * (40.0 * top).sqrt()) as usize;
    m += m % 2;
    let mut j_next = 0.0; // J_{k+1}
    let mut j_k = 1e-30; // J_k for k = m
    let mut sum = 0.0; // J_0 + 2 sum J_2k (unnormalised)
    let mut k = m;
    loop {
        if k <= n_max {
            out[k] = j_k;
        }
        if k & 1 == 0 {
            sum += if k == 0 { j_k } else { 2.0 * j_k };
        }
        if k == 0 {
            break;
        }
        let j_prev = 2.0 * k as f64 / x * j_k - j_next;
        j_next = j_k;
        j_k = j_prev;
        k -= 1;
        if j_k.abs() > 1e250 {
            let r = 1e-250;
            j_k *= r;
            j_next *= r;
            sum *= r;
            for o in out.iter_mut().skip(k + 1) {
                *o *= r;
            }
        }
    }
    for o in out.iter_mut() {
        *o /= sum;
    }
    out
}

/// Bessel table for the sine profile: c_n ~ J_n(-beta b / 2) (phase dropped).
pub(super) fn sine_table(height_um: f64, n_phys: i64) -> Result<OrderTable, String> {
    let half = 0.5 * height_um;
    let n_beta = beta_samples(half);
    let step = BETA_MAX / (n_beta - 1) as f64;
    let x_max = BETA_MAX * half;
    // J_n(x)^2 < 1e-12 for every x <= x_max beyond roughly x_max + 8 x^(1/3) + 20.
    let n_hi = n_phys
        .min((x_max + 8.0 * x_max.cbrt() + 25.0) as i64)
        .max(0);
    let orders = (n_hi + 1) as usize;
    let bytes = orders * n_beta * std::mem::size_of::<[Complex64; 3]>();
    if bytes > MAX_TABLE_BYTES {
        return Err(format!(
            "height_um ({height_um}) with period_um needs a {bytes}-byte Bessel table (limit {MAX_TABLE_BYTES}); reduce height_um"
        ));
    }
    let mut data = Vec::with_capacity(orders * n_beta);
    let mut max_power = vec![0.0f64; orders];
    let row_len = orders + 2;
    for j in 0..n_beta {
        let beta = -BETA_MAX + j as f64 * step;
        let x = (-beta * half).max(0.0);
        let row = bessel_j_row(x, row_len);
        // J_{-m} = (-1)^m J_m
        let jn = |m: i64| -> f64 {
            let v = row[m.unsigned_abs() as usize];
            if m < 0 && m % 2 != 0 {
                -v
            } else {
                v
            }
        };
        for n in 0..=n_hi {
            let val = jn(n);
            let d1 = 0.5 * (jn(n - 1) - jn(n + 1));
            let d2 = 0.25 * (jn(n - 2) - 2.0 * val + jn(n + 2));
            // d/dbeta J_n(-beta half) = -half J_n', d2 = half^2 J_n''
            data.push([
                Complex64::new(val, 0.0),
                Complex64::new(-half * d1, 0.0),
                Complex64::new(half * half * d2, 0.0),
            ]);
            max_power[n as usize] = max_power[n as usize].max(val * val);
        }
    }
    // Trim orders that never matter.
    let keep = max_power
        .iter()
        .rposition(|&p| p > ORDER_POWER_TOL)
        .unwrap_or(0);
    let table = OrderTable {
        step,
        n_beta,
        n_lo: 0,
        n_hi,
        symmetric: true,
        data,
    };
    Ok(trim_table(table, 0, keep as i64))
}

/// Keeps only the orders n_lo..=n_hi of a table.
fn trim_table(table: OrderTable, n_lo: i64, n_hi: i64) -> OrderTable {
    if n_lo == table.n_lo && n_hi == table.n_hi {
        return table;
    }
    let stride = table.orders();
    let first = (n_lo - table.n_lo) as usize;
    let width = (n_hi - n_lo + 1) as usize;
    let mut data = Vec::with_capacity(width * table.n_beta);
    for j in 0..table.n_beta {
        data.extend_from_slice(&table.data[j * stride + first..j * stride + first + width]);
    }
    OrderTable {
        n_lo,
        n_hi,
        data,
        ..table
    }
}

/// c_n of sampled heights (samples model, see the module doc), direct O(N).
pub(super) fn dft_coefficient(heights: &[f64], n: i64, beta: f64) -> Complex64 {
    let len = heights.len() as i64;
    let half = len / 2;
    if n.abs() > half {
        return Complex64::new(0.0, 0.0);
    }
    let mut acc = Complex64::new(0.0, 0.0);
    for (j, h) in heights.iter().enumerate() {
        let ph = beta * h - 2.0 * PI * ((n * j as i64).rem_euclid(len)) as f64 / len as f64;
        acc += Complex64::from_polar(1.0, ph);
    }
    acc /= len as f64;
    if len & 1 == 0 && n.abs() == half {
        acc /= std::f64::consts::SQRT_2;
    }
    acc
}

/// FFT table for a tabulated profile.
pub(super) fn tabulated_table(
    heights: &[f64],
    period_um: f64,
    n_phys: i64,
) -> Result<OrderTable, String> {
    let len = heights.len();
    let (lo, hi) = heights
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &h| {
            (a.min(h), b.max(h))
        });
    let mid = 0.5 * (lo + hi);
    let half = 0.5 * (hi - lo);
    let centred: Vec<f64> = heights.iter().map(|h| h - mid).collect();
    let n_beta = beta_samples(half);
    let step = BETA_MAX / (n_beta - 1) as f64;
    let nyq = (len / 2) as i64;
    let n_lim = n_phys.min(nyq);
    let mut planner = rustfft::FftPlanner::<f64>::new();
    let fft = planner.plan_fft_forward(len);
    let index = |n: i64| -> usize { n.rem_euclid(len as i64) as usize };
    let nyq_scale = |n: i64| -> f64 {
        if len & 1 == 0 && n.abs() == nyq {
            std::f64::consts::FRAC_1_SQRT_2
        } else {
            1.0
        }
    };
    let inv = 1.0 / len as f64;
    // Pass 1: the largest |c_n|^2 over the grid, to choose the orders.
    let mut max_power = vec![0.0f64; (2 * n_lim + 1) as usize];
    let mut buf = vec![Complex64::new(0.0, 0.0); len];
    for j in 0..n_beta {
        let beta = -BETA_MAX + j as f64 * step;
        for (b, h) in buf.iter_mut().zip(&centred) {
            *b = Complex64::from_polar(inv, beta * h);
        }
        fft.process(&mut buf);
        for n in -n_lim..=n_lim {
            let p = buf[index(n)].norm_sqr() * nyq_scale(n).powi(2);
            let slot = &mut max_power[(n + n_lim) as usize];
            *slot = slot.max(p);
        }
    }
    let first = max_power.iter().position(|&p| p > ORDER_POWER_TOL);
    let last = max_power.iter().rposition(|&p| p > ORDER_POWER_TOL);
    let (n_lo, n_hi) = match (first, last) {
        (Some(a), Some(b)) => (a as i64 - n_lim, b as i64 - n_lim),
        _ => (0, 0),
    };
    let orders = (n_hi - n_lo + 1) as usize;
    let bytes = orders * n_beta * std::mem::size_of::<[Complex64; 3]>();
    if bytes > MAX_TABLE_BYTES {
        return Err(format!(
            "heights_um (range {:.4} um) with period_um ({period_um}) needs {orders} orders x {n_beta} beta samples = {bytes} bytes of |c_n|^2 table (limit {MAX_TABLE_BYTES}); reduce the height range of heights_um or period_um",
            hi - lo
        ));
    }
    // Pass 2: value and beta derivatives (FFTs of e, i h e, -h^2 e).
    let mut data = Vec::with_capacity(orders * n_beta);
    let mut b1 = vec![Complex64::new(0.0, 0.0); len];
    let mut b2 = vec![Complex64::new(0.0, 0.0); len];
    for j in 0..n_beta {
        let beta = -BETA_MAX + j as f64 * step;
        for (i, h) in centred.iter().enumerate() {
            let e = Complex64::from_polar(inv, beta * h);
            buf[i] = e;
            b1[i] = e * Complex64::new(0.0, *h);
            b2[i] = e * (-h * h);
        }
        fft.process(&mut buf);
        fft.process(&mut b1);
        fft.process(&mut b2);
        for n in n_lo..=n_hi {
            let sc = nyq_scale(n);
            let i = index(n);
            data.push([buf[i] * sc, b1[i] * sc, b2[i] * sc]);
        }
    }
    Ok(OrderTable {
        step,
        n_beta,
        n_lo,
        n_hi,
        symmetric: false,
        data,
    })
}

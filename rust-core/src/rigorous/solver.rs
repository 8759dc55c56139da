//! The Fourier modal method (RCWA) for a 1-D periodic stack in conical
//! mounting, with Li's factorisation rules and a stable reflection-matrix
//! recursion.
//!
//! Units: lengths times k0 = 2 pi / lambda; time convention exp(-i omega t);
//! the period along x (grooves along y); z points from the superstrate down
//! into the substrate. Fields are expanded over orders m = -N..N with
//! kx_m = n1 sin(theta) cos(phi) + m lambda / Lam and ky = n1 sin(theta) sin(phi).
//! With H scaled by the vacuum impedance, Maxwell's curl equations in a layer
//! become, for the tangential amplitudes e = (Ex, Ey) and h = (Hx, Hy),
//!
//!   de/dz = i P h,  dh/dz = i Q e,
//!   P = [[Kx E^-1 ky, I - Kx E^-1 Kx], [ky^2 E^-1 - I, -ky E^-1 Kx]],
//!   Q = [[-ky Kx, Kx^2 - [[eps]]], [[[1/eps]]^-1 - ky^2, ky Kx]],
//!
//! where E = [[eps]] (Laurent's rule) multiplies the tangential E_y and the
//! E_z of D_z (both continuous across the x-interfaces of the lamellae) and
//! [[1/eps]]^-1 (the inverse rule) multiplies E_x, which is normal to them and
//! discontinuous (Li, JOSA A 13, 1870, 1996). The modes exp(i gamma z) are the
//! eigenvectors W of P Q with eigenvalues gamma^2 (Im gamma >= 0: decaying or
//! propagating down), and h = V c with V = Q W gamma^-1.
//!
//! Interfaces are matched from the substrate up with reflection matrices
//! (the R-matrix algorithm of Li, JOSA A 13, 1024, 1996): only exp(i gamma d)
//! with Im gamma >= 0 appears, so thick or metallic layers do not overflow.

use faer::linalg::solvers::DenseSolveCore;
use faer::prelude::*;
use faer::{c64, Mat};

use super::layers::{Layer, Stack};
use crate::StamError;

/// Largest order count N (2N + 1 orders; matrices of 4N + 2).
pub const MAX_ORDERS: usize = 400;

/// How products of the permittivity with a field are truncated in Fourier
/// space. `Li` is the correct rule (and the solver's); `Laurent` multiplies
/// every component by [[eps]], the classical formulation that converges
/// slowly for metals in TM, kept to show the difference (docs/rigorous.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Factorisation {
    Li,
    Laurent,
}

/// Direction of the incident light.
#[derive(Clone, Copy, Debug)]
pub struct Incidence {
    pub lambda_nm: f64,
    /// Polar angle from the surface normal, in [0, pi/2).
    pub theta_rad: f64,
    /// Azimuth of the plane of incidence from the grating vector (x): 0 is
    /// classical mounting (plane of incidence across the grooves).
    pub phi_rad: f64,
}

/// One propagating order, reflected or transmitted.
#[derive(Clone, Debug)]
pub struct Order {
    /// Order index m: kx_m = kx_incident + m lambda / Lam.
    pub m: i64,
    /// Unit direction of travel (z down: reflected orders have z < 0).
    pub direction: [f64; 3],
    /// Diffraction efficiency (power fraction) for s- and p-polarised
    /// incident light of unit power.
    pub efficiency: [f64; 2],
    /// Jones matrix: jones[a][b] = amplitude of outgoing polarisation a
    /// (0 = s, 1 = p) for unit incident polarisation b, scaled so that
    /// sum_a |jones[a][b]|^2 = efficiency[b]. s = z x k / |z x k| and
    /// p = s x k for a direction k (s = (-sin phi, cos phi, 0) along z).
    pub jones: [[c64; 2]; 2],
}

impl Order {
    /// Efficiency for unpolarised light.
    pub fn unpolarised(&self) -> f64 {
        0.5 * (self.efficiency[0] + self.efficiency[1])
    }
}

/// The solution at one incidence.
#[derive(Clone, Debug)]
pub struct Diffraction {
    /// Propagating reflected orders, by increasing m.
    pub reflected: Vec<Order>,
    /// Propagating transmitted orders (empty unless the substrate is
    /// lossless, where power can leave through it).
    pub transmitted: Vec<Order>,
    /// The order count N used (2N + 1 retained orders).
    pub n_orders: usize,
}

impl Diffraction {
    /// Total reflected power fraction, per incident polarisation.
    pub fn reflectance(&self) -> [f64; 2] {
        sum_efficiency(&self.reflected)
    }

    pub fn transmittance(&self) -> [f64; 2] {
        sum_efficiency(&self.transmitted)
    }

    /// The reflected order m, if it propagates.
    pub fn order(&self, m: i64) -> Option<&Order> {
        self.reflected.iter().find(|o| o.m == m)
    }
}

fn sum_efficiency(orders: &[Order]) -> [f64; 2] {
    orders.iter().fold([0.0; 2], |acc, o| {
        [acc[0] + o.efficiency[0], acc[1] + o.efficiency[1]]
    })
}

/// Modes of one region: tangential E = W c, tangential H = V c for the
/// down-going modes (up-going: W c, -V c), propagation constants gamma.
struct Modes {
    w: Option<Mat<c64>>, // None: identity (a homogeneous region)
    v: Mat<c64>,
    gamma: Vec<c64>,
}

/// Wavevector components of the retained orders.
struct Orders {
    n: usize,
    kx: Vec<f64>,
    ky: f64,
}

impl Orders {
    fn size(&self) -> usize {
        self.kx.len()
    }
}

/// k_z = sqrt(eps - kx^2 - ky^2) on the branch Im >= 0 (Re >= 0 when real),
/// nudged off 0 (an order exactly grazing: a Rayleigh anomaly) so that the
/// mode matrices stay invertible.
fn kz(eps: c64, kt2: f64) -> c64 {
    let mut s = (eps - kt2).sqrt();
    if s.im < 0.0 || (s.im == 0.0 && s.re < 0.0) {
        s = -s;
    }
    if s.norm() < 1e-9 {
        s = c64::new(1e-9, 1e-9);
    }
    s
}

/// Modes of a homogeneous region: plane waves, W = I.
fn homogeneous(orders: &Orders, eps: c64) -> Modes {
    let m = orders.size();
    let ky = orders.ky;
    let gamma: Vec<c64> = orders
        .kx
        .iter()
        .map(|&kx| kz(eps, kx * kx + ky * ky))
        .collect();
    let mut v = Mat::<c64>::zeros(2 * m, 2 * m);
    for (i, &kx) in orders.kx.iter().enumerate() {
        let g = gamma[i];
        // V = Q gamma^-1 with Q's 2x2 block of order i.
        v[(i, i)] = c64::new(-ky * kx, 0.0) / g;
        v[(i, m + i)] = (c64::new(kx * kx, 0.0) - eps) / g;
        v[(m + i, i)] = (eps - ky * ky) / g;
        v[(m + i, m + i)] = c64::new(ky * kx, 0.0) / g;
    }
    Modes {
        w: None,
        v,
        gamma: gamma.iter().chain(gamma.iter()).cloned().collect(),
    }
}

/// Modes of a lamellar layer: the eigenproblem P Q.
/// Modes of a lamellar layer. P Q is block lower-triangular,
///
///   P Q = [[(I - Kx E^-1 Kx) [[1/eps]]^-1 - ky^2, 0], [C, E - Kx^2 - ky^2]],
///
/// because a layer that varies along x alone has modes with E_x = 0 (the
/// lower block's eigenvectors, "TE to x") and with H_x = 0 (the upper
/// block's, "TM to x"), whose E_y follows from H_x = 0:
/// E_y = -ky (E - Kx^2)^-1 Kx E_x. Two eigenproblems of 2N + 1 instead of one
/// of 4N + 2 (about 4x faster), and ky only shifts their eigenvalues.
fn lamellar(orders: &Orders, layer: &Layer, rule: Factorisation) -> Result<Modes, StamError> {
    let m = orders.size();
    let ky = orders.ky;
    let laurent = layer.toeplitz(m, |e| e);
    let inverse_rule = match rule {
        Factorisation::Li => layer.toeplitz(m, |e| e.inv()).partial_piv_lu().inverse(),
        Factorisation::Laurent => laurent.clone(),
    };
    let laurent_inv = laurent.partial_piv_lu().inverse();
    let kx = &orders.kx;
    // (I - Kx E^-1 Kx) [[1/eps]]^-1 and E - Kx^2, without the -ky^2 shift.
    let kek = Mat::from_fn(m, m, |r, c| {
        let delta = if r == c { 1.0 } else { 0.0 };
        c64::new(delta, 0.0) - laurent_inv[(r, c)] * (kx[r] * kx[c])
    });
    let tm_matrix = &kek * &inverse_rule;
    let mut te_matrix = laurent.clone();
    for (i, &k) in kx.iter().enumerate() {
        te_matrix[(i, i)] -= k * k;
    }
    let eig = |a: &Mat<c64>| {
        a.eigen()
            .map_err(|e| StamError::new(format!("rigorous solver: eigenproblem failed ({e:?})")))
    };
    let tm = eig(&tm_matrix)?;
    let te = eig(&te_matrix)?;
    let tm_ex = tm.U();
    // E_y of the H_x = 0 modes: -ky (E - Kx^2)^-1 Kx E_x.
    let kx_ex = Mat::from_fn(m, m, |r, c| tm_ex[(r, c)] * kx[r]);
    let tm_ey = te_matrix.partial_piv_lu().solve(&kx_ex);
    let mut w = Mat::<c64>::zeros(2 * m, 2 * m);
    for r in 0..m {
        for c in 0..m {
            w[(r, c)] = tm_ex[(r, c)];
            w[(m + r, c)] = tm_ey[(r, c)] * (-ky);
            w[(m + r, m + c)] = te.U()[(r, c)];
        }
    }
    let gamma: Vec<c64> = tm
        .S()
        .column_vector()
        .iter()
        .chain(te.S().column_vector().iter())
        .map(|&g2| kz(g2, ky * ky))
        .collect();
    // V = Q W gamma^-1.
    let mut q = Mat::<c64>::zeros(2 * m, 2 * m);
    for r in 0..m {
        for c in 0..m {
            q[(r, m + c)] = -laurent[(r, c)];
            q[(m + r, c)] = inverse_rule[(r, c)];
        }
        q[(r, r)] = c64::new(-ky * kx[r], 0.0);
        q[(r, m + r)] += kx[r] * kx[r];
        q[(m + r, r)] -= ky * ky;
        q[(m + r, m + r)] = c64::new(ky * kx[r], 0.0);
    }
    let mut v = &q * &w;
    for (c, g) in gamma.iter().enumerate() {
        let inv = g.inv();
        for r in 0..2 * m {
            v[(r, c)] *= inv;
        }
    }
    Ok(Modes {
        w: Some(w),
        v,
        gamma,
    })
}

fn modes(orders: &Orders, layer: &Layer, rule: Factorisation) -> Result<Modes, StamError> {
    match layer.uniform_permittivity() {
        Some(eps) => Ok(homogeneous(orders, eps)),
        None => lamellar(orders, layer, rule),
    }
}

/// One matched interface, kept for the downward (transmission) pass.
struct Interface {
    /// LU of A + B, where forward amplitudes below = 2 (A + B)^-1 (those above).
    sum: faer::linalg::solvers::PartialPivLu<c64>,
    /// exp(i gamma d) of the layer below (None for the substrate).
    phase_below: Option<Vec<c64>>,
}

/// Solve the stack for both incident polarisations, with 2N + 1 orders.
pub fn solve(stack: &Stack, inc: &Incidence, n_orders: usize) -> Result<Diffraction, StamError> {
    solve_with(stack, inc, n_orders, Factorisation::Li)
}

/// `solve` with a chosen factorisation rule.
pub fn solve_with(
    stack: &Stack,
    inc: &Incidence,
    n_orders: usize,
    rule: Factorisation,
) -> Result<Diffraction, StamError> {
    stack.validate()?;
    if !(inc.lambda_nm > 0.0 && inc.lambda_nm.is_finite()) {
        return Err(StamError::new(format!(
            "lambda_nm must be a positive wavelength, got {}",
            inc.lambda_nm
        )));
    }
    if !(inc.theta_rad >= 0.0 && inc.theta_rad < 0.5 * std::f64::consts::PI) {
        return Err(StamError::new(format!(
            "the incidence angle must be in [0, 90) degrees, got {} degrees",
            inc.theta_rad.to_degrees()
        )));
    }
    if !inc.phi_rad.is_finite() {
        return Err(StamError::new("the incidence azimuth must be finite"));
    }
    if n_orders > MAX_ORDERS {
        return Err(StamError::new(format!(
            "orders: at most {MAX_ORDERS} Fourier orders each side, got {n_orders}"
        )));
    }
    let lambda_um = inc.lambda_nm * 1e-3;
    let k0 = 2.0 * std::f64::consts::PI / lambda_um;
    let n1 = stack.superstrate_index;
    let (st, ct) = inc.theta_rad.sin_cos();
    let (sp, cp) = inc.phi_rad.sin_cos();
    let grating_k = lambda_um / stack.period_um;
    let orders = Orders {
        n: n_orders,
        kx: (0..=2 * n_orders)
            .map(|i| n1 * st * cp + (i as f64 - n_orders as f64) * grating_k)
            .collect(),
        ky: n1 * st * sp,
    };
    let m = orders.size();
    let dim = 2 * m;
    let identity = Mat::<c64>::identity(dim, dim);

    // Upward pass: the reflection matrix at the top of each medium.
    let substrate = homogeneous(&orders, stack.substrate_eps);
    let superstrate = homogeneous(&orders, c64::new(n1 * n1, 0.0));
    let mut below = substrate;
    let mut phase_below: Option<Vec<c64>> = None;
    let mut reflection = Mat::<c64>::zeros(dim, dim);
    let mut interfaces: Vec<Interface> = Vec::with_capacity(stack.layers.len() + 1);
    let match_interface = |above: &Modes, below: &Modes, r: &Mat<c64>| {
        // Fields continuous: W_a (u + b) = W_b (I + R) f, V_a (u - b) = V_b (I - R) f.
        let plus = &identity + r;
        let minus = &identity - r;
        let wb = match &below.w {
            Some(w) => w * &plus,
            None => plus,
        };
        let a = match &above.w {
            Some(w) => w.partial_piv_lu().solve(&wb),
            None => wb,
        };
        let b = above.v.partial_piv_lu().solve(&below.v * &minus);
        let sum = &a + &b;
        let diff = &a - &b;
        (sum.partial_piv_lu(), diff)
    };
    for layer in stack.layers.iter().rev() {
        let above = modes(&orders, layer, rule)?;
        let (sum_lu, diff) = match_interface(&above, &below, &reflection);
        // R at the layer's bottom: (A - B)(A + B)^-1, then carried up by X R X.
        let r_bottom = sum_lu
            .solve_transpose(diff.transpose())
            .transpose()
            .to_owned();
        let d = k0 * layer.thickness_um;
        let x: Vec<c64> = above
            .gamma
            .iter()
            .map(|&g| (c64::new(0.0, d) * g).exp())
            .collect();
        reflection = Mat::from_fn(dim, dim, |r, c| x[r] * r_bottom[(r, c)] * x[c]);
        interfaces.push(Interface {
            sum: sum_lu,
            phase_below,
        });
        phase_below = Some(x);
        below = above;
    }
    let (sum_lu, diff) = match_interface(&superstrate, &below, &reflection);
    interfaces.push(Interface {
        sum: sum_lu,
        phase_below,
    });

    // Incident plane wave (unit amplitude, both polarisations as columns).
    let k_inc = [st * cp, st * sp, ct];
    let (s_inc, p_inc) = basis(k_inc, inc.phi_rad);
    let centre = n_orders;
    let mut incident = Mat::<c64>::zeros(dim, 2);
    for (col, e) in [s_inc, p_inc].iter().enumerate() {
        incident[(centre, col)] = c64::new(e[0], 0.0);
        incident[(m + centre, col)] = c64::new(e[1], 0.0);
    }
    let top = interfaces.last().expect("the superstrate interface");
    let y = top.sum.solve(&incident);
    let reflected_e = &diff * &y;
    let kz_inc = n1 * ct;
    let reflected = outgoing(
        &orders,
        &superstrate.gamma,
        &reflected_e,
        n1,
        -1.0,
        kz_inc,
        inc.phi_rad,
    );

    // Downward pass for the transmitted field, where it can carry power.
    let mut transmitted = Vec::new();
    if stack.substrate_eps.im == 0.0 && stack.substrate_eps.re > 0.0 {
        let mut forward = &y * faer::Scale(c64::new(2.0, 0.0));
        let mut downward = interfaces.iter().rev();
        let mut phase = downward.next().and_then(|top| top.phase_below.as_deref());
        for interface in downward {
            let x = phase.expect("a layer above every interface but the top one");
            for c in 0..2 {
                for r in 0..dim {
                    forward[(r, c)] *= x[r];
                }
            }
            forward = &interface.sum.solve(&forward) * faer::Scale(c64::new(2.0, 0.0));
            phase = interface.phase_below.as_deref();
        }
        let n2 = stack.substrate_eps.re.sqrt();
        let substrate = homogeneous(&orders, stack.substrate_eps);
        transmitted = outgoing(
            &orders,
            &substrate.gamma,
            &forward,
            n2,
            1.0,
            kz_inc,
            inc.phi_rad,
        );
    }
    Ok(Diffraction {
        reflected,
        transmitted,
        n_orders: orders.n,
    })
}

/// s and p unit vectors of a direction k (s = z x k normalised, p = s x k),
/// with s = (-sin phi, cos phi, 0) when k is along z.
fn basis(k: [f64; 3], phi_fallback: f64) -> ([f64; 3], [f64; 3]) {
    let kt = (k[0] * k[0] + k[1] * k[1]).sqrt();
    let s = if kt > 1e-12 {
        [-k[1] / kt, k[0] / kt, 0.0]
    } else {
        [-phi_fallback.sin(), phi_fallback.cos(), 0.0]
    };
    let p = [
        s[1] * k[2] - s[2] * k[1],
        s[2] * k[0] - s[0] * k[2],
        s[0] * k[1] - s[1] * k[0],
    ];
    (s, p)
}

/// The propagating orders of an outgoing field whose tangential amplitudes
/// (Ex over the first m rows, Ey below) are `e`, in a medium of real index
/// `n`, travelling along `sign` z.
fn outgoing(
    orders: &Orders,
    gamma: &[c64],
    e: &Mat<c64>,
    n: f64,
    sign: f64,
    kz_incident: f64,
    phi: f64,
) -> Vec<Order> {
    let m = orders.size();
    let ky = orders.ky;
    let mut out = Vec::new();
    for (i, &kx) in orders.kx.iter().enumerate() {
        let kz = gamma[i];
        if !(kx * kx + ky * ky < n * n) || kz.re <= 0.0 {
            continue;
        }
        let kz = kz.re;
        let k = [kx / n, ky / n, sign * kz / n];
        let (s, p) = basis(k, phi);
        let flux = (kz / kz_incident).sqrt();
        let mut jones = [[c64::new(0.0, 0.0); 2]; 2];
        let mut efficiency = [0.0; 2];
        for col in 0..2 {
            let ex = e[(i, col)];
            let ey = e[(m + i, col)];
            // Transversality k . E = 0 gives E_z.
            let ez = -(ex * kx + ey * ky) / (sign * kz);
            let field = [ex, ey, ez];
            for (row, basis_vector) in [s, p].iter().enumerate() {
                let a: c64 = (0..3).map(|j| field[j] * basis_vector[j]).sum();
                jones[row][col] = a * flux;
            }
            efficiency[col] = (kz / kz_incident) * field.iter().map(|f| f.norm_sqr()).sum::<f64>();
        }
        out.push(Order {
            m: i as i64 - orders.n as i64,
            direction: k,
            efficiency,
            jones,
        });
    }
    out
}

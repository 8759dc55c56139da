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
use crate::float_env::StandardFloats;
use crate::StamError;

/// Largest order count N (2N + 1 orders; matrices of 4N + 2).
pub const MAX_ORDERS: usize = 200;

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
    /// p = s x k for a direction k (s along the grooves, y, when k is along z).
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

/// A linear map on the 2(2N + 1) tangential amplitudes (Ex rows, then Ey):
/// the identity, one 2x2 block per order (homogeneous media), or dense.
enum Op {
    Identity,
    /// Block i acts on rows (i, m + i): [[a, b], [c, d]].
    Blocks(Vec<[c64; 4]>),
    Dense(Mat<c64>),
}

impl Op {
    /// self * x.
    fn apply(&self, x: Mat<c64>) -> Mat<c64> {
        match self {
            Op::Identity => x,
            Op::Dense(a) => a * &x,
            Op::Blocks(blocks) => {
                let m = blocks.len();
                let mut y = x;
                for c in 0..y.ncols() {
                    for (i, [a, b, cc, d]) in blocks.iter().enumerate() {
                        let (u, v) = (y[(i, c)], y[(m + i, c)]);
                        y[(i, c)] = a * u + b * v;
                        y[(m + i, c)] = cc * u + d * v;
                    }
                }
                y
            }
        }
    }

    /// x * self.
    fn apply_right(&self, x: Mat<c64>) -> Mat<c64> {
        match self {
            Op::Identity => x,
            Op::Dense(a) => &x * a,
            Op::Blocks(blocks) => {
                let m = blocks.len();
                let mut y = x;
                for r in 0..y.nrows() {
                    for (i, [a, b, c, d]) in blocks.iter().enumerate() {
                        let (u, v) = (y[(r, i)], y[(r, m + i)]);
                        y[(r, i)] = u * a + v * c;
                        y[(r, m + i)] = u * b + v * d;
                    }
                }
                y
            }
        }
    }

    fn dense(&self, dim: usize) -> Mat<c64> {
        match self {
            Op::Dense(a) => a.clone(),
            _ => self.apply(Mat::identity(dim, dim)),
        }
    }
}

/// Modes of one region at one ky: tangential E = W c, tangential H = V c for
/// the down-going modes (up-going: W c, -V c), propagation constants gamma.
struct Modes {
    w: Op,
    w_inv: Op,
    v: Op,
    v_inv: Op,
    gamma: Vec<c64>,
}

/// k_z = sqrt(eps - kt^2) on the branch Im >= 0 (Re >= 0 when real),
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

/// Modes of a homogeneous region: plane waves, W = I, and V = Q gamma^-1 a
/// 2x2 block per order.
fn homogeneous(kx: &[f64], ky: f64, eps: c64) -> Modes {
    let gamma: Vec<c64> = kx.iter().map(|&k| kz(eps, k * k + ky * ky)).collect();
    let blocks: Vec<[c64; 4]> = kx
        .iter()
        .zip(&gamma)
        .map(|(&k, &g)| {
            [
                c64::new(-ky * k, 0.0) / g,
                (c64::new(k * k, 0.0) - eps) / g,
                (eps - ky * ky) / g,
                c64::new(ky * k, 0.0) / g,
            ]
        })
        .collect();
    let inverse = blocks
        .iter()
        .map(|[a, b, c, d]| {
            let det = a * d - b * c;
            [d / det, -b / det, -c / det, a / det]
        })
        .collect();
    Modes {
        w: Op::Identity,
        w_inv: Op::Identity,
        v: Op::Blocks(blocks),
        v_inv: Op::Blocks(inverse),
        gamma: gamma.iter().chain(gamma.iter()).cloned().collect(),
    }
}

/// What a lamellar layer's modes need that does not depend on ky. P Q is
/// block lower-triangular,
///
///   P Q = [[(I - Kx E^-1 Kx) [[1/eps]]^-1 - ky^2, 0], [C, E - Kx^2 - ky^2]],
///
/// because a layer that varies along x alone has modes with E_x = 0 (the
/// lower block's eigenvectors Y, "TE to x") and with H_x = 0 (the upper
/// block's X, "TM to x"), whose E_y follows from H_x = 0:
/// E_y = -ky (E - Kx^2)^-1 Kx X = -ky Z. Two eigenproblems of 2N + 1
/// instead of one of 4N + 2, and ky only shifts their eigenvalues, so one
/// decomposition serves every ky (an efficiency table's whole row). With
/// G = E - Kx^2, whose eigen-decomposition is Y diag(lambda_y) Y^-1:
///
///   W = [[X, 0], [-ky Z, Y]],  W^-1 = [[X^-1, 0], [ky Y^-1 Z X^-1, Y^-1]],
///   V = [[0, -Y lambda_y / gamma_y], [(Ex X - ky^2 S) / gamma_x, ky Kx Y / gamma_y]]
///
/// with S = X + Kx Z and Ex the inverse-rule matrix.
struct Lamellar {
    x: Mat<c64>,
    x_inv: Mat<c64>,
    lambda_x: Vec<c64>,
    y: Mat<c64>,
    y_inv: Mat<c64>,
    lambda_y: Vec<c64>,
    z: Mat<c64>,
    /// Y^-1 Z X^-1.
    t: Mat<c64>,
    /// Ex X.
    ex_x: Mat<c64>,
    s: Mat<c64>,
    /// Kx G^-1.
    kx_g_inv: Mat<c64>,
}

fn eigen(a: &Mat<c64>) -> Result<(Mat<c64>, Vec<c64>), StamError> {
    let e = a
        .eigen()
        .map_err(|e| StamError::new(format!("rigorous solver: eigenproblem failed ({e:?})")))?;
    Ok((
        e.U().to_owned(),
        e.S().column_vector().iter().cloned().collect(),
    ))
}

impl Lamellar {
    fn new(kx: &[f64], layer: &Layer, rule: Factorisation) -> Result<Lamellar, StamError> {
        let m = kx.len();
        let laurent = layer.toeplitz(m, |e| e);
        let inverse_rule = match rule {
            Factorisation::Li => layer.toeplitz(m, |e| e.inv()).partial_piv_lu().inverse(),
            Factorisation::Laurent => laurent.clone(),
        };
        let laurent_inv = laurent.partial_piv_lu().inverse();
        // (I - Kx E^-1 Kx) Ex and G = E - Kx^2.
        let kek = Mat::from_fn(m, m, |r, c| {
            let delta = if r == c { 1.0 } else { 0.0 };
            c64::new(delta, 0.0) - laurent_inv[(r, c)] * (kx[r] * kx[c])
        });
        let (x, lambda_x) = eigen(&(&kek * &inverse_rule))?;
        let mut g = laurent;
        for (i, &k) in kx.iter().enumerate() {
            g[(i, i)] -= k * k;
        }
        let (y, lambda_y) = eigen(&g)?;
        let g_lu = g.partial_piv_lu();
        let kx_x = Mat::from_fn(m, m, |r, c| x[(r, c)] * kx[r]);
        let z = g_lu.solve(&kx_x);
        let kx_diag = Mat::from_fn(m, m, |r, c| {
            if r == c {
                c64::new(kx[r], 0.0)
            } else {
                c64::new(0.0, 0.0)
            }
        });
        // Kx G^-1 = (G^-T Kx)^T.
        let kx_g_inv = g_lu.solve_transpose(&kx_diag).transpose().to_owned();
        let x_inv = x.partial_piv_lu().inverse();
        let y_inv = y.partial_piv_lu().inverse();
        let t = &y_inv * &z * &x_inv;
        let ex_x = &inverse_rule * &x;
        let s = Mat::from_fn(m, m, |r, c| x[(r, c)] + z[(r, c)] * kx[r]);
        Ok(Lamellar {
            x,
            x_inv,
            lambda_x,
            y,
            y_inv,
            lambda_y,
            z,
            t,
            ex_x,
            s,
            kx_g_inv,
        })
    }

    fn modes(&self, kx: &[f64], ky: f64) -> Modes {
        let m = kx.len();
        let ky2 = ky * ky;
        let gamma_x: Vec<c64> = self.lambda_x.iter().map(|&l| kz(l, ky2)).collect();
        let gamma_y: Vec<c64> = self.lambda_y.iter().map(|&l| kz(l, ky2)).collect();
        let mut w = Mat::<c64>::zeros(2 * m, 2 * m);
        let mut w_inv = Mat::<c64>::zeros(2 * m, 2 * m);
        let mut v = Mat::<c64>::zeros(2 * m, 2 * m);
        let mut v_inv = Mat::<c64>::zeros(2 * m, 2 * m);
        // C = (Ex X - ky^2 S) / gamma_x; C^-1 = gamma_x (Ex X - ky^2 S)^-1.
        let c_core = Mat::from_fn(m, m, |r, c| self.ex_x[(r, c)] - self.s[(r, c)] * ky2);
        let c_core_inv = c_core.partial_piv_lu().inverse();
        let c_inv_kx_g_inv = &c_core_inv * &self.kx_g_inv;
        for r in 0..m {
            for c in 0..m {
                w[(r, c)] = self.x[(r, c)];
                w[(m + r, c)] = self.z[(r, c)] * (-ky);
                w[(m + r, m + c)] = self.y[(r, c)];
                w_inv[(r, c)] = self.x_inv[(r, c)];
                w_inv[(m + r, c)] = self.t[(r, c)] * ky;
                w_inv[(m + r, m + c)] = self.y_inv[(r, c)];
                v[(r, m + c)] = -self.y[(r, c)] * self.lambda_y[c] / gamma_y[c];
                v[(m + r, c)] = c_core[(r, c)] / gamma_x[c];
                v[(m + r, m + c)] = self.y[(r, c)] * (ky * kx[r]) / gamma_y[c];
                // V^-1 = [[-C^-1 D B^-1, C^-1], [B^-1, 0]], where
                // -C^-1 D B^-1 = ky C^-1 Kx G^-1 and B^-1 = -(gamma_y / lambda_y) Y^-1.
                v_inv[(r, c)] = gamma_x[r] * c_inv_kx_g_inv[(r, c)] * ky;
                v_inv[(r, m + c)] = gamma_x[r] * c_core_inv[(r, c)];
                v_inv[(m + r, c)] = -gamma_y[r] / self.lambda_y[r] * self.y_inv[(r, c)];
            }
        }
        Modes {
            w: Op::Dense(w),
            w_inv: Op::Dense(w_inv),
            v: Op::Dense(v),
            v_inv: Op::Dense(v_inv),
            gamma: gamma_x.into_iter().chain(gamma_y).collect(),
        }
    }
}

enum LayerBasis {
    Homogeneous(c64),
    Lamellar(Box<Lamellar>),
}

/// A stack prepared at one wavelength and one kx of the incident light:
/// every layer's eigen-decomposition, for any ky (`Prepared::solve`).
pub struct Prepared {
    n_orders: usize,
    kx: Vec<f64>,
    k0: f64,
    superstrate_index: f64,
    substrate_eps: c64,
    layers: Vec<(f64, LayerBasis)>,
}

/// One matched interface, kept for the downward (transmission) pass.
struct Interface {
    /// LU of A + B, where forward amplitudes below = 2 (A + B)^-1 (those above).
    sum: faer::linalg::solvers::PartialPivLu<c64>,
    /// exp(i gamma d) of the layer below (None for the substrate).
    phase_below: Option<Vec<c64>>,
}

/// Match tangential fields at an interface: W_a (u + b) = W_b (I + R) f and
/// V_a (u - b) = V_b (I - R) f, with R the reflection matrix at the top of
/// the medium below (None: nothing comes back up, the substrate). Returns
/// the LU of A + B and A - B, where u = (A + B) f / 2, b = (A - B) f / 2.
fn match_interface(
    above: &Modes,
    below: &Modes,
    reflection: Option<&Mat<c64>>,
    dim: usize,
) -> (faer::linalg::solvers::PartialPivLu<c64>, Mat<c64>) {
    let (a, b) = match reflection {
        None => (
            below.w.apply_right(above.w_inv.dense(dim)),
            below.v.apply_right(above.v_inv.dense(dim)),
        ),
        Some(r) => {
            let identity = Mat::<c64>::identity(dim, dim);
            let a = above.w_inv.apply(below.w.apply(&identity + r));
            let b = above.v_inv.apply(below.v.apply(&identity - r));
            (a, b)
        }
    };
    ((&a + &b).partial_piv_lu(), &a - &b)
}

impl Prepared {
    /// Solve for both incident polarisations at `ky` (the incident
    /// tangential wavevector is (kx, ky) over k0).
    pub fn solve(&self, ky: f64) -> Diffraction {
        // A renderer's thread may flush subnormals, which the solve needs.
        let _ieee = StandardFloats::enter();
        let m = self.kx.len();
        let dim = 2 * m;
        let n1 = self.superstrate_index;
        let kx0 = self.kx[self.n_orders];
        // Upward pass: the reflection matrix at the top of each medium.
        let mut below = homogeneous(&self.kx, ky, self.substrate_eps);
        let mut phase_below: Option<Vec<c64>> = None;
        let mut reflection: Option<Mat<c64>> = None;
        let mut interfaces: Vec<Interface> = Vec::with_capacity(self.layers.len() + 1);
        for (thickness_um, basis) in self.layers.iter().rev() {
            let above = match basis {
                LayerBasis::Homogeneous(eps) => homogeneous(&self.kx, ky, *eps),
                LayerBasis::Lamellar(l) => l.modes(&self.kx, ky),
            };
            let (sum_lu, diff) = match_interface(&above, &below, reflection.as_ref(), dim);
            // R at the layer's bottom, (A - B)(A + B)^-1, carried up by X R X.
            let r_bottom = sum_lu
                .solve_transpose(diff.transpose())
                .transpose()
                .to_owned();
            let d = self.k0 * thickness_um;
            let x: Vec<c64> = above
                .gamma
                .iter()
                .map(|&g| (c64::new(0.0, d) * g).exp())
                .collect();
            reflection = Some(Mat::from_fn(dim, dim, |r, c| {
                x[r] * r_bottom[(r, c)] * x[c]
            }));
            interfaces.push(Interface {
                sum: sum_lu,
                phase_below,
            });
            phase_below = Some(x);
            below = above;
        }
        let superstrate = homogeneous(&self.kx, ky, c64::new(n1 * n1, 0.0));
        // The top interface needs A - B on the two incident columns alone:
        // with U = V_top^-1 V, A + B = (W + U) + (W - U) R and
        // A - B = (W - U) + (W + U) R, one product of full matrices.
        enum Top<'a> {
            Diff(Mat<c64>),
            Split {
                plus: Mat<c64>,
                minus: Mat<c64>,
                r: &'a Mat<c64>,
            },
        }
        let (sum_lu, top) = match reflection.as_ref() {
            Some(r) => {
                let w = below.w.dense(dim);
                let u = superstrate.v_inv.apply(below.v.dense(dim));
                let plus = &w + &u;
                let minus = &w - &u;
                let sum = &plus + &minus * r;
                (sum.partial_piv_lu(), Top::Split { plus, minus, r })
            }
            None => {
                let (sum_lu, diff) = match_interface(&superstrate, &below, None, dim);
                (sum_lu, Top::Diff(diff))
            }
        };
        interfaces.push(Interface {
            sum: sum_lu,
            phase_below,
        });

        // Incident plane wave (unit amplitude, both polarisations as columns).
        let kz_inc = (n1 * n1 - kx0 * kx0 - ky * ky).max(0.0).sqrt();
        let k_inc = [kx0 / n1, ky / n1, kz_inc / n1];
        let (s_inc, p_inc) = basis(k_inc);
        let mut incident = Mat::<c64>::zeros(dim, 2);
        for (col, e) in [s_inc, p_inc].iter().enumerate() {
            incident[(self.n_orders, col)] = c64::new(e[0], 0.0);
            incident[(m + self.n_orders, col)] = c64::new(e[1], 0.0);
        }
        let y = interfaces
            .last()
            .expect("the superstrate interface")
            .sum
            .solve(&incident);
        let reflected_e = match &top {
            Top::Diff(diff) => diff * &y,
            Top::Split { plus, minus, r } => minus * &y + plus * (*r * &y),
        };
        let reflected = self.outgoing(ky, &superstrate.gamma, &reflected_e, n1, -1.0, kz_inc);

        // Downward pass for the transmitted field, where it can carry power.
        let mut transmitted = Vec::new();
        if self.substrate_eps.im == 0.0 && self.substrate_eps.re > 0.0 {
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
            let n2 = self.substrate_eps.re.sqrt();
            let substrate = homogeneous(&self.kx, ky, self.substrate_eps);
            transmitted = self.outgoing(ky, &substrate.gamma, &forward, n2, 1.0, kz_inc);
        }
        Diffraction {
            reflected,
            transmitted,
            n_orders: self.n_orders,
        }
    }

    /// The propagating orders of an outgoing field whose tangential
    /// amplitudes (Ex over the first m rows, Ey below) are `e`, in a medium
    /// of real index `n`, travelling along `sign` z.
    fn outgoing(
        &self,
        ky: f64,
        gamma: &[c64],
        e: &Mat<c64>,
        n: f64,
        sign: f64,
        kz_incident: f64,
    ) -> Vec<Order> {
        let m = self.kx.len();
        let mut out = Vec::new();
        for (i, &kx) in self.kx.iter().enumerate() {
            let kz = gamma[i];
            if !(kx * kx + ky * ky < n * n) || kz.re <= 0.0 {
                continue;
            }
            let kz = kz.re;
            let k = [kx / n, ky / n, sign * kz / n];
            let (s, p) = basis(k);
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
                efficiency[col] =
                    (kz / kz_incident) * field.iter().map(|f| f.norm_sqr()).sum::<f64>();
            }
            out.push(Order {
                m: i as i64 - self.n_orders as i64,
                direction: k,
                efficiency,
                jones,
            });
        }
        out
    }
}

/// Prepare `stack` at `lambda_nm` for incident light whose tangential
/// wavevector has x component `kx_incident` (over k0: n1 sin(theta) cos(phi)),
/// with 2N + 1 orders.
pub fn prepare(
    stack: &Stack,
    lambda_nm: f64,
    kx_incident: f64,
    n_orders: usize,
    rule: Factorisation,
) -> Result<Prepared, StamError> {
    let _ieee = StandardFloats::enter();
    stack.validate()?;
    if !(lambda_nm > 0.0 && lambda_nm.is_finite()) {
        return Err(StamError::new(format!(
            "lambda_nm must be a positive wavelength, got {lambda_nm}"
        )));
    }
    if n_orders > MAX_ORDERS {
        return Err(StamError::new(format!(
            "orders: at most {MAX_ORDERS} Fourier orders each side, got {n_orders}"
        )));
    }
    let lambda_um = lambda_nm * 1e-3;
    let grating_k = lambda_um / stack.period_um;
    // Every propagating order must be among those retained.
    let propagating = (stack.superstrate_index / grating_k).ceil();
    if !(n_orders as f64 > propagating) {
        return Err(StamError::new(format!(
            "orders: N = {n_orders} retains fewer orders than the {} that propagate at \
             {lambda_nm} nm with period_um {}; raise orders above {propagating}",
            2.0 * propagating + 1.0,
            stack.period_um
        )));
    }
    let kx: Vec<f64> = (0..=2 * n_orders)
        .map(|i| kx_incident + (i as f64 - n_orders as f64) * grating_k)
        .collect();
    let layers = stack
        .layers
        .iter()
        .map(|layer| {
            let basis = match layer.uniform_permittivity() {
                Some(eps) => LayerBasis::Homogeneous(eps),
                None => LayerBasis::Lamellar(Box::new(Lamellar::new(&kx, layer, rule)?)),
            };
            Ok((layer.thickness_um, basis))
        })
        .collect::<Result<Vec<_>, StamError>>()?;
    Ok(Prepared {
        n_orders,
        kx,
        k0: 2.0 * std::f64::consts::PI / lambda_um,
        superstrate_index: stack.superstrate_index,
        substrate_eps: stack.substrate_eps,
        layers,
    })
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
    if !(inc.theta_rad >= 0.0 && inc.theta_rad < 0.5 * std::f64::consts::PI) {
        return Err(StamError::new(format!(
            "the incidence angle must be in [0, 90) degrees, got {} degrees",
            inc.theta_rad.to_degrees()
        )));
    }
    if !inc.phi_rad.is_finite() {
        return Err(StamError::new("the incidence azimuth must be finite"));
    }
    let n1 = stack.superstrate_index;
    let st = inc.theta_rad.sin();
    let (sp, cp) = inc.phi_rad.sin_cos();
    let prepared = prepare(stack, inc.lambda_nm, n1 * st * cp, n_orders, rule)?;
    let d = prepared.solve(n1 * st * sp);
    let finite = d
        .reflected
        .iter()
        .chain(&d.transmitted)
        .all(|o| o.efficiency.iter().all(|e| e.is_finite() && *e >= 0.0));
    if !finite {
        return Err(StamError::new(
            "rigorous solver: no finite solution for this geometry (a degenerate \
             or extreme structure); check period_um, the heights and the wavelength",
        ));
    }
    Ok(d)
}

/// s and p unit vectors of a direction k (s = z x k normalised, p = s x k),
/// with s along the grooves (y) when k is along z.
pub(super) fn basis(k: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let kt = (k[0] * k[0] + k[1] * k[1]).sqrt();
    let s = if kt > 1e-12 {
        [-k[1] / kt, k[0] / kt, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let p = [
        s[1] * k[2] - s[2] * k[1],
        s[2] * k[0] - s[0] * k[2],
        s[0] * k[1] - s[1] * k[0],
    ];
    (s, p)
}

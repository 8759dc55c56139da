//! Each order's Mueller matrix from the solver's Jones matrix, in Stokes
//! bases tied to the grooves (what a table can interpolate).
//!
//! Stokes conventions are Mitsuba's (and the core's Fresnel reflection's,
//! `optics::fresnel::conductor_polarization`): for light travelling along
//! d, a basis vector x perpendicular to d and y = d x x; with E = Ex x +
//! Ey y, S = (|Ex|^2 + |Ey|^2, |Ex|^2 - |Ey|^2, 2 Re(Ex Ey*), 2 Im(Ex Ey*)).
//! A Jones matrix J (E_out = J E_in) in such bases has the Mueller matrix
//! M_ij = tr(sigma_i J sigma_j J^H) / 2, with sigma = (1, diag(1, -1),
//! [[0, 1], [1, 0]], [[0, i], [-i, 0]]) (S_k = tr(sigma_k E E^H)); for
//! J = diag(r_s, r_p) this is Mitsuba's `mueller::specular_reflection`.
//!
//! The solver's own bases, s = z x k and p = s x k with z into the
//! substrate, turn with the plane of incidence: near normal incidence they
//! spin with the azimuth, so a table of matrices in them could not be
//! interpolated. The table holds each order's matrix in the groove bases
//! instead: x = y x d normalised (y along the grooves, the direction the
//! grating does not change along), y = d x x. These are smooth over every
//! direction but the two grazing ones along the grooves. The renderer
//! rotates them into its own.
//!
//! Symmetries (why a table of ky >= 0, or of kx >= 0 for a symmetric
//! grating, serves every incidence): a mirror through the xz plane (the
//! grating is invariant along y) or, for a grating that is its own mirror
//! image, through the yz plane, maps the groove bases to themselves up to
//! the sign of one vector, which flips Ex Ey*: M -> D M D, D = diag(1, 1,
//! -1, -1) (`mirrored`).

use faer::c64;

use super::solver::Order;

/// A Mueller matrix, row-major.
pub type Mueller = [f64; 16];

/// The groove basis vector x of a direction of travel d (unit): y x d
/// normalised; x itself for d along the grooves (grazing).
pub fn groove_basis(d: [f64; 3]) -> [f64; 3] {
    // y x d = (d_z, 0, -d_x)
    let (a, b) = (d[2], -d[0]);
    let norm = (a * a + b * b).sqrt();
    if norm > 1e-12 {
        [a / norm, 0.0, b / norm]
    } else {
        [1.0, 0.0, 0.0]
    }
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The Mueller matrix of a Jones matrix given in (x, d x x) bases.
pub fn mueller_of_jones(j: [[c64; 2]; 2]) -> Mueller {
    let i = c64::new(0.0, 1.0);
    let (one, zero) = (c64::new(1.0, 0.0), c64::new(0.0, 0.0));
    let sigma = [
        [[one, zero], [zero, one]],
        [[one, zero], [zero, -one]],
        [[zero, one], [one, zero]],
        [[zero, i], [-i, zero]],
    ];
    let mul = |a: [[c64; 2]; 2], b: [[c64; 2]; 2]| {
        let mut m = [[zero; 2]; 2];
        for r in 0..2 {
            for c in 0..2 {
                m[r][c] = a[r][0] * b[0][c] + a[r][1] * b[1][c];
            }
        }
        m
    };
    let jh = [
        [j[0][0].conj(), j[1][0].conj()],
        [j[0][1].conj(), j[1][1].conj()],
    ];
    let mut out = [0.0; 16];
    for (a, sa) in sigma.iter().enumerate() {
        for (b, sb) in sigma.iter().enumerate() {
            let p = mul(mul(mul(*sa, j), *sb), jh);
            out[4 * a + b] = 0.5 * (p[0][0] + p[1][1]).re;
        }
    }
    out
}

/// An order's Mueller matrix in the groove bases of the incident direction
/// of travel `incident` and of the order's (both unit, in the solver's
/// frame), from its Jones matrix in the solver's (s, p) bases. M[0][0] is
/// the order's unpolarised efficiency.
pub fn order_mueller(incident: [f64; 3], order: &Order) -> Mueller {
    // The solver's (s, p) and the groove bases (x, d x x) of a direction.
    let change = |d: [f64; 3]| {
        let s = solver_s(d);
        let p = cross(s, d);
        let x = groove_basis(d);
        let y = cross(d, x);
        // Components in (x, y) of a field with components (a, b) in (s, p).
        [[dot(x, s), dot(x, p)], [dot(y, s), dot(y, p)]]
    };
    let a_in = change(incident);
    let a_out = change(order.direction);
    // J' = A_out J A_in^T (A orthogonal: its transpose takes (x, y) to (s, p)).
    let mut j = [[c64::new(0.0, 0.0); 2]; 2];
    for (row, out_row) in j.iter_mut().zip(&a_out) {
        for (v, in_row) in row.iter_mut().zip(&a_in) {
            for (jones_row, wa) in order.jones.iter().zip(out_row) {
                for (jab, wb) in jones_row.iter().zip(in_row) {
                    *v += *jab * (wa * wb);
                }
            }
        }
    }
    mueller_of_jones(j)
}

/// The solver's s of a direction k: z x k normalised, y along the grooves
/// for k along z (`solver::basis`).
fn solver_s(k: [f64; 3]) -> [f64; 3] {
    super::solver::basis(k).0
}

/// D M D, D = diag(1, 1, -1, -1): the matrix of the mirrored incidence.
pub fn mirrored(m: &mut Mueller) {
    for (e, v) in m.iter_mut().enumerate() {
        if odd_in_ky(e) {
            *v = -*v;
        }
    }
}

/// Degree of linear polarisation of unpolarised light after `m`.
pub fn dolp(m: &Mueller) -> f64 {
    if m[0] > 0.0 {
        m[4].hypot(m[8]) / m[0]
    } else {
        0.0
    }
}

/// Whether element (r, c) of a Mueller matrix lies in an off-diagonal
/// block ([I, Q] x [U, V] or [U, V] x [I, Q]): odd in ky, even elsewhere.
pub fn odd_in_ky(element: usize) -> bool {
    let (r, c) = (element / 4, element % 4);
    (r < 2) != (c < 2)
}

fn paulis() -> [[[c64; 2]; 2]; 4] {
    let i = c64::new(0.0, 1.0);
    let (one, zero) = (c64::new(1.0, 0.0), c64::new(0.0, 0.0));
    [
        [[one, zero], [zero, one]],
        [[one, zero], [zero, -one]],
        [[zero, one], [one, zero]],
        [[zero, i], [-i, zero]],
    ]
}

/// sigma_a (x) conj(sigma_b) at (r, c) of the 4x4 Kronecker product.
fn kron(sigma: &[[[c64; 2]; 2]; 4], a: usize, b: usize, r: usize, c: usize) -> c64 {
    sigma[a][r / 2][c / 2] * sigma[b][r % 2][c % 2].conj()
}

/// The Cloude coherency matrix H = (1/4) sum_ij M_ij sigma_i (x)
/// conj(sigma_j): Hermitian, with trace M[0][0]; positive semi-definite
/// exactly when M is physically realisable (a mixture of Jones matrices).
fn coherency(m: &Mueller) -> faer::Mat<c64> {
    let h = coherency_array(m);
    faer::Mat::from_fn(4, 4, |r, c| h[r][c])
}

/// The eigenvalues of the Cloude coherency matrix of `m` over m[0][0],
/// ascending (all >= 0 for a physically realisable matrix).
pub fn coherency_eigenvalues(m: &Mueller) -> [f64; 4] {
    let scale = if m[0] > 0.0 { 1.0 / m[0] } else { 1.0 };
    let values = coherency(m)
        .self_adjoint_eigenvalues(faer::Side::Lower)
        .unwrap_or_else(|_| vec![f64::NAN; 4]);
    let mut out = [0.0; 4];
    for (o, v) in out.iter_mut().zip(values) {
        *o = v * scale;
    }
    out
}

/// The coherency matrix (`coherency`) as an array, from each Pauli
/// matrix's two non-zero entries.
fn coherency_array(m: &Mueller) -> [[c64; 4]; 4] {
    let sigma = paulis();
    let mut h = [[c64::new(0.0, 0.0); 4]; 4];
    for a in 0..4 {
        for b in 0..4 {
            let w = 0.25 * m[4 * a + b];
            if w == 0.0 {
                continue;
            }
            for (r1, row_a) in sigma[a].iter().enumerate() {
                for (c1, &sa) in row_a.iter().enumerate() {
                    if sa == c64::new(0.0, 0.0) {
                        continue;
                    }
                    for (r2, row_b) in sigma[b].iter().enumerate() {
                        for (c2, &sb) in row_b.iter().enumerate() {
                            if sb != c64::new(0.0, 0.0) {
                                h[2 * r1 + r2][2 * c1 + c2] += sa * sb.conj() * w;
                            }
                        }
                    }
                }
            }
        }
    }
    h
}

fn det3(h: &[[c64; 4]; 4], i: [usize; 3], j: [usize; 3]) -> c64 {
    let e = |a: usize, b: usize| h[i[a]][j[b]];
    e(0, 0) * (e(1, 1) * e(2, 2) - e(1, 2) * e(2, 1))
        - e(0, 1) * (e(1, 0) * e(2, 2) - e(1, 2) * e(2, 0))
        + e(0, 2) * (e(1, 0) * e(2, 1) - e(1, 1) * e(2, 0))
}

/// How far below zero (relative to [0][0]) a coherency eigenvalue may lie
/// for `realisable` to leave a matrix as it is.
const SLACK: f64 = 1e-7;

/// Whether the coherency matrix of `m` has no eigenvalue below -SLACK
/// m[0][0]: the sums of its principal minors of each order (the
/// coefficients of its characteristic polynomial) are all >= 0, which for
/// a Hermitian matrix holds exactly when no eigenvalue is negative.
fn is_realisable(m: &Mueller) -> bool {
    let mut h = coherency_array(m);
    // Shifted by SLACK [0][0]: true exactly when no eigenvalue is below
    // -SLACK [0][0] (the coefficients are then those of H + SLACK I).
    let t = m[0].abs().max(1e-300);
    for (i, row) in h.iter_mut().enumerate() {
        row[i] += c64::new(SLACK * t, 0.0);
    }
    let tol = 0.0;
    let d = |i: usize| h[i][i].re;
    let e1: f64 = (0..4).map(d).sum();
    let pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)];
    let e2: f64 = pairs
        .iter()
        .map(|&(i, j)| d(i) * d(j) - h[i][j].norm_sqr())
        .sum();
    let triples = [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]];
    let e3: f64 = triples.iter().map(|&k| det3(&h, k, k).re).sum();
    // det by the first row's cofactors
    let mut e4 = c64::new(0.0, 0.0);
    for c in 0..4 {
        let cols: Vec<usize> = (0..4).filter(|&x| x != c).collect();
        let minor = det3(&h, [1, 2, 3], [cols[0], cols[1], cols[2]]);
        let sign = if c % 2 == 0 { 1.0 } else { -1.0 };
        e4 += h[0][c] * minor * sign;
    }
    e1 >= -tol * t && e2 >= -tol * t * t && e3 >= -tol * t * t * t && e4.re >= -tol * t.powi(4)
}

/// The nearest realisable matrix (Cloude's filter): the coherency
/// matrix's negative eigenvalues set to 0, rescaled to keep m[0][0].
/// Interpolating a table between its nodes can leave a matrix a little
/// outside the realisable set; the renderer must not get one. A matrix
/// that is realisable (most) returns as it is after a test of its
/// characteristic polynomial, without an eigendecomposition.
pub fn realisable(m: &Mueller) -> Mueller {
    if is_realisable(m) {
        return *m;
    }
    let h = coherency(m);
    let Ok(eigen) = h.self_adjoint_eigen(faer::Side::Lower) else {
        return *m;
    };
    let (u, values) = (eigen.U(), eigen.S().column_vector());
    if (0..4).all(|k| values[k].re >= 0.0) {
        return *m;
    }
    let kept: f64 = (0..4).map(|k| values[k].re.max(0.0)).sum();
    if !(kept > 0.0) {
        return *m;
    }
    let scale = m[0] / kept;
    let filtered = faer::Mat::from_fn(4, 4, |r, c| {
        let mut v = c64::new(0.0, 0.0);
        for k in 0..4 {
            let l = values[k].re.max(0.0) * scale;
            if l > 0.0 {
                v += u[(r, k)] * u[(c, k)].conj() * l;
            }
        }
        v
    });
    // M_ij = tr(H (sigma_i (x) conj(sigma_j))).
    let sigma = paulis();
    let mut out = [0.0; 16];
    for a in 0..4 {
        for b in 0..4 {
            let mut t = c64::new(0.0, 0.0);
            for r in 0..4 {
                for c in 0..4 {
                    t += filtered[(r, c)] * kron(&sigma, a, b, c, r);
                }
            }
            out[4 * a + b] = t.re;
        }
    }
    out
}

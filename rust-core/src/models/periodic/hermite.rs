//! Hermite bases on a table cell, shared by the native order tables (f64)
//! and the programs that read them (f32): written factored, so that every
//! weight keeps its relative precision near either end of the cell.

/// Quintic Hermite basis at t in [0, 1] (s = 1 - t) for a value, first and
/// second derivative at each end, the derivatives' weights without their
/// powers of the step (nor the 1/2 of the second): [value at 0, slope at 0,
/// curvature at 0, value at 1, slope at 1, curvature at 1]. Factored, so
/// that each weight keeps its relative precision in f32: the expanded
/// polynomials (1 - 10t^3 + 15t^4 - 6t^5, ...) cancel near t = 1, where a
/// weight of 1e-6 came out with an absolute error of 5e-7, and a table
/// read near a zero of c_n (the doubly grazing end, beta = 0) lost 6e-4
/// of its value in the JIT path.
pub(crate) fn quintic_hermite_basis<T>(t: T, s: T) -> [T; 6]
where
    T: Copy
        + std::ops::Add<Output = T>
        + std::ops::Add<f64, Output = T>
        + std::ops::Mul<Output = T>
        + std::ops::Mul<f64, Output = T>
        + std::ops::Neg<Output = T>,
{
    let (t2, s2) = (t * t, s * s);
    let (t3, s3) = (t2 * t, s2 * s);
    let (one_3t, one_3s) = (t * 3.0 + 1.0, s * 3.0 + 1.0);
    [
        s3 * (t2 * 6.0 + one_3t),
        t * s3 * one_3t,
        t2 * s3,
        t3 * (s2 * 6.0 + one_3s),
        -(t3 * s * one_3s),
        t3 * s2,
    ]
}

/// Cubic Hermite basis at t in [0, 1] (s = 1 - t): [value at 0, slope at 0,
/// value at 1, slope at 1], the slopes' weights per unit step; factored for
/// the reason `quintic_hermite_basis` gives.
pub(crate) fn cubic_hermite_basis<T>(t: T, s: T) -> [T; 4]
where
    T: Copy
        + std::ops::Add<f64, Output = T>
        + std::ops::Mul<Output = T>
        + std::ops::Mul<f64, Output = T>
        + std::ops::Neg<Output = T>,
{
    let (t2, s2) = (t * t, s * s);
    [
        s2 * (t * 2.0 + 1.0),
        t * s2,
        t2 * (s * 2.0 + 1.0),
        -(t2 * s),
    ]
}

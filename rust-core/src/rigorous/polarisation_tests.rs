//! Each order's Mueller matrix: the Jones-to-Mueller map against the
//! Fresnel reflection's, realisability, and the polarised table's reads
//! (with both mirror symmetries) against direct solves.

use faer::c64;

use super::layers::Grating;
use super::polarisation::{coherency_eigenvalues, mueller_of_jones, order_mueller, Mueller};
use super::table::{self, TableSpec};
use super::tests::aluminium;
use super::{solve, Incidence};
use crate::optics::fresnel::conductor_polarization;
use crate::optics::profile::Profile;

/// A pseudo-random number in [0, 1) (xorshift), for reproducible cases.
fn uniform(state: &mut u64) -> f64 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    (*state >> 11) as f64 / (1u64 << 53) as f64
}

#[test]
fn a_diagonal_jones_matrix_is_the_fresnel_reflections_mueller_matrix() {
    // diag(r_s, r_p) against the (b, c, s) of Mitsuba's
    // mueller::specular_reflection, which the core's Fresnel term follows.
    for (eta, k) in [(1.2, 6.9), (0.5, 2.4), (1.5, 0.0)] {
        let n = c64::new(eta, k);
        for cos in [0.2, 0.5, 0.9] {
            let w = (n * n - c64::new(1.0 - cos * cos, 0.0)).sqrt();
            let rs = (c64::new(cos, 0.0) - w) / (c64::new(cos, 0.0) + w);
            let rp = (n * n * cos - w) / (n * n * cos + w);
            let m = mueller_of_jones([[rs, c64::new(0.0, 0.0)], [c64::new(0.0, 0.0), rp]]);
            let [b, c, s] = conductor_polarization(cos, eta, k);
            let want = [
                1.0, b, 0.0, 0.0, b, 1.0, 0.0, 0.0, 0.0, 0.0, c, s, 0.0, 0.0, -s, c,
            ];
            for (got, want) in m.iter().zip(want) {
                assert!(
                    (got / m[0] - want).abs() < 1e-12,
                    "n = {eta} + {k}i, cos {cos}: {m:?} against {want:?}"
                );
            }
            assert!((m[0] - 0.5 * (rs.norm_sqr() + rp.norm_sqr())).abs() < 1e-14);
        }
    }
}

#[test]
fn coherency_eigenvalues_tell_realisable_matrices() {
    let mut state = 0x9e3779b97f4a7c15u64;
    for _ in 0..200 {
        let mut z = || c64::new(uniform(&mut state) - 0.5, uniform(&mut state) - 0.5);
        let j = [[z(), z()], [z(), z()]];
        let m = mueller_of_jones(j);
        let e = coherency_eigenvalues(&m);
        // One Jones matrix: one eigenvalue 1, three 0.
        assert!(
            (e[3] - 1.0).abs() < 1e-9 && e[..3].iter().all(|v| v.abs() < 1e-9),
            "{e:?}"
        );
    }
    // The ideal depolarizer: four equal quarters.
    let mut depolarizer: Mueller = [0.0; 16];
    depolarizer[0] = 1.0;
    assert!(coherency_eigenvalues(&depolarizer)
        .iter()
        .all(|v| (v - 0.25).abs() < 1e-12));
    // Not realisable: the identity with V reversed (a conjugation), and a
    // diattenuation above 1.
    let mut reversed: Mueller = [0.0; 16];
    for (i, v) in [1.0, 1.0, 1.0, -1.0].iter().enumerate() {
        reversed[5 * i] = *v;
    }
    assert!(coherency_eigenvalues(&reversed)[0] < -0.1);
    let mut too_much = depolarizer;
    too_much[1] = 1.2;
    too_much[4] = 1.2;
    assert!(coherency_eigenvalues(&too_much)[0] < -0.01);
}

/// The rigorous tests' small table grid, polarised.
fn spec(orders: usize) -> TableSpec {
    TableSpec {
        polarised: true,
        ..super::tests::small_spec(orders)
    }
}

/// The table's Mueller matrix at its own nodes, read at every sign of kx
/// and ky, against the solver at that incidence: the mirrors D M D the
/// table applies are the solver's, and its storage loses only f32.
fn check_nodes_and_mirrors(grating: &Grating, nodes: &[(usize, usize, f64)]) -> f64 {
    let spec = spec(10);
    let t = table::build(grating, &spec).unwrap();
    assert!(t.is_polarised());
    let mut worst = 0.0f64;
    // (wavelength row, kx row, place along the row's ky nodes)
    for &(il, ix, at) in nodes {
        let (lambda, kx) = (t.lambda_nm(il), t.kx(ix));
        let ky_nodes = t.ky_nodes(il, ix);
        let ky = ky_nodes[(at * (ky_nodes.len() - 1) as f64) as usize];
        for (sx, sy) in [(1.0, 1.0), (-1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)] {
            let (qx, qy) = (sx * kx, sy * ky);
            let r = qx.hypot(qy);
            let inc = Incidence {
                lambda_nm: lambda,
                theta_rad: r.asin(),
                phi_rad: qy.atan2(qx),
            };
            let d = solve(&grating.stack(lambda, 1.0), &inc, spec.orders).unwrap();
            let incident = [qx, qy, (1.0 - r * r).sqrt()];
            for o in &d.reflected {
                let want = order_mueller(incident, o);
                let got = t.mueller(lambda, qx, qy, o.m).unwrap();
                for (g, w) in got.iter().zip(want) {
                    worst = worst.max((g - w).abs());
                }
            }
        }
    }
    worst
}

#[test]
fn the_polarised_table_is_the_solver_at_its_nodes_under_both_mirrors() {
    // The compact disc (symmetric: rows for kx >= 0 alone) and an
    // asymmetric tabulated profile (rows for both signs of kx).
    let disc = super::tests::compact_disc();
    let worst = check_nodes_and_mirrors(&disc, &[(0, 1, 0.2), (1, 2, 0.5), (2, 3, 0.8)]);
    println!("compact disc: worst element {worst:.2e}");
    assert!(worst < 2e-6, "compact disc: {worst}");
    let skewed = Grating {
        period_um: 1.3,
        profile: Profile::Tabulated {
            heights_um: vec![0.0, 0.05, 0.16, 0.2, 0.12, 0.03],
        },
        metal: aluminium(),
        slices: 3,
    };
    let worst = check_nodes_and_mirrors(&skewed, &[(0, 2, 0.3), (1, 6, 0.6), (2, 5, 0.1)]);
    println!("asymmetric profile: worst element {worst:.2e}");
    assert!(worst < 2e-6, "asymmetric profile: {worst}");
}

#[test]
fn an_unpolarised_table_has_no_mueller_matrices() {
    let flat = Grating {
        period_um: 1.0,
        profile: Profile::Sine { height_um: 0.05 },
        metal: aluminium(),
        slices: 2,
    };
    let t = table::build(
        &flat,
        &TableSpec {
            polarised: false,
            n_kx: 3,
            n_lambda: 1,
            ..spec(4)
        },
    )
    .unwrap();
    assert!(!t.is_polarised() && t.mueller(500.0, 0.1, 0.1, 0).is_none());
}

#[test]
fn the_quick_realisability_test_agrees_with_the_eigenvalues() {
    // Random mixtures of Jones matrices, some pushed outside the realisable
    // set by a perturbation: `realisable` returns a matrix as it is exactly
    // when its coherency eigenvalues are >= 0 (within rounding), and
    // otherwise one whose are.
    let mut state = 0x1234_5678_9abc_def1u64;
    let (mut kept, mut mended) = (0, 0);
    for i in 0..2000 {
        let mut m: Mueller = [0.0; 16];
        for _ in 0..(1 + i % 3) {
            let mut z = || c64::new(uniform(&mut state) - 0.5, uniform(&mut state) - 0.5);
            let one = mueller_of_jones([[z(), z()], [z(), z()]]);
            m.iter_mut().zip(one).for_each(|(a, b)| *a += b);
        }
        if i % 2 == 1 {
            let e = (uniform(&mut state) * 16.0) as usize;
            m[e] += (uniform(&mut state) - 0.5) * 0.2 * m[0];
        }
        let lowest = coherency_eigenvalues(&m)[0];
        let r = super::polarisation::realisable(&m);
        if r == m {
            kept += 1;
            assert!(lowest > -1e-9, "kept a matrix with eigenvalue {lowest}");
        } else {
            mended += 1;
            assert!(lowest < 0.0);
            assert!(coherency_eigenvalues(&r)[0] > -1e-9 && (r[0] - m[0]).abs() < 1e-9 * m[0]);
        }
    }
    println!("{kept} kept, {mended} mended");
    assert!(kept > 500 && mended > 200);
}

//! A rigorous grating's Mueller matrices as the material gives them
//! (`Brdf::mueller`): a flat grating reflects as Fresnel says, the disc's
//! orders carry the solver's polarisation, every matrix is realisable.

use std::sync::OnceLock;

use glam::DVec3;

use crate::material::Brdf;
use crate::optics::fresnel::{metal_by_name, Fresnel};
use crate::rigorous::polarisation::{coherency_eigenvalues, dolp, mueller_of_jones, Mueller};
use crate::rigorous::{solve, Grating, Incidence, Medium};

use super::params::{CD_BUMP_HEIGHT_UM, CD_BUMP_WIDTH_UM, CD_PERIOD_UM};
use super::Profile;

fn uniform(state: &mut u64) -> f64 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    (*state >> 11) as f64 / (1u64 << 53) as f64
}

fn direction(theta_deg: f64, phi_deg: f64) -> DVec3 {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    DVec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
}

/// Mitsuba's rotator: the Stokes basis turned by theta about the direction
/// of travel (counter-clockwise looking against it).
fn rotator(theta: f64) -> [[f64; 4]; 4] {
    let (s, c) = (2.0 * theta).sin_cos();
    [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, c, s, 0.0],
        [0.0, -s, c, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ]
}

/// The rotation of a Stokes vector from basis `current` to `target` (both
/// perpendicular to the direction of travel d), as Mitsuba's
/// `mueller::rotate_stokes_basis`.
fn rotate_stokes_basis(d: DVec3, current: DVec3, target: DVec3) -> [[f64; 4]; 4] {
    let mut theta = current.dot(target).clamp(-1.0, 1.0).acos();
    if d.dot(current.cross(target)) < 0.0 {
        theta = -theta;
    }
    rotator(theta)
}

fn mul(a: [[f64; 4]; 4], b: [[f64; 4]; 4]) -> [[f64; 4]; 4] {
    let mut m = [[0.0; 4]; 4];
    for r in 0..4 {
        for c in 0..4 {
            m[r][c] = (0..4).map(|k| a[r][k] * b[k][c]).sum();
        }
    }
    m
}

/// `m` (bases `from` of d_in and d_out) in the bases `to`, as Mitsuba's
/// `mueller::rotate_mueller_basis`.
fn rotate_bases(m: &Mueller, d: [DVec3; 2], from: [DVec3; 2], to: [DVec3; 2]) -> Mueller {
    let mat = [
        [m[0], m[1], m[2], m[3]],
        [m[4], m[5], m[6], m[7]],
        [m[8], m[9], m[10], m[11]],
        [m[12], m[13], m[14], m[15]],
    ];
    let out = mul(
        mul(rotate_stokes_basis(d[1], from[1], to[1]), mat),
        rotate_stokes_basis(d[0], to[0], from[0]),
    );
    let mut flat = [0.0; 16];
    for r in 0..4 {
        for c in 0..4 {
            flat[4 * r + c] = out[r][c];
        }
    }
    flat
}

#[test]
fn a_flat_rigorous_grating_reflects_as_fresnel_says() {
    // A grating of zero height is a mirror of aluminium: at the mirror
    // pair its Mueller matrix, from the solver's amplitudes in the groove
    // bases, turned into the plane of reflection's bases, is the Fresnel
    // reflection's (the core's, which is Mitsuba's specular_reflection).
    // Conical incidence (any azimuth to the grooves) turns the groove
    // bases away from the plane of reflection, which the comparison needs.
    let brdf = Brdf::from_json(
        r#"{"surface":"periodic","profile":"rect","period_um":0.6,"height_um":0.0001,"width_um":0.3,"coherence_um":20,"orders":"rigorous","fresnel":"aluminium","fourier_orders":8}"#,
    )
    .unwrap();
    let fresnel = Fresnel::metal(metal_by_name("aluminium").unwrap());
    let mut state = 0x2545f4914f6cdd1du64;
    let mut errors = Vec::new();
    for _ in 0..300 {
        let theta = 75.0 * uniform(&mut state);
        let phi = 360.0 * uniform(&mut state);
        let lambda = 400.0 + 300.0 * uniform(&mut state);
        let from = direction(theta, phi);
        let to = DVec3::new(-from.x, -from.y, from.z);
        let (m, bases) = brdf.mueller(from, to, lambda).unwrap();
        let [b, c, s] = fresnel.polarization(from.z, lambda);
        let want = [
            1.0, b, 0.0, 0.0, b, 1.0, 0.0, 0.0, 0.0, 0.0, c, s, 0.0, 0.0, -s, c,
        ];
        // The plane of reflection's bases: z x d, normalised (at normal
        // incidence any axis: the matrix is then rotation invariant).
        let axis = |d: DVec3| {
            let a = DVec3::Z.cross(d);
            if a.length() > 1e-9 {
                a.normalize()
            } else {
                DVec3::X
            }
        };
        let d = [-from, to];
        let got = rotate_bases(&m, d, bases, [axis(d[0]), axis(d[1])]);
        let worst = got
            .iter()
            .zip(want)
            .map(|(g, w)| (g - w).abs())
            .fold(0.0, f64::max);
        errors.push((theta, worst));
    }
    // Within 50 degrees and beyond (where the metal's retardance turns
    // fastest and the table's rows are sparsest).
    let summary = |low: f64, high: f64| {
        let mut e: Vec<f64> = errors
            .iter()
            .filter(|(t, _)| (low..high).contains(t))
            .map(|(_, e)| *e)
            .collect();
        e.sort_by(f64::total_cmp);
        (e[e.len() / 2], e[e.len() * 9 / 10], e[e.len() - 1])
    };
    let (near, far) = (summary(0.0, 50.0), summary(50.0, 75.0));
    println!(
        "flat grating against Fresnel, worst element per pair (p50, p90, max): 0-50 deg {:.1e} {:.1e} {:.1e}; 50-75 deg {:.1e} {:.1e} {:.1e}",
        near.0, near.1, near.2, far.0, far.1, far.2
    );
    assert!(near.1 < 0.02 && near.2 < 0.04, "{near:?}");
    assert!(far.1 < 0.08 && far.2 < 0.15, "{far:?}");
}

/// The rigorous compact disc (its tables take seconds).
fn disc() -> &'static Brdf {
    static DISC: OnceLock<Brdf> = OnceLock::new();
    DISC.get_or_init(|| {
        Brdf::from_json(r#"{"surface":"cd","fresnel":"aluminium","orders":"rigorous"}"#).unwrap()
    })
}

#[test]
fn the_discs_orders_carry_the_solvers_polarisation() {
    // Each propagating order at random incidences: the degree of linear
    // polarisation of unpolarised light after the material's matrix (read
    // from its table at the exact order pair) against the solver's Jones
    // matrix there (basis-free, so this checks the table's reads, not its
    // bases).
    let brdf = disc();
    let grating = Grating {
        period_um: CD_PERIOD_UM,
        profile: Profile::Rect {
            height_um: CD_BUMP_HEIGHT_UM,
            width_um: CD_BUMP_WIDTH_UM,
        },
        metal: Medium::Metal(metal_by_name("aluminium").unwrap()),
        slices: 16,
    };
    let n = crate::rigorous::default_fourier_orders(CD_PERIOD_UM, 1.0);
    let mut state = 0x853c49e6748fea9bu64;
    let mut errors = Vec::new();
    let mut powers = Vec::new();
    for _ in 0..24 {
        let inc = Incidence {
            lambda_nm: 400.0 + 300.0 * uniform(&mut state),
            theta_rad: (70.0 * uniform(&mut state)).to_radians(),
            phi_rad: (360.0 * uniform(&mut state)).to_radians(),
        };
        let d = solve(&grating.stack(inc.lambda_nm, 1.0), &inc, n).unwrap();
        let (st, ct) = inc.theta_rad.sin_cos();
        // The solver's frame is the material's turned half a turn about x.
        let from = DVec3::new(-st * inc.phi_rad.cos(), st * inc.phi_rad.sin(), ct);
        for o in &d.reflected {
            let k = o.direction;
            let to = DVec3::new(k[0], -k[1], -k[2]);
            if o.unpolarised() < 1e-3 || to.z < 0.05 {
                continue;
            }
            let want = dolp(&mueller_of_jones(o.jones));
            let (m, _) = brdf.mueller(from, to, inc.lambda_nm).unwrap();
            errors.push((dolp(&m) - want).abs());
            powers.push(o.unpolarised() * (dolp(&m) - want).abs());
        }
    }
    let rms = (powers.iter().map(|p| p * p).sum::<f64>() / powers.len() as f64).sqrt();
    println!("polarised power (efficiency x DoLP) error: rms {rms:.1e}");
    errors.sort_by(f64::total_cmp);
    let at = |q: f64| errors[((errors.len() - 1) as f64 * q) as usize];
    println!(
        "degree of linear polarisation, {} orders: p50 {:.1e} p90 {:.1e} max {:.1e}",
        errors.len(),
        at(0.5),
        at(0.9),
        at(1.0)
    );
    // The efficiencies' own interpolation error is rms 0.009 (docs/rigorous.md).
    assert!(rms < 0.015 && at(0.5) < 0.04, "{errors:?}");
}

#[test]
fn the_discs_matrices_are_realisable_everywhere() {
    // Random pairs, half of them on an order's lobe: [0][0] is 1, the
    // matrix is physically realisable, and no light leaves more than fully
    // polarised.
    let brdf = disc();
    let mut state = 0xda3e39cb94b95bdbu64;
    let (mut lowest, mut most) = (f64::INFINITY, 0.0f64);
    for i in 0..400 {
        let from = direction(80.0 * uniform(&mut state), 360.0 * uniform(&mut state));
        let lambda = 380.0 + 400.0 * uniform(&mut state);
        let to = if i % 2 == 0 {
            direction(80.0 * uniform(&mut state), 360.0 * uniform(&mut state))
        } else {
            // On order n's lobe: u = -(from.x + to.x) = n lambda / Lam.
            let n = (uniform(&mut state) * 7.0) as i64 - 3;
            let x = -from.x + n as f64 * lambda * 1e-3 / CD_PERIOD_UM;
            let y = -from.y;
            if x * x + y * y >= 0.99 {
                continue;
            }
            DVec3::new(x, y, (1.0 - x * x - y * y).sqrt())
        };
        let (m, bases) = brdf.mueller(from, to, lambda).unwrap();
        assert!(
            m.iter().all(|v| v.is_finite()) && (m[0] - 1.0).abs() < 1e-12,
            "{m:?}"
        );
        assert!(bases.iter().all(|b| (b.length() - 1.0).abs() < 1e-9));
        assert!(bases[0].dot(from).abs() < 1e-9 && bases[1].dot(to).abs() < 1e-9);
        lowest = lowest.min(coherency_eigenvalues(&m)[0]);
        let stokes = [m[0], m[4], m[8], m[12]];
        most = most.max(stokes[1].hypot(stokes[2]).hypot(stokes[3]) / stokes[0]);
    }
    println!("lowest coherency eigenvalue {lowest:.2e}, most polarised {most:.4}");
    assert!(lowest > -1e-6 && most <= 1.0 + 1e-9);
}

#[test]
fn a_covered_grating_has_no_mueller_matrix() {
    let brdf = Brdf::from_json(
        r#"{"surface":"periodic","profile":"rect","period_um":0.6,"height_um":0.05,"width_um":0.3,"coherence_um":20,"orders":"rigorous","fresnel":"aluminium","fourier_orders":8,"cover_eta":1.5}"#,
    )
    .unwrap();
    assert!(brdf
        .mueller(direction(30.0, 10.0), direction(30.0, 190.0), 550.0)
        .is_none());
}

#[test]
#[ignore]
fn print_mueller_costs() {
    let brdf = disc();
    let mut state = 7u64;
    let pairs: Vec<(DVec3, DVec3, f64)> = (0..20000)
        .map(|_| {
            let from = direction(60.0 * uniform(&mut state), 360.0 * uniform(&mut state));
            let n = (uniform(&mut state) * 5.0) as i64 - 2;
            let lambda = 400.0 + 300.0 * uniform(&mut state);
            let x = -from.x + n as f64 * lambda * 1e-3 / CD_PERIOD_UM;
            let y = -from.y + 0.002;
            let to = DVec3::new(x, y, (1.0 - x * x - y * y).max(0.01).sqrt()).normalize();
            (from, to, lambda)
        })
        .collect();
    brdf.mueller(pairs[0].0, pairs[0].1, 500.0);
    let t = std::time::Instant::now();
    let mut acc = 0.0;
    for (a, b, l) in &pairs {
        acc += brdf.eval_spectral(*a, *b, *l);
    }
    let eval = t.elapsed().as_secs_f64() / pairs.len() as f64;
    let t = std::time::Instant::now();
    for (a, b, l) in &pairs {
        acc += brdf.mueller(*a, *b, *l).unwrap().0[5];
    }
    let mueller = t.elapsed().as_secs_f64() / pairs.len() as f64;
    let t = std::time::Instant::now();
    let m = brdf.mueller(pairs[1].0, pairs[1].1, pairs[1].2).unwrap().0;
    for _ in &pairs {
        acc += crate::rigorous::polarisation::realisable(&m)[5];
    }
    let filter = t.elapsed().as_secs_f64() / pairs.len() as f64;
    println!(
        "per pair and wavelength: eval_spectral {:.2} us, mueller {:.2} us (of which the filter {:.2} us) [{acc:.1}]",
        eval * 1e6,
        mueller * 1e6,
        filter * 1e6
    );
}

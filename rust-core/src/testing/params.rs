//! Checks of the parameters a material's programs read (`Op::Param`),
//! shared by the models' parameter tests: a program run with a parameter
//! changed by a few percent gives what the changed material gives (its own
//! program and its native path), the program's derivative with respect to
//! the parameter (what a renderer's AD sees) is the native path's, and the
//! program is smooth along a fine sweep of the parameter.
//! (Used by every model's param_tests.rs and optics/param_tests.rs.)

use super::programs::{exported, pairs, round};
use crate::material::program::ProgramKind;
use crate::program::{ParamId, Program};
use crate::Brdf;
use glam::DVec3;

/// A material: its JSON with `$name` (ParamId::name) where each parameter's
/// value goes, and the values. Every parameter its programs read must be
/// listed (`values` panics otherwise). Built with `"gradients": true`.
#[derive(Clone, Copy)]
pub struct Case {
    pub name: &'static str,
    pub template: &'static str,
    pub params: &'static [(ParamId, f64)],
    /// The lanes the checks run at (`lanes`; `grating_lanes` for peaked
    /// kernels).
    pub lanes: fn(usize, u64) -> Vec<Lane>,
}

impl Case {
    /// The parameters' values with `id` scaled by `factor`.
    pub fn scaled(&self, id: ParamId, factor: f64) -> Vec<(ParamId, f64)> {
        self.params
            .iter()
            .map(|&(p, v)| (p, if p == id { v * factor } else { v }))
            .collect()
    }

    pub fn brdf(&self, values: &[(ParamId, f64)]) -> Brdf {
        let mut json = self.template.to_string();
        for &(id, v) in values {
            let key = format!("${}", id.name());
            assert!(json.contains(&key), "{}: no {key}", self.name);
            json = json.replace(&key, &format!("{v:?}"));
        }
        assert!(!json.contains('$'), "{}: {json}", self.name);
        // Built as a renderer builds a material whose parameters carry
        // gradients: the programs follow them smoothly (C1).
        let mut value: serde_json::Value = serde_json::from_str(&json).expect("JSON");
        value["gradients"] = serde_json::Value::Bool(true);
        let json = crate::testing::stam_formula(&value.to_string());
        Brdf::from_json(&json).unwrap_or_else(|e| panic!("{}: {json}: {e}", self.name))
    }
}

/// The program's parameter values (by slot) from `values`.
pub fn slot_values(p: &Program, case: &Case, values: &[(ParamId, f64)]) -> Vec<f64> {
    p.params
        .iter()
        .map(|&(id, _)| {
            values
                .iter()
                .find(|g| g.0 == id)
                .unwrap_or_else(|| panic!("{}: the program reads {id:?}", case.name))
                .1
        })
        .collect()
}

/// Inputs of one lane: the pair (as f32) and the wavelength.
pub struct Lane {
    pub wi: DVec3,
    pub wo: DVec3,
    pub lambda: f64,
}

pub fn lanes(n: usize, seed: u64) -> Vec<Lane> {
    let mut rng = crate::benchmark::SplitMix64(seed);
    pairs(n, seed)
        .into_iter()
        .map(|(wi, wo)| Lane {
            wi: round(wi),
            wo: round(wo),
            lambda: (380.0 + 400.0 * rng.next_f64()) as f32 as f64,
        })
        .collect()
}

/// Lanes for a grating of `period_um` and `coherence_um` (grooves along
/// y): half random pairs (`lanes`), half on the flanks of its order peaks
/// (wi random, wo at u = n lambda / period + d / (l k), v = d' / (l k) for
/// a propagating order n, where the order's exponent is up to 16), where
/// the random pairs seldom fall.
pub fn grating_lanes(period_um: f64, coherence_um: f64, n: usize, seed: u64) -> Vec<Lane> {
    let mut out = lanes(n / 2, seed);
    let mut rng = crate::benchmark::SplitMix64(seed ^ 0x9e37);
    while out.len() < n {
        let [a, b, c] = rng.three();
        let lambda = (380.0 + 400.0 * a) as f32 as f64;
        let k = crate::spectrum::wavenumber_per_um(lambda);
        let wi = DVec3::new(1.6 * b - 0.8, 0.3 * c - 0.15, 0.0);
        let wi = DVec3::new(wi.x, wi.y, (1.0 - wi.length_squared()).sqrt());
        let [d, e, f] = rng.three();
        let n_max = (2.0 * period_um * 1000.0 / lambda) as i64;
        let order = ((2.0 * d - 1.0) * n_max as f64).round();
        let (du, dv) = (
            (8.0 * e - 4.0) / (coherence_um * k),
            (2.0 * f - 1.0) / (coherence_um * k),
        );
        let u = order * lambda / (1000.0 * period_um) + du;
        let (x, y) = (-wi.x - u, -wi.y - dv);
        if x * x + y * y < 0.999 {
            let wo = DVec3::new(x, y, (1.0 - x * x - y * y).sqrt());
            out.push(Lane {
                wi: round(wi),
                wo: round(wo),
                lambda,
            });
        }
    }
    out
}

/// The reflectance outputs of the kinds checked here (eval: f; coherent:
/// the lobe's reflectance, not its sampling probability).
fn outputs(kind: ProgramKind) -> usize {
    match kind {
        ProgramKind::EvalSpectral | ProgramKind::CoherentSpectral => 1,
        ProgramKind::EvalRgb | ProgramKind::CoherentRgb => 3,
        _ => panic!("{kind:?}: not a reflectance program"),
    }
}

/// The kind's reflectance outputs with the parameters' values `params`
/// (by slot), run in f64 or f32.
pub fn run(p: &Program, kind: ProgramKind, l: &Lane, params: &[f64], in_f64: bool) -> Vec<f64> {
    let mut x = vec![l.wi.x, l.wi.y, l.wi.z];
    if matches!(kind, ProgramKind::EvalSpectral | ProgramKind::EvalRgb) {
        x.extend([l.wo.x, l.wo.y, l.wo.z]);
    }
    if kind.spectral() {
        x.push(l.lambda);
    }
    let mut out = if in_f64 {
        p.run_with_params(&x, params)
    } else {
        let x: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let params: Vec<f32> = params.iter().map(|&v| v as f32).collect();
        p.run_with_params(&x, &params)
            .iter()
            .map(|&v| v as f64)
            .collect()
    };
    out.truncate(outputs(kind));
    out
}

/// The native path's value of what `run` returns.
pub fn native(b: &Brdf, kind: ProgramKind, l: &Lane) -> Vec<f64> {
    match kind {
        ProgramKind::EvalSpectral => vec![b.eval_spectral(l.wi, l.wo, l.lambda)],
        ProgramKind::EvalRgb => b.eval_rgb(l.wi, l.wo).to_vec(),
        ProgramKind::CoherentSpectral => vec![b.coherent_spectral(l.wi, l.lambda)],
        ProgramKind::CoherentRgb => b.coherent_rgb(l.wi).to_vec(),
        _ => panic!("{kind:?}: not a reflectance program"),
    }
}

/// The worst errors of the program run with `id` scaled by `factor`
/// against the changed material's native path and its own program, over
/// f32 lanes where the changed f (its largest channel) is above 1e-6 of
/// its peak (relative to that channel): (vs native, vs program, checked).
pub fn changed(
    case: &Case,
    kind: ProgramKind,
    id: ParamId,
    factor: f64,
    ls: &[Lane],
) -> (f64, f64, usize) {
    let p = exported(&case.brdf(case.params), kind).unwrap();
    let values = case.scaled(id, factor);
    let cb = case.brdf(&values);
    let cp = exported(&cb, kind).unwrap();
    let (vals, own_vals) = (
        slot_values(&p, case, &values),
        slot_values(&cp, case, &values),
    );
    let rows: Vec<(Vec<f64>, Vec<f64>)> = ls
        .iter()
        .map(|l| (native(&cb, kind, l), run(&p, kind, l, &vals, false)))
        .collect();
    let peak = rows
        .iter()
        .flat_map(|r| r.0.iter().copied())
        .fold(1e-300, f64::max);
    let (mut vs_native, mut vs_program, mut checked) = (0.0f64, 0.0f64, 0);
    for (l, (nat, got)) in ls.iter().zip(&rows) {
        let scale = nat.iter().copied().fold(0.0, f64::max);
        if scale < 1e-6 * peak {
            continue;
        }
        checked += 1;
        let own = run(&cp, kind, l, &own_vals, false);
        for c in 0..nat.len() {
            vs_native = vs_native.max((got[c] - nat[c]).abs() / scale);
            vs_program = vs_program.max((got[c] - own[c]).abs() / scale);
        }
    }
    (vs_native, vs_program, checked)
}

/// The central difference (relative step `h`) of the f64 program with
/// respect to `id` against the same difference of the native path, as
/// d ln f / d ln p where f is above `floor` of its peak: (largest relative
/// error where |d ln f / d ln p| >= 0.1, largest absolute error where it is
/// smaller, the number of the former).
pub fn derivative(
    case: &Case,
    kind: ProgramKind,
    id: ParamId,
    h: f64,
    floor: f64,
    ls: &[Lane],
) -> (f64, f64, usize) {
    let b = case.brdf(case.params);
    let p = exported(&b, kind).unwrap();
    let (up, down) = (case.scaled(id, 1.0 + h), case.scaled(id, 1.0 - h));
    let (bu, bd) = (case.brdf(&up), case.brdf(&down));
    let (vu, vd) = (slot_values(&p, case, &up), slot_values(&p, case, &down));
    let base = slot_values(&p, case, case.params);
    let rows: Vec<_> = ls
        .iter()
        .map(|l| {
            let f = native(&b, kind, l);
            let (nu, nd) = (native(&bu, kind, l), native(&bd, kind, l));
            let (pu, pd) = (run(&p, kind, l, &vu, true), run(&p, kind, l, &vd, true));
            let f_prog = run(&p, kind, l, &base, true);
            (f, nu, nd, pu, pd, f_prog)
        })
        .collect();
    let peak = rows
        .iter()
        .flat_map(|r| r.0.iter().copied())
        .fold(1e-300, f64::max);
    let (mut rel, mut abs, mut checked) = (0.0f64, 0.0f64, 0);
    for (f, nu, nd, pu, pd, f_prog) in &rows {
        for c in 0..f.len() {
            if f[c] < floor * peak {
                continue;
            }
            let d_native = (nu[c] - nd[c]) / (2.0 * h * f[c]);
            let d_prog = (pu[c] - pd[c]) / (2.0 * h * f_prog[c]);
            if d_native.abs() >= 0.1 {
                checked += 1;
                rel = rel.max((d_prog - d_native).abs() / d_native.abs());
            } else {
                abs = abs.max((d_prog - d_native).abs());
            }
        }
    }
    (rel, abs, checked)
}

/// Whether a sweep of values at a uniform step is smooth (C1 and more):
/// the largest second difference at the step is at most twice what the
/// second differences at 8 steps give (a smooth function's scale as the
/// step squared: 1/64; a kink's, as the step: 1/8; a jump's stay), less
/// f64 rounding: 1e-13 of `scale` (the largest of the lane's channels:
/// a gamut-mapped channel near 0 carries the others' rounding).
pub fn smooth(f: &[f64], scale: f64) -> bool {
    let d2 = |s: usize| {
        (s..f.len() - s)
            .map(|i| (f[i + s] - 2.0 * f[i] + f[i - s]).abs())
            .fold(0.0, f64::max)
    };
    let floor = 1e-13 * scale;
    d2(1) <= 2.0 * d2(8) / 64.0 + floor
}

/// The number of sweeps (of 12 lanes of large f, each channel) of the f64
/// program along ln p in +-`span` (801 points) that are not smooth (RGB
/// lanes whose sweep reaches the gamut's boundary are passed over).
pub fn rough_sweeps(case: &Case, kind: ProgramKind, id: ParamId, span: f64, ls: &[Lane]) -> usize {
    let p = exported(&case.brdf(case.params), kind).unwrap();
    let base = slot_values(&p, case, case.params);
    let slot = p.param_slot(id).unwrap();
    let mut ranked: Vec<(f64, &Lane)> = ls
        .iter()
        .filter(|l| l.wi.z > 0.05 && l.wo.z > 0.05)
        .map(|l| (run(&p, kind, l, &base, true)[0], l))
        .collect();
    ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
    let step = (ranked.len() / 12).clamp(1, 25);
    let mut bad = 0;
    for &(_, l) in ranked.iter().step_by(step).take(12) {
        let sweeps: Vec<Vec<f64>> = (0..801)
            .map(|i| {
                let mut v = base.clone();
                v[slot] *= (span * (i as f64 / 400.0 - 1.0)).exp();
                run(&p, kind, l, &v, true)
            })
            .collect();
        // An RGB sweep along which a channel reaches 0 crosses the gamut
        // map's boundary (a negative channel clamped, the others moved to
        // keep the luminance): a kink of the native function itself, not
        // of the program's tables.
        if !kind.spectral() && sweeps.iter().flatten().any(|&v| v == 0.0) {
            continue;
        }
        let scale = sweeps.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
        for c in 0..sweeps[0].len() {
            let f: Vec<f64> = sweeps.iter().map(|s| s[c]).collect();
            if !smooth(&f, scale) {
                bad += 1;
            }
        }
    }
    bad
}

/// Tolerances of `check`.
#[derive(Clone, Copy)]
pub struct Tolerances {
    /// Changed parameter, the f32 program against the changed material's
    /// native path (relative to f's largest channel): the program's own
    /// tolerance (1e-4 spectral; the RGB rule's where the program
    /// integrates the nodes itself).
    pub vs_native: f64,
    /// The same against the changed material's program, at +-0.5% and at
    /// +-2%.
    pub changed_small: f64,
    pub changed_large: f64,
    /// Derivatives: relative where |d ln f / d ln p| >= 0.1; absolute.
    pub derivative_rel: f64,
    pub derivative_abs: f64,
    /// Derivatives are compared where f is above this share of its peak
    /// (1e-3; a grating's peaks at grazing angles are 1e8 of its orders'
    /// typical values).
    pub derivative_floor: f64,
}

pub const TOLERANCES: Tolerances = Tolerances {
    vs_native: 1e-4,
    changed_small: 1e-4,
    changed_large: 1e-4,
    derivative_rel: 0.03,
    derivative_abs: 1e-2,
    derivative_floor: 1e-3,
};

/// The three checks of each of `ids` for each of `kinds` (every one must
/// read it) of `case`; prints the measured figures; returns the failures.
/// A changed-parameter comparison needs 50 lanes where f counts, a
/// derivative comparison 3 where |d ln f / d ln p| >= 0.1 (a Fresnel term
/// near its plateau moves little: the absolute criterion holds everywhere).
pub fn check(
    case: &Case,
    kinds: &[ProgramKind],
    ids: &[ParamId],
    tol: Tolerances,
    n_lanes: usize,
) -> Vec<String> {
    let mut failures = Vec::new();
    let ls = (case.lanes)(n_lanes, 21);
    let ls_d = (case.lanes)(n_lanes, 33);
    let b = case.brdf(case.params);
    for &kind in kinds {
        let p = exported(&b, kind).unwrap();
        // Every parameter the program reads is one of the case's.
        let _ = slot_values(&p, case, case.params);
        for &id in ids {
            if p.param_slot(id).is_none() {
                failures.push(format!("{} {kind:?}: does not read {id:?}", case.name));
                continue;
            }
            let drift = crate::program::MAX_PARAM_DRIFT;
            for factor in [1.0 - drift, 0.995, 1.005, 1.0 + drift] {
                let (vs_native, vs_program, checked) = changed(case, kind, id, factor, &ls);
                println!(
                    "{:>22} {kind:?} {id:?} x{factor}: {checked} checked, max rel vs native {vs_native:.2e}, vs the changed material's program {vs_program:.2e}",
                    case.name
                );
                let t = if (factor - 1.0f64).abs() > 0.01 {
                    tol.changed_large
                } else {
                    tol.changed_small
                };
                if !(vs_native <= tol.vs_native.max(t) && vs_program <= t && checked >= 50) {
                    failures.push(format!(
                        "{} {kind:?} {id:?} x{factor}: {vs_native:.2e} {vs_program:.2e} ({checked})",
                        case.name
                    ));
                }
            }
            let (rel, abs, checked) = derivative(case, kind, id, 0.01, tol.derivative_floor, &ls_d);
            println!(
                "{:>22} {kind:?} d/d{id:?}: {checked} checked, max rel {rel:.2e}, max |d ln f| error {abs:.2e}",
                case.name
            );
            if !(rel <= tol.derivative_rel && abs <= tol.derivative_abs && checked >= 3) {
                failures.push(format!(
                    "{} {kind:?} d/d{id:?}: rel {rel:.2e} abs {abs:.2e} ({checked})",
                    case.name
                ));
            }
            let bad = rough_sweeps(case, kind, id, 0.05, &ls);
            println!("{:>22} {kind:?} {id:?}: {bad} sweeps not smooth", case.name);
            if bad > 0 {
                failures.push(format!("{} {kind:?} {id:?}: {bad} rough sweeps", case.name));
            }
        }
    }
    failures
}

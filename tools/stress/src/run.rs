//! The stress runner: random materials, hostile inputs, every ABI entry
//! point (f32) beside the Rust API (f64), and the checks of the header's
//! contract (rust-core/include/stam.h):
//! - every output finite and >= 0 (ABI and Rust);
//! - ABI (f32) and Rust (f64, at the same f32-rounded inputs) agree to 1e-4
//!   relative wherever the f64 value lies in [1e-30, 1e30];
//! - sampling returns a unit vector above the horizon with a finite pdf > 0,
//!   or a clean failure (pdf 0); the returned pdf equals stam_brdf_pdf at the
//!   returned direction; pdf > 0 wherever f > 0 (an unbiased estimator needs
//!   it); the coherent probability lies in [0, 1] (ABI and Rust) and is
//!   compared like the other outputs;
//! - the path-vertex calls (4 wavelengths with hostile ones among them, and
//!   RGB): outputs finite and >= 0, samples sane, a sample's pdf and value
//!   equal to the vertex eval at the returned direction, and the separate
//!   sample call identical to the combined call's sample;
//! - the material's programs (stam_brdf_export_program): sized with NULL,
//!   written whole, the Rust API's own program (`Brdf::program`, encoded)
//!   bit for bit, every kind present (EVAL_RGB but for gratings above
//!   15 um: docs/parameters.md), and each run on the batch's lanes
//!   with the
//!   core's f32 executor under the contract of `crate::programs`;
//! - every refused material has a non-empty message; the version string is
//!   non-empty UTF-8; the plausibility warnings are UTF-8 and the Rust API's;
//!   the resolved parameters (stam_brdf_params_json) read back as the same
//!   material's, and the parameter reference is JSON.

use crate::gen::{self, Rng};
use crate::programs;
use glam::DVec3;
use stam::ffi;
use stam::material::plausibility::warnings_for_json;
use stam::params::MaterialParams;
use std::ffi::{c_char, CString};
use std::fmt::Write as _;
use std::time::Instant;

/// Relative agreement required between the f32 ABI and the f64 API.
pub const AGREEMENT: f64 = 1e-4;
/// |f64 value| range over which agreement is checked (representable in f32
/// with full relative precision).
pub const REPRESENTABLE: (f64, f64) = (1e-30, 1e30);

#[derive(Clone, Debug)]
pub struct Options {
    /// Minimum number of evaluations (ABI + Rust outputs) to perform.
    pub count: u64,
    pub seed: u64,
    /// Direction pairs per material.
    pub batch: usize,
    /// Negative control: overwrite every n-th ABI spectral output with NaN
    /// before the checks (0 = never).
    pub inject_nan_every: u64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            count: 100_000,
            seed: 1,
            batch: 128,
            inject_nan_every: 0,
        }
    }
}

/// Counts of one run. `failures()` is the number of contract violations.
#[derive(Clone, Debug, Default)]
pub struct Report {
    pub materials: u64,
    pub materials_per_kind: [u64; gen::SURFACES.len()],
    pub refused: u64,
    pub refused_without_message: u64,
    pub refusal_examples: Vec<String>,
    pub construction_seconds: f64,
    pub slowest_construction: (f64, String),
    pub evaluations_abi: u64,
    pub evaluations_rust: u64,
    pub nan: u64,
    pub inf: u64,
    pub negative: u64,
    pub compared: u64,
    pub disagreements: u64,
    pub worst_relative_difference: f64,
    pub samples: u64,
    pub sample_failures: u64,
    pub coherent_samples: u64,
    pub bad_samples: u64,
    pub pdf_mismatches: u64,
    pub f_positive_pdf_zero: u64,
    pub bad_coherent_probability: u64,
    /// Polarisation (b, c, s) not finite, off the unit sphere, a material
    /// with it through one path and not the other, or the ABI's apart from
    /// the Rust API's.
    pub bad_polarization: u64,
    /// stam_version returned NULL, an empty string or one that is not UTF-8.
    pub bad_version: u64,
    /// Materials with plausibility warnings (stam_brdf_warnings non-empty).
    pub warned: u64,
    /// stam_brdf_warnings returned NULL, text that is not UTF-8, or text
    /// other than the Rust API's warnings of the same parameters.
    pub bad_warnings: u64,
    /// stam_brdf_params_json returned NULL, text that is not UTF-8, or
    /// parameters that do not read back as the material's; or
    /// stam_parameter_reference is not the reference's JSON.
    pub bad_params_json: u64,
    /// Programs exported (materials times kinds).
    pub programs: u64,
    /// Lanes the programs were run on (one program, one lane).
    pub program_runs: u64,
    /// Program contract violations (crate::programs, the export's sizes,
    /// the ABI's array against the Rust API's, a missing kind).
    pub bad_programs: u64,
    /// Gratings above 15 um without an RGB eval program (docs/parameters.md:
    /// the JIT RGB variants serve periods up to about 20 um).
    pub coarse_gratings_without_rgb_eval: u64,
    pub seconds: f64,
    /// The first violations, for diagnosis.
    pub examples: Vec<String>,
}

impl Report {
    pub fn evaluations(&self) -> u64 {
        self.evaluations_abi + self.evaluations_rust
    }

    pub fn failures(&self) -> u64 {
        self.nan
            + self.inf
            + self.negative
            + self.disagreements
            + self.bad_samples
            + self.pdf_mismatches
            + self.f_positive_pdf_zero
            + self.bad_coherent_probability
            + self.bad_polarization
            + self.bad_version
            + self.bad_warnings
            + self.bad_params_json
            + self.bad_programs
            + self.refused_without_message
    }

    fn fail(&mut self, what: String) {
        if self.examples.len() < 20 {
            self.examples.push(what);
        }
    }

    /// Checks one output value (f64 from either path).
    fn check_value(&mut self, x: f64, what: impl Fn() -> String) {
        let bad = if x.is_nan() {
            self.nan += 1;
            true
        } else if x.is_infinite() {
            self.inf += 1;
            true
        } else if x < 0.0 {
            self.negative += 1;
            true
        } else {
            false
        };
        if bad {
            let w = what();
            self.fail(format!("{w}: output {x}"));
        }
    }

    /// Compares the f32 ABI output with the f64 Rust value.
    fn compare(&mut self, abi: f32, rust: f64, what: impl Fn() -> String) {
        let a = rust.abs();
        if !(a >= REPRESENTABLE.0 && a <= REPRESENTABLE.1) {
            return;
        }
        self.compared += 1;
        let d = (abi as f64 - rust).abs() / a;
        if d > self.worst_relative_difference {
            self.worst_relative_difference = d;
        }
        if !(d <= AGREEMENT) {
            self.disagreements += 1;
            let w = what();
            self.fail(format!("{w}: ABI {abi:e} vs Rust {rust:e}"));
        }
    }

    /// Markdown summary (docs/stress.md's table).
    pub fn markdown(&self, options: &Options) -> String {
        let mut s = String::new();
        let kinds: Vec<String> = gen::SURFACES
            .iter()
            .zip(self.materials_per_kind)
            .map(|(k, n)| format!("{k} {n}"))
            .collect();
        let _ = writeln!(s, "| quantity | count |\n|---|---|");
        let rows: Vec<(&str, String)> = vec![
            ("seed", options.seed.to_string()),
            ("evaluations (total)", self.evaluations().to_string()),
            (
                "  through the C ABI (f32)",
                self.evaluations_abi.to_string(),
            ),
            (
                "  through the Rust API (f64)",
                self.evaluations_rust.to_string(),
            ),
            (
                "materials built (per kind)",
                format!("{} ({})", self.materials, kinds.join(", ")),
            ),
            (
                "materials refused (all with a message)",
                self.refused.to_string(),
            ),
            (
                "refusals without a message",
                self.refused_without_message.to_string(),
            ),
            ("NaN outputs", self.nan.to_string()),
            ("infinite outputs", self.inf.to_string()),
            ("negative outputs", self.negative.to_string()),
            ("f32/f64 pairs compared", self.compared.to_string()),
            (
                "f32/f64 disagreements (> 1e-4 relative)",
                self.disagreements.to_string(),
            ),
            (
                "worst f32/f64 relative difference",
                format!("{:.2e}", self.worst_relative_difference),
            ),
            ("samples drawn (ABI + Rust)", self.samples.to_string()),
            ("  clean failures (pdf 0)", self.sample_failures.to_string()),
            (
                "  coherent (mirror) samples",
                self.coherent_samples.to_string(),
            ),
            (
                "  bad samples (not unit, below horizon, pdf not finite)",
                self.bad_samples.to_string(),
            ),
            (
                "  returned pdf != stam_brdf_pdf at the returned wo",
                self.pdf_mismatches.to_string(),
            ),
            ("f > 0 where pdf = 0", self.f_positive_pdf_zero.to_string()),
            (
                "coherent probability outside [0, 1]",
                self.bad_coherent_probability.to_string(),
            ),
            (
                "polarisation not finite, not unit, or apart between ABI and Rust",
                self.bad_polarization.to_string(),
            ),
            ("programs exported", self.programs.to_string()),
            ("  lanes run (f32 executor)", self.program_runs.to_string()),
            (
                "  program contract violations",
                self.bad_programs.to_string(),
            ),
            (
                "  gratings above 15 um without an RGB eval",
                self.coarse_gratings_without_rgb_eval.to_string(),
            ),
            (
                "construction time (total, s)",
                format!("{:.2}", self.construction_seconds),
            ),
            (
                "slowest construction (s)",
                format!("{:.3}", self.slowest_construction.0),
            ),
            ("run time (s)", format!("{:.1}", self.seconds)),
        ];
        for (k, v) in rows {
            let _ = writeln!(s, "| {k} | {v} |");
        }
        s
    }
}

/// f32 view of a direction, as the ABI receives it, and the f64 direction
/// the Rust side is evaluated at (the same rounded values).
fn rounded(d: DVec3) -> ([f32; 3], DVec3) {
    let f = [d.x as f32, d.y as f32, d.z as f32];
    (f, DVec3::new(f[0] as f64, f[1] as f64, f[2] as f64))
}

struct Material(*mut ffi::StamBrdf);

impl Drop for Material {
    fn drop(&mut self) {
        unsafe { ffi::stam_brdf_free(self.0) }
    }
}

/// Builds a material through the ABI; Err(message) on refusal.
fn build(json: &str) -> Result<Material, String> {
    let c = CString::new(json).map_err(|e| e.to_string())?;
    let mut err = vec![0 as c_char; 512];
    let p = unsafe { ffi::stam_brdf_new(c.as_ptr(), err.as_mut_ptr(), err.len()) };
    // A host's own keys change no verdict, only an unknown key's message.
    let hosts = c"[\"twist\", \"tracks\"]";
    let mut host_err = vec![0 as c_char; 512];
    let q = unsafe {
        ffi::stam_brdf_new_for_host(c.as_ptr(), hosts.as_ptr(), host_err.as_mut_ptr(), 512)
    };
    if p.is_null() != q.is_null() {
        return Err(format!(
            "stam_brdf_new_for_host decided otherwise than stam_brdf_new for {json}"
        ));
    }
    unsafe { ffi::stam_brdf_free(q) };
    if p.is_null() {
        let bytes: Vec<u8> = err
            .iter()
            .take_while(|&&c| c != 0)
            .map(|&c| c as u8)
            .collect();
        Err(String::from_utf8_lossy(&bytes).into_owned())
    } else {
        Ok(Material(p))
    }
}

/// Runs the stress test until at least `options.count` evaluations are done.
pub fn run(options: &Options) -> Report {
    let start = Instant::now();
    let mut report = Report::default();
    let version = ffi::stam_version();
    let version_ok = !version.is_null()
        && unsafe { std::ffi::CStr::from_ptr(version) }
            .to_str()
            .is_ok_and(|v| !v.trim().is_empty());
    if !version_ok {
        report.bad_version += 1;
        report.fail("stam_version: NULL, empty or not UTF-8".to_string());
    }
    let reference = ffi::stam_parameter_reference();
    let reference_ok = !reference.is_null()
        && unsafe { std::ffi::CStr::from_ptr(reference) }
            .to_str()
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(t).ok())
            .is_some_and(|v| v["surfaces"].is_array() && v["material"].is_array());
    if !reference_ok {
        report.bad_params_json += 1;
        report.fail("stam_parameter_reference: NULL, not UTF-8 or not its JSON".to_string());
    }
    if let Err(message) = rigorous_answers() {
        report.bad_params_json += 1;
        report.fail(format!("stam_rigorous_solve: {message}"));
    }
    let mut rng = Rng::new(options.seed);
    let mut texture_rng = Rng::new(options.seed ^ 0x7e87_0e5d);
    let mut kind = 0usize;
    let mut spectral_outputs = 0u64;
    while report.evaluations() < options.count {
        let json = gen::material(&mut rng, kind);
        let this_kind = kind % gen::SURFACES.len();
        kind += 1;
        let t0 = Instant::now();
        let built = build(&json);
        let dt = t0.elapsed().as_secs_f64();
        report.construction_seconds += dt;
        if dt > report.slowest_construction.0 {
            report.slowest_construction = (dt, json.clone());
        }
        let material = match built {
            Ok(m) => m,
            Err(message) => {
                report.refused += 1;
                if message.trim().is_empty() {
                    report.refused_without_message += 1;
                    report.fail(format!("refused without a message: {json}"));
                } else if report.refusal_examples.len() < 10 {
                    report.refusal_examples.push(format!("{json}: {message}"));
                }
                continue;
            }
        };
        report.materials += 1;
        report.materials_per_kind[this_kind] += 1;
        // A texture's plan on this material: a plain one and a hostile one
        // (from a generator of their own: the materials' stay as they were).
        let hostile = [0.0, -1.0, f64::NAN, f64::INFINITY, 1e-9, 250.0];
        let hostile = [
            texture_rng.pick(&hostile),
            texture_rng.log_range(1e-4, 10.0),
        ];
        let (largest, mean) = (texture_rng.pick(&hostile), texture_rng.pick(&hostile));
        for problem in texture_plan_problems(&json, 0.2, 0.1)
            .into_iter()
            .chain(texture_plan_problems(&json, largest, mean))
        {
            report.bad_params_json += 1;
            report.fail(problem);
        }
        let brdf = unsafe { &(*material.0).brdf };
        let b = material.0 as *const ffi::StamBrdf;
        let n = options.batch;

        // Inputs: f64 originals, the f32 arrays the ABI gets and the rounded
        // f64 values the Rust side is evaluated at.
        let mut wi64 = Vec::with_capacity(n);
        let mut wi32 = Vec::with_capacity(3 * n);
        let mut wo32 = Vec::with_capacity(3 * n);
        let mut wi_r = Vec::with_capacity(n);
        let mut wo_r = Vec::with_capacity(n);
        let mut lam32 = Vec::with_capacity(n);
        let mut rnd32 = Vec::with_capacity(3 * n);
        let mut rnd64 = Vec::with_capacity(n);
        for _ in 0..n {
            let wi = gen::direction(&mut rng);
            let wo = gen::direction_near_mirror(&mut rng, wi);
            let (fi, ri) = rounded(wi);
            let (fo, ro) = rounded(wo);
            wi64.push(wi);
            wi32.extend_from_slice(&fi);
            wo32.extend_from_slice(&fo);
            wi_r.push(ri);
            wo_r.push(ro);
            lam32.push(gen::wavelength(&mut rng) as f32);
            let r = gen::uniforms(&mut rng);
            rnd32.extend(r.iter().map(|&x| x as f32));
            rnd64.push(r);
        }
        let lam_r: Vec<f64> = lam32.iter().map(|&l| l as f64).collect();
        // The same lanes for the programs (their uniforms as the ABI gets
        // them, hostile ones included).
        let lanes: Vec<programs::Lane> = (0..n)
            .map(|i| {
                let at = |v: &[f32]| [v[3 * i], v[3 * i + 1], v[3 * i + 2]];
                programs::Lane {
                    wi: at(&wi32),
                    wo: at(&wo32),
                    u: at(&rnd32),
                    lambda: lam32[i],
                }
            })
            .collect();
        let ctx = |what: &'static str, i: usize| {
            let (wi, wo, l) = (wi_r[i], wo_r[i], lam_r[i]);
            let json = &json;
            move || format!("{what} {json} wi {wi:?} wo {wo:?} lambda {l}")
        };

        // Spectral.
        let mut out = vec![0f32; n];
        unsafe {
            ffi::stam_brdf_eval_spectral(
                b,
                n,
                wi32.as_ptr(),
                wo32.as_ptr(),
                lam32.as_ptr(),
                out.as_mut_ptr(),
            )
        };
        if options.inject_nan_every > 0 {
            for o in out.iter_mut() {
                spectral_outputs += 1;
                if spectral_outputs.is_multiple_of(options.inject_nan_every) {
                    *o = f32::NAN;
                }
            }
        }
        let mut f_spectral = vec![0.0; n];
        for i in 0..n {
            let f = brdf.eval_spectral(wi_r[i], wo_r[i], lam_r[i]);
            f_spectral[i] = f;
            report.check_value(out[i] as f64, ctx("ABI eval_spectral", i));
            report.check_value(f, ctx("Rust eval_spectral", i));
            report.compare(out[i], f, ctx("eval_spectral", i));
        }
        report.evaluations_abi += n as u64;
        report.evaluations_rust += n as u64;

        // RGB.
        let mut out3 = vec![0f32; 3 * n];
        unsafe { ffi::stam_brdf_eval_rgb(b, n, wi32.as_ptr(), wo32.as_ptr(), out3.as_mut_ptr()) };
        let mut f_rgb = vec![[0.0; 3]; n];
        for i in 0..n {
            let f = brdf.eval_rgb(wi_r[i], wo_r[i]);
            f_rgb[i] = f;
            for c in 0..3 {
                report.check_value(out3[3 * i + c] as f64, ctx("ABI eval_rgb", i));
                report.check_value(f[c], ctx("Rust eval_rgb", i));
                report.compare(out3[3 * i + c], f[c], ctx("eval_rgb", i));
            }
        }
        report.evaluations_abi += n as u64;
        report.evaluations_rust += n as u64;

        // Coherent lobe, spectral and RGB, and its sampling probability.
        unsafe {
            ffi::stam_brdf_coherent_spectral(b, n, wi32.as_ptr(), lam32.as_ptr(), out.as_mut_ptr());
            ffi::stam_brdf_coherent_rgb(b, n, wi32.as_ptr(), out3.as_mut_ptr());
        }
        for i in 0..n {
            let c = brdf.coherent_spectral(wi_r[i], lam_r[i]);
            report.check_value(out[i] as f64, ctx("ABI coherent_spectral", i));
            report.check_value(c, ctx("Rust coherent_spectral", i));
            report.compare(out[i], c, ctx("coherent_spectral", i));
            let c3 = brdf.coherent_rgb(wi_r[i]);
            for c in 0..3 {
                report.check_value(out3[3 * i + c] as f64, ctx("ABI coherent_rgb", i));
                report.check_value(c3[c], ctx("Rust coherent_rgb", i));
                report.compare(out3[3 * i + c], c3[c], ctx("coherent_rgb", i));
            }
        }
        report.evaluations_abi += 2 * n as u64;
        report.evaluations_rust += 2 * n as u64;
        for spectral in [true, false] {
            let lam_ptr = if spectral {
                lam32.as_ptr()
            } else {
                std::ptr::null()
            };
            unsafe {
                ffi::stam_brdf_coherent_probability(b, n, wi32.as_ptr(), lam_ptr, out.as_mut_ptr())
            };
            for (i, &p) in out.iter().enumerate() {
                let p64 = brdf.coherent_probability(wi_r[i], spectral.then_some(lam_r[i]));
                for (x, path) in [(p as f64, "ABI"), (p64, "Rust")] {
                    if !(0.0..=1.0).contains(&x) {
                        report.bad_coherent_probability += 1;
                        let w = ctx("coherent_probability", i)();
                        report.fail(format!("{w}: {path} {x}"));
                    }
                }
                report.compare(p, p64, ctx("coherent_probability", i));
            }
            report.evaluations_abi += n as u64;
            report.evaluations_rust += n as u64;
        }

        // Polarisation: finite, b^2 + c^2 + s^2 = 1, the ABI's the Rust
        // API's (f32 against f64, absolutely: values lie in [-1, 1]).
        let has = unsafe {
            ffi::stam_brdf_polarization(
                b,
                n,
                wi32.as_ptr(),
                wo32.as_ptr(),
                lam32.as_ptr(),
                out3.as_mut_ptr(),
            )
        };
        for i in 0..n {
            let rust = brdf.polarization(wi_r[i], wo_r[i], lam_r[i]);
            let abi = &out3[3 * i..3 * i + 3];
            let unit = |v: [f64; 3], tol: f64| {
                v.iter().all(|x| x.is_finite())
                    && (v.iter().map(|x| x * x).sum::<f64>() - 1.0).abs() <= tol
            };
            let abi64 = [abi[0] as f64, abi[1] as f64, abi[2] as f64];
            let ok = match rust {
                Some(r) => {
                    has == 1
                        && unit(r, 1e-9)
                        && unit(abi64, 1e-4)
                        && r.iter().zip(abi64).all(|(x, y)| (x - y).abs() <= 1e-5)
                }
                None => has == 0 && abi.iter().all(|&x| x == 0.0),
            };
            if !ok {
                report.bad_polarization += 1;
                let w = ctx("polarization", i)();
                report.fail(format!("{w}: ABI {abi:?} ({has}), Rust {rust:?}"));
            }
        }
        // Its program: where the material has a polarisation, the ABI's
        // array is the Rust API's, and run in f32 on these hostile lanes
        // it gives finite values on the unit sphere (b^2 + c^2 + s^2 = 1
        // within 1e-3; its agreement with the native values at ordinary
        // pairs is the core's test
        // polarization_program_follows_the_native_polarization: near
        // Brewster's angle of a dielectric, and near grazing, f32's
        // half-vector cosine moves them by more).
        let n_prog =
            unsafe { ffi::stam_brdf_export_polarization_program(b, std::ptr::null_mut(), 0) };
        let rust_prog = brdf.polarization_program();
        let mut prog_ok = (n_prog > 0) == rust_prog.is_some();
        if let (true, Some(p)) = (n_prog > 0, &rust_prog) {
            let mut array = vec![0f32; n_prog];
            unsafe { ffi::stam_brdf_export_polarization_program(b, array.as_mut_ptr(), n_prog) };
            prog_ok &= array == p.encode();
            for i in 0..n {
                let mut input = [0f32; 7];
                input[..3].copy_from_slice(&wi32[3 * i..3 * i + 3]);
                input[3..6].copy_from_slice(&wo32[3 * i..3 * i + 3]);
                input[6] = lam32[i];
                let out: Vec<f32> = p.run(&input);
                let q: f32 = out.iter().map(|x| x * x).sum();
                prog_ok &= q.is_finite() && (q - 1.0).abs() <= 1e-3;
            }
        }
        if !prog_ok {
            report.bad_polarization += 1;
            report.fail(format!(
                "polarization program ({n_prog} floats) apart from the Rust API for {json}"
            ));
        }
        report.evaluations_abi += n as u64;
        report.evaluations_rust += n as u64;

        // Mueller matrices (light from wo to wi): finite, [0][0] = 1, unit
        // bases, realisable (the Rust API's in f64), the ABI's the Rust
        // API's within 1e-5.
        let mut out22 = vec![0f32; 22 * n];
        let has_m = unsafe {
            ffi::stam_brdf_mueller(
                b,
                n,
                wo32.as_ptr(),
                wi32.as_ptr(),
                lam32.as_ptr(),
                out22.as_mut_ptr(),
            )
        };
        for i in 0..n {
            let abi = &out22[22 * i..22 * i + 22];
            let rust = brdf.mueller(wo_r[i], wi_r[i], lam_r[i]);
            let ok = match (has_m, rust) {
                (1, Some((m, bases))) if m.iter().all(|v| v.is_finite()) => {
                    let flat: Vec<f64> = m
                        .iter()
                        .copied()
                        .chain(bases[0].to_array())
                        .chain(bases[1].to_array())
                        .collect();
                    (m[0] - 1.0).abs() < 1e-9
                        && bases.iter().all(|b| (b.length() - 1.0).abs() < 1e-6)
                        && stam::rigorous::polarisation::coherency_eigenvalues(&m)[0] > -1e-6
                        && flat
                            .iter()
                            .zip(abi)
                            .all(|(x, y)| (x - *y as f64).abs() <= 1e-5)
                }
                // Directions the core cannot take: the ABI's depolarizer.
                (1, _) => abi[0] == 1.0 && abi[1..16].iter().all(|&x| x == 0.0),
                (_, _) => abi.iter().all(|&x| x == 0.0),
            };
            if !ok {
                report.bad_polarization += 1;
                let w = ctx("mueller", i)();
                report.fail(format!("{w}: ABI {abi:?} ({has_m})"));
            }
        }

        // Sampling through the ABI, spectral and RGB mode, with the pdf at
        // the returned direction, and through the Rust API at the unrounded
        // f64 inputs.
        let mut wo_s = vec![0f32; 3 * n];
        let mut pdf_s = vec![0f32; n];
        let mut coh = vec![0u8; n];
        let mut pdf_check = vec![0f32; n];
        for spectral in [true, false] {
            let lam_ptr = if spectral {
                lam32.as_ptr()
            } else {
                std::ptr::null()
            };
            unsafe {
                ffi::stam_brdf_sample(
                    b,
                    n,
                    wi32.as_ptr(),
                    lam_ptr,
                    rnd32.as_ptr(),
                    wo_s.as_mut_ptr(),
                    pdf_s.as_mut_ptr(),
                    coh.as_mut_ptr(),
                );
                ffi::stam_brdf_pdf(
                    b,
                    n,
                    wi32.as_ptr(),
                    wo_s.as_ptr(),
                    lam_ptr,
                    pdf_check.as_mut_ptr(),
                );
            }
            report.evaluations_abi += 2 * n as u64;
            for i in 0..n {
                let w = DVec3::new(
                    wo_s[3 * i] as f64,
                    wo_s[3 * i + 1] as f64,
                    wo_s[3 * i + 2] as f64,
                );
                let what = ctx(
                    if spectral {
                        "ABI sample (spectral)"
                    } else {
                        "ABI sample (RGB)"
                    },
                    i,
                );
                check_sample(&mut report, w, pdf_s[i] as f64, coh[i] != 0, 1e-5, &what);
                report.check_value(pdf_check[i] as f64, what);
                if pdf_s[i] > 0.0 && coh[i] == 0 {
                    let (a, c) = (pdf_s[i] as f64, pdf_check[i] as f64);
                    if !((a - c).abs() <= AGREEMENT * a.max(c)) {
                        report.pdf_mismatches += 1;
                        let w = what();
                        report.fail(format!("{w}: sampled pdf {a:e}, stam_brdf_pdf {c:e}"));
                    }
                }
                let lambda = spectral.then_some(lam_r[i]);
                let s = brdf.sample(wi64[i], lambda.map(|_| lam_r[i]), rnd64[i]);
                check_sample(
                    &mut report,
                    s.wo,
                    s.pdf,
                    s.coherent,
                    1e-12,
                    &ctx("Rust sample", i),
                );
                report.evaluations_rust += 1;
            }
        }

        // pdf > 0 wherever f > 0 (at the random pairs, both modes), through
        // the ABI's pdf.
        for spectral in [true, false] {
            let lam_ptr = if spectral {
                lam32.as_ptr()
            } else {
                std::ptr::null()
            };
            unsafe {
                ffi::stam_brdf_pdf(
                    b,
                    n,
                    wi32.as_ptr(),
                    wo32.as_ptr(),
                    lam_ptr,
                    pdf_check.as_mut_ptr(),
                )
            };
            report.evaluations_abi += n as u64;
            for i in 0..n {
                let p = pdf_check[i] as f64;
                report.check_value(p, ctx("ABI pdf", i));
                let f_pos = if spectral {
                    f_spectral[i] > 0.0
                } else {
                    f_rgb[i].iter().any(|&c| c > 0.0)
                };
                if f_pos {
                    let p64 = brdf.pdf(wi_r[i], wo_r[i], spectral.then_some(lam_r[i]));
                    report.evaluations_rust += 1;
                    report.check_value(p64, ctx("Rust pdf", i));
                    if !(p64 > 0.0) {
                        report.f_positive_pdf_zero += 1;
                        let w = ctx(
                            if spectral {
                                "f > 0, pdf = 0 (spectral)"
                            } else {
                                "f > 0, pdf = 0 (RGB)"
                            },
                            i,
                        )();
                        report.fail(w);
                    }
                }
            }
        }
        // The path-vertex ABI: 4 wavelengths per lane (the lane's own, its
        // neighbours', and every 7th lane a hostile one: 0 or NaN) and RGB.
        // Every output finite and >= 0, samples sane, and the one-call form
        // consistent with itself and with the separate calls: the sample's
        // pdf and value are the eval's at the returned direction, and
        // stam_brdf_sample_vertex with the same uniforms returns the same
        // sample.
        const NW: usize = 4;
        let lam4: Vec<f32> = (0..n * NW)
            .map(|k| match (k / NW % 7, k % NW) {
                (0, 3) => 0.0,
                (3, 2) => f32::NAN,
                _ => lam32[(k / NW + k % NW) % n],
            })
            .collect();
        for spectral in [true, false] {
            let (lam_ptr, nc) = if spectral {
                (lam4.as_ptr(), NW)
            } else {
                (std::ptr::null(), 3)
            };
            let (mut f, mut pdf) = (vec![0f32; n * nc], vec![0f32; n]);
            let (mut s_wo, mut s_pdf, mut s_coh, mut s_val) = (
                vec![0f32; 3 * n],
                vec![0f32; n],
                vec![0u8; n],
                vec![0f32; n * nc],
            );
            let (mut f_at, mut pdf_at) = (vec![0f32; n * nc], vec![0f32; n]);
            let (mut v_wo, mut v_pdf, mut v_coh, mut v_val) = (
                vec![0f32; 3 * n],
                vec![0f32; n],
                vec![0u8; n],
                vec![0f32; n * nc],
            );
            unsafe {
                ffi::stam_brdf_eval_pdf_sample_vertex(
                    b,
                    n,
                    wi32.as_ptr(),
                    wo32.as_ptr(),
                    lam_ptr,
                    NW,
                    rnd32.as_ptr(),
                    f.as_mut_ptr(),
                    pdf.as_mut_ptr(),
                    s_wo.as_mut_ptr(),
                    s_pdf.as_mut_ptr(),
                    s_coh.as_mut_ptr(),
                    s_val.as_mut_ptr(),
                );
                ffi::stam_brdf_eval_pdf_vertex(
                    b,
                    n,
                    wi32.as_ptr(),
                    s_wo.as_ptr(),
                    lam_ptr,
                    NW,
                    f_at.as_mut_ptr(),
                    pdf_at.as_mut_ptr(),
                );
                ffi::stam_brdf_sample_vertex(
                    b,
                    n,
                    wi32.as_ptr(),
                    lam_ptr,
                    NW,
                    rnd32.as_ptr(),
                    v_wo.as_mut_ptr(),
                    v_pdf.as_mut_ptr(),
                    v_coh.as_mut_ptr(),
                    v_val.as_mut_ptr(),
                );
            }
            report.evaluations_abi += (3 * nc + 5) as u64 * n as u64;
            let label = if spectral {
                "ABI vertex (4 wavelengths)"
            } else {
                "ABI vertex (RGB)"
            };
            for i in 0..n {
                let what = ctx(label, i);
                for c in 0..nc {
                    report.check_value(f[i * nc + c] as f64, what);
                    report.check_value(s_val[i * nc + c] as f64, what);
                }
                report.check_value(pdf[i] as f64, what);
                let w = DVec3::new(
                    s_wo[3 * i] as f64,
                    s_wo[3 * i + 1] as f64,
                    s_wo[3 * i + 2] as f64,
                );
                check_sample(&mut report, w, s_pdf[i] as f64, s_coh[i] != 0, 1e-5, &what);
                // The separate sample call: bit for bit the combined call's
                // sample (outputs already checked through it).
                let same =
                    |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
                let lane = |v: &[f32], k: usize| v[i * k..(i + 1) * k].to_vec();
                if !(same(&lane(&v_wo, 3), &lane(&s_wo, 3))
                    && same(&lane(&v_val, nc), &lane(&s_val, nc))
                    && v_pdf[i].to_bits() == s_pdf[i].to_bits()
                    && v_coh[i] == s_coh[i])
                {
                    report.pdf_mismatches += 1;
                    let w = what();
                    report.fail(format!(
                        "{w}: stam_brdf_sample_vertex (wo {:?} pdf {:e} coherent {} value {:?}) differs from the combined call's sample (wo {:?} pdf {:e} coherent {} value {:?})",
                        lane(&v_wo, 3), v_pdf[i], v_coh[i], lane(&v_val, nc),
                        lane(&s_wo, 3), s_pdf[i], s_coh[i], lane(&s_val, nc)
                    ));
                }
                if s_pdf[i] > 0.0 && s_coh[i] == 0 {
                    let (a, c) = (s_pdf[i] as f64, pdf_at[i] as f64);
                    let same_value = (0..nc).all(|c| s_val[i * nc + c] == f_at[i * nc + c]);
                    if !((a - c).abs() <= AGREEMENT * a.max(c)) || !same_value {
                        report.pdf_mismatches += 1;
                        let w = what();
                        report.fail(format!(
                            "{w}: vertex sample pdf {a:e} / value {:?} vs eval at its wo {c:e} / {:?}",
                            &s_val[i * nc..(i + 1) * nc],
                            &f_at[i * nc..(i + 1) * nc]
                        ));
                    }
                }
            }
        }

        // Flags and memory must not crash; memory is bounded.
        unsafe {
            let _ = ffi::stam_brdf_flags(b);
            let _ = ffi::stam_brdf_memory_bytes(b);
        }
        check_programs(&mut report, b, brdf, &json, &lanes);
        // The resolved parameters: UTF-8, read back as the same material's.
        let resolved = unsafe { ffi::stam_brdf_params_json(b) };
        let resolved = (!resolved.is_null())
            .then(|| unsafe { std::ffi::CStr::from_ptr(resolved) }.to_str().ok())
            .flatten();
        let same = resolved.is_some_and(|r| {
            MaterialParams::from_json(r).ok() == MaterialParams::from_json(&json).ok()
        });
        if !same {
            report.bad_params_json += 1;
            report.fail(format!(
                "stam_brdf_params_json: {resolved:?} does not read back as {json}"
            ));
        }
        // The warnings: UTF-8, the Rust API's, one per line.
        let warnings = unsafe { ffi::stam_brdf_warnings(b) };
        let expected: Vec<String> = warnings_for_json(&json)
            .into_iter()
            .map(|w| w.message)
            .collect();
        let text = (!warnings.is_null())
            .then(|| unsafe { std::ffi::CStr::from_ptr(warnings) }.to_str().ok())
            .flatten();
        match text {
            Some(t) if t == expected.join("\n") => report.warned += u64::from(!t.is_empty()),
            _ => {
                report.bad_warnings += 1;
                report.fail(format!(
                    "stam_brdf_warnings: {text:?} for {json}, the Rust API's: {expected:?}"
                ));
            }
        }
    }
    report.seconds = start.elapsed().as_secs_f64();
    report
}

/// The material's programs through the ABI: each kind sized with NULL,
/// nothing written into a short buffer, the whole array equal bit for bit
/// to the Rust API's program encoded, decoded and run on the lanes
/// (crate::programs). The sampling and pdf kinds exist for every material,
/// the coherent kinds too except where "energy": "conserving" keeps a
/// table per wavelength (gratings), whose RGB kinds the core does not
/// export (material/program.rs).
fn check_programs(
    report: &mut Report,
    b: *const ffi::StamBrdf,
    brdf: &stam::Brdf,
    json: &str,
    lanes: &[programs::Lane],
) {
    use stam::material::program::ProgramKind;
    let mut decoded = Vec::with_capacity(programs::KINDS as usize);
    let fail = |report: &mut Report, what: String| {
        report.bad_programs += 1;
        report.fail(format!("{what} for {json}"));
    };
    for kind in 0..programs::KINDS {
        let name = programs::NAMES[kind as usize];
        let n = unsafe { ffi::stam_brdf_export_program(b, kind, std::ptr::null_mut(), 0) };
        let rust = ProgramKind::from_code(kind)
            .and_then(|k| brdf.program(k))
            .map(|p| p.encode());
        if n == 0 && brdf.surface().is_unfactored() {
            // Rigorous gratings have no programs yet (the JIT variants
            // refuse them): none of any kind, like the Rust API.
            if rust.is_some() {
                fail(
                    report,
                    format!(
                        "stam_brdf_export_program: no {name} program, but the Rust API has one"
                    ),
                );
            }
            decoded.push(None);
            continue;
        }
        if n == 0 && kind == 0 && rust.is_none() && coarse_grating(json) {
            // A grating coarser than the RGB eval's unrolled orders serve
            // (docs/parameters.md, period_um: about 20 um) has no EVAL_RGB
            // program, like the Rust API; the other kinds exist.
            report.coarse_gratings_without_rgb_eval += 1;
            decoded.push(None);
            continue;
        }
        if n == 0 {
            // Every kind exists for every material (the JIT variants run
            // nothing else)
            fail(
                report,
                format!(
                    "stam_brdf_export_program: no {name} program (the Rust API's: {:?} floats)",
                    rust.as_ref().map(Vec::len)
                ),
            );
            decoded.push(None);
            continue;
        }
        report.programs += 1;
        let mut array = vec![-1.0f32; n + 1];
        let short = unsafe { ffi::stam_brdf_export_program(b, kind, array.as_mut_ptr(), n - 1) };
        let short_ok = short == n && array.iter().all(|&x| x == -1.0);
        let written = unsafe { ffi::stam_brdf_export_program(b, kind, array.as_mut_ptr(), n + 1) };
        if !short_ok || written != n || array[n] != -1.0 {
            fail(
                report,
                format!("stam_brdf_export_program {name}: {written} of {n} floats written, or written into a short buffer or past n"),
            );
        }
        array.truncate(n);
        let same = rust.as_ref().is_some_and(|r| {
            r.len() == n
                && r.iter()
                    .zip(&array)
                    .all(|(x, y)| x.to_bits() == y.to_bits())
        });
        if !same {
            fail(
                report,
                format!("stam_brdf_export_program {name}: not the Rust API's program ({n} floats, Rust {:?})", rust.as_ref().map(Vec::len)),
            );
        }
        match programs::decode_checked(kind, &array) {
            Ok(p) => {
                for v in check_program_run(&array, &p, kind, lanes) {
                    fail(report, format!("{name}: {v}"));
                }
                decoded.push(Some(p))
            }
            Err(e) => {
                fail(report, e);
                decoded.push(None);
            }
        }
    }
    // A kind out of range has none.
    for kind in [programs::KINDS, u32::MAX] {
        if unsafe { ffi::stam_brdf_export_program(b, kind, std::ptr::null_mut(), 0) } != 0 {
            fail(
                report,
                format!("stam_brdf_export_program: a program of kind {kind}"),
            );
        }
    }
    let checked = programs::check(&decoded, lanes);
    report.program_runs += checked.runs;
    for v in checked.violations {
        fail(report, v);
    }
    // The mixture programs over 4 wavelengths, where the spectral kinds
    // exist: the Rust API's, and the spectral programs mixed.
    if decoded[3].is_none() {
        return;
    }
    use stam::material::program::MixtureKind;
    let mut mixtures = Vec::new();
    for kind in MixtureKind::ALL {
        let export = |out: *mut f32, capacity: usize| unsafe {
            ffi::stam_brdf_export_mixture_program(b, kind as u32, 4, out, capacity)
        };
        let n = export(std::ptr::null_mut(), 0);
        let mut array = vec![0.0f32; n];
        let written = export(array.as_mut_ptr(), n);
        let rust = brdf.mixture_program(kind, 4).map(|p| p.encode());
        if n == 0 || written != n || rust.as_deref() != Some(&array[..]) {
            fail(
                report,
                format!(
                    "stam_brdf_export_mixture_program {kind:?}: {n} floats, not the Rust API's"
                ),
            );
            return;
        }
        let (mut n_in, mut n_out) = (0u32, 0u32);
        let known = unsafe { ffi::stam_program_io(kind as u32, 4, &mut n_in, &mut n_out) };
        match stam::program::decode(&array) {
            Some(p) if known == 1 && (p.n_inputs, p.outputs.len()) == (n_in, n_out as usize) => {
                mixtures.push(p)
            }
            _ => {
                return fail(
                    report,
                    format!("mixture {kind:?}: no decode, or not ({n_in}, {n_out})"),
                )
            }
        }
    }
    let checked = programs::check_mixtures(&mixtures, &decoded, lanes);
    report.program_runs += checked.runs;
    for v in checked.violations {
        fail(report, v);
    }
}

/// The core's executor through the ABI (stam_program_run, in f32 and f64)
/// on the lanes, equal bit for bit to the Rust API's lane-by-lane run (the
/// two schedules of one executor), and the program's parameter names
/// (stam_param_name) the Rust API's. Returns the differences found.
pub fn check_program_run(
    array: &[f32],
    p: &stam::program::Program,
    kind: u32,
    lanes: &[programs::Lane],
) -> Vec<String> {
    let mut found = Vec::new();
    let n_out = p.outputs.len();
    let x: Vec<f32> = lanes.iter().flat_map(|l| l.inputs(kind)).collect();
    let x64: Vec<f64> = x.iter().map(|&v| v as f64).collect();
    let mut out = vec![0.0f32; lanes.len() * n_out];
    let mut out64 = vec![0.0f64; lanes.len() * n_out];
    let mut err = [0 as std::ffi::c_char; 256];
    let null = std::ptr::null_mut();
    let ran = unsafe {
        ffi::stam_program_run(
            array.as_ptr(),
            array.len(),
            x.as_ptr(),
            lanes.len(),
            std::ptr::null(),
            0,
            out.as_mut_ptr(),
            None,
            None,
            null,
            err.as_mut_ptr(),
            err.len(),
        ) == 1
            && ffi::stam_program_run_f64(
                array.as_ptr(),
                array.len(),
                x64.as_ptr(),
                lanes.len(),
                std::ptr::null(),
                0,
                out64.as_mut_ptr(),
                err.as_mut_ptr(),
                err.len(),
            ) == 1
    };
    if !ran {
        let message = unsafe { std::ffi::CStr::from_ptr(err.as_ptr()) };
        found.push(format!("stam_program_run refused it: {message:?}"));
        return found;
    }
    for (i, lane) in lanes.iter().enumerate() {
        let inputs = lane.inputs(kind);
        let one = p.run::<f32>(&inputs);
        let one64 = p.run::<f64>(&inputs.iter().map(|&v| v as f64).collect::<Vec<_>>());
        let batch = &out[i * n_out..(i + 1) * n_out];
        let batch64 = &out64[i * n_out..(i + 1) * n_out];
        let same = one
            .iter()
            .zip(batch)
            .all(|(a, b)| a.to_bits() == b.to_bits())
            && one64
                .iter()
                .zip(batch64)
                .all(|(a, b)| a.to_bits() == b.to_bits());
        if !same {
            found.push(format!(
                "stam_program_run at lane {lane:?}: {batch:?} (f64 {batch64:?}), the lane-by-lane run {one:?} (f64 {one64:?})"
            ));
            break;
        }
    }
    for &(id, _) in &p.params {
        let name = unsafe { std::ffi::CStr::from_ptr(ffi::stam_param_name(id as u32)) };
        if name.to_str() != Ok(id.name()) {
            found.push(format!("stam_param_name({id:?}) is {name:?}"));
        }
    }
    found
}

fn check_sample(
    report: &mut Report,
    wo: DVec3,
    pdf: f64,
    coherent: bool,
    unit_tolerance: f64,
    what: &dyn Fn() -> String,
) {
    report.samples += 1;
    if !(pdf.is_finite() && pdf >= 0.0) {
        report.bad_samples += 1;
        let w = what();
        report.fail(format!("{w}: pdf {pdf}"));
        return;
    }
    if pdf == 0.0 {
        report.sample_failures += 1;
        return;
    }
    if coherent {
        report.coherent_samples += 1;
    }
    let unit = wo.is_finite() && (wo.length() - 1.0).abs() <= unit_tolerance;
    if !unit || !(wo.z > 0.0) || (coherent && pdf > 1.0) {
        report.bad_samples += 1;
        let w = what();
        report.fail(format!(
            "{w}: sampled wo {wo:?} pdf {pdf} coherent {coherent}"
        ));
    }
}

/// stam_rigorous_solve answers a grating with efficiencies in [0, 1] that
/// sum to at most 1 (an absorbing metal), and refuses bad input by name.
fn rigorous_answers() -> Result<(), String> {
    let request = c"{\"period_um\":1.6,\"profile\":\"sine\",\"height_um\":0.12,\"slices\":4,\"fresnel\":\"aluminium\",\"lambda_nm\":550,\"theta_deg\":30,\"phi_deg\":20,\"orders\":8}";
    let mut err = [0 as std::ffi::c_char; 256];
    let answer = unsafe { ffi::stam_rigorous_solve(request.as_ptr(), err.as_mut_ptr(), err.len()) };
    if answer.is_null() {
        return Err("a valid request was refused".to_string());
    }
    let text = unsafe { std::ffi::CStr::from_ptr(answer) }
        .to_str()
        .map(str::to_string);
    unsafe { ffi::stam_text_free(answer) };
    let value: serde_json::Value = text
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .ok_or("the answer is not UTF-8 JSON")?;
    let mut total = [0.0f64; 2];
    for order in value["reflected"].as_array().ok_or("no reflected orders")? {
        for (pol, sum) in total.iter_mut().enumerate() {
            let e = order["efficiency"][pol]
                .as_f64()
                .ok_or("an efficiency is not a number")?;
            if !(0.0..=1.0).contains(&e) {
                return Err(format!("efficiency {e} outside [0, 1]"));
            }
            *sum += e;
        }
    }
    if total.iter().any(|&t| !(t > 0.0 && t <= 1.0)) {
        return Err(format!("total reflectance {total:?} outside (0, 1]"));
    }
    let bad = unsafe { ffi::stam_rigorous_solve(c"{}".as_ptr(), err.as_mut_ptr(), err.len()) };
    let message = unsafe { std::ffi::CStr::from_ptr(err.as_ptr()) }.to_string_lossy();
    if !bad.is_null() || !message.contains("period_um") {
        return Err(format!(
            "an empty request was not refused by name: {message}"
        ));
    }
    Ok(())
}

/// Whether the material is a grating of period above 15 um, where its RGB
/// eval program may unroll more orders than it serves (MAX_RGB_ORDERS:
/// about 20 um at the compact disc's coherence length; every grating of
/// period up to 15 um must have one).
fn coarse_grating(json: &str) -> bool {
    let Ok(value) = serde_json::from_str::<serde_json::Value>(json) else {
        return false;
    };
    let periodic = matches!(value["surface"].as_str(), Some("periodic" | "cd"));
    periodic && value["period_um"].as_f64().is_some_and(|p| p > 15.0)
}

/// The textured parameters' plans (`stam_texture_plan`) of the material
/// `params_json` at a texture's `largest` and `mean`: for each of
/// sigma_um, height_um and a parameter that takes none, the problems found.
pub fn texture_plan_problems(params_json: &str, largest: f64, mean: f64) -> Vec<String> {
    let Ok(serde_json::Value::Object(given)) = serde_json::from_str(params_json) else {
        return vec![format!("not a JSON object: {params_json}")];
    };
    let mut found = Vec::new();
    for name in ["sigma_um", "height_um", "corr_um"] {
        let mut without = given.clone();
        without.remove(name);
        let text = CString::new(serde_json::Value::Object(without).to_string()).unwrap();
        let c_name = CString::new(name).unwrap();
        let takes = unsafe { ffi::stam_param_takes_texture(c_name.as_ptr()) };
        let mut err = [0 as c_char; 512];
        let answer = unsafe {
            ffi::stam_texture_plan(
                text.as_ptr(),
                c_name.as_ptr(),
                largest,
                mean,
                err.as_mut_ptr(),
                err.len(),
            )
        };
        if let Some(problem) = unsafe { texture_plan_problem(answer, &err, takes, name, &text) } {
            found.push(format!(
                "stam_texture_plan({name}, {largest}, {mean}): {problem}"
            ));
        }
        unsafe { ffi::stam_text_free(answer) };
    }
    found
}

/// What is wrong with `stam_texture_plan`'s answer (not freed here) for
/// parameter `name` of the material `params_json`, given that
/// `stam_param_takes_texture(name)` said `takes`: a refusal must say why
/// (and a parameter that takes no texture is always refused), a plan must
/// be the parameter's, its range finite and ordered, its keys numbers with
/// which the material builds.
///
/// # Safety
/// `answer` NULL or a NUL-terminated string.
pub unsafe fn texture_plan_problem(
    answer: *const c_char,
    err: &[c_char],
    takes: i32,
    name: &str,
    params_json: &std::ffi::CStr,
) -> Option<String> {
    if answer.is_null() {
        let message = std::ffi::CStr::from_ptr(err.as_ptr()).to_string_lossy();
        let refused_by_name = message.contains(&format!("'{name}'"))
            || (takes == 1 && !message.contains("internal error") && !message.is_empty());
        return (!refused_by_name).then(|| format!("refused without saying why: {message:?}"));
    }
    if takes != 1 {
        return Some("a plan for a parameter that takes no texture".into());
    }
    let text = std::ffi::CStr::from_ptr(answer).to_str().ok()?;
    let Ok(plan) = serde_json::from_str::<serde_json::Value>(text) else {
        return Some(format!("not JSON: {text}"));
    };
    let param = plan["param"].as_u64().unwrap_or(u64::MAX);
    let own = stam::program::ParamId::ALL
        .iter()
        .any(|id| *id as u64 == param && id.name() == name);
    let range = [plan["range"][0].as_f64(), plan["range"][1].as_f64()];
    let ordered =
        matches!(range, [Some(lo), Some(hi)] if lo.is_finite() && hi.is_finite() && lo <= hi);
    let Some(add) = plan["add"].as_object() else {
        return Some(format!("no keys to add: {text}"));
    };
    if !own || !ordered || !add.contains_key(name) || add.values().any(|v| !v.is_f64()) {
        return Some(format!("not a plan of '{name}': {text}"));
    }
    let mut material: serde_json::Value = serde_json::from_str(params_json.to_str().ok()?).ok()?;
    material.as_object_mut()?.extend(add.clone());
    MaterialParams::from_json(&material.to_string())
        .err()
        .map(|e| format!("its material is refused: {e}"))
}

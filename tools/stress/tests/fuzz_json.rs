//! Proptest version of the cargo-fuzz target `fuzz/fuzz_targets/params_json.rs`
//! (run in CI): arbitrary strings and structurally valid JSON with random keys,
//! values and types go to `stam_brdf_new` through the C ABI. No panic (a
//! caught panic surfaces as an "internal error" message and fails here), no
//! crash; every refusal has a non-empty message that names a parameter key or
//! the JSON problem; every accepted material survives every ABI entry point
//! with arbitrary floats (outputs finite and >= 0). The material's programs
//! (stam_brdf_export_program) are decoded and run on the same floats with
//! the core's f32 executor, under the contract of `stress::programs`.

#![allow(clippy::neg_cmp_op_on_partial_ord)]

use proptest::prelude::*;
use std::ffi::{c_char, CString};
use std::sync::atomic::{AtomicU64, Ordering};
use stress::programs::{self, Lane};

static ACCEPTED: AtomicU64 = AtomicU64::new(0);
static REFUSED: AtomicU64 = AtomicU64::new(0);
static PROGRAM_RUNS: AtomicU64 = AtomicU64::new(0);

/// Every key the parameters know (docs/parameters.md).
const KEYS: [&str; 24] = [
    "surface",
    "energy",
    "sigma_um",
    "corr_um",
    "corr_x_um",
    "corr_y_um",
    "hurst",
    "lag_um",
    "period_um",
    "coherence_um",
    "profile",
    "height_um",
    "width_um",
    "heights_um",
    "fresnel",
    "eta",
    "k",
    "series_tolerance",
    "rgb_nodes",
    "sigma_um_max",
    "file",
    "pixel_um",
    "height_scale_um",
    "tile_px",
];

/// A refusal must name a key (as a whole word) or say what is wrong with the
/// JSON / the text.
fn names_key_or_json_problem(message: &str) -> bool {
    if message.contains("JSON") || message.contains("UTF-8") || message.contains("NUL") {
        return true;
    }
    message
        .split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .any(|w| KEYS.contains(&w))
}

/// Builds through the ABI and, on success, calls every entry point with the
/// given floats. Returns Err(description) on a contract violation.
fn exercise(text: &str, floats: &[f32]) -> Result<(), String> {
    // The ABI takes a NUL-terminated string: cut at an interior NUL as a C
    // caller would.
    let text = text.split('\0').next().unwrap_or("");
    let c = CString::new(text).unwrap();
    let mut err = vec![0x55 as c_char; 256];
    let p = unsafe { stam::ffi::stam_brdf_new(c.as_ptr(), err.as_mut_ptr(), err.len()) };
    // A host's own keys change no verdict; its key list is the same text.
    let mut host_err = vec![0 as c_char; 256];
    let q = unsafe {
        stam::ffi::stam_brdf_new_for_host(
            c.as_ptr(),
            c"[\"twist\"]".as_ptr(),
            host_err.as_mut_ptr(),
            256,
        )
    };
    let bad_hosts = unsafe {
        stam::ffi::stam_brdf_new_for_host(c"{}".as_ptr(), c.as_ptr(), host_err.as_mut_ptr(), 256)
    };
    unsafe { stam::ffi::stam_brdf_free(bad_hosts) };
    if p.is_null() != q.is_null() {
        return Err(format!(
            "stam_brdf_new_for_host decided otherwise for {text:?}"
        ));
    }
    unsafe { stam::ffi::stam_brdf_free(q) };
    if p.is_null() {
        REFUSED.fetch_add(1, Ordering::Relaxed);
        let end = err
            .iter()
            .position(|&c| c == 0)
            .ok_or("err not NUL-terminated")?;
        let bytes: Vec<u8> = err[..end].iter().map(|&c| c as u8).collect();
        let message = String::from_utf8(bytes).map_err(|_| "message not UTF-8".to_string())?;
        if message.trim().is_empty() {
            return Err(format!("refusal without a message for {text:?}"));
        }
        if message.contains("internal error") {
            return Err(format!("panic caught for {text:?}: {message}"));
        }
        // Messages are truncated to the buffer: check the key in what fits.
        if !names_key_or_json_problem(&message) {
            return Err(format!("refusal names no key for {text:?}: {message}"));
        }
        return Ok(());
    }
    ACCEPTED.fetch_add(1, Ordering::Relaxed);
    // The resolved parameters read back as the same material's
    let resolved = unsafe { stam::ffi::stam_brdf_params_json(p) };
    let resolved = (!resolved.is_null())
        .then(|| unsafe { std::ffi::CStr::from_ptr(resolved) }.to_str().ok())
        .flatten();
    let same = resolved.is_some_and(|r| {
        stam::params::MaterialParams::from_json(r).ok()
            == stam::params::MaterialParams::from_json(text).ok()
    });
    if !same {
        unsafe { stam::ffi::stam_brdf_free(p) };
        return Err(format!(
            "stam_brdf_params_json {resolved:?} does not read back as {text}"
        ));
    }
    let r = call_everything(p, floats);
    unsafe { stam::ffi::stam_brdf_free(p) };
    r.map_err(|e| format!("{text}: {e}"))
}

/// Every ABI function on `floats` (cycled into directions, wavelengths and
/// uniforms); outputs must be finite and >= 0.
fn call_everything(p: *mut stam::ffi::StamBrdf, floats: &[f32]) -> Result<(), String> {
    use stam::ffi::*;
    let n = 4;
    let at = |i: usize| -> f32 {
        if floats.is_empty() {
            0.5
        } else {
            floats[i % floats.len()]
        }
    };
    let wi: Vec<f32> = (0..3 * n).map(at).collect();
    let wo: Vec<f32> = (0..3 * n).map(|i| at(i + 3 * n)).collect();
    let lam: Vec<f32> = (0..n).map(|i| at(i + 6 * n)).collect();
    let rnd: Vec<f32> = (0..3 * n).map(|i| at(i + 7 * n)).collect();
    let mut out = vec![0f32; 3 * n];
    let mut pdf = vec![0f32; n];
    let mut coh = vec![0u8; n];
    let check = |what: &str, v: &[f32]| -> Result<(), String> {
        match v.iter().find(|x| !(x.is_finite() && **x >= 0.0)) {
            Some(x) => Err(format!("{what} gave {x}")),
            None => Ok(()),
        }
    };
    unsafe {
        stam_brdf_eval_spectral(
            p,
            n,
            wi.as_ptr(),
            wo.as_ptr(),
            lam.as_ptr(),
            out.as_mut_ptr(),
        );
        check("eval_spectral", &out[..n])?;
        stam_brdf_eval_rgb(p, n, wi.as_ptr(), wo.as_ptr(), out.as_mut_ptr());
        check("eval_rgb", &out)?;
        stam_brdf_coherent_spectral(p, n, wi.as_ptr(), lam.as_ptr(), out.as_mut_ptr());
        check("coherent_spectral", &out[..n])?;
        stam_brdf_coherent_rgb(p, n, wi.as_ptr(), out.as_mut_ptr());
        check("coherent_rgb", &out)?;
        // Polarisation: finite, on the unit sphere where the material has
        // one, zeros where it has none.
        let has = stam_brdf_polarization(
            p,
            n,
            wi.as_ptr(),
            wo.as_ptr(),
            lam.as_ptr(),
            out.as_mut_ptr(),
        );
        for v in out.chunks_exact(3) {
            let q: f32 = v.iter().map(|x| x * x).sum();
            if !(q.is_finite()
                && if has == 1 {
                    (q - 1.0).abs() < 1e-4
                } else {
                    q == 0.0
                })
            {
                return Err(format!("polarization gave {v:?} (returned {has})"));
            }
        }
        // Mueller matrices: finite, [0][0] = 1 where the material has them,
        // zeros where it has none.
        let mut mm = vec![0f32; 22 * n];
        let has_m = stam_brdf_mueller(
            p,
            n,
            wo.as_ptr(),
            wi.as_ptr(),
            lam.as_ptr(),
            mm.as_mut_ptr(),
        );
        for m in mm.chunks_exact(22) {
            let fine = m.iter().all(|x| x.is_finite())
                && if has_m == 1 {
                    (m[0] - 1.0).abs() < 1e-5
                } else {
                    m.iter().all(|&x| x == 0.0)
                };
            if !fine {
                return Err(format!("mueller gave {m:?} (returned {has_m})"));
            }
        }
        if (stam_brdf_export_polarization_program(p, std::ptr::null_mut(), 0) > 0) != (has == 1) {
            return Err(format!(
                "a polarization program where polarization returned {has}"
            ));
        }
        for lam_ptr in [lam.as_ptr(), std::ptr::null()] {
            stam_brdf_sample(
                p,
                n,
                wi.as_ptr(),
                lam_ptr,
                rnd.as_ptr(),
                out.as_mut_ptr(),
                pdf.as_mut_ptr(),
                coh.as_mut_ptr(),
            );
            check("sample pdf", &pdf)?;
            for i in 0..n {
                if pdf[i] > 0.0 {
                    let w = &out[3 * i..3 * i + 3];
                    let len = (w.iter().map(|x| (*x as f64).powi(2)).sum::<f64>()).sqrt();
                    if !((len - 1.0).abs() < 1e-5) {
                        return Err(format!("sample wo {w:?} is not unit (pdf {})", pdf[i]));
                    }
                }
            }
            stam_brdf_pdf(p, n, wi.as_ptr(), wo.as_ptr(), lam_ptr, pdf.as_mut_ptr());
            check("pdf", &pdf)?;
            stam_brdf_coherent_probability(p, n, wi.as_ptr(), lam_ptr, pdf.as_mut_ptr());
            check("coherent_probability", &pdf)?;
            if let Some(x) = pdf.iter().find(|&&x| x > 1.0) {
                return Err(format!("coherent_probability gave {x} > 1"));
            }
        }
        // The path-vertex calls: the lanes' n values as one lane's
        // wavelengths, and RGB; the combined call, then the separate eval
        // and sample calls, which must give the same outputs.
        for (lam_ptr, nw) in [(lam.as_ptr(), n), (std::ptr::null(), 0)] {
            let mut f = vec![0f32; 3 * n];
            let mut s_val = vec![0f32; 3 * n];
            let mut s_wo = vec![0f32; 3];
            let (mut p1, mut s_pdf, mut s_coh) = (0f32, 0f32, 0u8);
            stam_brdf_eval_pdf_sample_vertex(
                p,
                1,
                wi.as_ptr(),
                wo.as_ptr(),
                lam_ptr,
                nw,
                rnd.as_ptr(),
                f.as_mut_ptr(),
                &mut p1,
                s_wo.as_mut_ptr(),
                &mut s_pdf,
                &mut s_coh,
                s_val.as_mut_ptr(),
            );
            check("vertex f", &f)?;
            check("vertex pdf", &[p1, s_pdf])?;
            check("vertex sample value", &s_val)?;
            if s_pdf > 0.0 {
                let len = (s_wo.iter().map(|x| (*x as f64).powi(2)).sum::<f64>()).sqrt();
                if !((len - 1.0).abs() < 1e-5) {
                    return Err(format!("vertex sample wo {s_wo:?} is not unit"));
                }
            }
            let mut f_sep = vec![0f32; 3 * n];
            let mut p_sep = 0f32;
            stam_brdf_eval_pdf_vertex(
                p,
                1,
                wi.as_ptr(),
                wo.as_ptr(),
                lam_ptr,
                nw,
                f_sep.as_mut_ptr(),
                &mut p_sep,
            );
            let mut v_wo = vec![0f32; 3];
            let mut v_val = vec![0f32; 3 * n];
            let (mut v_pdf, mut v_coh) = (0f32, 0u8);
            stam_brdf_sample_vertex(
                p,
                1,
                wi.as_ptr(),
                lam_ptr,
                nw,
                rnd.as_ptr(),
                v_wo.as_mut_ptr(),
                &mut v_pdf,
                &mut v_coh,
                v_val.as_mut_ptr(),
            );
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            if bits(&f_sep) != bits(&f) || p_sep.to_bits() != p1.to_bits() {
                return Err(format!(
                    "eval_pdf_vertex ({f_sep:?}, {p_sep}) differs from the combined call ({f:?}, {p1})"
                ));
            }
            if bits(&v_wo) != bits(&s_wo)
                || v_pdf.to_bits() != s_pdf.to_bits()
                || v_coh != s_coh
                || bits(&v_val) != bits(&s_val)
            {
                return Err(format!(
                    "sample_vertex ({v_wo:?}, {v_pdf}, {v_coh}, {v_val:?}) differs from the combined call ({s_wo:?}, {s_pdf}, {s_coh}, {s_val:?})"
                ));
            }
        }
        // The programs: sized with NULL, nothing written into a small
        // buffer, the whole array decoded (stress::programs::decode_checked)
        // and run on the lanes: the floats as they come, and again with the
        // uniforms folded into [0, 1) so that sampling is reached with the
        // inputs a renderer gives.
        let lanes: Vec<Lane> = (0..n)
            .map(|i| Lane {
                wi: [wi[3 * i], wi[3 * i + 1], wi[3 * i + 2]],
                wo: [wo[3 * i], wo[3 * i + 1], wo[3 * i + 2]],
                u: [rnd[3 * i], rnd[3 * i + 1], rnd[3 * i + 2]],
                lambda: lam[i],
            })
            .flat_map(|l| [l, l.with_valid_uniforms()])
            .collect();
        let mut decoded = Vec::new();
        for kind in 0..programs::KINDS {
            let len = stam_brdf_export_program(p, kind, std::ptr::null_mut(), 0);
            let mut small = [0.0f32; 4];
            if stam_brdf_export_program(p, kind, small.as_mut_ptr(), small.len()) != len
                || (len > 0 && (len <= small.len() || small != [0.0; 4]))
            {
                return Err(format!(
                    "stam_brdf_export_program {kind}: {len} floats, wrote {small:?} into 4"
                ));
            }
            if len == 0 {
                decoded.push(None);
                continue;
            }
            let mut array = vec![0.0f32; len];
            let written = stam_brdf_export_program(p, kind, array.as_mut_ptr(), len);
            if written != len {
                return Err(format!(
                    "stam_brdf_export_program {kind}: {written} of {len} floats"
                ));
            }
            let program = programs::decode_checked(kind, &array)?;
            // The ABI's executor equals the lane-by-lane one on these lanes.
            if let Some(v) = stress::run::check_program_run(&array, &program, kind, &lanes).first()
            {
                return Err(format!("program {kind}: {v}"));
            }
            decoded.push(Some(program));
        }
        // The mixture programs over 4 wavelengths: the spectral ones mixed;
        // none for a count out of range.
        if decoded[3].is_some() {
            let mut mixtures = Vec::new();
            for kind in 0..3 {
                let len = stam_brdf_export_mixture_program(p, kind, 4, std::ptr::null_mut(), 0);
                let mut array = vec![0.0f32; len];
                stam_brdf_export_mixture_program(p, kind, 4, array.as_mut_ptr(), len);
                let out_of_range =
                    stam_brdf_export_mixture_program(p, kind, 0, std::ptr::null_mut(), 0)
                        + stam_program_io(kind, 17, std::ptr::null_mut(), std::ptr::null_mut())
                            as usize;
                match stam::program::decode(&array) {
                    Some(program) if out_of_range == 0 => mixtures.push(program),
                    _ => {
                        return Err(format!(
                            "stam_brdf_export_mixture_program {kind}: {len} floats"
                        ))
                    }
                }
            }
            let checked = programs::check_mixtures(&mixtures, &decoded, &lanes);
            if let Some(v) = checked.violations.first() {
                return Err(format!("mixture: {v}"));
            }
        }
        // The executor refuses what is not a program: NULL, and these
        // floats as an array; a parameter id past the last has no name.
        let mut err = [0 as c_char; 64];
        let (null, none) = (std::ptr::null(), std::ptr::null_mut());
        let mut out = [0.0f32; 4];
        let mut out64 = [0.0f64; 4];
        let as_array = [wi.as_slice(), wo.as_slice(), rnd.as_slice()].concat();
        if stam_program_run(
            null,
            0,
            null,
            1,
            null,
            0,
            out.as_mut_ptr(),
            None,
            None,
            none,
            err.as_mut_ptr(),
            err.len(),
        ) != 0
            || stam_program_run_f64(
                as_array.as_ptr(),
                as_array.len(),
                std::ptr::null(),
                0,
                std::ptr::null(),
                0,
                out64.as_mut_ptr(),
                err.as_mut_ptr(),
                err.len(),
            ) != 0
            || *stam_param_name(stam::program::PARAM_COUNT) != 0
        {
            return Err(
                "stam_program_run ran no program, or an unknown parameter id has a name".into(),
            );
        }
        for kind in [programs::KINDS, u32::MAX] {
            if stam_brdf_export_program(p, kind, std::ptr::null_mut(), 0) != 0 {
                return Err(format!(
                    "stam_brdf_export_program: a program of kind {kind}"
                ));
            }
        }
        let checked = programs::check(&decoded, &lanes);
        PROGRAM_RUNS.fetch_add(checked.runs, Ordering::Relaxed);
        if let Some(v) = checked.violations.first() {
            return Err(format!("program: {v}"));
        }
        let _ = stam_brdf_flags(p);
        let _ = stam_brdf_memory_bytes(p);
        let warnings = stam_brdf_warnings(p);
        if warnings.is_null() || std::ffi::CStr::from_ptr(warnings).to_str().is_err() {
            return Err("stam_brdf_warnings is NULL or not UTF-8".to_string());
        }
        let version = stam_version();
        if version.is_null() || std::ffi::CStr::from_ptr(version).to_bytes().is_empty() {
            return Err("stam_version is NULL or empty".to_string());
        }
        let reference = stam_parameter_reference();
        let parsed = (!reference.is_null())
            .then(|| std::ffi::CStr::from_ptr(reference).to_str().ok())
            .flatten()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(t).ok());
        if !parsed.is_some_and(|v| v["surfaces"].is_array()) {
            return Err("stam_parameter_reference is not the reference's JSON".to_string());
        }
        rigorous_request(&at)?;
        texture_plans(p, &at)?;
    }
    Ok(())
}

/// stam_texture_plan on the material's resolved parameters (the textured
/// key left out) at the fuzzed floats as the texture's largest value and
/// mean: a plan the material builds with, or a refusal saying why
/// (`stress::run::texture_plan_problems`); NULL inputs refused.
unsafe fn texture_plans(
    p: *mut stam::ffi::StamBrdf,
    at: &dyn Fn(usize) -> f32,
) -> Result<(), String> {
    use stam::ffi::*;
    let resolved = std::ffi::CStr::from_ptr(stam_brdf_params_json(p)).to_string_lossy();
    let (largest, mean) = (at(9) as f64, at(10) as f64);
    if let Some(problem) = stress::run::texture_plan_problems(&resolved, largest, mean).first() {
        return Err(problem.clone());
    }
    let mut err = [0 as c_char; 64];
    let null = std::ptr::null();
    let refused = stam_texture_plan(null, c"sigma_um".as_ptr(), 1.0, 1.0, err.as_mut_ptr(), 64)
        .is_null()
        && stam_texture_plan(c"{}".as_ptr(), null, 1.0, 1.0, err.as_mut_ptr(), 64).is_null();
    if !refused || stam_param_takes_texture(null) != 0 {
        return Err("stam_texture_plan or stam_param_takes_texture took NULL".into());
    }
    Ok(())
}

/// stam_rigorous_solve on a rect grating made of the fuzzed floats: refused
/// with a message, or finite efficiencies >= 0.
unsafe fn rigorous_request(at: &dyn Fn(usize) -> f32) -> Result<(), String> {
    use stam::ffi::*;
    // NaN and Inf become null, which is refused by name.
    let request = serde_json::json!({
        "period_um": at(0), "profile": "rect", "height_um": at(1), "width_um": at(2),
        "fresnel": {"eta": at(3), "k": at(4)}, "lambda_nm": at(5), "theta_deg": at(6),
        "phi_deg": at(7), "orders": (at(8).abs() as usize).min(6),
    });
    let request = std::ffi::CString::new(request.to_string()).unwrap();
    let mut err = [0 as std::ffi::c_char; 256];
    let answer = stam_rigorous_solve(request.as_ptr(), err.as_mut_ptr(), err.len());
    if answer.is_null() {
        let message = std::ffi::CStr::from_ptr(err.as_ptr()).to_string_lossy();
        if message.is_empty() || message.contains("internal error") {
            return Err(format!(
                "stam_rigorous_solve refused without a message or panicked: {message}"
            ));
        }
        return Ok(());
    }
    let text = std::ffi::CStr::from_ptr(answer)
        .to_str()
        .map(str::to_string);
    stam_text_free(answer);
    let value: serde_json::Value = text
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .ok_or("stam_rigorous_solve: the answer is not UTF-8 JSON")?;
    for order in value["reflected"]
        .as_array()
        .ok_or("stam_rigorous_solve: no reflected orders")?
    {
        for pol in 0..2 {
            let e = order["efficiency"][pol].as_f64().unwrap_or(f64::NAN);
            if !(e.is_finite() && e >= 0.0) {
                return Err(format!("stam_rigorous_solve: efficiency {e}"));
            }
        }
    }
    Ok(())
}

fn any_float() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => -2.0f32..2.0,
        2 => 300.0f32..900.0,
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => Just(f32::NEG_INFINITY),
        1 => Just(0.0f32),
        1 => Just(-0.0f32),
        1 => Just(f32::MAX),
        1 => Just(f32::MIN_POSITIVE / 4.0),
        1 => any::<f32>(),
    ]
}

/// A JSON number in text form, including the awkward ones.
fn number() -> impl Strategy<Value = String> {
    prop_oneof![
        (-1e3f64..1e3).prop_map(|x| format!("{x}")),
        (-300i32..300).prop_map(|e| format!("1e{e}")),
        (0.0f64..1.0).prop_map(|x| format!("{x}")),
        any::<i64>().prop_map(|x| format!("{x}")),
        Just("1e400".to_string()),
        Just("-0".to_string()),
        Just("0".to_string()),
        Just("123456789012345678901234567890".to_string()),
        (1u32..70).prop_map(|x| format!("{x}")),
        (1e-7f64..200.0).prop_map(|x| format!("{x}")),
    ]
}

fn string_value() -> impl Strategy<Value = String> {
    prop_oneof![
        prop::sample::select(vec![
            "gaussian",
            "fractal",
            "periodic",
            "cd",
            "rect",
            "sine",
            "aluminium",
            "silver",
            "gold",
            "copper",
            "chromium",
            "",
            "Gaussian",
            "glass",
        ])
        .prop_map(|s| format!("\"{s}\"")),
        "[a-z_\\\\\"\u{e9}\u{1F600}]{0,12}".prop_map(|s| serde_json::to_string(&s).unwrap()),
    ]
}

fn key() -> impl Strategy<Value = String> {
    prop_oneof![
        6 => prop::sample::select(KEYS.to_vec()).prop_map(|s| s.to_string()),
        1 => "[a-zA-Z_\u{e9}]{0,10}",
    ]
    .prop_map(|k| serde_json::to_string(&k).unwrap())
}

/// Any JSON value, nested to a small depth, biased to numbers and the
/// known strings.
fn value() -> impl Strategy<Value = String> {
    let leaf = prop_oneof![
        4 => number(),
        3 => string_value(),
        1 => Just("true".to_string()),
        1 => Just("null".to_string()),
    ];
    leaf.prop_recursive(3, 24, 6, |inner| {
        prop_oneof![
            prop::collection::vec(inner.clone(), 0..6).prop_map(|v| format!("[{}]", v.join(","))),
            prop::collection::vec((key(), inner), 0..4).prop_map(|kv| {
                let items: Vec<String> = kv.iter().map(|(k, v)| format!("{k}:{v}")).collect();
                format!("{{{}}}", items.join(","))
            }),
            prop::collection::vec(number(), 0..40)
                .prop_map(|v| format!("{{\"heights_um\":[{}]}}", v.join(","))),
        ]
    })
}

/// A structurally valid JSON object, usually with a valid surface and some
/// of its keys, so that validation goes deep.
fn object() -> impl Strategy<Value = String> {
    (
        prop::option::weighted(
            0.9,
            prop::sample::select(vec!["gaussian", "fractal", "periodic", "cd"]),
        ),
        prop::collection::vec((key(), value()), 0..7),
    )
        .prop_map(|(surface, kv)| {
            let mut items: Vec<String> = Vec::new();
            if let Some(s) = surface {
                items.push(format!("\"surface\":\"{s}\""));
            }
            items.extend(kv.iter().map(|(k, v)| format!("{k}:{v}")));
            format!("{{{}}}", items.join(","))
        })
}

/// A valid random material (the stress generator's) with 0 to 2 mutations:
/// a key removed, a key set to a random value of any type, or a known key
/// added.
fn mutated_material() -> impl Strategy<Value = String> {
    (
        any::<u64>(),
        0usize..stress::gen::SURFACES.len(),
        prop::collection::vec(
            (0usize..3, any::<prop::sample::Index>(), key(), value()),
            0..3,
        ),
    )
        .prop_map(|(seed, kind, mutations)| {
            let mut rng = stress::gen::Rng::new(seed);
            let json = stress::gen::material(&mut rng, kind);
            let serde_json::Value::Object(mut obj) = serde_json::from_str(&json).unwrap() else {
                unreachable!()
            };
            for (what, index, key, value) in mutations {
                let keys: Vec<String> = obj.keys().cloned().collect();
                if keys.is_empty() {
                    continue;
                }
                let existing = keys[index.index(keys.len())].clone();
                let value: serde_json::Value =
                    serde_json::from_str(&value).unwrap_or(serde_json::Value::Null);
                match what {
                    0 => {
                        obj.remove(&existing);
                    }
                    1 => {
                        obj.insert(existing, value);
                    }
                    _ => {
                        obj.insert(serde_json::from_str::<String>(&key).unwrap(), value);
                    }
                }
            }
            serde_json::Value::Object(obj).to_string()
        })
}

fn run_strategy<S: Strategy<Value = String>>(name: &str, strategy: S, cases: u32) {
    let accepted = ACCEPTED.load(Ordering::Relaxed);
    let refused = REFUSED.load(Ordering::Relaxed);
    let mut runner = proptest::test_runner::TestRunner::new(ProptestConfig {
        cases,
        failure_persistence: None,
        ..ProptestConfig::default()
    });
    let floats = prop::collection::vec(any_float(), 0..40);
    let result = runner.run(&(strategy, floats), |(text, floats)| {
        exercise(&text, &floats).map_err(TestCaseError::fail)
    });
    println!(
        "{name}: {cases} cases, accepted {}, refused {} (all refusals with a message naming a key or the JSON problem); program lanes run so far {}",
        ACCEPTED.load(Ordering::Relaxed) - accepted,
        REFUSED.load(Ordering::Relaxed) - refused,
        PROGRAM_RUNS.load(Ordering::Relaxed)
    );
    if let Err(e) = result {
        panic!("{name}: {e}");
    }
}

/// Cases per strategy (env FUZZ_CASES overrides both defaults; `make
/// fuzz` runs 30,000 of each). The mutated valid materials get fewer by
/// default: a third of them are accepted, and each accepted one builds
/// its tables for every program (about 0.2 s on one core, nearly all of
/// the run), where a refused text takes microseconds.
fn cases() -> u32 {
    fuzz_cases().unwrap_or(3000)
}

fn mutated_cases() -> u32 {
    fuzz_cases().unwrap_or(1000)
}

fn fuzz_cases() -> Option<u32> {
    std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
}

#[test]
fn fuzz_parameters_and_abi() {
    run_strategy("arbitrary text", ".{0,200}", cases());
    run_strategy(
        "JSON-ish text",
        "[{}\\[\\]\":,0-9.eE+\\-a-z_ ]{0,120}",
        cases(),
    );
    run_strategy("structured JSON", object(), cases());
    // The on-success path must actually be reached, not only refusals.
    assert!(ACCEPTED.load(Ordering::Relaxed) > 0);
}

/// Mutated valid materials, in two tests of half the cases each (each
/// runner draws its own random cases), so that the test harness's threads
/// share them: an accepted material builds and runs its programs, about
/// 85 ms each, which made this strategy nearly all of the fuzz run's time
/// on one thread.
#[test]
fn fuzz_mutated_materials_first_half() {
    run_strategy(
        "mutated valid materials (1 of 2)",
        mutated_material(),
        mutated_cases().div_ceil(2),
    );
}

#[test]
fn fuzz_mutated_materials_second_half() {
    run_strategy(
        "mutated valid materials (2 of 2)",
        mutated_material(),
        mutated_cases().div_ceil(2),
    );
}

/// Valid materials (those tagged `fuzz` in tests/materials.json) with random
/// float inputs: the fuzzer's "on success" path must actually be reached, not
/// only refusals.
#[test]
fn fuzz_reaches_accepted_materials() {
    let accepted_before = ACCEPTED.load(Ordering::Relaxed);
    let materials = stress::materials::tagged("fuzz");
    assert_eq!(materials.len(), 3);
    for m in &materials {
        exercise(&m.params, &[0.1, 0.2, 0.9, f32::NAN, 500.0, -0.3, 0.7]).unwrap();
    }
    assert!(ACCEPTED.load(Ordering::Relaxed) >= accepted_before + 3);
    // ... and the programs were run: every material has at least its
    // sampling, pdf and coherent kinds (6 kinds, 8 lanes, 3 materials).
    assert!(PROGRAM_RUNS.load(Ordering::Relaxed) >= 6 * 8 * 3);
    println!(
        "fuzz counts so far in this process: accepted {}, refused {}",
        ACCEPTED.load(Ordering::Relaxed),
        REFUSED.load(Ordering::Relaxed)
    );
}

#[test]
fn refusal_check_is_not_vacuous() {
    assert!(!names_key_or_json_problem("something went wrong"));
    assert!(names_key_or_json_problem(
        "parameter 'sigma_um' = -1 is out of range"
    ));
    assert!(names_key_or_json_problem(
        "parameters are not valid JSON: EOF"
    ));
}

//! The C ABI (include/stam.h). Thin: converts, checks pointers, catches
//! panics. No physics here.
//!
//! Every entry point is wrapped in `catch_unwind`: a bug must never unwind
//! into C. On a caught panic, outputs are zeroed (and construction reports
//! the panic message).

mod program;

pub use program::{
    stam_param_name, stam_program_io, stam_program_run, stam_program_run_f64,
    StamProgramElementary, StamProgramRegion,
};

use crate::material::params::{parameter_reference, resolved_json_text};
use crate::material::plausibility::warnings_for_json;
use crate::material::program::ProgramKind;
use crate::material::Brdf;
use crate::material::Channels;
use glam::DVec3;
use std::ffi::{c_char, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::OnceLock;

/// Opaque handle handed to C.
pub struct StamBrdf {
    pub brdf: Brdf,
    /// The plausibility warnings of its parameters, one per line
    /// (`stam_brdf_warnings`).
    pub warnings: CString,
    /// Its parameters with the defaults filled in, as JSON
    /// (`stam_brdf_params_json`).
    pub params_json: CString,
}

/// f64 -> f32 for outputs: finite, non-negative, clamped to f32::MAX.
#[inline]
fn to_output(x: f64) -> f32 {
    if x > 0.0 {
        x.min(f32::MAX as f64) as f32
    } else {
        0.0
    }
}

#[inline]
unsafe fn direction(p: *const f32, i: usize) -> DVec3 {
    let s = std::slice::from_raw_parts(p.add(3 * i), 3);
    DVec3::new(s[0] as f64, s[1] as f64, s[2] as f64)
}

/// Copy `message` into the caller's buffer, truncated at a char boundary and
/// NUL-terminated.
unsafe fn write_message(err: *mut c_char, err_len: usize, message: &str) {
    if err.is_null() || err_len == 0 {
        return;
    }
    let mut len = message.len().min(err_len - 1);
    while !message.is_char_boundary(len) {
        len -= 1;
    }
    std::ptr::copy_nonoverlapping(message.as_ptr(), err as *mut u8, len);
    *err.add(len) = 0;
}

fn panic_message(payload: Box<dyn std::any::Any + Send>) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        format!("internal error: {s}")
    } else if let Some(s) = payload.downcast_ref::<String>() {
        format!("internal error: {s}")
    } else {
        "internal error".to_string()
    }
}

/// # Safety
/// `params_json` must be NULL or a NUL-terminated string; `err` NULL or
/// writable for `err_len` bytes.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_new(
    params_json: *const c_char,
    err: *mut c_char,
    err_len: usize,
) -> *mut StamBrdf {
    new_material(params_json, &[], err, err_len)
}

/// # Safety
/// As `stam_brdf_new`; `host_keys_json` NULL or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_new_for_host(
    params_json: *const c_char,
    host_keys_json: *const c_char,
    err: *mut c_char,
    err_len: usize,
) -> *mut StamBrdf {
    let host_keys = if host_keys_json.is_null() {
        Vec::new()
    } else {
        let keys = CStr::from_ptr(host_keys_json)
            .to_str()
            .ok()
            .and_then(|t| serde_json::from_str::<Vec<String>>(t).ok());
        match keys {
            Some(keys) => keys,
            None => {
                write_message(
                    err,
                    err_len,
                    "host_keys_json is not a JSON array of strings (the host's own keys)",
                );
                return std::ptr::null_mut();
            }
        }
    };
    new_material(params_json, &host_keys, err, err_len)
}

/// The material of `params_json`, or NULL with the reason in `err` (an
/// unknown key's message listing `host_keys` too).
unsafe fn new_material(
    params_json: *const c_char,
    host_keys: &[String],
    err: *mut c_char,
    err_len: usize,
) -> *mut StamBrdf {
    if params_json.is_null() {
        write_message(err, err_len, "params_json is NULL");
        return std::ptr::null_mut();
    }
    let text = match CStr::from_ptr(params_json).to_str() {
        Ok(t) => t,
        Err(_) => {
            write_message(err, err_len, "params_json is not valid UTF-8");
            return std::ptr::null_mut();
        }
    };
    match catch_unwind(|| Brdf::from_json(text)) {
        Ok(Ok(brdf)) => {
            write_message(err, err_len, "");
            let warnings = catch_unwind(|| warnings_text(text)).unwrap_or_default();
            let params_json = catch_unwind(|| c_text(resolved_json_text(text).unwrap_or_default()))
                .unwrap_or_default();
            Box::into_raw(Box::new(StamBrdf {
                brdf,
                warnings,
                params_json,
            }))
        }
        Ok(Err(e)) => {
            write_message(err, err_len, &e.with_host_keys(host_keys).message);
            std::ptr::null_mut()
        }
        Err(payload) => {
            write_message(err, err_len, &panic_message(payload));
            std::ptr::null_mut()
        }
    }
}

/// The warnings of accepted parameters, one per line, without NUL bytes.
fn warnings_text(text: &str) -> CString {
    let lines: Vec<String> = warnings_for_json(text)
        .iter()
        .map(|w| w.message.replace(['\n', '\0'], " "))
        .collect();
    CString::new(lines.join("\n")).unwrap_or_default()
}

/// Text as a C string (a NUL byte, which JSON text escapes, would end it:
/// "" then).
fn c_text(text: String) -> CString {
    CString::new(text).unwrap_or_default()
}

/// # Safety
/// `brdf` must be NULL or a pointer returned by `stam_brdf_new`, freed once.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_free(brdf: *mut StamBrdf) {
    if !brdf.is_null() {
        let _ = catch_unwind(AssertUnwindSafe(|| drop(Box::from_raw(brdf))));
    }
}

/// Run `body` over n items, zero-filling `out` (n * width floats) when the
/// material is NULL or a panic is caught.
unsafe fn batch(
    b: *const StamBrdf,
    n: usize,
    out: *mut f32,
    width: usize,
    inputs_ok: bool,
    body: impl Fn(&Brdf, usize, &mut [f32]),
) {
    if out.is_null() || n == 0 {
        return;
    }
    let out = std::slice::from_raw_parts_mut(out, n * width);
    if b.is_null() || !inputs_ok {
        out.fill(0.0);
        return;
    }
    let brdf = &(*b).brdf;
    let result = catch_unwind(AssertUnwindSafe(|| {
        for (i, chunk) in out.chunks_exact_mut(width).enumerate() {
            body(brdf, i, chunk);
        }
    }));
    if result.is_err() {
        out.fill(0.0);
    }
}

/// # Safety
/// Arrays hold n (wi, wo: 3n) floats; `b` NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_eval_spectral(
    b: *const StamBrdf,
    n: usize,
    wi: *const f32,
    wo: *const f32,
    lambda_nm: *const f32,
    out: *mut f32,
) {
    let ok = !wi.is_null() && !wo.is_null() && !lambda_nm.is_null();
    batch(b, n, out, 1, ok, |brdf, i, o| {
        let f = brdf.eval_spectral(direction(wi, i), direction(wo, i), *lambda_nm.add(i) as f64);
        o[0] = to_output(f);
    });
}

/// # Safety
/// wi, wo hold 3n floats, out_rgb 3n; `b` NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_eval_rgb(
    b: *const StamBrdf,
    n: usize,
    wi: *const f32,
    wo: *const f32,
    out_rgb: *mut f32,
) {
    let ok = !wi.is_null() && !wo.is_null();
    batch(b, n, out_rgb, 3, ok, |brdf, i, o| {
        let rgb = brdf.eval_rgb(direction(wi, i), direction(wo, i));
        for c in 0..3 {
            o[c] = to_output(rgb[c]);
        }
    });
}

/// # Safety
/// wi holds 3n floats, lambda_nm and out n; `b` NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_coherent_spectral(
    b: *const StamBrdf,
    n: usize,
    wi: *const f32,
    lambda_nm: *const f32,
    out: *mut f32,
) {
    let ok = !wi.is_null() && !lambda_nm.is_null();
    batch(b, n, out, 1, ok, |brdf, i, o| {
        o[0] = to_output(brdf.coherent_spectral(direction(wi, i), *lambda_nm.add(i) as f64));
    });
}

/// # Safety
/// wi and out_rgb hold 3n floats; `b` NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_coherent_rgb(
    b: *const StamBrdf,
    n: usize,
    wi: *const f32,
    out_rgb: *mut f32,
) {
    batch(b, n, out_rgb, 3, !wi.is_null(), |brdf, i, o| {
        let rgb = brdf.coherent_rgb(direction(wi, i));
        for c in 0..3 {
            o[c] = to_output(rgb[c]);
        }
    });
}

/// # Safety
/// wi, wo and out hold 3n floats, lambda_nm n; `b` NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_polarization(
    b: *const StamBrdf,
    n: usize,
    wi: *const f32,
    wo: *const f32,
    lambda_nm: *const f32,
    out: *mut f32,
) -> i32 {
    // A material without a polarisation, or an input missing: zeros, and 0
    let polarizes = !wi.is_null()
        && !wo.is_null()
        && !lambda_nm.is_null()
        && !out.is_null()
        && !b.is_null()
        && (*b).brdf.polarizes();
    batch(b, n, out, 3, polarizes, |brdf, i, o| {
        let lambda = *lambda_nm.add(i) as f64;
        let p = brdf
            .polarization(direction(wi, i), direction(wo, i), lambda)
            .unwrap_or([0.0, -1.0, 0.0]);
        for (o, v) in o.iter_mut().zip(p) {
            *o = v as f32;
        }
    });
    polarizes as i32
}

/// # Safety
/// from, to hold 3n floats, lambda_nm n, out 22n; `b` NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_mueller(
    b: *const StamBrdf,
    n: usize,
    from: *const f32,
    to: *const f32,
    lambda_nm: *const f32,
    out: *mut f32,
) -> i32 {
    // A material without a Mueller matrix, or an input missing: zeros, and 0
    let has = !from.is_null()
        && !to.is_null()
        && !lambda_nm.is_null()
        && !out.is_null()
        && !b.is_null()
        && (*b).brdf.has_mueller();
    batch(b, n, out, STAM_MUELLER_FLOATS, has, |brdf, i, o| {
        let lambda = *lambda_nm.add(i) as f64;
        let (from, to) = (direction(from, i), direction(to, i));
        // Directions the core cannot take (zero, not finite): a depolarizer.
        let (m, bases) = brdf
            .mueller(from, to, lambda)
            .filter(|(m, bases)| {
                m.iter().all(|v| v.is_finite()) && bases.iter().all(|b| b.is_finite())
            })
            .unwrap_or((
                [
                    1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                ],
                [DVec3::X, DVec3::X],
            ));
        for (o, v) in o.iter_mut().zip(
            m.iter()
                .copied()
                .chain(bases[0].to_array())
                .chain(bases[1].to_array()),
        ) {
            *o = if v.is_finite() { v as f32 } else { 0.0 };
        }
    });
    has as i32
}

/// Floats per entry of `stam_brdf_mueller`: the matrix, then two bases.
const STAM_MUELLER_FLOATS: usize = 22;

#[inline]
unsafe fn optional_lambda(lambda_nm: *const f32, i: usize) -> Option<f64> {
    if lambda_nm.is_null() {
        None
    } else {
        Some(*lambda_nm.add(i) as f64)
    }
}

/// # Safety
/// wi, rnd and wo hold 3n floats, pdf n floats, coherent n bytes (or NULL);
/// lambda_nm NULL (RGB mode) or n floats; `b` NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_sample(
    b: *const StamBrdf,
    n: usize,
    wi: *const f32,
    lambda_nm: *const f32,
    rnd: *const f32,
    wo: *mut f32,
    pdf: *mut f32,
    coherent: *mut u8,
) {
    if n == 0 {
        return;
    }
    let zero = |wo: *mut f32, pdf: *mut f32, coherent: *mut u8| {
        if !wo.is_null() {
            std::slice::from_raw_parts_mut(wo, 3 * n).fill(0.0);
        }
        if !pdf.is_null() {
            std::slice::from_raw_parts_mut(pdf, n).fill(0.0);
        }
        if !coherent.is_null() {
            std::slice::from_raw_parts_mut(coherent, n).fill(0);
        }
    };
    if b.is_null() || wi.is_null() || rnd.is_null() || wo.is_null() || pdf.is_null() {
        zero(wo, pdf, coherent);
        return;
    }
    let brdf = &(*b).brdf;
    let result = catch_unwind(AssertUnwindSafe(|| {
        for i in 0..n {
            let sampler = brdf.sampler(direction(wi, i), optional_lambda(lambda_nm, i));
            let r = std::slice::from_raw_parts(rnd.add(3 * i), 3);
            let s = sampler.sample([r[0] as f64, r[1] as f64, r[2] as f64]);
            let out = [s.wo.x as f32, s.wo.y as f32, s.wo.z as f32];
            // The pdf of the direction as the caller sees it (rounded to f32),
            // so that stam_brdf_pdf at the returned wo gives the same value.
            let p = if s.pdf > 0.0 && !s.coherent {
                sampler.pdf(DVec3::new(out[0] as f64, out[1] as f64, out[2] as f64))
            } else {
                s.pdf
            };
            std::slice::from_raw_parts_mut(wo.add(3 * i), 3).copy_from_slice(&out);
            *pdf.add(i) = to_output(p);
            if !coherent.is_null() {
                *coherent.add(i) = u8::from(s.coherent && p > 0.0);
            }
        }
    }));
    if result.is_err() {
        zero(wo, pdf, coherent);
    }
}

/// # Safety
/// wi and wo hold 3n floats, pdf n; lambda_nm NULL (RGB mode) or n floats;
/// `b` NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_pdf(
    b: *const StamBrdf,
    n: usize,
    wi: *const f32,
    wo: *const f32,
    lambda_nm: *const f32,
    pdf: *mut f32,
) {
    let ok = !wi.is_null() && !wo.is_null();
    batch(b, n, pdf, 1, ok, |brdf, i, o| {
        let p = brdf.pdf(
            direction(wi, i),
            direction(wo, i),
            optional_lambda(lambda_nm, i),
        );
        o[0] = to_output(p);
    });
}

/// # Safety
/// wi holds 3n floats, out n; lambda_nm NULL (RGB mode) or n floats; `b`
/// NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_coherent_probability(
    b: *const StamBrdf,
    n: usize,
    wi: *const f32,
    lambda_nm: *const f32,
    out: *mut f32,
) {
    batch(b, n, out, 1, !wi.is_null(), |brdf, i, o| {
        let p = brdf.coherent_probability(direction(wi, i), optional_lambda(lambda_nm, i));
        o[0] = to_output(p);
    });
}

/// Most wavelengths per path the vertex queries take (more are refused:
/// outputs zeroed).
pub const MAX_PATH_WAVELENGTHS: usize = 64;

/// Lane i's channels: RGB for NULL wavelengths, else its nw wavelengths
/// (converted into `buf`).
#[inline]
unsafe fn lane_channels<'a>(
    lambda_nm: *const f32,
    nw: usize,
    i: usize,
    buf: &'a mut [f64; MAX_PATH_WAVELENGTHS],
) -> Channels<'a> {
    if lambda_nm.is_null() {
        return Channels::Rgb;
    }
    let src = std::slice::from_raw_parts(lambda_nm.add(i * nw), nw);
    for (b, &l) in buf.iter_mut().zip(src) {
        *b = l as f64;
    }
    Channels::Wavelengths(&buf[..nw])
}

/// Channels per lane of the vertex queries: 3 (RGB) or nw; None when nw is
/// out of range.
fn channel_count(lambda_nm: *const f32, nw: usize) -> Option<usize> {
    if lambda_nm.is_null() {
        Some(3)
    } else {
        (1..=MAX_PATH_WAVELENGTHS).contains(&nw).then_some(nw)
    }
}

/// # Safety
/// wi, wo hold 3n floats; lambda_nm NULL (RGB) or n * nw floats; f NULL or
/// n * nc floats (nc = 3 or nw), pdf NULL or n floats; `b` NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_eval_pdf_vertex(
    b: *const StamBrdf,
    n: usize,
    wi: *const f32,
    wo: *const f32,
    lambda_nm: *const f32,
    nw: usize,
    f: *mut f32,
    pdf: *mut f32,
) {
    let null = std::ptr::null_mut();
    vertex_queries(
        b,
        n,
        wi,
        lambda_nm,
        nw,
        (wo, f, pdf),
        (std::ptr::null(), null, null, std::ptr::null_mut(), null),
    );
}

/// # Safety
/// wi, rnd and wo hold 3n floats; lambda_nm NULL (RGB) or n * nw floats;
/// pdf n floats; coherent NULL or n bytes; value NULL or n * nc floats (nc
/// = 3 or nw); `b` NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_sample_vertex(
    b: *const StamBrdf,
    n: usize,
    wi: *const f32,
    lambda_nm: *const f32,
    nw: usize,
    rnd: *const f32,
    wo: *mut f32,
    pdf: *mut f32,
    coherent: *mut u8,
    value: *mut f32,
) {
    let null = std::ptr::null_mut();
    vertex_queries(
        b,
        n,
        wi,
        lambda_nm,
        nw,
        (std::ptr::null(), null, null),
        (rnd, wo, pdf, coherent, value),
    );
}

/// # Safety
/// As stam_brdf_eval_pdf_vertex for (wo, f, pdf) and stam_brdf_sample_vertex
/// for (rnd, s_wo, s_pdf, s_coherent, s_value).
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_eval_pdf_sample_vertex(
    b: *const StamBrdf,
    n: usize,
    wi: *const f32,
    wo: *const f32,
    lambda_nm: *const f32,
    nw: usize,
    rnd: *const f32,
    f: *mut f32,
    pdf: *mut f32,
    s_wo: *mut f32,
    s_pdf: *mut f32,
    s_coherent: *mut u8,
    s_value: *mut f32,
) {
    // The sample part is required here: without rnd, zeros (vertex_queries
    // would take all-NULL sample pointers for an eval-only call).
    let b = if rnd.is_null() { std::ptr::null() } else { b };
    vertex_queries(
        b,
        n,
        wi,
        lambda_nm,
        nw,
        (wo, f, pdf),
        (rnd, s_wo, s_pdf, s_coherent, s_value),
    );
}

/// The vertex queries of n lanes, sharing each lane's strategy: an eval
/// part (wo, f, pdf: wo NULL for none, f or pdf NULL to skip) and a sample
/// part (rnd, wo, pdf, coherent, value: all NULL for none). Outputs are
/// zeroed for a NULL material or wi, nw out of range, a sample part
/// missing one of rnd, wo and pdf, or a caught panic.
#[allow(clippy::type_complexity)]
unsafe fn vertex_queries(
    b: *const StamBrdf,
    n: usize,
    wi: *const f32,
    lambda_nm: *const f32,
    nw: usize,
    (wo, f, pdf): (*const f32, *mut f32, *mut f32),
    (rnd, s_wo, s_pdf, s_coh, s_value): (*const f32, *mut f32, *mut f32, *mut u8, *mut f32),
) {
    if n == 0 {
        return;
    }
    let nc = channel_count(lambda_nm, nw);
    let eval = !wo.is_null() && (!f.is_null() || !pdf.is_null());
    // A sample part is asked for by any of its inputs or required outputs,
    // and needs all three.
    let sample = !rnd.is_null() && !s_wo.is_null() && !s_pdf.is_null();
    let sample_incomplete = !sample && (!rnd.is_null() || !s_wo.is_null() || !s_pdf.is_null());
    let zero = || {
        let fill = |p: *mut f32, len: usize| {
            if !p.is_null() {
                std::slice::from_raw_parts_mut(p, len).fill(0.0);
            }
        };
        let k = nc.unwrap_or(0);
        fill(f, n * k);
        fill(pdf, n);
        fill(s_wo, 3 * n);
        fill(s_pdf, n);
        fill(s_value, n * k);
        if !s_coh.is_null() {
            std::slice::from_raw_parts_mut(s_coh, n).fill(0);
        }
    };
    let Some(nc) = nc else {
        return zero();
    };
    if b.is_null() || wi.is_null() || (!eval && !sample) || sample_incomplete {
        return zero();
    }
    let needs_strategy = sample || !pdf.is_null();
    let brdf = &(*b).brdf;
    // The caller sees f32 directions: a sample's pdf and value are taken there.
    let round = |w: DVec3| DVec3::new(w.x as f32 as f64, w.y as f32 as f64, w.z as f32 as f64);
    let result = catch_unwind(AssertUnwindSafe(|| {
        let mut buf = [0.0; MAX_PATH_WAVELENGTHS];
        let mut values = [0.0; MAX_PATH_WAVELENGTHS];
        for i in 0..n {
            let channels = lane_channels(lambda_nm, nw, i, &mut buf);
            let wi_i = direction(wi, i);
            let strategy = needs_strategy.then(|| brdf.vertex_strategy(wi_i, channels));
            if eval {
                let wo_i = direction(wo, i);
                if !f.is_null() {
                    brdf.eval_channels(wi_i, wo_i, channels, &mut values);
                    let out = std::slice::from_raw_parts_mut(f.add(i * nc), nc);
                    for (o, &v) in out.iter_mut().zip(&values) {
                        *o = to_output(v);
                    }
                }
                if let (false, Some(strategy)) = (pdf.is_null(), &strategy) {
                    *pdf.add(i) = to_output(strategy.pdf(wo_i));
                }
            }
            if let (true, Some(strategy)) = (sample, &strategy) {
                let r = std::slice::from_raw_parts(rnd.add(3 * i), 3);
                let s = brdf.sample_with(
                    strategy,
                    wi_i,
                    channels,
                    [r[0] as f64, r[1] as f64, r[2] as f64],
                    round,
                    &mut values,
                );
                let ok = s.pdf > 0.0;
                let d = if ok { round(s.wo) } else { DVec3::ZERO };
                std::slice::from_raw_parts_mut(s_wo.add(3 * i), 3)
                    .copy_from_slice(&[d.x as f32, d.y as f32, d.z as f32]);
                *s_pdf.add(i) = to_output(s.pdf);
                if !s_coh.is_null() {
                    *s_coh.add(i) = u8::from(ok && s.coherent);
                }
                if !s_value.is_null() {
                    let out = std::slice::from_raw_parts_mut(s_value.add(i * nc), nc);
                    for (o, &v) in out.iter_mut().zip(&values) {
                        *o = if ok { to_output(v) } else { 0.0 };
                    }
                }
            }
        }
    }));
    if result.is_err() {
        zero();
    }
}

/// # Safety
/// `b` NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_flags(b: *const StamBrdf) -> u32 {
    if b.is_null() {
        return 0;
    }
    catch_unwind(AssertUnwindSafe(|| (*b).brdf.flags())).unwrap_or(0)
}

/// # Safety
/// `b` NULL or valid.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_memory_bytes(b: *const StamBrdf) -> usize {
    if b.is_null() {
        return 0;
    }
    catch_unwind(AssertUnwindSafe(|| (*b).brdf.memory_bytes())).unwrap_or(0)
}

/// # Safety
/// `b` NULL or valid; `out` NULL or valid for `capacity` floats.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_export_program(
    b: *const StamBrdf,
    kind: u32,
    out: *mut f32,
    capacity: usize,
) -> usize {
    export(b, kind, out, capacity, |brdf, code, at_built| {
        let kind = ProgramKind::from_code(code)?;
        match at_built {
            true => brdf.program_at_built(kind),
            false => brdf.program(kind),
        }
    })
}

/// # Safety
/// `b` NULL or valid; `out` NULL or valid for `capacity` floats.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_export_polarization_program(
    b: *const StamBrdf,
    out: *mut f32,
    capacity: usize,
) -> usize {
    export(b, 0, out, capacity, |brdf, _, _| {
        brdf.polarization_program()
    })
}

/// # Safety
/// `b` NULL or valid; `out` NULL or valid for `capacity` floats.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_export_mixture_program(
    b: *const StamBrdf,
    kind: u32,
    n_wavelengths: u32,
    out: *mut f32,
    capacity: usize,
) -> usize {
    use crate::material::program::MixtureKind;
    export(b, kind, out, capacity, |brdf, code, at_built| {
        let (kind, n) = (MixtureKind::from_code(code)?, n_wavelengths as usize);
        match at_built {
            true => brdf.mixture_program_at_built(kind, n),
            false => brdf.mixture_program(kind, n),
        }
    })
}

/// The program `program(material, code, at_built)` gives for `code` (with
/// STAM_PROGRAM_AT_BUILT split off) written as `write_program` does; 0 for
/// none, a NULL material or a panic.
unsafe fn export(
    b: *const StamBrdf,
    code: u32,
    out: *mut f32,
    capacity: usize,
    program: impl FnOnce(&Brdf, u32, bool) -> Option<crate::program::Program>,
) -> usize {
    if b.is_null() {
        return 0;
    }
    catch_unwind(AssertUnwindSafe(|| {
        let at_built = code & ProgramKind::AT_BUILT != 0;
        program(&(*b).brdf, code & !ProgramKind::AT_BUILT, at_built)
            .map_or(0, |p| write_program(&p, out, capacity))
    }))
    .unwrap_or(0)
}

/// The encoded program's length, the program written to `out` where it
/// fits in `capacity` floats.
unsafe fn write_program(
    program: &crate::program::Program,
    out: *mut f32,
    capacity: usize,
) -> usize {
    let encoded = program.encode();
    if !out.is_null() && capacity >= encoded.len() {
        std::ptr::copy_nonoverlapping(encoded.as_ptr(), out, encoded.len());
    }
    encoded.len()
}

/// # Safety
/// `b` NULL or valid. The string lives as long as the material.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_warnings(b: *const StamBrdf) -> *const c_char {
    if b.is_null() {
        return c"".as_ptr();
    }
    (*b).warnings.as_ptr()
}

/// # Safety
/// `b` NULL or valid. The string lives as long as the material.
#[no_mangle]
pub unsafe extern "C" fn stam_brdf_params_json(b: *const StamBrdf) -> *const c_char {
    if b.is_null() {
        return c"".as_ptr();
    }
    (*b).params_json.as_ptr()
}

#[no_mangle]
pub extern "C" fn stam_parameter_reference() -> *const c_char {
    static REFERENCE: OnceLock<CString> = OnceLock::new();
    REFERENCE
        .get_or_init(|| {
            catch_unwind(|| c_text(parameter_reference().to_string())).unwrap_or_default()
        })
        .as_ptr()
}

#[no_mangle]
pub extern "C" fn stam_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr() as *const c_char
}

/// # Safety
/// `request_json` must be NULL or a NUL-terminated string; `err` NULL or
/// writable for `err_len` bytes. The answer is freed with `stam_text_free`.
#[no_mangle]
pub unsafe extern "C" fn stam_rigorous_solve(
    request_json: *const c_char,
    err: *mut c_char,
    err_len: usize,
) -> *mut c_char {
    text_answer(request_json, "request_json", err, err_len, |text| {
        crate::rigorous::request::solve_json(text)
    })
}

/// # Safety
/// `params_json` and `name` must be NULL or NUL-terminated strings; `err`
/// NULL or writable for `err_len` bytes. The answer is freed with
/// `stam_text_free`.
#[no_mangle]
pub unsafe extern "C" fn stam_texture_plan(
    params_json: *const c_char,
    name: *const c_char,
    largest: f64,
    mean: f64,
    err: *mut c_char,
    err_len: usize,
) -> *mut c_char {
    let Some(name) = c_str(name) else {
        write_message(err, err_len, "name is NULL or not valid UTF-8");
        return std::ptr::null_mut();
    };
    text_answer(params_json, "params_json", err, err_len, |text| {
        let plan = crate::material::textures::texture_plan(text, name, largest, mean)?;
        let answer = serde_json::json!({
            "param": plan.param as u32,
            "add": plan.add,
            "range": [plan.range.0, plan.range.1],
        });
        Ok(answer.to_string())
    })
}

/// # Safety
/// `name` must be NULL or a NUL-terminated string.
#[no_mangle]
pub unsafe extern "C" fn stam_param_takes_texture(name: *const c_char) -> i32 {
    catch_unwind(|| c_str(name).is_some_and(crate::material::textures::takes_texture))
        .unwrap_or(false) as i32
}

/// `text` as UTF-8 (None: NULL or not UTF-8).
unsafe fn c_str<'a>(text: *const c_char) -> Option<&'a str> {
    if text.is_null() {
        return None;
    }
    CStr::from_ptr(text).to_str().ok()
}

/// `answer(input)` as a string to free with `stam_text_free`, or NULL with
/// the reason in `err` (the input, called `what`, NULL or not UTF-8; the
/// answer's error; a panic).
unsafe fn text_answer(
    input: *const c_char,
    what: &str,
    err: *mut c_char,
    err_len: usize,
    answer: impl FnOnce(&str) -> Result<String, crate::StamError> + std::panic::UnwindSafe,
) -> *mut c_char {
    if input.is_null() {
        write_message(err, err_len, &format!("{what} is NULL"));
        return std::ptr::null_mut();
    }
    let Some(text) = c_str(input) else {
        write_message(err, err_len, &format!("{what} is not valid UTF-8"));
        return std::ptr::null_mut();
    };
    match catch_unwind(|| answer(text)) {
        Ok(Ok(answer)) => {
            write_message(err, err_len, "");
            c_text(answer).into_raw()
        }
        Ok(Err(e)) => {
            write_message(err, err_len, &e.message);
            std::ptr::null_mut()
        }
        Err(payload) => {
            write_message(err, err_len, &panic_message(payload));
            std::ptr::null_mut()
        }
    }
}

/// # Safety
/// `text` must be NULL or a string returned by a stam function that says
/// it is freed here, freed once.
#[no_mangle]
pub unsafe extern "C" fn stam_text_free(text: *mut c_char) {
    if !text.is_null() {
        drop(CString::from_raw(text));
    }
}

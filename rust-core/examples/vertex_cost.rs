//! Cost of one path vertex as the Mitsuba plugin asks for it, through the C
//! ABI, against Cook-Torrance doing the same work, in one process.
//!
//! A path tracer's vertex (Mitsuba's `eval_pdf_sample`) is: f and pdf towards
//! the sampled light, then one BSDF sample with f (and the pdf) at the
//! sampled direction. The plugin makes them in one call
//! (stam_brdf_eval_pdf_sample_vertex; see mitsuba-plugin/diffraction.cpp);
//! this replays it for the render
//! benchmark's materials (scripts/bench_render.py) with random incident
//! directions (a render's are more coherent, so caches fare better there),
//! so that changes to the core can be measured in seconds instead of
//! renders.
//!
//! Usage: cargo run --release -p stam-core --example vertex_cost [vertices] [filter] [rgb|spectral|all] [separate]

use stam::benchmark::{cook_torrance_beckmann, SplitMix64};
use stam::ffi::*;
use std::ffi::CString;
use std::time::Instant;

const MATERIALS: [(&str, &str); 4] = [
    (
        "gaussian rough",
        r#"{"surface":"gaussian","sigma_um":0.5,"corr_um":4.0,"fresnel":"aluminium"}"#,
    ),
    (
        "gaussian smooth",
        r#"{"surface":"gaussian","sigma_um":0.05,"corr_um":2.0,"fresnel":"aluminium"}"#,
    ),
    (
        "fractal",
        r#"{"surface":"fractal","hurst":0.7,"sigma_um":0.1,"lag_um":1.0,"fresnel":"aluminium"}"#,
    ),
    ("cd", r#"{"surface":"cd","fresnel":"aluminium"}"#),
];

/// Mitsuba's spectral variants carry 4 wavelengths per path.
const PATH_WAVELENGTHS: usize = 4;

struct Vertex {
    wi: [f32; 3],
    wo_light: [f32; 3],
    rnd: [f32; 3],
    lambda_nm: [f32; PATH_WAVELENGTHS],
}

fn hemisphere(rng: &mut SplitMix64, min_cos: f64) -> [f32; 3] {
    let ct = min_cos + (1.0 - min_cos) * rng.next_f64();
    let phi = 2.0 * std::f64::consts::PI * rng.next_f64();
    let st = (1.0 - ct * ct).sqrt();
    [(st * phi.cos()) as f32, (st * phi.sin()) as f32, ct as f32]
}

fn vertices(count: usize) -> Vec<Vertex> {
    let mut rng = SplitMix64(7);
    (0..count)
        .map(|_| {
            let hero = 380.0 + 400.0 * rng.next_f64();
            // Stratified like Mitsuba's sample_wavelength: one offset, then
            // equal steps through the band.
            let lambda_nm = std::array::from_fn(|j| {
                let x = hero - 380.0 + j as f64 * 400.0 / PATH_WAVELENGTHS as f64;
                (380.0 + x % 400.0) as f32
            });
            let rnd = rng.three().map(|x| x as f32);
            Vertex {
                wi: hemisphere(&mut rng, 0.05),
                wo_light: hemisphere(&mut rng, 0.0),
                rnd,
                lambda_nm,
            }
        })
        .collect()
}

/// One vertex in RGB mode, as run_batch does it. Returns a checksum.
unsafe fn vertex_rgb(b: *const StamBrdf, v: &Vertex) -> f32 {
    let (mut f, mut pdf) = ([0f32; 3], 0f32);
    stam_brdf_eval_rgb(b, 1, v.wi.as_ptr(), v.wo_light.as_ptr(), f.as_mut_ptr());
    stam_brdf_pdf(
        b,
        1,
        v.wi.as_ptr(),
        v.wo_light.as_ptr(),
        std::ptr::null(),
        &mut pdf,
    );
    let (mut wo, mut spdf, mut coh) = ([0f32; 3], 0f32, 0u8);
    stam_brdf_sample(
        b,
        1,
        v.wi.as_ptr(),
        std::ptr::null(),
        v.rnd.as_ptr(),
        wo.as_mut_ptr(),
        &mut spdf,
        &mut coh,
    );
    let mut g = [0f32; 3];
    if coh != 0 {
        stam_brdf_coherent_rgb(b, 1, v.wi.as_ptr(), g.as_mut_ptr());
    } else {
        stam_brdf_eval_rgb(b, 1, v.wi.as_ptr(), wo.as_ptr(), g.as_mut_ptr());
    }
    f[1] + pdf + spdf + g[1]
}

/// One vertex in spectral mode (4 wavelengths), as run_batch does it.
unsafe fn vertex_spectral(b: *const StamBrdf, v: &Vertex) -> f32 {
    const M: usize = PATH_WAVELENGTHS;
    let wi4: [f32; 3 * M] = std::array::from_fn(|i| v.wi[i % 3]);
    let wl4: [f32; 3 * M] = std::array::from_fn(|i| v.wo_light[i % 3]);
    let (mut f, mut p) = ([0f32; M], [0f32; M]);
    stam_brdf_eval_spectral(
        b,
        M,
        wi4.as_ptr(),
        wl4.as_ptr(),
        v.lambda_nm.as_ptr(),
        f.as_mut_ptr(),
    );
    stam_brdf_pdf(
        b,
        M,
        wi4.as_ptr(),
        wl4.as_ptr(),
        v.lambda_nm.as_ptr(),
        p.as_mut_ptr(),
    );
    let hero = ((v.rnd[0] * M as f32) as usize).min(M - 1);
    let r0 = (v.rnd[0] * M as f32 - hero as f32).min(0.999_999_94);
    let rnd = [r0, v.rnd[1], v.rnd[2]];
    let (mut wo, mut spdf, mut coh) = ([0f32; 3], 0f32, 0u8);
    stam_brdf_sample(
        b,
        1,
        v.wi.as_ptr(),
        &v.lambda_nm[hero],
        rnd.as_ptr(),
        wo.as_mut_ptr(),
        &mut spdf,
        &mut coh,
    );
    let (mut g, mut q) = ([0f32; M], [0f32; M]);
    if coh != 0 {
        stam_brdf_coherent_spectral(b, M, wi4.as_ptr(), v.lambda_nm.as_ptr(), g.as_mut_ptr());
    } else {
        let wo4: [f32; 3 * M] = std::array::from_fn(|i| wo[i % 3]);
        stam_brdf_eval_spectral(
            b,
            M,
            wi4.as_ptr(),
            wo4.as_ptr(),
            v.lambda_nm.as_ptr(),
            g.as_mut_ptr(),
        );
        stam_brdf_pdf(
            b,
            M,
            wi4.as_ptr(),
            wo4.as_ptr(),
            v.lambda_nm.as_ptr(),
            q.as_mut_ptr(),
        );
    }
    f[0] + p[0] + spdf + g[0] + q[0]
}

/// One vertex through the vertex ABI, as the plugin calls it: f and pdf
/// towards the light and a sample with its value, in one call, for RGB (nw =
/// 0) or the path's wavelengths.
unsafe fn vertex_fused(b: *const StamBrdf, v: &Vertex, nw: usize) -> f32 {
    let lam = if nw == 0 {
        std::ptr::null()
    } else {
        v.lambda_nm.as_ptr()
    };
    let (mut f, mut pdf) = ([0f32; 4], 0f32);
    let (mut wo, mut spdf, mut coh, mut value) = ([0f32; 3], 0f32, 0u8, [0f32; 4]);
    stam_brdf_eval_pdf_sample_vertex(
        b,
        1,
        v.wi.as_ptr(),
        v.wo_light.as_ptr(),
        lam,
        nw,
        v.rnd.as_ptr(),
        f.as_mut_ptr(),
        &mut pdf,
        wo.as_mut_ptr(),
        &mut spdf,
        &mut coh,
        value.as_mut_ptr(),
    );
    f[0] + pdf + spdf + value[0]
}

/// Cook-Torrance (Beckmann, alpha 0.25, aluminium-like index) doing a
/// vertex's work: f and a Beckmann pdf at the light, a half-vector sample, f
/// at the sample; `channels` evaluations of f each (3 RGB, 4 spectral).
fn vertex_baseline(v: &Vertex, channels: usize) -> f32 {
    let d = |w: [f32; 3]| glam::DVec3::new(w[0] as f64, w[1] as f64, w[2] as f64);
    let (wi, wl) = (d(v.wi), d(v.wo_light));
    let alpha = 0.25;
    let mut acc = 0.0;
    for c in 0..channels {
        acc += cook_torrance_beckmann(wi, wl, alpha, 1.2 + 0.01 * c as f64, 7.0);
    }
    let h = (wi + wl).normalize();
    acc += (-(1.0 - h.z * h.z) / (h.z * h.z * alpha * alpha)).exp() * h.z / (4.0 * wi.dot(h));
    let sx = alpha * stam::sampling::inverse_normal(v.rnd[1] as f64);
    let sy = alpha * stam::sampling::inverse_normal(v.rnd[2] as f64);
    let m = glam::DVec3::new(-sx, -sy, 1.0).normalize();
    let wo = 2.0 * wi.dot(m) * m - wi;
    for c in 0..channels {
        acc += cook_torrance_beckmann(wi, wo, alpha, 1.2 + 0.01 * c as f64, 7.0);
    }
    acc as f32
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let count: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(200_000);
    let filter = args.get(2).cloned().unwrap_or_default();
    let mode = args.get(3).cloned().unwrap_or_default();
    let (do_rgb, do_spectral) = (mode != "spectral", mode != "rgb");
    // "separate": also the per-query calls the plugin made before the
    // vertex ABI (eval, pdf, sample, eval again; per wavelength).
    let separate = args.get(4).is_some_and(|a| a == "separate");
    let verts = vertices(count);
    let warmup = vertices(20_000);
    let time = |f: &mut dyn FnMut() -> f32| {
        // Best of 3: the machine is shared.
        let mut best = f64::INFINITY;
        let mut sink = 0.0f32;
        for _ in 0..3 {
            let t = Instant::now();
            sink += f();
            best = best.min(t.elapsed().as_secs_f64());
        }
        std::hint::black_box(sink);
        best * 1e9 / count as f64
    };
    let base_rgb = time(&mut || verts.iter().map(|v| vertex_baseline(v, 3)).sum());
    let base_spec = time(&mut || verts.iter().map(|v| vertex_baseline(v, 4)).sum());
    println!(
        "[vertex_cost] {count} vertices; Cook-Torrance vertex: {base_rgb:.0} ns (RGB), {base_spec:.0} ns (4 wavelengths)"
    );
    println!(
        "{:<18} {:>10} {:>8} {:>14} {:>8}",
        "material", "RGB ns", "ratio", "spectral ns", "ratio"
    );
    for (name, json) in MATERIALS {
        if !name.contains(filter.as_str()) {
            continue;
        }
        let text = CString::new(json).unwrap();
        let mut err = [0 as std::ffi::c_char; 256];
        let b = unsafe { stam_brdf_new(text.as_ptr(), err.as_mut_ptr(), err.len()) };
        assert!(!b.is_null(), "material {name}");
        // Build the lazily made tables (the universal ones, the material's
        // cells) before timing, as a render's first samples would.
        let mut warm = 0.0;
        for v in warmup.iter() {
            warm += unsafe { vertex_fused(b, v, 0) + vertex_fused(b, v, PATH_WAVELENGTHS) };
        }
        std::hint::black_box(warm);
        let (mut rgb, mut spec) = (f64::NAN, f64::NAN);
        if do_rgb {
            rgb = time(&mut || verts.iter().map(|v| unsafe { vertex_fused(b, v, 0) }).sum());
        }
        if do_spectral {
            spec = time(&mut || {
                verts
                    .iter()
                    .map(|v| unsafe { vertex_fused(b, v, PATH_WAVELENGTHS) })
                    .sum()
            });
        }
        if separate {
            let old_rgb = time(&mut || verts.iter().map(|v| unsafe { vertex_rgb(b, v) }).sum());
            let old_spec =
                time(&mut || verts.iter().map(|v| unsafe { vertex_spectral(b, v) }).sum());
            println!("{name:<18} separate calls: {old_rgb:.0} ns RGB, {old_spec:.0} ns spectral");
        }
        println!(
            "{name:<18} {rgb:>10.0} {:>7.1}x {spec:>14.0} {:>7.1}x",
            rgb / base_rgb,
            spec / base_spec
        );
        unsafe { stam_brdf_free(b) };
    }
}

//! cargo fuzz run params_json
//!
//! The input is split at the first 0xFF byte: before it, the parameter text
//! given to stam_brdf_new (cut at a NUL as a C caller would); after it, the
//! floats (4 bytes each) given to every ABI entry point when the material is
//! accepted. Invariants: no panic or crash (the ABI catches panics and would
//! report "internal error"), every refusal has a non-empty message, every
//! output is finite and >= 0, sampled directions are unit vectors when their
//! pdf is > 0. The material's programs (stam_brdf_export_program) are
//! decoded with stam::program::decode and run on the same floats with the
//! core's f32 executor (the contract of tools/stress/src/programs.rs, which
//! the proptest twin applies in full).
#![no_main]

use libfuzzer_sys::fuzz_target;
use stam::ffi::*;
use std::ffi::{c_char, CString};

fuzz_target!(|data: &[u8]| {
    let split = data.iter().position(|&b| b == 0xFF).unwrap_or(data.len());
    let (text, rest) = data.split_at(split);
    let text = &text[..text.iter().position(|&b| b == 0).unwrap_or(text.len())];
    let c = CString::new(text).unwrap();
    let floats: Vec<f32> = rest
        .get(1..)
        .unwrap_or(&[])
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let mut err = vec![0 as c_char; 256];
    let p = unsafe { stam_brdf_new(c.as_ptr(), err.as_mut_ptr(), err.len()) };
    // A host's own keys change no verdict; the fuzzed text as a host key list
    // is refused or read, never a crash.
    let mut host_err = vec![0 as c_char; 256];
    let q = unsafe { stam_brdf_new_for_host(c.as_ptr(), c"[\"twist\"]".as_ptr(), host_err.as_mut_ptr(), host_err.len()) };
    assert!(p.is_null() == q.is_null(), "stam_brdf_new_for_host decided otherwise");
    unsafe { stam_brdf_free(q) };
    unsafe { stam_brdf_free(stam_brdf_new_for_host(c"{}".as_ptr(), c.as_ptr(), host_err.as_mut_ptr(), host_err.len())) };
    if p.is_null() {
        let len = err.iter().position(|&c| c == 0).expect("message is NUL-terminated");
        assert!(len > 0, "refusal without a message");
        let msg: Vec<u8> = err[..len].iter().map(|&c| c as u8).collect();
        let msg = String::from_utf8_lossy(&msg);
        assert!(!msg.contains("internal error"), "caught panic: {msg}");
        return;
    }
    let n = 4;
    let at = |i: usize| if floats.is_empty() { 0.5 } else { floats[i % floats.len()] };
    let wi: Vec<f32> = (0..3 * n).map(at).collect();
    let wo: Vec<f32> = (0..3 * n).map(|i| at(i + 3 * n)).collect();
    let lam: Vec<f32> = (0..n).map(|i| at(i + 6 * n)).collect();
    let rnd: Vec<f32> = (0..3 * n).map(|i| at(i + 7 * n)).collect();
    let mut out = vec![0f32; 3 * n];
    let mut pdf = vec![0f32; n];
    let mut coh = vec![0u8; n];
    let ok = |v: &[f32]| v.iter().all(|x| x.is_finite() && *x >= 0.0);
    unsafe {
        stam_brdf_eval_spectral(p, n, wi.as_ptr(), wo.as_ptr(), lam.as_ptr(), out.as_mut_ptr());
        assert!(ok(&out[..n]));
        stam_brdf_eval_rgb(p, n, wi.as_ptr(), wo.as_ptr(), out.as_mut_ptr());
        assert!(ok(&out));
        stam_brdf_coherent_spectral(p, n, wi.as_ptr(), lam.as_ptr(), out.as_mut_ptr());
        assert!(ok(&out[..n]));
        stam_brdf_coherent_rgb(p, n, wi.as_ptr(), out.as_mut_ptr());
        assert!(ok(&out));
        let has = stam_brdf_polarization(p, n, wi.as_ptr(), wo.as_ptr(), lam.as_ptr(), out.as_mut_ptr());
        for v in out.chunks_exact(3) {
            let q: f32 = v.iter().map(|x| x * x).sum();
            assert!(q.is_finite() && if has == 1 { (q - 1.0).abs() < 1e-4 } else { q == 0.0 });
        }
        assert_eq!(stam_brdf_export_polarization_program(p, std::ptr::null_mut(), 0) > 0, has == 1);
        let mut mm = vec![0f32; 22 * n];
        let has_m = stam_brdf_mueller(p, n, wo.as_ptr(), wi.as_ptr(), lam.as_ptr(), mm.as_mut_ptr());
        for m in mm.chunks_exact(22) {
            assert!(m.iter().all(|x| x.is_finite()));
            assert!(if has_m == 1 { (m[0] - 1.0).abs() < 1e-5 } else { m.iter().all(|&x| x == 0.0) });
        }
        for lam_ptr in [lam.as_ptr(), std::ptr::null()] {
            stam_brdf_sample(p, n, wi.as_ptr(), lam_ptr, rnd.as_ptr(), out.as_mut_ptr(), pdf.as_mut_ptr(), coh.as_mut_ptr());
            assert!(ok(&pdf));
            for i in 0..n {
                if pdf[i] > 0.0 {
                    let l: f64 = out[3 * i..3 * i + 3].iter().map(|x| (*x as f64).powi(2)).sum::<f64>().sqrt();
                    assert!((l - 1.0).abs() < 1e-5, "sampled wo not unit");
                }
            }
            stam_brdf_pdf(p, n, wi.as_ptr(), wo.as_ptr(), lam_ptr, pdf.as_mut_ptr());
            assert!(ok(&pdf));
            stam_brdf_coherent_probability(p, n, wi.as_ptr(), lam_ptr, pdf.as_mut_ptr());
            assert!(ok(&pdf) && pdf.iter().all(|&x| x <= 1.0));
        }
        // Path-vertex calls: the combined one, then the separate eval and
        // sample calls, which must give the same outputs bit for bit.
        for (lam_ptr, nw) in [(lam.as_ptr(), n), (std::ptr::null(), 0)] {
            let (mut f, mut s_val, mut s_wo) = (vec![0f32; 3 * n], vec![0f32; 3 * n], vec![0f32; 3]);
            let (mut p1, mut s_pdf, mut s_coh) = (0f32, 0f32, 0u8);
            stam_brdf_eval_pdf_sample_vertex(p, 1, wi.as_ptr(), wo.as_ptr(), lam_ptr, nw, rnd.as_ptr(), f.as_mut_ptr(), &mut p1, s_wo.as_mut_ptr(), &mut s_pdf, &mut s_coh, s_val.as_mut_ptr());
            assert!(ok(&f) && ok(&[p1, s_pdf]) && ok(&s_val));
            let (mut f2, mut p2) = (vec![0f32; 3 * n], 0f32);
            stam_brdf_eval_pdf_vertex(p, 1, wi.as_ptr(), wo.as_ptr(), lam_ptr, nw, f2.as_mut_ptr(), &mut p2);
            let (mut v_wo, mut v_val, mut v_pdf, mut v_coh) = (vec![0f32; 3], vec![0f32; 3 * n], 0f32, 0u8);
            stam_brdf_sample_vertex(p, 1, wi.as_ptr(), lam_ptr, nw, rnd.as_ptr(), v_wo.as_mut_ptr(), &mut v_pdf, &mut v_coh, v_val.as_mut_ptr());
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert!(bits(&f2) == bits(&f) && p2.to_bits() == p1.to_bits(), "eval_pdf_vertex differs from the combined call");
            assert!(
                bits(&v_wo) == bits(&s_wo) && v_pdf.to_bits() == s_pdf.to_bits() && v_coh == s_coh && bits(&v_val) == bits(&s_val),
                "sample_vertex differs from the combined call"
            );
        }
        // Programs: sized with NULL, nothing written into a small buffer,
        // format 4 with the kind's inputs and outputs (stam.h), decodable;
        // run on the lanes (a sample's uniforms also folded into [0, 1)):
        // eval, pdf and coherent outputs finite and >= 0 (a probability
        // <= 1); a sample's flag 0 or 1 and, from uniforms in [0, 1], a
        // finite direction, unit where it is above the horizon.
        for kind in 0..8u32 {
            let len = stam_brdf_export_program(p, kind, std::ptr::null_mut(), 0);
            let mut small = [0.0f32; 4];
            assert!(stam_brdf_export_program(p, kind, small.as_mut_ptr(), small.len()) == len);
            assert!(len == 0 || len > small.len() && small == [0.0; 4], "program written into a small buffer");
            if len == 0 {
                continue;
            }
            let mut array = vec![0.0f32; len];
            assert!(stam_brdf_export_program(p, kind, array.as_mut_ptr(), len) == len);
            assert!(array[0] == stam::program::FORMAT as f32 && array[5] == len as f32, "program header");
            let prog = stam::program::decode(&array).expect("an exported program decodes");
            let (mut n_in, mut n_out) = (0u32, 0u32);
            assert!(stam_program_io(kind, 0, &mut n_in, &mut n_out) == 1, "a kind without inputs and outputs");
            assert!((prog.n_inputs, prog.outputs.len()) == (n_in, n_out as usize), "program inputs / outputs");
            // The ABI's executor refuses what is not a program; an unknown
            // parameter id has no name.
            {
                let mut err = [0 as c_char; 64];
                let null = std::ptr::null::<f32>();
                let (null64, none) = (std::ptr::null::<f64>(), std::ptr::null_mut());
                let mut out = [0.0f32; 4];
                let mut out64 = [0.0f64; 4];
                assert!(stam_program_run(null, 0, null, 1, null, 0, out.as_mut_ptr(), None, None, none, err.as_mut_ptr(), err.len()) == 0);
                assert!(stam_program_run_f64(array.as_ptr(), array.len() - 1, null64, 0, null64, 0, out64.as_mut_ptr(), err.as_mut_ptr(), err.len()) == 0);
                assert!(*stam_param_name(stam::program::PARAM_COUNT) == 0);
            }
            let sampling = kind / 2 == 2;
            for i in 0..n {
                for fold in [false, true].into_iter().take(if sampling { 2 } else { 1 }) {
                    let fold_u = |x: f32| if !fold { x } else if x.is_finite() { x.abs().fract() } else { 0.5 };
                    let u: Vec<f32> = rnd[3 * i..3 * i + 3].iter().map(|&x| fold_u(x)).collect();
                    let mut inputs = wi[3 * i..3 * i + 3].to_vec();
                    match kind / 2 {
                        0 | 1 => inputs.extend_from_slice(&wo[3 * i..3 * i + 3]),
                        2 => inputs.extend_from_slice(&u),
                        _ => {}
                    }
                    if kind % 2 == 1 {
                        inputs.push(lam[i]);
                    }
                    let out = prog.run::<f32>(&inputs);
                    // The ABI's executor gives the lane-by-lane one's bits.
                    let mut abi = vec![0.0f32; out.len()];
                    let mut err = [0 as c_char; 64];
                    let ran = stam_program_run(array.as_ptr(), array.len(), inputs.as_ptr(), 1, std::ptr::null(), 0, abi.as_mut_ptr(), None, None, std::ptr::null_mut(), err.as_mut_ptr(), err.len());
                    assert!(ran == 1 && abi.iter().zip(&out).all(|(a, b)| a.to_bits() == b.to_bits()), "stam_program_run differs");
                    if sampling {
                        assert!(out[3] == 0.0 || out[3] == 1.0, "a sample's coherent flag {}", out[3]);
                        if u.iter().all(|x| (0.0..=1.0).contains(x)) {
                            assert!(out[..3].iter().all(|x| x.is_finite()), "sampled direction not finite");
                            if out[2] > 0.0 {
                                let l: f64 = out[..3].iter().map(|x| (*x as f64).powi(2)).sum::<f64>().sqrt();
                                assert!((l - 1.0).abs() <= 1e-4, "sampled direction not unit");
                            }
                        }
                    } else {
                        assert!(ok(&out), "program {kind} output not finite and >= 0: {out:?}");
                        assert!(kind < 6 || out[out.len() - 1] <= 1.0, "coherent probability > 1");
                    }
                }
            }
        }
        // The mixture programs over 4 wavelengths decode, with 4 wavelength
        // inputs; none for a count out of range.
        for kind in 0..3u32 {
            let len = stam_brdf_export_mixture_program(p, kind, 4, std::ptr::null_mut(), 0);
            let mut array = vec![0.0f32; len];
            assert!(stam_brdf_export_mixture_program(p, kind, 4, array.as_mut_ptr(), len) == len);
            if len > 0 {
                let prog = stam::program::decode(&array).expect("a mixture program decodes");
                let (mut n_in, mut n_out) = (0u32, 0u32);
                assert!(stam_program_io(kind, 4, &mut n_in, &mut n_out) == 1);
                assert!((prog.n_inputs, prog.outputs.len()) == (n_in, n_out as usize), "mixture inputs / outputs");
            }
            assert!(stam_brdf_export_mixture_program(p, kind, 17, std::ptr::null_mut(), 0) == 0);
        }
        assert!(stam_brdf_export_program(p, 8, std::ptr::null_mut(), 0) == 0);
        assert!(stam_brdf_export_program(p, u32::MAX, std::ptr::null_mut(), 0) == 0);
        let _ = stam_brdf_flags(p);
        let _ = stam_brdf_memory_bytes(p);
        let warnings = stam_brdf_warnings(p);
        assert!(!warnings.is_null() && std::ffi::CStr::from_ptr(warnings).to_str().is_ok());
        let version = stam_version();
        assert!(!version.is_null() && !std::ffi::CStr::from_ptr(version).to_bytes().is_empty());
        // The resolved parameters read back as the same material's
        let resolved = stam_brdf_params_json(p);
        assert!(!resolved.is_null());
        let resolved = std::ffi::CStr::from_ptr(resolved).to_str().expect("params_json UTF-8");
        let given = std::str::from_utf8(text).expect("an accepted text is UTF-8");
        assert!(
            stam::params::MaterialParams::from_json(resolved).ok()
                == stam::params::MaterialParams::from_json(given).ok(),
            "params_json {resolved} does not read back as {given}"
        );
        let reference = stam_parameter_reference();
        assert!(!reference.is_null() && std::ffi::CStr::from_ptr(reference).to_str().is_ok());
        // A rigorous solve of a rect grating made of the floats: refused with
        // a message, or finite efficiencies >= 0 (NaN and Inf become null).
        let request = serde_json::json!({
            "period_um": at(0), "profile": "rect", "height_um": at(1), "width_um": at(2),
            "fresnel": {"eta": at(3), "k": at(4)}, "lambda_nm": at(5), "theta_deg": at(6),
            "phi_deg": at(7), "orders": (at(8).abs() as usize).min(6),
        });
        let request = CString::new(request.to_string()).unwrap();
        let answer = stam_rigorous_solve(request.as_ptr(), err.as_mut_ptr(), err.len());
        if answer.is_null() {
            assert!(err[0] != 0, "a rigorous request refused without a message");
        } else {
            let text = std::ffi::CStr::from_ptr(answer).to_str().expect("UTF-8 answer");
            let value: serde_json::Value = serde_json::from_str(text).expect("JSON answer");
            for order in value["reflected"].as_array().expect("reflected orders") {
                for pol in 0..2 {
                    let e = order["efficiency"][pol].as_f64().unwrap_or(f64::NAN);
                    assert!(e.is_finite() && e >= 0.0, "rigorous efficiency {e}");
                }
            }
            stam_text_free(answer);
        }
        // A texture's plan on the material (its key left out) at two of the
        // floats: a JSON plan, or a refusal with a message.
        if let Ok(serde_json::Value::Object(mut obj)) = serde_json::from_str(resolved) {
            for name in [c"sigma_um", c"height_um", c"corr_um"] {
                obj.remove(name.to_str().unwrap());
                let params = CString::new(serde_json::Value::Object(obj.clone()).to_string()).unwrap();
                let plan = stam_texture_plan(params.as_ptr(), name.as_ptr(), at(9) as f64, at(10) as f64, err.as_mut_ptr(), err.len());
                if plan.is_null() {
                    assert!(err[0] != 0, "a texture plan refused without a message");
                } else {
                    assert!(stam_param_takes_texture(name.as_ptr()) == 1, "a plan for a parameter that takes no texture");
                    let text = std::ffi::CStr::from_ptr(plan).to_str().expect("UTF-8 plan");
                    let value: serde_json::Value = serde_json::from_str(text).expect("JSON plan");
                    assert!(value["range"][0].as_f64() <= value["range"][1].as_f64(), "texture range {text}");
                    stam_text_free(plan);
                }
            }
        }
        stam_brdf_free(p);
    }
});

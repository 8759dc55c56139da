//! The C ABI of the programs' CPU executor (`stam_program_run`, stam.h):
//! a renderer's or a script's check of an exported program without a
//! renderer. Thin: checks pointers and the array, catches panics; the
//! executor is `Program::run_batch`.

use super::write_message;
use crate::program::{decode_checked, BatchHooks, Lane, Op, ParamId, Program, FORMAT};
use std::ffi::{c_char, c_void};
use std::panic::{catch_unwind, AssertUnwindSafe};

/// `stam_program_elementary` of stam.h.
pub type StamProgramElementary = Option<
    unsafe extern "C" fn(
        user: *mut c_void,
        op: u32,
        lanes: usize,
        a: *const f32,
        b: *const f32,
        out: *mut f32,
    ) -> i32,
>;

/// `stam_program_region` of stam.h.
pub type StamProgramRegion = Option<
    unsafe extern "C" fn(
        user: *mut c_void,
        position: usize,
        first_lane: usize,
        lanes: usize,
        runs: *const u8,
    ),
>;

/// The caller's functions as the executor's hooks.
struct CallerHooks {
    elementary: StamProgramElementary,
    region: StamProgramRegion,
    user: *mut c_void,
}

impl BatchHooks<f32> for CallerHooks {
    fn takes_elementary(&self) -> bool {
        self.elementary.is_some()
    }

    fn elementary(&mut self, op: Op, a: &[f32], b: &[f32], out: &mut [f32]) -> bool {
        let Some(f) = self.elementary else {
            return false;
        };
        let b = if b.is_empty() {
            std::ptr::null()
        } else {
            b.as_ptr()
        };
        // SAFETY: the caller's function, given arrays of `a.len()` lanes.
        unsafe {
            f(
                self.user,
                op as u32,
                a.len(),
                a.as_ptr(),
                b,
                out.as_mut_ptr(),
            ) != 0
        }
    }

    fn region(&mut self, position: usize, first_lane: usize, runs: &[bool]) {
        if let Some(f) = self.region {
            let bytes: Vec<u8> = runs.iter().map(|&r| r as u8).collect();
            // SAFETY: the caller's function, given `runs.len()` bytes.
            unsafe { f(self.user, position, first_lane, runs.len(), bytes.as_ptr()) }
        }
    }
}

/// The program of an array, with its parameters' values by slot (the
/// caller's, or the stored ones), or the error's text.
unsafe fn prepare<T: Lane>(
    program: *const f32,
    program_len: usize,
    param_values: *const T,
    n_param_values: usize,
) -> Result<(Program, Vec<T>), String> {
    if program.is_null() {
        return Err("program is NULL".into());
    }
    let array = std::slice::from_raw_parts(program, program_len);
    let p = decode_checked(array).map_err(|why| {
        format!("not a program array of format {FORMAT} (stam_brdf_export_program's): {why}")
    })?;
    let params = if param_values.is_null() {
        p.params.iter().map(|&(_, v)| T::from_f32(v)).collect()
    } else if n_param_values != p.params.len() {
        let names: Vec<&str> = p.params.iter().map(|&(id, _)| id.name()).collect();
        return Err(format!(
            "n_param_values is {n_param_values}, but the program reads {} parameters ({})",
            p.params.len(),
            names.join(", ")
        ));
    } else {
        std::slice::from_raw_parts(param_values, n_param_values).to_vec()
    };
    Ok((p, params))
}

/// The caller's lanes (stam.h): inputs, their count, the parameters'
/// values and their count, outputs.
struct LaneArrays<T>(*const T, usize, *const T, usize, *mut T);

/// Checks the array and the lanes' pointers, runs the program (f32 or
/// f64) and writes the outcome into `err`: 1, or 0 for an error.
unsafe fn run_caught<T: Lane>(
    program: *const f32,
    program_len: usize,
    arrays: LaneArrays<T>,
    hooks: &mut dyn BatchHooks<T>,
    err: *mut c_char,
    err_len: usize,
) -> i32 {
    let result = catch_unwind(AssertUnwindSafe(|| {
        run(program, program_len, arrays, hooks)
    }));
    outcome(result, err, err_len)
}

unsafe fn run<T: Lane>(
    program: *const f32,
    program_len: usize,
    arrays: LaneArrays<T>,
    hooks: &mut dyn BatchHooks<T>,
) -> Result<(), String> {
    let LaneArrays(inputs, lanes, param_values, n_param_values, outputs) = arrays;
    let (p, params) = prepare(program, program_len, param_values, n_param_values)?;
    let (n_in, n_out) = (p.n_inputs as usize, p.outputs.len());
    let Some(n_in_total) = lanes.checked_mul(n_in) else {
        return Err("lanes times inputs overflows".into());
    };
    let Some(n_out_total) = lanes.checked_mul(n_out) else {
        return Err("lanes times outputs overflows".into());
    };
    if lanes == 0 {
        return Ok(());
    }
    if n_in_total > 0 && inputs.is_null() {
        return Err(format!(
            "inputs is NULL (the program takes {n_in} per lane)"
        ));
    }
    if n_out_total > 0 && outputs.is_null() {
        return Err(format!(
            "outputs is NULL (the program gives {n_out} per lane)"
        ));
    }
    let x = if n_in_total == 0 {
        &[][..]
    } else {
        std::slice::from_raw_parts(inputs, n_in_total)
    };
    let out = if n_out_total == 0 {
        &mut [][..]
    } else {
        std::slice::from_raw_parts_mut(outputs, n_out_total)
    };
    p.run_batch(x, lanes, &params, hooks, out);
    Ok(())
}

/// Writes the outcome into `err`: 1 for success, 0 for an error.
unsafe fn outcome(
    result: std::thread::Result<Result<(), String>>,
    err: *mut c_char,
    err_len: usize,
) -> i32 {
    match result {
        Ok(Ok(())) => {
            write_message(err, err_len, "");
            1
        }
        Ok(Err(message)) => {
            write_message(err, err_len, &message);
            0
        }
        Err(payload) => {
            write_message(err, err_len, &super::panic_message(payload));
            0
        }
    }
}

/// # Safety
/// `program` NULL or valid for `program_len` floats; `inputs` NULL or valid
/// for `lanes` x n_inputs floats, `outputs` for `lanes` x n_outputs;
/// `param_values` NULL or valid for `n_param_values`; `err` NULL or
/// writable for `err_len` bytes; the callbacks, where given, callable with
/// `user`.
#[no_mangle]
pub unsafe extern "C" fn stam_program_run(
    program: *const f32,
    program_len: usize,
    inputs: *const f32,
    lanes: usize,
    param_values: *const f32,
    n_param_values: usize,
    outputs: *mut f32,
    elementary: StamProgramElementary,
    on_region: StamProgramRegion,
    user: *mut c_void,
    err: *mut c_char,
    err_len: usize,
) -> i32 {
    let mut hooks = CallerHooks {
        elementary,
        region: on_region,
        user,
    };
    let arrays = LaneArrays(inputs, lanes, param_values, n_param_values, outputs);
    run_caught(program, program_len, arrays, &mut hooks, err, err_len)
}

/// # Safety
/// As `stam_program_run`, with f64 inputs, parameter values and outputs.
#[no_mangle]
pub unsafe extern "C" fn stam_program_run_f64(
    program: *const f32,
    program_len: usize,
    inputs: *const f64,
    lanes: usize,
    param_values: *const f64,
    n_param_values: usize,
    outputs: *mut f64,
    err: *mut c_char,
    err_len: usize,
) -> i32 {
    let arrays = LaneArrays(inputs, lanes, param_values, n_param_values, outputs);
    let mut hooks = crate::program::NoHooks;
    run_caught(program, program_len, arrays, &mut hooks, err, err_len)
}

/// Writes the inputs and outputs of program kind `kind` (n_wavelengths 0)
/// or of mixture kind `kind` over `n_wavelengths`; 0 for neither.
///
/// # Safety
/// `inputs` and `outputs` NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn stam_program_io(
    kind: u32,
    n_wavelengths: u32,
    inputs: *mut u32,
    outputs: *mut u32,
) -> i32 {
    use crate::material::program::{MixtureKind, ProgramKind, MAX_MIXTURE_WAVELENGTHS};
    let n = n_wavelengths as usize;
    let io = match n {
        0 => ProgramKind::from_code(kind).map(ProgramKind::io),
        _ if n <= MAX_MIXTURE_WAVELENGTHS => MixtureKind::from_code(kind).map(|k| k.io(n)),
        _ => None,
    };
    let Some((n_in, n_out)) = io else {
        return 0;
    };
    if !inputs.is_null() {
        *inputs = n_in as u32;
    }
    if !outputs.is_null() {
        *outputs = n_out as u32;
    }
    1
}

/// The name of parameter id `id` (STAM_PARAM_*), "" for none.
#[no_mangle]
pub extern "C" fn stam_param_name(id: u32) -> *const c_char {
    match ParamId::from_code(id) {
        Some(p) => p.c_name().as_ptr(),
        None => c"".as_ptr(),
    }
}

//! A program as one f32 array (the ABI's `stam_brdf_export_program`):
//!
//! | values | meaning |
//! |---|---|
//! | 0..HEADER_LEN | FORMAT, inputs, outputs, instructions, tables, total length, parameters, 0 |
//! | outputs | the output registers |
//! | 2 per table | offset (from the array's start) and length |
//! | 2 per parameter | its id (`ParamId`, STAM_PARAM_*) and the value the program was built with |
//! | 4 per instruction | op code, a, b, c (Const: a is the value itself; Param: a is the slot; If: a is the mask; EndIf: a is its If) |
//! | the tables' values | |
//!
//! Integers are stored as floats (exact below 2^24; `decode` checks).
//! Parameter k of the section is slot k: `Param` with a = k reads its value
//! (the same for every lane), which a renderer may replace (differentiate,
//! texture) without rebuilding the program.

use super::builder::{arity, operands};
use super::{Instr, Op, ParamId, Program};

/// Version of the layout and of the operation set.
pub const FORMAT: u32 = 4;
/// Values before the outputs.
pub const HEADER_LEN: usize = 8;

impl Program {
    /// The program as one f32 array.
    pub fn encode(&self) -> Vec<f32> {
        let n_out = self.outputs.len();
        let n_tab = self.tables.len();
        let n_code = self.code.len();
        let n_par = self.params.len();
        let dir = HEADER_LEN + n_out;
        let code_at = dir + 2 * n_tab + 2 * n_par;
        let data_at = code_at + 4 * n_code;
        let total = data_at + self.table_len();
        let mut v = Vec::with_capacity(total);
        v.extend([
            FORMAT as f32,
            self.n_inputs as f32,
            n_out as f32,
            n_code as f32,
            n_tab as f32,
            total as f32,
            n_par as f32,
            0.0,
        ]);
        v.extend(self.outputs.iter().map(|&o| o as f32));
        let mut offset = data_at;
        for t in &self.tables {
            v.extend([offset as f32, t.len() as f32]);
            offset += t.len();
        }
        for &(id, value) in &self.params {
            v.extend([id as u32 as f32, value]);
        }
        for ins in &self.code {
            let a = match ins.op {
                Op::Const => f32::from_bits(ins.a),
                _ => ins.a as f32,
            };
            v.extend([ins.op as u32 as f32, a, ins.b as f32, ins.c as f32]);
        }
        for t in &self.tables {
            v.extend_from_slice(t);
        }
        debug_assert_eq!(v.len(), total);
        v
    }
}

/// The program of an array made by `encode`, checked: every operand a
/// register defined before its use and of the right kind (float or mask;
/// a region's markers are read by nothing), regions nested, each `EndIf`
/// naming the innermost open `If`, no Input, Const or Param inside one,
/// every table inside the array, every parameter a known id (each at most
/// once) with a finite value, every `Param` reading one of them. None for
/// anything else (`decode_checked` says why).
pub fn decode(v: &[f32]) -> Option<Program> {
    decode_checked(v).ok()
}

/// `decode`, with the first check an array fails.
pub fn decode_checked(v: &[f32]) -> Result<Program, String> {
    let int = |x: f32, what: &dyn Fn() -> String| -> Result<u32, String> {
        ((0.0..16_777_216.0).contains(&x) && x.fract() == 0.0)
            .then_some(x as u32)
            .ok_or_else(|| format!("{} is {x}, not an integer below 2^24", what()))
    };
    let fail = |m: String| -> Result<Program, String> { Err(m) };
    if v.len() < HEADER_LEN {
        return fail(format!("{} values, shorter than the header", v.len()));
    }
    let format = int(v[0], &|| "the format".into())?;
    if format != FORMAT {
        return fail(format!("format {format}, not {FORMAT}"));
    }
    let n_inputs = int(v[1], &|| "the input count".into())?;
    let n_out = int(v[2], &|| "the output count".into())? as usize;
    let n_code = int(v[3], &|| "the instruction count".into())? as usize;
    let n_tab = int(v[4], &|| "the table count".into())? as usize;
    let total = int(v[5], &|| "the length".into())? as usize;
    let n_par = int(v[6], &|| "the parameter count".into())? as usize;
    if total != v.len() {
        return fail(format!(
            "the header says {total} values, the array has {}",
            v.len()
        ));
    }
    if v[7] != 0.0 {
        return fail(format!("header value 7 is {}, not 0", v[7]));
    }
    let dir = HEADER_LEN + n_out;
    let par_at = dir + 2 * n_tab;
    let code_at = par_at + 2 * n_par;
    if code_at + 4 * n_code > total {
        return fail(format!(
            "{n_code} instructions, {n_tab} tables and {n_par} parameters do not fit in {total} values"
        ));
    }
    let mut tables = Vec::with_capacity(n_tab);
    for t in 0..n_tab {
        let off = int(v[dir + 2 * t], &|| format!("table {t}'s offset"))? as usize;
        let len = int(v[dir + 2 * t + 1], &|| format!("table {t}'s length"))? as usize;
        if off < code_at + 4 * n_code || off + len > total {
            return fail(format!(
                "table {t} at {off}..{} lies outside the tables' section",
                off + len
            ));
        }
        tables.push(v[off..off + len].to_vec());
    }
    let mut params: Vec<(ParamId, f32)> = Vec::with_capacity(n_par);
    for k in 0..n_par {
        let code = int(v[par_at + 2 * k], &|| format!("parameter {k}'s id"))?;
        let id = ParamId::from_code(code)
            .ok_or_else(|| format!("parameter {k} has the unknown id {code}"))?;
        let value = v[par_at + 2 * k + 1];
        if !value.is_finite() {
            return fail(format!("parameter {k} ({}) is {value}", id.name()));
        }
        if params.iter().any(|&(p, _)| p == id) {
            return fail(format!("parameter {k} ({}) is listed twice", id.name()));
        }
        params.push((id, value));
    }
    let mut code = Vec::with_capacity(n_code);
    // Per register: Some(whether a mask), None for a region's marker.
    let mut is_mask: Vec<Option<bool>> = Vec::with_capacity(n_code);
    let mut open: Vec<u32> = Vec::new();
    for i in 0..n_code {
        let w = &v[code_at + 4 * i..code_at + 4 * i + 4];
        let op_code = int(w[0], &|| format!("instruction {i}'s op code"))?;
        let op = Op::from_code(op_code)
            .ok_or_else(|| format!("instruction {i} has the unknown op code {op_code}"))?;
        let a = if op == Op::Const {
            w[1].to_bits()
        } else {
            int(w[1], &|| format!("instruction {i}'s operand a"))?
        };
        let ins = Instr {
            op,
            a,
            b: int(w[2], &|| format!("instruction {i}'s operand b"))?,
            c: int(w[3], &|| format!("instruction {i}'s operand c"))?,
        };
        let bad = |what: String| format!("instruction {i} ({op:?}) {what}");
        match op {
            Op::Input if a >= n_inputs => {
                return fail(bad(format!("reads input {a} of {n_inputs}")))
            }
            Op::Gather if a as usize >= n_tab => {
                return fail(bad(format!("reads table {a} of {n_tab}")))
            }
            Op::Param if a as usize >= n_par => {
                return fail(bad(format!("reads parameter slot {a} of {n_par}")))
            }
            Op::Input | Op::Const | Op::Param if !open.is_empty() => {
                return fail(bad("lies inside a region".into()))
            }
            Op::If => open.push(i as u32),
            Op::EndIf if open.pop() != Some(a) => {
                return fail(bad(format!(
                    "ends the region of register {a}, which is not the innermost open one"
                )))
            }
            _ => {}
        }
        // Operand kinds: masks where the operation takes masks.
        let wants_mask = |k: usize| match op {
            Op::And | Op::Or | Op::Not | Op::If => true,
            Op::Select => k == 0,
            _ => false,
        };
        for (k, r) in operands(&ins).into_iter().enumerate() {
            if r as usize >= i {
                return fail(bad(format!(
                    "reads register {r}, which is not defined before it"
                )));
            }
            if is_mask[r as usize] != Some(wants_mask(k)) {
                let kind = |m: Option<bool>| match m {
                    Some(true) => "a mask",
                    Some(false) => "a float",
                    None => "a region's marker",
                };
                return fail(bad(format!(
                    "reads register {r}, {}, where it takes {}",
                    kind(is_mask[r as usize]),
                    kind(Some(wants_mask(k)))
                )));
            }
        }
        let _ = arity(op);
        is_mask.push((!op.is_marker()).then_some(op.gives_mask()));
        code.push(ins);
    }
    if let Some(r) = open.last() {
        return fail(format!("the region of register {r} is not closed"));
    }
    let mut outputs = Vec::with_capacity(n_out);
    for k in 0..n_out {
        let r = int(v[HEADER_LEN + k], &|| format!("output {k}'s register"))?;
        if r as usize >= n_code || is_mask[r as usize] != Some(false) {
            return fail(format!(
                "output {k} is register {r}, not a float register of the code"
            ));
        }
        outputs.push(r);
    }
    Ok(Program {
        n_inputs,
        code,
        outputs,
        tables,
        params,
    })
}

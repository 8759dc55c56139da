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
/// anything else.
pub fn decode(v: &[f32]) -> Option<Program> {
    let int = |x: f32| -> Option<u32> {
        ((0.0..16_777_216.0).contains(&x) && x.fract() == 0.0).then_some(x as u32)
    };
    if v.len() < HEADER_LEN || int(v[0])? != FORMAT {
        return None;
    }
    let n_inputs = int(v[1])?;
    let n_out = int(v[2])? as usize;
    let n_code = int(v[3])? as usize;
    let n_tab = int(v[4])? as usize;
    let total = int(v[5])? as usize;
    let n_par = int(v[6])? as usize;
    if total != v.len() || v[7] != 0.0 {
        return None;
    }
    let dir = HEADER_LEN + n_out;
    let par_at = dir + 2 * n_tab;
    let code_at = par_at + 2 * n_par;
    if code_at + 4 * n_code > total {
        return None;
    }
    let mut tables = Vec::with_capacity(n_tab);
    for t in 0..n_tab {
        let off = int(v[dir + 2 * t])? as usize;
        let len = int(v[dir + 2 * t + 1])? as usize;
        if off < code_at + 4 * n_code || off + len > total {
            return None;
        }
        tables.push(v[off..off + len].to_vec());
    }
    let mut params: Vec<(ParamId, f32)> = Vec::with_capacity(n_par);
    for k in 0..n_par {
        let id = ParamId::from_code(int(v[par_at + 2 * k])?)?;
        let value = v[par_at + 2 * k + 1];
        if !value.is_finite() || params.iter().any(|&(p, _)| p == id) {
            return None;
        }
        params.push((id, value));
    }
    let mut code = Vec::with_capacity(n_code);
    // Per register: Some(whether a mask), None for a region's marker.
    let mut is_mask: Vec<Option<bool>> = Vec::with_capacity(n_code);
    let mut open: Vec<u32> = Vec::new();
    for i in 0..n_code {
        let w = &v[code_at + 4 * i..code_at + 4 * i + 4];
        let op = Op::from_code(int(w[0])?)?;
        let a = if op == Op::Const {
            w[1].to_bits()
        } else {
            int(w[1])?
        };
        let ins = Instr {
            op,
            a,
            b: int(w[2])?,
            c: int(w[3])?,
        };
        match op {
            Op::Input if a >= n_inputs => return None,
            Op::Gather if a as usize >= n_tab => return None,
            Op::Param if a as usize >= n_par => return None,
            Op::Input | Op::Const | Op::Param if !open.is_empty() => return None,
            Op::If => open.push(i as u32),
            Op::EndIf if open.pop() != Some(a) => return None,
            _ => {}
        }
        // Operand kinds: masks where the operation takes masks.
        let wants_mask = |k: usize| match op {
            Op::And | Op::Or | Op::Not | Op::If => true,
            Op::Select => k == 0,
            _ => false,
        };
        for (k, r) in operands(&ins).into_iter().enumerate() {
            if r as usize >= i || is_mask[r as usize] != Some(wants_mask(k)) {
                return None;
            }
        }
        let _ = arity(op);
        is_mask.push((!op.is_marker()).then_some(op.gives_mask()));
        code.push(ins);
    }
    if !open.is_empty() {
        return None;
    }
    let mut outputs = Vec::with_capacity(n_out);
    for k in 0..n_out {
        let r = int(v[HEADER_LEN + k])?;
        if r as usize >= n_code || is_mask[r as usize] != Some(false) {
            return None;
        }
        outputs.push(r);
    }
    Some(Program {
        n_inputs,
        code,
        outputs,
        tables,
        params,
    })
}

//! Programs of array operations: how the core tells a tracing renderer
//! (Dr.Jit's symbolic loops and calls, `dr.freeze`, CUDA) what to compute,
//! so that the physics stays here (docs/jit.md).
//!
//! A program is straight-line SSA code over 32-bit float lanes: register i
//! is the result of instruction i. Each instruction is one array operation
//! a renderer has (arithmetic, exp/log/sqrt/trigonometry, compare and
//! select, a gather from a table); bounded loops are unrolled when the
//! program is built. A model writes its program with [`Builder`], whose
//! values overload the arithmetic operators, so that the code reads as the
//! formula. This module knows no model: models and the material build
//! their programs on it, the ABI exports them ([`Program::encode`]), the
//! plugin executes them with Dr.Jit, and [`Program::run`] executes them on
//! the CPU, so that tests compare a program against the native path.

mod builder;
mod encode;
mod interpret;
pub mod lookup;

pub use builder::{Builder, Mask, Table, Value};
pub use encode::{decode, FORMAT, HEADER_LEN};

/// Operation codes (the plugin's executor mirrors them: program.h).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Op {
    /// Input a (float).
    Input = 0,
    /// The constant a (float).
    Const = 1,
    Add = 2,
    Sub = 3,
    Mul = 4,
    Div = 5,
    Min = 6,
    Max = 7,
    /// a * b + c.
    Fma = 8,
    Neg = 9,
    Abs = 10,
    Sqrt = 11,
    Exp = 12,
    /// Natural logarithm.
    Log = 13,
    Sin = 14,
    Cos = 15,
    /// atan2(a, b) = the angle of (b, a).
    Atan2 = 16,
    Floor = 17,
    /// Masks from floats.
    Lt = 18,
    Le = 19,
    Gt = 20,
    Ge = 21,
    Eq = 22,
    /// a is finite (not NaN, not infinite): a mask.
    Finite = 23,
    /// Masks from masks.
    And = 24,
    Or = 25,
    Not = 26,
    /// Mask a ? float b : float c.
    Select = 27,
    /// Table a at the index held by float b: truncated towards zero after
    /// clamping into [0, len - 1], NaN to 0 (so that a gather can never
    /// leave its table, whatever the program computes).
    Gather = 28,
}

/// The number of operations (codes 0 .. OP_COUNT - 1).
pub const OP_COUNT: u32 = 29;

impl Op {
    pub fn from_code(code: u32) -> Option<Op> {
        use Op::*;
        const ALL: [Op; OP_COUNT as usize] = [
            Input, Const, Add, Sub, Mul, Div, Min, Max, Fma, Neg, Abs, Sqrt, Exp, Log, Sin, Cos,
            Atan2, Floor, Lt, Le, Gt, Ge, Eq, Finite, And, Or, Not, Select, Gather,
        ];
        ALL.get(code as usize).copied()
    }

    /// Whether the result is a mask (else a float).
    pub fn gives_mask(self) -> bool {
        use Op::*;
        matches!(self, Lt | Le | Gt | Ge | Eq | Finite | And | Or | Not)
    }
}

/// One instruction: the operation and its operands (register indices,
/// except Input: the input's index; Const: the value's bits; Gather: the
/// table's index, then the index register).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instr {
    pub op: Op,
    pub a: u32,
    pub b: u32,
    pub c: u32,
}

/// A finished program.
#[derive(Clone, Debug, Default)]
pub struct Program {
    pub n_inputs: u32,
    pub code: Vec<Instr>,
    /// Registers returned, in order (floats).
    pub outputs: Vec<u32>,
    pub tables: Vec<Vec<f32>>,
}

impl Program {
    /// Values held in tables.
    pub fn table_len(&self) -> usize {
        self.tables.iter().map(Vec::len).sum()
    }
}

//! Programs of array operations: how the core tells a tracing renderer
//! (Dr.Jit's symbolic loops and calls, `dr.freeze`, CUDA) what to compute,
//! so that the physics stays here (docs/jit.md).
//!
//! A program is straight-line SSA code over 32-bit float lanes: register i
//! is the result of instruction i. Each instruction is one array operation
//! a renderer has (arithmetic, exp/log/sqrt/trigonometry, compare and
//! select, a gather from a table); bounded loops are unrolled when the
//! program is built. A region (`Op::If` .. `Op::EndIf`, built with
//! `Builder::region`) runs only on the lanes that need it, so that a
//! renderer skips the SIMD packets or warps none of whose lanes does. A
//! model writes its program with [`Builder`], whose values overload the
//! arithmetic operators, so that the code reads as the formula. This
//! module knows no model: models and the material build their programs on
//! it, the ABI exports them ([`Program::encode`]), the
//! plugin executes them with Dr.Jit, and [`Program::run`] executes them on
//! the CPU, so that tests compare a program against the native path.

mod batch;
mod builder;
mod encode;
mod interpret;
pub mod lookup;
mod real;
pub mod special;
#[cfg(test)]
mod tests;

pub use batch::{BatchHooks, NoHooks, BATCH_LANES};
pub use builder::{Builder, Mask, Table, Value};
pub use encode::{decode, decode_checked, FORMAT, HEADER_LEN};
pub use interpret::Lane;
pub use real::Real;

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
    /// The program's parameter in slot a of its parameter list (the same
    /// value for every lane; `Program::params`, the array's parameter
    /// section): what a renderer differentiates or textures.
    Param = 29,
    /// The start of a region that runs only on the lanes where mask a
    /// holds (a renderer branches: Dr.Jit's `if_stmt`, which skips a SIMD
    /// packet or GPU warp none of whose lanes needs it). Regions nest; each
    /// ends at the `EndIf` naming it. Every register defined inside a
    /// region reads 0 (false for a mask) on the other lanes. Input, Const
    /// and Param never lie inside a region (`Builder::finish` hoists them).
    /// Its register holds no value and is read only by its `EndIf`.
    If = 30,
    /// The end of the region whose `If` is register a (no value).
    EndIf = 31,
}

/// How far (relative) a renderer may move a parameter a program reads
/// (`Op::Param`) before it rebuilds the material: within this the programs
/// stay within 1e-4 of the changed material's (1.1e-3 for the Gaussian RGB
/// table of isotropic metals), which `testing::params::check` asserts at
/// plus and minus this change. `STAM_PROGRAM_MAX_DRIFT` of stam.h.
pub const MAX_PARAM_DRIFT: f64 = 0.02;

/// The number of operations (codes 0 .. OP_COUNT - 1).
pub const OP_COUNT: u32 = 32;

impl Op {
    pub fn from_code(code: u32) -> Option<Op> {
        use Op::*;
        const ALL: [Op; OP_COUNT as usize] = [
            Input, Const, Add, Sub, Mul, Div, Min, Max, Fma, Neg, Abs, Sqrt, Exp, Log, Sin, Cos,
            Atan2, Floor, Lt, Le, Gt, Ge, Eq, Finite, And, Or, Not, Select, Gather, Param, If,
            EndIf,
        ];
        ALL.get(code as usize).copied()
    }

    /// Whether the result is a mask (else a float).
    pub fn gives_mask(self) -> bool {
        use Op::*;
        matches!(self, Lt | Le | Gt | Ge | Eq | Finite | And | Or | Not)
    }

    /// Whether it marks a region (its register holds no value).
    pub fn is_marker(self) -> bool {
        matches!(self, Op::If | Op::EndIf)
    }
}

/// A material parameter a program can read through `Op::Param` (so that a
/// renderer can differentiate or texture it): stable numeric ids, the
/// array's parameter section names parameters by them (mirrored by
/// `STAM_PARAM_*` in stam.h). New ids are appended, never renumbered.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ParamId {
    /// RMS height sigma (um).
    SigmaUm = 0,
    /// Correlation length of an isotropic surface (um): both axes'.
    CorrUm = 1,
    /// Correlation lengths along x and y of an anisotropic surface (um).
    CorrXUm = 2,
    CorrYUm = 3,
    LagUm = 4,
    PeriodUm = 5,
    HeightUm = 6,
    WidthUm = 7,
    CoherenceUm = 8,
    Twist = 9,
    /// The constant Fresnel reflectance.
    Fresnel = 10,
    /// The complex index n = eta + i k.
    Eta = 11,
    K = 12,
}

/// The number of parameter ids (codes 0 .. PARAM_COUNT - 1).
pub const PARAM_COUNT: u32 = 13;

impl ParamId {
    pub const ALL: [ParamId; PARAM_COUNT as usize] = {
        use ParamId::*;
        [
            SigmaUm,
            CorrUm,
            CorrXUm,
            CorrYUm,
            LagUm,
            PeriodUm,
            HeightUm,
            WidthUm,
            CoherenceUm,
            Twist,
            Fresnel,
            Eta,
            K,
        ]
    };

    pub fn from_code(code: u32) -> Option<ParamId> {
        ParamId::ALL.get(code as usize).copied()
    }

    /// The material parameter's name (the JSON key).
    pub fn name(self) -> &'static str {
        self.c_name().to_str().unwrap_or_default()
    }

    /// `name` as a C string (`stam_param_name`).
    pub fn c_name(self) -> &'static std::ffi::CStr {
        use ParamId::*;
        match self {
            SigmaUm => c"sigma_um",
            CorrUm => c"corr_um",
            CorrXUm => c"corr_x_um",
            CorrYUm => c"corr_y_um",
            LagUm => c"lag_um",
            PeriodUm => c"period_um",
            HeightUm => c"height_um",
            WidthUm => c"width_um",
            CoherenceUm => c"coherence_um",
            Twist => c"twist",
            Fresnel => c"fresnel",
            Eta => c"eta",
            K => c"k",
        }
    }
}

/// One instruction: the operation and its operands (register indices,
/// except Input: the input's index; Const: the value's bits; Gather: the
/// table's index, then the index register; Param: the parameter's slot).
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
    /// The parameters `Op::Param` reads, by slot: their ids and the values
    /// the program was built with.
    pub params: Vec<(ParamId, f32)>,
}

impl Program {
    /// Values held in tables.
    pub fn table_len(&self) -> usize {
        self.tables.iter().map(Vec::len).sum()
    }

    /// Whether instruction `i` reads a constant from a table at a constant
    /// index (`Builder::built`): a renderer loads it once, not per lane.
    pub fn is_table_constant(&self, i: usize) -> bool {
        let ins = self.code[i];
        ins.op == Op::Gather && self.code[ins.b as usize].op == Op::Const
    }

    /// The gathers that read per lane (not the built constants' loads):
    /// what a gather costs on a CPU.
    pub fn lane_gathers(&self) -> usize {
        (0..self.code.len())
            .filter(|&i| self.code[i].op == Op::Gather && !self.is_table_constant(i))
            .count()
    }

    /// The instructions that compute per lane: not the inputs, constants,
    /// parameters and built constants.
    pub fn lane_ops(&self) -> usize {
        (0..self.code.len())
            .filter(|&i| {
                !matches!(self.code[i].op, Op::Input | Op::Const | Op::Param)
                    && !self.is_table_constant(i)
            })
            .count()
    }

    /// The slot of parameter `id`, if the program reads it.
    pub fn param_slot(&self, id: ParamId) -> Option<usize> {
        self.params.iter().position(|&(p, _)| p == id)
    }
}

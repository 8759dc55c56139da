//! The CPU executor: runs a program one lane at a time, in f32 (as the
//! renderer's kernels do) or f64 (to tell the program's logic from f32
//! rounding in tests).

use super::{Instr, Op, Program};

/// The arithmetic an executor needs from its float type.
pub trait Lane: Copy + PartialOrd {
    fn from_f32(x: f32) -> Self;
    fn to_f64(self) -> f64;
    fn zero() -> Self {
        Self::from_f32(0.0)
    }
    fn one() -> Self {
        Self::from_f32(1.0)
    }
    fn add(self, o: Self) -> Self;
    fn sub(self, o: Self) -> Self;
    fn mul(self, o: Self) -> Self;
    fn div(self, o: Self) -> Self;
    fn fma(self, m: Self, a: Self) -> Self;
    fn un(self, op: Op) -> Self;
    fn atan2(self, x: Self) -> Self;
    fn min(self, o: Self) -> Self;
    fn max(self, o: Self) -> Self;
    fn is_finite(self) -> bool;
    fn is_nan(self) -> bool;
}

macro_rules! lane {
    ($t:ty) => {
        impl Lane for $t {
            fn from_f32(x: f32) -> Self {
                x as $t
            }
            fn to_f64(self) -> f64 {
                self as f64
            }
            fn add(self, o: Self) -> Self {
                self + o
            }
            fn sub(self, o: Self) -> Self {
                self - o
            }
            fn mul(self, o: Self) -> Self {
                self * o
            }
            fn div(self, o: Self) -> Self {
                self / o
            }
            fn fma(self, m: Self, a: Self) -> Self {
                self.mul_add(m, a)
            }
            fn un(self, op: Op) -> Self {
                match op {
                    Op::Neg => -self,
                    Op::Abs => self.abs(),
                    Op::Sqrt => self.sqrt(),
                    Op::Exp => self.exp(),
                    Op::Log => self.ln(),
                    Op::Sin => self.sin(),
                    Op::Cos => self.cos(),
                    Op::Floor => self.floor(),
                    _ => unreachable!("not a unary operation"),
                }
            }
            fn atan2(self, x: Self) -> Self {
                self.atan2(x)
            }
            // With a NaN operand the result is unspecified (programs test
            // `finite` where it matters); here the other operand.
            fn min(self, o: Self) -> Self {
                <$t>::min(self, o)
            }
            fn max(self, o: Self) -> Self {
                <$t>::max(self, o)
            }
            fn is_finite(self) -> bool {
                self.is_finite()
            }
            fn is_nan(self) -> bool {
                self.is_nan()
            }
        }
    };
}
lane!(f32);
lane!(f64);

impl Program {
    /// The outputs for one lane of inputs (`inputs.len()` = n_inputs),
    /// into `out` (n outputs) with `regs` as scratch (grown as needed),
    /// with the parameters' stored values.
    pub fn run_into<T: Lane>(&self, inputs: &[T], regs: &mut Vec<T>, out: &mut [T]) {
        let params: Vec<T> = self.params.iter().map(|&(_, v)| T::from_f32(v)).collect();
        self.run_with_params_into(inputs, &params, regs, out);
    }

    /// `run_into` with the parameters' values `params` (by slot,
    /// `params.len()` = the program's parameters) in place of the stored
    /// ones.
    pub fn run_with_params_into<T: Lane>(
        &self,
        inputs: &[T],
        params: &[T],
        regs: &mut Vec<T>,
        out: &mut [T],
    ) {
        assert_eq!(params.len(), self.params.len(), "parameter values");
        regs.clear();
        regs.reserve(self.code.len());
        let code = &self.code;
        let mut i = 0;
        while i < code.len() {
            let ins = &code[i];
            // A region this lane skips: its If, everything up to its EndIf
            // (which names the If) and the EndIf are 0, without running
            // them (a grating's programs skip most of their order regions
            // on most lanes); with no EndIf, the rest of the program.
            if ins.op == Op::If && !(regs[ins.a as usize] > T::zero()) {
                let end = self.region_end(i);
                regs.resize(end, T::zero());
                i = end;
                continue;
            }
            i += 1;
            let v = self.apply(ins, |k| inputs[k as usize], params, |k| regs[k as usize]);
            regs.push(v);
        }
        for (o, &r) in out.iter_mut().zip(&self.outputs) {
            *o = regs[r as usize];
        }
    }

    /// Where the region whose `If` is instruction `begin` ends: just past
    /// its `EndIf`, or the program's end where it has none. A lane (or a
    /// batch of lanes) that does not run the region resumes there.
    pub(super) fn region_end(&self, begin: usize) -> usize {
        self.code[begin + 1..]
            .iter()
            .position(|x| x.op == Op::EndIf && x.a == begin as u32)
            .map_or(self.code.len(), |k| begin + 1 + k + 1)
    }

    /// One instruction's value on one lane: what every schedule of the
    /// executor (`run_with_params_into` lane by lane, `columns.rs` over
    /// lanes) computes, so that an operation's meaning is written once.
    /// `input` and `reg` read the lane's inputs and registers; a region's
    /// markers are 0.
    #[inline(always)]
    pub(super) fn apply<T: Lane>(
        &self,
        ins: &Instr,
        input: impl Fn(u32) -> T,
        params: &[T],
        r: impl Fn(u32) -> T,
    ) -> T {
        let flag = |m: bool| if m { T::one() } else { T::zero() };
        match ins.op {
            Op::Input => input(ins.a),
            Op::Const => T::from_f32(f32::from_bits(ins.a)),
            Op::Param => params[ins.a as usize],
            Op::Add => r(ins.a).add(r(ins.b)),
            Op::Sub => r(ins.a).sub(r(ins.b)),
            Op::Mul => r(ins.a).mul(r(ins.b)),
            Op::Div => r(ins.a).div(r(ins.b)),
            Op::Min => r(ins.a).min(r(ins.b)),
            Op::Max => r(ins.a).max(r(ins.b)),
            Op::Fma => r(ins.a).fma(r(ins.b), r(ins.c)),
            op @ (Op::Neg
            | Op::Abs
            | Op::Sqrt
            | Op::Exp
            | Op::Log
            | Op::Sin
            | Op::Cos
            | Op::Floor) => r(ins.a).un(op),
            Op::Atan2 => r(ins.a).atan2(r(ins.b)),
            Op::Lt => flag(r(ins.a) < r(ins.b)),
            Op::Le => flag(r(ins.a) <= r(ins.b)),
            Op::Gt => flag(r(ins.a) > r(ins.b)),
            Op::Ge => flag(r(ins.a) >= r(ins.b)),
            Op::Eq => flag(r(ins.a) == r(ins.b)),
            Op::Finite => flag(r(ins.a).is_finite()),
            Op::And => flag(r(ins.a) > T::zero() && r(ins.b) > T::zero()),
            Op::Or => flag(r(ins.a) > T::zero() || r(ins.b) > T::zero()),
            Op::Not => flag(!(r(ins.a) > T::zero())),
            Op::Select => {
                if r(ins.a) > T::zero() {
                    r(ins.b)
                } else {
                    r(ins.c)
                }
            }
            Op::Gather => {
                let t = &self.tables[ins.a as usize];
                let x = r(ins.b).to_f64();
                let i = if x.is_nan() {
                    0
                } else {
                    x.clamp(0.0, (t.len().max(1) - 1) as f64) as usize
                };
                T::from_f32(t.get(i).copied().unwrap_or(0.0))
            }
            // A region's markers hold no value: 0 as a register
            Op::If | Op::EndIf => T::zero(),
        }
    }

    /// The outputs for one lane of inputs.
    pub fn run<T: Lane>(&self, inputs: &[T]) -> Vec<T> {
        let mut regs = Vec::new();
        let mut out = vec![T::zero(); self.outputs.len()];
        self.run_into(inputs, &mut regs, &mut out);
        out
    }

    /// The outputs for one lane of inputs with the parameters' values
    /// `params` (by slot) in place of the stored ones.
    pub fn run_with_params<T: Lane>(&self, inputs: &[T], params: &[T]) -> Vec<T> {
        let mut regs = Vec::new();
        let mut out = vec![T::zero(); self.outputs.len()];
        self.run_with_params_into(inputs, params, &mut regs, &mut out);
        out
    }
}

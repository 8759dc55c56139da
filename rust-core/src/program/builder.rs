//! Writing a program as formulas: [`Value`] and [`Mask`] are handles to
//! registers of a [`Builder`] and overload the arithmetic operators.

use super::{Instr, Op, ParamId, Program};
use std::cell::RefCell;
use std::collections::HashMap;
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

#[derive(Default)]
struct State {
    code: Vec<Instr>,
    consts: HashMap<u32, u32>,
    /// The table of the built constants (`Builder::built`).
    built_table: Option<u32>,
    tables: Vec<Vec<f32>>,
    n_inputs: u32,
    /// Parameters by slot, and the register of each.
    params: Vec<(ParamId, f32, u32)>,
    /// Per register: the `If` of the innermost region it was defined in
    /// (OUTSIDE: none; Input, Const and Param are always outside, since
    /// `finish` hoists them).
    scope: Vec<u32>,
    /// The regions open now, innermost last (their `If` registers).
    open: Vec<u32>,
}

/// The scope of a register defined outside every region.
const OUTSIDE: u32 = u32::MAX;

/// Collects the instructions of one program.
#[derive(Default)]
pub struct Builder {
    state: RefCell<State>,
    /// The renderer promises that every parameter the program reads has the
    /// value it is built with (no texture, no gradient): what only follows
    /// a change of parameter may be left out.
    at_built: bool,
    /// The parameters the renderer differentiates: where a program can
    /// follow a parameter more cheaply than smoothly (C1), it reads these
    /// smoothly.
    gradients: Vec<ParamId>,
}

/// A float register.
#[derive(Clone, Copy)]
pub struct Value<'a> {
    b: &'a Builder,
    id: u32,
}

/// A mask register.
#[derive(Clone, Copy)]
pub struct Mask<'a> {
    b: &'a Builder,
    id: u32,
}

/// A table of the program, with its length.
#[derive(Clone, Copy, Debug)]
pub struct Table {
    id: u32,
    len: usize,
}

impl Table {
    pub fn len(&self) -> usize {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

impl Builder {
    pub fn new() -> Builder {
        Builder::default()
    }

    /// A builder for a program that the renderer runs only with the
    /// parameters' built values (`at_built`).
    pub fn at_built_values() -> Builder {
        Builder {
            at_built: true,
            ..Builder::default()
        }
    }

    /// Whether the program will only see its parameters' built values.
    pub fn at_built(&self) -> bool {
        self.at_built
    }

    /// The builder for a renderer that differentiates `ids`.
    pub fn differentiating(mut self, ids: &[ParamId]) -> Builder {
        self.gradients = ids.to_vec();
        self
    }

    /// Whether the renderer differentiates parameter `id` (never in a
    /// program for the built values).
    pub fn differentiated(&self, id: ParamId) -> bool {
        !self.at_built && self.gradients.contains(&id)
    }

    fn push(&self, op: Op, a: u32, b: u32, c: u32) -> u32 {
        let mut s = self.state.borrow_mut();
        let ins = Instr { op, a, b, c };
        // A register defined in a region that has closed is 0 on the lanes
        // the region skipped: only what the region returns may be read.
        if op != Op::EndIf {
            for r in operands(&ins) {
                let scope = s.scope[r as usize];
                assert!(
                    scope == OUTSIDE || s.open.contains(&scope),
                    "register {r} read outside its region"
                );
            }
        }
        let scope = match op {
            Op::Input | Op::Const | Op::Param => OUTSIDE,
            _ => s.open.last().copied().unwrap_or(OUTSIDE),
        };
        s.code.push(ins);
        s.scope.push(scope);
        (s.code.len() - 1) as u32
    }

    /// `body`'s values where `mask` holds and 0 elsewhere; `body` runs only
    /// on the lanes where it holds (`Op::If`), so that a renderer skips
    /// the packets where it holds nowhere. A value `body` computes may be
    /// read after the region only through what it returns.
    pub fn region<'a, const N: usize>(
        &'a self,
        mask: Mask<'a>,
        body: impl FnOnce() -> [Value<'a>; N],
    ) -> [Value<'a>; N] {
        let begin = self.push(Op::If, mask.id, 0, 0);
        self.state.borrow_mut().open.push(begin);
        let zero = self.c(0.0);
        let out = body().map(|v| {
            // Defined outside: a copy inside, so that it reads 0 elsewhere.
            let inside = {
                let s = self.state.borrow();
                let scope = s.scope[v.id as usize];
                scope != OUTSIDE && !s.open[..s.open.len() - 1].contains(&scope)
            };
            if inside {
                v
            } else {
                v + zero
            }
        });
        let enclosing = {
            let mut s = self.state.borrow_mut();
            assert_eq!(s.open.pop(), Some(begin), "regions closed out of order");
            s.open.last().copied().unwrap_or(OUTSIDE)
        };
        self.push(Op::EndIf, begin, 0, 0);
        let mut s = self.state.borrow_mut();
        for v in &out {
            s.scope[v.id as usize] = enclosing;
        }
        out
    }

    fn value(&self, id: u32) -> Value<'_> {
        Value { b: self, id }
    }

    /// The next input (inputs are numbered in the order of these calls).
    pub fn input(&self) -> Value<'_> {
        let i = {
            let mut s = self.state.borrow_mut();
            s.n_inputs += 1;
            s.n_inputs - 1
        };
        self.value(self.push(Op::Input, i, 0, 0))
    }

    /// A constant (rounded to f32; equal constants share a register).
    pub fn c(&self, x: f64) -> Value<'_> {
        let bits = (x as f32).to_bits();
        if let Some(&id) = self.state.borrow().consts.get(&bits) {
            return self.value(id);
        }
        let id = self.push(Op::Const, bits, 0, 0);
        self.state.borrow_mut().consts.insert(bits, id);
        self.value(id)
    }

    /// A constant derived from the material's parameters (`1 / period`,
    /// a count's scale, ...), rounded to f32. A renderer reads it from the
    /// program's tables rather than from the code: a material rebuilt for
    /// slightly different parameters then has the same code (the same
    /// compiled kernels, docs/jit.md "Parameters") as long as its shape
    /// does not change. Read outside every region (its `Op::Gather` at a
    /// constant index is hoisted with the constants). Equal values do not
    /// share a slot: which values coincide may change with the parameters,
    /// and the code would with it.
    pub fn built(&self, x: f64) -> Value<'_> {
        let (table, slot) = {
            let mut s = self.state.borrow_mut();
            let t = match s.built_table {
                Some(t) => t,
                None => {
                    s.tables.push(Vec::new());
                    let t = (s.tables.len() - 1) as u32;
                    s.built_table = Some(t);
                    t
                }
            };
            let values = &mut s.tables[t as usize];
            values.push(x as f32);
            (t, values.len() - 1)
        };
        let index = self.c(slot as f64);
        let id = self.push(Op::Gather, table, index.id, 0);
        self.state.borrow_mut().scope[id as usize] = OUTSIDE;
        self.value(id)
    }

    /// The material parameter `id`, whose value is `value` (rounded to
    /// f32) for the material the program is built for: an `Op::Param`
    /// register (one per id), so that a renderer can change the value
    /// without rebuilding the program (differentiate it, texture it).
    pub fn param(&self, id: ParamId, value: f64) -> Value<'_> {
        let value = value as f32;
        if let Some(&(_, v, reg)) = self.state.borrow().params.iter().find(|p| p.0 == id) {
            debug_assert!(
                v.to_bits() == value.to_bits(),
                "parameter {id:?} given as {v} and {value}"
            );
            return self.value(reg);
        }
        let slot = self.state.borrow().params.len() as u32;
        let reg = self.push(Op::Param, slot, 0, 0);
        self.state.borrow_mut().params.push((id, value, reg));
        self.value(reg)
    }

    /// A table the program gathers from.
    pub fn table(&self, values: Vec<f32>) -> Table {
        let mut s = self.state.borrow_mut();
        let len = values.len();
        s.tables.push(values);
        Table {
            id: (s.tables.len() - 1) as u32,
            len,
        }
    }

    /// table[index] (index clamped into the table, truncated; NaN to 0).
    pub fn gather<'a>(&'a self, table: Table, index: Value<'a>) -> Value<'a> {
        self.value(self.push(Op::Gather, table.id, index.id, 0))
    }

    /// The mask that is true everywhere.
    pub fn always(&self) -> Mask<'_> {
        let one = self.c(1.0);
        one.eq(one)
    }

    /// The program returning `outputs`, without the instructions and tables
    /// they do not need (the builder is empty afterwards).
    pub fn finish(&self, outputs: &[Value]) -> Program {
        let s = self.state.take();
        assert!(s.open.is_empty(), "a region left open");
        let n = s.code.len();
        // Each region's end, by its If.
        let mut end = vec![0usize; n];
        for (i, ins) in s.code.iter().enumerate() {
            if ins.op == Op::EndIf {
                end[ins.a as usize] = i;
            }
        }
        let mut live = vec![false; n];
        for o in outputs {
            live[o.id as usize] = true;
        }
        // Backwards: what the live instructions read; a region is kept
        // (with its mask) where anything inside it is live. Repeated until
        // nothing changes, since a kept region's mask lies before it.
        // Inputs, constants, parameters and built constants (gathers from
        // their table, at constant indices) come first, outside every region.
        let hoisted = |i: usize| {
            let ins = s.code[i];
            matches!(ins.op, Op::Input | Op::Const | Op::Param)
                || (ins.op == Op::Gather && Some(ins.a) == s.built_table)
        };
        loop {
            let mut changed = false;
            for i in (0..n).rev() {
                let ins = s.code[i];
                let inside_live = || (i + 1..end[i]).any(|k| live[k] && !hoisted(k));
                if ins.op == Op::If && !live[i] && inside_live() {
                    live[i] = true;
                    live[end[i]] = true;
                    changed = true;
                }
                if !live[i] || ins.op == Op::EndIf {
                    continue;
                }
                for r in operands(&ins) {
                    changed |= !live[r as usize];
                    live[r as usize] = true;
                }
            }
            if !changed {
                break;
            }
        }
        // Renumber the live instructions and the tables they use: inputs,
        // constants, parameters and built constants first (none inside a
        // region), then the rest in order.
        let mut new_id = vec![u32::MAX; n];
        let mut table_id = vec![u32::MAX; s.tables.len()];
        let mut tables = Vec::new();
        let mut params = Vec::new();
        let mut code = Vec::new();
        let mut inputs_seen = 0;
        let mut tables_in = s.tables.into_iter().map(Some).collect::<Vec<_>>();
        let order = (0..n)
            .filter(|&i| hoisted(i))
            .chain((0..n).filter(|&i| !hoisted(i)));
        for i in order {
            let ins = &s.code[i];
            if ins.op == Op::Input {
                inputs_seen = inputs_seen.max(ins.a + 1);
            }
            if !live[i] {
                continue;
            }
            let map = |r: u32| new_id[r as usize];
            let mut out = *ins;
            match ins.op {
                Op::Input | Op::Const => {}
                Op::Param => {
                    let (id, value, _) = s.params[ins.a as usize];
                    out.a = params.len() as u32;
                    params.push((id, value));
                }
                Op::Gather => {
                    let t = ins.a as usize;
                    if table_id[t] == u32::MAX {
                        table_id[t] = tables.len() as u32;
                        tables.push(tables_in[t].take().unwrap_or_default());
                    }
                    out.a = table_id[t];
                    out.b = map(ins.b);
                }
                Op::EndIf => out.a = map(ins.a),
                _ => {
                    let k = arity(ins.op);
                    if k >= 1 {
                        out.a = map(ins.a);
                    }
                    if k >= 2 {
                        out.b = map(ins.b);
                    }
                    if k >= 3 {
                        out.c = map(ins.c);
                    }
                }
            }
            new_id[i] = code.len() as u32;
            code.push(out);
        }
        Program {
            n_inputs: s.n_inputs.max(inputs_seen),
            code,
            outputs: outputs.iter().map(|o| new_id[o.id as usize]).collect(),
            tables,
            params,
        }
    }
}

/// Number of register operands of an arithmetic operation.
pub(super) fn arity(op: Op) -> usize {
    use Op::*;
    match op {
        Input | Const | Param => 0,
        Neg | Abs | Sqrt | Exp | Log | Sin | Cos | Floor | Finite | Not => 1,
        // If reads its mask; EndIf names its If (not a read: `operands`).
        If | EndIf => 1,
        Add | Sub | Mul | Div | Min | Max | Atan2 | Lt | Le | Gt | Ge | Eq | And | Or => 2,
        Gather => 1,
        Fma | Select => 3,
    }
}

/// The registers an instruction reads.
pub(super) fn operands(ins: &Instr) -> Vec<u32> {
    match ins.op {
        Op::Gather => vec![ins.b],
        Op::EndIf => vec![],
        op => [ins.a, ins.b, ins.c][..arity(op)].to_vec(),
    }
}

/// Something that becomes a float register: a register or a constant.
pub trait IntoValue<'a> {
    fn into_value(self, b: &'a Builder) -> Value<'a>;
}
impl<'a> IntoValue<'a> for Value<'a> {
    fn into_value(self, _: &'a Builder) -> Value<'a> {
        self
    }
}
impl<'a> IntoValue<'a> for f64 {
    fn into_value(self, b: &'a Builder) -> Value<'a> {
        b.c(self)
    }
}

impl<'a> Value<'a> {
    pub fn builder(&self) -> &'a Builder {
        self.b
    }
    fn un(self, op: Op) -> Value<'a> {
        self.b.value(self.b.push(op, self.id, 0, 0))
    }
    fn bin(self, op: Op, other: impl IntoValue<'a>) -> Value<'a> {
        let o = other.into_value(self.b);
        self.b.value(self.b.push(op, self.id, o.id, 0))
    }
    fn cmp(self, op: Op, other: impl IntoValue<'a>) -> Mask<'a> {
        let o = other.into_value(self.b);
        Mask {
            b: self.b,
            id: self.b.push(op, self.id, o.id, 0),
        }
    }
    pub fn sqrt(self) -> Value<'a> {
        self.un(Op::Sqrt)
    }
    pub fn exp(self) -> Value<'a> {
        self.un(Op::Exp)
    }
    pub fn ln(self) -> Value<'a> {
        self.un(Op::Log)
    }
    pub fn sin(self) -> Value<'a> {
        self.un(Op::Sin)
    }
    pub fn cos(self) -> Value<'a> {
        self.un(Op::Cos)
    }
    pub fn abs(self) -> Value<'a> {
        self.un(Op::Abs)
    }
    pub fn floor(self) -> Value<'a> {
        self.un(Op::Floor)
    }
    pub fn sq(self) -> Value<'a> {
        self * self
    }
    /// atan2(self, x): the angle of (x, self).
    pub fn atan2(self, x: impl IntoValue<'a>) -> Value<'a> {
        self.bin(Op::Atan2, x)
    }
    pub fn min(self, o: impl IntoValue<'a>) -> Value<'a> {
        self.bin(Op::Min, o)
    }
    pub fn max(self, o: impl IntoValue<'a>) -> Value<'a> {
        self.bin(Op::Max, o)
    }
    /// self clamped into [lo, hi] (NaN stays NaN in neither bound's
    /// favour: callers that need a number test `finite` first).
    pub fn clamp(self, lo: impl IntoValue<'a>, hi: impl IntoValue<'a>) -> Value<'a> {
        self.max(lo).min(hi)
    }
    /// self * m + a.
    pub fn fma(self, m: impl IntoValue<'a>, a: impl IntoValue<'a>) -> Value<'a> {
        let m = m.into_value(self.b);
        let a = a.into_value(self.b);
        self.b.value(self.b.push(Op::Fma, self.id, m.id, a.id))
    }
    pub fn lt(self, o: impl IntoValue<'a>) -> Mask<'a> {
        self.cmp(Op::Lt, o)
    }
    pub fn le(self, o: impl IntoValue<'a>) -> Mask<'a> {
        self.cmp(Op::Le, o)
    }
    pub fn gt(self, o: impl IntoValue<'a>) -> Mask<'a> {
        self.cmp(Op::Gt, o)
    }
    pub fn ge(self, o: impl IntoValue<'a>) -> Mask<'a> {
        self.cmp(Op::Ge, o)
    }
    pub fn eq(self, o: impl IntoValue<'a>) -> Mask<'a> {
        self.cmp(Op::Eq, o)
    }
    pub fn finite(self) -> Mask<'a> {
        Mask {
            b: self.b,
            id: self.b.push(Op::Finite, self.id, 0, 0),
        }
    }
    /// self where it is finite and positive, else 0 (the core's
    /// `finite_non_negative`).
    pub fn finite_non_negative(self) -> Value<'a> {
        (self.gt(0.0) & self.finite()).select(self, 0.0)
    }
}

impl<'a> Mask<'a> {
    /// self ? a : b.
    pub fn select(self, a: impl IntoValue<'a>, b: impl IntoValue<'a>) -> Value<'a> {
        let a = a.into_value(self.b);
        let b = b.into_value(self.b);
        self.b.value(self.b.push(Op::Select, self.id, a.id, b.id))
    }
}

impl<'a> BitAnd for Mask<'a> {
    type Output = Mask<'a>;
    fn bitand(self, o: Mask<'a>) -> Mask<'a> {
        Mask {
            b: self.b,
            id: self.b.push(Op::And, self.id, o.id, 0),
        }
    }
}
impl<'a> BitOr for Mask<'a> {
    type Output = Mask<'a>;
    fn bitor(self, o: Mask<'a>) -> Mask<'a> {
        Mask {
            b: self.b,
            id: self.b.push(Op::Or, self.id, o.id, 0),
        }
    }
}
impl<'a> Not for Mask<'a> {
    type Output = Mask<'a>;
    fn not(self) -> Mask<'a> {
        Mask {
            b: self.b,
            id: self.b.push(Op::Not, self.id, 0, 0),
        }
    }
}
impl<'a> Neg for Value<'a> {
    type Output = Value<'a>;
    fn neg(self) -> Value<'a> {
        self.un(Op::Neg)
    }
}

macro_rules! arith {
    ($trait:ident, $method:ident, $op:expr) => {
        impl<'a> $trait<Value<'a>> for Value<'a> {
            type Output = Value<'a>;
            fn $method(self, o: Value<'a>) -> Value<'a> {
                self.bin($op, o)
            }
        }
        impl<'a> $trait<f64> for Value<'a> {
            type Output = Value<'a>;
            fn $method(self, o: f64) -> Value<'a> {
                self.bin($op, o)
            }
        }
        impl<'a> $trait<Value<'a>> for f64 {
            type Output = Value<'a>;
            fn $method(self, o: Value<'a>) -> Value<'a> {
                o.b.c(self).bin($op, o)
            }
        }
    };
}
arith!(Add, add, Op::Add);
arith!(Sub, sub, Op::Sub);
arith!(Mul, mul, Op::Mul);
arith!(Div, div, Op::Div);

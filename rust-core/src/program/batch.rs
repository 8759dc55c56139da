//! The CPU executor over a batch of lanes: each instruction on every lane,
//! then the next (`Program::run_batch`), the schedule behind the ABI's
//! `stam_program_run`. Its operations are `Program::apply`'s, the ones the
//! lane-by-lane schedule (`Program::run`) runs, so that the two cannot
//! differ. What this schedule adds is for callers outside the core: the
//! elementary functions (exp, log, sin, cos, atan2) may be the caller's
//! own, called once per instruction over the lanes (a test supplies Dr.Jit's
//! to compare the plugin's kernels with the program's operations alone),
//! and a caller may watch which lanes each region runs on (what a SIMD
//! packet of them would run: scripts/program_regions.py).

use super::interpret::Lane;
use super::{builder::operands, Op, Program};

/// Lanes computed together: memory is the live registers times this.
pub const BATCH_LANES: usize = 16_384;

/// What a caller may supply to `run_batch`.
pub trait BatchHooks<T> {
    /// Whether `elementary` may compute any operation (else the executor
    /// hands it none, copying no operands).
    fn takes_elementary(&self) -> bool {
        false
    }

    /// Computes the elementary function `op` (Exp, Log, Sin, Cos; Atan2 of
    /// (a, b)) of the lanes into `out`, or returns false to leave it to the
    /// executor. `b` is empty but for Atan2.
    fn elementary(&mut self, _op: Op, _a: &[T], _b: &[T], _out: &mut [T]) -> bool {
        false
    }

    /// At each region (`Op::If`, register `position`): whether each lane of
    /// the batch starting at lane `first_lane` runs it (its mask and every
    /// enclosing region's). Not called for the regions inside one that no
    /// lane of the batch runs (skipped, as a SIMD packet skips it).
    fn region(&mut self, _position: usize, _first_lane: usize, _runs: &[bool]) {}
}

/// No hooks: the executor's own functions.
pub struct NoHooks;
impl<T> BatchHooks<T> for NoHooks {}

/// A register over the batch: one value for every lane (constants,
/// parameters and what only they make), or a value per lane.
enum Column<T> {
    Uniform(T),
    Lanes(Vec<T>),
    /// Read by nothing after this point.
    Dropped,
}

impl<T: Lane> Column<T> {
    #[inline(always)]
    fn at(&self, lane: usize) -> T {
        match self {
            Column::Uniform(v) => *v,
            Column::Lanes(v) => v[lane],
            Column::Dropped => unreachable!("a register read after its last reader"),
        }
    }

    fn lanes(&self, n: usize) -> Vec<T> {
        (0..n).map(|l| self.at(l)).collect()
    }
}

impl Program {
    /// The outputs (`lanes` x n_outputs, lane-major) for `inputs` (`lanes`
    /// x n_inputs, lane-major) with the parameters' values `params` (by
    /// slot), computed as `run_with_params` computes each lane: a region's
    /// registers are 0 on the lanes it does not run on.
    pub fn run_batch<T: Lane>(
        &self,
        inputs: &[T],
        lanes: usize,
        params: &[T],
        hooks: &mut dyn BatchHooks<T>,
        out: &mut [T],
    ) {
        let (n_in, n_out) = (self.n_inputs as usize, self.outputs.len());
        assert_eq!(params.len(), self.params.len(), "parameter values");
        assert_eq!(inputs.len(), lanes * n_in, "inputs");
        assert_eq!(out.len(), lanes * n_out, "outputs");
        // Registers are dropped after their last reader.
        let n_code = self.code.len();
        let mut last = vec![0usize; n_code];
        for (i, ins) in self.code.iter().enumerate() {
            for r in operands(ins) {
                last[r as usize] = i;
            }
        }
        for &r in &self.outputs {
            last[r as usize] = n_code;
        }
        let mut dead_after = vec![Vec::new(); n_code];
        for (r, &i) in last.iter().enumerate() {
            if i < n_code && i >= r {
                dead_after[i].push(r);
            }
        }
        let mut first = 0;
        while first < lanes {
            let n = (lanes - first).min(BATCH_LANES);
            let x = &inputs[first * n_in..(first + n) * n_in];
            let regs = self.run_columns(x, n, first, params, hooks, &dead_after);
            for (k, &r) in self.outputs.iter().enumerate() {
                let col = &regs[r as usize];
                for l in 0..n {
                    out[(first + l) * n_out + k] = col.at(l);
                }
            }
            first += n;
        }
    }

    /// One batch of `n` lanes (inputs `x`, the batch's first lane
    /// `first`): every register, the dropped ones `Column::Dropped`.
    fn run_columns<T: Lane>(
        &self,
        x: &[T],
        n: usize,
        first: usize,
        params: &[T],
        hooks: &mut dyn BatchHooks<T>,
        dead_after: &[Vec<usize>],
    ) -> Vec<Column<T>> {
        let n_in = self.n_inputs as usize;
        let mut regs: Vec<Column<T>> = Vec::with_capacity(self.code.len());
        // Per open region: the lanes it runs on (and every enclosing one).
        let mut runs: Vec<Vec<bool>> = Vec::new();
        // Up to this instruction (a region no lane runs, and its EndIf):
        // every register 0, nothing computed.
        let mut skip_to = 0;
        for (i, ins) in self.code.iter().enumerate() {
            if i < skip_to {
                regs.push(Column::Uniform(T::zero()));
                for &r in &dead_after[i] {
                    regs[r] = Column::Dropped;
                }
                continue;
            }
            let col = match ins.op {
                Op::If => {
                    let mask = &regs[ins.a as usize];
                    let r: Vec<bool> = (0..n)
                        .map(|l| {
                            let enclosing = match runs.last() {
                                Some(o) => o[l],
                                None => true,
                            };
                            enclosing && mask.at(l) > T::zero()
                        })
                        .collect();
                    hooks.region(i, first, &r);
                    if !r.contains(&true) {
                        // As the lane-by-lane schedule skips it (with no
                        // EndIf: the rest of the program).
                        skip_to = self.region_end(i);
                    } else {
                        runs.push(r);
                    }
                    Column::Uniform(T::zero())
                }
                Op::EndIf => {
                    runs.pop();
                    Column::Uniform(T::zero())
                }
                Op::Input => Column::Lanes((0..n).map(|l| x[l * n_in + ins.a as usize]).collect()),
                op @ (Op::Exp | Op::Log | Op::Sin | Op::Cos | Op::Atan2)
                    if hooks.takes_elementary() =>
                {
                    // The caller's function: over the lanes, or once for a
                    // uniform operand.
                    let m = if uniform(ins, &regs) { 1 } else { n };
                    let a = regs[ins.a as usize].lanes(m);
                    let b = if op == Op::Atan2 {
                        regs[ins.b as usize].lanes(m)
                    } else {
                        Vec::new()
                    };
                    let mut v = vec![T::zero(); m];
                    match (hooks.elementary(op, &a, &b, &mut v), m) {
                        (false, _) => self.column(ins, x, n, params, &regs),
                        (true, 1) if n != 1 => Column::Uniform(v[0]),
                        (true, _) => Column::Lanes(v),
                    }
                }
                _ => self.column(ins, x, n, params, &regs),
            };
            // A region's registers are 0 on the lanes it does not run on.
            let col = match (runs.last(), col) {
                (Some(r), col) if !ins.op.is_marker() && !r.iter().all(|&b| b) => Column::Lanes(
                    (0..n)
                        .map(|l| if r[l] { col.at(l) } else { T::zero() })
                        .collect(),
                ),
                (_, col) => col,
            };
            regs.push(col);
            for &r in &dead_after[i] {
                regs[r] = Column::Dropped;
            }
        }
        regs
    }

    /// Instruction `ins` on every lane, by `apply`: uniform where its
    /// operands are.
    fn column<T: Lane>(
        &self,
        ins: &super::Instr,
        x: &[T],
        n: usize,
        params: &[T],
        regs: &[Column<T>],
    ) -> Column<T> {
        let n_in = self.n_inputs as usize;
        if ins.op != Op::Input && uniform(ins, regs) {
            return Column::Uniform(self.apply(
                ins,
                |_| unreachable!("an input is per lane"),
                params,
                |k| regs[k as usize].at(0),
            ));
        }
        Column::Lanes(
            (0..n)
                .map(|l| {
                    self.apply(
                        ins,
                        |k| x[l * n_in + k as usize],
                        params,
                        |k| regs[k as usize].at(l),
                    )
                })
                .collect(),
        )
    }
}

/// Whether every register `ins` reads holds one value for all lanes.
fn uniform<T>(ins: &super::Instr, regs: &[Column<T>]) -> bool {
    operands(ins)
        .iter()
        .all(|&r| matches!(regs[r as usize], Column::Uniform(_)))
}

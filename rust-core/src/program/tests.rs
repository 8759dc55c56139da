//! Programs with parameters: the encoded array round trip, `decode`
//! refusing bad parameter sections and operands, the executor reading the
//! stored values or the given ones; regions.

use super::{decode, Builder, Op, ParamId, Program, HEADER_LEN, PARAM_COUNT};

/// f = x sigma^2 + corr (sigma twice: one register) and a table.
fn program() -> Program {
    let b = Builder::new();
    let x = b.input();
    let sigma = b.param(ParamId::SigmaUm, 0.25);
    let corr = b.param(ParamId::CorrUm, 3.0);
    let again = b.param(ParamId::SigmaUm, 0.25);
    let t = b.table(vec![1.0, 2.0, 4.0]);
    let unused = b.param(ParamId::Twist, 1.0);
    let _ = unused * 2.0;
    let f = x * sigma * again + corr + b.gather(t, x);
    b.finish(&[f])
}

#[test]
fn params_round_trip_and_run() {
    let p = program();
    // Dead parameters are dropped; one slot per id.
    assert_eq!(
        p.params,
        vec![(ParamId::SigmaUm, 0.25), (ParamId::CorrUm, 3.0)]
    );
    assert_eq!(p.code.iter().filter(|i| i.op == Op::Param).count(), 2);
    let v = p.encode();
    assert_eq!(v[6], 2.0);
    let q = decode(&v).expect("decodes");
    assert_eq!(q.code, p.code);
    assert_eq!(q.params, p.params);
    assert_eq!(q.tables, p.tables);
    assert_eq!(q.encode(), v);
    // Stored values, then overridden ones (f64: exact).
    assert_eq!(q.run(&[1.0f64]), vec![1.0 * 0.0625 + 3.0 + 2.0]);
    assert_eq!(
        q.run_with_params(&[2.0f64], &[0.5, 1.0]),
        vec![2.0 * 0.25 + 1.0 + 4.0]
    );
    assert_eq!(q.param_slot(ParamId::CorrUm), Some(1));
    assert_eq!(q.param_slot(ParamId::Eta), None);
}

#[test]
fn decode_refuses_bad_parameters() {
    let p = program();
    let v = p.encode();
    let par_at = HEADER_LEN + p.outputs.len() + 2 * p.tables.len();
    assert!(decode(&v).is_some());
    let refused = |what: &str, f: &dyn Fn(&mut Vec<f32>)| {
        let mut w = v.clone();
        f(&mut w);
        assert!(decode(&w).is_none(), "{what} was accepted");
    };
    refused("an unknown id", &|w| w[par_at] = PARAM_COUNT as f32);
    refused("a fractional id", &|w| w[par_at] = 0.5);
    refused("a repeated id", &|w| w[par_at + 2] = w[par_at]);
    refused("a NaN value", &|w| w[par_at + 1] = f32::NAN);
    refused("an infinite value", &|w| w[par_at + 3] = f32::INFINITY);
    refused("header field 7", &|w| w[7] = 1.0);
    // One parameter fewer in the header: the section and the code shift,
    // so the array no longer reads as a program.
    refused("a shorter section", &|w| w[6] = 1.0);
    // A Param reading a slot beyond the section.
    let code_at = par_at + 2 * p.params.len();
    let k = p.code.iter().position(|i| i.op == Op::Param).unwrap();
    refused("a Param out of range", &|w| w[code_at + 4 * k + 1] = 2.0);
    // A format 2 array (no parameter section) is refused.
    refused("format 2", &|w| w[0] = 2.0);
}

#[test]
fn param_ids_are_their_codes() {
    for (code, id) in ParamId::ALL.iter().enumerate() {
        assert_eq!(*id as u32, code as u32);
        assert_eq!(ParamId::from_code(code as u32), Some(*id));
    }
    assert_eq!(ParamId::from_code(PARAM_COUNT), None);
    assert_eq!(Op::from_code(29), Some(Op::Param));
    assert_eq!(Op::from_code(31), Some(Op::EndIf));
    assert_eq!(Op::from_code(super::OP_COUNT), None);
}

#[test]
fn select_chain_reads_the_indexed_value_and_clamps() {
    let values = [0.5, -1.0, 2.0, 7.0];
    let b = Builder::new();
    let i = b.input();
    let f = super::lookup::select_chain(&b, &values, i);
    let p = b.finish(&[f]);
    for (k, &v) in values.iter().enumerate() {
        assert_eq!(p.run(&[k as f64]), vec![v]);
    }
    assert_eq!(p.run(&[-3.0f64]), vec![values[0]]);
    assert_eq!(p.run(&[9.0f64]), vec![values[3]]);
}

/// f = x > 0 ? (x + 1) * 2 + (x > 1 ? 10 x : 0) : 0, and g = x + 3 (a
/// value from outside returned by the region) with regions nested; the
/// inner constants are hoisted out of them.
fn regions() -> Program {
    let b = Builder::new();
    let x = b.input();
    let unused = b.region(x.gt(5.0), || [x * 7.0]);
    let _ = unused;
    let outer = x + 3.0;
    let [f, g] = b.region(x.gt(0.0), || {
        let y = (x + 1.0) * 2.0;
        let [z] = b.region(x.gt(1.0), || [x * 10.0]);
        [y + z, outer]
    });
    b.finish(&[f, g, outer])
}

#[test]
fn regions_run_where_their_mask_holds() {
    let p = regions();
    // The dead region is dropped; two Ifs and their EndIfs are kept.
    assert_eq!(p.code.iter().filter(|i| i.op == Op::If).count(), 2);
    assert_eq!(p.code.iter().filter(|i| i.op == Op::EndIf).count(), 2);
    // Inputs and constants come before every region.
    let first_if = p.code.iter().position(|i| i.op == Op::If).unwrap();
    assert!(p.code[first_if..]
        .iter()
        .all(|i| !matches!(i.op, Op::Input | Op::Const | Op::Param)));
    let q = decode(&p.encode()).expect("decodes");
    assert_eq!(q.code, p.code);
    for (x, f, g) in [
        (-1.0, 0.0, 0.0),
        (0.5, 3.0, 3.5),
        (2.0, 26.0, 5.0),
        (f64::NAN, 0.0, 0.0),
    ] {
        let out = q.run(&[x]);
        assert_eq!(out[..2], [f, g], "x = {x}");
        assert!(out[2].to_bits() == (x + 3.0).to_bits() || x.is_nan());
    }
}

#[test]
fn decode_refuses_bad_regions() {
    let p = regions();
    let v = p.encode();
    let code_at = HEADER_LEN + p.outputs.len() + 2 * p.tables.len() + 2 * p.params.len();
    let at = |op: Op, k: usize| {
        p.code
            .iter()
            .enumerate()
            .filter(|(_, i)| i.op == op)
            .nth(k)
            .unwrap()
            .0
    };
    let refused = |what: &str, f: &dyn Fn(&mut Vec<f32>)| {
        let mut w = v.clone();
        f(&mut w);
        assert!(decode(&w).is_none(), "{what} was accepted");
    };
    let (if0, end0) = (at(Op::If, 0), at(Op::EndIf, 1));
    refused("an EndIf naming the wrong If", &|w| {
        w[code_at + 4 * end0 + 1] = at(Op::If, 1) as f32
    });
    refused("an unclosed region", &|w| {
        w[code_at + 4 * end0] = Op::Add as u32 as f32;
        w[code_at + 4 * end0 + 1] = 0.0;
        w[code_at + 4 * end0 + 2] = 0.0;
    });
    refused("an If on a float", &|w| w[code_at + 4 * if0 + 1] = 0.0);
    refused("a marker read", &|w| {
        let k = at(Op::Add, 1);
        w[code_at + 4 * k + 1] = if0 as f32;
    });
    refused("a constant inside a region", &|w| {
        let k = if0 + 1;
        w[code_at + 4 * k] = Op::Const as u32 as f32;
    });
}

#[test]
#[should_panic(expected = "outside its region")]
fn a_region_keeps_its_values() {
    let b = Builder::new();
    let x = b.input();
    let mut leaked = None;
    let _ = b.region(x.gt(0.0), || {
        leaked = Some(x * 2.0);
        [x]
    });
    let _ = leaked.unwrap() + 1.0;
}

/// Hooks that record what they see and compute exp themselves (as
/// exp(x) + 1, so that their use shows).
#[derive(Default)]
struct Recording {
    elementary: usize,
    regions: Vec<(usize, usize, Vec<bool>)>,
}

impl super::BatchHooks<f32> for Recording {
    fn takes_elementary(&self) -> bool {
        true
    }

    fn elementary(&mut self, op: Op, a: &[f32], _b: &[f32], out: &mut [f32]) -> bool {
        self.elementary += 1;
        if op != Op::Exp {
            return false;
        }
        for (o, x) in out.iter_mut().zip(a) {
            *o = x.exp() + 1.0;
        }
        true
    }

    fn region(&mut self, position: usize, first_lane: usize, runs: &[bool]) {
        self.regions.push((position, first_lane, runs.to_vec()));
    }
}

#[test]
fn the_batch_schedule_equals_the_lane_by_lane_one() {
    // Nested regions, over more lanes than a batch: the same bits as the
    // lane-by-lane run, in f32 and f64; the regions reported per batch
    // with the lanes that run them, none inside a region no lane runs.
    let p = regions();
    let lanes = super::BATCH_LANES + 5;
    let xs: Vec<f32> = (0..lanes)
        .map(|i| match i % 4 {
            0 => f32::NAN,
            _ => (i % 7) as f32 * 0.4 - 0.9,
        })
        .collect();
    let mut out = vec![0.0f32; lanes * p.outputs.len()];
    let mut hooks = Recording::default();
    p.run_batch(&xs, lanes, &[], &mut hooks, &mut out);
    let x64: Vec<f64> = xs.iter().map(|&x| x as f64).collect();
    let mut out64 = vec![0.0f64; lanes * p.outputs.len()];
    p.run_batch(&x64, lanes, &[], &mut super::NoHooks, &mut out64);
    let n_out = p.outputs.len();
    for (i, &x) in xs.iter().enumerate() {
        let one = p.run::<f32>(&[x]);
        let one64 = p.run::<f64>(&[x as f64]);
        for k in 0..n_out {
            assert_eq!(out[i * n_out + k].to_bits(), one[k].to_bits(), "lane {i}");
            assert_eq!(
                out64[i * n_out + k].to_bits(),
                one64[k].to_bits(),
                "lane {i}"
            );
        }
    }
    // Two regions in each of two batches, the second batch's masks its lanes'.
    let ifs: Vec<usize> = (0..p.code.len())
        .filter(|&i| p.code[i].op == Op::If)
        .collect();
    assert_eq!(hooks.regions.len(), 2 * ifs.len());
    let (pos, first, runs) = &hooks.regions[ifs.len()];
    assert_eq!((*pos, *first, runs.len()), (ifs[0], super::BATCH_LANES, 5));
    for (l, &r) in runs.iter().enumerate() {
        assert_eq!(
            r,
            xs[super::BATCH_LANES + l] > 0.0,
            "lane {l} of the second batch"
        );
    }
    // A batch where no lane runs the outer region: its inner one is not
    // reported, and the outputs are still the lane-by-lane ones.
    let mut hooks = Recording::default();
    let negative = vec![-1.0f32; 3];
    let mut out = vec![1.0f32; 3 * n_out];
    p.run_batch(&negative, 3, &[], &mut hooks, &mut out);
    assert_eq!(hooks.regions.len(), 1);
    assert_eq!(out, p.run::<f32>(&[-1.0]).repeat(3));
}

#[test]
fn the_batch_schedule_takes_the_callers_elementary_functions() {
    // f = exp(x) and sin(x): exp from the hook (exp(x) + 1), sin the
    // executor's (the hook declines); a uniform operand is computed once.
    let b = Builder::new();
    let x = b.input();
    let c = b.c(0.5);
    let f = x.exp();
    let g = x.sin();
    let h = c.exp();
    let p = b.finish(&[f, g, h]);
    let xs = [0.0f32, 1.0, -2.0];
    let mut out = vec![0.0f32; 9];
    let mut hooks = Recording::default();
    p.run_batch(&xs, 3, &[], &mut hooks, &mut out);
    for (i, &x) in xs.iter().enumerate() {
        assert_eq!(out[3 * i], x.exp() + 1.0);
        assert_eq!(out[3 * i + 1], x.sin());
        assert_eq!(out[3 * i + 2], 0.5f32.exp() + 1.0);
    }
    assert_eq!(hooks.elementary, 3);
}

#[test]
fn a_refused_array_says_why() {
    let p = regions();
    let v = p.encode();
    let code_at = HEADER_LEN + p.outputs.len() + 2 * p.tables.len() + 2 * p.params.len();
    let why = |f: &dyn Fn(&mut Vec<f32>)| {
        let mut w = v.clone();
        f(&mut w);
        super::decode_checked(&w).unwrap_err()
    };
    assert_eq!(why(&|w| w[0] = 3.0), "format 3, not 4");
    assert!(why(&|w| w.truncate(5)).contains("shorter than the header"));
    assert!(why(&|w| w[code_at] = 99.0).contains("instruction 0 has the unknown op code 99"));
    let first_if = p.code.iter().position(|i| i.op == Op::If).unwrap();
    // The If's mask: a float register (the input) where a mask goes.
    assert!(why(&|w| w[code_at + 4 * first_if + 1] = 0.0)
        .contains("reads register 0, a float, where it takes a mask"));
    assert!(why(&|w| w[HEADER_LEN] = 1e6).contains("output 0 is register 1000000"));
}

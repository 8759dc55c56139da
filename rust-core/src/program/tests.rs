//! Programs with parameters: the encoded array round trip, `decode`
//! refusing bad parameter sections and operands, the executor reading the
//! stored values or the given ones.

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
    assert_eq!(Op::from_code(30), None);
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

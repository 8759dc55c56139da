//! Size of each exported program (instructions, table values, gathers) for
//! the materials of `scripts/bench_render.py`, with the default and with
//! Stam's formula: the JIT variants' cost per lane grows with the
//! instructions a kernel traces (docs/plugin_speed.md). Rows "(built)":
//! the program for the built parameters (STAM_PROGRAM_AT_BUILT), which an
//! ordinary render runs, and "(gradients)": the plain program of the
//! material built with `"gradients": true`, which a render that
//! differentiates its parameters runs (rows only where they differ).
//! Usage: cargo run --release -p stam-core --example program_sizes
use stam::material::program::ProgramKind;
use stam::program::{Op, Program};
use stam::Brdf;

fn main() {
    let materials = [
        (
            "gaussian (rough)",
            r#""surface":"gaussian","sigma_um":0.5,"corr_um":4"#,
        ),
        (
            "gaussian (smooth)",
            r#""surface":"gaussian","sigma_um":0.05,"corr_um":2"#,
        ),
        (
            "fractal",
            r#""surface":"fractal","hurst":0.7,"sigma_um":0.1,"lag_um":1"#,
        ),
        ("cd", r#""surface":"cd""#),
    ];
    println!("| material | energy | program | instructions | gathers | table values |");
    println!("|---|---|---|---|---|---|");
    let gathers = |p: &Program| p.code.iter().filter(|i| i.op == Op::Gather).count();
    for (name, body) in materials {
        for energy in ["conserving", "stam"] {
            let json = format!(r#"{{{body},"energy":"{energy}"}}"#);
            let brdf = Brdf::from_json(&json).expect("material");
            let json = format!(r#"{{{body},"energy":"{energy}","gradients":true}}"#);
            let differentiated = Brdf::from_json(&json).expect("material");
            for kind in ProgramKind::ALL {
                let Some(p) = brdf.program(kind) else {
                    continue;
                };
                let row = |label: &str, p: &Program| {
                    println!(
                        "| {name} | {energy} | {kind:?}{label} | {} | {} | {} |",
                        p.code.len(),
                        gathers(p),
                        p.table_len()
                    )
                };
                row("", &p);
                if let Some(g) = differentiated.program(kind) {
                    if g.encode() != p.encode() {
                        row(" (gradients)", &g);
                    }
                }
                if let Some(lean) = brdf.program_at_built(kind) {
                    row(" (built)", &lean);
                }
            }
        }
    }
}

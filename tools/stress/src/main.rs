//! `stress`: the numerical stress run (see the library's `run` module).
//!
//! cargo run --release -p stress --bin stress -- --count 10000000 [--seed 1] [--batch 128] [--write docs/stress.md]
//!
//! Prints the counts; with --write, replaces the table between the
//! `<!-- stress-table -->` markers of the given file. Exits with status 1 if
//! any contract violation was found.

use stress::run::{run, Options};

fn main() {
    let mut options = Options::default();
    let mut write: Option<String> = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || {
            args.next()
                .unwrap_or_else(|| usage(&format!("{a} needs a value")))
        };
        match a.as_str() {
            "--count" => options.count = parse(&value()),
            "--seed" => options.seed = parse(&value()),
            "--batch" => options.batch = parse::<u64>(&value()) as usize,
            "--inject-nan-every" => options.inject_nan_every = parse(&value()),
            "--write" => write = Some(value()),
            _ => usage(&format!("unknown argument {a}")),
        }
    }
    let report = run(&options);
    let table = report.markdown(&options);
    println!("{table}");
    for e in &report.refusal_examples {
        println!("refusal example: {e}");
    }
    println!(
        "slowest construction: {:.3} s: {}",
        report.slowest_construction.0, report.slowest_construction.1
    );
    for e in &report.examples {
        println!("VIOLATION: {e}");
    }
    println!("violations: {}", report.failures());
    if let Some(path) = write {
        let marker = "<!-- stress-table -->";
        let doc =
            std::fs::read_to_string(&path).unwrap_or_else(|_| format!("{marker}\n{marker}\n"));
        let (head, rest) = doc.split_once(marker).unwrap_or((&doc, ""));
        let tail = rest.split_once(marker).map(|(_, t)| t).unwrap_or("\n");
        let text = format!(
            "{head}{marker}\nCommand: `cargo run --release -p stress --bin stress -- --count {} --seed {} --batch {}`\n\n{table}{marker}{tail}",
            options.count, options.seed, options.batch
        );
        std::fs::write(&path, text).expect("write the report");
    }
    if report.failures() > 0 {
        std::process::exit(1);
    }
}

fn parse<T: std::str::FromStr>(s: &str) -> T {
    s.parse()
        .unwrap_or_else(|_| usage(&format!("bad number {s}")))
}

fn usage(msg: &str) -> ! {
    eprintln!("stress: {msg}\nusage: stress [--count N] [--seed S] [--batch B] [--inject-nan-every K] [--write docs/stress.md]");
    std::process::exit(2)
}

//! CI version of the stress run: 10^5 evaluations (the full run is
//! `cargo run --release -p stress -- --count 10000000`), and a negative
//! control showing that the checks catch a NaN.

use stress::run::{run, Options};

#[test]
fn stress_1e5_evaluations_clean() {
    let options = Options {
        count: 100_000,
        seed: std::env::var("STRESS_SEED")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(2),
        ..Options::default()
    };
    let report = run(&options);
    println!("{}", report.markdown(&options));
    for e in &report.examples {
        println!("VIOLATION: {e}");
    }
    assert!(report.evaluations() >= options.count);
    // Every surface kind was exercised, values were compared and samples
    // succeeded: a run that checks nothing must not pass.
    assert!(
        report.materials_per_kind.iter().all(|&n| n > 0),
        "{:?}",
        report.materials_per_kind
    );
    assert!(report.compared > 1000, "compared {}", report.compared);
    assert!(report.samples > report.sample_failures + 1000);
    // The programs were exported and run (the sampling and pdf kinds at
    // least, for every material).
    assert!(report.programs >= 6, "programs {}", report.programs);
    assert!(
        report.program_runs >= report.programs * options.batch as u64,
        "program lanes run {}",
        report.program_runs
    );
    assert_eq!(
        report.failures(),
        0,
        "contract violations: {:#?}",
        report.examples
    );
}

/// The same pipeline with every 200th ABI spectral output replaced by NaN:
/// the run must report it.
#[test]
fn negative_control_injected_nan_is_caught() {
    let options = Options {
        count: 20_000,
        seed: 3,
        inject_nan_every: 200,
        ..Options::default()
    };
    let report = run(&options);
    assert!(report.nan > 0, "injected NaNs were not detected");
    assert!(report.failures() >= report.nan);
    assert!(report.examples.iter().any(|e| e.contains("NaN")));
}

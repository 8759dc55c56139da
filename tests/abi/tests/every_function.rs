//! Completeness of the ABI's checks: every function declared in
//! rust-core/include/stam.h must be
//! - defined by the Rust core (an `extern "C" fn` under rust-core/src), and
//!   every such definition declared in the header;
//! - in the bindgen signature check (a `same_signature(h::NAME ...,
//!   ffi::NAME ...)` call in tests/abi/src/lib.rs);
//! - called by the C caller (tests/abi/c/caller.c);
//! - called by the stress runner (tools/stress/src/run.rs);
//! - called by the fuzzers that feed arbitrary inputs to every entry point:
//!   the cargo-fuzz target fuzz/fuzz_targets/params_json.rs and its proptest
//!   twin tools/stress/tests/fuzz_json.rs (the one CI runs).
//!
//! and every value macro of the header (`#define STAM_...`) must be compared
//! with the Rust constant in tests/abi/src/lib.rs (`h::NAME`).
//!
//! The sources are read as tokens with comments and string literals removed,
//! so a name mentioned in a comment or a message does not count. Adding a
//! function to the header without adding it everywhere fails here, naming
//! the function and the place. (Renderers, the Mitsuba plugin among them,
//! call only what they need: they are not places.)

use std::path::{Path, PathBuf};

/// A token of C or Rust source: an identifier, a number, `::`, a single
/// punctuation character, or `"` standing for a whole string literal.
/// Comments and the contents of string and character literals are dropped.
fn tokens(src: &str, nested_comments: bool) -> Vec<String> {
    let c: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    let ident_start = |ch: char| ch.is_ascii_alphabetic() || ch == '_';
    let ident_char = |ch: char| ch.is_ascii_alphanumeric() || ch == '_';
    while i < c.len() {
        let ch = c[i];
        let next = c.get(i + 1).copied();
        if ch.is_whitespace() {
            i += 1;
        } else if ch == '/' && next == Some('/') {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if ch == '/' && next == Some('*') {
            let mut depth = 1;
            i += 2;
            while i < c.len() && depth > 0 {
                if nested_comments && c[i] == '/' && c.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && c.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                } else {
                    i += 1;
                }
            }
        } else if ch == '"' {
            i += 1;
            while i < c.len() && c[i] != '"' {
                i += if c[i] == '\\' { 2 } else { 1 };
            }
            i += 1;
            out.push("\"".to_string());
        } else if ch == '\'' {
            // A character literal ('x', '\n', '\'') or a Rust lifetime / loop
            // label ('a, dropped).
            if next == Some('\\') {
                // Past the quote, the backslash and the escaped character.
                i += 3;
                while i < c.len() && c[i] != '\'' {
                    i += if c[i] == '\\' { 2 } else { 1 };
                }
                i += 1;
            } else if c.get(i + 2) == Some(&'\'') {
                i += 3;
            } else {
                i += 1;
            }
        } else if ident_start(ch) {
            let start = i;
            while i < c.len() && ident_char(c[i]) {
                i += 1;
            }
            let word: String = c[start..i].iter().collect();
            // Rust raw strings: r"...", r#"..."#, br#"..."#.
            let hashes = c[i..].iter().take_while(|&&h| h == '#').count();
            if (word == "r" || word == "br") && c.get(i + hashes) == Some(&'"') {
                let close: Vec<char> = format!("\"{}", "#".repeat(hashes)).chars().collect();
                i += hashes + 1;
                while i < c.len() && !c[i..].starts_with(&close) {
                    i += 1;
                }
                i += close.len();
                out.push("\"".to_string());
            } else if word == "b" && c.get(i) == Some(&'\'') {
                // Byte literal b'x': the quote is handled next round.
            } else {
                out.push(word);
            }
        } else if ch.is_ascii_digit() {
            // A decimal point only before a digit (`0..n` is a range).
            while i < c.len()
                && (ident_char(c[i])
                    || (c[i] == '.' && c.get(i + 1).is_some_and(|d| d.is_ascii_digit())))
            {
                i += 1;
            }
            out.push("0".to_string());
        } else if ch == ':' && next == Some(':') {
            out.push("::".to_string());
            i += 2;
        } else {
            out.push(ch.to_string());
            i += 1;
        }
    }
    out
}

/// Functions declared in the header: a `stam_` name followed by `(`.
fn header_functions(header: &[String]) -> Vec<String> {
    let mut names: Vec<String> = header
        .windows(2)
        .filter(|w| w[0].starts_with("stam_") && w[1] == "(")
        .map(|w| w[0].clone())
        .collect();
    names.sort();
    names.dedup();
    names
}

/// Value macros of the header: `#define STAM_...`, less the include guard
/// (the name of an `#ifndef`).
fn header_constants(header: &[String]) -> Vec<String> {
    let guards: Vec<&String> = header
        .windows(2)
        .filter(|w| w[0] == "ifndef")
        .map(|w| &w[1])
        .collect();
    header
        .windows(3)
        .filter(|w| w[0] == "#" && w[1] == "define" && w[2].starts_with("STAM_"))
        .map(|w| w[2].clone())
        .filter(|n| !guards.contains(&n))
        .collect()
}

/// Names defined as `extern "C" fn stam_...` in Rust source.
fn rust_definitions(src: &[String]) -> Vec<String> {
    src.windows(4)
        .filter(|w| w[0] == "extern" && w[1] == "\"" && w[2] == "fn" && w[3].starts_with("stam_"))
        .map(|w| w[3].clone())
        .collect()
}

/// Whether `name` is called: the identifier followed by `(`.
fn calls(src: &[String], name: &str) -> bool {
    src.windows(2).any(|w| w[0] == name && w[1] == "(")
}

/// Whether a `same_signature(...)` call has `h::name` and `ffi::name` among
/// its arguments.
fn signature_checked(src: &[String], name: &str) -> bool {
    let has = |args: &[String], module: &str| {
        args.windows(3)
            .any(|w| w[0] == module && w[1] == "::" && w[2] == name)
    };
    (0..src.len()).any(|i| {
        if !(src[i] == "same_signature" && src.get(i + 1).map(String::as_str) == Some("(")) {
            return false;
        }
        let mut depth = 0;
        let mut end = i + 1;
        for (j, t) in src.iter().enumerate().skip(i + 1) {
            match t.as_str() {
                "(" => depth += 1,
                ")" => depth -= 1,
                _ => {}
            }
            if depth == 0 {
                end = j;
                break;
            }
        }
        let args = &src[i + 2..end];
        has(args, "h") && has(args, "ffi")
    })
}

/// `h::name` occurs in the source (a header constant compared in Rust).
fn constant_used(src: &[String], name: &str) -> bool {
    src.windows(3)
        .any(|w| w[0] == "h" && w[1] == "::" && w[2] == name)
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn read(relative: &str) -> String {
    let path = root().join(relative);
    std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {} ({e}): was it moved?", path.display()))
}

fn rust_sources(dir: &Path, out: &mut Vec<PathBuf>) {
    let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    for entry in entries {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// How a place shows that it covers a function.
#[derive(Clone, Copy)]
enum Coverage {
    /// `same_signature(h::NAME ..., ffi::NAME ...)`.
    SignatureCheck,
    /// `NAME(` in code.
    Call,
}

/// The places every header function must reach: (path, what it is, how).
const PLACES: [(&str, &str, Coverage); 5] = [
    (
        "tests/abi/src/lib.rs",
        "the bindgen signature check (header_declarations_match_rust_definitions)",
        Coverage::SignatureCheck,
    ),
    ("tests/abi/c/caller.c", "the C caller", Coverage::Call),
    (
        "tools/stress/src/run.rs",
        "the stress runner",
        Coverage::Call,
    ),
    (
        "fuzz/fuzz_targets/params_json.rs",
        "the cargo-fuzz target",
        Coverage::Call,
    ),
    (
        "tools/stress/tests/fuzz_json.rs",
        "the proptest fuzz (call_everything)",
        Coverage::Call,
    ),
];

/// Every gap between the header and the places, one line each. `sources`
/// maps each of PLACES' paths to its text.
fn gaps(header: &str, rust_core: &[String], sources: &dyn Fn(&str) -> String) -> Vec<String> {
    let header = tokens(header, false);
    let functions = header_functions(&header);
    let mut gaps = Vec::new();
    let defined = rust_definitions(rust_core);
    for name in &defined {
        if !functions.contains(name) {
            gaps.push(format!(
                "{name} is defined by the Rust core but not declared in rust-core/include/stam.h"
            ));
        }
    }
    for name in &functions {
        if !defined.contains(name) {
            gaps.push(format!(
                "{name} is declared in stam.h but not defined by the Rust core (no extern \"C\" fn under rust-core/src)"
            ));
        }
    }
    for (path, what, coverage) in PLACES {
        let src = tokens(&sources(path), path.ends_with(".rs"));
        for name in &functions {
            let ok = match coverage {
                Coverage::SignatureCheck => signature_checked(&src, name),
                Coverage::Call => calls(&src, name),
            };
            if !ok {
                let how = match coverage {
                    Coverage::SignatureCheck => {
                        format!("no same_signature(h::{name} ..., ffi::{name} ...)")
                    }
                    Coverage::Call => "never called".to_string(),
                };
                gaps.push(format!("{name} is missing from {what}, {path}: {how}"));
            }
        }
    }
    let lib = tokens(&sources("tests/abi/src/lib.rs"), true);
    for name in header_constants(&header) {
        if !constant_used(&lib, &name) {
            gaps.push(format!(
                "the macro {name} of stam.h is not compared with the Rust value in tests/abi/src/lib.rs (no h::{name})"
            ));
        }
    }
    gaps
}

fn rust_core_tokens() -> Vec<String> {
    let mut files = Vec::new();
    rust_sources(&root().join("rust-core/src"), &mut files);
    files
        .iter()
        .flat_map(|f| tokens(&std::fs::read_to_string(f).unwrap(), true))
        .collect()
}

#[test]
fn every_header_function_is_checked_everywhere() {
    let header = read("rust-core/include/stam.h");
    let functions = header_functions(&tokens(&header, false));
    // The parse itself must find the API (a broken lexer would pass
    // vacuously): 17 functions today.
    for expected in ["stam_brdf_new", "stam_brdf_free", "stam_version"] {
        assert!(functions.iter().any(|f| f == expected), "{functions:?}");
    }
    assert!(functions.len() >= 10, "{functions:?}");
    let gaps = gaps(&header, &rust_core_tokens(), &|p| read(p));
    assert!(
        gaps.is_empty(),
        "{} gap(s) between stam.h and its checks:\n  {}",
        gaps.len(),
        gaps.join("\n  ")
    );
}

/// Negative control: the real sources with one function removed from one
/// place (its calls commented out, its signature line dropped) must be
/// reported, naming the function and the place.
#[test]
fn a_function_missing_from_one_place_is_reported() {
    let header = read("rust-core/include/stam.h");
    let core = rust_core_tokens();
    let name = "stam_brdf_coherent_probability";
    for (path, _, coverage) in PLACES {
        let sources = |p: &str| {
            let text = read(p);
            if p != path {
                return text;
            }
            match coverage {
                // A comment may still mention it: that must not count.
                Coverage::Call => text.replace(&format!("{name}("), &format!("/* {name} */(")),
                Coverage::SignatureCheck => text
                    .replace(&format!("h::{name} "), "h::stam_brdf_pdf ")
                    .replace(&format!("h::{name}\n"), "h::stam_brdf_pdf\n"),
            }
        };
        let gaps = gaps(&header, &core, &sources);
        assert!(
            gaps.len() == 1 && gaps[0].contains(name) && gaps[0].contains(path),
            "removing {name} from {path} gave {gaps:?}"
        );
    }
    // A header function the Rust core does not define, and a constant not
    // compared.
    let end = "#ifdef __cplusplus\n}";
    assert!(header.contains(end));
    let extra = header.replace(
        end,
        &format!("void stam_brdf_unchecked(void);\n#define STAM_UNCHECKED 1\n{end}"),
    );
    let gaps = gaps(&extra, &core, &|p| read(p));
    let about = |what: &str| gaps.iter().filter(|g| g.contains(what)).count();
    assert_eq!(about("stam_brdf_unchecked"), 1 + PLACES.len(), "{gaps:?}");
    assert_eq!(about("STAM_UNCHECKED"), 1, "{gaps:?}");
}

#[test]
fn lexer_drops_comments_and_literals() {
    let src = r###"
        // stam_a(
        /* stam_b( /* nested */ stam_c( */
        let s = "stam_d(\" stam_e(";
        let r = r#"stam_f(" "#;
        let c = '"'; let d = b'\''; let e = '\\'; let f = '\x41';
        for i in 0..stam_i(n) {}
        fn g<'a>(x: &'a str) {}
        stam_g(1.5e3, x::y);
    "###;
    let t = tokens(src, true);
    for hidden in ["stam_a", "stam_b", "stam_c", "stam_d", "stam_e", "stam_f"] {
        assert!(!t.iter().any(|x| x == hidden), "{hidden} in {t:?}");
    }
    assert!(calls(&t, "stam_g") && calls(&t, "stam_i"), "{t:?}");
    assert!(t.windows(3).any(|w| w == ["x", "::", "y"]), "{t:?}");
    // C comments do not nest.
    let c = tokens("/* a /* b */ stam_h(); /* */", false);
    assert!(calls(&c, "stam_h"), "{c:?}");
}

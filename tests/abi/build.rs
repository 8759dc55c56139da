//! Generates Rust declarations from rust-core/include/stam.h with bindgen
//! and compiles a C program that calls every function through the header.
//! The crate's tests then (a) type-check each Rust definition against the
//! header's declaration and (b) run the C caller.

use std::path::PathBuf;

fn main() {
    let header = PathBuf::from("../../rust-core/include/stam.h");
    println!("cargo:rerun-if-changed={}", header.display());
    println!("cargo:rerun-if-changed=c/caller.c");

    let bindings = bindgen::Builder::default()
        .header(header.to_str().unwrap())
        .allowlist_function("stam_.*")
        .allowlist_var("STAM_.*")
        // The opaque handle is the Rust type itself, so signatures compare
        // exactly.
        .blocklist_type("StamBrdf")
        .raw_line("pub use stam::ffi::StamBrdf;")
        .generate()
        .expect("bindgen could not parse stam.h");
    let out = PathBuf::from(std::env::var("OUT_DIR").unwrap());
    bindings
        .write_to_file(out.join("stam_header.rs"))
        .expect("write bindings");

    cc::Build::new()
        .file("c/caller.c")
        .include("../../rust-core/include")
        .flag_if_supported("-std=c99")
        .warnings_into_errors(true)
        .compile("stam_c_caller");
}

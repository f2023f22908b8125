//! Puts `memory.x` on the linker path and adds embedded-test's linker script to test binaries.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy("memory.x", out.join("memory.x")).expect("memory.x is readable");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    // embedded-test's linker script, for test binaries only.
    println!("cargo:rustc-link-arg-tests=-Tembedded-test.x");
    // The embedded-test macro emits cfg(rust_analyzer).
    println!("cargo::rustc-check-cfg=cfg(rust_analyzer)");
}

//! Puts the workspace's top-level `memory.x` on the linker search path and adds the link scripts.

use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").unwrap_or_default());
    let src =
        PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default()).join("../memory.x");
    match fs::read(&src) {
        Ok(bytes) => {
            if let Err(e) = fs::write(out.join("memory.x"), bytes) {
                println!("cargo::error=cannot write memory.x to OUT_DIR: {e}");
            }
        }
        Err(e) => println!("cargo::error=cannot read {}: {e}", src.display()),
    }
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=../memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    // cortex-m-rt's and defmt's link scripts, for the firmware binary only.
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    println!("cargo:rustc-link-arg-bins=--nmagic");
}

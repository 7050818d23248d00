//! Puts the workspace's top-level `memory.x` on the linker search path and adds the link scripts.

use std::{env, fs, path::PathBuf, process::Command};

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
    identity(&out);
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=../memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    // cortex-m-rt's and defmt's link scripts, for the firmware binary only.
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    println!("cargo:rustc-link-arg-bins=--nmagic");
}

/// Output of a git command in the crate's directory, `None` if git is missing or fails.
fn git(args: &[&str]) -> Option<String> {
    let o = Command::new("git").args(args).output().ok()?;
    o.status
        .success()
        .then(|| String::from_utf8_lossy(&o.stdout).trim().to_string())
}

/// Writes `identity.rs`: the commit (first 8 hex digits, 0 if unknown), whether the tree had
/// uncommitted changes, and the build date as YYYYMMDD. The date is the commit's, so the same
/// commit always builds the same image; without git it is 0 (unknown).
fn identity(out: &std::path::Path) {
    let hash = git(&["rev-parse", "HEAD"]).unwrap_or_default();
    let hash = hash.get(..8).unwrap_or("");
    let dirty =
        git(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|s| !s.is_empty());
    let date = git(&["log", "-1", "--format=%cd", "--date=format:%Y%m%d"])
        .and_then(|d| d.parse::<u32>().ok())
        .unwrap_or(0);
    let part = |name: &str| {
        env::var(name)
            .ok()
            .and_then(|v| v.parse::<u32>().ok())
            .unwrap_or(0)
    };
    // major << 16 | minor << 8 | patch, the wire layout of McuInfo.fw_version.
    let fw = (part("CARGO_PKG_VERSION_MAJOR").min(0xFFFF) << 16)
        | (part("CARGO_PKG_VERSION_MINOR").min(0xFF) << 8)
        | part("CARGO_PKG_VERSION_PATCH").min(0xFF);
    let text = format!(
        "/// This crate's version, `major << 16 | minor << 8 | patch`.\n\
         pub const FW_VERSION: u32 = {fw};\n\
         /// First 8 hex digits of the commit built (empty if unknown).\n\
         pub const GIT_HASH: &str = \"{hash}\";\n\
         /// The working tree had uncommitted changes.\n\
         pub const GIT_DIRTY: bool = {dirty};\n\
         /// The commit's date, YYYYMMDD (0 if unknown).\n\
         pub const BUILD_DATE: u32 = {date};\n"
    );
    if let Err(e) = fs::write(out.join("identity.rs"), text) {
        println!("cargo::error=cannot write identity.rs to OUT_DIR: {e}");
    }
    println!("cargo:rerun-if-changed=../.git/HEAD");
    println!("cargo:rerun-if-changed=../.git/index");
}

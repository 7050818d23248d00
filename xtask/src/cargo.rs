//! Cargo runs that several subcommands need: one cargo command in the workspace, and the
//! `motorlink` binary the end-to-end sessions drive.

use std::path::{Path, PathBuf};
use std::process::Command;

/// Runs `cargo <args>` in `root` (the cargo that runs this xtask, else the one on the path).
pub fn cargo(root: &Path, args: &[&str]) -> Result<(), String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(&cargo)
        .args(args)
        .current_dir(root)
        .status()
        .map_err(|e| format!("cannot run cargo: {e}"))?;
    status
        .success()
        .then_some(())
        .ok_or_else(|| format!("cargo {} failed", args.join(" ")))
}

/// Builds `motorlink` and returns its path: the dev build, which `cargo test` has built already
/// (the release build is the same code).
pub fn motorlink(root: &Path) -> Result<PathBuf, String> {
    cargo(root, &["build", "-p", "motorlink"])?;
    Ok(root.join("target/debug/motorlink"))
}

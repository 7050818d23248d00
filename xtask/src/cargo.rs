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

/// The `motorlink` binary to drive: the one the environment variable `MOTORLINK` names if it is
/// set (`.ci/run` names the one `cargo test` built, whose dependencies' features are unified with
/// the tests', so that `cargo build -p motorlink` would rebuild them), else the dev build, built
/// here (the release build is the same code).
pub fn motorlink(root: &Path) -> Result<PathBuf, String> {
    if let Some(named) = std::env::var_os("MOTORLINK") {
        let path = root.join(named);
        return if path.is_file() {
            Ok(path)
        } else {
            Err(format!(
                "MOTORLINK names {}, which is not a file",
                path.display()
            ))
        };
    }
    cargo(root, &["build", "-p", "motorlink"])?;
    Ok(root.join("target/debug/motorlink"))
}

//! `cargo xtask ros-e2e`: `motorlink ros --sim` against an independent DDS implementation
//! (Eclipse Cyclone DDS's Python binding), run by `host/tests/ros/cmd_vel_odom.py`.
//!
//! RustDDS puts no locator on a loopback interface, and `lo` carries no multicast, so two
//! processes on 127.0.0.1 never discover each other. The test therefore builds a network of its
//! own: a network namespace `mlros` holding a veth pair with an address on each end, multicast on,
//! and the multicast range routed through it. Both the node and the Python side run inside it;
//! the namespace is deleted afterwards whatever happened. `ip netns` needs root: when not root,
//! every `ip` command goes through `sudo` (GitHub runners have password-less sudo) and the Python
//! side runs as the calling user again, with the same interpreter.
//!
//! `MOTORLINK_ROS_E2E_SKIP=1` skips the whole test with a message.

// A host-side test driver: an index out of range or an overflow here is a failed test run.
#![allow(clippy::indexing_slicing, clippy::arithmetic_side_effects)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// The namespace the test creates and deletes.
pub const NETNS: &str = "mlros";

/// Cyclone DDS on the namespace's veth1 (RustDDS uses every non-loopback interface).
const CYCLONE_CONFIG: &str = "<CycloneDDS><Domain Id=\"any\"><General><Interfaces>\
<NetworkInterface name=\"veth1\" multicast=\"true\"/></Interfaces></General></Domain></CycloneDDS>";

/// The commands that build the namespace's network, each run with `ip netns exec mlros` but
/// the first.
pub fn setup_commands() -> Vec<Vec<&'static str>> {
    vec![
        vec!["ip", "netns", "add", NETNS],
        vec!["ip", "link", "set", "lo", "up"],
        vec![
            "ip", "link", "add", "veth0", "type", "veth", "peer", "name", "veth1",
        ],
        vec!["ip", "addr", "add", "10.231.0.1/24", "dev", "veth0"],
        vec!["ip", "addr", "add", "10.231.0.2/24", "dev", "veth1"],
        vec!["ip", "link", "set", "veth0", "multicast", "on"],
        vec!["ip", "link", "set", "veth1", "multicast", "on"],
        vec!["ip", "link", "set", "veth0", "up"],
        vec!["ip", "link", "set", "veth1", "up"],
        vec!["ip", "route", "add", "224.0.0.0/4", "dev", "veth0"],
    ]
}

fn output(cmd: &str, args: &[&str]) -> Result<String, String> {
    let o = Command::new(cmd)
        .args(args)
        .output()
        .map_err(|e| format!("cannot run {cmd}: {e}"))?;
    if o.status.success() {
        Ok(String::from_utf8_lossy(&o.stdout).trim().to_string())
    } else {
        Err(format!(
            "{cmd} {} failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&o.stderr).trim()
        ))
    }
}

/// Runs `argv` as root (through `sudo -n` when not root already).
fn as_root(root: bool, argv: &[&str]) -> Result<(), String> {
    let (cmd, args): (&str, Vec<&str>) = if root {
        (argv[0], argv[1..].to_vec())
    } else {
        ("sudo", [&["-n"][..], argv].concat())
    };
    output(cmd, &args).map(|_| ())
}

/// The namespace, deleted when dropped.
struct Netns {
    root: bool,
}

impl Netns {
    fn create(root: bool) -> Result<Self, String> {
        // A namespace left over from an interrupted run goes first.
        let _ = as_root(root, &["ip", "netns", "del", NETNS]);
        let ns = Self { root };
        for (i, c) in setup_commands().iter().enumerate() {
            let argv: Vec<&str> = if i == 0 {
                c.clone()
            } else {
                [&["ip", "netns", "exec", NETNS][..], c].concat()
            };
            as_root(root, &argv)?;
        }
        Ok(ns)
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        match as_root(self.root, &["ip", "netns", "del", NETNS]) {
            Ok(()) => println!("network namespace {NETNS} deleted"),
            Err(e) => eprintln!("could not delete network namespace {NETNS}: {e}"),
        }
    }
}

/// The command line that runs `cmd` in the namespace with `env`: as is when root; when not
/// (`user` given), `ip netns exec` through `sudo -n`, then back to `user` inside.
pub fn check_argv(user: Option<&str>, env: &[String], cmd: &[&str]) -> Vec<String> {
    let mut argv: Vec<String> = Vec::new();
    if user.is_some() {
        argv.extend(["sudo".into(), "-n".into()]);
    }
    argv.extend(["ip", "netns", "exec", NETNS].map(String::from));
    if let Some(u) = user {
        // Back to the calling user inside the namespace: their Python and its packages.
        argv.extend(["sudo", "-n", "-u", u].map(String::from));
    }
    argv.push("env".into());
    argv.extend(env.iter().cloned());
    argv.extend(cmd.iter().map(|s| (*s).to_string()));
    argv
}

/// Takes motorlink (`crate::cargo::motorlink`: the one `MOTORLINK` names, else the dev build), runs
/// the Python check in the namespace; the summary or why it failed.
pub fn run(root_dir: &Path) -> Result<String, String> {
    if std::env::var("MOTORLINK_ROS_E2E_SKIP").is_ok_and(|v| v == "1") {
        return Ok("ros-e2e skipped (MOTORLINK_ROS_E2E_SKIP=1)".into());
    }
    let ml: PathBuf = crate::cargo::motorlink(root_dir)?;
    let script = root_dir.join("host/tests/ros/cmd_vel_odom.py");
    let python =
        output("sh", &["-c", "command -v python3"]).map_err(|_| "python3 not found".to_string())?;
    output(&python, &["-c", "import cyclonedds"]).map_err(|_| {
        format!("{python} cannot import cyclonedds: `{python} -m pip install cyclonedds` first")
    })?;
    let uid = output("id", &["-u"])?;
    let user = output("id", &["-un"])?;
    let is_root = uid == "0";
    let out_dir = root_dir.join("target/ros-e2e");
    std::fs::create_dir_all(&out_dir).map_err(|e| format!("{}: {e}", out_dir.display()))?;
    let log = out_dir.join("node.log");
    let ns = Netns::create(is_root)?;
    println!("network namespace {NETNS}: veth0 10.231.0.1/24, veth1 10.231.0.2/24, multicast routed via veth0");
    let env = [
        format!("PATH={}", std::env::var("PATH").unwrap_or_default()),
        format!("HOME={}", std::env::var("HOME").unwrap_or_default()),
        format!("CYCLONEDDS_URI={CYCLONE_CONFIG}"),
    ];
    let argv = check_argv(
        (!is_root).then_some(user.as_str()),
        &env,
        &[
            python.as_str(),
            &script.display().to_string(),
            "--motorlink",
            &ml.display().to_string(),
            "--log",
            &log.display().to_string(),
        ],
    );
    println!("running {}", script.display());
    let status = Command::new(&argv[0])
        .args(&argv[1..])
        .current_dir(root_dir)
        .status()
        .map_err(|e| format!("cannot run {}: {e}", argv[0]));
    drop(ns);
    let status = status?;
    if status.success() {
        Ok(format!(
            "ros-e2e: passed (node output in {})",
            log.display()
        ))
    } else {
        let tail = std::fs::read_to_string(&log).unwrap_or_default();
        let last: Vec<&str> = tail.lines().rev().take(20).collect();
        let last: Vec<&str> = last.into_iter().rev().collect();
        Err(format!(
            "the check failed ({status}); last lines of the node's output ({}):\n{}",
            log.display(),
            last.join("\n")
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn as_root_the_check_runs_in_the_namespace_directly() {
        let a = check_argv(None, &["A=1".into()], &["python3", "t.py"]);
        assert_eq!(
            a,
            ["ip", "netns", "exec", NETNS, "env", "A=1", "python3", "t.py"]
        );
    }

    /// A GitHub runner is not root: sudo for the namespace, then the runner's user again inside,
    /// so the check runs with the Python (and cyclonedds) of the user who started it.
    #[test]
    fn as_a_user_the_namespace_goes_through_sudo_and_back() {
        let a = check_argv(Some("runner"), &["A=1".into()], &["python3", "t.py"]);
        assert_eq!(
            a,
            [
                "sudo", "-n", "ip", "netns", "exec", NETNS, "sudo", "-n", "-u", "runner", "env",
                "A=1", "python3", "t.py"
            ]
        );
    }

    #[test]
    fn the_namespace_is_created_first_and_multicast_is_routed() {
        let c = setup_commands();
        assert_eq!(c[0], ["ip", "netns", "add", NETNS]);
        assert!(c
            .iter()
            .any(|a| a[..] == ["ip", "route", "add", "224.0.0.0/4", "dev", "veth0"]));
        // Both ends carry multicast and are up.
        for end in ["veth0", "veth1"] {
            assert!(c
                .iter()
                .any(|a| a[..] == ["ip", "link", "set", end, "multicast", "on"]));
            assert!(c.iter().any(|a| a[..] == ["ip", "link", "set", end, "up"]));
        }
    }
}

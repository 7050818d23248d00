//! `cargo xtask fuzz [--seconds N] [--runs N] [--jobs J] [--merge] [--toolchain T] [TARGET…]`:
//! runs every bolero fuzz target of the workspace coverage-guided (libFuzzer) for the given budget
//! and prints one table row per target: executions, executions per second, libFuzzer's coverage
//! (`cov`, edges, and `ft`, features), the corpus it reached, the committed corpus, and the result.
//!
//! The targets are ordinary `cargo test` functions (`bolero::check!`), so `cargo test` runs them in
//! random mode; here each test binary is built with libFuzzer's instrumentation the way
//! `cargo bolero test --engine libfuzzer` builds it, with two differences: no sanitizer (the
//! targets are `#![forbid(unsafe_code)]` crates; a panic or an overflow, checked in every profile
//! of the workspace, is the finding), and only the test binary that holds the target is built, so
//! the package's other test binaries need no libFuzzer runtime. The release profile is used with
//! fat LTO off (LTO removes libFuzzer's coverage counters at link time) and opt-level 3.
//!
//! Each target reads its committed corpus (bolero's location,
//! `<package>/tests/__fuzz__/<target without fuzz_>/corpus/`, which `cargo test` replays) and writes what it
//! finds to a working corpus under `target/fuzz/corpus/<target>/`; `--merge` then minimises both
//! into the committed corpus (libFuzzer `-merge=1 -use_counters=0`: only inputs that reach a new
//! edge are kept, so the committed corpus stays small; the working corpus keeps the rest). A
//! failing input goes to `target/fuzz/crashes/<target>/` and the row says FINDING.
#![allow(clippy::indexing_slicing, clippy::arithmetic_side_effects)]

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// One fuzz target: a bolero test function in an integration-test file of a package.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Target {
    /// The package (and its directory under the workspace root).
    pub package: &'static str,
    /// The integration-test file under `<package>/tests/`, without `.rs`.
    pub test: &'static str,
    /// The test function.
    pub name: &'static str,
    /// libFuzzer's `-max_len`: the target's own `with_max_len` (bolero's libFuzzer engine does not
    /// pass it on, and longer inputs only cost time), at least the bytes the target reads.
    pub max_len: usize,
}

const fn t(
    package: &'static str,
    test: &'static str,
    name: &'static str,
    max_len: usize,
) -> Target {
    Target {
        package,
        test,
        name,
        max_len,
    }
}

/// Every fuzz target of the workspace.
pub const TARGETS: [Target; 9] = [
    // amr::FRAME_LEN
    t("protocol", "fuzz", "fuzz_amr_command", 64),
    t("protocol", "fuzz", "fuzz_amr_feedback", 64),
    t("protocol", "fuzz", "fuzz_amr_info", 64),
    // 2 × cdc::MAX_FRAME_LEN
    t("protocol", "fuzz", "fuzz_cdc", 522),
    t(
        "protocol",
        "fuzz",
        "fuzz_cdc_stream_holds_back_no_frame",
        64,
    ),
    // 3 × teensy::ROBUST_BUF
    t("protocol", "fuzz", "fuzz_teensy", 270),
    t(
        "protocol",
        "fuzz",
        "fuzz_teensy_stream_holds_back_no_frame",
        64,
    ),
    // at least pi_spi::TRANSFER_LEN (the larger buffer)
    t("protocol", "fuzz", "fuzz_pi_spi", 512),
    t(
        "statemachine",
        "fuzz_ladder",
        "fuzz_ladder_against_model",
        256,
    ),
];

/// The instrumentation `cargo bolero` 0.13.5 passes for libFuzzer, without a sanitizer.
const RUSTFLAGS: &str = "--cfg fuzzing -Cpasses=sancov-module --cfg fuzzing_libfuzzer \
    -Cllvm-args=-sanitizer-coverage-inline-8bit-counters -Cllvm-args=-sanitizer-coverage-level=4 \
    -Cllvm-args=-sanitizer-coverage-pc-table -Cllvm-args=-sanitizer-coverage-trace-compares \
    -Cllvm-args=-sanitizer-coverage-stack-depth";

/// The command line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Options {
    /// Time budget per target (libFuzzer `-max_total_time`).
    pub seconds: u64,
    /// Execution budget per target (libFuzzer `-runs`), if any.
    pub runs: Option<u64>,
    /// Targets run at once.
    pub jobs: usize,
    /// Minimise the working and committed corpora into the committed one afterwards.
    pub merge: bool,
    /// The rustup toolchain that builds the instrumented binaries.
    pub toolchain: String,
    /// The targets to run (all if empty).
    pub only: Vec<String>,
}

/// The nightly toolchain the instrumented binaries are built with unless `--toolchain` says
/// otherwise: a dated one, so that a campaign's figures (proofs/REPORT.md, "Fuzzing") can be
/// rerun on the same compiler and the same libFuzzer instrumentation passes. Install it with
/// `rustup toolchain install nightly-2026-05-20 --profile minimal`.
pub const NIGHTLY: &str = "nightly-2026-05-20";

/// The usage line of `cargo xtask fuzz`.
pub const USAGE: &str = "cargo xtask fuzz [--seconds N (60)] [--runs N] [--jobs J (1)] [--merge] \
    [--toolchain T (nightly-2026-05-20)] [TARGET...]";

/// `cargo xtask fuzz --help`.
pub const HELP: &str = "Runs every bolero fuzz target coverage-guided (libFuzzer, no sanitizer, the release
profile without fat LTO) and prints executions, exec/s, coverage (cov, ft) and corpus size per target.

Options:
  --seconds N     time budget per target (default 60)
  --runs N        execution budget per target (default: none)
  --jobs J        targets run at once (default 1)
  --merge         minimise what the run found into the committed corpora
                  (<crate>/tests/__fuzz__/<target>/corpus/, one input per edge)
  --toolchain T   rustup toolchain that builds the instrumented binaries
                  (default nightly-2026-05-20, the pinned one)
  TARGET...       run only these targets (default: all)

Exit status: 0 if every target ran without a finding, 1 otherwise, 64 for a usage error.
Logs: target/fuzz/logs/<target>.log; a failing input: target/fuzz/crashes/<target>/.";

/// Reads the arguments after `fuzz`.
pub fn parse_args(args: &[String]) -> Result<Options, String> {
    let mut o = Options {
        seconds: 60,
        runs: None,
        jobs: 1,
        merge: false,
        toolchain: NIGHTLY.to_string(),
        only: Vec::new(),
    };
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = |what: &str| {
            it.next()
                .cloned()
                .ok_or_else(|| format!("{a} needs {what}"))
        };
        let number = |v: String| {
            v.parse::<u64>()
                .map_err(|_| format!("{a}: `{v}` is not a whole number"))
        };
        match a.as_str() {
            "--seconds" => o.seconds = number(value("a number of seconds")?)?,
            "--runs" => o.runs = Some(number(value("a number of executions")?)?),
            "--jobs" => {
                o.jobs = usize::try_from(number(value("a number of targets")?)?)
                    .map_err(|_| format!("{a}: too large"))?
                    .max(1);
            }
            "--toolchain" => o.toolchain = value("a rustup toolchain name")?,
            "--merge" => o.merge = true,
            name if !name.starts_with('-') => {
                if !TARGETS.iter().any(|t| t.name == name) {
                    let names: Vec<&str> = TARGETS.iter().map(|t| t.name).collect();
                    return Err(format!(
                        "no fuzz target `{name}`; the targets: {}",
                        names.join(", ")
                    ));
                }
                o.only.push(name.to_string());
            }
            other => return Err(format!("unknown option `{other}`")),
        }
    }
    Ok(o)
}

/// What libFuzzer reported for one run.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Stats {
    /// `stat::number_of_executed_units`.
    pub executions: Option<u64>,
    /// `stat::average_exec_per_sec`.
    pub exec_per_sec: Option<u64>,
    /// `cov:` of the last status line: edges covered.
    pub cov: Option<u64>,
    /// `ft:` of the last status line: features (edges with hit counts, compared values).
    pub ft: Option<u64>,
    /// `corp:` of the last status line: inputs in the corpus in memory.
    pub corpus: Option<u64>,
}

fn field(line: &str, key: &str) -> Option<u64> {
    let rest = &line[line.find(key)? + key.len()..];
    let word = rest.split_whitespace().next()?;
    word.split('/').next()?.parse().ok()
}

/// Reads libFuzzer's output (its status lines and `-print_final_stats=1`).
pub fn parse_libfuzzer(text: &str) -> Stats {
    let mut s = Stats::default();
    for line in text.lines() {
        if let Some(v) = line.strip_prefix("stat::number_of_executed_units:") {
            s.executions = v.trim().parse().ok();
        } else if let Some(v) = line.strip_prefix("stat::average_exec_per_sec:") {
            s.exec_per_sec = v.trim().parse().ok();
        } else if line.starts_with('#') && line.contains(" cov: ") {
            s.cov = field(line, " cov: ").or(s.cov);
            s.ft = field(line, " ft: ").or(s.ft);
            s.corpus = field(line, " corp: ").or(s.corpus);
        }
    }
    s
}

/// One row of the table.
#[derive(Clone, Debug)]
pub struct Row {
    /// The target.
    pub target: Target,
    /// libFuzzer's figures.
    pub stats: Stats,
    /// Files in the committed corpus after the run (and the merge).
    pub committed: usize,
    /// "no finding", or what went wrong.
    pub result: String,
    /// True if the run ended cleanly.
    pub ok: bool,
}

fn num(v: Option<u64>) -> String {
    v.map_or("–".to_string(), |n| {
        let s = n.to_string();
        let mut out = String::new();
        for (i, c) in s.chars().enumerate() {
            if i > 0 && (s.len() - i) % 3 == 0 {
                out.push(',');
            }
            out.push(c);
        }
        out
    })
}

/// The Markdown table of `rows`, with the total of executions.
pub fn table(rows: &[Row]) -> String {
    let mut out = String::from(
        "| target | executions | exec/s | cov | ft | corpus (run) | corpus (committed) | result |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    let mut total = 0u64;
    for r in rows {
        total = total.saturating_add(r.stats.executions.unwrap_or(0));
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {} | {} | {} | {} | {} |",
            r.target.name,
            num(r.stats.executions),
            num(r.stats.exec_per_sec),
            num(r.stats.cov),
            num(r.stats.ft),
            num(r.stats.corpus),
            r.committed,
            r.result
        );
    }
    let _ = writeln!(out, "| total | {} | | | | | | |", num(Some(total)));
    out
}

fn cargo(opts: &Options) -> Command {
    let mut c = Command::new("rustup");
    c.args(["run", &opts.toolchain, "cargo"]);
    for var in [
        "CARGO",
        "RUSTC",
        "RUSTDOC",
        "RUSTC_WRAPPER",
        "RUSTUP_TOOLCHAIN",
    ] {
        c.env_remove(var);
    }
    c
}

/// Builds the instrumented test binary of `package`'s `tests/<test>.rs`; returns its path.
fn build(root: &Path, opts: &Options, package: &str, test: &str) -> Result<PathBuf, String> {
    let out = cargo(opts)
        .current_dir(root)
        .args([
            "test",
            "-p",
            package,
            "--test",
            test,
            "--profile",
            "release",
        ])
        .args(["--target", "x86_64-unknown-linux-gnu", "--no-run"])
        .args([
            "--message-format",
            "json-render-diagnostics",
            "--target-dir",
        ])
        .arg(root.join("target").join("fuzz").join("build"))
        .env("RUSTFLAGS", RUSTFLAGS)
        .env("RUSTDOCFLAGS", RUSTFLAGS)
        .env("BOLERO_FUZZER", "libfuzzer")
        .env("CARGO_PROFILE_RELEASE_LTO", "false")
        .env("CARGO_PROFILE_RELEASE_OPT_LEVEL", "3")
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| format!("cannot run rustup ({e}); is rustup installed?"))?;
    if !out.status.success() {
        return Err(format!(
            "building {package}'s tests/{test}.rs for libFuzzer failed ({}); is the `{}` toolchain \
             installed (`rustup toolchain install {} --profile minimal`)?",
            out.status, opts.toolchain, opts.toolchain
        ));
    }
    test_executable(&String::from_utf8_lossy(&out.stdout), test)
        .ok_or_else(|| format!("cargo named no executable for {package}'s tests/{test}.rs"))
}

/// The test binary of the integration-test file `test` that cargo's JSON messages
/// (`--message-format json…`, one message a line) name.
pub fn test_executable(messages: &str, test: &str) -> Option<PathBuf> {
    let name_key = format!("\"name\":\"{test}\"");
    messages
        .lines()
        .filter(|l| l.contains("\"reason\":\"compiler-artifact\"") && l.contains(&name_key))
        .find_map(|l| {
            let rest = &l[l.find("\"executable\":\"")? + "\"executable\":\"".len()..];
            Some(PathBuf::from(&rest[..rest.find('"')?]))
        })
}

/// Runs the instrumented binary `exe` on `target` with libFuzzer arguments `args`; returns its
/// exit status and its output (libFuzzer writes to stderr).
fn libfuzzer(
    exe: &Path,
    target: &Target,
    dir: &Path,
    args: &[String],
) -> Result<(bool, String), String> {
    let out = Command::new(exe)
        .args([target.name, "--exact", "--nocapture", "--quiet"])
        .args(["--test-threads", "1"])
        .current_dir(dir)
        .env("BOLERO_TEST_NAME", target.name)
        .env("BOLERO_LIBTEST_HARNESS", "1")
        .env("BOLERO_LIBFUZZER_ARGS", args.join(" "))
        .output()
        .map_err(|e| format!("cannot run {}: {e}", exe.display()))?;
    let mut text = String::from_utf8_lossy(&out.stderr).into_owned();
    text.push_str(&String::from_utf8_lossy(&out.stdout));
    Ok((out.status.success(), text))
}

/// The committed corpus of `target`: bolero's own location,
/// `<package>/tests/__fuzz__/<target without its fuzz_ prefix>/corpus/`, which `cargo test`
/// replays before its random inputs.
pub fn committed_corpus(root: &Path, target: &Target) -> PathBuf {
    let dir = target.name.strip_prefix("fuzz_").unwrap_or(target.name);
    root.join(target.package)
        .join("tests")
        .join("__fuzz__")
        .join(dir)
        .join("corpus")
}

fn files_in(dir: &Path) -> usize {
    std::fs::read_dir(dir).map_or(0, |d| d.filter(|e| e.is_ok()).count())
}

fn path_arg(p: &Path) -> Result<String, String> {
    let s = p.display().to_string();
    if s.contains(char::is_whitespace) {
        return Err(format!(
            "{s}: libFuzzer's arguments are split at spaces; use a path without them"
        ));
    }
    Ok(s)
}

/// Fuzzes one target and, with `--merge`, minimises its corpora into the committed one.
fn run_one(root: &Path, opts: &Options, exe: &Path, target: &Target) -> Result<Row, String> {
    let pkg = root.join(target.package);
    let committed = committed_corpus(root, target);
    let fuzz = root.join("target").join("fuzz");
    let work = fuzz.join("corpus").join(target.name);
    let crashes = fuzz.join("crashes").join(target.name);
    for d in [&committed, &work, &crashes] {
        std::fs::create_dir_all(d).map_err(|e| format!("{}: {e}", d.display()))?;
    }
    let mut args = vec![
        path_arg(&work)?,
        path_arg(&committed)?,
        format!("-artifact_prefix={}/", path_arg(&crashes)?),
        format!("-max_total_time={}", opts.seconds),
        format!("-max_len={}", target.max_len),
        "-print_final_stats=1".to_string(),
    ];
    if let Some(r) = opts.runs {
        args.push(format!("-runs={r}"));
    }
    let (ok, text) = libfuzzer(exe, target, &pkg, &args)?;
    let logs = fuzz.join("logs");
    std::fs::create_dir_all(&logs).map_err(|e| format!("{}: {e}", logs.display()))?;
    let log = logs.join(format!("{}.log", target.name));
    std::fs::write(&log, &text).map_err(|e| format!("{}: {e}", log.display()))?;
    let stats = parse_libfuzzer(&text);
    let result = if ok {
        "no finding".to_string()
    } else {
        format!(
            "**FINDING** (input in {}, log {})",
            crashes.display(),
            log.display()
        )
    };
    if ok && opts.merge {
        let fresh = fuzz.join("merged").join(target.name);
        let _ = std::fs::remove_dir_all(&fresh);
        std::fs::create_dir_all(&fresh).map_err(|e| format!("{}: {e}", fresh.display()))?;
        let merge = vec![
            "-merge=1".to_string(),
            // One input per edge, not per hit-count bucket: the committed corpus stays at a few
            // hundred inputs and still reaches every edge the run reached.
            "-use_counters=0".to_string(),
            path_arg(&fresh)?,
            path_arg(&committed)?,
            path_arg(&work)?,
        ];
        let (merged, mtext) = libfuzzer(exe, target, &pkg, &merge)?;
        if !merged || files_in(&fresh) == 0 {
            return Err(format!(
                "{}: the corpus merge failed:\n{mtext}",
                target.name
            ));
        }
        std::fs::remove_dir_all(&committed).map_err(|e| format!("{}: {e}", committed.display()))?;
        std::fs::rename(&fresh, &committed).map_err(|e| format!("{}: {e}", committed.display()))?;
    }
    Ok(Row {
        target: *target,
        stats,
        committed: files_in(&committed),
        result,
        ok,
    })
}

/// Builds and runs the selected targets; returns the table and whether every run was clean.
pub fn run(root: &Path, opts: &Options) -> Result<(String, bool), String> {
    let targets: Vec<Target> = TARGETS
        .iter()
        .filter(|t| opts.only.is_empty() || opts.only.iter().any(|n| n == t.name))
        .copied()
        .collect();
    let mut exes: Vec<((&str, &str), PathBuf)> = Vec::new();
    for t in &targets {
        if !exes.iter().any(|(k, _)| *k == (t.package, t.test)) {
            let exe = build(root, opts, t.package, t.test)?;
            exes.push(((t.package, t.test), exe));
        }
    }
    let next = AtomicUsize::new(0);
    let rows: Mutex<Vec<(usize, Result<Row, String>)>> = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..opts.jobs.min(targets.len()) {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(t) = targets.get(i) else { break };
                let Some((_, exe)) = exes.iter().find(|(k, _)| *k == (t.package, t.test)) else {
                    break;
                };
                eprintln!("xtask fuzz: {} for {} s ...", t.name, opts.seconds);
                let r = run_one(root, opts, exe, t);
                if let Ok(mut v) = rows.lock() {
                    v.push((i, r));
                }
            });
        }
    });
    let mut rows = rows
        .into_inner()
        .map_err(|_| "a fuzz job failed".to_string())?;
    rows.sort_by_key(|(i, _)| *i);
    let mut done = Vec::new();
    for (_, r) in rows {
        done.push(r?);
    }
    let ok = done.len() == targets.len() && done.iter().all(|r| r.ok);
    Ok((table(&done), ok))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn reads_libfuzzer_figures() {
        let text = "INFO: Seed: 1\n#2\tINITED cov: 12 ft: 13 corp: 1/1b exec/s: 0 rss: 30Mb\n\
            #4096\tpulse  cov: 607 ft: 2736 corp: 425/12Kb lim: 64 exec/s: 1424 rss: 51Mb\n\
            #1282756\tDONE   cov: 610 ft: 2740 corp: 430/13Kb lim: 64 exec/s: 1423 rss: 51Mb\n\
            Done 1282756 runs in 901 second(s)\n\
            stat::number_of_executed_units: 1282756\nstat::average_exec_per_sec:     1423\n\
            stat::new_units_added:          9\n";
        let s = parse_libfuzzer(text);
        assert_eq!(
            s,
            Stats {
                executions: Some(1_282_756),
                exec_per_sec: Some(1423),
                cov: Some(610),
                ft: Some(2740),
                corpus: Some(430),
            }
        );
        let row = Row {
            target: TARGETS[0],
            stats: s,
            committed: 17,
            result: "no finding".into(),
            ok: true,
        };
        let t = table(&[row]);
        assert!(
            t.contains(
                "| `fuzz_amr_command` | 1,282,756 | 1,423 | 610 | 2,740 | 430 | 17 | no finding |"
            ),
            "{t}"
        );
        assert!(t.contains("| total | 1,282,756 |"), "{t}");
    }

    #[test]
    fn a_run_that_printed_nothing_has_no_figures() {
        assert_eq!(parse_libfuzzer("thread panicked\n"), Stats::default());
    }

    #[test]
    fn arguments_are_checked() {
        let a = |v: &[&str]| parse_args(&v.iter().map(|s| s.to_string()).collect::<Vec<_>>());
        let o = a(&[
            "--seconds",
            "30",
            "--runs",
            "1000",
            "--jobs",
            "2",
            "fuzz_cdc",
        ])
        .unwrap();
        assert_eq!((o.seconds, o.runs, o.jobs), (30, Some(1000), 2));
        assert_eq!(o.only, vec!["fuzz_cdc".to_string()]);
        assert!(a(&["--seconds", "x"])
            .unwrap_err()
            .contains("not a whole number"));
        assert!(a(&["--seconds"]).unwrap_err().contains("needs"));
        assert!(a(&["nope"]).unwrap_err().contains("no fuzz target `nope`"));
        assert!(a(&["--fast"]).unwrap_err().contains("unknown option"));
    }

    #[test]
    fn every_target_is_a_test_of_its_file() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
        for t in TARGETS {
            let file = root
                .join(t.package)
                .join("tests")
                .join(format!("{}.rs", t.test));
            let src = std::fs::read_to_string(&file).unwrap();
            assert!(
                src.contains(&format!("fn {}()", t.name)),
                "{} in {}",
                t.name,
                file.display()
            );
        }
    }
}

//! `cargo xtask fuzz-coverage [TARGET…]`: the source coverage that each fuzz target's committed
//! corpus reaches in the production code the target exercises, one Markdown table per target.
//!
//! `cargo xtask fuzz` prints libFuzzer's `cov` and `ft`: edge counts of one instrumented binary
//! that holds every target of its test file, with no per-file total, so they say whether a run
//! found something new, not how much of a decoder the corpus reaches. This command answers the
//! latter with LLVM's source-based coverage:
//!
//! 1. each test binary that holds a selected target is built with `-C instrument-coverage` (the
//!    repository's toolchain, the dev profile, `RUSTFLAGS` set for this build only) into a target
//!    directory of its own, `target/fuzz-coverage/build/`;
//! 2. each target runs alone, in bolero's test mode, with `BOLERO_RANDOM_ITERATIONS=0`: bolero
//!    then replays the files of the target's committed corpus
//!    (`<package>/tests/__fuzz__/<target without fuzz_>/corpus/`) and generates no random input
//!    (the variable overrides the target's own `with_iterations`); the target's own count of
//!    executions, printed beside the corpus size, shows it. Its profile goes to
//!    `target/fuzz-coverage/profiles/<target>.profraw`;
//! 3. `llvm-profdata merge` indexes the profile, and `llvm-cov export` (its `-summary-only` JSON
//!    for regions and lines, its lcov output for the line numbers) reports it for the production
//!    files of [`files`] only: the decoder's module and the modules it calls, never a `tests` or
//!    `verification` module (those are not compiled into an integration test anyway) nor
//!    `statemachine::harness`.
//!
//! The table gives, per file, regions and lines covered of the total and the number of lines not
//! executed (from the summary); the line numbers, from the lcov output, go to
//! `target/fuzz-coverage/uncovered/<target>.txt` (llvm-cov's lcov records omit a few lines that its
//! summary counts, so that list can be a line or two shorter than the count).
//! `llvm-profdata` and `llvm-cov` are those of the `llvm-tools` rustup component
//! (`rustup component add llvm-tools`; the repository's toolchain file and `.ci/run` install it),
//! found in `$(rustc --print sysroot)/lib/rustlib/<host>/bin/`.
#![allow(clippy::arithmetic_side_effects)]

use crate::fuzz::{committed_corpus, test_executable, Target, TARGETS};
use serde_json::Value;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// The usage line of `cargo xtask fuzz-coverage`.
pub const USAGE: &str = "cargo xtask fuzz-coverage [TARGET...]";

/// `cargo xtask fuzz-coverage --help`.
pub const HELP: &str = "Builds the fuzz targets' test binaries with -C instrument-coverage, replays only each
target's committed corpus (BOLERO_RANDOM_ITERATIONS=0) and prints, per target, the regions and lines of
the production files it exercises that the corpus reaches (llvm-cov).

  TARGET...   report only these targets (default: all)

Needs the llvm-tools component (rustup component add llvm-tools).
Output: target/fuzz-coverage/ (build/, profiles/, uncovered/<target>.txt: the uncovered line numbers).";

/// The production source files (relative to the workspace root) whose code `target` calls: the
/// decoder's module and the modules it uses. Empty for a name that is no target.
pub fn files(target: &str) -> &'static [&'static str] {
    match target {
        "fuzz_amr_command" | "fuzz_amr_feedback" | "fuzz_amr_info" => &[
            "protocol/src/amr.rs",
            "protocol/src/pb.rs",
            "protocol/src/crc16.rs",
        ],
        // The targets decode and encode frames; they do not turn a frame into a ladder command,
        // the only path into statemachine's code.
        "fuzz_cdc" | "fuzz_cdc_stream_holds_back_no_frame" => &[
            "protocol/src/cdc.rs",
            "protocol/src/crc16.rs",
            "protocol/src/le.rs",
        ],
        "fuzz_teensy" | "fuzz_teensy_stream_holds_back_no_frame" => &[
            "protocol/src/teensy.rs",
            "protocol/src/crc16.rs",
            "protocol/src/le.rs",
        ],
        "fuzz_pi_spi" => &[
            "protocol/src/pi_spi.rs",
            "protocol/src/pi_spi/assumed.rs",
            "protocol/src/le.rs",
        ],
        "fuzz_ladder_against_model" => &[
            "statemachine/src/ladder.rs",
            "statemachine/src/validate.rs",
            "statemachine/src/config.rs",
            "statemachine/src/types.rs",
        ],
        _ => &[],
    }
}

/// Reads the arguments after `fuzz-coverage`: the targets to report (all if none).
pub fn parse_args(args: &[String]) -> Result<Vec<String>, String> {
    let mut only = Vec::new();
    for a in args {
        if a.starts_with('-') {
            return Err(format!("unknown option `{a}`"));
        }
        if !TARGETS.iter().any(|t| t.name == a) {
            let names: Vec<&str> = TARGETS.iter().map(|t| t.name).collect();
            return Err(format!(
                "no fuzz target `{a}`; the targets: {}",
                names.join(", ")
            ));
        }
        only.push(a.clone());
    }
    Ok(only)
}

/// Covered and total of one kind of coverage item (regions or lines).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Count {
    /// Items executed at least once.
    pub covered: u64,
    /// Items in the file.
    pub total: u64,
}

/// What `llvm-cov export -summary-only` says of one file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FileSummary {
    /// The file as llvm-cov names it (an absolute path for the workspace's files).
    pub file: String,
    /// Code regions.
    pub regions: Count,
    /// Lines with code.
    pub lines: Count,
}

fn count(summary: &Value, kind: &str) -> Option<Count> {
    let k = summary.get(kind)?;
    Some(Count {
        covered: k.get("covered")?.as_u64()?,
        total: k.get("count")?.as_u64()?,
    })
}

/// Reads the per-file summaries of `llvm-cov export -summary-only` (`data[0].files[]`).
pub fn parse_summary(json: &str) -> Result<Vec<FileSummary>, String> {
    let doc: Value =
        serde_json::from_str(json).map_err(|e| format!("llvm-cov's summary is not JSON: {e}"))?;
    let Some(files) = doc
        .get("data")
        .and_then(|d| d.get(0))
        .and_then(|d| d.get("files"))
        .and_then(Value::as_array)
    else {
        return Err("llvm-cov's summary has no data[0].files".into());
    };
    files
        .iter()
        .map(|f| {
            let Some(file) = f.get("filename").and_then(Value::as_str) else {
                return Err("a file of llvm-cov's summary has no filename".to_string());
            };
            let summary = f.get("summary");
            let regions = summary.and_then(|s| count(s, "regions"));
            let lines = summary.and_then(|s| count(s, "lines"));
            match (regions, lines) {
                (Some(regions), Some(lines))
                    if regions.covered <= regions.total && lines.covered <= lines.total =>
                {
                    Ok(FileSummary {
                        file: file.to_string(),
                        regions,
                        lines,
                    })
                }
                _ => Err(format!(
                    "{file}: llvm-cov's summary has no valid region and line counts"
                )),
            }
        })
        .collect()
}

/// The lines of each file that have code and were not executed, from lcov text
/// (`llvm-cov export -format=lcov`: `SF:<file>`, then `DA:<line>,<count>` per line), in order.
pub fn uncovered_lines(lcov: &str) -> Result<Vec<(String, Vec<u32>)>, String> {
    let mut out: Vec<(String, Vec<u32>)> = Vec::new();
    for line in lcov.lines() {
        if let Some(file) = line.strip_prefix("SF:") {
            out.push((file.to_string(), Vec::new()));
        } else if let Some(da) = line.strip_prefix("DA:") {
            let mut parts = da.split(',');
            let (Some(n), Some(hits)) = (parts.next(), parts.next()) else {
                return Err(format!("lcov: bad line `{line}`"));
            };
            let n: u32 = n.parse().map_err(|_| format!("lcov: bad line `{line}`"))?;
            let hits: u64 = hits
                .parse()
                .map_err(|_| format!("lcov: bad line `{line}`"))?;
            let Some((_, lines)) = out.last_mut() else {
                return Err(format!("lcov: `{line}` before any SF: record"));
            };
            if hits == 0 {
                lines.push(n);
            }
        }
    }
    Ok(out)
}

/// `lines` (ascending) as ranges: `3-4, 7`.
pub fn ranges(lines: &[u32]) -> String {
    let mut out = String::new();
    let mut i = 0;
    while let Some(&start) = lines.get(i) {
        let mut end = start;
        while lines.get(i + 1) == end.checked_add(1).as_ref() {
            end += 1;
            i += 1;
        }
        if !out.is_empty() {
            out.push_str(", ");
        }
        if end == start {
            let _ = write!(out, "{start}");
        } else {
            let _ = write!(out, "{start}-{end}");
        }
        i += 1;
    }
    out
}

/// `covered/total` as a percentage with one decimal, rounded half up (`–` for no items).
pub fn percent(c: Count) -> String {
    if c.total == 0 {
        return "–".into();
    }
    let tenths = (c.covered * 2000 + c.total) / (c.total * 2);
    format!("{}.{} %", tenths / 10, tenths % 10)
}

/// One file's row: its summary, and the uncovered lines the lcov output lists for it. llvm-cov's
/// lcov export (LLVM 22 of Rust 1.95) omits a few lines that its summary counts (3 of amr.rs's 344, for one), so the
/// counts come from the summary and the line numbers from lcov.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FileRow {
    /// The file, relative to the workspace root.
    pub file: String,
    /// Regions and lines.
    pub summary: FileSummary,
    /// Lines with code not executed.
    pub uncovered: Vec<u32>,
}

/// The Markdown table of one target's rows, with a total row.
pub fn table(rows: &[FileRow]) -> String {
    let mut out = String::from(
        "| file | regions covered/total | regions | lines covered/total | lines | uncovered lines |\n\
         |---|---|---|---|---|---|\n",
    );
    let mut regions = Count::default();
    let mut lines = Count::default();
    let mut uncovered = 0u64;
    for r in rows {
        let s = &r.summary;
        regions.covered += s.regions.covered;
        regions.total += s.regions.total;
        lines.covered += s.lines.covered;
        lines.total += s.lines.total;
        uncovered += s.lines.total - s.lines.covered;
        let _ = writeln!(
            out,
            "| `{}` | {}/{} | {} | {}/{} | {} | {} |",
            r.file,
            s.regions.covered,
            s.regions.total,
            percent(s.regions),
            s.lines.covered,
            s.lines.total,
            percent(s.lines),
            s.lines.total - s.lines.covered
        );
    }
    let _ = writeln!(
        out,
        "| total | {}/{} | {} | {}/{} | {} | {uncovered} |",
        regions.covered,
        regions.total,
        percent(regions),
        lines.covered,
        lines.total,
        percent(lines)
    );
    out
}

/// The number of executions a target reports at its end (`fuzz <name>: <n> executions…`).
pub fn executions(output: &str) -> Option<u64> {
    output.lines().find_map(|l| {
        let (_, rest) = l.strip_prefix("fuzz ")?.split_once(": ")?;
        rest.split_once(" executions")?.0.parse().ok()
    })
}

fn output_of(cmd: &mut Command, what: &str) -> Result<std::process::Output, String> {
    cmd.output().map_err(|e| format!("cannot run {what}: {e}"))
}

/// The host's target triple and the directory of the `llvm-tools` component's binaries, for the
/// repository's toolchain.
fn llvm_tools(root: &Path) -> Result<(String, PathBuf), String> {
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let run = |args: &[&str]| -> Result<String, String> {
        let out = output_of(Command::new(&rustc).args(args).current_dir(root), "rustc")?;
        if !out.status.success() {
            return Err(format!("rustc {} failed ({})", args.join(" "), out.status));
        }
        Ok(String::from_utf8_lossy(&out.stdout).trim().to_string())
    };
    let sysroot = run(&["--print", "sysroot"])?;
    let version = run(&["-vV"])?;
    let host = version
        .lines()
        .find_map(|l| l.strip_prefix("host: "))
        .ok_or("rustc -vV names no host")?
        .to_string();
    let bin = Path::new(&sysroot)
        .join("lib")
        .join("rustlib")
        .join(&host)
        .join("bin");
    for tool in ["llvm-profdata", "llvm-cov"] {
        if !bin.join(tool).is_file() {
            return Err(format!(
                "{} is missing: install the llvm-tools component (`rustup component add llvm-tools`)",
                bin.join(tool).display()
            ));
        }
    }
    Ok((host, bin))
}

/// Builds `package`'s `tests/<test>.rs` with coverage instrumentation for `host`; returns the
/// test binary. With `--target`, `RUSTFLAGS` instruments the test and the crates it links, not
/// build scripts and procedural macros.
fn build(root: &Path, host: &str, package: &str, test: &str) -> Result<PathBuf, String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.current_dir(root)
        .args(["test", "-p", package, "--test", test, "--no-run"])
        .args(["--target", host])
        .args([
            "--message-format",
            "json-render-diagnostics",
            "--target-dir",
        ])
        .arg(root.join("target").join("fuzz-coverage").join("build"))
        // Cargo prefers the encoded variable to RUSTFLAGS; it must not replace the instrumentation.
        .env_remove("CARGO_ENCODED_RUSTFLAGS")
        .env("RUSTFLAGS", "-C instrument-coverage")
        .stderr(Stdio::inherit());
    let out = output_of(&mut cmd, "cargo")?;
    if !out.status.success() {
        return Err(format!(
            "building {package}'s tests/{test}.rs with coverage instrumentation failed ({})",
            out.status
        ));
    }
    test_executable(&String::from_utf8_lossy(&out.stdout), test)
        .ok_or_else(|| format!("cargo named no executable for {package}'s tests/{test}.rs"))
}

/// Replays `target`'s committed corpus in the instrumented `exe`, indexes the profile and reads
/// the coverage of [`files`]; returns the target's section of the report.
fn report_one(root: &Path, tools: &Path, exe: &Path, target: &Target) -> Result<String, String> {
    let out_dir = root.join("target").join("fuzz-coverage");
    let profiles = out_dir.join("profiles");
    let uncovered_dir = out_dir.join("uncovered");
    for d in [&profiles, &uncovered_dir] {
        std::fs::create_dir_all(d).map_err(|e| format!("{}: {e}", d.display()))?;
    }
    let raw = profiles.join(format!("{}.profraw", target.name));
    let indexed = profiles.join(format!("{}.profdata", target.name));
    for f in [&raw, &indexed] {
        if f.exists() {
            std::fs::remove_file(f).map_err(|e| format!("{}: {e}", f.display()))?;
        }
    }
    let run = output_of(
        Command::new(exe)
            .args([target.name, "--exact", "--nocapture", "--test-threads", "1"])
            .current_dir(root.join(target.package))
            .env("BOLERO_RANDOM_ITERATIONS", "0")
            .env_remove("BOLERO_RANDOM_SEED")
            .env_remove("BOLERO_RANDOM_TEST_TIME_MS")
            .env("LLVM_PROFILE_FILE", &raw),
        &exe.display().to_string(),
    )?;
    let mut text = String::from_utf8_lossy(&run.stderr).into_owned();
    text.push_str(&String::from_utf8_lossy(&run.stdout));
    if !run.status.success() {
        return Err(format!(
            "{} failed on its committed corpus ({}):\n{text}",
            target.name, run.status
        ));
    }
    if !raw.is_file() {
        return Err(format!(
            "{} wrote no profile ({}): is the binary instrumented?",
            target.name,
            raw.display()
        ));
    }
    let tool = |name: &str, args: &[&std::ffi::OsStr]| -> Result<String, String> {
        let out = output_of(Command::new(tools.join(name)).args(args), name)?;
        if !out.status.success() {
            return Err(format!(
                "{name} failed ({}): {}",
                out.status,
                String::from_utf8_lossy(&out.stderr)
            ));
        }
        Ok(String::from_utf8_lossy(&out.stdout).into_owned())
    };
    tool(
        "llvm-profdata",
        &[
            "merge".as_ref(),
            "-sparse".as_ref(),
            raw.as_os_str(),
            "-o".as_ref(),
            indexed.as_os_str(),
        ],
    )?;
    let sources: Vec<PathBuf> = files(target.name).iter().map(|f| root.join(f)).collect();
    let mut args: Vec<&std::ffi::OsStr> = vec![
        "export".as_ref(),
        "-instr-profile".as_ref(),
        indexed.as_os_str(),
        exe.as_os_str(),
    ];
    args.extend(sources.iter().map(|s| s.as_os_str()));
    let mut summary_args = args.clone();
    summary_args.insert(1, "-summary-only".as_ref());
    let summaries = parse_summary(&tool("llvm-cov", &summary_args)?)?;
    let mut lcov_args = args;
    lcov_args.insert(1, "-format=lcov".as_ref());
    let lcov = uncovered_lines(&tool("llvm-cov", &lcov_args)?)?;

    let mut rows = Vec::new();
    let mut listing = String::new();
    for (rel, abs) in files(target.name).iter().zip(&sources) {
        let same = |f: &str| Path::new(f) == abs.as_path() || Path::new(f) == Path::new(rel);
        let summary = summaries
            .iter()
            .find(|s| same(&s.file))
            .ok_or_else(|| format!("{}: llvm-cov has no coverage of {rel}", target.name))?;
        let uncovered = lcov
            .iter()
            .find(|(f, _)| same(f))
            .map(|(_, l)| l.clone())
            .unwrap_or_default();
        let _ = writeln!(
            listing,
            "{rel}: {} lines not executed (summary); the lcov records list {}: {}",
            summary.lines.total - summary.lines.covered,
            uncovered.len(),
            ranges(&uncovered)
        );
        rows.push(FileRow {
            file: (*rel).to_string(),
            summary: summary.clone(),
            uncovered,
        });
    }
    let list = uncovered_dir.join(format!("{}.txt", target.name));
    std::fs::write(&list, listing).map_err(|e| format!("{}: {e}", list.display()))?;

    let corpus = std::fs::read_dir(committed_corpus(root, target)).map_or(0, |d| {
        d.filter_map(Result::ok)
            .filter(|e| e.path().is_file())
            .count()
    });
    let replayed = executions(&text).map_or("–".to_string(), |n| n.to_string());
    let mut out = format!(
        "### `{}`\n\nCommitted corpus: {corpus} inputs; executions reported by the target: {replayed}. \
         Uncovered line numbers: `{}`.\n\n",
        target.name,
        list.strip_prefix(root).unwrap_or(&list).display()
    );
    out.push_str(&table(&rows));
    Ok(out)
}

/// Builds and runs the selected targets (all if `only` is empty); returns the report.
pub fn run(root: &Path, only: &[String]) -> Result<String, String> {
    let (host, tools) = llvm_tools(root)?;
    let targets: Vec<&Target> = TARGETS
        .iter()
        .filter(|t| only.is_empty() || only.iter().any(|n| n == t.name))
        .collect();
    let mut exes: Vec<((&str, &str), PathBuf)> = Vec::new();
    let mut out = String::new();
    for t in targets {
        let key = (t.package, t.test);
        let exe = match exes.iter().find(|(k, _)| *k == key) {
            Some((_, exe)) => exe.clone(),
            None => {
                let exe = build(root, &host, t.package, t.test)?;
                exes.push((key, exe.clone()));
                exe
            }
        };
        eprintln!("xtask fuzz-coverage: {} ...", t.name);
        if !out.is_empty() {
            out.push('\n');
        }
        out.push_str(&report_one(root, &tools, &exe, t)?);
    }
    Ok(out)
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    /// `llvm-cov export -summary-only` of two files, shortened by hand (the real output has the
    /// same members, on one line).
    const SUMMARY: &str = r#"{"data":[{"files":[
        {"filename":"/w/protocol/src/cdc.rs","summary":{"branches":{"count":0,"covered":0,"notcovered":0,"percent":0},
         "functions":{"count":33,"covered":22,"percent":66.666666666666657},
         "lines":{"count":335,"covered":265,"percent":79.104477611940297},
         "regions":{"count":625,"covered":528,"notcovered":97,"percent":84.480000000000004}}},
        {"filename":"/w/a \"quoted\"\u00e9.rs","summary":{"lines":{"count":4,"covered":0,"percent":0},
         "regions":{"count":3,"covered":0,"notcovered":3,"percent":0}}}],
        "totals":{"lines":{"count":339,"covered":265,"percent":78.17}}}],
        "type":"llvm.coverage.json.export","version":"3.1.0"}"#;

    #[test]
    fn reads_llvm_covs_summary() {
        let s = parse_summary(SUMMARY).unwrap();
        assert_eq!(
            s,
            vec![
                FileSummary {
                    file: "/w/protocol/src/cdc.rs".into(),
                    regions: Count {
                        covered: 528,
                        total: 625
                    },
                    lines: Count {
                        covered: 265,
                        total: 335
                    },
                },
                FileSummary {
                    file: "/w/a \"quoted\"é.rs".into(),
                    regions: Count {
                        covered: 0,
                        total: 3
                    },
                    lines: Count {
                        covered: 0,
                        total: 4
                    },
                },
            ]
        );
    }

    #[test]
    fn a_summary_without_counts_or_bad_json_is_an_error() {
        assert!(
            parse_summary(r#"{"data":[{"files":[{"filename":"x","summary":{}}]}]}"#)
                .unwrap_err()
                .contains("x: llvm-cov's summary has no valid")
        );
        assert!(parse_summary(r#"{"data":[]}"#)
            .unwrap_err()
            .contains("no data[0].files"));
        // More covered than there are.
        assert!(parse_summary(
            r#"{"data":[{"files":[{"filename":"x","summary":{"lines":{"count":1,"covered":2},"regions":{"count":1,"covered":1}}}]}]}"#
        )
        .is_err());
        assert!(parse_summary("{\"data\":[{\"files\":[")
            .unwrap_err()
            .contains("not JSON"));
    }

    #[test]
    fn reads_the_uncovered_lines_of_lcov() {
        let lcov = "SF:/w/a.rs\nFN:1,f\nDA:1,5\nDA:3,0\nDA:4,0\nDA:7,0\nDA:9,1\nLF:5\nLH:2\n\
                    end_of_record\nSF:/w/b.rs\nDA:2,3\nend_of_record\n";
        let u = uncovered_lines(lcov).unwrap();
        assert_eq!(
            u,
            vec![
                ("/w/a.rs".to_string(), vec![3, 4, 7]),
                ("/w/b.rs".to_string(), vec![])
            ]
        );
        assert_eq!(ranges(&u[0].1), "3-4, 7");
        assert_eq!(ranges(&[1, 2, 3, 10, 12, 13]), "1-3, 10, 12-13");
        assert_eq!(ranges(&[]), "");
        assert!(uncovered_lines("DA:1,0\n").is_err());
        assert!(uncovered_lines("SF:a\nDA:x,0\n").is_err());
    }

    #[test]
    fn the_table_adds_up_and_rounds() {
        assert_eq!(
            percent(Count {
                covered: 2,
                total: 3
            }),
            "66.7 %"
        );
        assert_eq!(
            percent(Count {
                covered: 1,
                total: 8
            }),
            "12.5 %"
        );
        assert_eq!(
            percent(Count {
                covered: 0,
                total: 0
            }),
            "–"
        );
        let row = |file: &str, r: (u64, u64), l: (u64, u64), u: Vec<u32>| FileRow {
            file: file.into(),
            summary: FileSummary {
                file: file.into(),
                regions: Count {
                    covered: r.0,
                    total: r.1,
                },
                lines: Count {
                    covered: l.0,
                    total: l.1,
                },
            },
            uncovered: u,
        };
        let t = table(&[
            row("a.rs", (528, 625), (265, 335), vec![1; 70]),
            row("b.rs", (0, 3), (0, 4), vec![1, 2, 3, 4]),
        ]);
        assert!(
            t.contains("| `a.rs` | 528/625 | 84.5 % | 265/335 | 79.1 % | 70 |"),
            "{t}"
        );
        assert!(
            t.contains("| `b.rs` | 0/3 | 0.0 % | 0/4 | 0.0 % | 4 |"),
            "{t}"
        );
        // 528/628 = 84.08 %, 265/339 = 78.17 %.
        assert!(
            t.contains("| total | 528/628 | 84.1 % | 265/339 | 78.2 % | 74 |"),
            "{t}"
        );
    }

    #[test]
    fn reads_the_targets_execution_count() {
        assert_eq!(
            executions("running 1 test\nfuzz amr_command: 54 executions, no finding\nok\n"),
            Some(54)
        );
        assert_eq!(
            executions("fuzz ladder_against_model: 272 executions, 9 events, no disagreement"),
            Some(272)
        );
        assert_eq!(executions("test result: ok\n"), None);
    }

    #[test]
    fn every_target_has_production_files_only() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
        for t in TARGETS {
            let f = files(t.name);
            assert!(!f.is_empty(), "{} has no files", t.name);
            for file in f {
                assert!(root.join(file).is_file(), "{file} of {}", t.name);
                assert!(file.starts_with(&format!("{}/src/", t.package)), "{file}");
                for not in ["tests", "verification", "harness"] {
                    assert!(!file.contains(not), "{file} of {}", t.name);
                }
            }
        }
        assert!(files("fuzz_nothing").is_empty());
    }

    #[test]
    fn arguments_are_checked() {
        let a = |v: &[&str]| parse_args(&v.iter().map(|s| s.to_string()).collect::<Vec<_>>());
        assert_eq!(a(&["fuzz_cdc"]).unwrap(), vec!["fuzz_cdc".to_string()]);
        assert!(a(&[]).unwrap().is_empty());
        assert!(a(&["--seconds"]).unwrap_err().contains("unknown option"));
        assert!(a(&["fuzz_x"])
            .unwrap_err()
            .contains("no fuzz target `fuzz_x`"));
    }
}

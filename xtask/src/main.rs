//! Project chores: `cargo xtask <command>`.
//!
//! `qemu-e2e <cdc|teensy>`: boots the profile's emulator image in QEMU with its link on a pty and
//! drives it with the real `motorlink`, checking the firmware's own trace (see `e2e`).
//!
//! `kani-table <dir>`: reads the per-harness result files that `cargo kani -Z unstable-options
//! --output-into-files` writes (one file per harness, named by its path) and prints the Markdown
//! table of `proofs/REPORT.md`: harness, result, checks, covers, verification time, one row per
//! harness in name order, so the report's figures come from a run, not from typing. With `--write
//! DIR…` it rewrites the generated block of `proofs/REPORT.md` (between `<!-- kani:begin` and
//! `<!-- kani:end -->`) with one such table per directory, under the command and the wall-clock
//! time that `.ci/run` recorded beside it (`<dir>.command`, `<dir>.seconds`). With `--check DIR…`
//! it fails when those tables and the run differ in a harness, a result, a check count or a cover
//! count (not in times): `.ci/run` runs it after its Kani steps, so the tables stay those of the
//! code.
//!
//! `fuzz [--seconds N] [--runs N] [--jobs J] [--merge] [TARGET…]`: runs every bolero fuzz target
//! coverage-guided (libFuzzer, nightly) and prints executions, coverage and corpus per target (see
//! `fuzz`).
//!
//! `fuzz-coverage [TARGET…]`: the source coverage (regions, lines) that each fuzz target's
//! committed corpus alone reaches in the production files the target exercises, one Markdown
//! table per target (see `fuzz_coverage`).
//!
//! `trace`: checks that `proofs/SAFETY.md`, `proofs/REPORT.md` and the harness code agree (see
//! `trace`): one line per problem, non-zero exit if there is any.
//!
//! `ros-e2e`: `motorlink ros --sim` against Cyclone DDS's Python binding in a network namespace of
//! its own (see `ros_e2e`).
#![forbid(unsafe_code)]

mod cargo;
mod e2e;
mod fuzz;
mod fuzz_coverage;
mod ros_e2e;
mod rta;
mod trace;
mod variant;

use std::fmt::Write as _;
use std::path::Path;
use std::process::ExitCode;

/// What one harness's result file says.
#[derive(Debug, Default, PartialEq)]
struct Row {
    harness: String,
    verified: Option<bool>,
    checks: Option<String>,
    covers: Option<String>,
    seconds: Option<f64>,
    /// Kani stopped CBMC at `--harness-timeout`: no verdict either way.
    timed_out: bool,
}

/// Reads the summary lines of one result file (the last occurrence of each wins). The covers are
/// counted from the file's per-property results where it has them: one per `cover!` of the
/// source, which Kani reports more than once where rustc's optimisation copied it onto several
/// paths (the copies have one message, one source location and one function: such a cover is
/// satisfied if any copy is). Without per-property results, Kani's own summary line is taken.
fn parse(harness: &str, text: &str) -> Row {
    let mut row = Row {
        harness: harness.to_string(),
        ..Row::default()
    };
    let mut covers = std::collections::BTreeMap::<(&str, &str), bool>::new();
    let mut lines = text.lines().map(str::trim).peekable();
    while let Some(line) = lines.next() {
        if line.starts_with("Check ") && line.contains(".cover.") {
            let mut field = |key: &str| {
                lines
                    .next_if(|l| l.starts_with(key))
                    .and_then(|l| l.strip_prefix(key))
                    .map_or("", str::trim)
            };
            let status = field("- Status:");
            let description = field("- Description:");
            let location = field("- Location:");
            *covers.entry((description, location)).or_default() |= status == "SATISFIED";
        } else if let Some(rest) = line.strip_prefix("** ") {
            if rest.contains("cover properties satisfied") {
                row.covers = Some(rest.replace(" cover properties satisfied", " satisfied"));
            } else if rest.contains(" failed") {
                row.checks = Some(rest.to_string());
            }
        } else if let Some(v) = line.strip_prefix("VERIFICATION:- ") {
            row.verified = Some(v == "SUCCESSFUL");
        } else if let Some(t) = line.strip_prefix("Verification Time: ") {
            row.seconds = t.trim_end_matches('s').parse().ok();
        } else if line.starts_with("CBMC timed out") {
            row.timed_out = true;
        }
    }
    if !covers.is_empty() {
        let satisfied = covers.values().filter(|s| **s).count();
        row.covers = Some(format!("{satisfied} of {} satisfied", covers.len()));
    }
    row
}

/// A row's result as the table prints it.
fn result_cell(r: &Row) -> &'static str {
    match r.verified {
        _ if r.timed_out => "**TIMED OUT**",
        Some(true) => "VERIFIED",
        Some(false) => "**FAILED**",
        None => "no result",
    }
}

/// The Markdown table of `rows`.
fn table(rows: &[Row]) -> String {
    let mut out =
        String::from("| harness | result | checks | covers | time |\n|---|---|---|---|---|\n");
    let mut total = 0.0;
    for r in rows {
        let result = result_cell(r);
        let time = r.seconds.map_or("–".to_string(), |s| {
            total += s;
            format!("{s:.1} s")
        });
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {} | {} |",
            r.harness,
            result,
            r.checks.as_deref().unwrap_or("–"),
            r.covers.as_deref().unwrap_or("–"),
            time
        );
    }
    let _ = writeln!(
        out,
        "\n{} harnesses, verification times summing to {total:.0} s.",
        rows.len()
    );
    out
}

fn kani_table(dir: &Path) -> Result<String, String> {
    let rows = kani_rows(dir)?;
    let mut out = String::new();
    if let Some(secs) = wall_seconds(dir) {
        let _ = writeln!(
            out,
            "Wall-clock time of this `cargo kani` step: {} min {:02} s.\n",
            secs / 60,
            secs % 60
        );
    }
    out.push_str(&table(&rows));
    Ok(out)
}

/// The rows of the result files in `dir`, in name order.
fn kani_rows(dir: &Path) -> Result<Vec<Row>, String> {
    let entries = std::fs::read_dir(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut rows = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| e.to_string())?.path();
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let text =
            std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let harness = name.rsplit("::").next().unwrap_or(&name).to_string();
        rows.push(parse(&harness, &text));
    }
    if rows.is_empty() {
        return Err(format!("{}: no result files", dir.display()));
    }
    rows.sort_by(|a, b| a.harness.cmp(&b.harness));
    // The report and `trace` name a harness by its function name: two of one name would share a row.
    if let Some(pair) = rows
        .iter()
        .zip(rows.iter().skip(1))
        .find(|(a, b)| a.harness == b.harness)
    {
        return Err(format!(
            "{}: two harnesses named `{}`: rename one (the report names harnesses by function name)",
            dir.display(),
            pair.0.harness
        ));
    }
    Ok(rows)
}

/// `cargo xtask kani-table --check DIR…`: what differs between the runs whose results are in the
/// directories and REPORT.md's generated tables (`doc`), one line per difference. Each harness of
/// the runs must have a row of the same result, checks and covers (times differ from run to run and
/// are not compared), except those on the report's `Not in this run:` line; each row must be a
/// harness of the runs, except those on its `Stale rows:` line (harnesses removed since the tables'
/// run, which `cargo xtask trace` checks are gone from the code). The check counts and covers of
/// one program are the same in every run.
fn kani_check(doc: &str, runs: &[Row]) -> Vec<String> {
    let fresh = trace::fresh_clone(doc);
    if fresh.rows.is_empty() {
        return vec!["proofs/REPORT.md: no fresh-clone table rows".into()];
    }
    let mut problems = Vec::new();
    for r in runs {
        let want = [
            result_cell(r).to_string(),
            r.checks.clone().unwrap_or_else(|| "–".into()),
            r.covers.clone().unwrap_or_else(|| "–".into()),
        ];
        match fresh.cells.get(&r.harness) {
            Some(row) if *row == want => {}
            Some(row) => problems.push(format!(
                "proofs/REPORT.md: `{}` reads {} / {} / {}, this run {} / {} / {} \
                 (regenerate: cargo xtask kani-table --write DIR…)",
                r.harness, row[0], row[1], row[2], want[0], want[1], want[2]
            )),
            None if fresh.not_run.contains(&r.harness) => {}
            None => problems.push(format!(
                "proofs/REPORT.md: `{}` ran but has no row and is not on the `Not in this run:` line",
                r.harness
            )),
        }
    }
    for h in &fresh.rows {
        if !runs.iter().any(|r| &r.harness == h) && !fresh.stale.contains(h) {
            problems.push(format!("proofs/REPORT.md: `{h}` has a row but did not run"));
        }
    }
    problems
}

/// The wall-clock seconds of the run whose results are in `dir`, from the file `<dir>.seconds`
/// that `.ci/run` writes beside it (absent when the results came from elsewhere).
fn wall_seconds(dir: &Path) -> Option<u64> {
    let mut name = dir.file_name()?.to_os_string();
    name.push(".seconds");
    std::fs::read_to_string(dir.with_file_name(name))
        .ok()?
        .trim()
        .parse()
        .ok()
}

/// Markers of REPORT.md's generated Kani tables.
const KANI_BEGIN: &str =
    "<!-- kani:begin (generated by `cargo xtask kani-table --write DIR…`; do not edit) -->";
const KANI_END: &str = "<!-- kani:end -->";

/// `cargo xtask kani-table --write DIR…`: replaces the generated block of `proofs/REPORT.md` with
/// one table per result directory, each under the directory's `cargo kani` command line as
/// `.ci/run` recorded it in `<dir>.command` (if present).
fn kani_write(root: &Path, dirs: &[&str]) -> Result<(), String> {
    let path = root.join("proofs/REPORT.md");
    let doc = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut body = String::new();
    for d in dirs {
        let dir = Path::new(d);
        let name = dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let _ = writeln!(body, "\n### `{name}`\n");
        if let Ok(cmd) = std::fs::read_to_string(dir.with_file_name(format!("{name}.command"))) {
            let _ = writeln!(body, "`{}`\n", cmd.trim());
        }
        body.push_str(&kani_table(dir)?);
    }
    let new = rta::replace_between(&doc, KANI_BEGIN, KANI_END, &format!("{}\n", body.trim()))
        .map_err(|e| format!("proofs/REPORT.md: {e}"))?;
    std::fs::write(&path, new).map_err(|e| format!("{}: {e}", path.display()))
}

/// `cargo xtask rta [--check [FILE] | --write [FILE]]`: prints the response-time analysis of every
/// firmware image (exit status 1 when a task misses its deadline or a comm-loss bound is not met);
/// `--check` also fails when FILE's (default `proofs/SAFETY.md`) generated section differs from it,
/// `--write` regenerates that section.
fn rta_main(args: &[&str]) -> ExitCode {
    let root = workspace_root();
    let (mode, file) = match args {
        [] => ("print", None),
        ["--check"] | ["--write"] => (args.first().copied().unwrap_or(""), None),
        [m @ ("--check" | "--write"), f] => (*m, Some(*f)),
        ["--help" | "-h"] => {
            println!(
                "cargo xtask rta [--check [FILE] | --write [FILE]]\n\n\
                 Response-time analysis of every firmware image's RTIC tasks under the stack resource\n\
                 policy, from the RTIC apps' #[task] attributes and lock sites and firmware/BUDGET.md's\n\
                 instruction counts and rates, and the comm-loss bound per link profile in wall time.\n\
                 Prints one Markdown table per image; exits 1 when a task's response time exceeds its\n\
                 deadline or a comm-loss bound is not met.\n\n\
                 --check [FILE]  also fail unless FILE's (default proofs/SAFETY.md) section between\n\
                 \x20               the rta:begin and rta:end markers equals the printed report\n\
                 --write [FILE]  rewrite that section with the report"
            );
            return ExitCode::SUCCESS;
        }
        _ => {
            eprintln!("usage: cargo xtask rta [--check [FILE] | --write [FILE]] (see --help)");
            return ExitCode::from(64);
        }
    };
    let results = match rta::run(root) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("xtask rta: {e}");
            return ExitCode::FAILURE;
        }
    };
    let report = rta::report(&results);
    print!("{report}");
    let mut ok = results.iter().all(rta::ImageResult::passes);
    if !ok {
        eprintln!("xtask rta: a task misses its deadline or a comm-loss bound is not met");
    }
    if mode != "print" {
        let path = file.map_or_else(|| root.join("proofs/SAFETY.md"), std::path::PathBuf::from);
        let doc = match std::fs::read_to_string(&path) {
            Ok(d) => d,
            Err(e) => {
                eprintln!("xtask rta: {}: {e}", path.display());
                return ExitCode::FAILURE;
            }
        };
        let body = rta::section_body(&report);
        if mode == "--write" {
            match rta::replace_section(&doc, &body) {
                Ok(new) => {
                    if let Err(e) = std::fs::write(&path, new) {
                        eprintln!("xtask rta: {}: {e}", path.display());
                        return ExitCode::FAILURE;
                    }
                    eprintln!("xtask rta: wrote {}", path.display());
                }
                Err(e) => {
                    eprintln!("xtask rta: {}: {e}", path.display());
                    return ExitCode::FAILURE;
                }
            }
        } else {
            let current = rta::section(&doc).map(|s| s.strip_prefix('\n').unwrap_or(s));
            if current != Some(body.as_str()) {
                eprintln!(
                    "xtask rta: {}'s generated section is missing or stale: run `cargo xtask rta --write`",
                    path.display()
                );
                ok = false;
            }
        }
    }
    if ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

/// The workspace's root directory (the parent of this crate's).
fn workspace_root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap_or(Path::new("."))
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        ["kani-table", "--write", dirs @ ..] if !dirs.is_empty() => {
            let root = workspace_root();
            match kani_write(root, dirs) {
                Ok(()) => {
                    println!("xtask kani-table: proofs/REPORT.md's generated tables rewritten");
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("xtask kani-table: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        ["kani-table", "--check", dirs @ ..] if !dirs.is_empty() => {
            let root = workspace_root();
            let path = root.join("proofs/REPORT.md");
            let doc = match std::fs::read_to_string(&path) {
                Ok(d) => d,
                Err(e) => {
                    eprintln!("xtask kani-table: {}: {e}", path.display());
                    return ExitCode::FAILURE;
                }
            };
            let mut runs = Vec::new();
            for d in dirs {
                match kani_rows(Path::new(d)) {
                    Ok(rows) => runs.extend(rows),
                    Err(e) => {
                        eprintln!("xtask kani-table: {e}");
                        return ExitCode::FAILURE;
                    }
                }
            }
            let problems = kani_check(&doc, &runs);
            for p in &problems {
                eprintln!("{p}");
            }
            if problems.is_empty() {
                println!(
                    "xtask kani-table: proofs/REPORT.md's tables agree with this run ({} harnesses: \
                     result, checks, covers)",
                    runs.len()
                );
                ExitCode::SUCCESS
            } else {
                eprintln!("xtask kani-table: {} difference(s)", problems.len());
                ExitCode::FAILURE
            }
        }
        ["kani-table", dir] => match kani_table(Path::new(dir)) {
            Ok(t) => {
                print!("{t}");
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("xtask kani-table: {e}");
                ExitCode::FAILURE
            }
        },
        ["trace"] => {
            let root = workspace_root();
            match trace::run(root) {
                Ok(problems) if problems.is_empty() => {
                    println!("xtask trace: SAFETY.md, REPORT.md and the harness code agree");
                    ExitCode::SUCCESS
                }
                Ok(problems) => {
                    for p in &problems {
                        eprintln!("{p}");
                    }
                    eprintln!("xtask trace: {} problem(s)", problems.len());
                    ExitCode::FAILURE
                }
                Err(e) => {
                    eprintln!("xtask trace: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        ["ros-e2e"] => {
            let root = workspace_root();
            match ros_e2e::run(root) {
                Ok(summary) => {
                    println!("{summary}");
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("xtask ros-e2e: FAILED: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        ["rta", rest @ ..] => rta_main(rest),
        ["fw-variant", variant] => {
            let root = workspace_root();
            match variant::build(root, variant) {
                Ok(dir) => {
                    println!("{variant} images in {}", dir.display());
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("xtask fw-variant: FAILED: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        ["qemu-e2e", profile] => {
            let root = workspace_root();
            match e2e::run(root, profile) {
                Ok(summary) => {
                    println!("{summary}");
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("xtask qemu-e2e {profile}: FAILED: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        ["fuzz-coverage", "--help" | "-h"] => {
            println!("usage: {}\n\n{}", fuzz_coverage::USAGE, fuzz_coverage::HELP);
            ExitCode::SUCCESS
        }
        ["fuzz-coverage", rest @ ..] => {
            let rest: Vec<String> = rest.iter().map(|s| s.to_string()).collect();
            let only = match fuzz_coverage::parse_args(&rest) {
                Ok(o) => o,
                Err(e) => {
                    eprintln!("xtask fuzz-coverage: {e}\nusage: {}", fuzz_coverage::USAGE);
                    return ExitCode::from(64);
                }
            };
            match fuzz_coverage::run(workspace_root(), &only) {
                Ok(report) => {
                    print!("{report}");
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("xtask fuzz-coverage: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        ["fuzz", "--help" | "-h"] => {
            println!("usage: {}\n\n{}", fuzz::USAGE, fuzz::HELP);
            let names: Vec<&str> = fuzz::TARGETS.iter().map(|t| t.name).collect();
            println!("\nTargets: {}", names.join(", "));
            ExitCode::SUCCESS
        }
        ["fuzz", rest @ ..] => {
            let rest: Vec<String> = rest.iter().map(|s| s.to_string()).collect();
            let opts = match fuzz::parse_args(&rest) {
                Ok(o) => o,
                Err(e) => {
                    eprintln!("xtask fuzz: {e}\nusage: {}", fuzz::USAGE);
                    return ExitCode::from(64);
                }
            };
            let root = workspace_root();
            match fuzz::run(root, &opts) {
                Ok((table, ok)) => {
                    print!("{table}");
                    if ok {
                        ExitCode::SUCCESS
                    } else {
                        eprintln!("xtask fuzz: a target failed (see its row)");
                        ExitCode::FAILURE
                    }
                }
                Err(e) => {
                    eprintln!("xtask fuzz: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        _ => {
            eprintln!(
                "usage: cargo xtask kani-table <dir of `--output-into-files` results>\n       cargo xtask kani-table --write <dir>…  (rewrites proofs/REPORT.md's generated tables)\n       cargo xtask trace\n       cargo xtask rta [--check [FILE] | --write [FILE]]\n       cargo xtask qemu-e2e <cdc|teensy>\n       {}\n       cargo xtask ros-e2e\n       {}\n       {}",
                variant::USAGE,
                fuzz::USAGE,
                fuzz_coverage::USAGE
            );
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    /// A result directory of `files` (name, contents) under the system's temporary directory.
    fn results(tag: &str, files: &[(&str, &str)]) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("xtask-kani-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        for (name, text) in files {
            std::fs::write(dir.join(name), text).unwrap();
        }
        dir
    }

    #[test]
    fn the_check_compares_result_checks_and_covers_but_not_times() {
        let row = |h: &str, checks: &str| Row {
            harness: h.into(),
            verified: Some(true),
            checks: Some(checks.into()),
            covers: Some("2 of 2 satisfied".into()),
            seconds: Some(9.0),
            timed_out: false,
        };
        let doc = format!(
            "## Fresh-clone tables\n\nNot in this run: `verify_new`.\n{KANI_BEGIN}\n| harness | result | checks | covers | time |\n\
             |---|---|---|---|---|\n| `verify_a` | VERIFIED | 0 of 5 failed | 2 of 2 satisfied | 1.0 s |\n\
             | `verify_b` | VERIFIED | 0 of 7 failed | 2 of 2 satisfied | 3.0 s |\n{KANI_END}\n"
        );
        // The same figures at other times, and a harness the report says was added after its run.
        let same = [
            row("verify_a", "0 of 5 failed"),
            row("verify_b", "0 of 7 failed"),
            row("verify_new", "0 of 1 failed"),
        ];
        assert!(kani_check(&doc, &same).is_empty());
        // One check more, a harness gone, a harness new and not declared, a failure.
        let changed = [
            row("verify_a", "0 of 6 failed"),
            row("verify_c", "0 of 1 failed"),
        ];
        let p = kani_check(&doc, &changed);
        assert_eq!(p.len(), 3, "{p:?}");
        assert!(
            p[0].contains("`verify_a` reads VERIFIED / 0 of 5 failed"),
            "{p:?}"
        );
        assert!(p[1].contains("`verify_c` ran but has no row"), "{p:?}");
        assert!(
            p[2].contains("`verify_b` has a row but did not run"),
            "{p:?}"
        );
        // A row the report declares stale need not run.
        let stale = doc.replace("Not in this run: `verify_new`.", "Stale rows: `verify_b`.");
        assert!(kani_check(&stale, &[row("verify_a", "0 of 5 failed")]).is_empty());
        let mut failed = row("verify_a", "0 of 5 failed");
        failed.verified = Some(false);
        let p = kani_check(&doc, &[failed, row("verify_b", "0 of 7 failed")]);
        assert_eq!(p.len(), 1, "{p:?}");
        assert!(p[0].contains("this run **FAILED**"), "{p:?}");
    }

    #[test]
    fn two_harnesses_of_one_name_are_refused_and_the_wall_time_is_read() {
        let ok = "VERIFICATION:- SUCCESSFUL\nVerification Time: 1.5s\n";
        let dup = results(
            "dup",
            &[("a::proofs::verify_x", ok), ("b::proofs::verify_x", ok)],
        );
        let e = kani_table(&dup).unwrap_err();
        assert!(e.contains("two harnesses named `verify_x`"), "{e}");
        let one = results("one", &[("a::proofs::verify_x", ok)]);
        std::fs::write(
            one.with_file_name(format!("xtask-kani-one-{}.seconds", std::process::id())),
            "754\n",
        )
        .unwrap();
        let t = kani_table(&one).unwrap();
        assert!(
            t.starts_with("Wall-clock time of this `cargo kani` step: 12 min 34 s."),
            "{t}"
        );
        assert!(t.contains("| `verify_x` | VERIFIED |"), "{t}");
    }

    #[test]
    fn reads_a_kani_summary() {
        let text = "Checking harness x...\n\t - Status: SUCCESS\nSUMMARY:\n ** 0 of 3178 failed (37 unreachable)\n ** 3 of 3 cover properties satisfied\nVERIFICATION:- SUCCESSFUL\nVerification Time: 46.92777s\n";
        let r = parse("verify_x_2", text);
        assert_eq!(r.verified, Some(true));
        assert_eq!(
            r.checks.as_deref(),
            Some("0 of 3178 failed (37 unreachable)")
        );
        assert_eq!(r.covers.as_deref(), Some("3 of 3 satisfied"));
        assert_eq!(r.seconds, Some(46.92777));
        let t = table(&[r]);
        assert!(t.contains("| `verify_x_2` | VERIFIED | 0 of 3178 failed (37 unreachable) | 3 of 3 satisfied | 46.9 s |"), "{t}");
    }

    #[test]
    fn a_cover_reported_twice_counts_once() {
        // Three cover results of two `cover!`s: "a" twice at one place (one copy satisfied), "b"
        // once and never reached. Kani's own summary counts three.
        let cover = |n: u32, status: &str, msg: &str, line: u32| {
            format!(
                "Check {n}: f.cover.{n}\n\t - Status: {status}\n\t - Description: \"{msg}\"\n\t - Location: src/x.rs:{line}:5 in function f\n\n"
            )
        };
        let text = [
            cover(1, "UNSATISFIABLE", "a", 10),
            cover(2, "SATISFIED", "a", 10),
            cover(3, "UNSATISFIABLE", "b", 11),
            " ** 1 of 3 cover properties satisfied\n".into(),
        ]
        .concat();
        assert_eq!(
            parse("x", &text).covers.as_deref(),
            Some("1 of 2 satisfied")
        );
        // The same message at another place is another cover.
        let apart = [
            cover(1, "SATISFIED", "a", 10),
            cover(2, "UNSATISFIABLE", "a", 12),
        ]
        .concat();
        assert_eq!(
            parse("x", &apart).covers.as_deref(),
            Some("1 of 2 satisfied")
        );
    }

    #[test]
    fn a_failed_or_cut_run_is_not_reported_verified() {
        let failed = parse("f", "VERIFICATION:- FAILED\nVerification Time: 1s\n");
        assert_eq!(failed.verified, Some(false));
        assert!(table(&[failed]).contains("**FAILED**"));
        let cut = parse("c", "Checking harness c...\n");
        assert!(table(&[cut]).contains("no result"));
        // What Kani 0.67 writes when `--harness-timeout` stops CBMC.
        let slow = parse(
            "s",
            "Checking harness s...\n\nCBMC failed\nVERIFICATION:- FAILED\nCBMC timed out. You may want to rerun your proof with a larger timeout\n",
        );
        assert!(table(&[slow]).contains("| `s` | **TIMED OUT** |"));
    }
}

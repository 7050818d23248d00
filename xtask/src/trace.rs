//! `cargo xtask trace`: checks that the safety case (`proofs/SAFETY.md`), the proof report
//! (`proofs/REPORT.md`) and the harness code agree, so the traceability is checked, not hand-kept.
//!
//! Everything here except [`run`] and [`read_sources`] is a pure function over file contents, so the
//! rules are unit-tested on small, deliberately broken snippets. The rules:
//!
//! - **Names.** Every harness name in SAFETY.md (a backticked name whose last `::` segment starts
//!   with `verify_`) exists in the code. Templates are expanded against the code's names and must
//!   match at least one: `<kind>` and `*` stand for any name part, `{a,b}` for each listed part, and
//!   `…_x` after a name in the same table cell (or sentence) is that name with its last `_` part
//!   replaced by `_x`. A ladder body (`statemachine/src/verification.rs`) names its Kani entries
//!   `verify_<body>_2`/`_4`. In a table column whose header says "harness", "twin" or "test", every
//!   backticked snake_case name with two or more underscores names a harness, a ladder body or a
//!   function of the code.
//! - **Coverage.** Every Kani harness of the code (pending ones included) is named in SAFETY.md.
//! - **Property line.** The first line of the doc comment of the body a Kani entry calls (the first
//!   function of its file that the entry calls; the ladder's `proofs!` rows name it before `=>`; an
//!   entry that calls none is its own body) names a property id, `INV-n` or `P-n`.
//! - **Twins.** Every Kani harness has a `#[test]` twin: the entry's name without `verify_`, a ladder
//!   body's `twins!` module, or the twin [`TWIN_OF`] names (each with its reason).
//! - **Chains.** Every hazard of §2 is some requirement's (§3); every requirement of §3 has a row in
//!   §6 naming an invariant, a test or a harness; every id of the §4/§5 tables is in a §6 row.
//! - **Status.** Each row of the §4/§5 tables that have an id column carries a `status` cell, equal
//!   to the status derived from the report: EXHAUSTIVE when the row names an exhaustive test
//!   ([`EXHAUSTIVE`]) and every Kani harness it names (if any) is VERIFIED in REPORT.md's
//!   "Fresh-clone tables"; else VERIFIED when it names harnesses and every one is VERIFIED there;
//!   else PENDING when every harness it names is a pending one; else TWIN.
//! - **Report.** The fresh-clone tables list exactly the code's non-pending harnesses, except those
//!   listed on REPORT.md's line starting `Not in this run:` (harnesses added after the run, which
//!   then count as not verified).
//! - **Static messages.** In the verification files, outside `#[cfg(test)]` modules (which Kani never
//!   compiles), no `assert_eq!`, `assert_ne!`, `debug_assert*`, no assertion whose message is
//!   formatted at run time (Kani reports those as a placeholder instead of the property), no
//!   `assert!` or `panic!` (core's, in these `no_std` crates: Kani reports even a literal message
//!   as the placeholder; `check!` and `fail!` pass it on), and no assertion without a message
//!   (Kani reports only its condition). `const` assertions are the compiler's.
//! - **Property messages.** There too, the message of every `check!` and `fail!` is a string
//!   literal that starts with the ids of the properties it checks, `"INV-4: …"` or
//!   `"INV-3/INV-16: …"`, each an id that a table of SAFETY.md defines (the first cell of a row), so
//!   a failing proof names its property. [`UNNAMED_MESSAGES`] lists the exceptions, each with its
//!   reason; an entry whose message no longer appears without an id is reported, to be removed.
//! - **Covers.** Every row of the fresh-clone tables has covers, all satisfied ("n of n
//!   satisfied"): a harness without a satisfied cover may be vacuous. [`COVERS_NOT_ALL_SATISFIED`]
//!   lists the exceptions with the counts the tables must show and the reason each cover left is
//!   unreachable by design; an entry that matches no such row is reported, to be removed.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The crates whose sources are read: every file among them that holds a `#[kani::proof]` is a
/// verification file (found, not listed, so a new file of harnesses cannot go unchecked).
const CRATES: &[&str] = &[
    "statemachine",
    "protocol",
    "control",
    "mcu",
    "proofs",
    "sim",
    "host",
    "firmware",
];

/// The file whose bodies are instantiated per axis count (`verify_<body>_2`, `_4`).
const LADDER_FILE: &str = "statemachine/src/verification.rs";

/// Harnesses whose twin is not their name without `verify_`: (file, harness or prefix ending in
/// `*`, twin test in the same file, why).
pub const TWIN_OF: &[(&str, &str, &str, &str)] = &[
    (
        "protocol/src/cdc/verification.rs",
        "verify_len_flip_*",
        "bit_flip_in_every_sample_for_every_bit",
        "one Kani entry for the LEN byte of every message kind; the test flips every bit of a sample of each kind",
    ),
    (
        "protocol/src/cdc/verification.rs",
        "verify_round_trip_*",
        "round_trip_of_every_kind",
        "one Kani entry for every message kind, one after the other; the twin runs every kind",
    ),
    (
        "protocol/src/cdc/verification.rs",
        "verify_stream_round_trip_*",
        "round_trip_of_every_kind",
        "the twin feeds every kind's frame to a stream decoder too",
    ),
    (
        "protocol/src/cdc/verification.rs",
        "verify_stream_holds_back_no_frame_*",
        "stream_holds_back_no_frame",
        "one Kani entry per frame kind; the twin draws the kind",
    ),
    (
        "mcu/src/odometry/verification.rs",
        "verify_heading_wrap_stays_bounded_*",
        "heading_wrap_stays_bounded",
        "one Kani entry per sign of the heading's high part; the twin runs both",
    ),
    (
        "control/src/verification.rs",
        "verify_profile_smooth_for_fixed_target_*",
        "profile_smooth_for_fixed_target",
        "one Kani entry per direction of the velocity (down, or at rest and up); the twin runs both",
    ),
];

/// Kani harnesses without a `cargo test` twin of their own: (file, harness, why).
pub const NO_TWIN: &[(&str, &str, &str)] = &[(
    "protocol/src/crc16/verification.rs",
    "verify_fold*_total",
    "contract proofs of the CRC's block functions; `seed_loop_is_checksum` runs every block \
         function against the bitwise loop at every frame length, `checksum_total` is the twin of \
         the function built from them",
)];

/// Tests that enumerate their claim's whole input space, or a part that the argument written beside
/// the claim shows to stand for the rest (the CRC's linearity for the bit flips of sampled frames,
/// the monotonicity of rounding for the odometry's magnitudes at their bounds): a claim they back is
/// EXHAUSTIVE.
pub const EXHAUSTIVE: &[&str] = &[
    "every_burst_by_byte_order",
    "every_burst_within_the_stuffed_bytes_changes_the_crc",
    "sinf_is_within_its_range_for_every_f32",
    "cosf_is_within_its_range_for_every_f32",
    "remainderf_by_tau_is_within_pi_for_every_f32",
    "append_keeps_the_bytes_in_order",
    "update_magnitudes_are_finite_at_the_bounds",
    "bit_flip_refused_by_open_for_every_bit",
    "bit_flip_refused_for_every_bit",
    "bit_flip_in_every_sample_for_every_bit",
    "robust_holds_back_no_frame_after_every_byte",
];

/// Tests that enumerate every input up to a bound, not the whole input space: (test, the bound). A
/// claim that names one is BOUNDED, whatever else it names: its proof holds up to the bound only.
pub const BOUNDED: &[(&str, &str)] = &[
    (
        "stream_holds_back_no_frame_exhaustively",
        "seed 001: every garbage prefix of up to 6 bytes over the decoder's dangerous values (Kani: \
         any 3 bytes)",
    ),
    (
        "robust_stream_holds_back_no_frame_exhaustively",
        "Teensy robust: every garbage prefix of up to 5 bytes over zeros, COBS codes and the \
         frame's own bytes (any length by `verify_robust_push_step`'s induction)",
    ),
];

/// `check!`/`fail!` messages left without a property id: (file, message, why). Each is matched
/// by its whole text, so a message changed or given its id makes the entry stale (reported).
/// None at present: every message names its property.
pub const UNNAMED_MESSAGES: &[(&str, &str, &str)] = &[];

/// Fresh-clone rows whose covers are not all satisfied, or which have none: (harness or prefix
/// ending in `*`, covers satisfied, covers reported, why the others cannot be reached). The
/// table's counts must be exactly these.
pub const COVERS_NOT_ALL_SATISFIED: &[(&str, u32, u32, &str)] = &[
    (
        "verify_len_flip_every_kind",
        8,
        11,
        "`check_bit_flip_detected_in` has one cover for a flip of the LEN byte (\"LEN made longer\", \
         satisfied) and three in the branch of `Flip::OtherBytes` (\"flip in SOF\", \"flip in \
         MSG_ID\", \"flip in CRC\"), which this harness never takes: it flips the LEN byte \
         (`Flip::LenByte`) of each kind, whose seven covers of its own are satisfied. The test \
         `bit_flip_in_every_sample_for_every_bit` enumerates every flip of the other bytes, where \
         those three fire",
    ),
    (
        "verify_stream_holds_back_no_frame_*",
        2,
        4,
        "under Kani the garbage before the frame is three bytes (`GARBAGE`); \"frame delivered after \
         a crc error\" and \"the garbage began a valid frame\" need a candidate from the garbage \
         that ends inside the frame, whose LEN takes a fourth garbage byte (with three, its LEN is \
         the frame's `AA`, which ends past the frame). The twins (up to 24 garbage bytes) and the \
         exhaustive test `stream_holds_back_no_frame_exhaustively` reach both",
    ),
    (
        "verify_fold*_total",
        0,
        0,
        "contract proofs (`proof_for_contract`) of the CRC's block functions, without `cover!`: \
         register and block are `kani::any()`, with no assumption and no precondition, so no \
         input is excluded and the proof cannot be vacuous",
    ),
];

/// One Kani harness found in the code.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Harness {
    /// Entry name, `verify_…`.
    pub name: String,
    /// File it is in.
    pub file: String,
    /// Compiled as a proof only with `--cfg kani_pending`.
    pub pending: bool,
    /// The function whose doc carries the property id.
    pub body: String,
}

/// What the checker knows of the code.
#[derive(Debug, Default)]
pub struct Code {
    /// Every Kani harness.
    pub harnesses: Vec<Harness>,
    /// Ladder bodies (named in SAFETY.md without `verify_`).
    pub ladder_bodies: BTreeSet<String>,
    /// `#[test]` names per file (a ladder body's `twins!` module counts as the body's name).
    pub tests: BTreeMap<String, BTreeSet<String>>,
    /// First doc line of each function, per file.
    pub docs: BTreeMap<String, BTreeMap<String, String>>,
    /// Every function name of every scanned file (verification files and others).
    pub all_fns: BTreeSet<String>,
}

/// Extracts one backticked span after another.
fn backticked(s: &str) -> Vec<&str> {
    s.split('`').skip(1).step_by(2).collect()
}

/// Cells of a Markdown table row.
fn cells(row: &str) -> Vec<String> {
    let t = row.trim().trim_start_matches('|').trim_end_matches('|');
    // `\|` inside a cell is a literal bar
    let mut out = Vec::new();
    let mut cur = String::new();
    let mut prev = ' ';
    for c in t.chars() {
        if c == '|' && prev != '\\' {
            out.push(cur.trim().to_string());
            cur.clear();
        } else {
            cur.push(c);
        }
        prev = c;
    }
    out.push(cur.trim().to_string());
    out
}

/// Identifiers starting at each byte offset: `(start, word)`.
fn words(s: &str) -> Vec<(usize, &str)> {
    let mut out = Vec::new();
    let b = s.as_bytes();
    let mut i = 0;
    while i < b.len() {
        let c = b.get(i).copied().unwrap_or(b' ');
        if c.is_ascii_alphabetic() || c == b'_' || c == b'$' {
            let start = i;
            while i < b.len()
                && b.get(i)
                    .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_' || *c == b'$')
            {
                i = i.saturating_add(1);
            }
            out.push((start, s.get(start..i).unwrap_or("")));
        } else {
            i = i.saturating_add(1);
        }
    }
    out
}

/// Removes string and char literals and `//` comments, keeping the line structure (for brace
/// counting and call finding).
fn code_only(line: &str) -> String {
    let mut out = String::new();
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '"' => {
                let mut esc = false;
                for d in chars.by_ref() {
                    if esc {
                        esc = false;
                    } else if d == '\\' {
                        esc = true;
                    } else if d == '"' {
                        break;
                    }
                }
                out.push_str("\"\"");
            }
            '\'' => {
                // a char literal `'x'` or `'\x'`; a lifetime has no closing quote soon after
                let rest: String = chars.clone().take(4).collect();
                if let Some(end) = rest.find('\'') {
                    if end <= 2 && !rest.starts_with('\'') {
                        for _ in 0..=end {
                            chars.next();
                        }
                        out.push_str("' '");
                        continue;
                    }
                }
                out.push(c);
            }
            '/' if chars.peek() == Some(&'/') => break,
            _ => out.push(c),
        }
    }
    out
}

/// Index of the line where the item opening at `start` closes (brace counting), or the last line.
fn block_end(lines: &[String], start: usize) -> usize {
    let mut depth: i64 = 0;
    let mut opened = false;
    for (i, l) in lines.iter().enumerate().skip(start) {
        for c in l.chars() {
            match c {
                '{' | '(' | '[' => {
                    depth = depth.saturating_add(1);
                    opened = true;
                }
                '}' | ')' | ']' => depth = depth.saturating_sub(1),
                _ => {}
            }
        }
        if opened && depth <= 0 {
            return i;
        }
    }
    lines.len().saturating_sub(1)
}

/// The name a `fn` line defines, if it defines one.
fn fn_name(code: &str) -> Option<&str> {
    let ws = words(code);
    let pos = ws.iter().position(|(_, w)| *w == "fn")?;
    // only item keywords may come before `fn`
    if ws.iter().take(pos).any(|(_, w)| {
        !matches!(
            *w,
            "pub" | "crate" | "super" | "const" | "unsafe" | "extern" | "async" | "in"
        )
    }) {
        return None;
    }
    ws.get(pos.saturating_add(1)).map(|(_, w)| *w)
}

/// The attribute and doc lines directly above line `at`: (attribute text, doc lines, top to bottom).
fn above(raw: &[&str], at: usize) -> (String, Vec<String>) {
    let mut attrs = String::new();
    let mut docs = Vec::new();
    let mut i = at;
    let mut in_docs = false;
    while i > 0 {
        i = i.saturating_sub(1);
        let t = raw.get(i).map_or("", |l| l.trim());
        if let Some(d) = t.strip_prefix("///") {
            in_docs = true;
            docs.push(d.trim().to_string());
        } else if in_docs
            || t.is_empty()
            || t.ends_with('}')
            || t.ends_with(';')
            || t.ends_with('{')
        {
            if !t.starts_with("//") || in_docs {
                break;
            }
        } else if !t.starts_with("//") {
            // plain comments between attributes are passed over, never read as attributes
            attrs.insert_str(0, t);
        }
    }
    docs.reverse();
    (attrs, docs)
}

/// Reads the harnesses, tests and docs of one verification file.
fn scan_file(code: &mut Code, file: &str, text: &str) {
    let raw: Vec<&str> = text.lines().collect();
    let lines: Vec<String> = raw.iter().map(|l| code_only(l)).collect();
    // function definitions of the file (and `name!` for macros), with their first doc line
    let mut fns: BTreeMap<String, String> = BTreeMap::new();
    let mut tests = BTreeSet::new();
    // macro spans: name -> (start, end)
    let mut macros: Vec<(String, usize, usize)> = Vec::new();
    for (i, l) in lines.iter().enumerate() {
        if let Some(rest) = l.trim().strip_prefix("macro_rules!") {
            let name = rest.trim().trim_end_matches('{').trim().to_string();
            let (_, docs) = above(&raw, i);
            fns.insert(
                format!("{name}!"),
                docs.first().cloned().unwrap_or_default(),
            );
            macros.push((name, i, block_end(&lines, i)));
        }
    }
    let in_macro = |i: usize| macros.iter().find(|(_, s, e)| i > *s && i <= *e);
    let invocations = |name: &str| -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        for (i, l) in lines.iter().enumerate() {
            let t = l.trim();
            if t.starts_with("macro_rules!") {
                continue;
            }
            if in_macro(i).is_some_and(|(m, _, _)| m == name) {
                continue;
            }
            if words(t).first().is_some_and(|(_, w)| *w == name)
                && t.get(name.len()..).is_some_and(|r| r.starts_with('!'))
            {
                out.push((i, block_end(&lines, i)));
            }
        }
        out
    };
    let mut entries: Vec<(String, bool, usize)> = Vec::new(); // (name or $param, pending, line)
    for (i, l) in lines.iter().enumerate() {
        let Some(name) = fn_name(l) else { continue };
        let (attrs, docs) = above(&raw, i);
        if attrs.contains("#[test]") {
            // a twin shares its body's name; the body's doc is the one that counts
            tests.insert(name.to_string());
            fns.entry(name.to_string()).or_default();
        } else {
            fns.insert(name.to_string(), docs.first().cloned().unwrap_or_default());
        }
        if attrs.contains("kani::proof") {
            entries.push((name.to_string(), attrs.contains("kani_pending"), i));
        }
    }
    // `twins!`-style macros: a macro whose rule holds `#[test]` makes the name before `=>` of each
    // invocation row a twin (the ladder's twin modules)
    for (m, s, e) in &macros {
        let holds_test = raw
            .get(*s..=*e)
            .is_some_and(|ls| ls.iter().any(|l| l.contains("#[test]")));
        if holds_test {
            for (a, b) in invocations(m) {
                for l in lines.get(a.saturating_add(1)..b).unwrap_or(&[]) {
                    if let Some((lhs, _)) = l.split_once("=>") {
                        if let Some((_, w)) = words(lhs).last() {
                            tests.insert((*w).to_string());
                        }
                    }
                }
            }
        }
    }
    // resolve each entry to its harness names and body
    let body_of = |from: usize, entry: &str| -> Option<String> {
        let end = block_end(&lines, from);
        for l in lines.get(from.saturating_add(1)..=end).unwrap_or(&[]) {
            for (pos, w) in words(l) {
                if w == entry || w == "fn" {
                    continue;
                }
                let after = l.get(pos.saturating_add(w.len())..).unwrap_or("");
                let is_call = after.starts_with('(') || after.starts_with("::<");
                // `super::$body` is the ladder's body parameter; `crate::…::$f` the code proven
                let param_body =
                    w.starts_with('$') && l.get(..pos).is_some_and(|b| b.ends_with("super::"));
                if is_call && (fns.contains_key(w) || param_body) {
                    return Some(w.to_string());
                }
            }
        }
        None
    };
    for (name, pending, at) in entries {
        let body = body_of(at, &name);
        if let Some(param) = name.strip_prefix('$') {
            let _ = param;
            let Some((m, _, _)) = in_macro(at) else {
                continue;
            };
            for (a, b) in invocations(m) {
                for l in lines.get(a..=b).unwrap_or(&[]) {
                    for (_, w) in words(l) {
                        if !w.starts_with("verify_") {
                            continue;
                        }
                        let body = match &body {
                            Some(bd) if bd.starts_with('$') => l
                                .split_once("=>")
                                .and_then(|(lhs, _)| words(lhs).last().map(|(_, w)| w.to_string()))
                                .unwrap_or_else(|| w.to_string()),
                            Some(bd) => bd.clone(),
                            None => format!("{m}!"),
                        };
                        if !code.harnesses.iter().any(|h| h.name == w && h.file == file) {
                            code.harnesses.push(Harness {
                                name: w.to_string(),
                                file: file.to_string(),
                                pending,
                                body: body.clone(),
                            });
                        }
                        if file == LADDER_FILE {
                            code.ladder_bodies.insert(body);
                        }
                    }
                }
            }
        } else {
            code.harnesses.push(Harness {
                body: body.unwrap_or_else(|| name.clone()),
                name,
                file: file.to_string(),
                pending,
            });
        }
    }
    code.all_fns.extend(fns.keys().cloned());
    code.tests.insert(file.to_string(), tests);
    code.docs.insert(file.to_string(), fns);
}

/// Builds the code model from the verification files and the names of every other function.
pub fn scan(files: &[(String, String)], other_fn_names: &BTreeSet<String>) -> Code {
    let mut code = Code::default();
    for (f, text) in files {
        scan_file(&mut code, f, text);
    }
    code.all_fns.extend(other_fn_names.iter().cloned());
    code
}

/// Function names defined in `text` (for the names SAFETY.md may give of tests elsewhere).
pub fn fn_names(text: &str) -> BTreeSet<String> {
    text.lines()
        .filter_map(|l| fn_name(&code_only(l)).map(str::to_string))
        .collect()
}

/// A `*`/`<…>`/`{a,b}` template matches `name`.
fn template_matches(t: &str, name: &str) -> bool {
    // expand `{a,b}` first
    if let (Some(o), Some(c)) = (t.find('{'), t.find('}')) {
        if o < c {
            let (pre, rest) = t.split_at(o);
            let inner = rest.get(1..c.saturating_sub(o)).unwrap_or("");
            let post = rest
                .get(c.saturating_sub(o).saturating_add(1)..)
                .unwrap_or("");
            return inner
                .split(',')
                .any(|alt| template_matches(&format!("{pre}{}{post}", alt.trim()), name));
        }
    }
    // `<kind>` is a wildcard like `*`
    let mut pattern = String::new();
    let mut in_angle = false;
    for c in t.chars() {
        match c {
            '<' => {
                in_angle = true;
                pattern.push('*');
            }
            '>' => in_angle = false,
            _ if in_angle => {}
            _ => pattern.push(c),
        }
    }
    glob(&pattern, name)
}

/// `*` matches one or more characters.
fn glob(p: &str, s: &str) -> bool {
    match p.split_once('*') {
        None => p == s,
        Some((head, tail)) => {
            let Some(rest) = s.strip_prefix(head) else {
                return false;
            };
            (1..=rest.len()).any(|k| rest.get(k..).is_some_and(|r| glob(tail, r)))
        }
    }
}

/// A reference to code that SAFETY.md makes.
#[derive(Debug, Clone, PartialEq)]
enum Ref {
    /// Kani harnesses (a template expanded, or one name): (name, file).
    Harnesses(Vec<(String, String)>),
    /// A test (or other function) by name.
    Test(String),
}

/// The references of one piece of text (a table cell, a line): harness names, templates and
/// continuations, ladder bodies, tests. Unresolved harness names go to `dangling`.
fn refs_of(text: &str, code: &Code, strict: bool, dangling: &mut Vec<String>) -> Vec<Ref> {
    let mut out = Vec::new();
    let mut last_harness: Option<String> = None;
    let mut last_hint: Option<String> = None;
    for span in backticked(text) {
        let span = span.trim();
        if span.contains(' ') || span.contains('(') && !span.contains('{') {
            continue;
        }
        let mut segs: Vec<&str> = span.split("::").collect();
        let last = segs.pop().unwrap_or(span);
        // a module named before the harness (`teensy::verify_…`) picks the file
        let hint = segs
            .iter()
            .rev()
            .find(|s| {
                code.harnesses
                    .iter()
                    .any(|h| h.file.split('/').any(|part| part == **s))
            })
            .map(|s| (*s).to_string());
        let name = if let Some(cont) = last.strip_prefix('…') {
            match &last_harness {
                Some(prev) => match prev.rsplit_once('_') {
                    Some((stem, _)) => format!("{stem}{cont}"),
                    None => continue,
                },
                None => continue,
            }
        } else {
            last_hint = hint.clone();
            last.to_string()
        };
        let hint = hint.or_else(|| last_hint.clone());
        let in_hint = |h: &Harness| {
            hint.as_ref()
                .is_none_or(|m| h.file.split('/').any(|part| part == m))
        };
        if name.starts_with("verify_") {
            let stem = name.trim_start_matches("verify_");
            if stem.is_empty() || stem.starts_with('<') || stem.starts_with('*') {
                // `verify_<body>_2` and the like describe the naming scheme, not harnesses
                continue;
            }
            last_harness = Some(name.clone());
            let templ = name.contains('<') || name.contains('*') || name.contains('{');
            let found: Vec<(String, String)> = code
                .harnesses
                .iter()
                .filter(|h| in_hint(h))
                .filter(|h| {
                    if templ {
                        template_matches(&name, &h.name)
                    } else {
                        h.name == name
                    }
                })
                .map(|h| (h.name.clone(), h.file.clone()))
                .collect();
            if found.is_empty() {
                dangling.push(name);
            } else {
                out.push(Ref::Harnesses(found));
            }
        } else if code.ladder_bodies.contains(&name) {
            let found: Vec<(String, String)> = code
                .harnesses
                .iter()
                .filter(|h| h.file == LADDER_FILE && h.body == name)
                .map(|h| (h.name.clone(), h.file.clone()))
                .collect();
            out.push(Ref::Harnesses(found));
        } else if is_test_like(&name) {
            if code.all_fns.contains(&name) {
                out.push(Ref::Test(name));
            } else if strict {
                dangling.push(name);
            }
        }
    }
    out
}

/// A snake_case name with two or more underscores (what a test or harness body looks like).
fn is_test_like(s: &str) -> bool {
    s.matches('_').count() >= 2
        && s.chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
}

/// Lines of the section whose heading starts with `## {n}.`.
fn section<'a>(doc: &'a str, n: &str) -> Vec<&'a str> {
    let head = format!("## {n}.");
    let mut out = Vec::new();
    let mut inside = false;
    for l in doc.lines() {
        if l.starts_with("## ") {
            inside = l.starts_with(&head);
            continue;
        }
        if inside {
            out.push(l);
        }
    }
    out
}

/// The Markdown tables of some lines: (header cells, rows of cells, raw rows).
/// A Markdown table: header cells, and each row's cells with its raw line.
type Table<'a> = (Vec<String>, Vec<(Vec<String>, &'a str)>);

fn tables<'a>(lines: &[&'a str]) -> Vec<Table<'a>> {
    let mut out = Vec::new();
    let mut cur: Option<Table<'a>> = None;
    let mut sep_seen = false;
    for l in lines {
        if l.trim_start().starts_with('|') {
            match &mut cur {
                None => {
                    cur = Some((cells(l), Vec::new()));
                    sep_seen = false;
                }
                Some((_, rows)) => {
                    if !sep_seen && l.contains("---") {
                        sep_seen = true;
                    } else {
                        rows.push((cells(l), *l));
                    }
                }
            }
        } else if let Some(t) = cur.take() {
            out.push(t);
        }
    }
    if let Some(t) = cur {
        out.push(t);
    }
    out
}

/// Ids like `H-3`, `SR-12`, `INV-4`, `P-2` in `s` with the given prefix.
fn ids(s: &str, prefix: &str) -> Vec<String> {
    let mut out = Vec::new();
    for (pos, w) in words(s) {
        if w != prefix {
            continue;
        }
        let after = s.get(pos.saturating_add(w.len())..).unwrap_or("");
        if let Some(rest) = after.strip_prefix('-') {
            let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
            if !digits.is_empty() {
                // not part of a longer word (`SR-1` inside `XSR-1` is excluded by `words`)
                out.push(format!("{prefix}-{digits}"));
            }
        }
    }
    out
}

/// What REPORT.md's "Fresh-clone tables" say.
#[derive(Debug, Default)]
pub struct Fresh {
    /// Harness → VERIFIED in its row (stale rows left out).
    pub results: BTreeMap<String, bool>,
    /// Every row's harness, stale ones included.
    pub rows: BTreeSet<String>,
    /// The `Not in this run:` line: harnesses added after the run.
    pub not_run: BTreeSet<String>,
    /// The `Stale rows:` line: rows whose harness was removed or made pending since the run.
    pub stale: BTreeSet<String>,
    /// Harness → (covers satisfied, covers reported), for the rows of tables with a `covers`
    /// column (`–`, no covers, is (0, 0)); stale rows left out.
    pub covers: BTreeMap<String, (u32, u32)>,
    /// Harness → its row's result, checks and covers cells as written (`–` where the table has
    /// no such column), stale rows included: what `cargo xtask kani-table --check` compares.
    pub cells: BTreeMap<String, [String; 3]>,
}

/// A covers cell: `n of m satisfied` → (n, m); anything else (`–`) → no covers, (0, 0).
fn covers_of(cell: &str) -> (u32, u32) {
    let mut parts = cell.split_whitespace();
    let n = parts.next().and_then(|n| n.parse().ok());
    let of = parts.next();
    let m = parts.next().and_then(|m| m.parse().ok());
    match (n, of, m) {
        (Some(n), Some("of"), Some(m)) => (n, m),
        _ => (0, 0),
    }
}

/// The backticked `verify_…` names of a line.
fn harness_names(l: &str) -> impl Iterator<Item = String> + '_ {
    backticked(l)
        .into_iter()
        .filter(|n| n.starts_with("verify_"))
        .map(str::to_string)
}

/// Reads REPORT.md's "Fresh-clone tables" section.
pub fn fresh_clone(report: &str) -> Fresh {
    let mut results = BTreeMap::new();
    let mut covers = BTreeMap::new();
    let mut not_run = BTreeSet::new();
    let mut stale = BTreeSet::new();
    let mut cells_of = BTreeMap::new();
    let mut inside = false;
    let mut covers_col = None;
    let mut checks_col = None;
    for l in report.lines() {
        if l.starts_with("## ") {
            inside = l.starts_with("## Fresh-clone tables");
            continue;
        }
        if !inside {
            continue;
        }
        if l.starts_with('|') {
            let c = cells(l);
            if let (Some(h), Some(r)) = (c.first(), c.get(1)) {
                let h = h.trim_matches('`');
                if h.starts_with("verify_") {
                    results.insert(h.to_string(), r == "VERIFIED");
                    let cell = |col: Option<usize>| col.and_then(|k| c.get(k).cloned());
                    if let Some(cover) = cell(covers_col) {
                        covers.insert(h.to_string(), covers_of(&cover));
                    }
                    let dash = || "–".to_string();
                    cells_of.insert(
                        h.to_string(),
                        [
                            r.clone(),
                            cell(checks_col).unwrap_or_else(dash),
                            cell(covers_col).unwrap_or_else(dash),
                        ],
                    );
                } else if h == "harness" {
                    covers_col = c.iter().position(|x| x == "covers");
                    checks_col = c.iter().position(|x| x == "checks");
                }
            }
        } else if l.starts_with("Not in this run:") {
            not_run.extend(harness_names(l));
        } else if l.starts_with("Stale rows:") {
            stale.extend(harness_names(l));
        }
    }
    let rows = results.keys().cloned().collect();
    results.retain(|h, _| !stale.contains(h));
    covers.retain(|h, _| !stale.contains(h));
    Fresh {
        results,
        rows,
        not_run,
        stale,
        covers,
        cells: cells_of,
    }
}

/// The statuses a claim can have.
const STATUSES: &[&str] = &["VERIFIED", "EXHAUSTIVE", "BOUNDED", "TWIN", "PENDING"];

/// Derives a row's status from what it names.
fn derive_status(refs: &[Ref], code: &Code, results: &BTreeMap<String, bool>) -> &'static str {
    let harnesses: Vec<&(String, String)> = refs
        .iter()
        .filter_map(|r| match r {
            Ref::Harnesses(v) => Some(v),
            Ref::Test(_) => None,
        })
        .flatten()
        .collect();
    let pending = |(n, f): &(String, String)| {
        code.harnesses
            .iter()
            .any(|h| &h.name == n && &h.file == f && h.pending)
    };
    let exhaustive = refs
        .iter()
        .any(|r| matches!(r, Ref::Test(t) if EXHAUSTIVE.contains(&t.as_str())));
    let bounded = refs
        .iter()
        .any(|r| matches!(r, Ref::Test(t) if BOUNDED.iter().any(|(b, _)| *b == t.as_str())));
    let all_verified = harnesses
        .iter()
        .all(|h| !pending(h) && results.get(&h.0) == Some(&true));
    // A claim that rests partly on a test bounded in its inputs is BOUNDED, and one that rests
    // partly on an exhaustive test EXHAUSTIVE, even where its harnesses verified; one harness not
    // verified makes it a twin claim whatever else it names.
    if bounded && all_verified {
        "BOUNDED"
    } else if exhaustive && all_verified {
        "EXHAUSTIVE"
    } else if !harnesses.is_empty() && all_verified {
        "VERIFIED"
    } else if !harnesses.is_empty() && harnesses.iter().all(|h| pending(h)) {
        "PENDING"
    } else {
        "TWIN"
    }
}

/// Whether the assertion text (one statement) is one Kani cannot report by its property.
fn bad_assertion(stmt: &str) -> Option<&'static str> {
    let code = code_only(stmt);
    if code.contains("assert_eq!") {
        return Some("`assert_eq!` (Kani reports a placeholder message)");
    }
    if code.contains("assert_ne!") {
        return Some("`assert_ne!` (Kani reports a placeholder message)");
    }
    if code.contains("debug_assert") {
        return Some("`debug_assert*` (not a property check)");
    }
    let is_assert = words(&code)
        .iter()
        .any(|(_, w)| matches!(*w, "assert" | "check"));
    if is_assert && !stmt.contains('"') {
        return Some("an assertion without a message (Kani reports only its condition)");
    }
    if is_assert {
        // a string literal with a `{` in an assertion is a runtime-formatted message
        let mut in_str = false;
        let mut esc = false;
        for c in stmt.chars() {
            if in_str {
                if esc {
                    esc = false;
                } else if c == '\\' {
                    esc = true;
                } else if c == '"' {
                    in_str = false;
                } else if c == '{' {
                    return Some("an assertion message formatted at run time");
                }
            } else if c == '"' {
                in_str = true;
            }
        }
    }
    // In these `no_std` crates `assert!` and `panic!` are core's, whose message Kani reports as a
    // placeholder even when it is a literal: `check!` and `fail!` pass it to Kani.
    let w = words(&code);
    if w.iter().any(|(_, w)| *w == "assert") {
        return Some("`assert!` (Kani reports a placeholder message: use `check!`)");
    }
    if w.iter().any(|(_, w)| *w == "panic") {
        return Some("`panic!` (Kani reports a placeholder message: use `fail!`)");
    }
    None
}

/// The `#[cfg(test)]` items of a file (test modules and test helpers, which Kani never compiles):
/// (first line, last line), 0-based, inclusive.
fn test_items(raw: &[&str], lines: &[String]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < raw.len() {
        let t = raw.get(i).map_or("", |l| l.trim());
        if t.starts_with("#[cfg(test)]") {
            // the item that follows, after its other attributes and comments
            let mut j = i.saturating_add(1);
            while raw
                .get(j)
                .is_some_and(|l| l.trim().starts_with("#[") || l.trim().starts_with("//"))
            {
                j = j.saturating_add(1);
            }
            let end = block_end(lines, j);
            out.push((i, end));
            i = end;
        }
        i = i.saturating_add(1);
    }
    out
}

/// The assertion problems of one verification file: (line number, what).
fn assertion_problems(text: &str) -> Vec<(usize, &'static str)> {
    let raw: Vec<&str> = text.lines().collect();
    let lines: Vec<String> = raw.iter().map(|l| code_only(l)).collect();
    let skipped = test_items(&raw, &lines);
    let mut out = Vec::new();
    for i in 0..raw.len() {
        if skipped.iter().any(|(s, e)| (*s..=*e).contains(&i)) {
            continue;
        }
        let c = lines.get(i).map_or("", String::as_str);
        // a `const` assertion is checked by the compiler, not by Kani
        let starts_assert = !c.trim_start().starts_with("const ")
            && [
                "assert_eq!",
                "assert_ne!",
                "debug_assert",
                "assert!(",
                "check!(",
                "panic!(",
            ]
            .iter()
            .any(|k| c.contains(k));
        if starts_assert {
            // the statement runs to the line where its brackets close
            let end = block_end(&lines, i);
            let stmt = raw.get(i..=end).map(|ls| ls.join("\n")).unwrap_or_default();
            if let Some(what) = bad_assertion(&stmt) {
                out.push((i.saturating_add(1), what));
            }
        }
    }
    out
}

/// A character that continues an identifier.
fn ident_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// A `check!` or `fail!` invocation: 0-based line of its name, the macro, and the string
/// literals directly among its arguments (as written, escapes included).
type MacroCall = (usize, &'static str, Vec<String>);

/// The `check!` and `fail!` invocations of a file, outside comments and literals.
fn macro_calls(text: &str) -> Vec<MacroCall> {
    let cs: Vec<char> = text.chars().collect();
    let at = |k: usize| cs.get(k).copied().unwrap_or('\0');
    let mut out = Vec::new();
    // open invocations: (line, macro, bracket depth inside its parentheses, literals)
    let mut open: Vec<MacroCall> = Vec::new();
    let mut depths: Vec<usize> = Vec::new();
    let mut depth = 0usize;
    let mut line = 0usize;
    let mut i = 0usize;
    while i < cs.len() {
        let c = at(i);
        let next = at(i.saturating_add(1));
        let prev = if i == 0 {
            '\0'
        } else {
            at(i.saturating_sub(1))
        };
        if c == '\n' {
            line = line.saturating_add(1);
            i = i.saturating_add(1);
        } else if c == '/' && next == '/' {
            while i < cs.len() && at(i) != '\n' {
                i = i.saturating_add(1);
            }
        } else if c == '/' && next == '*' {
            i = i.saturating_add(2);
            while i < cs.len() && !(at(i) == '*' && at(i.saturating_add(1)) == '/') {
                if at(i) == '\n' {
                    line = line.saturating_add(1);
                }
                i = i.saturating_add(1);
            }
            i = i.saturating_add(2);
        } else if c == '"' || (c == 'r' && !ident_char(prev) && matches!(next, '"' | '#')) {
            // a string literal, or a raw one (`r"…"`, `r#"…"#`)
            let mut hashes = 0usize;
            let mut k = i;
            if c == 'r' {
                k = k.saturating_add(1);
                while at(k) == '#' {
                    hashes = hashes.saturating_add(1);
                    k = k.saturating_add(1);
                }
                if at(k) != '"' {
                    // a raw identifier, `r#name`
                    i = k;
                    continue;
                }
            }
            let start = k.saturating_add(1);
            let mut end = start;
            loop {
                let d = at(end);
                if end >= cs.len() {
                    break;
                }
                if c != 'r' && d == '\\' {
                    end = end.saturating_add(2);
                    continue;
                }
                if d == '"' && (1..=hashes).all(|h| at(end.saturating_add(h)) == '#') {
                    break;
                }
                end = end.saturating_add(1);
            }
            let lit: String = cs
                .get(start..end.min(cs.len()))
                .unwrap_or(&[])
                .iter()
                .collect();
            line = line.saturating_add(lit.matches('\n').count());
            if let (Some(call), Some(d)) = (open.last_mut(), depths.last()) {
                if *d == depth {
                    call.2.push(lit);
                }
            }
            i = end.saturating_add(1).saturating_add(hashes);
        } else if c == '\'' {
            // a char literal (`'x'`, `'\n'`, `'\u{…}'`), else a lifetime
            if next == '\\' {
                let mut k = i.saturating_add(2);
                while k < cs.len() && at(k) != '\'' {
                    k = k.saturating_add(1);
                }
                i = k.saturating_add(1);
            } else if at(i.saturating_add(2)) == '\'' {
                i = i.saturating_add(3);
            } else {
                i = i.saturating_add(1);
            }
        } else if (c.is_ascii_alphabetic() || c == '_') && !ident_char(prev) && prev != '$' {
            let start = i;
            while ident_char(at(i)) {
                i = i.saturating_add(1);
            }
            let word: String = cs.get(start..i).unwrap_or(&[]).iter().collect();
            let name = match word.as_str() {
                "check" => Some("check"),
                "fail" => Some("fail"),
                _ => None,
            };
            if let Some(name) = name.filter(|_| at(i) == '!' && at(i.saturating_add(1)) == '(') {
                depth = depth.saturating_add(1);
                open.push((line, name, Vec::new()));
                depths.push(depth);
                i = i.saturating_add(2);
            }
        } else {
            match c {
                '(' | '[' | '{' => depth = depth.saturating_add(1),
                ')' | ']' | '}' => {
                    if depths.last() == Some(&depth) {
                        depths.pop();
                        if let Some(call) = open.pop() {
                            out.push(call);
                        }
                    }
                    depth = depth.saturating_sub(1);
                }
                _ => {}
            }
            i = i.saturating_add(1);
        }
    }
    out
}

/// The property ids (`INV-4`, `P-2`, and the requirements' `SR-12`) that a table of SAFETY.md
/// defines: the ids in the first cell of each row.
fn defined_ids(safety: &str) -> BTreeSet<String> {
    let lines: Vec<&str> = safety.lines().collect();
    let mut out = BTreeSet::new();
    for (_, rows) in tables(&lines) {
        for (c, _) in rows {
            let first = c.first().map_or("", String::as_str);
            for (pos, w) in words(first) {
                if matches!(w, "INV" | "P" | "SR") {
                    out.extend(ids(first.get(pos..).unwrap_or(""), w).into_iter().take(1));
                }
            }
        }
    }
    out
}

/// The ids a message starts with: `"INV-3/INV-16: …"` (or `"INV-10, INV-11: …"`) gives INV-3 and
/// INV-16; `None` when it does not start with ids and `": "`.
fn message_ids(msg: &str) -> Option<Vec<String>> {
    let (head, rest) = msg.split_once(':')?;
    if !rest.starts_with(' ') {
        return None;
    }
    let mut out = Vec::new();
    for part in head.split(['/', ',']) {
        let part = part.trim();
        let (p, n) = part.split_once('-')?;
        let prefix = !p.is_empty() && p.chars().all(|c| c.is_ascii_uppercase());
        let number = !n.is_empty() && n.chars().all(|c| c.is_ascii_digit());
        if !(prefix && number) {
            return None;
        }
        out.push(part.to_string());
    }
    Some(out)
}

/// The message problems of one verification file (`file:line: what`), with the `allowed`
/// messages without an id that it carries (`(file, message)`).
fn message_problems<'a>(
    file: &str,
    text: &str,
    known: &BTreeSet<String>,
    allowed: &[(&'a str, &'a str, &'a str)],
    used: &mut BTreeSet<(&'a str, &'a str)>,
) -> Vec<String> {
    let raw: Vec<&str> = text.lines().collect();
    let lines: Vec<String> = raw.iter().map(|l| code_only(l)).collect();
    let skipped = test_items(&raw, &lines);
    let mut out = Vec::new();
    for (line, name, lits) in macro_calls(text) {
        if skipped.iter().any(|(s, e)| (*s..=*e).contains(&line)) {
            continue;
        }
        let at = format!("{file}:{}: `{name}!`", line.saturating_add(1));
        let Some(msg) = lits.last() else {
            out.push(format!(
                "{at} has no string literal message naming its property"
            ));
            continue;
        };
        match message_ids(msg) {
            None => {
                if let Some((f, m, _)) = allowed
                    .iter()
                    .find(|(f, m, _)| *f == file && *m == msg.as_str())
                {
                    used.insert((f, m));
                } else {
                    out.push(format!(
                        "{at} message \"{}\" does not start with a property id of proofs/SAFETY.md (\"INV-n: …\", \"P-n: …\")",
                        short(msg)
                    ));
                }
            }
            Some(ids) => {
                for id in ids.iter().filter(|id| !known.contains(*id)) {
                    out.push(format!(
                        "{at} message names {id}, which no table of proofs/SAFETY.md defines"
                    ));
                }
            }
        }
    }
    out
}

/// The exceptions the rules allow (the repository's: [`REPOSITORY`]).
#[derive(Debug, Clone, Copy)]
pub struct Allowed<'a> {
    /// `check!`/`fail!` messages without a property id: (file, message, why).
    pub unnamed_messages: &'a [(&'a str, &'a str, &'a str)],
    /// Fresh-clone rows with covers not all satisfied, or none: (harness or `*` prefix, satisfied,
    /// reported, why).
    pub covers: &'a [(&'a str, u32, u32, &'a str)],
}

/// The repository's exceptions.
pub const REPOSITORY: Allowed<'static> = Allowed {
    unnamed_messages: UNNAMED_MESSAGES,
    covers: COVERS_NOT_ALL_SATISFIED,
};

/// Every problem found, one line each (empty: the safety case, the report and the code agree),
/// with the repository's exceptions.
pub fn check(safety: &str, report: &str, code: &Code, sources: &[(String, String)]) -> Vec<String> {
    check_allowing(safety, report, code, sources, REPOSITORY)
}

/// Every problem found, with the exceptions `allowed`.
pub fn check_allowing(
    safety: &str,
    report: &str,
    code: &Code,
    sources: &[(String, String)],
    allowed: Allowed<'_>,
) -> Vec<String> {
    let mut problems = Vec::new();
    let s = "proofs/SAFETY.md";
    let r = "proofs/REPORT.md";
    let fresh = fresh_clone(report);
    let results = &fresh.results;

    // names anywhere in SAFETY.md: dangling harness names, and what is named
    let mut named: BTreeSet<(String, String)> = BTreeSet::new();
    let mut dangling = Vec::new();
    for para in safety.split("\n\n") {
        for line in para.lines() {
            let is_row = line.trim_start().starts_with('|');
            let texts: Vec<String> = if is_row {
                cells(line)
            } else {
                vec![para.to_string()]
            };
            for t in texts {
                for rf in refs_of(&t, code, false, &mut dangling) {
                    if let Ref::Harnesses(v) = rf {
                        named.extend(v);
                    }
                }
            }
            if !is_row {
                break;
            }
        }
    }
    // table columns that name harnesses, twins or tests: every test-like name must exist
    for n in ["4", "5", "6"] {
        for (head, rows) in tables(&section(safety, n)) {
            for (cs, _) in &rows {
                for (k, c) in cs.iter().enumerate() {
                    let h = head.get(k).map_or("", |h| h.as_str()).to_lowercase();
                    if h.contains("harness") || h.contains("twin") || h.contains("test") {
                        refs_of(c, code, true, &mut dangling);
                    }
                }
            }
        }
    }
    let dangling: BTreeSet<String> = dangling.into_iter().collect();
    for d in &dangling {
        problems.push(format!(
            "{s}: names `{d}`, which is no harness, ladder body or function of the code"
        ));
    }

    // the property ids the §4/§5 tables claim (a harness's property line must name one of them)
    let mut claimed: BTreeSet<String> = BTreeSet::new();
    for n in ["4", "5"] {
        for (head, rows) in tables(&section(safety, n)) {
            let first = head.first().map_or("", String::as_str);
            if first == "INV" || first == "id" {
                for (c, _) in rows {
                    let id = c.first().map_or("", String::as_str);
                    claimed.extend(ids(id, "INV").into_iter().chain(ids(id, "P")));
                }
            }
        }
    }

    // every harness named, with a property line and a twin
    for h in &code.harnesses {
        if !named.contains(&(h.name.clone(), h.file.clone())) {
            problems.push(format!(
                "{}: harness `{}` is not named in {s}",
                h.file, h.name
            ));
        }
        let doc = code
            .docs
            .get(&h.file)
            .and_then(|d| d.get(&h.body))
            .map_or("", String::as_str);
        if ids(doc, "INV").is_empty() && ids(doc, "P").is_empty() {
            problems.push(format!(
                "{}: harness `{}`: the first doc line of `{}` names no property id (INV-n or P-n)",
                h.file, h.name, h.body
            ));
        }
        for id in ids(doc, "INV").into_iter().chain(ids(doc, "P")) {
            if !claimed.contains(&id) {
                problems.push(format!(
                    "{}: harness `{}`: the first doc line of `{}` names {id}, which no row of {s} §4/§5 claims",
                    h.file, h.name, h.body
                ));
            }
        }
        let tests = code.tests.get(&h.file);
        let has = |t: &str| tests.is_some_and(|ts| ts.contains(t));
        let plain = h.name.strip_prefix("verify_").unwrap_or(&h.name);
        let mapped = TWIN_OF
            .iter()
            .find(|(f, p, _, _)| *f == h.file && glob_or_eq(p, &h.name));
        let excepted = NO_TWIN
            .iter()
            .any(|(f, p, _)| *f == h.file && glob_or_eq(p, &h.name));
        let twin_ok = excepted
            || has(plain)
            || (h.file == LADDER_FILE && has(&h.body))
            || mapped.is_some_and(|(_, _, t, _)| has(t));
        if !twin_ok {
            problems.push(format!(
                "{}: harness `{}` has no `cargo test` twin (`{}`{})",
                h.file,
                h.name,
                mapped.map_or(plain, |(_, _, t, _)| t),
                if h.file == LADDER_FILE {
                    " or the ladder's twins! module"
                } else {
                    ""
                }
            ));
        }
    }
    // hazards → requirements
    let hazards: Vec<String> = tables(&section(safety, "2"))
        .iter()
        .flat_map(|(_, rows)| rows.iter().filter_map(|(c, _)| c.first().cloned()))
        .filter(|id| id.starts_with("H-"))
        .collect();
    let mut srs: Vec<(String, Vec<String>)> = Vec::new();
    for (head, rows) in tables(&section(safety, "3")) {
        let hz = head.iter().position(|h| h == "hazards");
        for (c, _) in rows {
            if let Some(id) = c.first().filter(|id| id.starts_with("SR-")) {
                let hs = hz
                    .and_then(|k| c.get(k))
                    .map_or(Vec::new(), |t| ids(t, "H"));
                srs.push((id.clone(), hs));
            }
        }
    }
    for h in &hazards {
        if !srs.iter().any(|(_, hs)| hs.contains(h)) {
            problems.push(format!("{s}: hazard {h} (§2) has no requirement in §3"));
        }
    }

    // requirements and invariants → traceability rows
    let mut traced_srs = BTreeSet::new();
    let mut traced_ids = BTreeSet::new();
    for (head, rows) in tables(&section(safety, "6")) {
        let col = |name: &str| head.iter().position(|h| h == name);
        let (Some(sr), Some(inv)) = (col("SR"), col("INV")) else {
            continue;
        };
        let hcol = col("harnesses");
        for (c, _) in rows {
            let inv_text = c.get(inv).map_or("", String::as_str);
            let row_ids: Vec<String> = ids(inv_text, "INV")
                .into_iter()
                .chain(ids(inv_text, "P"))
                .collect();
            let evidence = !row_ids.is_empty()
                || hcol
                    .and_then(|k| c.get(k))
                    .is_some_and(|t| !backticked(t).is_empty());
            if evidence {
                traced_srs.extend(ids(c.get(sr).map_or("", String::as_str), "SR"));
            }
            traced_ids.extend(row_ids);
        }
    }
    for (sr, _) in &srs {
        if !traced_srs.contains(sr) {
            problems.push(format!(
                "{s}: requirement {sr} (§3) has no invariant, test or harness in §6"
            ));
        }
    }

    // claims of §4/§5: traced, with the status the report supports
    for n in ["4", "5"] {
        for (head, rows) in tables(&section(safety, n)) {
            let first = head.first().map_or("", String::as_str);
            if !(first == "INV" || first == "id") {
                continue;
            }
            let status_col = head.iter().position(|h| h == "status");
            for (c, raw) in rows {
                let id = c.first().cloned().unwrap_or_default();
                let claim_ids: Vec<String> =
                    ids(&id, "INV").into_iter().chain(ids(&id, "P")).collect();
                if claim_ids.is_empty() {
                    problems.push(format!("{s}: §{n} row `{}` has no id", short(raw)));
                }
                for cid in &claim_ids {
                    if !traced_ids.contains(cid) {
                        problems.push(format!("{s}: {cid} (§{n}) is in no traceability row of §6"));
                    }
                }
                let mut ignore = Vec::new();
                let refs = refs_of(raw, code, false, &mut ignore);
                let derived = derive_status(&refs, code, results);
                let written = status_col.and_then(|k| c.get(k)).map_or("", String::as_str);
                if written.is_empty() {
                    problems.push(format!(
                        "{s}: {id} (§{n}) has no status (derived from REPORT.md: {derived})"
                    ));
                } else if !STATUSES.contains(&written) {
                    problems.push(format!(
                        "{s}: {id} (§{n}) has status `{written}`, not one of {STATUSES:?}"
                    ));
                } else if written != derived {
                    problems.push(format!(
                        "{s}: {id} (§{n}) says {written}, REPORT.md's fresh-clone tables support {derived}"
                    ));
                }
            }
        }
    }

    // the report's fresh-clone rows against the code (by name, as the table names them)
    let mut by_name: BTreeMap<&str, (bool, &str)> = BTreeMap::new(); // name -> (all pending, file)
    for h in &code.harnesses {
        let e = by_name
            .entry(h.name.as_str())
            .or_insert((true, h.file.as_str()));
        e.0 &= h.pending;
    }
    for (name, (pending, file)) in &by_name {
        let in_table = fresh.rows.contains(*name);
        let stale = fresh.stale.contains(*name);
        let not_run = fresh.not_run.contains(*name);
        if *pending && in_table && !stale {
            problems.push(format!(
                "{r}: fresh-clone row `{name}` is a pending harness now ({file}); put it on the `Stale rows:` line"
            ));
        } else if !*pending && !in_table && !not_run {
            problems.push(format!(
                "{r}: harness `{name}` ({file}) has no fresh-clone row and is not on the `Not in this run:` line"
            ));
        } else if in_table && not_run {
            problems.push(format!(
                "{r}: harness `{name}` is both in the fresh-clone tables and on the `Not in this run:` line"
            ));
        } else if !*pending && stale {
            problems.push(format!(
                "{r}: `{name}` is on the `Stale rows:` line but is a harness of the code as run"
            ));
        }
    }
    for name in fresh.rows.iter().chain(fresh.not_run.iter()) {
        if !by_name.contains_key(name.as_str()) && !fresh.stale.contains(name) {
            problems.push(format!(
                "{r}: fresh-clone tables name `{name}`, which is no harness of the code"
            ));
        }
    }
    for name in &fresh.stale {
        if !fresh.rows.contains(name) {
            problems.push(format!(
                "{r}: `{name}` is on the `Stale rows:` line but has no fresh-clone row"
            ));
        }
    }

    // every cover satisfied, but for the listed exceptions with their counts
    for (name, &(sat, all)) in &fresh.covers {
        if sat == all && all > 0 {
            continue;
        }
        let entry = allowed
            .covers
            .iter()
            .find(|(p, _, _, _)| glob_or_eq(p, name));
        match entry {
            None if all == 0 => problems.push(format!(
                "{r}: fresh-clone row `{name}` has no covers: nothing shows that the harness is not vacuous (or list it with its reason in trace.rs's COVERS_NOT_ALL_SATISFIED)"
            )),
            None => problems.push(format!(
                "{r}: fresh-clone row `{name}` has {sat} of {all} covers satisfied: an unsatisfied cover is a case the harness never reached (or list it with its reason in trace.rs's COVERS_NOT_ALL_SATISFIED)"
            )),
            Some((p, s, a, _)) if (*s, *a) != (sat, all) => problems.push(format!(
                "{r}: fresh-clone row `{name}` has {sat} of {all} covers satisfied; COVERS_NOT_ALL_SATISFIED allows `{p}` {s} of {a}"
            )),
            Some(_) => {}
        }
    }
    for (p, s, a, _) in allowed.covers {
        let matched = fresh
            .covers
            .iter()
            .any(|(name, &c)| glob_or_eq(p, name) && c == (*s, *a));
        if !matched {
            problems.push(format!(
                "xtask/src/trace.rs: COVERS_NOT_ALL_SATISFIED allows `{p}` {s} of {a} covers, which no fresh-clone row shows: remove or correct the entry"
            ));
        }
    }

    // static failure messages, each naming its property
    let known = defined_ids(safety);
    let mut used = BTreeSet::new();
    for (f, text) in sources {
        for (line, what) in assertion_problems(text) {
            problems.push(format!("{f}:{line}: {what}"));
        }
        problems.extend(message_problems(
            f,
            text,
            &known,
            allowed.unnamed_messages,
            &mut used,
        ));
    }
    for (f, m, _) in allowed.unnamed_messages {
        if !used.contains(&(*f, *m)) {
            problems.push(format!(
                "xtask/src/trace.rs: UNNAMED_MESSAGES lists \"{}\" of {f}, which no `check!` or `fail!` there carries without an id: remove the entry",
                short(m)
            ));
        }
    }
    problems
}

/// `p` equals `name`, or is a `*` pattern matching it.
fn glob_or_eq(p: &str, name: &str) -> bool {
    p == name || (p.contains('*') && glob(p, name))
}

/// The first 60 characters of a row, for messages.
fn short(row: &str) -> String {
    row.chars().take(60).collect()
}

/// Files as (path relative to the workspace root, contents).
pub type Files = Vec<(String, String)>;

/// Reads the verification files (every source of the crates holding a `#[kani::proof]`), and
/// the function names of every Rust source of the crates.
pub fn read_sources(root: &Path) -> Result<(Files, BTreeSet<String>), String> {
    let mut files = Vec::new();
    let mut others = BTreeSet::new();
    for krate in CRATES {
        for sub in ["src", "tests", "examples"] {
            collect(root, &root.join(krate).join(sub), &mut files, &mut others)?;
        }
    }
    files.sort();
    Ok((files, others))
}

fn collect(
    root: &Path,
    dir: &Path,
    files: &mut Files,
    out: &mut BTreeSet<String>,
) -> Result<(), String> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Ok(());
    };
    for e in entries {
        let p = e.map_err(|e| e.to_string())?.path();
        if p.is_dir() {
            collect(root, &p, files, out)?;
        } else if p.extension().is_some_and(|x| x == "rs") {
            let text = std::fs::read_to_string(&p).map_err(|e| format!("{}: {e}", p.display()))?;
            out.extend(fn_names(&text));
            if text.contains("#[kani::proof]") {
                let rel = p.strip_prefix(root).unwrap_or(&p);
                files.push((rel.to_string_lossy().replace('\\', "/"), text));
            }
        }
    }
    Ok(())
}

/// Runs every check on the workspace at `root`: the problems, one line each.
pub fn run(root: &Path) -> Result<Vec<String>, String> {
    let read = |f: &str| {
        let p = root.join(f);
        std::fs::read_to_string(&p).map_err(|e| format!("{}: {e}", p.display()))
    };
    let safety = read("proofs/SAFETY.md")?;
    let report = read("proofs/REPORT.md")?;
    let (files, others) = read_sources(root)?;
    let code = scan(&files, &others);
    let mut problems = check(&safety, &report, &code, &files);
    problems.extend(stale_twin_exceptions(&code, TWIN_OF, NO_TWIN));
    Ok(problems)
}

/// The entries of `twin_of` ([`TWIN_OF`]) and `no_twin` ([`NO_TWIN`]) that name no harness of
/// their file: a harness renamed or removed leaves its exception behind, which could then excuse
/// another harness of the same name.
pub fn stale_twin_exceptions(
    code: &Code,
    twin_of: &[(&str, &str, &str, &str)],
    no_twin: &[(&str, &str, &str)],
) -> Vec<String> {
    twin_of
        .iter()
        .map(|(f, p, _, _)| (*f, *p))
        .chain(no_twin.iter().map(|(f, p, _)| (*f, *p)))
        .filter(|(f, p)| {
            !code
                .harnesses
                .iter()
                .any(|h| h.file == *f && glob_or_eq(p, &h.name))
        })
        .map(|(f, p)| {
            format!(
                "xtask/src/trace.rs: the twin exception `{p}` of {f} names no harness there: remove or correct it"
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const CODE: &str = r#"//! Fixture.

/// P-1: the thing stays bounded.
pub fn thing_bounded(src: &mut impl Source) {
    let x = src.u8();
    check!(x < 200, "P-1: the thing stays bounded");
}

#[cfg(kani)]
mod proofs {
    #[kani::proof]
    fn verify_thing_bounded() {
        super::thing_bounded(&mut KaniSource);
    }
}

#[cfg(test)]
mod twins {
    #[test]
    fn thing_bounded() {
        assert_eq!(1, 1, "a test may format {}", 1);
        super::thing_bounded(&mut Twin::new(1));
    }
}
"#;

    const PER_KIND: &str = r#"//! Fixture with one entry per kind.

/// P-2: encode then decode gives the message back.
pub fn check_round_trip_of(src: &mut impl Source, kind: u8) {
    check!(decode(&encode(kind)) == Ok(kind), "P-2: a frame round-trips");
}

#[cfg(kani)]
mod proofs {
    /// One harness per kind.
    macro_rules! round_trip_of {
        ($($name:ident => $kind:literal),+) => {$(
            #[kani::proof]
            fn $name() {
                check_round_trip_of(&mut KaniSource, $kind);
            }
        )+};
    }
    round_trip_of!(
        verify_round_trip_ping => 3,
        verify_round_trip_ack => 4
    );
}

#[cfg(test)]
mod twins {
    #[test]
    fn round_trip_of_every_kind() {
        super::check_round_trip_of(&mut Twin::new(2), 3);
    }
}
"#;

    const SAFETY: &str = "# Safety case

## 2. Hazards

| id | hazard |
|---|---|
| H-1 | runaway |

## 3. Safety requirements

| id | requirement | hazards |
|---|---|---|
| SR-1 | the thing stays bounded and frames round-trip | H-1 |

## 5. Harnesses

| id | property | harness | status |
|---|---|---|---|
| P-1 | bounded | `verify_thing_bounded` | VERIFIED |
| P-2 | round trip | `cdc::verify_round_trip_<kind>` | TWIN |

## 6. Traceability

| hazard | SR | INV | harnesses |
|---|---|---|---|
| H-1 | SR-1 | P-1, P-2 | `verify_thing_bounded` |
";

    const REPORT: &str = "# Report

## Fresh-clone tables

| harness | result | checks | covers | time |
|---|---|---|---|---|
| `verify_thing_bounded` | VERIFIED | 0 of 3 failed | 1 of 1 satisfied | 0.1 s |

Not in this run: `verify_round_trip_ping`, `verify_round_trip_ack`.
";

    /// The problems of the fixture with each file replaced as given.
    fn problems(safety: &str, report: &str, code: &str, per_kind: &str) -> Vec<String> {
        let files = vec![
            ("control/src/verification.rs".to_string(), code.to_string()),
            (
                "protocol/src/cdc/verification.rs".to_string(),
                per_kind.to_string(),
            ),
        ];
        let c = scan(&files, &BTreeSet::new());
        check_allowing(safety, report, &c, &files, NONE)
    }

    /// No exceptions (the repository's name files and harnesses the fixtures do not have).
    const NONE: Allowed<'static> = Allowed {
        unnamed_messages: &[],
        covers: &[],
    };

    /// Asserts that exactly the expected problem is reported.
    fn expect(got: &[String], wanted: &str) {
        assert!(
            got.iter().any(|p| p == wanted),
            "expected {wanted:?}, got {got:#?}"
        );
    }

    #[test]
    #[allow(clippy::expect_used)]
    fn every_file_with_a_harness_is_read() {
        let root = std::env::temp_dir().join(format!("xtask-trace-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let put = |rel: &str, text: &str| {
            let p = root.join(rel);
            std::fs::create_dir_all(p.parent().expect("a parent")).expect("temp dir");
            std::fs::write(p, text).expect("temp file");
        };
        put(
            "mcu/src/deep/new_place.rs",
            "#[kani::proof]\nfn verify_a() {}\n",
        );
        put("mcu/src/plain.rs", "fn helper() {}\n");
        put(
            "xtask/src/lib.rs",
            "#[kani::proof]\nfn verify_outside() {}\n",
        );
        let (files, names) = read_sources(&root).expect("readable");
        let _ = std::fs::remove_dir_all(&root);
        let paths: Vec<&str> = files.iter().map(|(p, _)| p.as_str()).collect();
        assert_eq!(paths, ["mcu/src/deep/new_place.rs"]);
        assert!(names.contains("helper") && names.contains("verify_a"));
    }

    #[test]
    fn the_consistent_fixture_passes() {
        let got = problems(SAFETY, REPORT, CODE, PER_KIND);
        assert!(got.is_empty(), "{got:#?}");
    }

    #[test]
    fn the_code_model_sees_entries_bodies_and_twins() {
        let files = vec![
            ("control/src/verification.rs".to_string(), CODE.to_string()),
            (
                "protocol/src/cdc/verification.rs".to_string(),
                PER_KIND.to_string(),
            ),
        ];
        let c = scan(&files, &BTreeSet::new());
        let names: Vec<(&str, &str)> = c
            .harnesses
            .iter()
            .map(|h| (h.name.as_str(), h.body.as_str()))
            .collect();
        assert_eq!(
            names,
            [
                ("verify_thing_bounded", "thing_bounded"),
                ("verify_round_trip_ping", "check_round_trip_of"),
                ("verify_round_trip_ack", "check_round_trip_of"),
            ]
        );
    }

    #[test]
    fn a_dangling_harness_name_is_reported() {
        let safety = SAFETY.replace(
            "| P-1 | bounded | `verify_thing_bounded` |",
            "| P-1 | bounded | `verify_thing_is_bounded` |",
        );
        expect(
            &problems(&safety, REPORT, CODE, PER_KIND),
            "proofs/SAFETY.md: names `verify_thing_is_bounded`, which is no harness, ladder body or function of the code",
        );
    }

    #[test]
    fn a_template_that_matches_no_harness_is_reported() {
        let safety = SAFETY.replace(
            "`cdc::verify_round_trip_<kind>`",
            "`cdc::verify_trip_<kind>`",
        );
        expect(
            &problems(&safety, REPORT, CODE, PER_KIND),
            "proofs/SAFETY.md: names `verify_trip_<kind>`, which is no harness, ladder body or function of the code",
        );
    }

    #[test]
    fn an_unnamed_harness_is_reported() {
        let safety = SAFETY.replace(
            "`cdc::verify_round_trip_<kind>`",
            "`cdc::verify_round_trip_ping`",
        );
        expect(
            &problems(&safety, REPORT, CODE, PER_KIND),
            "protocol/src/cdc/verification.rs: harness `verify_round_trip_ack` is not named in proofs/SAFETY.md",
        );
    }

    #[test]
    fn a_harness_without_a_property_line_is_reported() {
        let code = CODE.replace(
            "/// P-1: the thing stays bounded.",
            "/// The thing stays bounded.\n/// P-1.",
        );
        let got = problems(SAFETY, REPORT, &code, PER_KIND);
        expect(
            &got,
            "control/src/verification.rs: harness `verify_thing_bounded`: the first doc line of `thing_bounded` names no property id (INV-n or P-n)",
        );
        let code = CODE.replace(
            "/// P-1: the thing stays bounded.",
            "/// The thing stays bounded.",
        );
        expect(
            &problems(SAFETY, REPORT, &code, PER_KIND),
            "control/src/verification.rs: harness `verify_thing_bounded`: the first doc line of `thing_bounded` names no property id (INV-n or P-n)",
        );
    }

    #[test]
    fn a_property_line_naming_an_unclaimed_id_is_reported() {
        let code = CODE.replace(
            "/// P-1: the thing stays bounded.",
            "/// P-1, P-99: the thing stays bounded.",
        );
        expect(
            &problems(SAFETY, REPORT, &code, PER_KIND),
            "control/src/verification.rs: harness `verify_thing_bounded`: the first doc line of `thing_bounded` names P-99, which no row of proofs/SAFETY.md §4/§5 claims",
        );
    }

    #[test]
    fn a_harness_without_a_twin_is_reported() {
        let code = CODE.replace("    fn thing_bounded() {", "    fn thing_is_bounded() {");
        expect(
            &problems(SAFETY, REPORT, &code, PER_KIND),
            "control/src/verification.rs: harness `verify_thing_bounded` has no `cargo test` twin (`thing_bounded`)",
        );
    }

    #[test]
    fn a_hazard_without_a_requirement_is_reported() {
        let safety = SAFETY.replace("| H-1 | runaway |", "| H-1 | runaway |\n| H-2 | fire |");
        expect(
            &problems(&safety, REPORT, CODE, PER_KIND),
            "proofs/SAFETY.md: hazard H-2 (§2) has no requirement in §3",
        );
    }

    #[test]
    fn an_untraced_requirement_or_property_is_reported() {
        let safety = SAFETY
            .replace(
                "| SR-1 | the thing stays bounded and frames round-trip | H-1 |",
                "| SR-1 | the thing stays bounded and frames round-trip | H-1 |\n| SR-2 | more | H-1 |",
            )
            .replace("| H-1 | SR-1 | P-1, P-2 |", "| H-1 | SR-1 | P-1 |");
        let got = problems(&safety, REPORT, CODE, PER_KIND);
        expect(
            &got,
            "proofs/SAFETY.md: requirement SR-2 (§3) has no invariant, test or harness in §6",
        );
        expect(
            &got,
            "proofs/SAFETY.md: P-2 (§5) is in no traceability row of §6",
        );
    }

    #[test]
    fn a_wrong_or_missing_status_is_reported() {
        let safety = SAFETY.replace(
            "| `verify_thing_bounded` | VERIFIED |",
            "| `verify_thing_bounded` | TWIN |",
        );
        expect(
            &problems(&safety, REPORT, CODE, PER_KIND),
            "proofs/SAFETY.md: P-1 (§5) says TWIN, REPORT.md's fresh-clone tables support VERIFIED",
        );
        // a claim resting on a harness not in the run is not VERIFIED
        let safety = SAFETY.replace(
            "| `cdc::verify_round_trip_<kind>` | TWIN |",
            "| `cdc::verify_round_trip_<kind>` | VERIFIED |",
        );
        expect(
            &problems(&safety, REPORT, CODE, PER_KIND),
            "proofs/SAFETY.md: P-2 (§5) says VERIFIED, REPORT.md's fresh-clone tables support TWIN",
        );
        // a failed run does not support VERIFIED
        let report = REPORT.replace("| VERIFIED | 0 of 3 failed", "| **FAILED** | 1 of 3 failed");
        expect(
            &problems(SAFETY, &report, CODE, PER_KIND),
            "proofs/SAFETY.md: P-1 (§5) says VERIFIED, REPORT.md's fresh-clone tables support TWIN",
        );
        let safety = SAFETY.replace(
            "| `verify_thing_bounded` | VERIFIED |",
            "| `verify_thing_bounded` |  |",
        );
        expect(
            &problems(&safety, REPORT, CODE, PER_KIND),
            "proofs/SAFETY.md: P-1 (§5) has no status (derived from REPORT.md: VERIFIED)",
        );
    }

    #[test]
    fn report_rows_are_compared_with_the_code() {
        let report = REPORT.replace(
            "Not in this run: `verify_round_trip_ping`, ",
            "Not in this run: ",
        );
        expect(
            &problems(SAFETY, &report, CODE, PER_KIND),
            "proofs/REPORT.md: harness `verify_round_trip_ping` (protocol/src/cdc/verification.rs) has no fresh-clone row and is not on the `Not in this run:` line",
        );
        let report = REPORT.replace(
            "Not in this run:",
            "| `verify_gone` | VERIFIED | 0 of 1 failed | – | 1.0 s |\n\nNot in this run:",
        );
        expect(
            &problems(SAFETY, &report, CODE, PER_KIND),
            "proofs/REPORT.md: fresh-clone tables name `verify_gone`, which is no harness of the code",
        );
    }

    #[test]
    fn runtime_formatted_assertions_are_reported_outside_test_modules() {
        let code = CODE.replace(
            "    check!(x < 200, \"P-1: the thing stays bounded\");",
            "    assert_eq!(x, 1);\n    assert!(\n        x < 200,\n        \"P-1: {x} too large\"\n    );\n    debug_assert!(x > 0);\n    assert!(x > 1);\n    const _: () = assert!(1 > 0);\n    assert!(x < 200, \"P-1: the thing stays bounded\");\n    let _ = if x > 9 { 0 } else { panic!(\"P-1: small\") };\n    check!(x < 200, \"P-1: the thing stays bounded\");\n    let _ = if x > 9 { 0 } else { fail!(\"P-1: small\") };",
        );
        let got = problems(SAFETY, REPORT, &code, PER_KIND);
        expect(
            &got,
            "control/src/verification.rs:6: `assert_eq!` (Kani reports a placeholder message)",
        );
        expect(
            &got,
            "control/src/verification.rs:7: an assertion message formatted at run time",
        );
        expect(
            &got,
            "control/src/verification.rs:11: `debug_assert*` (not a property check)",
        );
        expect(
            &got,
            "control/src/verification.rs:12: an assertion without a message (Kani reports only its condition)",
        );
        expect(
            &got,
            "control/src/verification.rs:14: `assert!` (Kani reports a placeholder message: use `check!`)",
        );
        expect(
            &got,
            "control/src/verification.rs:15: `panic!` (Kani reports a placeholder message: use `fail!`)",
        );
        // neither the `const` assertion, nor `check!` and `fail!`, nor the `assert_eq!` of the
        // `#[cfg(test)]` module
        assert_eq!(got.len(), 6, "{got:#?}");
    }

    #[test]
    fn a_message_without_a_property_id_is_rejected_and_one_with_an_id_accepted() {
        let msg = |m: &str| {
            CODE.replace(
                "check!(x < 200, \"P-1: the thing stays bounded\");",
                &format!("check!(x < 200, \"{m}\");\n    let _ = || fail!(\"P-1: unreachable\");"),
            )
        };
        // with an id the table defines (one, or several as `INV-3/INV-16: …`), nothing to report
        for ok in [
            "P-1: the thing stays bounded",
            "P-1/P-2: the thing stays bounded",
            "SR-1: the thing stays bounded",
        ] {
            let got = problems(SAFETY, REPORT, &msg(ok), PER_KIND);
            assert!(got.is_empty(), "{ok}: {got:#?}");
        }
        // without one, or with an id no table defines, or not at the start
        let got = problems(SAFETY, REPORT, &msg("the thing stays bounded"), PER_KIND);
        assert_eq!(
            got,
            ["control/src/verification.rs:6: `check!` message \"the thing stays bounded\" does not start with a property id of proofs/SAFETY.md (\"INV-n: …\", \"P-n: …\")"]
        );
        let got = problems(
            SAFETY,
            REPORT,
            &msg("P-99: the thing stays bounded"),
            PER_KIND,
        );
        assert_eq!(
            got,
            ["control/src/verification.rs:6: `check!` message names P-99, which no table of proofs/SAFETY.md defines"]
        );
        let got = problems(
            SAFETY,
            REPORT,
            &msg("H-1: the thing stays bounded"),
            PER_KIND,
        );
        assert_eq!(got.len(), 1, "a hazard is no property: {got:#?}");
        let got = problems(SAFETY, REPORT, &msg("bounded (P-1)"), PER_KIND);
        assert_eq!(got.len(), 1, "{got:#?}");
        // `fail!` too, a message over several lines, and the line of the macro's name
        let code = CODE.replace(
            "check!(x < 200, \"P-1: the thing stays bounded\");",
            "check!(x < 200, \"P-1: the thing stays bounded\");\n    if x > 250 {\n        fail!(\n            \"never\"\n        )\n    }",
        );
        let got = problems(SAFETY, REPORT, &code, PER_KIND);
        assert_eq!(
            got,
            ["control/src/verification.rs:8: `fail!` message \"never\" does not start with a property id of proofs/SAFETY.md (\"INV-n: …\", \"P-n: …\")"]
        );
        // messages of the `#[cfg(test)]` module, comments and other literals are not read
        let code = CODE
            .replace(
                "        assert_eq!(1, 1, \"a test may format {}\", 1);",
                "        check!(true, \"a test's message\");",
            )
            .replace(
                "    let x = src.u8();",
                "    let x = src.u8(); // check!(x > 0, \"a comment\")\n    let _s = r#\"check!(x > 0, \"a literal\")\"#;\n    let _c = '\"';",
            );
        let got = problems(SAFETY, REPORT, &code, PER_KIND);
        assert!(got.is_empty(), "{got:#?}");
    }

    #[test]
    fn a_listed_message_without_an_id_is_allowed_and_a_stale_entry_reported() {
        let code = CODE.replace(
            "\"P-1: the thing stays bounded\"",
            "\"the thing stays bounded\"",
        );
        let files = vec![("control/src/verification.rs".to_string(), code)];
        let c = scan(&files, &BTreeSet::new());
        let safety = SAFETY.replace(
            "| P-2 | round trip | `cdc::verify_round_trip_<kind>` | TWIN |\n",
            "",
        );
        let report = REPORT.replace(
            "Not in this run: `verify_round_trip_ping`, `verify_round_trip_ack`.\n",
            "",
        );
        let listed = [(
            "control/src/verification.rs",
            "the thing stays bounded",
            "a fixture's reason",
        )];
        let allowed = Allowed {
            unnamed_messages: &listed,
            covers: &[],
        };
        let got = check_allowing(&safety, &report, &c, &files, allowed);
        assert!(got.is_empty(), "{got:#?}");
        let files = vec![("control/src/verification.rs".to_string(), CODE.to_string())];
        let got = check_allowing(&safety, &report, &c, &files, allowed);
        assert_eq!(
            got,
            ["xtask/src/trace.rs: UNNAMED_MESSAGES lists \"the thing stays bounded\" of control/src/verification.rs, which no `check!` or `fail!` there carries without an id: remove the entry"]
        );
    }

    #[test]
    fn unsatisfied_or_missing_covers_are_rejected_unless_listed() {
        let run = |covers: &str, allowed: &[(&str, u32, u32, &str)]| {
            let report = REPORT.replace("1 of 1 satisfied", covers);
            let files = vec![
                ("control/src/verification.rs".to_string(), CODE.to_string()),
                (
                    "protocol/src/cdc/verification.rs".to_string(),
                    PER_KIND.to_string(),
                ),
            ];
            let c = scan(&files, &BTreeSet::new());
            let allowed = Allowed {
                unnamed_messages: &[],
                covers: allowed,
            };
            check_allowing(SAFETY, &report, &c, &files, allowed)
        };
        let why = "a fixture's reason";
        assert_eq!(
            run("1 of 2 satisfied", &[]),
            ["proofs/REPORT.md: fresh-clone row `verify_thing_bounded` has 1 of 2 covers satisfied: an unsatisfied cover is a case the harness never reached (or list it with its reason in trace.rs's COVERS_NOT_ALL_SATISFIED)"]
        );
        assert_eq!(
            run("–", &[]),
            ["proofs/REPORT.md: fresh-clone row `verify_thing_bounded` has no covers: nothing shows that the harness is not vacuous (or list it with its reason in trace.rs's COVERS_NOT_ALL_SATISFIED)"]
        );
        // listed with its counts: allowed; with other counts, or a listing no row needs: reported
        assert!(run("1 of 2 satisfied", &[("verify_thing_*", 1, 2, why)]).is_empty());
        assert!(run("–", &[("verify_thing_bounded", 0, 0, why)]).is_empty());
        assert_eq!(
            run("0 of 2 satisfied", &[("verify_thing_*", 1, 2, why)]),
            [
                "proofs/REPORT.md: fresh-clone row `verify_thing_bounded` has 0 of 2 covers satisfied; COVERS_NOT_ALL_SATISFIED allows `verify_thing_*` 1 of 2",
                "xtask/src/trace.rs: COVERS_NOT_ALL_SATISFIED allows `verify_thing_*` 1 of 2 covers, which no fresh-clone row shows: remove or correct the entry",
            ]
        );
        assert_eq!(
            run("1 of 1 satisfied", &[("verify_thing_bounded", 0, 0, why)]),
            ["xtask/src/trace.rs: COVERS_NOT_ALL_SATISFIED allows `verify_thing_bounded` 0 of 0 covers, which no fresh-clone row shows: remove or correct the entry"]
        );
    }

    #[test]
    fn a_twin_exception_that_names_no_harness_is_reported() {
        let files = vec![("control/src/verification.rs".to_string(), CODE.to_string())];
        let code = scan(&files, &BTreeSet::new());
        let file = "control/src/verification.rs";
        let live = [(file, "verify_thing_*", "thing_bounded", "why")];
        assert!(stale_twin_exceptions(&code, &live, &[]).is_empty());
        let gone = [(file, "verify_gone", "why")];
        assert_eq!(
            stale_twin_exceptions(&code, &live, &gone),
            ["xtask/src/trace.rs: the twin exception `verify_gone` of control/src/verification.rs names no harness there: remove or correct it"]
        );
    }

    #[test]
    fn every_listed_exception_has_its_reason() {
        for (f, m, why) in UNNAMED_MESSAGES {
            assert!(!why.trim().is_empty(), "{f}: {m}");
        }
        for (p, _, _, why) in COVERS_NOT_ALL_SATISFIED {
            assert!(!why.trim().is_empty(), "{p}");
        }
    }

    const LADDER: &str = r#"//! Ladder fixture.

/// INV-7: latching faults brake in the same step.
pub fn faults_brake<const N: usize>(src: &mut impl Source) {
    check!(brakes::<N>(src), "INV-7: a fault brakes in the same step");
}

#[cfg(kani)]
macro_rules! proofs {
    ($($kind:ident $body:ident => $two:ident $(, $four:ident)?;)*) => {
        $( proofs!(@one $kind $body $two 2); $(proofs!(@one $kind $body $four 4);)? )*
    };
    (@one plain $body:ident $name:ident $n:literal) => {
        // a comment that mentions #[test] is not an attribute
        #[kani::proof]
        fn $name() {
            super::$body::<$n>(&mut KaniSource);
        }
    };
}

#[cfg(kani)]
mod kani_entry {
    proofs! {
        plain faults_brake => verify_faults_brake_2, verify_faults_brake_4;
    }
}

#[cfg(test)]
macro_rules! twins {
    ($($body:ident => $seed:expr;)*) => {
        $(
            mod $body {
                #[test]
                fn two_axes() {}
            }
        )*
    };
}

#[cfg(test)]
mod twins {
    twins! {
        faults_brake => 1;
    }
}
"#;

    #[test]
    fn a_ladder_body_names_its_entries_for_each_axis_count() {
        let files = vec![(LADDER_FILE.to_string(), LADDER.to_string())];
        let c = scan(&files, &BTreeSet::new());
        let names: Vec<(&str, &str)> = c
            .harnesses
            .iter()
            .map(|h| (h.name.as_str(), h.body.as_str()))
            .collect();
        assert_eq!(
            names,
            [
                ("verify_faults_brake_2", "faults_brake"),
                ("verify_faults_brake_4", "faults_brake")
            ]
        );
        let safety = "## 4. Invariants\n\n| INV | statement | harness / twin | status |\n|---|---|---|---|\n\
                      | INV-7 | faults brake | `faults_brake` | VERIFIED |\n\n\
                      ## 6. Traceability\n\n| hazard | SR | INV | harnesses |\n|---|---|---|---|\n\
                      | H-6 | SR-6 | INV-7 | `faults_brake` |\n";
        let report = "## Fresh-clone tables\n\n| harness | result |\n|---|---|\n\
                      | `verify_faults_brake_2` | VERIFIED |\n| `verify_faults_brake_4` | VERIFIED |\n";
        let got = check_allowing(safety, report, &c, &files, NONE);
        assert!(got.is_empty(), "{got:#?}");
        // one axis count missing from the run: the claim is no longer VERIFIED
        let report = report.replace("| `verify_faults_brake_4` | VERIFIED |\n", "");
        let got = check_allowing(safety, &report, &c, &files, NONE);
        expect(
            &got,
            "proofs/SAFETY.md: INV-7 (§4) says VERIFIED, REPORT.md's fresh-clone tables support TWIN",
        );
    }

    #[test]
    fn templates_expand() {
        assert!(template_matches(
            "verify_round_trip_<kind>",
            "verify_round_trip_ping"
        ));
        assert!(!template_matches(
            "verify_round_trip_<kind>",
            "verify_round_trip_"
        ));
        assert!(template_matches(
            "verify_fold{16,8}_total",
            "verify_fold8_total"
        ));
        assert!(!template_matches(
            "verify_fold{16,8}_total",
            "verify_fold4_total"
        ));
        assert!(template_matches(
            "verify_*_bit_flip_detected",
            "verify_command_bit_flip_detected"
        ));
    }

    /// The real safety case, report and code agree (the same check as `cargo xtask trace`).
    #[test]
    fn the_repository_passes() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"))
            .parent()
            .unwrap_or(Path::new("."));
        let problems = run(root).unwrap_or_else(|e| vec![e]);
        assert!(problems.is_empty(), "{}", problems.join("\n"));
    }
}

//! Output of a batch of runs: the summary table (text and CSV) and SVG plots.

use crate::runner::Summary;

fn opt(x: Option<f64>, digits: usize) -> String {
    x.map_or_else(|| "-".to_string(), |v| format!("{v:.digits$}"))
}

/// Column headers of the summary table. A column that does not apply to a profile shows "-".
pub const COLUMNS: [&str; 20] = [
    "scenario",
    "profile",
    "result",
    "HOLD ms",
    "STOP ms",
    "BRAKE ms",
    "BRAKE after last frame ms",
    "bridge braked after last frame ms",
    "BRAKE after last frame ticks",
    "v at onset m/s",
    "stop distance m",
    "corrupted sent/rejected/applied",
    "final mode",
    "clock err us",
    "replies decoded/bad",
    "joint err steps",
    "odometry err % (heading deg)",
    "servo violations/checks",
    "host reports",
    "speed x real time",
];

fn row(s: &Summary, failures: &[String]) -> Vec<String> {
    vec![
        s.name.clone(),
        s.profile.clone(),
        if failures.is_empty() {
            "PASS".into()
        } else {
            "FAIL".into()
        },
        opt(s.hold_ms, 1),
        opt(s.stop_ms, 1),
        opt(s.brake_ms, 1),
        opt(s.brake_after_last_frame_ms, 2),
        opt(s.bridge_brake_after_last_frame_ms, 2),
        s.brake_after_last_frame_ticks
            .map_or_else(|| "-".to_string(), |n| n.to_string()),
        opt(s.speed_at_onset, 2),
        opt(s.stop_distance_m, 3),
        format!(
            "{}/{}/{}",
            s.corrupted_sent, s.corrupted_rejected, s.corrupted_applied
        ),
        s.final_mode.clone(),
        opt(s.clock_err_final_us, 1),
        s.replies
            .map_or_else(|| "-".to_string(), |[ok, bad]| format!("{ok}/{bad}")),
        opt(s.joint_err_steps, 2),
        s.odometry_err_pct.map_or_else(
            || "-".to_string(),
            |x| format!("{x:.3} ({})", opt(s.odometry_heading_err_deg, 2)),
        ),
        s.servo_violations
            .map_or_else(|| "-".to_string(), |n| format!("{n}/{}", s.servo_checks)),
        s.host_reports
            .iter()
            .map(|(t, n, c)| format!("{n}@{t:.3}s×{c}"))
            .collect::<Vec<_>>()
            .join(" "),
        format!("{:.0}", s.speedup()),
    ]
}

/// The summary as an aligned text table (times in ms after the fault onset).
pub fn table(results: &[(Summary, Vec<String>)]) -> String {
    let rows: Vec<Vec<String>> = results.iter().map(|(s, f)| row(s, f)).collect();
    let mut widths: Vec<usize> = COLUMNS.iter().map(|c| c.chars().count()).collect();
    for r in &rows {
        for (w, c) in widths.iter_mut().zip(r) {
            *w = (*w).max(c.chars().count());
        }
    }
    let line = |cells: &[String]| {
        cells
            .iter()
            .zip(&widths)
            .map(|(c, w)| format!("{c:<w$}"))
            .collect::<Vec<_>>()
            .join(" | ")
    };
    let head: Vec<String> = COLUMNS.iter().map(|c| (*c).to_string()).collect();
    let mut out = line(&head);
    out.push('\n');
    out.push_str(
        &widths
            .iter()
            .map(|w| "-".repeat(*w))
            .collect::<Vec<_>>()
            .join("-|-"),
    );
    for r in &rows {
        out.push('\n');
        out.push_str(&line(r));
    }
    for (s, f) in results {
        for msg in f {
            out.push_str(&format!("\nFAIL {}: {msg}", s.name));
        }
    }
    out.push('\n');
    out
}

/// The summary as CSV.
pub fn csv(results: &[(Summary, Vec<String>)]) -> String {
    let esc = |c: &str| {
        if c.contains(',') || c.contains('"') {
            format!("\"{}\"", c.replace('"', "\"\""))
        } else {
            c.to_string()
        }
    };
    let mut out = COLUMNS.iter().map(|c| esc(c)).collect::<Vec<_>>().join(",");
    for (s, f) in results {
        out.push('\n');
        out.push_str(
            &row(s, f)
                .iter()
                .map(|c| esc(c))
                .collect::<Vec<_>>()
                .join(","),
        );
    }
    out.push('\n');
    out
}

pub use crate::plot::plot;

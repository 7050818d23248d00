//! Output of a batch of runs: the summary table (text and CSV) and SVG plots.

use std::path::Path;

use plotters::prelude::*;

use crate::runner::{RunResult, Series, Summary};

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

/// Keeps at most `max` points; min/max-preserving for step signals.
fn decimate(n: usize, max: usize) -> usize {
    n.div_ceil(max.max(1)).max(1)
}

/// Draws speed, mode and watchdog age over time into an SVG file.
pub fn plot(path: &Path, title: &str, r: &RunResult) -> Result<(), String> {
    let s: &Series = &r.series;
    if s.t.is_empty() {
        return Err("no series recorded".into());
    }
    let stride = decimate(s.t.len(), 4000);
    let idx: Vec<usize> = (0..s.t.len()).step_by(stride).collect();
    let t0 = s.t.first().copied().unwrap_or(0.0);
    let t1 = s.t.last().copied().unwrap_or(1.0).max(t0 + 1e-3);
    let root = SVGBackend::new(path, (1100, 820)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let root = root
        .titled(title, ("sans-serif", 20))
        .map_err(|e| e.to_string())?;
    let panels = root.split_evenly((3, 1));
    let e = |x: DrawingAreaErrorKind<std::io::Error>| x.to_string();

    // Speeds (seed 000), or the profile's own signals.
    const PALETTE: [RGBColor; 8] = [
        BLUE,
        RED,
        RGBColor(0, 150, 0),
        MAGENTA,
        CYAN,
        RGBColor(160, 120, 0),
        RGBColor(120, 120, 120),
        BLACK,
    ];
    type Line<'a> = (&'a str, &'a Vec<f64>, RGBColor);
    let (caption, lines): (&str, Vec<Line>) = match &s.lines {
        Some(panel) => (
            panel.caption.as_str(),
            panel
                .signals
                .iter()
                .zip(PALETTE.iter().cycle())
                .map(|((name, ys), c)| (name.as_str(), ys, *c))
                .collect(),
        ),
        None => (
            "wheel speed (rad/s)",
            vec![
                ("left wheel", &s.wheel[0], BLUE),
                ("right wheel", &s.wheel[1], RED),
                ("left applied (ladder)", &s.applied[0], CYAN),
                ("right applied (ladder)", &s.applied[1], MAGENTA),
                ("left host command", &s.host_cmd[0], RGBColor(0, 120, 0)),
                ("right host command", &s.host_cmd[1], RGBColor(160, 120, 0)),
            ],
        ),
    };
    let mut lo = -1.0f64;
    let mut hi = 1.0f64;
    for (_, ys, _) in &lines {
        for v in ys.iter().filter(|v| v.is_finite()) {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    }
    let pad = 0.05 * (hi - lo);
    let mut c = ChartBuilder::on(&panels[0])
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .caption(caption, ("sans-serif", 15))
        .build_cartesian_2d(t0..t1, (lo - pad)..(hi + pad))
        .map_err(e)?;
    c.configure_mesh().x_desc("t (s)").draw().map_err(e)?;
    for (name, ys, color) in lines {
        c.draw_series(LineSeries::new(
            idx.iter()
                .filter(|&&i| ys[i].is_finite())
                .map(|&i| (s.t[i], ys[i])),
            color.stroke_width(1),
        ))
        .map_err(e)?
        .label(name)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], color));
    }
    c.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(e)?;

    // Mode (per-bucket maximum so short excursions stay visible).
    let bucket_max = |v: &[u8]| -> Vec<(f64, f64)> {
        (0..s.t.len())
            .step_by(stride)
            .map(|i| {
                let end = (i + stride).min(v.len());
                let m = v[i..end].iter().copied().max().unwrap_or(0);
                (s.t[i], f64::from(m))
            })
            .collect()
    };
    let mut c = ChartBuilder::on(&panels[1])
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .caption(
            "ladder mode (0 NORMAL, 1 REDUCED, 2 HOLD, 3 STOP, 4 BRAKE)",
            ("sans-serif", 15),
        )
        .build_cartesian_2d(t0..t1, -0.2f64..4.4f64)
        .map_err(e)?;
    c.configure_mesh()
        .x_desc("t (s)")
        .y_labels(5)
        .draw()
        .map_err(e)?;
    c.draw_series(LineSeries::new(bucket_max(&s.mode), BLACK.stroke_width(2)))
        .map_err(e)?;

    // Watchdog age.
    let age: Vec<u8> = s.age.iter().map(|&m| m.min(255) as u8).collect();
    let top = f64::from(age.iter().copied().max().unwrap_or(0).max(12)) + 1.0;
    let th = statemachine::ConfigParams::DEFAULT;
    let [hold_after, stop_after, brake_after] =
        s.thresholds
            .unwrap_or([th.hold_after, th.stop_after, th.brake_after]);
    let caption = format!(
        "watchdog age (ticks since last valid frame; HOLD ≥ {hold_after}, STOP ≥ {stop_after}, BRAKE ≥ {brake_after})"
    );
    let mut c = ChartBuilder::on(&panels[2])
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .caption(caption, ("sans-serif", 15))
        .build_cartesian_2d(t0..t1, 0f64..top)
        .map_err(e)?;
    c.configure_mesh().x_desc("t (s)").draw().map_err(e)?;
    c.draw_series(LineSeries::new(bucket_max(&age), BLUE.stroke_width(1)))
        .map_err(e)?;
    for (lvl, col) in [
        (hold_after, RGBColor(200, 150, 0)),
        (stop_after, RGBColor(230, 90, 0)),
        (brake_after, RED),
    ] {
        let lvl = f64::from(lvl);
        c.draw_series(LineSeries::new(
            vec![(t0, lvl), (t1, lvl)],
            col.stroke_width(1),
        ))
        .map_err(e)?;
    }
    root.present().map_err(|x| x.to_string())?;
    Ok(())
}

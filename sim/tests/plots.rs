//! The plots a run writes, read back as SVG text: the mode axis names the modes, the fault and the
//! BRAKE are marked and zoomed on, the description is whole, the legends stand beside the traces
//! (never over them), and the clock-drift run plots its clock error.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::panic
)]

use motorlink::SimHost;
use sim::report;
use sim::scenario::builtin;

/// Runs a built-in scenario (its duration capped at `max_s`) with series kept and returns the SVG.
fn svg_of(name: &str, max_s: f64) -> (String, String) {
    let mut sc = builtin()
        .unwrap()
        .into_iter()
        .find(|s| s.name == name)
        .unwrap_or_else(|| panic!("no built-in {name}"));
    sc.duration_s = sc.duration_s.min(max_s);
    let mut host = SimHost::new();
    let opts = sim::RunOptions {
        progress: false,
        keep_series: true,
    };
    let r = sim::run(&sc, &mut host, opts, None).unwrap();
    static RUN: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let k = RUN.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("plots-test-{}-{k}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("plot.svg");
    report::plot(&path, &sc.name, &sc.description, &r).unwrap();
    let svg = std::fs::read_to_string(&path).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    (sc.description, svg)
}

/// Every `<text …>content</text>` of the SVG with its x attribute.
fn texts(svg: &str) -> Vec<(f64, String)> {
    let mut out = Vec::new();
    let mut rest = svg;
    while let Some(start) = rest.find("<text") {
        rest = &rest[start..];
        let Some(close) = rest.find('>') else { break };
        let tag = &rest[..close];
        let Some(end) = rest.find("</text>") else {
            break;
        };
        let content = rest[close + 1..end].trim().to_string();
        let x = tag
            .split("x=\"")
            .nth(1)
            .and_then(|v| v.split('"').next())
            .and_then(|v| v.parse().ok())
            .unwrap_or(f64::NAN);
        out.push((x, content));
        rest = &rest[end..];
    }
    out
}

/// The largest x of the traces: every point of the SVG's polylines of three points or more (legend
/// glyphs, markers and threshold lines are two-point lines).
fn max_polyline_x(svg: &str) -> f64 {
    let mut max = f64::NEG_INFINITY;
    for part in svg.split("<polyline").skip(1) {
        let points = part
            .split("points=\"")
            .nth(1)
            .and_then(|v| v.split('"').next())
            .unwrap_or("");
        let pairs: Vec<&str> = points.split_whitespace().collect();
        if pairs.len() < 3 {
            continue;
        }
        for pair in pairs {
            if let Some(x) = pair.split(',').next().and_then(|v| v.parse::<f64>().ok()) {
                max = max.max(x);
            }
        }
    }
    max
}

#[test]
fn a_comm_loss_plot_names_the_modes_marks_and_zooms_on_the_fault() {
    let (description, svg) = svg_of("gc-pause-50ms", 3.0);
    let t = texts(&svg);
    let has = |s: &str| t.iter().any(|(_, c)| c.contains(s));
    for mode in ["NORMAL", "REDUCED", "HOLD", "STOP", "BRAKE"] {
        assert!(
            t.iter().any(|(_, c)| c == mode),
            "the mode axis names {mode}"
        );
    }
    assert!(has("fault onset"), "the fault's onset is marked");
    assert!(has("last valid frame"), "the last valid frame is marked");
    assert!(has("zoom: ladder mode"), "a zoomed mode panel is drawn");
    assert!(has("zoom: watchdog age"), "a zoomed age panel is drawn");
    for level in ["HOLD ≥", "STOP ≥", "BRAKE ≥"] {
        assert!(has(level), "the {level} threshold is labelled");
    }
    // The title is the whole description: every word appears in some text line.
    let all: String = t
        .iter()
        .map(|(_, c)| c.as_str())
        .collect::<Vec<_>>()
        .join(" ");
    let all = all
        .replace("&amp;", "&")
        .replace("&lt;", "<")
        .replace("&gt;", ">");
    for word in description.split_whitespace() {
        assert!(all.contains(word), "the title keeps the word {word:?}");
    }
    // A zoom of about the comm-loss descent: the caption says how wide, a few tens of ms.
    let zoom = t
        .iter()
        .find(|(_, c)| c.starts_with("zoom: ladder mode"))
        .map(|(_, c)| c.clone())
        .unwrap();
    let ms: f64 = zoom
        .split(", ")
        .nth(1)
        .and_then(|v| v.split(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap();
    assert!(ms > 8.0 && ms < 100.0, "zoom span {ms} ms");
}

#[test]
fn legends_stand_right_of_every_trace() {
    let (_, svg) = svg_of("gc-pause-50ms", 3.0);
    let t = texts(&svg);
    let right_edge = max_polyline_x(&svg);
    assert!(right_edge.is_finite(), "traces are drawn");
    for name in ["left wheel", "right host command", "age"] {
        let (x, _) = t
            .iter()
            .find(|(_, c)| c == name)
            .unwrap_or_else(|| panic!("legend entry {name}"));
        assert!(
            *x > right_edge,
            "legend entry {name} at x = {x} is right of every trace (≤ {right_edge})"
        );
    }
}

#[test]
fn the_clock_drift_run_plots_its_clock_error_and_the_others_without_sync_do_not() {
    let (_, svg) = svg_of("clock-drift-50ppm", 4.0);
    let t = texts(&svg);
    assert!(
        t.iter().any(|(_, c)| c.starts_with("clock-sync error")),
        "the clock-drift run has a clock-error panel"
    );
    let (_, svg) = svg_of("cdc-4wd-timeout", 4.0);
    let t = texts(&svg);
    assert!(
        !t.iter().any(|(_, c)| c.starts_with("clock-sync error")),
        "the USB CDC link has no clock sync to plot"
    );
    assert!(
        t.iter().any(|(_, c)| c.starts_with("zoom: ladder mode")),
        "its comm-loss BRAKE is zoomed on"
    );
}

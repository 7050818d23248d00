//! The SVG plot of one run: what a person reviewing a fault wants to see at a glance.
//!
//! ```text
//!  ┌ name (bold) ─────────────────────────────────────────────┐
//!  │ description, wrapped (never cut)                          │
//!  ├──────────────────────────────────────────────┬────────────┤
//!  │ speeds (or the profile's own signals)         │ legend     │
//!  │ ladder mode, axis labelled NORMAL … BRAKE     │ markers    │
//!  │ zoom: mode │ zoom: watchdog age               │            │  (around the fault)
//!  │ watchdog age, HOLD/STOP/BRAKE lines labelled  │            │
//!  │ clock-sync error (the AMR link's runs)        │            │
//!  └──────────────────────────────────────────────┴────────────┘
//! ```
//!
//! Markers: the fault's onset, the last valid frame before the comm-loss BRAKE, and the BRAKE
//! itself, drawn as vertical lines in every time panel. Legends sit in their own column, so they
//! never cover a trace.

use std::path::Path;

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::runner::{RunResult, Series, Summary};

/// Width of the SVG, px.
const WIDTH: u32 = 1400;
/// Width of the legend column at the right, px.
const LEGEND_W: u32 = 250;
/// Characters per line of the wrapped description.
const WRAP: usize = 140;
/// Colours of the first panel's signals.
const PALETTE: [RGBColor; 8] = [
    BLUE,
    RED,
    RGBColor(0, 150, 0),
    MAGENTA,
    RGBColor(0, 150, 170),
    RGBColor(160, 120, 0),
    RGBColor(120, 120, 120),
    BLACK,
];
/// The ladder's modes, in the order of their numbers in the series.
const MODE_NAMES: [&str; 5] = ["NORMAL", "REDUCED", "HOLD", "STOP", "BRAKE"];
/// Colour of the fault-onset marker.
const ONSET: RGBColor = RGBColor(220, 0, 0);
/// Colour of the last-valid-frame marker.
const LAST_FRAME: RGBColor = RGBColor(110, 110, 110);
/// Colour of the BRAKE marker.
const BRAKE: RGBColor = RGBColor(0, 0, 0);

type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;
type Err = String;

fn err<E: std::fmt::Display>(e: E) -> Err {
    e.to_string()
}

/// Splits `text` into lines of at most `width` characters at spaces (a longer word gets a line of
/// its own); nothing is dropped.
pub fn wrap(text: &str, width: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut line = String::new();
    for word in text.split_whitespace() {
        if !line.is_empty() && line.chars().count() + 1 + word.chars().count() > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines
}

/// The label of a mode-axis tick: the mode's name at whole numbers, nothing between them.
pub fn mode_label(v: f64) -> String {
    let r = v.round();
    if (v - r).abs() > 1e-6 || !(0.0..=4.0).contains(&r) {
        return String::new();
    }
    MODE_NAMES
        .get(r as usize)
        .map_or_else(String::new, |s| (*s).to_string())
}

/// The instants a reader looks for, s: the fault's onset, the last valid frame before the
/// comm-loss BRAKE, and the first BRAKE after the onset.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Markers {
    /// Fault onset.
    pub onset: Option<f64>,
    /// Last valid frame before the comm-loss BRAKE.
    pub last_frame: Option<f64>,
    /// First BRAKE after the onset.
    pub brake: Option<f64>,
}

impl Markers {
    /// The markers of a run, from its summary.
    pub fn of(s: &Summary) -> Self {
        let brake = s.onset_s.zip(s.brake_ms).map(|(o, b)| o + b * 1e-3);
        let last_frame = brake
            .zip(s.brake_after_last_frame_ms)
            .map(|(b, since)| b - since * 1e-3);
        Self {
            onset: s.onset_s,
            last_frame,
            brake,
        }
    }

    fn each(&self) -> impl Iterator<Item = (f64, &'static str, RGBColor)> {
        [
            self.onset.map(|t| (t, "fault onset", ONSET)),
            self.last_frame.map(|t| (t, "last valid frame", LAST_FRAME)),
            self.brake.map(|t| (t, "BRAKE", BRAKE)),
        ]
        .into_iter()
        .flatten()
    }

    /// The zoom window around the fault, s: from shortly before the onset (or the last valid
    /// frame) to shortly after the BRAKE; none without a BRAKE after an onset.
    pub fn zoom(&self) -> Option<(f64, f64)> {
        let brake = self.brake?;
        let start = self
            .onset
            .into_iter()
            .chain(self.last_frame)
            .fold(brake, f64::min);
        let span = (brake - start).max(0.005);
        Some((start - 0.5 * span, brake + 0.5 * span))
    }
}

/// One legend entry: a name and a colour, in the legend column beside its panel.
struct Entry {
    name: String,
    color: RGBColor,
    dashed: bool,
}

fn draw_legend(area: &Area<'_>, title: &str, entries: &[Entry]) -> Result<(), Err> {
    let font = ("sans-serif", 13).into_font();
    let title = wrap(title, 32);
    for (k, line) in title.iter().enumerate() {
        area.draw(&Text::new(
            line.clone(),
            (6, 4 + 16 * k as i32),
            ("sans-serif", 13).into_font().style(FontStyle::Bold),
        ))
        .map_err(err)?;
    }
    let top = 8 + 16 * title.len() as i32;
    for (k, entry) in entries.iter().enumerate() {
        let y = top + 18 * k as i32;
        let style = entry.color.stroke_width(2);
        if entry.dashed {
            for x in [6, 14, 22] {
                area.draw(&PathElement::new(vec![(x, y + 7), (x + 5, y + 7)], style))
                    .map_err(err)?;
            }
        } else {
            area.draw(&PathElement::new(vec![(6, y + 7), (28, y + 7)], style))
                .map_err(err)?;
        }
        area.draw(&Text::new(entry.name.clone(), (34, y), font.clone()))
            .map_err(err)?;
    }
    Ok(())
}

fn marker_entries(m: &Markers) -> Vec<Entry> {
    m.each()
        .map(|(_, name, color)| Entry {
            name: name.to_string(),
            color,
            dashed: true,
        })
        .collect()
}

/// Vertical dashed lines at the markers inside `[x0, x1]`, from `y0` to `y1`.
fn draw_markers<DB: DrawingBackend>(
    c: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    m: &Markers,
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
) -> Result<(), Err>
where
    DB::ErrorType: 'static,
{
    for (t, _, color) in m.each().filter(|(t, _, _)| (x0..=x1).contains(t)) {
        c.draw_series(DashedLineSeries::new(
            [(t, y0), (t, y1)],
            4,
            4,
            color.stroke_width(1),
        ))
        .map_err(err)?;
    }
    Ok(())
}

/// The indices of the series inside `[x0, x1]`, at most about `max` of them.
fn window(t: &[f64], (x0, x1): (f64, f64), max: usize) -> Vec<usize> {
    let inside: Vec<usize> = (0..t.len())
        .filter(|&i| (x0..=x1).contains(&t[i]))
        .collect();
    let stride = inside.len().div_ceil(max.max(1)).max(1);
    inside.into_iter().step_by(stride).collect()
}

/// Per-bucket maximum of a step signal at the indices `idx` (short excursions stay visible).
fn bucket_max(t: &[f64], v: &[f64], idx: &[usize]) -> Vec<(f64, f64)> {
    idx.iter()
        .enumerate()
        .map(|(k, &i)| {
            let end = idx.get(k + 1).copied().unwrap_or(i + 1).min(v.len());
            let m = v[i..end.max(i + 1).min(v.len())]
                .iter()
                .copied()
                .fold(f64::NEG_INFINITY, f64::max);
            (t[i], m)
        })
        .collect()
}

/// A step signal's points as drawn: each value holds until the next sample (no slanted edges).
pub fn steps(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(points.len() * 2);
    for (k, &(t, v)) in points.iter().enumerate() {
        if k > 0 {
            if let Some(&(_, prev)) = points.get(k - 1) {
                out.push((t, prev));
            }
        }
        out.push((t, v));
    }
    out
}

fn mode_panel(
    area: &Area<'_>,
    caption: &str,
    s: &Series,
    m: &Markers,
    range: (f64, f64),
) -> Result<(), Err> {
    let idx = window(&s.t, range, 4000);
    let mode: Vec<f64> = s.mode.iter().map(|&x| f64::from(x)).collect();
    let mut c = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(75)
        .caption(caption, ("sans-serif", 15))
        .build_cartesian_2d(range.0..range.1, -0.4f64..4.4f64)
        .map_err(err)?;
    c.configure_mesh()
        .x_desc("t (s)")
        .y_labels(9)
        .y_label_formatter(&|v| mode_label(*v))
        .draw()
        .map_err(err)?;
    c.draw_series(LineSeries::new(
        steps(&bucket_max(&s.t, &mode, &idx)),
        BLACK.stroke_width(2),
    ))
    .map_err(err)?;
    draw_markers(&mut c, m, range, (-0.4, 4.4))
}

/// The watchdog-age panel with the profile's HOLD, STOP and BRAKE thresholds as labelled lines
/// (the labels beside the lines where they have room, else only in the legend). Returns the
/// thresholds' legend entries.
fn age_panel(
    area: &Area<'_>,
    caption: &str,
    s: &Series,
    m: &Markers,
    range: (f64, f64),
) -> Result<Vec<Entry>, Err> {
    let th = statemachine::ConfigParams::DEFAULT;
    let [hold, stop, brake] =
        s.thresholds
            .unwrap_or([th.hold_after, th.stop_after, th.brake_after]);
    let idx = window(&s.t, range, 4000);
    let age: Vec<f64> = s.age.iter().map(|&a| f64::from(a)).collect();
    let shown_max = idx.iter().map(|&i| age[i]).fold(0.0, f64::max);
    let top = shown_max.max(f64::from(brake) * 1.25).max(12.0) + 1.0;
    let mut c = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(75)
        .caption(caption, ("sans-serif", 15))
        .build_cartesian_2d(range.0..range.1, 0f64..top)
        .map_err(err)?;
    c.configure_mesh()
        .x_desc("t (s)")
        .y_desc("ticks")
        .draw()
        .map_err(err)?;
    c.draw_series(LineSeries::new(
        steps(&bucket_max(&s.t, &age, &idx)),
        BLUE.stroke_width(1),
    ))
    .map_err(err)?;
    let lines = [
        (hold, "HOLD", RGBColor(200, 150, 0)),
        (stop, "STOP", RGBColor(230, 90, 0)),
        (brake, "BRAKE", RED),
    ];
    // Pixels between the closest two thresholds: the labels need about 13.
    let (_, plot_h) = c.plotting_area().dim_in_pixel();
    let gap = f64::from(stop.abs_diff(hold).min(brake.abs_diff(stop)));
    let room = gap / top * f64::from(plot_h) >= 13.0;
    let mut entries = Vec::new();
    for (level, name, color) in lines {
        let y = f64::from(level);
        c.draw_series(LineSeries::new(
            [(range.0, y), (range.1, y)],
            color.stroke_width(1),
        ))
        .map_err(err)?;
        let label = format!("{name} ≥ {level} ticks");
        if room {
            c.draw_series(std::iter::once(Text::new(
                label.clone(),
                (range.0 + 0.005 * (range.1 - range.0), y),
                ("sans-serif", 12).into_font().color(&color),
            )))
            .map_err(err)?;
        }
        entries.push(Entry {
            name: label,
            color,
            dashed: false,
        });
    }
    draw_markers(&mut c, m, range, (0.0, top))?;
    Ok(entries)
}

/// Draws a run into an SVG file at `path`: the scenario's `name` and its whole `description`
/// (wrapped), the profile's signals, the ladder's mode with named levels, a zoom around the fault,
/// the watchdog age against the labelled thresholds, and the clock-sync error where the run has one.
pub fn plot(path: &Path, name: &str, description: &str, r: &RunResult) -> Result<(), Err> {
    let s: &Series = &r.series;
    if s.t.is_empty() {
        return Err("no series recorded".into());
    }
    let t0 = s.t.first().copied().unwrap_or(0.0);
    let t1 = s.t.last().copied().unwrap_or(1.0).max(t0 + 1e-3);
    let full = (t0, t1);
    let m = Markers::of(&r.summary);
    let zoom = m
        .zoom()
        .map(|(a, b)| (a.max(t0), b.min(t1)))
        .filter(|(a, b)| b > a);
    let clock: Vec<(f64, f64)> =
        s.t.iter()
            .zip(&s.clock_err_us)
            .filter(|(_, e)| e.is_finite())
            .map(|(t, e)| (*t, *e))
            .collect();

    let desc = wrap(description, WRAP);
    let title_h = 36 + 19 * desc.len() as u32;
    let rows: Vec<(&str, u32)> = [
        Some(("signals", 270)),
        Some(("mode", 170)),
        zoom.map(|_| ("zoom", 230)),
        Some(("age", 190)),
        (!clock.is_empty()).then_some(("clock", 190)),
    ]
    .into_iter()
    .flatten()
    .collect();
    let height = title_h + rows.iter().map(|(_, h)| h).sum::<u32>() + 10;

    let root = SVGBackend::new(path, (WIDTH, height)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (title, body) = root.split_vertically(title_h);
    title
        .draw(&Text::new(
            name.to_string(),
            (12, 8),
            ("sans-serif", 22).into_font().style(FontStyle::Bold),
        ))
        .map_err(err)?;
    for (k, line) in desc.iter().enumerate() {
        title
            .draw(&Text::new(
                line.clone(),
                (12, 36 + 19 * k as i32),
                ("sans-serif", 15),
            ))
            .map_err(err)?;
    }

    let (plots, legends) = body.split_horizontally(WIDTH - LEGEND_W);
    let heights: Vec<u32> = rows.iter().map(|(_, h)| *h).collect();
    let mut y = 0u32;
    let mut split = Vec::new();
    for h in &heights {
        split.push(y + h);
        y += h;
    }
    let plot_rows = plots.split_by_breakpoints::<u32, u32, _, _>(Vec::new(), split.clone());
    let legend_rows = legends.split_by_breakpoints::<u32, u32, _, _>(Vec::new(), split);
    let markers = marker_entries(&m);

    for (((kind, _), area), legend) in rows.iter().zip(&plot_rows).zip(&legend_rows) {
        match *kind {
            "signals" => {
                let (caption, entries) = signals_panel(area, s, &m, full)?;
                let mut entries = entries;
                entries.extend(marker_entries(&m));
                draw_legend(legend, &caption, &entries)?;
            }
            "mode" => {
                mode_panel(area, "ladder mode", s, &m, full)?;
                draw_legend(legend, "ladder mode", &markers)?;
            }
            "zoom" => {
                if let Some(z) = zoom {
                    let (left, right) = area.split_horizontally((WIDTH - LEGEND_W) / 2);
                    let span_ms = (z.1 - z.0) * 1e3;
                    mode_panel(
                        &left,
                        &format!("zoom: ladder mode, {span_ms:.0} ms around the fault"),
                        s,
                        &m,
                        z,
                    )?;
                    let thresholds = age_panel(&right, "zoom: watchdog age", s, &m, z)?;
                    let mut entries = vec![Entry {
                        name: "mode".into(),
                        color: BLACK,
                        dashed: false,
                    }];
                    entries.extend(thresholds);
                    entries.extend(marker_entries(&m));
                    draw_legend(legend, "zoom", &entries)?;
                }
            }
            "age" => {
                let thresholds = age_panel(
                    area,
                    "watchdog age (ticks since the last valid frame)",
                    s,
                    &m,
                    full,
                )?;
                let mut entries = vec![Entry {
                    name: "age".into(),
                    color: BLUE,
                    dashed: false,
                }];
                entries.extend(thresholds);
                entries.extend(marker_entries(&m));
                draw_legend(legend, "watchdog age", &entries)?;
            }
            _ => {
                clock_panel(area, &clock, full)?;
                draw_legend(
                    legend,
                    "clock sync",
                    &[Entry {
                        name: "estimate − truth".into(),
                        color: RGBColor(0, 120, 0),
                        dashed: false,
                    }],
                )?;
            }
        }
    }
    root.present().map_err(err)?;
    Ok(())
}

/// The first panel: the wheel speeds of the AMR link's run, or the profile's own signals.
/// Returns the legend's title and entries.
fn signals_panel(
    area: &Area<'_>,
    s: &Series,
    m: &Markers,
    range: (f64, f64),
) -> Result<(String, Vec<Entry>), Err> {
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
                (
                    "left applied (ladder)",
                    &s.applied[0],
                    RGBColor(0, 150, 170),
                ),
                ("right applied (ladder)", &s.applied[1], MAGENTA),
                ("left host command", &s.host_cmd[0], RGBColor(0, 120, 0)),
                ("right host command", &s.host_cmd[1], RGBColor(160, 120, 0)),
            ],
        ),
    };
    let idx = window(&s.t, range, 4000);
    let mut lo = -1.0f64;
    let mut hi = 1.0f64;
    for (_, ys, _) in &lines {
        for v in ys.iter().filter(|v| v.is_finite()) {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    }
    let pad = 0.05 * (hi - lo);
    let mut c = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(75)
        .caption(caption, ("sans-serif", 15))
        .build_cartesian_2d(range.0..range.1, (lo - pad)..(hi + pad))
        .map_err(err)?;
    c.configure_mesh().x_desc("t (s)").draw().map_err(err)?;
    let mut entries = Vec::new();
    for (name, ys, color) in lines {
        c.draw_series(LineSeries::new(
            idx.iter()
                .filter(|&&i| ys.get(i).is_some_and(|v| v.is_finite()))
                .map(|&i| (s.t[i], ys[i])),
            color.stroke_width(1),
        ))
        .map_err(err)?;
        entries.push(Entry {
            name: name.to_string(),
            color,
            dashed: false,
        });
    }
    draw_markers(&mut c, m, range, (lo - pad, hi + pad))?;
    Ok((caption.to_string(), entries))
}

/// The clock-sync panel: the host's estimate of the MCU clock minus the truth, µs.
fn clock_panel(area: &Area<'_>, clock: &[(f64, f64)], range: (f64, f64)) -> Result<(), Err> {
    let stride = clock.len().div_ceil(4000).max(1);
    let pts: Vec<(f64, f64)> = clock.iter().step_by(stride).copied().collect();
    let (lo, hi) = pts.iter().fold((-10.0f64, 10.0f64), |(lo, hi), (_, e)| {
        (lo.min(*e), hi.max(*e))
    });
    let pad = 0.05 * (hi - lo);
    let mut c = ChartBuilder::on(area)
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(75)
        .caption(
            "clock-sync error: host's estimate of the MCU's timestamp minus the truth (µs)",
            ("sans-serif", 15),
        )
        .build_cartesian_2d(range.0..range.1, (lo - pad)..(hi + pad))
        .map_err(err)?;
    c.configure_mesh()
        .x_desc("t (s)")
        .y_desc("µs")
        .draw()
        .map_err(err)?;
    c.draw_series(LineSeries::new(pts, RGBColor(0, 120, 0).stroke_width(1)))
        .map_err(err)?;
    c.draw_series(LineSeries::new(
        [(range.0, 0.0), (range.1, 0.0)],
        BLACK.mix(0.4).stroke_width(1),
    ))
    .map_err(err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_keeps_every_word_and_respects_the_width() {
        let text = "MCU crystal 50 ppm fast, host clock 0.3 ppm (NTP); 1 % of link cycles preempted by up to 3 ms.";
        let lines = wrap(text, 30);
        assert!(lines.iter().all(|l| l.chars().count() <= 30));
        assert_eq!(lines.join(" "), text);
        assert!(lines.len() >= 3);
    }

    #[test]
    fn steps_hold_each_value_until_the_next_sample() {
        let drawn = steps(&[(0.0, 0.0), (1.0, 4.0), (2.0, 2.0)]);
        assert_eq!(
            drawn,
            vec![(0.0, 0.0), (1.0, 0.0), (1.0, 4.0), (2.0, 4.0), (2.0, 2.0)]
        );
    }

    #[test]
    fn mode_axis_names_the_five_modes_and_nothing_between() {
        assert_eq!(mode_label(0.0), "NORMAL");
        assert_eq!(mode_label(1.0), "REDUCED");
        assert_eq!(mode_label(2.0), "HOLD");
        assert_eq!(mode_label(3.0), "STOP");
        assert_eq!(mode_label(4.0), "BRAKE");
        assert_eq!(mode_label(0.5), "");
        assert_eq!(mode_label(-1.0), "");
        assert_eq!(mode_label(5.0), "");
    }

    #[test]
    fn markers_put_the_last_frame_before_the_brake_and_the_zoom_around_both() {
        let s = Summary {
            onset_s: Some(2.0),
            brake_ms: Some(10.0),
            brake_after_last_frame_ms: Some(9.5),
            ..Summary::default()
        };
        let m = Markers::of(&s);
        let brake = m.brake.unwrap_or(f64::NAN);
        let last = m.last_frame.unwrap_or(f64::NAN);
        assert!((brake - 2.010).abs() < 1e-9);
        assert!((last - 2.0005).abs() < 1e-9);
        let (a, b) = m.zoom().unwrap_or((f64::NAN, f64::NAN));
        assert!(a < 2.0 && b > 2.010, "the zoom holds onset and BRAKE");
        assert!(b - a < 0.1, "the zoom is a zoom: {a}..{b}");
        assert_eq!(Markers::of(&Summary::default()).zoom(), None);
    }
}

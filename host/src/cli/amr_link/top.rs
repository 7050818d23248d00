//! `motorlink top`: the AMR link live in the terminal (ratatui on crossterm): the MCU's mode,
//! feedback age, wheel speeds, currents, faults by name, link counters, clock sync, and plots of
//! the wheel speeds and the mode over the last seconds. `teleop` draws the same view with its
//! command line. The drawing is a pure function of a [`View`], tested on ratatui's `TestBackend`.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Mutex};
use std::time::{Duration, Instant};

use ratatui::crossterm::event::{self, Event, KeyCode, KeyEvent, KeyEventKind, KeyModifiers};
use ratatui::layout::{Constraint, Direction, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Axis, Block, Borders, Chart, Dataset, GraphType, Paragraph, Sparkline};
use ratatui::{DefaultTerminal, Frame};
use statemachine::Mode;

use super::teleop::{Key, Teleop};
use super::{
    fault_names, mode_name, ArmResult, LinkCounters, Outcome, Port, Report, Session, WAIT_MS,
};

/// How many seconds the plots show.
pub const PLOT_SECONDS: f64 = 5.0;

/// Everything the view shows, taken from a session at one moment.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct View {
    /// The title: the verb and the device.
    pub title: String,
    /// The MCU's mode, if any feedback came.
    pub mode: Option<&'static str>,
    /// Age of the last feedback, ms.
    pub feedback_age_ms: Option<f64>,
    /// The bridge's arming state.
    pub arm_state: String,
    /// Wheel speeds (left, right), rad/s.
    pub wheel_radps: [f32; 2],
    /// Motor currents (left, right), A.
    pub current_a: [f32; 2],
    /// Encoder counts.
    pub encoder: [i32; 2],
    /// Fault flags by name.
    pub faults: Vec<String>,
    /// Link counters.
    pub counters: LinkCounters,
    /// Clock sync: acquired.
    pub clock_synced: bool,
    /// Clock offset MCU − host, µs, when synced.
    pub clock_offset_us: Option<f64>,
    /// Clock skew, ppm.
    pub clock_skew_ppm: f64,
    /// Wheel speeds over the last [`PLOT_SECONDS`]: (seconds before now, left, right).
    pub wheel_history: Vec<(f64, f64, f64)>,
    /// The mode over the last [`PLOT_SECONDS`], oldest first (0 NORMAL … 4 BRAKE).
    pub mode_history: Vec<u64>,
    /// Teleop's command line (v m/s, ω rad/s, being sent).
    pub command: Option<(f64, f64, bool)>,
    /// The last diagnostics, newest last.
    pub recent: Vec<String>,
    /// The key help line.
    pub help: String,
}

impl View {
    /// A snapshot of `s`.
    pub fn of<P: Port>(s: &Session<P>, title: &str) -> Self {
        let fb = s.feedback();
        let now = s.now_us;
        let mut wheel_history = Vec::new();
        let mut mode_history = Vec::new();
        let mut last_mode_t: Option<u64> = None;
        for smp in s.history.iter() {
            let ago = now.saturating_sub(smp.t_us) as f64 * 1e-6;
            if ago > PLOT_SECONDS {
                continue;
            }
            wheel_history.push((
                -ago,
                f64::from(smp.fb.left_speed),
                f64::from(smp.fb.right_speed),
            ));
            // One mode bar per 50 ms.
            if last_mode_t.is_none_or(|t| smp.t_us.saturating_sub(t) >= 50_000) {
                last_mode_t = Some(smp.t_us);
                mode_history.push(u64::from(smp.fb.mode.min(u32::from(u8::MAX))));
            }
        }
        let clock = &s.bridge.clock;
        let synced = clock.is_synced(now);
        Self {
            title: title.to_string(),
            mode: fb.map(|f| mode_name(f.mode)),
            feedback_age_ms: s.feedback_age_us().map(|a| a as f64 * 1e-3),
            arm_state: format!("{:?}", s.bridge.state()),
            wheel_radps: fb.map_or([0.0; 2], |f| [f.left_speed, f.right_speed]),
            current_a: fb.map_or([0.0; 2], |f| [f.left_current, f.right_current]),
            encoder: fb.map_or([0; 2], |f| [f.left_encoder, f.right_encoder]),
            faults: fb.map_or_else(Vec::new, |f| fault_names(f.fault_flags)),
            counters: s.counters.clone(),
            clock_synced: synced,
            clock_offset_us: if synced {
                clock.offset_at(now as f64)
            } else {
                None
            },
            clock_skew_ppm: clock.skew_ppm(),
            wheel_history,
            mode_history,
            command: None,
            recent: s
                .recent
                .iter()
                .rev()
                .take(4)
                .rev()
                .map(|(t, d)| format!("{:9.3} s  {} {}", *t as f64 * 1e-6, d.name(), detail(d)))
                .collect(),
            help: "q quit".into(),
        }
    }
}

/// The fields of a diagnostic worth a glance.
fn detail(d: &crate::Diagnostic) -> String {
    use crate::Diagnostic as D;
    match d {
        D::Mode { mode } => mode_name(u32::from(*mode)).to_string(),
        D::BrakeLatched { faults } | D::ArmRefused { faults } => {
            fault_names(u32::from(*faults)).join(",")
        }
        D::HostLate { gap_us } => format!("{gap_us} us"),
        D::FeedbackRejected { reason } => format!("reason {reason}"),
        _ => String::new(),
    }
}

/// The colour of a mode.
fn mode_style(mode: Option<&str>) -> Style {
    let c = match mode {
        Some("NORMAL") => Color::Green,
        Some("REDUCED") => Color::Yellow,
        Some("HOLD") | Some("STOP") => Color::LightRed,
        Some("BRAKE") => Color::Red,
        _ => Color::Gray,
    };
    Style::default().fg(c).add_modifier(Modifier::BOLD)
}

/// Draws `v` on the whole frame.
pub fn render(f: &mut Frame<'_>, v: &View) {
    let rows = Layout::default()
        .direction(Direction::Vertical)
        .constraints([
            Constraint::Length(8),
            Constraint::Min(6),
            Constraint::Length(5),
            Constraint::Length(6),
        ])
        .split(f.area());
    let area = |i: usize| rows.get(i).copied().unwrap_or_default();
    f.render_widget(status(v), area(0));
    render_wheels(f, v, area(1));
    let modes = Sparkline::default()
        .block(Block::default().borders(Borders::ALL).title(format!(
            "mode, last {PLOT_SECONDS} s (bar height: 0 NORMAL .. 4 BRAKE)"
        )))
        .data(&v.mode_history)
        .max(Mode::Brake as u64)
        .style(Style::default().fg(Color::LightRed));
    f.render_widget(modes, area(2));
    let mut lines: Vec<Line<'_>> = v.recent.iter().map(|r| Line::from(r.as_str())).collect();
    lines.push(Line::from(Span::styled(
        v.help.as_str(),
        Style::default().add_modifier(Modifier::DIM),
    )));
    f.render_widget(
        Paragraph::new(lines).block(Block::default().borders(Borders::ALL).title("diagnostics")),
        area(3),
    );
}

fn status(v: &View) -> Paragraph<'_> {
    let mode = v.mode.unwrap_or("no feedback");
    let age = v
        .feedback_age_ms
        .map_or("-".to_string(), |a| format!("{a:.1} ms"));
    let faults = if v.faults.is_empty() {
        "none".to_string()
    } else {
        v.faults.join(" ")
    };
    let clock = if v.clock_synced {
        format!(
            "synced, offset {} us, skew {:+.1} ppm",
            v.clock_offset_us
                .map_or("-".to_string(), |o| format!("{o:+.0}")),
            v.clock_skew_ppm
        )
    } else {
        "not synced".to_string()
    };
    let c = &v.counters;
    let mut lines = vec![
        Line::from(vec![
            Span::raw("mode "),
            Span::styled(mode, mode_style(v.mode)),
            Span::raw(format!(
                "   bridge {}   feedback age {age}   clock {clock}",
                v.arm_state
            )),
        ]),
        Line::from(format!(
            "wheels  L {:+7.2}  R {:+7.2} rad/s   currents  L {:+6.2}  R {:+6.2} A   encoders {} {}",
            v.wheel_radps[0], v.wheel_radps[1], v.current_a[0], v.current_a[1], v.encoder[0], v.encoder[1]
        )),
        Line::from(vec![
            Span::raw("faults  "),
            Span::styled(
                faults,
                if v.faults.is_empty() {
                    Style::default()
                } else {
                    Style::default().fg(Color::Red)
                },
            ),
        ]),
        Line::from(format!(
            "link    exchanges {}  feedback ok {}  refused {}  not accepted {}  transport errors {}  gaps {}",
            c.exchanges, c.feedback_ok, c.feedback_rejected, c.not_accepted, c.transport_errors, c.gaps
        )),
    ];
    if let Some((cv, cw, live)) = v.command {
        lines.push(Line::from(format!(
            "command v {cv:+.2} m/s  w {cw:+.2} rad/s  {}",
            if live {
                "SENDING (a key came within the hold time)"
            } else {
                "IDLE: no key recently, nothing sent; the bridge ramps to zero"
            }
        )));
    }
    Paragraph::new(lines).block(
        Block::default()
            .borders(Borders::ALL)
            .title(v.title.as_str()),
    )
}

fn render_wheels(f: &mut Frame<'_>, v: &View, area: Rect) {
    let left: Vec<(f64, f64)> = v.wheel_history.iter().map(|p| (p.0, p.1)).collect();
    let right: Vec<(f64, f64)> = v.wheel_history.iter().map(|p| (p.0, p.2)).collect();
    let peak = v
        .wheel_history
        .iter()
        .fold(1.0f64, |m, p| m.max(p.1.abs()).max(p.2.abs()));
    let bound = (peak * 1.1).ceil();
    let data = vec![
        Dataset::default()
            .name("left")
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .style(Style::default().fg(Color::Cyan))
            .data(&left),
        Dataset::default()
            .name("right")
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .style(Style::default().fg(Color::Magenta))
            .data(&right),
    ];
    let chart = Chart::new(data)
        .block(
            Block::default()
                .borders(Borders::ALL)
                .title(format!("wheel speed, rad/s, last {PLOT_SECONDS} s")),
        )
        .x_axis(Axis::default().bounds([-PLOT_SECONDS, 0.0]).labels(vec![
            Line::from(format!("-{PLOT_SECONDS} s")),
            Line::from("now"),
        ]))
        .y_axis(Axis::default().bounds([-bound, bound]).labels(vec![
            Line::from(format!("{:.0}", -bound)),
            Line::from("0"),
            Line::from(format!("{bound:.0}")),
        ]));
    f.render_widget(chart, area);
}

/// What runs the view: `top` only watches; `teleop` drives.
pub enum Driver {
    /// Watch: enable 0 frames, the bridge never arms.
    Watch,
    /// Drive with the keyboard.
    Teleop(Teleop),
}

/// The terminal in raw mode on the alternate screen; restored when dropped (also on a panic:
/// ratatui's `try_init` installs a hook that restores it first).
struct TermGuard(DefaultTerminal);

impl TermGuard {
    fn enter() -> Result<Self, String> {
        ratatui::try_init().map(Self).map_err(|e| {
            format!("cannot put the terminal in raw mode ({e}): top and teleop need a terminal")
        })
    }
}

impl Drop for TermGuard {
    fn drop(&mut self) {
        let _ = ratatui::try_restore();
    }
}

/// Reads the keys that arrive within `wait` (and any more already there).
fn keys(wait: Duration) -> Vec<KeyEvent> {
    let mut out = Vec::new();
    let mut wait = wait;
    while matches!(event::poll(wait), Ok(true)) {
        wait = Duration::ZERO;
        if let Ok(Event::Key(k)) = event::read() {
            if k.kind != KeyEventKind::Release {
                out.push(k);
            }
        }
    }
    out
}

/// A key press as teleop's key.
pub fn key_of(k: &KeyEvent) -> Key {
    if k.modifiers.contains(KeyModifiers::CONTROL) && k.code == KeyCode::Char('c') {
        return Key::Quit;
    }
    match k.code {
        KeyCode::Up | KeyCode::Char('w') | KeyCode::Char('W') => Key::Up,
        KeyCode::Down | KeyCode::Char('s') | KeyCode::Char('S') => Key::Down,
        KeyCode::Left | KeyCode::Char('a') | KeyCode::Char('A') => Key::Left,
        KeyCode::Right | KeyCode::Char('d') | KeyCode::Char('D') => Key::Right,
        KeyCode::Char(' ') => Key::Zero,
        KeyCode::Char('q') | KeyCode::Char('Q') | KeyCode::Esc => Key::Quit,
        KeyCode::Char('x') | KeyCode::Char('X') => Key::Estop,
        KeyCode::Char('r') | KeyCode::Char('R') => Key::Rearm,
        _ => Key::Other,
    }
}

/// How often the view is redrawn.
const REDRAW: Duration = Duration::from_millis(100);

/// How long the terminal thread waits for a key before it looks at the view again.
const KEY_POLL: Duration = Duration::from_millis(20);

/// Runs the view (and, for teleop, the keyboard drive) until q, Ctrl-C, `stop` or `seconds`;
/// always restores the terminal, then returns the report (the robot commanded to zero and
/// disarmed first).
///
/// The 1 kHz bridge runs in its own thread, so drawing and reading keys never delay a frame:
///
/// ```text
///  link thread   cycle ─ cycle ─ cycle ─ … every 1 ms; keys from the channel; a View every 100 ms
///  this thread   poll keys (20 ms) ─► channel;  latest View ─► terminal;  q / signal ─► quit flag
/// ```
pub fn run<P: Port + Send>(
    s: &mut Session<P>,
    verb: &'static str,
    driver: Driver,
    seconds: Option<f64>,
    stop: &mut dyn FnMut() -> bool,
) -> Result<Report, String> {
    s.bridge.disarm();
    let before = s.feedback();
    let title = format!("motorlink {verb}: {}", s.port.name());
    let mut term = TermGuard::enter()?;
    let t0 = Instant::now();
    let quit = AtomicBool::new(false);
    let latest: Mutex<Option<View>> = Mutex::new(None);
    let (keys_tx, keys_rx) = mpsc::channel::<Key>();
    let mut interrupted = false;
    let session = &mut *s;
    let (looped, drawn) = std::thread::scope(|scope| {
        let (quit, latest, title) = (&quit, &latest, &title);
        let link =
            scope.spawn(move || link_loop(session, driver, seconds, &keys_rx, quit, latest, title));
        let mut drawn: Result<(), String> = Ok(());
        while !link.is_finished() {
            if stop() {
                interrupted = true;
                quit.store(true, Ordering::Relaxed);
            }
            for k in keys(KEY_POLL) {
                let key = key_of(&k);
                if key == Key::Quit {
                    quit.store(true, Ordering::Relaxed);
                } else {
                    let _ = keys_tx.send(key);
                }
            }
            let view = latest.lock().ok().and_then(|mut l| l.take());
            if let (Some(v), true) = (view, drawn.is_ok()) {
                if let Err(e) = term.0.draw(|f| render(f, &v)) {
                    drawn = Err(format!("cannot draw: {e}"));
                    quit.store(true, Ordering::Relaxed);
                }
            }
        }
        let looped = link
            .join()
            .unwrap_or_else(|_| Err("the link thread failed".into()));
        (looped, drawn)
    });
    drop(term);
    looped?;
    drawn?;
    let verdict = if s.feedback().is_some() {
        Outcome::Done
    } else {
        Outcome::NoReply
    };
    let msg = format!(
        "{:.1} s; ended commanded to zero with enable 0",
        t0.elapsed().as_secs_f64()
    );
    let mut r = Report::new(verb, s, before, verdict, msg);
    r.interrupted = interrupted;
    Ok(r)
}

/// The link thread: the bridge at 1 kHz with teleop's keys, a [`View`] published every
/// [`REDRAW`]; at the end (quit, `seconds`, a failed exchange) zero, wheels standing, enable 0.
fn link_loop<P: Port>(
    s: &mut Session<P>,
    mut driver: Driver,
    seconds: Option<f64>,
    keys: &mpsc::Receiver<Key>,
    quit: &AtomicBool,
    latest: &Mutex<Option<View>>,
    title: &str,
) -> Result<(), String> {
    let end = seconds.map(super::cycles_of);
    let mut note = String::new();
    let mut quit_now = || quit.load(Ordering::Relaxed);
    if let Driver::Teleop(_) = driver {
        note = arm_note(s, &mut quit_now).map_err(|e| e.to_string())?;
    }
    let mut cycles = 0u64;
    let mut last_view: Option<Instant> = None;
    let result = loop {
        if quit_now() || end.is_some_and(|e| cycles >= e) {
            break Ok(());
        }
        while let Ok(key) = keys.try_recv() {
            if let Driver::Teleop(t) = &mut driver {
                note = teleop_key(s, t, key);
            }
        }
        if let Driver::Teleop(t) = &mut driver {
            if let Some((v, w)) = t.command(s.now_us) {
                s.bridge.cmd_vel(s.now_us, v, w);
            }
        }
        if let Err(e) = s.cycle() {
            break Err(e.to_string());
        }
        cycles = cycles.saturating_add(1);
        if last_view.is_none_or(|t| t.elapsed() >= REDRAW) {
            last_view = Some(Instant::now());
            let mut v = View::of(s, title);
            v.help = match &driver {
                Driver::Watch => {
                    "q quit   (top watches: it sends enable 0 frames and never arms)".into()
                }
                Driver::Teleop(t) => {
                    v.command = Some(t.shown(s.now_us));
                    format!("w/s up/down: v   a/d left/right: w   space: zero   x: stop by frame gap (BRAKE)   r: rearm   q: quit   {note}")
                }
            };
            if let Ok(mut l) = latest.try_lock() {
                *l = Some(v);
            }
        }
    };
    // Stop first, whatever ended the loop.
    let stopped = s.stop_and_disarm(3_000).map_err(|e| e.to_string());
    result.and(stopped)
}

/// Teleop's start: arm and say how it went.
fn arm_note<P: Port>(
    s: &mut Session<P>,
    stop: &mut dyn FnMut() -> bool,
) -> Result<String, crate::LinkError> {
    Ok(match s.arm_and_wait(WAIT_MS, stop)? {
        ArmResult::Armed => "armed".into(),
        ArmResult::Refused => "NOT ARMED: the MCU stayed in BRAKE (see faults); r retries".into(),
        ArmResult::NoFeedback => "NOT ARMED: no feedback".into(),
        ArmResult::Stopped => "stopped".into(),
    })
}

/// Applies one teleop key to the session; a note for the help line.
fn teleop_key<P: Port>(s: &mut Session<P>, t: &mut Teleop, key: Key) -> String {
    match key {
        Key::Estop => {
            t.zero(s.now_us);
            s.gap(super::ESTOP_GAP_MS);
            s.bridge.disarm();
            "frame gap: the MCU brakes (BRAKE latched); r re-arms".into()
        }
        Key::Rearm => {
            t.zero(s.now_us);
            s.bridge.rearm(s.now_us);
            "re-arm requested".into()
        }
        k => {
            t.key(k, s.now_us);
            String::new()
        }
    }
}

#[cfg(test)]
#[allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]
mod tests {
    use super::*;
    use crate::cli::amr_link::{SimPort, SETTLE_CYCLES};
    use crate::simlink::SimMcu;
    use ratatui::backend::TestBackend;
    use ratatui::Terminal;

    /// The view drawn on a 120 x 32 test terminal, as its lines of text.
    fn draw(v: &View) -> Vec<String> {
        let mut term = Terminal::new(TestBackend::new(120, 32)).unwrap();
        term.draw(|f| render(f, v)).unwrap();
        let buf = term.backend().buffer().clone();
        let w = usize::from(buf.area.width);
        let cells: Vec<&str> = buf.content().iter().map(|c| c.symbol()).collect();
        cells.chunks(w).map(|row| row.concat()).collect()
    }

    fn has(lines: &[String], what: &str) -> bool {
        lines.iter().any(|l| l.contains(what))
    }

    #[test]
    fn a_given_state_shows_mode_faults_counters_and_command() {
        let v = View {
            title: "motorlink top: test".into(),
            mode: Some("BRAKE"),
            feedback_age_ms: Some(1.5),
            arm_state: "Latched".into(),
            wheel_radps: [1.25, -2.5],
            current_a: [0.5, 0.75],
            encoder: [100, -200],
            faults: vec!["ESTOP".into(), "BRAKE_LATCHED".into()],
            counters: LinkCounters {
                exchanges: 4321,
                feedback_ok: 4300,
                feedback_rejected: 17,
                not_accepted: 3,
                transport_errors: 2,
                gaps: 1,
                ..LinkCounters::default()
            },
            clock_synced: true,
            clock_offset_us: Some(-1234.0),
            clock_skew_ppm: 12.5,
            wheel_history: vec![(-1.0, 1.0, -1.0), (0.0, 1.25, -2.5)],
            mode_history: vec![0, 0, 4, 4],
            command: Some((0.25, -0.5, true)),
            recent: vec!["    1.000 s  brake_latched ESTOP,BRAKE_LATCHED".into()],
            help: "q quit".into(),
        };
        let l = draw(&v);
        assert!(has(&l, "motorlink top: test"), "{l:#?}");
        assert!(has(&l, "mode BRAKE"), "{l:#?}");
        assert!(has(&l, "faults  ESTOP BRAKE_LATCHED"), "{l:#?}");
        assert!(has(&l, "exchanges 4321"));
        assert!(has(&l, "feedback ok 4300"));
        assert!(has(&l, "refused 17"));
        assert!(has(&l, "not accepted 3"));
        assert!(has(&l, "transport errors 2"));
        assert!(has(&l, "gaps 1"));
        assert!(has(&l, "feedback age 1.5 ms"));
        assert!(has(&l, "synced, offset -1234 us, skew +12.5 ppm"), "{l:#?}");
        assert!(has(&l, "L   +1.25  R   -2.50 rad/s"), "{l:#?}");
        assert!(has(&l, "command v +0.25 m/s  w -0.50 rad/s  SENDING"));
        assert!(has(&l, "brake_latched ESTOP,BRAKE_LATCHED"));
        assert!(has(&l, "wheel speed, rad/s"));
        assert!(has(&l, "q quit"));
        // The plots drew something: braille dots in the chart, bars in the mode sparkline.
        assert!(l
            .iter()
            .any(|r| r.chars().any(|c| ('\u{2801}'..='\u{28ff}').contains(&c))));
        assert!(l.iter().any(|r| r.contains('█')), "{l:#?}");
    }

    #[test]
    fn no_feedback_and_no_faults_are_said_so() {
        let l = draw(&View::default());
        assert!(has(&l, "mode no feedback"), "{l:#?}");
        assert!(has(&l, "faults  none"));
        assert!(has(&l, "clock not synced"));
        assert!(!has(&l, "command v"));
    }

    #[test]
    fn the_view_of_a_simulated_board_with_its_estop_held() {
        let mut mcu = SimMcu::lockstep();
        mcu.set_estop(true);
        let mut s = Session::new(SimPort::new(mcu));
        let mut never = || false;
        s.run(SETTLE_CYCLES * 10, &mut never).unwrap();
        let v = View::of(&s, "motorlink top: sim");
        assert_eq!(v.mode, Some("BRAKE"));
        assert!(v.faults.contains(&"ESTOP".to_string()), "{:?}", v.faults);
        assert_eq!(v.counters.exchanges, SETTLE_CYCLES * 10);
        // 200 ms of feedback at one sample per 1 ms: one mode bar per 50 ms.
        assert_eq!(v.mode_history, vec![4; 4]);
        assert!(v.wheel_history.len() >= 190, "{}", v.wheel_history.len());
        let l = draw(&v);
        assert!(has(&l, "mode BRAKE"));
        assert!(has(&l, "ESTOP"));
        assert!(has(&l, "exchanges 200"), "{l:#?}");
    }
}

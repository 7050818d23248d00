//! What every profile's run measures the same way, whatever the board: the ladder's mode changes
//! after the fault onset, the robot's way from the onset to standstill, the ladder's counters at
//! the end, the host's reports, and the columns every CSV trace opens with.

use std::io::{self, Write};
use std::time::Instant;

use statemachine::{Counters, FaultFlags, Mode};

use crate::plant::Plant;
use crate::runner::{mode_name, Panel, Series, Summary};
use crate::scenario::Scenario;

/// The measurements a run takes step by step, written into its [`Summary`] as they happen.
#[derive(Clone, Copy, Debug)]
pub struct Watch {
    /// The ladder's mode at the last [`Watch::mode`].
    pub mode: Mode,
    odo_at_onset: Option<f64>,
}

impl Watch {
    /// Starts from the board's mode out of reset.
    pub fn new(mode: Mode) -> Self {
        Self {
            mode,
            odo_at_onset: None,
        }
    }

    /// The ladder's mode at `t`, s, with its faults. A new mode records the first HOLD, STOP and
    /// BRAKE after the onset (ms after it), and the first comm-loss BRAKE (after the onset, when
    /// there is one) from `last_valid`, the time of the last valid frame. Returns true when it
    /// recorded that comm-loss BRAKE, so the profile can add its own figures of it.
    pub fn mode(
        &mut self,
        s: &mut Summary,
        t: f64,
        mode: Mode,
        faults: FaultFlags,
        last_valid: Option<f64>,
    ) -> bool {
        if mode == self.mode {
            return false;
        }
        self.mode = mode;
        let after = s.onset_s.filter(|&o| t >= o).map(|o| (t - o) * 1e3);
        match mode {
            Mode::Hold if s.hold_ms.is_none() => s.hold_ms = after,
            Mode::Stop if s.stop_ms.is_none() => s.stop_ms = after,
            Mode::Brake => {
                if s.brake_ms.is_none() {
                    s.brake_ms = after;
                }
                if s.brake_after_last_frame_ms.is_none()
                    && faults.contains(FaultFlags::COMM_LOST)
                    && (s.onset_s.is_none() || after.is_some())
                {
                    if let Some(lv) = last_valid {
                        s.brake_after_last_frame_ms = Some((t - lv) * 1e3);
                        return true;
                    }
                }
            }
            _ => {}
        }
        false
    }

    /// The robot at `t`, s: its speed at the onset and the distance from there to standstill,
    /// the first step after the onset with every motor `braked` (ms after it), the peak speed
    /// and the peak of the motors' `currents`.
    pub fn motion(
        &mut self,
        s: &mut Summary,
        t: f64,
        body: &Plant,
        currents: &[f64],
        braked: bool,
    ) {
        if let Some(o) = s.onset_s {
            if t >= o && self.odo_at_onset.is_none() {
                self.odo_at_onset = Some(body.odometer);
                s.speed_at_onset = Some(body.v);
            }
            if t >= o && braked && s.bridge_brake_ms.is_none() {
                s.bridge_brake_ms = Some((t - o) * 1e3);
            }
        }
        if let Some(o0) = self.odo_at_onset {
            if s.stop_distance_m.is_none() && body.v.abs() < 0.002 && body.w.abs() < 0.01 {
                s.stop_distance_m = Some(body.odometer - o0);
            }
        }
        s.peak_speed = s.peak_speed.max(body.v.abs());
        s.peak_current = currents.iter().fold(s.peak_current, |m, i| m.max(i.abs()));
    }
}

impl Summary {
    /// A run of `sc` about to start: its name, profile and fault onset.
    pub fn new(sc: &Scenario) -> Self {
        Self {
            name: sc.name.clone(),
            profile: sc.profile.name().into(),
            onset_s: sc.fault_onset(),
            ..Self::default()
        }
    }

    /// The end of a run of `sc` started at `wall`: the ladder's counters `c` and final `mode`.
    pub fn finish(&mut self, sc: &Scenario, wall: Instant, c: &Counters, mode: Mode) {
        self.rejected_total = u64::from(c.rejected_total());
        self.brake_entries = u64::from(c.brake_entries);
        self.rearms = u64::from(c.rearms);
        self.final_mode = mode_name(mode).to_string();
        self.sim_s = sc.duration_s;
        self.wall_s = wall.elapsed().as_secs_f64();
    }
}

/// Counts `count` more of the host's report `name`, first made at `t`, s.
pub fn add_report(reports: &mut Vec<(f64, String, u64)>, t: f64, name: &str, count: u64) {
    match reports.iter_mut().find(|(_, n, _)| n == name) {
        Some(e) => e.2 += count,
        None => reports.push((t, name.into(), count)),
    }
}

impl Panel {
    /// A panel of signals named `names`, nothing recorded yet.
    pub fn new(caption: &str, names: impl IntoIterator<Item = String>) -> Self {
        Self {
            caption: caption.into(),
            signals: names.into_iter().map(|n| (n, Vec::new())).collect(),
        }
    }
}

impl Series {
    /// A traced tick at `t`, s: the columns every profile keeps, and a value of each signal of
    /// the first panel ([`Series::lines`]) if there is one.
    pub fn push_tick(
        &mut self,
        t: f64,
        mode: Mode,
        age: u16,
        values: impl IntoIterator<Item = f64>,
    ) {
        self.t.push(t);
        self.mode.push(mode as u8);
        self.age.push(age);
        if let Some(p) = self.lines.as_mut() {
            for ((_, signal), x) in p.signals.iter_mut().zip(values) {
                signal.push(x);
            }
        }
    }
}

/// The CSV trace of a run: a header, then a row every `trace_every_ms` ticks. Every profile's
/// rows open with the same columns (`t_s,mode,age,faults`), its own follow.
pub struct Trace<'a> {
    out: Option<&'a mut dyn Write>,
    every: u64,
}

impl<'a> Trace<'a> {
    /// A trace of `sc` into `out` (none: nothing written); writes the header, the common columns
    /// then the profile's `columns`.
    pub fn new(sc: &Scenario, out: Option<&'a mut dyn Write>, columns: &str) -> io::Result<Self> {
        let mut trace = Self {
            out,
            every: u64::from(sc.trace_every_ms),
        };
        if let Some(w) = trace.out.as_deref_mut() {
            writeln!(w, "t_s,mode,age,faults,{columns}")?;
        }
        Ok(trace)
    }

    /// True if the tick with this index is traced (and kept for the plots).
    pub fn due(&self, tick_index: u64) -> bool {
        tick_index.is_multiple_of(self.every)
    }

    /// Opens a row with the common columns of the ladder at `t`, s; returns the writer for the
    /// profile's columns, none if no trace is written.
    pub fn row(
        &mut self,
        t: f64,
        mode: Mode,
        age: u16,
        faults: FaultFlags,
    ) -> io::Result<Option<&mut (dyn Write + 'a)>> {
        let Some(w) = self.out.as_deref_mut() else {
            return Ok(None);
        };
        write!(w, "{:.4},{},{},{:#06x},", t, mode_name(mode), age, faults.0)?;
        Ok(Some(w))
    }
}

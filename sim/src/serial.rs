//! What the seed 001 and seed 003 runs share: the serial link between the scripted host and the
//! board (the line both ways with the scenario's faults, the frames the host wrote, a monitor
//! that reads them as the board does), and the re-arm rule the runs check.

use std::fmt::Debug;
use std::io::{self, Write};

use mcu::Safety;
use statemachine::{Counters, Mode, Output};

use crate::measure::Watch;
use crate::rng::Rng;
use crate::runner::{corrupt, Summary};
use crate::scenario::{Fault, Scenario};
use crate::wire::Wire;

/// What one received byte did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ByteReport {
    /// The byte completed a frame that decoded.
    pub decoded: bool,
    /// The ladder accepted a command frame (seed 001: `SET_MOTOR_PWM`, `MOTOR_ENABLE 0`; seed
    /// 003: `MTRS`).
    pub valid: bool,
}

/// A simulated serial board with `N` axes, as the link drives it.
pub trait SerialBoard<const N: usize> {
    /// The safety core.
    fn safety(&self) -> &Safety<N>;
    /// `link_rx`: one received byte.
    fn on_byte(&mut self, byte: u8);
    /// `link_tx`: the next byte for the transmitter.
    fn tx_pop(&mut self) -> Option<u8>;
    /// Frames the link task decoded.
    fn frames(&self) -> u32;
}

/// A stream decoder of the protocol crate.
pub trait Decode {
    /// What it decodes.
    type Msg;
    /// Why a frame does not decode.
    type Error: Debug;
    /// One byte; the frame that ends at it, decoded or not.
    fn decode(&mut self, byte: u8) -> Option<Result<Self::Msg, Self::Error>>;
}

/// The scripted host's decoder of what the board sends, with its counts.
#[derive(Clone, Debug, Default)]
pub struct HostRx<D> {
    dec: D,
    /// Replies decoded.
    pub decoded: u64,
    /// Frames that did not decode.
    pub broken: u64,
}

impl<D: Decode> HostRx<D> {
    /// One byte from the board at `t`, s: the reply it completes, if any. A frame that does not
    /// decode is counted, and described as a failure to decode `what` it was (e.g. "a reply").
    pub fn byte(&mut self, t: f64, byte: u8, what: &str) -> Result<Option<D::Msg>, String> {
        match self.dec.decode(byte) {
            None => Ok(None),
            Some(Ok(m)) => {
                self.decoded += 1;
                Ok(Some(m))
            }
            Some(Err(e)) => {
                self.broken += 1;
                Err(format!("{t:.4} s: host could not decode {what}: {e:?}"))
            }
        }
    }

    /// Replies decoded, and frames that did not decode.
    pub fn counts(&self) -> [u64; 2] {
        [self.decoded, self.broken]
    }
}

/// When the scripted host writes: a stream of frames every 1/`frame_hz` s from 0, and its
/// commands at their times. A paused host skips the stream's frames that fall due and holds its
/// commands back until it resumes.
#[derive(Clone, Debug)]
pub struct Schedule<C> {
    /// The commands, in time order.
    pub commands: Vec<C>,
    at: fn(&C) -> f64,
    next_command: usize,
    period: f64,
    next_frame: f64,
}

impl<C: Copy> Schedule<C> {
    /// A stream at `frame_hz`, and `commands`, each made at `at(command)`, s.
    pub fn new(frame_hz: f64, commands: &[C], at: fn(&C) -> f64) -> Self {
        let mut commands = commands.to_vec();
        commands.sort_by(|a, b| at(a).total_cmp(&at(b)));
        Self {
            commands,
            at,
            next_command: 0,
            period: 1.0 / frame_hz,
            next_frame: 0.0,
        }
    }

    /// The stream's frames due by `t`: `write(time of the frame)` for each, unless `paused`.
    pub fn frames_due(&mut self, t: f64, paused: bool, mut write: impl FnMut(f64)) {
        while self.next_frame <= t {
            if !paused {
                write(self.next_frame);
            }
            self.next_frame += self.period;
        }
    }

    /// The commands due by `t`: `write(index, command)` for each, none while `paused`.
    pub fn commands_due(&mut self, t: f64, paused: bool, mut write: impl FnMut(usize, C)) {
        while !paused
            && self
                .commands
                .get(self.next_command)
                .is_some_and(|c| (self.at)(c) <= t)
        {
            write(self.next_command, self.commands[self.next_command]);
            self.next_command += 1;
        }
    }
}

/// A frame the host wrote.
#[derive(Clone, Debug)]
pub struct Sent<M, E> {
    /// The message.
    pub msg: M,
    /// When the host wrote it, s.
    pub t: f64,
    /// What its reply must be (the profile's).
    pub expect: E,
    /// Bytes changed on the way (corruption fault or a bit error on the line).
    pub corrupted: bool,
    /// A byte of it fell into a link cut.
    pub lost: bool,
    /// The board decoded it.
    pub decoded: bool,
}

/// The serial link of a run: host → board with the line's bit errors, board → host without.
#[derive(Clone, Debug)]
pub struct Link<M, E, D> {
    down: Wire,
    up: Wire,
    monitor: D,
    /// Every frame the host wrote, in order: a frame's index is the tag its bytes carry.
    pub sent: Vec<Sent<M, E>>,
    /// The last frame the ladder accepted: its arrival, s, and the board's tick count then.
    pub last_valid: Option<(f64, u32)>,
}

impl<M: PartialEq, E, D: Decode<Msg = M>> Link<M, E, D> {
    /// The scenario's line, with `monitor` on the host → board direction: a decoder that reads
    /// it as the board does (a logic analyser on the wire), so the run knows what message the
    /// board took from which frame.
    pub fn new(sc: &Scenario, monitor: D) -> Self {
        let l = &sc.serial;
        Self {
            down: Wire::new(l.baud, l.latency_ms, l.bit_error_rate),
            up: Wire::new(l.baud, l.latency_ms, 0.0),
            monitor,
            sent: Vec::new(),
            last_valid: None,
        }
    }

    /// The host writes `msg`, encoded as `bytes`, at `t`: the scenario's corruption faults in
    /// force change the bytes, then the line's bit errors. Its reply must be `expect`. Returns
    /// the frame's tag.
    pub fn write(
        &mut self,
        sc: &Scenario,
        t: f64,
        msg: M,
        bytes: &mut [u8],
        expect: E,
        rng: &mut Rng,
    ) -> usize {
        let mut corrupted = false;
        for f in &sc.faults {
            if let Fault::Corruption { rate, .. } = *f {
                if f.active_at(t) && rng.chance(rate) {
                    corrupted |= corrupt(bytes, rng);
                }
            }
        }
        let tag = self.sent.len();
        corrupted |= self.down.write(t, bytes, tag, rng) > 0;
        self.sent.push(Sent {
            msg,
            t,
            expect,
            corrupted,
            lost: false,
            decoded: false,
        });
        tag
    }

    /// `link_rx`: the next byte that reached `board` by `t` (a byte that fell into a link cut is
    /// lost, its frame marked so). The monitor reads it too: a message it decodes takes the
    /// host's frame, or, when the host never sent it, counts as a corrupted frame applied.
    /// Returns the board's report and that message; none when no byte is left.
    pub fn link_rx<B: SerialBoard<N>, const N: usize>(
        &mut self,
        sc: &Scenario,
        t: f64,
        board: &mut B,
        s: &mut Summary,
    ) -> Option<(ByteReport, Option<M>)> {
        let b = loop {
            let b = self.down.arrived(t)?;
            if !sc.link_cut(b.at) {
                break b;
            }
            self.sent[b.tag].lost = true;
        };
        let valid_frames = |b: &B| b.safety().ladder().counters().valid_frames;
        let (frames, valid) = (board.frames(), valid_frames(board));
        board.on_byte(b.byte);
        let rep = ByteReport {
            decoded: board.frames() != frames,
            valid: valid_frames(board) != valid,
        };
        let m = self.monitor.decode(b.byte).and_then(Result::ok);
        if let Some(m) = &m {
            debug_assert!(rep.decoded);
            if *m != self.sent[b.tag].msg {
                s.corrupted_applied += 1;
            } else {
                self.sent[b.tag].decoded = true;
            }
        }
        if rep.valid {
            self.last_valid = Some((t, board.safety().ticks()));
        }
        Some((rep, m))
    }

    /// `link_tx` in the step from `t` to `t + step`: the board's transmitter sends what it has
    /// queued while the line is free; then every byte that reached the host by `t` and did not
    /// fall into a link cut goes to `receive`, with the frames the host wrote.
    pub fn link_tx<const N: usize>(
        &mut self,
        sc: &Scenario,
        t: f64,
        step: f64,
        board: &mut impl SerialBoard<N>,
        rng: &mut Rng,
        mut receive: impl FnMut(u8, &[Sent<M, E>]),
    ) {
        while self.up.idle_before(t + step) {
            match board.tx_pop() {
                Some(b) => {
                    self.up.write(t, &[b], 0, rng);
                }
                None => break,
            }
        }
        while let Some(b) = self.up.arrived(t) {
            if !sc.link_cut(b.at) {
                receive(b.byte, &self.sent);
            }
        }
    }

    /// [`Watch::mode`] for the board's output `out` at `t`, timed from this link's last valid
    /// frame; a comm-loss BRAKE it records is also counted in the board's ticks (`ticks` now).
    /// Returns true when it recorded one.
    pub fn watch_mode<const N: usize>(
        &self,
        watch: &mut Watch,
        s: &mut Summary,
        t: f64,
        out: &Output<N>,
        ticks: u32,
    ) -> bool {
        let last_valid = self.last_valid.map(|(lt, _)| lt);
        if !watch.mode(s, t, out.mode, out.faults, last_valid) {
            return false;
        }
        if let Some((_, lticks)) = self.last_valid {
            s.brake_after_last_frame_ticks = Some(ticks.wrapping_sub(lticks));
        }
        true
    }

    /// Ends a trace row with the link's columns: frames the host wrote, corrupted on the way,
    /// corrupted and applied, refused by the ladder, replies the host decoded and could not.
    pub fn trace_tail<const N: usize>(
        &self,
        w: &mut dyn Write,
        s: &Summary,
        board: &impl SerialBoard<N>,
        replies: [u64; 2],
    ) -> io::Result<()> {
        let [decoded, broken] = replies;
        writeln!(
            w,
            "{},{},{},{},{decoded},{broken}",
            self.sent.len(),
            self.corrupted(),
            s.corrupted_applied,
            board.safety().ladder().counters().rejected_total(),
        )
    }

    /// Frames changed on the way.
    pub fn corrupted(&self) -> usize {
        self.sent.iter().filter(|f| f.corrupted).count()
    }

    /// The frames' figures at the end of the run: written, corrupted, corrupted and refused.
    pub fn tally(&self, s: &mut Summary) {
        s.frames_sent = self.sent.len() as u64;
        s.corrupted_sent = self.corrupted() as u64;
        s.corrupted_rejected = self
            .sent
            .iter()
            .filter(|f| f.corrupted && !f.decoded && !f.lost)
            .count() as u64;
    }
}

/// The re-arm rule: BRAKE is left only after a re-arm message reached the board since the latch.
#[derive(Clone, Copy, Debug)]
pub struct Rearm {
    brake_entries: u32,
    delivered: bool,
}

impl Rearm {
    /// Starts from the ladder's counters out of reset.
    pub fn new(c: &Counters) -> Self {
        Self {
            brake_entries: c.brake_entries,
            delivered: false,
        }
    }

    /// A re-arm message reached the board.
    pub fn deliver(&mut self) {
        self.delivered = true;
    }

    /// Something that cancels a re-arm reached the board (an ESTOP).
    pub fn cancel(&mut self) {
        self.delivered = false;
    }

    /// After the board handled a byte or a tick: a new latch cancels an earlier re-arm.
    pub fn latches(&mut self, c: &Counters) {
        if c.brake_entries != self.brake_entries {
            self.brake_entries = c.brake_entries;
            self.delivered = false;
        }
    }

    /// After a tick that took the ladder from `before` to `now`: leaving BRAKE without a re-arm
    /// is a violation (counted in `s`), and uses the re-arm up.
    pub fn tick(&mut self, c: &Counters, before: Mode, now: Mode, s: &mut Summary) {
        self.latches(c);
        if before == Mode::Brake && now != Mode::Brake {
            if !self.delivered {
                s.rearm_violations += 1;
            }
            self.delivered = false;
        }
    }
}

//! The serial verbs of `motorlink`: talk to a board over seed 001 (`--kind serial`: `ping`,
//! `enable`, `estop`, `drive`, `send-hex`) or seed 003 (`--kind teensy`: `ping`, `move`, `cal`,
//! `endeff`, `config`, `send-hex`), print every frame received as a JSON line, end with a verdict.
//!
//! Every verb runs over any [`ByteStream`] (the CLI opens a [`crate::transport::SerialTransport`])
//! and writes JSON objects to a sink, one per line, each with `t_ms` (milliseconds since the verb
//! started). The shapes:
//!
//! ```text
//!  {"t_ms":..,"message":{..}}                      a frame received (seed 001: CdcJson; seed 003: CmdMsgJson)
//!  {"t_ms":..,"error":"Crc","code":1,..}           a frame refused by the decoder (seed 001; seed 003: "reason")
//!  {"t_ms":..,"ping":i,"round_trip_us":..,"reply":{..}} | {"t_ms":..,"ping":i,"no_reply_ms":..}
//!  {"t_ms":..,"sending":{..},..}                    what a paced verb (drive, move) is about to repeat
//!  {"t_ms":..,"verdict":"done"|"refused"|"no_reply",..}   always the last line; its fields per verb
//! ```
//!
//! The verdict is the exit status ([`Verdict::exit_code`]); an argument, open or I/O error is the
//! `Err` of the verb, and the CLI gives it its own status ([`crate::cli::exit::Exit`]).
//!
//! Leaving BRAKE (seed 001 `drive --enable`, seed 003 `move --cal`): the board leaves BRAKE at a
//! tick after a re-arm and a fresh enabled frame. Its `MOTOR_ENABLE 1` / `CAL` carries a coasting
//! frame, so a re-arm waits for the first command frame for up to the board's BRAKE threshold
//! (249 ms) and lapses after it. The paced verbs do not rely on that window: they send one frame
//! first, the re-arm right after it, and keep the frames coming while the re-arm's reply travels
//! back; the reply is checked inside the paced loop:
//!
//! ```text
//!  host   PWM ─ ENABLE 1 ─────── PWM ──────── PWM ──────── PWM ...   (every 1/hz, absolute deadlines)
//!  board    age 0   re-arm pending   ACK(0x02, 0) ─▶   fresh frame → leaves BRAKE at the next tick
//! ```

use std::time::{Duration, Instant};

use protocol::{cdc, teensy};
use serde_json::{json, Map, Value};
use statemachine::{Estop, RejectReason};

use crate::cli::{with_motors, CdcJson, CmdMsgJson};
use crate::pacing::{Pacer, PeriodStats};
use crate::serial::{CdcLink, TeensyLink};
use crate::transport::{ByteStream, LinkError};

/// How a verb ended. Printed as the `verdict` of the last line; it is the exit status.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// The board answered and did what was asked (ACK result 0, `cmd_success` 1, replies came).
    Done,
    /// The board answered and refused (ACK result ≠ 0, `cmd_success` 0).
    Refused,
    /// An expected reply did not come before `--wait-ms` (or, for `drive`, nothing came at all).
    NoReply,
}

impl Verdict {
    /// The process exit status: 0 done, 1 refused, 69 no reply (see [`crate::cli::exit::Exit`]).
    pub fn exit_code(self) -> u8 {
        crate::cli::exit::Exit::from(self).code()
    }

    /// The name printed in `verdict`.
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Done => "done",
            Self::Refused => "refused",
            Self::NoReply => "no_reply",
        }
    }
}

/// A seed 001 verb.
#[derive(Clone, Debug, PartialEq)]
pub enum CdcVerb {
    /// `count` PINGs, each waiting for a STATUS (or an ACK of PING).
    Ping {
        /// PINGs to send.
        count: u32,
    },
    /// MOTOR_ENABLE, waiting for its ACK.
    Enable(bool),
    /// ESTOP engage / release, waiting for its ACK.
    Estop(Estop),
    /// SET_MOTOR_PWM at a fixed rate.
    Drive(DrivePlan),
    /// Raw bytes, then listen.
    SendHex(SendHex),
}

/// A seed 003 verb.
#[derive(Clone, Debug, PartialEq)]
pub enum TeensyVerb {
    /// `count` ENDEFF_OFF round trips (seed 003 has no probe message; switching the end effector
    /// off is idempotent and safe).
    Ping {
        /// Commands to send.
        count: u32,
    },
    /// CAL: the explicit re-arm.
    Cal,
    /// ENDEFF_ON (`true`) or ENDEFF_OFF.
    Endeff(bool),
    /// CONFIG: the joints' acceleration, deg/s².
    Config {
        /// `mtr_accel_deg_s_s`.
        accel_deg_s2: i32,
    },
    /// MTRS to absolute angles at a fixed rate.
    Move(MovePlan),
    /// Raw bytes, then listen.
    SendHex(SendHex),
}

/// `send-hex`: bytes written as they are, then every reply within `listen`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SendHex {
    /// The bytes (a frame, a corrupted frame, garbage).
    pub bytes: Vec<u8>,
    /// How long to listen after the write.
    pub listen: Duration,
}

/// Largest `--hz` of the paced verbs (the board's tick rate).
pub const MAX_HZ: f64 = 1000.0;
/// Longest `--seconds` of the paced verbs (one day).
pub const MAX_SECONDS: f64 = 86_400.0;

/// A checked `drive`: built only from arguments the board could take, so nothing is sent otherwise.
#[derive(Clone, Debug, PartialEq)]
pub struct DrivePlan {
    /// The frame repeated.
    pub frame: cdc::SetMotorPwm,
    /// Time between frames.
    pub period: Duration,
    /// Frames to send, the first at once.
    pub frames: u64,
    /// How long the verb runs (the frames, then listening to the end of the last period).
    pub duration: Duration,
    /// MOTOR_ENABLE 1 right after the first frame, its ACK checked while driving.
    pub enable: bool,
}

impl DrivePlan {
    /// Checks the arguments: four duties within ±[`cdc::PWM_FULL_SCALE`], a `timeout_ms` from the
    /// frame period to 65535 (0 is refused by the board; a timeout shorter than the period would
    /// brake the board between any two frames), `hz` in (0, [`MAX_HZ`]], `seconds` in
    /// (0, [`MAX_SECONDS`]].
    pub fn new(
        pwm: &[i32],
        timeout_ms: u32,
        hz: f64,
        seconds: f64,
        enable: bool,
    ) -> Result<Self, String> {
        let full = i32::from(cdc::PWM_FULL_SCALE);
        let duties: [i32; 4] = pwm.try_into().map_err(|_| {
            format!(
                "--pwm takes 4 duties (motors 1 to 4), got {}; e.g. --pwm 300,-300,0,0",
                pwm.len()
            )
        })?;
        if let Some((i, d)) = duties
            .iter()
            .enumerate()
            .find(|(_, d)| d.unsigned_abs() > full.unsigned_abs())
        {
            return Err(format!(
                "--pwm: motor {} duty {d} is outside -{full} ..= {full} (full scale); nothing was sent",
                i.saturating_add(1)
            ));
        }
        let (period, frames, duration) = paced_frames(hz, seconds)?;
        let period_ms = period.as_secs_f64() * 1000.0;
        if timeout_ms == 0 {
            return Err(
                "--timeout-ms 0: the board refuses a frame without a timeout; give the time after which it must brake, at least one frame period; nothing was sent"
                    .into(),
            );
        }
        if f64::from(timeout_ms) < period_ms {
            return Err(format!(
                "--timeout-ms {timeout_ms} is shorter than the frame period ({period_ms:.1} ms at {hz} Hz): the board would brake between any two frames; give at least {} or raise --hz; nothing was sent",
                period_ms.ceil()
            ));
        }
        let timeout_ms = u16::try_from(timeout_ms).map_err(|_| {
            format!("--timeout-ms {timeout_ms} does not fit the frame's 16 bits (at most 65535); nothing was sent")
        })?;
        Ok(Self {
            frame: cdc::SetMotorPwm {
                pwm: duties.map(|d| i16::try_from(d).unwrap_or(0)),
                timeout_ms,
            },
            period,
            frames,
            duration,
            enable,
        })
    }
}

/// A checked `move`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MovePlan {
    /// One absolute angle per joint, degrees.
    pub angles: Vec<i32>,
    /// The speed cap, deg/s.
    pub speed_deg_s: i32,
    /// Send `is_relative` = 1 (a board that refuses relative moves answers `cmd_success` 0).
    pub relative: bool,
    /// Time between MTRS frames.
    pub period: Duration,
    /// MTRS frames to send, the first at once.
    pub frames: u64,
    /// How long the verb runs (at least until every echo is in or `--wait-ms` has passed).
    pub duration: Duration,
    /// CAL right after the first MTRS, its echo checked while moving.
    pub cal: bool,
}

impl MovePlan {
    /// Checks the arguments: one angle per motor, a speed cap ≥ 0, `hz` and `seconds` as for
    /// [`DrivePlan::new`]. `once`: a single MTRS (with `cal`, one before the CAL and one after).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        angles: &[i32],
        motors: usize,
        speed_deg_s: i32,
        relative: bool,
        hz: f64,
        seconds: f64,
        once: bool,
        cal: bool,
    ) -> Result<Self, String> {
        if angles.len() != motors {
            return Err(format!(
                "--angles has {} values but the board has {motors} joints (--motors); give one angle per joint, e.g. --angles {}",
                angles.len(),
                vec!["0"; motors].join(",")
            ));
        }
        if speed_deg_s < 0 {
            return Err(format!(
                "--speed {speed_deg_s}: the speed cap is a magnitude, give 0 or more deg/s; nothing was sent"
            ));
        }
        let (period, frames, duration) = if once {
            let (period, _, _) = paced_frames(hz, 1.0)?;
            (period, if cal { 2 } else { 1 }, Duration::ZERO)
        } else {
            paced_frames(hz, seconds)?
        };
        Ok(Self {
            angles: angles.to_vec(),
            speed_deg_s,
            relative,
            period,
            frames,
            duration,
            cal,
        })
    }
}

/// Period, frame count (the first at t = 0, so ⌈seconds · hz⌉) and duration of a paced verb.
pub(super) fn paced_frames(hz: f64, seconds: f64) -> Result<(Duration, u64, Duration), String> {
    if !(hz.is_finite() && hz > 0.0 && hz <= MAX_HZ) {
        return Err(format!(
            "--hz {hz}: give a rate above 0 and at most {MAX_HZ} Hz (the board's tick)"
        ));
    }
    if !(seconds.is_finite() && seconds > 0.0 && seconds <= MAX_SECONDS) {
        return Err(format!(
            "--seconds {seconds}: give a duration above 0 and at most {MAX_SECONDS} s"
        ));
    }
    let period = Duration::from_secs_f64(1.0 / hz);
    let frames = (seconds * hz).ceil().max(1.0) as u64;
    Ok((period, frames, Duration::from_secs_f64(seconds)))
}

/// Parses `a,b,c` into integers; `what` names the option in errors.
pub fn parse_list(s: &str, what: &str) -> Result<Vec<i32>, String> {
    s.split(',')
        .map(|x| {
            x.trim().parse::<i32>().map_err(|_| {
                format!("{what}: '{}' is not an integer; give comma-separated integers, e.g. {what} 100,-100,0,0", x.trim())
            })
        })
        .collect()
}

/// Spin before each paced deadline ([`Pacer`]); reading stops this much earlier.
pub(super) const SPIN: Duration = Duration::from_micros(200);
/// Reading stops this long before a paced deadline; the pacer sleeps the rest.
const READ_MARGIN: Duration = Duration::from_millis(2);
/// Read wait while only listening (no deadline near).
const MIN_READ: Duration = Duration::from_millis(1);
/// Longest single read wait, so deadlines and overdue replies are checked often.
const MAX_READ: Duration = Duration::from_millis(50);
/// A drive of at least this long must hear the board (it sends STATUS every 100 ms).
const HEARD_WITHIN: Duration = Duration::from_millis(200);

/// JSON lines with `t_ms` since the verb started.
pub(super) struct Lines<'a> {
    pub(super) t0: Instant,
    pub(super) sink: &'a mut dyn FnMut(Value),
}

impl Lines<'_> {
    pub(super) fn ms(&self) -> u64 {
        u64::try_from(self.t0.elapsed().as_millis()).unwrap_or(u64::MAX)
    }

    pub(super) fn put(&mut self, v: Value) {
        let mut map = match v {
            Value::Object(m) => m,
            other => {
                let mut m = Map::new();
                m.insert("value".into(), other);
                m
            }
        };
        map.insert("t_ms".into(), json!(self.ms()));
        (self.sink)(Value::Object(map));
    }
}

pub(super) fn us(d: Duration) -> u64 {
    u64::try_from(d.as_micros()).unwrap_or(u64::MAX)
}

fn ms(d: Duration) -> u64 {
    u64::try_from(d.as_millis()).unwrap_or(u64::MAX)
}

fn err(e: LinkError) -> String {
    e.to_string()
}

fn after(t: Instant, d: Duration) -> Instant {
    t.checked_add(d).unwrap_or(t)
}

pub(super) fn pacing_json(stats: &PeriodStats) -> Value {
    json!({"periods": stats.count, "mean_us": stats.mean_us(), "min_us": stats.min_us,
        "max_us": stats.max_us, "late": stats.late, "skipped": stats.skipped})
}

/// What the verbs need of a board link, for either protocol.
trait BoardLink {
    /// A message of the protocol.
    type Msg: Copy;
    /// Why the decoder refused a frame.
    type Refused;
    /// What a session counts of what it received.
    type Counts: Counts<Self::Msg>;
    /// The byte stream under the link.
    type Stream: ByteStream;

    /// The byte stream, for raw writes and its read timeout.
    fn stream(&mut self) -> &mut Self::Stream;
    /// Discards everything received and not yet read; returns the bytes discarded.
    fn discard_input(&mut self) -> Result<usize, LinkError>;
    /// Writes one message.
    fn send(&mut self, m: &Self::Msg) -> Result<(), LinkError>;
    /// One read: the messages it completed.
    fn poll(&mut self) -> Result<Vec<Self::Msg>, LinkError>;
    /// The frames the decoder refused since the last call.
    fn refused(&mut self) -> Vec<Self::Refused>;
    /// The decoder's counters, as printed.
    fn decoder(&self) -> Value;
    /// A message, as printed.
    fn message_json(m: &Self::Msg) -> Value;
    /// A refused frame, as printed (the fields of its line).
    fn refused_json(r: &Self::Refused) -> Value;
    /// What a reply to a command says: done or refused.
    fn verdict(reply: &Self::Msg) -> Verdict;
}

/// What a session counts of the messages it received.
trait Counts<M>: Default {
    /// One message.
    fn add(&mut self, m: &M);
    /// One frame the decoder refused.
    fn refused(&mut self);
    /// The counts, as printed in `received`.
    fn json(&self) -> Value;
}

/// A board link with its printer and counts.
struct Session<'a, L: BoardLink> {
    link: L,
    out: Lines<'a>,
    rx: L::Counts,
}

impl<'a, L: BoardLink> Session<'a, L> {
    /// A session over `link` that prints through `sink`, its clock started now.
    fn new(link: L, sink: &'a mut dyn FnMut(Value)) -> Self {
        Self {
            link,
            out: Lines {
                t0: Instant::now(),
                sink,
            },
            rx: L::Counts::default(),
        }
    }

    fn send(&mut self, m: &L::Msg) -> Result<(), String> {
        self.link.send(m).map_err(err)
    }

    /// One read of at most `window`: prints and counts every frame; returns the messages.
    fn listen(&mut self, window: Duration) -> Result<Vec<L::Msg>, String> {
        self.link
            .stream()
            .set_read_timeout(window.min(MAX_READ))
            .map_err(err)?;
        let got = self.link.poll().map_err(err)?;
        for m in &got {
            self.rx.add(m);
            self.out.put(json!({"message": L::message_json(m)}));
        }
        for r in self.link.refused() {
            self.rx.refused();
            self.out.put(L::refused_json(&r));
        }
        Ok(got)
    }

    /// What the session received, as printed in `received`.
    fn received(&self) -> Value {
        self.rx.json()
    }

    /// Reads until a message satisfying `is_reply` arrives (returned with its arrival) or `deadline`.
    fn wait_for(
        &mut self,
        deadline: Instant,
        is_reply: impl Fn(&L::Msg) -> bool,
    ) -> Result<Option<(L::Msg, Instant)>, String> {
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            if let Some(m) = self.listen(left)?.into_iter().find(&is_reply) {
                return Ok(Some((m, Instant::now())));
            }
        }
    }
}

/// `send-hex`: the bytes as given, then every reply within the listening time.
fn send_hex<L: BoardLink>(s: &mut Session<'_, L>, h: &SendHex) -> Result<Verdict, String> {
    s.link.stream().write_all(&h.bytes).map_err(err)?;
    s.out
        .put(json!({"sent_hex": crate::cli::to_hex(&h.bytes), "bytes": h.bytes.len()}));
    let end = after(Instant::now(), h.listen);
    s.wait_for(end, |_| false)?;
    let decoder = s.link.decoder();
    s.out.put(
        json!({"verdict": Verdict::Done.as_str(), "received": s.received(), "decoder": decoder}),
    );
    Ok(Verdict::Done)
}

/// `count` round trips of `probe`, each waiting up to `wait` for a message satisfying `is_reply`.
///
/// Before each probe the input is discarded (a periodic frame, or the late reply of an earlier
/// probe, would otherwise be taken for this one's reply), so the reply is the first matching
/// message that arrives after the probe was written:
///
/// ```text
///  host   discard ── PING ─────────────── discard ── PING ───── ...
///  board  STATUS (periodic: dropped)  ◀── STATUS (the reply to this PING)
/// ```
fn ping<L: BoardLink>(
    s: &mut Session<'_, L>,
    probe: L::Msg,
    is_reply: impl Fn(&L::Msg) -> bool,
    count: u32,
    wait: Duration,
) -> Result<Verdict, String> {
    let mut rtts = Vec::new();
    let mut discarded = 0usize;
    for i in 0..count {
        let stale = s.link.discard_input().map_err(err)?;
        discarded = discarded.saturating_add(stale);
        let t = Instant::now();
        s.send(&probe)?;
        match s.wait_for(after(t, wait), &is_reply)? {
            Some((m, at)) => {
                let rtt = at.duration_since(t);
                rtts.push(rtt);
                s.out.put(
                    json!({"ping": i, "round_trip_us": us(rtt), "reply": L::message_json(&m)}),
                );
            }
            None => s.out.put(json!({"ping": i, "no_reply_ms": ms(wait)})),
        }
    }
    let verdict = if rtts.is_empty() {
        Verdict::NoReply
    } else {
        Verdict::Done
    };
    let decoder = s.link.decoder();
    s.out.put(
        json!({"verdict": verdict.as_str(), "sent": count, "replies": rtts.len(),
        "round_trip_us": rtt_json(&rtts), "discarded_bytes": discarded, "decoder": decoder}),
    );
    Ok(verdict)
}

fn rtt_json(rtts: &[Duration]) -> Value {
    let (Some(min), Some(max)) = (rtts.iter().min(), rtts.iter().max()) else {
        return Value::Null;
    };
    let sum: f64 = rtts.iter().map(Duration::as_secs_f64).sum();
    json!({"min": us(*min), "avg": (sum / rtts.len() as f64 * 1e6).round(), "max": us(*max)})
}

/// Sends `msg` and waits up to `wait` for its reply, a message satisfying `is_reply`.
fn command<L: BoardLink>(
    s: &mut Session<'_, L>,
    msg: L::Msg,
    is_reply: impl Fn(&L::Msg) -> bool,
    wait: Duration,
) -> Result<Verdict, String> {
    let t = Instant::now();
    s.send(&msg)?;
    let sent = L::message_json(&msg);
    let (verdict, line) = match s.wait_for(after(t, wait), is_reply)? {
        Some((m, at)) => {
            let v = L::verdict(&m);
            let line = json!({"verdict": v.as_str(), "sent": sent, "reply": L::message_json(&m),
                "round_trip_us": us(at.duration_since(t))});
            (v, line)
        }
        None => (
            Verdict::NoReply,
            json!({"verdict": Verdict::NoReply.as_str(), "sent": sent, "waited_ms": ms(wait)}),
        ),
    };
    s.out.put(line);
    Ok(verdict)
}

/// A reply checked inside a paced loop (the re-arm of `drive --enable` and `move --cal`).
#[derive(Clone, Debug)]
enum Pending<M> {
    /// Not asked for.
    None,
    /// Sent at this instant, no reply yet.
    Waiting(Instant),
    /// The reply and its round trip.
    Answered(M, Duration),
}

impl<M: Copy> Pending<M> {
    /// Takes `m` as the reply if one is awaited and `is_reply` holds.
    fn take(&mut self, m: &M, is_reply: impl Fn(&M) -> bool) {
        if let Self::Waiting(t) = *self {
            if is_reply(m) {
                *self = Self::Answered(*m, t.elapsed());
            }
        }
    }

    /// Still waiting past `wait`.
    fn overdue(&self, wait: Duration) -> bool {
        matches!(self, Self::Waiting(t) if t.elapsed() >= wait)
    }

    fn waiting(&self) -> bool {
        matches!(self, Self::Waiting(_))
    }

    /// What the reply says, if it stops a paced verb: a refusal ([`BoardLink::verdict`]), or no
    /// reply within `wait`.
    fn verdict<L: BoardLink<Msg = M>>(&self, wait: Duration) -> Option<Verdict> {
        match self {
            Self::Answered(m, _) if L::verdict(m) == Verdict::Refused => Some(Verdict::Refused),
            p if p.overdue(wait) => Some(Verdict::NoReply),
            _ => None,
        }
    }

    /// The reply as the verb's last line prints it: none asked for, none within `wait`, or the
    /// reply and its round trip.
    fn json<L: BoardLink<Msg = M>>(&self, wait: Duration) -> Value {
        match self {
            Self::None => Value::Null,
            Self::Waiting(_) => json!({"no_reply_ms": ms(wait)}),
            Self::Answered(m, rtt) => {
                json!({"reply": L::message_json(m), "round_trip_us": us(*rtt)})
            }
        }
    }
}

/// Sends one frame at once, then up to `frames − 1` more on absolute deadlines `period` apart,
/// listening in between; then listens to the end of `duration`, and on while `more` says so (a
/// reply still awaited). A deadline at or past the end of `duration` is not kept: after a stall
/// that skipped deadlines, the frames stop on time rather than run late. `send(k)` sends frame `k`;
/// `listen(window)` reads once and returns `Some(verdict)` to stop at once (a refusal, an overdue
/// reply). Returns the early verdict, the frames sent and the pacing.
fn paced<E>(
    period: Duration,
    frames: u64,
    duration: Duration,
    mut send: impl FnMut(&mut E, u64) -> Result<(), String>,
    mut listen: impl FnMut(&mut E, Duration) -> Result<Option<Verdict>, String>,
    mut more: impl FnMut(&E) -> bool,
    env: &mut E,
) -> Result<(Option<Verdict>, u64, PeriodStats), String> {
    let mut pacer = Pacer::new(period, SPIN);
    pacer.stats = PeriodStats::new(period, period.checked_div(10).unwrap_or(period));
    let end = after(Instant::now(), duration);
    send(env, 0)?;
    let mut sent = 1u64;
    while sent < frames && (duration.is_zero() || pacer.next_deadline() < end) {
        // At least one read per period (a zero-wait one when the period is shorter than the margin).
        loop {
            let window = pacer
                .next_deadline()
                .saturating_duration_since(Instant::now())
                .saturating_sub(READ_MARGIN);
            if let Some(v) = listen(env, window)? {
                return Ok((Some(v), sent, pacer.stats));
            }
            if window.is_zero() {
                break;
            }
        }
        pacer.wait();
        send(env, sent)?;
        sent = sent.saturating_add(1);
    }
    loop {
        let left = end.saturating_duration_since(Instant::now());
        if left.is_zero() && !more(env) {
            return Ok((None, sent, pacer.stats));
        }
        if let Some(v) = listen(env, left.max(MIN_READ))? {
            return Ok((Some(v), sent, pacer.stats));
        }
    }
}

/// What a seed 001 session received, by kind.
#[derive(Clone, Copy, Debug, Default)]
struct CdcCounts {
    status: u32,
    status_motor_enabled: u32,
    status_estop_latched: u32,
    imu: u32,
    ack: u32,
    other: u32,
    errors: u32,
    last_status: Option<cdc::Status>,
}

impl Counts<cdc::Message> for CdcCounts {
    fn add(&mut self, m: &cdc::Message) {
        let inc = |c: &mut u32| *c = c.saturating_add(1);
        match m {
            cdc::Message::Status(s) => {
                inc(&mut self.status);
                if s.flags.has(cdc::StatusFlags::MOTOR_ENABLED) {
                    inc(&mut self.status_motor_enabled);
                }
                if s.flags.has(cdc::StatusFlags::ESTOP_LATCHED) {
                    inc(&mut self.status_estop_latched);
                }
                self.last_status = Some(*s);
            }
            cdc::Message::Imu(_) => inc(&mut self.imu),
            cdc::Message::Ack(_) => inc(&mut self.ack),
            _ => inc(&mut self.other),
        }
    }

    fn refused(&mut self) {
        self.errors = self.errors.saturating_add(1);
    }

    fn json(&self) -> Value {
        json!({"status": self.status, "status_motor_enabled": self.status_motor_enabled,
            "status_estop_latched": self.status_estop_latched, "imu": self.imu, "ack": self.ack,
            "other": self.other, "errors": self.errors,
            "last_status": self.last_status.map(|s| CdcJson::from(cdc::Message::Status(s)))})
    }
}

impl<S: ByteStream> BoardLink for CdcLink<S> {
    type Msg = cdc::Message;
    type Refused = cdc::Error;
    type Counts = CdcCounts;
    type Stream = S;

    fn stream(&mut self) -> &mut S {
        &mut self.stream
    }

    fn discard_input(&mut self) -> Result<usize, LinkError> {
        CdcLink::discard_input(self)
    }

    fn send(&mut self, m: &cdc::Message) -> Result<(), LinkError> {
        CdcLink::send(self, m)
    }

    fn poll(&mut self) -> Result<Vec<cdc::Message>, LinkError> {
        CdcLink::poll(self)
    }

    fn refused(&mut self) -> Vec<cdc::Error> {
        self.errors.drain(..).collect()
    }

    fn decoder(&self) -> Value {
        json!(self.stats())
    }

    fn message_json(m: &cdc::Message) -> Value {
        json!(CdcJson::from(*m))
    }

    fn refused_json(e: &cdc::Error) -> Value {
        json!({"error": format!("{e:?}"), "code": *e as u8,
            "reason": format!("{:?}", e.reason()), "reason_code": e.reason() as u8})
    }

    fn verdict(reply: &cdc::Message) -> Verdict {
        match reply {
            cdc::Message::Ack(a) if a.result == 0 => Verdict::Done,
            _ => Verdict::Refused,
        }
    }
}

/// A seed 001 session.
type Cdc<'a, S> = Session<'a, CdcLink<S>>;

fn is_ack_of(id: cdc::MsgId) -> impl Fn(&cdc::Message) -> bool {
    move |m| matches!(m, cdc::Message::Ack(a) if a.msg_id == id as u8)
}

/// Runs a seed 001 verb over `stream`, waiting up to `wait` for each reply; prints through `sink`.
pub fn run_cdc(
    stream: impl ByteStream,
    verb: &CdcVerb,
    wait: Duration,
    sink: &mut dyn FnMut(Value),
) -> Result<Verdict, String> {
    let mut s = Session::new(CdcLink::new(stream), sink);
    let acked = |s: &mut Cdc<'_, _>, msg: cdc::Message| command(s, msg, is_ack_of(msg.id()), wait);
    match verb {
        CdcVerb::Ping { count } => {
            let is_reply = |m: &cdc::Message| {
                matches!(m, cdc::Message::Status(_)) || is_ack_of(cdc::MsgId::Ping)(m)
            };
            ping(&mut s, cdc::Message::Ping, is_reply, *count, wait)
        }
        CdcVerb::Enable(on) => acked(&mut s, cdc::Message::MotorEnable(*on)),
        CdcVerb::Estop(a) => acked(&mut s, cdc::Message::Estop(*a)),
        CdcVerb::Drive(plan) => cdc_drive(&mut s, plan, wait),
        CdcVerb::SendHex(h) => send_hex(&mut s, h),
    }
}

fn cdc_drive<S: ByteStream>(
    s: &mut Cdc<'_, S>,
    plan: &DrivePlan,
    wait: Duration,
) -> Result<Verdict, String> {
    let frame = cdc::Message::SetMotorPwm(plan.frame);
    s.out.put(
        json!({"sending": CdcJson::from(frame), "frames": plan.frames,
        "hz": 1.0 / plan.period.as_secs_f64(), "enable": plan.enable}),
    );
    struct Env<'s, 'a, S: ByteStream> {
        s: &'s mut Cdc<'a, S>,
        enable: Pending<cdc::Message>,
    }
    let mut env = Env {
        s,
        enable: Pending::None,
    };
    let is_enable_ack = is_ack_of(cdc::MsgId::MotorEnable);
    let (early, sent, pacing) = paced(
        plan.period,
        plan.frames,
        plan.duration,
        |e: &mut Env<'_, '_, S>, k| {
            e.s.send(&frame)?;
            if k == 0 && plan.enable {
                e.s.send(&cdc::Message::MotorEnable(true))?;
                e.enable = Pending::Waiting(Instant::now());
            }
            Ok(())
        },
        |e, window| {
            for m in e.s.listen(window)? {
                e.enable.take(&m, &is_enable_ack);
            }
            Ok(e.enable.verdict::<CdcLink<S>>(wait))
        },
        |e| e.enable.waiting(),
        &mut env,
    )?;
    let heard = env.s.link.stats().frames > 0;
    let verdict = match early {
        Some(v) => v,
        None if !heard && plan.duration >= HEARD_WITHIN => Verdict::NoReply,
        None => Verdict::Done,
    };
    let enable = env.enable.json::<CdcLink<S>>(wait);
    let s = env.s;
    let decoder = s.link.decoder();
    s.out.put(
        json!({"verdict": verdict.as_str(), "frames_sent": sent, "enable": enable,
        "received": s.received(), "decoder": decoder, "pacing": pacing_json(&pacing),
        "stopped_early": early.is_some()}),
    );
    Ok(verdict)
}

/// What a seed 003 session received.
#[derive(Clone, Copy, Debug, Default)]
struct TeensyCounts {
    messages: u32,
    errors: u32,
}

impl<const N: usize> Counts<teensy::CmdMsg<N>> for TeensyCounts {
    fn add(&mut self, _: &teensy::CmdMsg<N>) {
        self.messages = self.messages.saturating_add(1);
    }

    fn refused(&mut self) {
        self.errors = self.errors.saturating_add(1);
    }

    fn json(&self) -> Value {
        json!({"messages": self.messages, "errors": self.errors})
    }
}

impl<S: ByteStream, const N: usize> BoardLink for TeensyLink<S, N> {
    type Msg = teensy::CmdMsg<N>;
    type Refused = RejectReason;
    type Counts = TeensyCounts;
    type Stream = S;

    fn stream(&mut self) -> &mut S {
        &mut self.stream
    }

    fn discard_input(&mut self) -> Result<usize, LinkError> {
        TeensyLink::discard_input(self)
    }

    fn send(&mut self, m: &teensy::CmdMsg<N>) -> Result<(), LinkError> {
        TeensyLink::send(self, m)
    }

    fn poll(&mut self) -> Result<Vec<teensy::CmdMsg<N>>, LinkError> {
        TeensyLink::poll(self)
    }

    fn refused(&mut self) -> Vec<RejectReason> {
        self.errors.drain(..).collect()
    }

    fn decoder(&self) -> Value {
        json!(self.stats())
    }

    fn message_json(m: &teensy::CmdMsg<N>) -> Value {
        json!(CmdMsgJson::from(m))
    }

    fn refused_json(r: &RejectReason) -> Value {
        json!({"reason": format!("{r:?}"), "reason_code": *r as u8})
    }

    fn verdict(reply: &teensy::CmdMsg<N>) -> Verdict {
        if reply.cmd_success != 0 {
            Verdict::Done
        } else {
            Verdict::Refused
        }
    }
}

/// A seed 003 session with `N` joints.
type Teensy<'a, S, const N: usize> = Session<'a, TeensyLink<S, N>>;

/// The echo of `sent`: the same command, whatever its `cmd_success`.
fn is_echo_of<const N: usize>(sent: teensy::CmdMsg<N>) -> impl Fn(&teensy::CmdMsg<N>) -> bool {
    move |m| m.reply(true) == sent.reply(true)
}

fn cmd<const N: usize>(cmd_type: teensy::CmdType) -> teensy::CmdMsg<N> {
    teensy::CmdMsg {
        cmd_type,
        ..teensy::CmdMsg::default()
    }
}

/// Runs a seed 003 verb for a board of `motors` joints over `stream`, waiting up to `wait` for each
/// echo; prints through `sink`.
pub fn run_teensy(
    stream: impl ByteStream,
    motors: usize,
    verb: &TeensyVerb,
    wait: Duration,
    sink: &mut dyn FnMut(Value),
) -> Result<Verdict, String> {
    with_motors!(motors, run_teensy_n(stream, verb, wait, sink))
}

fn run_teensy_n<const N: usize>(
    stream: impl ByteStream,
    verb: &TeensyVerb,
    wait: Duration,
    sink: &mut dyn FnMut(Value),
) -> Result<Verdict, String> {
    let mut s = Session::new(TeensyLink::<_, N>::new(stream), sink);
    let echoed = |s: &mut Teensy<'_, _, N>, msg| command(s, msg, is_echo_of(msg), wait);
    match verb {
        TeensyVerb::Ping { count } => {
            let probe = cmd::<N>(teensy::CmdType::EndeffOff);
            ping(&mut s, probe, is_echo_of(probe), *count, wait)
        }
        TeensyVerb::Cal => echoed(&mut s, cmd(teensy::CmdType::Cal)),
        TeensyVerb::Endeff(on) => {
            let t = if *on {
                teensy::CmdType::EndeffOn
            } else {
                teensy::CmdType::EndeffOff
            };
            echoed(&mut s, cmd(t))
        }
        TeensyVerb::Config { accel_deg_s2 } => {
            let c = teensy::CmdMsg {
                mtr_accel_deg_s_s: *accel_deg_s2,
                ..cmd(teensy::CmdType::Config)
            };
            echoed(&mut s, c)
        }
        TeensyVerb::Move(plan) => teensy_move(&mut s, plan, wait),
        TeensyVerb::SendHex(h) => send_hex(&mut s, h),
    }
}

fn teensy_move<S: ByteStream, const N: usize>(
    s: &mut Teensy<'_, S, N>,
    plan: &MovePlan,
    wait: Duration,
) -> Result<Verdict, String> {
    let angles = <[i32; N]>::try_from(plan.angles.as_slice()).map_err(|_| {
        format!(
            "--angles has {} values but --motors is {N}",
            plan.angles.len()
        )
    })?;
    let mtrs = teensy::CmdMsg::<N> {
        cmd_type: teensy::CmdType::Mtrs,
        is_relative: i32::from(plan.relative),
        mtr_angles: angles,
        mtr_speed_deg_s: plan.speed_deg_s,
        ..teensy::CmdMsg::default()
    };
    let cal = cmd::<N>(teensy::CmdType::Cal);
    s.out.put(
        json!({"sending": CmdMsgJson::from(&mtrs), "frames": plan.frames,
        "hz": 1.0 / plan.period.as_secs_f64(), "cal": plan.cal}),
    );
    struct Env<'s, 'a, S: ByteStream, const N: usize> {
        s: &'s mut Teensy<'a, S, N>,
        cal: Pending<teensy::CmdMsg<N>>,
        mtrs_sent: u64,
        last_sent: Instant,
        echoes_ok: u64,
        echoes_refused: u64,
    }
    impl<S: ByteStream, const N: usize> Env<'_, '_, S, N> {
        fn echoes(&self) -> u64 {
            self.echoes_ok.saturating_add(self.echoes_refused)
        }
        fn echo_overdue(&self, wait: Duration) -> bool {
            self.echoes() < self.mtrs_sent && self.last_sent.elapsed() >= wait
        }
    }
    let mut env = Env {
        s,
        cal: Pending::None,
        mtrs_sent: 0,
        last_sent: Instant::now(),
        echoes_ok: 0,
        echoes_refused: 0,
    };
    let is_mtrs_echo = is_echo_of(mtrs);
    let is_cal_echo = is_echo_of(cal);
    let (early, _, pacing) = paced(
        plan.period,
        plan.frames,
        plan.duration,
        |e: &mut Env<'_, '_, S, N>, k| {
            e.s.send(&mtrs)?;
            e.mtrs_sent = e.mtrs_sent.saturating_add(1);
            e.last_sent = Instant::now();
            if k == 0 && plan.cal {
                e.s.send(&cal)?;
                e.cal = Pending::Waiting(Instant::now());
            }
            Ok(())
        },
        |e, window| {
            for m in e.s.listen(window)? {
                e.cal.take(&m, &is_cal_echo);
                if is_mtrs_echo(&m) {
                    if m.cmd_success != 0 {
                        e.echoes_ok = e.echoes_ok.saturating_add(1);
                    } else {
                        e.echoes_refused = e.echoes_refused.saturating_add(1);
                    }
                }
            }
            if e.echoes_refused > 0 {
                return Ok(Some(Verdict::Refused));
            }
            let cal = e.cal.verdict::<TeensyLink<S, N>>(wait);
            Ok(cal.or_else(|| e.echo_overdue(wait).then_some(Verdict::NoReply)))
        },
        |e| e.cal.waiting() || e.echoes() < e.mtrs_sent,
        &mut env,
    )?;
    let verdict = early.unwrap_or(Verdict::Done);
    let cal_json = env.cal.json::<TeensyLink<S, N>>(wait);
    let (sent, ok, refused) = (env.mtrs_sent, env.echoes_ok, env.echoes_refused);
    let s = env.s;
    let decoder = s.link.decoder();
    let received = s.received();
    s.out.put(json!({"verdict": verdict.as_str(), "mtrs_sent": sent, "echoes_ok": ok,
        "echoes_refused": refused, "echoes_missing": sent.saturating_sub(ok.saturating_add(refused)),
        "cal": cal_json, "received": received, "decoder": decoder, "pacing": pacing_json(&pacing),
        "stopped_early": early.is_some()}));
    Ok(verdict)
}

#[cfg(test)]
mod tests;

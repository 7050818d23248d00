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
//! `Err` of the verb and exits with [`EXIT_ERROR`].
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
use statemachine::Estop;

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

/// Exit status of an error outside the exchange: a bad argument (refused before anything is sent),
/// a device that cannot be opened, an I/O error. Also clap's status for a usage error.
pub const EXIT_ERROR: u8 = 2;

impl Verdict {
    /// The process exit status: 0 done, 1 refused, 3 no reply ([`EXIT_ERROR`] is 2).
    pub const fn exit_code(self) -> u8 {
        match self {
            Self::Done => 0,
            Self::Refused => 1,
            Self::NoReply => 3,
        }
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
fn paced_frames(hz: f64, seconds: f64) -> Result<(Duration, u64, Duration), String> {
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
const SPIN: Duration = Duration::from_micros(200);
/// Reading stops this long before a paced deadline; the pacer sleeps the rest.
const READ_MARGIN: Duration = Duration::from_millis(2);
/// Read wait while only listening (no deadline near).
const MIN_READ: Duration = Duration::from_millis(1);
/// Longest single read wait, so deadlines and overdue replies are checked often.
const MAX_READ: Duration = Duration::from_millis(50);
/// A drive of at least this long must hear the board (it sends STATUS every 100 ms).
const HEARD_WITHIN: Duration = Duration::from_millis(200);

/// JSON lines with `t_ms` since the verb started.
struct Lines<'a> {
    t0: Instant,
    sink: &'a mut dyn FnMut(Value),
}

impl Lines<'_> {
    fn ms(&self) -> u64 {
        u64::try_from(self.t0.elapsed().as_millis()).unwrap_or(u64::MAX)
    }

    fn put(&mut self, v: Value) {
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

fn us(d: Duration) -> u64 {
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

fn pacing_json(stats: &PeriodStats) -> Value {
    json!({"periods": stats.count, "mean_us": stats.mean_us(), "min_us": stats.min_us,
        "max_us": stats.max_us, "late": stats.late, "skipped": stats.skipped})
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

impl CdcCounts {
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

    fn json(&self) -> Value {
        json!({"status": self.status, "status_motor_enabled": self.status_motor_enabled,
            "status_estop_latched": self.status_estop_latched, "imu": self.imu, "ack": self.ack,
            "other": self.other, "errors": self.errors,
            "last_status": self.last_status.map(|s| CdcJson::from(cdc::Message::Status(s)))})
    }
}

/// A seed 001 link with its printer and counts.
struct Cdc<'a, S: ByteStream> {
    link: CdcLink<S>,
    out: Lines<'a>,
    rx: CdcCounts,
}

impl<S: ByteStream> Cdc<'_, S> {
    fn send(&mut self, m: &cdc::Message) -> Result<(), String> {
        self.link.send(m).map_err(err)
    }

    /// One read of at most `window`: prints and counts every frame; returns the messages.
    fn listen(&mut self, window: Duration) -> Result<Vec<cdc::Message>, String> {
        self.link
            .stream
            .set_read_timeout(window.min(MAX_READ))
            .map_err(err)?;
        let got = self.link.poll().map_err(err)?;
        for m in &got {
            self.rx.add(m);
            self.out.put(json!({"message": CdcJson::from(*m)}));
        }
        for e in self.link.errors.drain(..) {
            self.rx.errors = self.rx.errors.saturating_add(1);
            self.out
                .put(json!({"error": format!("{e:?}"), "code": e as u8,
                "reason": format!("{:?}", e.reason()), "reason_code": e.reason() as u8}));
        }
        Ok(got)
    }

    /// Reads until a message satisfying `is_reply` arrives (returned with its arrival) or `deadline`.
    fn wait_for(
        &mut self,
        deadline: Instant,
        is_reply: impl Fn(&cdc::Message) -> bool,
    ) -> Result<Option<(cdc::Message, Instant)>, String> {
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

    fn decoder(&self) -> Value {
        json!(self.link.stats())
    }
}

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
    let mut s = Cdc {
        link: CdcLink::new(stream),
        out: Lines {
            t0: Instant::now(),
            sink,
        },
        rx: CdcCounts::default(),
    };
    match verb {
        CdcVerb::Ping { count } => cdc_ping(&mut s, *count, wait),
        CdcVerb::Enable(on) => cdc_command(&mut s, cdc::Message::MotorEnable(*on), wait),
        CdcVerb::Estop(a) => cdc_command(&mut s, cdc::Message::Estop(*a), wait),
        CdcVerb::Drive(plan) => cdc_drive(&mut s, plan, wait),
        CdcVerb::SendHex(h) => {
            s.link.stream.write_all(&h.bytes).map_err(err)?;
            s.out
                .put(json!({"sent_hex": crate::cli::to_hex(&h.bytes), "bytes": h.bytes.len()}));
            let end = after(Instant::now(), h.listen);
            s.wait_for(end, |_| false)?;
            let decoder = s.decoder();
            s.out.put(json!({"verdict": Verdict::Done.as_str(), "received": s.rx.json(), "decoder": decoder}));
            Ok(Verdict::Done)
        }
    }
}

fn cdc_ping<S: ByteStream>(
    s: &mut Cdc<'_, S>,
    count: u32,
    wait: Duration,
) -> Result<Verdict, String> {
    let is_reply =
        |m: &cdc::Message| matches!(m, cdc::Message::Status(_)) || is_ack_of(cdc::MsgId::Ping)(m);
    let mut rtts = Vec::new();
    for i in 0..count {
        let t = Instant::now();
        s.send(&cdc::Message::Ping)?;
        match s.wait_for(after(t, wait), is_reply)? {
            Some((m, at)) => {
                let rtt = at.duration_since(t);
                rtts.push(rtt);
                s.out
                    .put(json!({"ping": i, "round_trip_us": us(rtt), "reply": CdcJson::from(m)}));
            }
            None => s.out.put(json!({"ping": i, "no_reply_ms": ms(wait)})),
        }
    }
    let verdict = if rtts.is_empty() {
        Verdict::NoReply
    } else {
        Verdict::Done
    };
    let decoder = s.decoder();
    s.out.put(
        json!({"verdict": verdict.as_str(), "sent": count, "replies": rtts.len(),
        "round_trip_us": rtt_json(&rtts), "decoder": decoder}),
    );
    Ok(verdict)
}

fn rtt_json(rtts: &[Duration]) -> Value {
    let (Some(min), Some(max)) = (rtts.iter().min(), rtts.iter().max()) else {
        return Value::Null;
    };
    let sum: f64 = rtts.iter().map(Duration::as_secs_f64).sum();
    json!({"min": us(*min), "max": us(*max), "mean": (sum / rtts.len() as f64 * 1e6).round()})
}

fn cdc_command<S: ByteStream>(
    s: &mut Cdc<'_, S>,
    msg: cdc::Message,
    wait: Duration,
) -> Result<Verdict, String> {
    let t = Instant::now();
    s.send(&msg)?;
    let sent = CdcJson::from(msg);
    let (verdict, line) = match s.wait_for(after(t, wait), is_ack_of(msg.id()))? {
        Some((m @ cdc::Message::Ack(a), at)) => {
            let v = if a.result == 0 {
                Verdict::Done
            } else {
                Verdict::Refused
            };
            let line = json!({"verdict": v.as_str(), "sent": sent, "reply": CdcJson::from(m),
                "round_trip_us": us(at.duration_since(t))});
            (v, line)
        }
        _ => (
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
            Ok(match &e.enable {
                Pending::Answered(cdc::Message::Ack(a), _) if a.result != 0 => {
                    Some(Verdict::Refused)
                }
                p if p.overdue(wait) => Some(Verdict::NoReply),
                _ => None,
            })
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
    let enable = match &env.enable {
        Pending::None => Value::Null,
        Pending::Waiting(_) => json!({"no_reply_ms": ms(wait)}),
        Pending::Answered(m, rtt) => {
            json!({"reply": CdcJson::from(*m), "round_trip_us": us(*rtt)})
        }
    };
    let s = env.s;
    let decoder = s.decoder();
    s.out.put(
        json!({"verdict": verdict.as_str(), "frames_sent": sent, "enable": enable,
        "received": s.rx.json(), "decoder": decoder, "pacing": pacing_json(&pacing),
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

/// A seed 003 link with its printer and counts.
struct Teensy<'a, S: ByteStream, const N: usize> {
    link: TeensyLink<S, N>,
    out: Lines<'a>,
    rx: TeensyCounts,
}

impl<S: ByteStream, const N: usize> Teensy<'_, S, N> {
    fn send(&mut self, m: &teensy::CmdMsg<N>) -> Result<(), String> {
        self.link.send(m).map_err(err)
    }

    fn listen(&mut self, window: Duration) -> Result<Vec<teensy::CmdMsg<N>>, String> {
        self.link
            .stream
            .set_read_timeout(window.min(MAX_READ))
            .map_err(err)?;
        let got = self.link.poll().map_err(err)?;
        for m in &got {
            self.rx.messages = self.rx.messages.saturating_add(1);
            self.out.put(json!({"message": CmdMsgJson::from(m)}));
        }
        for r in self.link.errors.drain(..) {
            self.rx.errors = self.rx.errors.saturating_add(1);
            self.out
                .put(json!({"reason": format!("{r:?}"), "reason_code": r as u8}));
        }
        Ok(got)
    }

    fn wait_for(
        &mut self,
        deadline: Instant,
        is_reply: impl Fn(&teensy::CmdMsg<N>) -> bool,
    ) -> Result<Option<(teensy::CmdMsg<N>, Instant)>, String> {
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

    fn decoder(&self) -> Value {
        json!(self.link.stats())
    }

    fn counts(&self) -> Value {
        json!({"messages": self.rx.messages, "errors": self.rx.errors})
    }
}

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
    let mut s = Teensy::<_, N> {
        link: TeensyLink::new(stream),
        out: Lines {
            t0: Instant::now(),
            sink,
        },
        rx: TeensyCounts::default(),
    };
    match verb {
        TeensyVerb::Ping { count } => teensy_ping(&mut s, *count, wait),
        TeensyVerb::Cal => teensy_command(&mut s, cmd(teensy::CmdType::Cal), wait),
        TeensyVerb::Endeff(on) => {
            let t = if *on {
                teensy::CmdType::EndeffOn
            } else {
                teensy::CmdType::EndeffOff
            };
            teensy_command(&mut s, cmd(t), wait)
        }
        TeensyVerb::Config { accel_deg_s2 } => {
            let c = teensy::CmdMsg {
                mtr_accel_deg_s_s: *accel_deg_s2,
                ..cmd(teensy::CmdType::Config)
            };
            teensy_command(&mut s, c, wait)
        }
        TeensyVerb::Move(plan) => teensy_move(&mut s, plan, wait),
        TeensyVerb::SendHex(h) => {
            s.link.stream.write_all(&h.bytes).map_err(err)?;
            s.out
                .put(json!({"sent_hex": crate::cli::to_hex(&h.bytes), "bytes": h.bytes.len()}));
            let end = after(Instant::now(), h.listen);
            s.wait_for(end, |_| false)?;
            let decoder = s.decoder();
            let received = s.counts();
            s.out.put(json!({"verdict": Verdict::Done.as_str(), "received": received, "decoder": decoder}));
            Ok(Verdict::Done)
        }
    }
}

fn teensy_ping<S: ByteStream, const N: usize>(
    s: &mut Teensy<'_, S, N>,
    count: u32,
    wait: Duration,
) -> Result<Verdict, String> {
    let probe = cmd::<N>(teensy::CmdType::EndeffOff);
    let mut rtts = Vec::new();
    for i in 0..count {
        let t = Instant::now();
        s.send(&probe)?;
        match s.wait_for(after(t, wait), is_echo_of(probe))? {
            Some((m, at)) => {
                let rtt = at.duration_since(t);
                rtts.push(rtt);
                s.out.put(
                    json!({"ping": i, "round_trip_us": us(rtt), "reply": CmdMsgJson::from(&m)}),
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
    let decoder = s.decoder();
    s.out.put(
        json!({"verdict": verdict.as_str(), "sent": count, "replies": rtts.len(),
        "round_trip_us": rtt_json(&rtts), "decoder": decoder}),
    );
    Ok(verdict)
}

fn teensy_command<S: ByteStream, const N: usize>(
    s: &mut Teensy<'_, S, N>,
    msg: teensy::CmdMsg<N>,
    wait: Duration,
) -> Result<Verdict, String> {
    let t = Instant::now();
    s.send(&msg)?;
    let sent = CmdMsgJson::from(&msg);
    let (verdict, line) = match s.wait_for(after(t, wait), is_echo_of(msg))? {
        Some((m, at)) => {
            let v = if m.cmd_success != 0 {
                Verdict::Done
            } else {
                Verdict::Refused
            };
            let line = json!({"verdict": v.as_str(), "sent": sent, "reply": CmdMsgJson::from(&m),
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
            Ok(match &e.cal {
                _ if e.echoes_refused > 0 => Some(Verdict::Refused),
                Pending::Answered(m, _) if m.cmd_success == 0 => Some(Verdict::Refused),
                p if p.overdue(wait) => Some(Verdict::NoReply),
                _ if e.echo_overdue(wait) => Some(Verdict::NoReply),
                _ => None,
            })
        },
        |e| e.cal.waiting() || e.echoes() < e.mtrs_sent,
        &mut env,
    )?;
    let verdict = early.unwrap_or(Verdict::Done);
    let cal_json = match &env.cal {
        Pending::None => Value::Null,
        Pending::Waiting(_) => json!({"no_reply_ms": ms(wait)}),
        Pending::Answered(m, rtt) => {
            json!({"reply": CmdMsgJson::from(m), "round_trip_us": us(*rtt)})
        }
    };
    let (sent, ok, refused) = (env.mtrs_sent, env.echoes_ok, env.echoes_refused);
    let s = env.s;
    let decoder = s.decoder();
    let received = s.counts();
    s.out.put(json!({"verdict": verdict.as_str(), "mtrs_sent": sent, "echoes_ok": ok,
        "echoes_refused": refused, "echoes_missing": sent.saturating_sub(ok.saturating_add(refused)),
        "cal": cal_json, "received": received, "decoder": decoder, "pacing": pacing_json(&pacing),
        "stopped_early": early.is_some()}));
    Ok(verdict)
}

#[cfg(test)]
mod tests;

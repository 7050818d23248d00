//! Framed links over a byte stream: seed 001 (USB CDC / UART, `AA 55` frames) and seed 003 (robust COBS + CRC).
//!
//! Reception always goes through the protocol crate's resynchronising decoders
//! ([`cdc::StreamDecoder`], [`teensy::RobustDecoder`]), so garbage, split reads and broken frames
//! cost only the broken frame. Requests wait for their reply until a deadline:
//!
//! ```text
//!  host   ──PING──▶                      ──ENABLE 1──▶
//!  MCU          ◀── IMU ── STATUS/ACK ──        ◀── ACK(0x02, 0) ──
//!               └ kept in `other` ┘ └ the reply ┘
//! ```

use std::time::{Duration, Instant};

use protocol::{cdc, teensy};
use statemachine::{Estop, Event};

use crate::transport::{ByteStream, LinkError};

/// Bytes read per call.
const READ_CHUNK: usize = 256;

/// What came back for a request.
#[derive(Clone, Debug, PartialEq)]
pub struct Reply<M> {
    /// The message that answered the request.
    pub reply: M,
    /// Time from the write to the reply.
    pub round_trip: Duration,
    /// Other messages received meanwhile (IMU, STATUS), in order.
    pub other: Vec<M>,
}

/// A seed 001 link: sends messages, decodes every received frame.
pub struct CdcLink<S: ByteStream> {
    /// The byte stream.
    pub stream: S,
    decoder: cdc::StreamDecoder,
    /// Frames refused so far (CRC, length, unknown id, value), in order of arrival.
    pub errors: Vec<cdc::Error>,
}

impl<S: ByteStream> CdcLink<S> {
    /// A link over `stream`.
    pub fn new(stream: S) -> Self {
        Self {
            stream,
            decoder: cdc::StreamDecoder::new(),
            errors: Vec::new(),
        }
    }

    /// The receive decoder's counters.
    pub fn stats(&self) -> cdc::Stats {
        self.decoder.stats()
    }

    /// Discards what was received and not yet read, and the decoder's partial frame (counted as
    /// dropped): the next message is one that arrives after this call. Returns the bytes discarded.
    pub fn discard_input(&mut self) -> Result<usize, LinkError> {
        let held = self.decoder.buffered();
        self.decoder.reset();
        Ok(self.stream.discard_input()?.saturating_add(held))
    }

    /// Frames and sends `msg`.
    pub fn send(&mut self, msg: &cdc::Message) -> Result<(), LinkError> {
        let mut out = [0u8; cdc::MAX_FRAME_LEN];
        let n = msg.encode(&mut out);
        self.stream.write_all(out.get(..n).unwrap_or(&[]))
    }

    /// One read: every message it completes (refused frames go to [`Self::errors`]).
    pub fn poll(&mut self) -> Result<Vec<cdc::Message>, LinkError> {
        let mut buf = [0u8; READ_CHUNK];
        let n = self.stream.read_some(&mut buf)?;
        let mut out = Vec::new();
        for r in self.decoder.feed(buf.get(..n).unwrap_or(&[])) {
            match r {
                Ok(m) => out.push(m),
                Err(e) => self.errors.push(e),
            }
        }
        Ok(out)
    }

    /// Sends `msg` and reads until a message satisfying `is_reply` arrives or `timeout` passes.
    pub fn request(
        &mut self,
        msg: &cdc::Message,
        timeout: Duration,
        expected: &str,
        is_reply: impl Fn(&cdc::Message) -> bool,
    ) -> Result<Reply<cdc::Message>, LinkError> {
        let t0 = Instant::now();
        self.send(msg)?;
        await_reply(t0, timeout, || self.poll(), is_reply)?
            .ok_or_else(|| LinkError::NoReply(self.stream.name().to_string(), expected.to_string()))
    }

    /// PING; the reply is an ACK of 0x10 or a STATUS.
    pub fn ping(&mut self, timeout: Duration) -> Result<Reply<cdc::Message>, LinkError> {
        self.request(&cdc::Message::Ping, timeout, "ACK or STATUS", |m| {
            matches!(m, cdc::Message::Status(_))
                || matches!(m, cdc::Message::Ack(a) if a.msg_id == cdc::MsgId::Ping as u8)
        })
    }

    /// Sends a low-rate command and waits for its ACK. Returns the ACK and the ladder event the
    /// MCU applies for the command ([`cdc::Message::to_event`]); an ACK with a non-zero result
    /// means the MCU refused it.
    pub fn command(
        &mut self,
        msg: cdc::Message,
        timeout: Duration,
    ) -> Result<(Reply<cdc::Message>, Option<Event<4>>), LinkError> {
        let id = msg.id() as u8;
        let r = self.request(
            &msg,
            timeout,
            "ACK",
            |m| matches!(m, cdc::Message::Ack(a) if a.msg_id == id),
        )?;
        Ok((r, msg.to_event()))
    }

    /// MOTOR_ENABLE: `true` re-arms (`Event::Rearm`), `false` stops (an enable = 0 frame).
    pub fn enable(
        &mut self,
        on: bool,
        timeout: Duration,
    ) -> Result<(Reply<cdc::Message>, Option<Event<4>>), LinkError> {
        self.command(cdc::Message::MotorEnable(on), timeout)
    }

    /// ESTOP engage / release (`Event::Estop`).
    pub fn estop(
        &mut self,
        action: Estop,
        timeout: Duration,
    ) -> Result<(Reply<cdc::Message>, Option<Event<4>>), LinkError> {
        self.command(cdc::Message::Estop(action), timeout)
    }
}

/// A seed 003 robust link to a Teensy with `N` motors: sends `CmdMsg` frames, waits for the echo.
pub struct TeensyLink<S: ByteStream, const N: usize> {
    /// The byte stream.
    pub stream: S,
    decoder: teensy::RobustDecoder<N>,
    /// Frames refused so far, as ladder reject reasons.
    pub errors: Vec<statemachine::RejectReason>,
}

impl<S: ByteStream, const N: usize> TeensyLink<S, N> {
    /// A link over `stream`.
    pub fn new(stream: S) -> Self {
        Self {
            stream,
            decoder: teensy::RobustDecoder::new(),
            errors: Vec::new(),
        }
    }

    /// The receive decoder's counters.
    pub fn stats(&self) -> teensy::RobustStats {
        self.decoder.stats()
    }

    /// Discards what was received and not yet read: the next command decoded starts after this
    /// call (a partial frame held by the decoder fails its CRC and is counted as refused). Returns
    /// the bytes discarded.
    pub fn discard_input(&mut self) -> Result<usize, LinkError> {
        self.stream.discard_input()
    }

    /// Sends `msg` as a robust frame.
    pub fn send(&mut self, msg: &teensy::CmdMsg<N>) -> Result<(), LinkError> {
        let mut out = [0u8; teensy::ROBUST_BUF];
        let n = msg.encode_robust(&mut out).unwrap_or(0);
        self.stream.write_all(out.get(..n).unwrap_or(&[]))
    }

    /// One read: every command it completes (refused frames go to [`Self::errors`]).
    pub fn poll(&mut self) -> Result<Vec<teensy::CmdMsg<N>>, LinkError> {
        let mut buf = [0u8; READ_CHUNK];
        let n = self.stream.read_some(&mut buf)?;
        let mut out = Vec::new();
        for &b in buf.get(..n).unwrap_or(&[]) {
            match self.decoder.push(b) {
                Some(Ok(m)) => out.push(m),
                Some(Err(e)) => self.errors.push(e),
                None => {}
            }
        }
        Ok(out)
    }

    /// Sends `msg` and waits for the Teensy's echo (same command, `cmd_success` set).
    pub fn command(
        &mut self,
        msg: &teensy::CmdMsg<N>,
        timeout: Duration,
    ) -> Result<Reply<teensy::CmdMsg<N>>, LinkError> {
        let t0 = Instant::now();
        self.send(msg)?;
        let echo_of = |m: &teensy::CmdMsg<N>| m.reply(true) == msg.reply(true);
        await_reply(t0, timeout, || self.poll(), echo_of)?.ok_or_else(|| {
            LinkError::NoReply(
                self.stream.name().to_string(),
                "echo of the command".to_string(),
            )
        })
    }
}

/// Polls until a message satisfying `is_reply` arrives (`Some`) or `timeout` has passed since the
/// request went out at `t0` (`None`). Messages before the reply, and after it in the same read, are
/// kept in [`Reply::other`] in order.
fn await_reply<M>(
    t0: Instant,
    timeout: Duration,
    mut poll: impl FnMut() -> Result<Vec<M>, LinkError>,
    is_reply: impl Fn(&M) -> bool,
) -> Result<Option<Reply<M>>, LinkError> {
    let mut other = Vec::new();
    loop {
        let mut got = poll()?.into_iter();
        while let Some(m) = got.next() {
            if is_reply(&m) {
                other.extend(got);
                return Ok(Some(Reply {
                    reply: m,
                    round_trip: t0.elapsed(),
                    other,
                }));
            }
            other.push(m);
        }
        if t0.elapsed() >= timeout {
            return Ok(None);
        }
    }
}

#[cfg(test)]
mod tests;

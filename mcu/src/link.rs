//! `spi_dma_done` (priority 2, once per link transaction): the received frame → decode → ladder
//! event, and the feedback frame the next transaction sends back.
//!
//! A frame never moves the drive (the tick is the only event that changes the setpoint, INV-8),
//! so this task does not touch the bridge: the next tick applies whatever the ladder decided.
//!
//! A command whose `request` is [`REQUEST_IDENTITY`] is answered in the next feedback slot with
//! an [`McuInfo`] frame (firmware identity, reset cause) instead of a `MotorFeedback`; it takes
//! that slot's sequence number. The request is honoured for any frame that decoded, whether or
//! not the ladder accepted its command: answering reads nothing the ladder decides.

use crate::safety::Safety;
use crate::Measurements;
use crate::AXES;
use protocol::amr::{
    decode_command, encode_feedback, encode_info, McuInfo, MotorCommand, MotorFeedback, FRAME_LEN,
    REQUEST_IDENTITY,
};
use statemachine::RejectReason;

type Output = statemachine::Output<AXES>;

/// The link task's own state: the feedback sequence, the last accepted command's sequence, and
/// the identity it answers with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LinkTask {
    seq: u32,
    cmd_seq: u32,
    identity: McuInfo,
    identity_requested: bool,
}

impl LinkTask {
    /// Before the first frame; `identity` is what an identity request is answered with (its
    /// `seq` is filled in when sent).
    pub const fn new(identity: McuInfo) -> Self {
        Self {
            seq: 0,
            cmd_seq: 0,
            identity,
            identity_requested: false,
        }
    }

    /// One transaction: hands the received frame to the ladder, then writes the next feedback
    /// frame into `tx`, stamped `now_us` (µs since boot, [`Safety::micros`]).
    pub fn on_frame(
        &mut self,
        safety: &mut Safety,
        frame: &[u8; FRAME_LEN],
        meas: &Measurements,
        now_us: u32,
        tx: &mut [u8; FRAME_LEN],
    ) -> Output {
        let out = self.receive(safety, frame);
        self.feedback(&out, meas, now_us, tx);
        out
    }

    /// Decode, validate and step the ladder: the received-frame unit of the budget (CRC, protobuf,
    /// validation, ladder step). Not inlined, so the budget report can count it as one unit.
    #[inline(never)]
    pub fn receive(&mut self, safety: &mut Safety, frame: &[u8; FRAME_LEN]) -> Output {
        self.apply(safety, decode_command(frame))
    }

    /// A transaction cut short at the link's chip select (the board re-armed its receiver at a
    /// frame boundary): the lost frame is a framing refusal, like any frame that did not arrive
    /// whole, through the same path as every decode result ([`LinkTask::apply`]).
    pub fn transaction_cut(&mut self, safety: &mut Safety) -> Output {
        self.apply(safety, Err(RejectReason::Framing))
    }

    /// What the task does with a decode result: a refusal becomes `Event::Rejected`, a command
    /// `Event::Frame` (validated by the ladder); an identity request is noted for the next slot.
    /// The cross-crate proofs prove this function for every result a decoder can return.
    #[inline(always)]
    pub fn apply(
        &mut self,
        safety: &mut Safety,
        decoded: Result<MotorCommand, RejectReason>,
    ) -> Output {
        let seq = decoded.as_ref().map_or(0, |c| c.seq);
        if decoded
            .as_ref()
            .is_ok_and(|c| c.request == REQUEST_IDENTITY)
        {
            self.identity_requested = true;
        }
        let before = safety.ladder().counters().valid_frames;
        let out = safety.step(protocol::event_from(decoded.and_then(|c| c.to_command())));
        if safety.ladder().counters().valid_frames != before {
            self.cmd_seq = seq;
        }
        out
    }

    /// Builds the feedback frame for the next transaction, or the identity if the last frame
    /// asked for it. Not inlined, for the budget report.
    #[inline(never)]
    pub fn feedback(
        &mut self,
        out: &Output,
        m: &Measurements,
        now_us: u32,
        tx: &mut [u8; FRAME_LEN],
    ) {
        self.seq = self.seq.wrapping_add(1);
        if self.identity_requested {
            self.identity_requested = false;
            let info = McuInfo {
                seq: self.seq,
                ..self.identity
            };
            encode_info(&info, tx);
            return;
        }
        let [sl, sr] = m.speeds;
        let [il, ir] = m.currents;
        let [el, er] = m.encoders;
        let fb = MotorFeedback {
            timestamp_us: now_us,
            left_speed: sl.to_num(),
            right_speed: sr.to_num(),
            left_current: il.to_num(),
            right_current: ir.to_num(),
            left_encoder: el,
            right_encoder: er,
            fault_flags: 0,
            seq: self.seq,
            mode: 0,
            cmd_seq: self.cmd_seq,
        }
        .with_output(out);
        encode_feedback(&fb, tx);
    }
}

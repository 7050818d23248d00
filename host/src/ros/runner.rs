//! The node's 1 kHz bridge thread: the existing [`Link`] (absolute-deadline pacing, one exchange
//! per period, the [`crate::bridge::Bridge`] with its 200 ms cmd_vel rule and arming ladder),
//! fed and read through [`Shared`] without ever waiting for the DDS thread.
//!
//! ```text
//!  every 1 ms: wait for the deadline ─► take cmd_vel (try) ─► take requests (try)
//!      ─► exchange (unless ESTOP stopped them) ─► publish snapshot + diagnostics (try)
//!  on stop: disarm, 50 more exchanges with enable = 0 (the MCU stops under control), then end
//! ```

use std::time::SystemTime;

use crate::bridge::{Bridge, BridgeConfig, Diagnostic};
use crate::link::Link;
use crate::transport::Transport;

use super::shared::{Request, Shared};

/// A transport as the node drives it: a real device runs the bridge on the link's own clock; a
/// simulated board in lockstep has a clock of its own, which the bridge must run on, and lets a
/// millisecond pass with no frame while ESTOP keeps the link silent.
pub trait NodeTransport: Transport {
    /// The transport's own clock now, µs, and how long after sending the feedback is in hand; None
    /// for a real device (the link's clock is the time).
    fn board_clock(&self) -> Option<(u64, u64)> {
        None
    }
    /// One period with no frame (a real device's time passes by itself).
    fn idle_period(&mut self) {}
}

impl NodeTransport for crate::transport::SpiTransport {}

impl NodeTransport for crate::simlink::SimMcu {
    fn board_clock(&self) -> Option<(u64, u64)> {
        (self.config().clock == crate::simlink::SimClock::Lockstep)
            .then(|| (self.now_us(), crate::simlink::LOCKSTEP_RECV_US))
    }
    fn idle_period(&mut self) {
        if self.config().clock == crate::simlink::SimClock::Lockstep {
            self.idle(1);
        }
    }
}

impl<T: NodeTransport + ?Sized> NodeTransport for Box<T> {
    fn board_clock(&self) -> Option<(u64, u64)> {
        (**self).board_clock()
    }
    fn idle_period(&mut self) {
        (**self).idle_period();
    }
}

/// The bridge's time now: the board's clock where the transport has one, else the link's.
fn now_of<T: NodeTransport>(link: &Link<T>) -> u64 {
    link.transport
        .board_clock()
        .map_or_else(|| link.now_us(), |(t, _)| t)
}

/// Exchanges with enable = 0 sent after a stop request before the thread ends (50 ms).
pub const SHUTDOWN_CYCLES: u32 = 50;

/// The bridge thread's own state besides the link.
#[derive(Debug, Default)]
pub struct BridgeLoop {
    /// ESTOP engaged: no exchanges.
    pub silent: bool,
    /// Diagnostics not yet handed to the DDS side.
    pending: Vec<(u64, Diagnostic)>,
    /// Reception time of the latest cmd_vel, on the link's clock.
    cmd_vel_at: Option<u64>,
    last_error: Option<String>,
}

impl BridgeLoop {
    /// A loop that exchanges frames.
    pub fn new() -> Self {
        Self::default()
    }

    /// One cycle after the deadline: hand-offs, one exchange, the snapshot.
    pub fn cycle<T: NodeTransport>(&mut self, link: &mut Link<T>, shared: &Shared) {
        let now = now_of(link);
        if let Some(c) = shared.take_cmd_vel() {
            // The age it had on the shared clock, carried over to the link's clock.
            let age = shared.now_us().saturating_sub(c.received_us);
            let at = now.saturating_sub(age);
            link.bridge.cmd_vel(at, c.v, c.w);
            self.cmd_vel_at = Some(at);
        }
        for r in shared.take_requests() {
            match r {
                Request::Arm => link.bridge.arm(now),
                Request::Rearm => link.bridge.rearm(now),
                Request::Disarm => link.bridge.disarm(),
                Request::Estop(true) => {
                    link.bridge.disarm();
                    self.silent = true;
                }
                Request::Estop(false) => self.silent = false,
            }
        }
        self.exchange(link);
        let _ = self.publish(link, shared, false);
    }

    /// One exchange on the bridge's clock, or, while ESTOP keeps the link silent, one period
    /// without a frame.
    fn exchange<T: NodeTransport>(&mut self, link: &mut Link<T>) {
        if self.silent {
            link.transport.idle_period();
            return;
        }
        let r = match link.transport.board_clock() {
            Some((t, recv)) => link.exchange_at(t, t.saturating_add(recv)),
            None => link.exchange(),
        };
        match r {
            Ok(d) => self.pending.extend(d),
            Err(e) => self.last_error = Some(e.to_string()),
        }
    }

    /// Hands the state to the DDS side; false if it holds the lock (retried next cycle).
    pub fn publish<T: NodeTransport>(
        &mut self,
        link: &Link<T>,
        shared: &Shared,
        ended: bool,
    ) -> bool {
        let now = now_of(link);
        let b: &Bridge = &link.bridge;
        let silent = self.silent;
        let age = self.cmd_vel_at.map(|t| now.saturating_sub(t));
        let last_error = self.last_error.clone();
        shared.publish(&mut self.pending, |s| {
            s.cycles = link.pacer.stats.count;
            s.stamp = Some(SystemTime::now());
            s.feedback = b.last_feedback;
            s.mcu_info = b.mcu_info();
            s.arm = Some(b.state());
            s.output = b.output();
            s.cmd_vel_age_us = age;
            s.stats = b.stats;
            s.transport_errors = link.transport_errors;
            s.last_error = last_error;
            s.clock_synced = b.clock.is_synced(now);
            s.clock_offset_us = b.clock.offset_at(now as f64);
            s.silent = silent;
            s.period_misses = link.pacer.stats.misses;
            s.skipped_deadlines = link.pacer.stats.skipped;
            s.ended = ended;
        })
    }
}

/// Runs the bridge over `transport` until [`Shared::stop`], then disarms and sends
/// [`SHUTDOWN_CYCLES`] more frames (unless ESTOP stopped the exchanges).
pub fn run<T: NodeTransport>(transport: T, cfg: BridgeConfig, arm: bool, shared: &Shared) {
    let mut link = Link::new(transport, Bridge::new(cfg));
    // Who answers (firmware version, reset cause) goes to the diagnostics.
    link.bridge.request_identity();
    if arm {
        let now = now_of(&link);
        link.bridge.arm(now);
    }
    let mut l = BridgeLoop::new();
    while !shared.stopping() {
        link.pacer.wait();
        l.cycle(&mut link, shared);
    }
    link.bridge.disarm();
    for _ in 0..SHUTDOWN_CYCLES {
        if l.silent {
            break;
        }
        link.pacer.wait();
        l.exchange(&mut link);
    }
    // The last snapshot must reach the DDS side: retry while it holds the lock.
    let mut tries = 0u32;
    while !l.publish(&link, shared, true) && tries < 1000 {
        tries = tries.saturating_add(1);
        std::thread::yield_now();
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
    use crate::bridge::ArmState;
    use crate::transport::LinkError;
    use protocol::amr::{self, MotorFeedback, FRAME_LEN};

    /// An MCU that accepts every command and reports it back as measured, in NORMAL (enough to
    /// watch the hand-off; the ladder itself is tested in `bridge` and `statemachine`).
    #[derive(Default)]
    struct EchoMcu {
        seq: u32,
        t_us: u32,
        commands: Vec<amr::MotorCommand>,
    }

    impl Transport for EchoMcu {
        fn exchange(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
            let frame: &[u8; FRAME_LEN] = tx.try_into().unwrap();
            let c = amr::decode_command(frame).unwrap();
            self.commands.push(c);
            self.seq += 1;
            self.t_us += 1000;
            let fb = MotorFeedback {
                timestamp_us: self.t_us,
                left_speed: c.left_speed_cmd,
                right_speed: c.right_speed_cmd,
                seq: self.seq,
                cmd_seq: c.seq,
                ..MotorFeedback::default()
            };
            let out: &mut [u8; FRAME_LEN] = rx.try_into().unwrap();
            amr::encode_feedback(&fb, out);
            Ok(())
        }
        fn name(&self) -> &str {
            "echo"
        }
    }

    impl NodeTransport for EchoMcu {}

    fn link() -> Link<EchoMcu> {
        Link::new(EchoMcu::default(), Bridge::new(BridgeConfig::DEFAULT))
    }

    #[test]
    fn a_cmd_vel_from_the_dds_side_reaches_the_wheels() {
        let shared = Shared::new();
        let mut link = link();
        let mut l = BridgeLoop::new();
        shared.request(Request::Arm);
        for _ in 0..10 {
            shared.put_cmd_vel(0.4, 0.0);
            l.cycle(&mut link, &shared);
        }
        let s = shared.snapshot();
        assert_eq!(s.arm, Some(ArmState::Armed));
        // Ramping towards 0.4/0.08 = 5 rad/s at 0.04 rad/s per cycle.
        assert!(s.output[0] > 0.0 && s.output[0] <= 5.0, "{:?}", s.output);
        assert_eq!(s.stats.feedback_ok, 10);
        assert!(s.cmd_vel_age_us.unwrap() < 200_000);
    }

    /// A cmd_vel keeps its reception time across the hand-off: one received 300 ms before the
    /// bridge takes it is already stale (200 ms rule), so the wheels get zero.
    #[test]
    fn a_cmd_vel_taken_late_is_judged_by_its_reception_time() {
        let shared = Shared::new();
        let mut link = link();
        let mut l = BridgeLoop::new();
        shared.request(Request::Arm);
        l.cycle(&mut link, &shared);
        shared.put_cmd_vel(0.4, 0.0);
        std::thread::sleep(std::time::Duration::from_millis(300));
        for _ in 0..5 {
            l.cycle(&mut link, &shared);
        }
        let s = shared.snapshot();
        assert_eq!(s.output, [0.0, 0.0]);
        assert!(s.cmd_vel_age_us.unwrap() >= 300_000);
        assert!(s.events.iter().any(|(_, d)| *d == Diagnostic::CmdVelStale));
        assert!(link
            .transport
            .commands
            .iter()
            .all(|c| c.left_speed_cmd == 0.0));
    }

    #[test]
    fn estop_stops_the_exchanges_and_disarms_until_asked_again() {
        let shared = Shared::new();
        let mut link = link();
        let mut l = BridgeLoop::new();
        shared.request(Request::Arm);
        for _ in 0..5 {
            l.cycle(&mut link, &shared);
        }
        let sent = link.transport.commands.len();
        shared.request(Request::Estop(true));
        for _ in 0..5 {
            l.cycle(&mut link, &shared);
        }
        assert_eq!(
            link.transport.commands.len(),
            sent,
            "no exchange while stopped"
        );
        let s = shared.snapshot();
        assert!(s.silent);
        assert_eq!(s.arm, Some(ArmState::Disarmed));
        shared.request(Request::Estop(false));
        l.cycle(&mut link, &shared);
        assert_eq!(link.transport.commands.len(), sent + 1);
        // Resuming does not arm: enable stays 0 until an explicit request.
        assert!(!link.transport.commands.last().unwrap().enable);
    }

    #[test]
    fn a_stopped_run_disarms_and_sends_its_last_frames_disabled() {
        let shared = std::sync::Arc::new(Shared::new());
        let t = {
            let shared = shared.clone();
            std::thread::spawn(move || {
                let mut mcu = EchoMcu::default();
                let mut sent = Vec::new();
                // Run on a wrapper that records the commands the thread sent.
                struct Rec<'a>(&'a mut EchoMcu, &'a mut Vec<amr::MotorCommand>);
                impl Transport for Rec<'_> {
                    fn exchange(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
                        self.0.exchange(tx, rx)?;
                        self.1.push(*self.0.commands.last().unwrap());
                        Ok(())
                    }
                    fn name(&self) -> &str {
                        "rec"
                    }
                }
                impl NodeTransport for Rec<'_> {}
                run(
                    Rec(&mut mcu, &mut sent),
                    BridgeConfig::DEFAULT,
                    true,
                    &shared,
                );
                sent
            })
        };
        while shared.snapshot().arm != Some(ArmState::Armed) {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        shared.stop();
        let sent = t.join().unwrap();
        assert!(sent.iter().any(|c| c.enable), "it was armed");
        let tail = &sent[sent.len() - SHUTDOWN_CYCLES as usize..];
        assert!(tail.iter().all(|c| !c.enable && c.left_speed_cmd == 0.0));
        assert!(shared.snapshot().ended);
    }
}

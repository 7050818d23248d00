//! The real-time loop on the robot: every 1 ms (absolute deadlines) build the command, exchange
//! one frame over the transport, decode and check the feedback.

use std::time::{Duration, Instant};

use protocol::amr::{self, FRAME_LEN};

use crate::bridge::{Bridge, Diagnostic};
use crate::pacing::Pacer;
use crate::transport::{LinkError, Transport};

/// The bridge bound to a transport and a pacer.
pub struct Link<T: Transport> {
    /// The byte link.
    pub transport: T,
    /// The bridge state machine.
    pub bridge: Bridge,
    /// The 1 kHz pacer and its period statistics.
    pub pacer: Pacer,
    epoch: Instant,
    /// Exchanges that failed at the transport level.
    pub transport_errors: u64,
}

impl<T: Transport> Link<T> {
    /// A link paced at the seed's 1 ms contract.
    pub fn new(transport: T, bridge: Bridge) -> Self {
        Self {
            transport,
            bridge,
            pacer: Pacer::contract(),
            epoch: Instant::now(),
            transport_errors: 0,
        }
    }

    /// Host time in µs since the link was created.
    pub fn now_us(&self) -> u64 {
        u64::try_from(self.epoch.elapsed().as_micros()).unwrap_or(u64::MAX)
    }

    /// Waits for the next deadline and runs one exchange. Returns the diagnostics it raised.
    pub fn cycle(&mut self) -> Result<Vec<(u64, Diagnostic)>, LinkError> {
        self.pacer.wait();
        self.exchange()
    }

    /// One exchange now, without waiting, on the link's own clock.
    pub fn exchange(&mut self) -> Result<Vec<(u64, Diagnostic)>, LinkError> {
        let t_send = self.now_us();
        self.exchange_timed(t_send, None)
    }

    /// One exchange without waiting, the host times given by the caller instead of read from the
    /// link's clock: the command is built for `t_send`, and the feedback is taken as received at
    /// `t_recv` (µs, on one clock of the caller's). A transport with a clock of its own (the
    /// simulated board in lockstep, [`crate::simlink::SimMcu`]) runs the bridge on that clock, so
    /// a host thread that the machine starves does not look like a late host or a frozen MCU.
    pub fn exchange_at(
        &mut self,
        t_send: u64,
        t_recv: u64,
    ) -> Result<Vec<(u64, Diagnostic)>, LinkError> {
        self.exchange_timed(t_send, Some(t_recv))
    }

    /// The exchange; `t_recv` read from the link's clock after the transfer when `None`.
    fn exchange_timed(
        &mut self,
        t_send: u64,
        t_recv: Option<u64>,
    ) -> Result<Vec<(u64, Diagnostic)>, LinkError> {
        let mut tx = [0u8; FRAME_LEN];
        let mut rx = [0u8; FRAME_LEN];
        let cmd = self.bridge.next_command(t_send);
        amr::encode_command(&cmd, &mut tx);
        let r = self.transport.exchange(&tx, &mut rx);
        let t_recv = t_recv.unwrap_or_else(|| self.now_us());
        match r {
            Ok(()) => {
                let frame = amr::decode_mcu_frame(&rx);
                self.bridge.on_frame(t_send, t_recv, cmd.seq, frame);
                Ok(self.bridge.drain())
            }
            Err(e) => {
                self.transport_errors = self.transport_errors.saturating_add(1);
                Err(e)
            }
        }
    }

    /// Runs for `duration`, calling `sink` with the diagnostics of each cycle.
    pub fn run_for(
        &mut self,
        duration: Duration,
        mut sink: impl FnMut(&[(u64, Diagnostic)]),
    ) -> Result<(), LinkError> {
        let end = Instant::now()
            .checked_add(duration)
            .unwrap_or_else(Instant::now);
        while Instant::now() < end {
            let d = self.cycle()?;
            if !d.is_empty() {
                sink(&d);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::bridge::BridgeConfig;
    use crate::transport::NullTransport;

    #[test]
    fn a_silent_device_is_reported_frozen() {
        // The null device answers zeros: every feedback fails its CRC, nothing ever advances.
        let mut l = Link::new(
            NullTransport {
                reply: vec![0; FRAME_LEN],
            },
            Bridge::new(BridgeConfig::DEFAULT),
        );
        l.bridge.arm(0);
        let mut names = Vec::new();
        l.run_for(Duration::from_millis(20), |d| {
            names.extend(d.iter().map(|(_, x)| x.name()));
        })
        .unwrap();
        assert!(names.contains(&"feedback_rejected"));
        assert!(names.contains(&"mcu_frozen"), "{names:?}");
    }

    #[test]
    fn an_info_frame_in_the_feedback_slot_reaches_the_bridge_as_info() {
        let info = amr::McuInfo {
            fw_version: amr::pack_fw_version(0, 3, 1),
            reset_cause: amr::ResetCause::PowerOn,
            ..Default::default()
        };
        let mut reply = [0u8; FRAME_LEN];
        amr::encode_info(&info, &mut reply);
        let mut l = Link::new(
            NullTransport {
                reply: reply.to_vec(),
            },
            Bridge::new(BridgeConfig::DEFAULT),
        );
        for _ in 0..3 {
            l.exchange().unwrap();
        }
        assert_eq!(l.bridge.mcu_info(), Some(info));
        assert_eq!(l.bridge.stats.info_frames, 3);
        assert_eq!(l.bridge.stats.feedback_rejected, 0);
    }
}

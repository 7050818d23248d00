//! The host as the simulator runs it: the real [`Bridge`] behind `sim::HostModel`, with frames
//! encoded and decoded by the `protocol` crate exactly as on the robot.

use protocol::amr::{self, FRAME_LEN};
use sim::scenario::Request;

use crate::bridge::{Bridge, BridgeConfig, Diagnostic};

/// A simulated host running the real bridge.
#[derive(Clone, Debug)]
pub struct SimHost {
    /// The bridge under test.
    pub bridge: Bridge,
    pending_seq: u32,
    /// Every diagnostic with its host time, µs (kept for inspection after a run).
    pub log: Vec<(u64, Diagnostic)>,
    undrained: Vec<String>,
}

impl SimHost {
    /// A host with the default bridge configuration.
    pub fn new() -> Self {
        Self::with_config(BridgeConfig::DEFAULT)
    }

    /// A host with `cfg`; like the real bridge at start-up, it first asks the MCU who it is.
    pub fn with_config(cfg: BridgeConfig) -> Self {
        let mut bridge = Bridge::new(cfg);
        bridge.request_identity();
        Self {
            bridge,
            pending_seq: 0,
            log: Vec::new(),
            undrained: Vec::new(),
        }
    }

    fn collect(&mut self) {
        for (t, d) in self.bridge.drain() {
            if !matches!(d, Diagnostic::Mode { .. }) {
                self.undrained.push(d.name().to_string());
            }
            self.log.push((t, d));
        }
    }
}

impl Default for SimHost {
    fn default() -> Self {
        Self::new()
    }
}

impl sim::HostModel for SimHost {
    fn cmd_vel(&mut self, host_us: u64, v: f64, w: f64) {
        self.bridge.cmd_vel(host_us, v, w);
    }

    fn request(&mut self, host_us: u64, request: Request) {
        match request {
            Request::Arm { .. } => self.bridge.arm(host_us),
            Request::Rearm { .. } => self.bridge.rearm(host_us),
            Request::Disarm { .. } => self.bridge.disarm(),
        }
    }

    fn begin_cycle(&mut self, host_us: u64, tx: &mut [u8; FRAME_LEN]) {
        let cmd = self.bridge.next_command(host_us);
        self.pending_seq = cmd.seq;
        amr::encode_command(&cmd, tx);
        self.collect();
    }

    fn end_cycle(&mut self, t_send_us: u64, t_recv_us: u64, rx: &[u8; FRAME_LEN]) {
        let frame = amr::decode_mcu_frame(rx);
        self.bridge
            .on_frame(t_send_us, t_recv_us, self.pending_seq, frame);
        self.collect();
    }

    fn mcu_to_host_us(&self, mcu_us: u64) -> (Option<f64>, Option<f64>) {
        let seed = (self.bridge.clock.mcu_to_host(mcu_us).is_some())
            .then(|| self.bridge.seed_clock.mcu_to_host(mcu_us));
        (self.bridge.clock.mcu_to_host(mcu_us), seed)
    }

    fn drain_diagnostics(&mut self) -> Vec<String> {
        core::mem::take(&mut self.undrained)
    }

    fn last_command(&self) -> [f32; 2] {
        let o = self.bridge.output();
        [o[0] as f32, o[1] as f32]
    }
}

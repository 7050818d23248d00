//! The interface between the simulator and a host implementation (the real one is
//! `motorlink::simhost::SimHost`), so the simulated host runs the same bridge code as the robot.

use crate::scenario::Request;
pub use protocol::amr::FRAME_LEN;

/// A host as the simulator drives it. Times are the host's own clock, µs.
pub trait HostModel {
    /// Nav2 published a velocity command.
    fn cmd_vel(&mut self, host_us: u64, v: f64, w: f64);
    /// The operator or the host software asks for something.
    fn request(&mut self, host_us: u64, request: Request);
    /// A link cycle starts: write the command frame to send.
    fn begin_cycle(&mut self, host_us: u64, tx: &mut [u8; FRAME_LEN]);
    /// The exchange started at `t_send_us` has completed at `t_recv_us`; `rx` is what came back.
    fn end_cycle(&mut self, t_send_us: u64, t_recv_us: u64, rx: &[u8; FRAME_LEN]);
    /// The host's estimate of its own clock at the moment the MCU clock read `mcu_us`
    /// (ours, and the seed's estimator for comparison).
    fn mcu_to_host_us(&self, mcu_us: u64) -> (Option<f64>, Option<f64>);
    /// Names of diagnostics raised since the last call (e.g. `mcu_frozen`, `brake_latched`).
    fn drain_diagnostics(&mut self) -> Vec<String>;
    /// The wheel speeds (left, right) the host last commanded, rad/s.
    fn last_command(&self) -> [f32; 2];
}

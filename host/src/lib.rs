//! Linux host side of the motor controller: byte transports (spidev, serial / USB CDC), the 1 kHz
//! bridge with absolute-deadline pacing, inverse kinematics, feedback validation, clock sync, and
//! the simulator's host model.
//!
//! All encoding is done by the `protocol` crate; the bridge is a pure state machine driven with
//! explicit times, so the simulator (`sim`) runs exactly this code against the simulated MCU.

pub mod bridge;
pub mod cli;
pub mod clocksync;
pub mod feedback;
pub mod kinematics;
pub mod link;
pub mod loopstats;
pub mod names;
pub mod pacing;
pub mod record;
pub mod ros;
pub mod rt;
pub mod serial;
pub mod simhost;
pub mod simlink;
pub mod transport;

pub use bridge::{ArmState, Bridge, BridgeConfig, Diagnostic};
pub use clocksync::{ClockSync, ClockSyncConfig};
pub use kinematics::{DiffDrive, DiffDriveConfig, GeometryError};
pub use simhost::SimHost;
pub use simlink::{SimClock, SimConfig, SimMcu, Truth};
pub use transport::{ByteStream, LinkError, Transport};

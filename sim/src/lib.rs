//! Software-in-the-loop simulator: the real `statemachine`, `protocol` and `control` code at their
//! firmware rates against two DC motors and a differential-drive robot, driven by a simulated host
//! with fault injection.
//!
//! Host-only code: indexing and arithmetic here are on fixed two-wheel arrays and floats of a
//! model, and a panic would be a simulator bug, never a robot fault; the MCU-path crates it drives
//! keep the workspace's strict lints.
#![allow(
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::needless_range_loop
)]

pub mod board;
pub mod host;
pub mod plant;
pub mod report;
pub mod rng;
pub mod runner;
pub mod scenario;
pub mod skid;
pub mod wire;

pub use host::HostModel;
pub use runner::{run, RunOptions, RunResult, Summary};
pub use scenario::{Fault, Request, Scenario};

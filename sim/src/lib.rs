//! Software-in-the-loop simulator: the real `statemachine`, `protocol` and `control` code at their
//! firmware rates, through the board application's task bodies (`mcu`), driven by a simulated host
//! with fault injection. Four boards: seed 000 (SPI, two DC motors and a differential-drive robot:
//! [`board`], [`runner`]), seed 001 (USB CDC / UART, four PWM motors on a skid-steer robot:
//! [`cdc`], [`skid`]), seed 003 (UART, a four-joint stepper arm: [`teensy`]) and seed 004 (the
//! Raspberry Pi's SPI buffers, four encoder motors on the skid-steer robot and four servos:
//! [`pi_spi`]); the scenario's `profile` chooses. What every run measures the same way is in
//! [`measure`]; what the two serial boards' runs share (the line, the host's frames, the re-arm
//! rule) in [`serial`].
//!
//! Host-only code: indexing and arithmetic here are on fixed wheel, motor and joint arrays and
//! floats of a model, and a panic would be a simulator bug, never a robot fault; the MCU-path
//! crates it drives keep the workspace's strict lints.
#![allow(
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::needless_range_loop
)]

pub mod board;
pub mod cdc;
pub mod host;
pub mod measure;
pub mod pi_spi;
pub mod plant;
pub mod plot;
pub mod report;
pub mod rng;
pub mod runner;
pub mod scenario;
pub mod serial;
pub mod skid;
pub mod teensy;
pub mod wire;

pub use host::HostModel;
pub use runner::{run, RunOptions, RunResult, Summary};
pub use scenario::{Fault, Profile, Request, Scenario};

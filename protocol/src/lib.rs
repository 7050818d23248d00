//! Every wire format of the robot's links, turned into typed messages or typed errors, never a panic.
//!
//! | module      | link (seed)                               | integrity                      |
//! |-------------|-------------------------------------------|--------------------------------|
//! | [`amr`]     | Jetson ↔ STM32 SPI, 1 kHz (seed 000)      | CRC-16, version, sequence      |
//! | [`cdc`]     | Jetson ↔ STM32 USB CDC / UART (seed 001)  | SOF + CRC-16, streaming resync |
//! | [`pi_spi`]  | Raspberry Pi ↔ STM32 SPI (seed 004)       | version byte + parity bit      |
//! | [`teensy`]  | Jetson ↔ Teensy serial (seed 003)         | legacy `\n`; COBS, CRC-16 of it |
//!
//! Each link decodes into the same domain types of the safety core: commands become
//! [`statemachine::Command`] (or another [`statemachine::Event`]), failures become
//! [`statemachine::RejectReason`], so the ladder does not care which link delivered a command.
//! Frame layouts are drawn byte by byte in each module's documentation and in `protocol/README.md`.
//!
//! Every decoder is total: for every input it returns `Ok` or a typed error. The harnesses in each
//! module's `verification` submodule state this (and round-trips, and bit-flip detection); each is a
//! Kani proof and a `cargo test` twin. `tests/fuzz.rs` fuzzes every decoder with bolero.
//!
//! Feature `serde` (no_std, no alloc) derives `Serialize`/`Deserialize` on the plain message structs
//! (missing fields default to zero, unknown fields are refused); the host tools use it for JSON.
//! Types holding `statemachine` enums or const-generic arrays (`cdc::Message`, `teensy::CmdMsg`)
//! are converted by hand on the host.
#![no_std]
// No unsafe code in any build of the crate; the one exception is the Kani-only stand-in
// `crc16::verification::model::uninterpreted_checksum` (its memory of earlier answers), which
// exists only under `cfg(kani)` and allows it locally.
#![cfg_attr(not(kani), forbid(unsafe_code))]
#![cfg_attr(kani, deny(unsafe_code))]
// Loop contracts are attributes on statements.
#![cfg_attr(kani_loop_contracts, feature(stmt_expr_attributes, proc_macro_hygiene))]
#![cfg_attr(
    test,
    allow(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::indexing_slicing,
        clippy::arithmetic_side_effects,
        clippy::panic
    )
)]

#[cfg(test)]
#[macro_use]
extern crate std;

pub mod amr;
pub mod cdc;
pub mod crc16;
mod le;
mod pb;
pub mod pi_spi;
pub mod teensy;

use statemachine::{Event, RejectReason};

/// The ladder event for a decode result: the command if it decoded, `Rejected(reason)` if not.
pub fn event_from<const N: usize>(
    result: Result<statemachine::Command<N>, RejectReason>,
) -> Event<N> {
    match result {
        Ok(cmd) => Event::Frame(cmd),
        Err(reason) => Event::Rejected(reason),
    }
}

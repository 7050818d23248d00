//! Board support shared by every image of the motor controller: the pin maps, clocks and
//! register-level drivers of each board (`board`), the panic handler and reset record (`panic`),
//! and the build identity. Each image (`src/main.rs` for `amr-spi`, `src/bin/*.rs` for the
//! others) is an RTIC app that binds interrupts to the board application of its link profile
//! (crate `mcu`) through these modules.
#![no_std]
#![deny(unsafe_code)]

pub mod board;
pub mod panic;

/// Build identity from `build.rs`: commit, dirty flag, date.
pub mod build {
    include!(concat!(env!("OUT_DIR"), "/identity.rs"));
}

use defmt_rtt as _;

#[cfg(all(feature = "usb", feature = "qemu"))]
compile_error!("QEMU's netduinoplus2 has no USB model: build the `usb` variant for the board only");

//! The serial link of the `cdc` (UART variant) and `teensy` images: USART1 on PA9 (TX) / PA10 (RX),
//! 115 200 baud 8N1, one interrupt for both directions.
//!
//! ```text
//!  USART1 IRQ ─► link_usart (priority 2)
//!     RXNE: read SR then DR (clears RXNE, and ORE if set) ─► the profile's on_byte, byte by byte
//!     TXE : next queued byte ─► DR; TXEIE stays on only while bytes wait
//! ```
//!
//! Reception is interrupt-driven one byte at a time: at 115 200 baud a byte arrives every 87 µs,
//! far longer than the decoder's per-byte work. An overrun (a byte lost because the previous one
//! was not read in time) is counted ([`Uart::overruns`]); the frame it broke fails its CRC and is
//! refused like any other.

use super::regs::*;
use super::PCLK2_HZ;
use stm32f4xx_hal::pac;
use stm32f4xx_hal::rcc::{Enable, Reset};

/// Link baud rate.
pub const BAUD: u32 = 115_200;
/// BRR for [`BAUD`] at oversampling 16: PCLK2 / baud, rounded (mantissa and 4-bit fraction
/// together are the divider in sixteenths).
pub const BRR: u16 = {
    let d = (PCLK2_HZ + BAUD / 2) / BAUD;
    assert!(d <= 0xFFFF, "baud divider out of range");
    d as u16
};
// The rounded divider is within 0.5 % of the wanted rate (84 MHz: 0.02 %, 16 MHz: 0.08 %).
const _: () = assert!((PCLK2_HZ / BRR as u32).abs_diff(BAUD) * 200 < BAUD);

const SR_ORE: u16 = 1 << 3;
const SR_RXNE: u16 = 1 << 5;
const SR_TXE: u16 = 1 << 7;
const CR1_RE: u16 = 1 << 2;
const CR1_TE: u16 = 1 << 3;
const CR1_RXNEIE: u16 = 1 << 5;
const CR1_TXEIE: u16 = 1 << 7;
const CR1_UE: u16 = 1 << 13;

/// USART1 as the link: owns the peripheral; the pins are set to AF7 by the board's init.
pub struct Uart {
    usart: pac::USART1,
    overruns: u32,
}

impl Uart {
    /// Enables and configures USART1 (8N1, [`BAUD`]) with the receive interrupt on.
    pub fn new(usart: pac::USART1, rcc: &mut pac::RCC) -> Self {
        pac::USART1::enable(rcc);
        pac::USART1::reset(rcc);
        wr16(usart.brr(), BRR);
        wr16(usart.cr1(), CR1_UE | CR1_TE | CR1_RE | CR1_RXNEIE);
        Self { usart, overruns: 0 }
    }

    /// The next received byte, if one is waiting. Reading SR then DR clears RXNE and ORE.
    pub fn read(&mut self) -> Option<u8> {
        let sr = self.usart.sr().read().bits();
        if sr & SR_ORE != 0 {
            self.overruns = self.overruns.saturating_add(1);
        }
        if sr & (SR_RXNE | SR_ORE) == 0 {
            return None;
        }
        let byte = (self.usart.dr().read().bits() & 0xFF) as u8;
        (sr & SR_RXNE != 0).then_some(byte)
    }

    /// Sends what the transmitter takes now from `q`, then leaves the TXE interrupt on only if
    /// bytes still wait.
    pub fn pump<const CAP: usize>(&mut self, q: &mut mcu::serial::TxQueue<CAP>) {
        while self.usart.sr().read().bits() & SR_TXE != 0 {
            let Some(b) = q.pop() else { break };
            wr16(self.usart.dr(), u16::from(b));
        }
        if q.is_empty() {
            rmw16(self.usart.cr1(), CR1_TXEIE, 0);
        } else {
            rmw16(self.usart.cr1(), 0, CR1_TXEIE);
        }
    }

    /// Receive overruns since boot (saturating).
    pub const fn overruns(&self) -> u32 {
        self.overruns
    }
}

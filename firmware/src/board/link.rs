//! The seed 000 link: SPI2 slave with circular double-buffered DMA, one frame per transaction.

use super::regs::*;
use super::FRAME_LEN;
use stm32f4xx_hal::pac;
use stm32f4xx_hal::rcc::{Enable, Reset};

/// SPI2 slave with circular, double-buffered DMA: one [`FRAME_LEN`]-byte transaction per frame.
///
/// ```text
///  DMA1 stream 3 (RX, ch 0): SPI2 DR → rx[0] / rx[1]  alternately (DBM), transfer-complete IRQ
///  DMA1 stream 4 (TX, ch 0): tx[0] / tx[1] → SPI2 DR  alternately (DBM)
///  at TC: rx[1 − CT] holds the frame just received; tx[1 − CT] is free for the next feedback
/// ```
///
/// A byte slip (a glitch on SCK) shifts every following frame; each then fails its CRC, the
/// ladder brakes on comm loss after 10 ticks, and only a reset resynchronises (fail-safe, not
/// fail-operational; see proofs/SAFETY.md §7, F7).
pub struct SpiLink {
    dma: pac::DMA1,
    _spi: pac::SPI2,
    rx: *mut [[u8; FRAME_LEN]; 2],
    tx: *mut [[u8; FRAME_LEN]; 2],
}

// SAFETY: `SpiLink` is moved once, from `init` into the one task that owns it; the raw pointers
// address 'static buffers that only that task and the DMA engine touch.
unsafe impl Send for SpiLink {}

const DMA_CR_EN: u32 = 1;
const DMA_CR_TEIE: u32 = 1 << 2;
const DMA_CR_TCIE: u32 = 1 << 4;
const DMA_CR_DIR_M2P: u32 = 0b01 << 6;
const DMA_CR_CIRC: u32 = 1 << 8;
const DMA_CR_MINC: u32 = 1 << 10;
const DMA_CR_PL_VERY_HIGH: u32 = 0b11 << 16;
const DMA_CR_DBM: u32 = 1 << 18;
const DMA_CR_CT: u32 = 1 << 19;
/// All stream-3 flags in LISR/LIFCR (FEIF3, DMEIF3, TEIF3, HTIF3, TCIF3).
const DMA_S3_FLAGS: u32 = 0x0F40_0000;
const DMA_S3_TEIF: u32 = 1 << 25;
/// All stream-4 flags in HISR/HIFCR.
const DMA_S4_FLAGS: u32 = 0x3D;

impl SpiLink {
    /// Configures SPI2 as a mode-0 slave and both DMA streams; starts listening.
    pub fn new(
        spi: pac::SPI2,
        dma: pac::DMA1,
        rx: &'static mut [[u8; FRAME_LEN]; 2],
        tx: &'static mut [[u8; FRAME_LEN]; 2],
        rcc: &mut pac::RCC,
    ) -> Self {
        pac::SPI2::enable(rcc);
        pac::SPI2::reset(rcc);
        pac::DMA1::enable(rcc);
        let dr = spi.dr().as_ptr() as u32;
        let rx: *mut [[u8; FRAME_LEN]; 2] = rx;
        let tx: *mut [[u8; FRAME_LEN]; 2] = tx;
        let addr = |p: *mut [[u8; FRAME_LEN]; 2], i: usize| -> u32 {
            p.cast::<u8>().wrapping_add(i.wrapping_mul(FRAME_LEN)) as u32
        };
        let len = FRAME_LEN as u32;
        let rx_s = dma.st(3);
        wr(rx_s.par(), dr);
        wr(rx_s.m0ar(), addr(rx, 0));
        wr(rx_s.m1ar(), addr(rx, 1));
        wr(rx_s.ndtr(), len);
        wr(
            rx_s.cr(),
            DMA_CR_DBM
                | DMA_CR_PL_VERY_HIGH
                | DMA_CR_MINC
                | DMA_CR_CIRC
                | DMA_CR_TCIE
                | DMA_CR_TEIE,
        );
        let tx_s = dma.st(4);
        wr(tx_s.par(), dr);
        wr(tx_s.m0ar(), addr(tx, 0));
        wr(tx_s.m1ar(), addr(tx, 1));
        wr(tx_s.ndtr(), len);
        wr(
            tx_s.cr(),
            DMA_CR_DBM | DMA_CR_PL_VERY_HIGH | DMA_CR_MINC | DMA_CR_CIRC | DMA_CR_DIR_M2P,
        );
        wr(dma.lifcr(), DMA_S3_FLAGS);
        wr(dma.hifcr(), DMA_S4_FLAGS);
        rmw(rx_s.cr(), 0, DMA_CR_EN);
        rmw(tx_s.cr(), 0, DMA_CR_EN);
        wr16(spi.cr2(), 0b11); // RXDMAEN | TXDMAEN
        wr16(spi.cr1(), 1 << 6); // SPE; slave, CPOL = CPHA = 0, 8 bit, MSB first, hardware NSS
        Self {
            dma,
            _spi: spi,
            rx,
            tx,
        }
    }

    /// Handles the transfer-complete interrupt: copies out the frame just received and returns it,
    /// or `None` after a transfer error (the stream is restarted and the frame is lost).
    pub fn take_rx(&mut self) -> Option<[u8; FRAME_LEN]> {
        let flags = self.dma.lisr().read().bits();
        wr(self.dma.lifcr(), DMA_S3_FLAGS);
        if flags & DMA_S3_TEIF != 0 {
            rmw(self.dma.st(3).cr(), 0, DMA_CR_EN);
            return None;
        }
        let ct = self.dma.st(3).cr().read().bits() & DMA_CR_CT != 0;
        let done = usize::from(!ct);
        // SAFETY: `rx` points to two 'static buffers; the DMA now writes buffer `ct`, so buffer
        // `done` is stable until the next transaction completes (≥ 256 µs away at 2 MHz, far
        // longer than this copy). The read is volatile because the DMA engine wrote it.
        let frame =
            unsafe { core::ptr::read_volatile(self.rx.cast::<[u8; FRAME_LEN]>().add(done)) };
        Some(frame)
    }

    /// Writes the feedback frame into the TX buffer the DMA is not sending.
    pub fn put_tx(&mut self, frame: &[u8; FRAME_LEN]) {
        let ct = self.dma.st(4).cr().read().bits() & DMA_CR_CT != 0;
        let idle = usize::from(!ct);
        // SAFETY: as in `take_rx`: buffer `idle` is not the DMA's current target.
        unsafe { core::ptr::write_volatile(self.tx.cast::<[u8; FRAME_LEN]>().add(idle), *frame) };
    }
}

//! The SPI links (seed 000: one `FRAME_LEN`-byte frame per transaction; seed 004: one
//! `TRANSFER_LEN`-byte exchange): SPI2 slave with circular double-buffered DMA.

use super::regs::*;
use stm32f4xx_hal::pac;
use stm32f4xx_hal::rcc::Enable;

/// SPI2 slave with circular, double-buffered DMA: one `N`-byte transaction per frame
/// (`N` = [`super::FRAME_LEN`] for seed 000, `protocol::pi_spi::TRANSFER_LEN` for seed 004).
///
/// ```text
///  DMA1 stream 3 (RX, ch 0): SPI2 DR → rx[0] / rx[1]  alternately (DBM), transfer-complete IRQ
///  DMA1 stream 4 (TX, ch 0): tx[0] / tx[1] → SPI2 DR  alternately (DBM)
///  at TC: rx[1 − CT] holds the frame just received; tx[1 − CT] is free for the next feedback
/// ```
///
/// A transaction cut short (NSS released early, or a lost SCK edge) would shift every following
/// frame; the NSS rising edge (EXTI12) checks the receive count and re-arms the link at a frame
/// boundary ([`SpiLink::resync_if_cut`]), so only the cut frame is lost (counted as a framing
/// refusal).
pub struct SpiLink<const N: usize> {
    dma: pac::DMA1,
    spi: pac::SPI2,
    rx: *mut [[u8; N]; 2],
    tx: *mut [[u8; N]; 2],
}

// SAFETY: `SpiLink` is moved once, from `init` into a resource of the two priority-2 link tasks,
// which never preempt each other; the raw pointers address 'static buffers that only those tasks
// and the DMA engine touch.
unsafe impl<const N: usize> Send for SpiLink<N> {}

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

impl<const N: usize> SpiLink<N> {
    /// `N` must fit the DMA stream's 16-bit transfer count (NDTR); checked when `new` is compiled.
    const LEN_FITS_NDTR: () = assert!(N >= 1 && N <= 0xFFFF);

    /// Configures SPI2 as a mode-0 slave and both DMA streams; starts listening.
    pub fn new(
        spi: pac::SPI2,
        dma: pac::DMA1,
        rx: &'static mut [[u8; N]; 2],
        tx: &'static mut [[u8; N]; 2],
        rcc: &mut pac::RCC,
    ) -> Self {
        let () = Self::LEN_FITS_NDTR;
        pac::SPI2::enable(rcc);
        pac::DMA1::enable(rcc);
        let l = Self { dma, spi, rx, tx };
        l.arm();
        l
    }

    /// (Re)starts the link from a clean state: SPI2 reset through RCC (no half-shifted byte
    /// survives), both streams stopped, pointed at the start of buffer 0 with a full frame to go,
    /// flags cleared, then re-enabled. Called at start-up and after a cut-short transaction.
    fn arm(&self) {
        let dma = &self.dma;
        let (rx_s, tx_s) = (dma.st(3), dma.st(4));
        for st in [rx_s, tx_s] {
            rmw(st.cr(), DMA_CR_EN, 0);
            // EN reads 1 until the stream has finished its current beat (a few bus cycles).
            for _ in 0..1000u32 {
                if st.cr().read().bits() & DMA_CR_EN == 0 {
                    break;
                }
            }
        }
        // SAFETY: RCC APB1RSTR bit SPI2RST pulses the SPI2 reset; no other bit is touched and
        // nothing else writes APB1RSTR after init.
        let rcc = unsafe { &*pac::RCC::ptr() };
        rmw(rcc.apb1rstr(), 0, 1 << 14);
        rmw(rcc.apb1rstr(), 1 << 14, 0);
        let spi = &self.spi;
        let dr = spi.dr().as_ptr() as u32;
        let addr = |p: *mut [[u8; N]; 2], i: usize| -> u32 {
            p.cast::<u8>().wrapping_add(i.wrapping_mul(N)) as u32
        };
        let len = N as u32;
        wr(rx_s.par(), dr);
        wr(rx_s.m0ar(), addr(self.rx, 0));
        wr(rx_s.m1ar(), addr(self.rx, 1));
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
        wr(tx_s.par(), dr);
        wr(tx_s.m0ar(), addr(self.tx, 0));
        wr(tx_s.m1ar(), addr(self.tx, 1));
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
    }

    /// Called at the rising edge of NSS (end of a transaction): if the receive stream is not at a
    /// frame boundary, the transaction was cut short; the link is re-armed so the next
    /// transaction lands at the start of a buffer instead of shifting every later frame.
    /// Returns true if it resynchronised.
    ///
    /// ```text
    ///  NSS   ‾‾\____________________/‾‾‾   complete frame: TC ran first (lower IRQ number),
    ///  NDTR     N … 1 → reload N    ↑      NDTR = N at the edge: nothing to do
    ///  NSS   ‾‾\________/‾‾‾               cut short: NDTR = N − k at the edge → re-arm
    /// ```
    pub fn resync_if_cut(&mut self) -> bool {
        let left = self.dma.st(3).ndtr().read().bits() & 0xFFFF;
        if left == N as u32 {
            return false;
        }
        self.arm();
        true
    }

    /// Handles the transfer-complete interrupt: copies out the frame just received and returns it,
    /// or `None` after a transfer error (the stream is restarted and the frame is lost).
    pub fn take_rx(&mut self) -> Option<[u8; N]> {
        let flags = self.dma.lisr().read().bits();
        wr(self.dma.lifcr(), DMA_S3_FLAGS);
        if flags & DMA_S3_TEIF != 0 {
            rmw(self.dma.st(3).cr(), 0, DMA_CR_EN);
            return None;
        }
        let ct = self.dma.st(3).cr().read().bits() & DMA_CR_CT != 0;
        let done = usize::from(!ct);
        // SAFETY: `rx` points to two 'static buffers; the DMA now writes buffer `ct`, so buffer
        // `done` is stable until the next transaction completes (N bytes away: ≥ 256 µs for 64
        // bytes at 2 MHz, far longer than this copy). The read is volatile because the DMA engine
        // wrote it.
        let frame = unsafe { core::ptr::read_volatile(self.rx.cast::<[u8; N]>().add(done)) };
        Some(frame)
    }

    /// Writes the feedback frame into the TX buffer the DMA is not sending.
    pub fn put_tx(&mut self, frame: &[u8; N]) {
        let ct = self.dma.st(4).cr().read().bits() & DMA_CR_CT != 0;
        let idle = usize::from(!ct);
        // SAFETY: as in `take_rx`: buffer `idle` is not the DMA's current target.
        unsafe { core::ptr::write_volatile(self.tx.cast::<[u8; N]>().add(idle), *frame) };
    }
}

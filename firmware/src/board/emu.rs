//! Emulator support (feature `qemu`): QEMU's `netduinoplus2` models neither SPI slave mode, DMA nor
//! the ADC trigger, so the link is a pair of host files read and written by semihosting, the
//! speed loop pends the current loop, and the tick pends the link task and prints a trace line.
//!
//! Seed 000 (`EmuLink<FRAME_LEN>`), in QEMU's working directory: [`FRAMES_FILE`] (`frames.bin`),
//! one record per watchdog tick, `tag (1 byte) ‖ frame (FRAME_LEN bytes)`; tag 1 = a transaction
//! carrying that frame, tag 0 = no transaction in this tick. End of file = the host stopped
//! sending. [`FEEDBACK_FILE`] (`feedback.bin`): every feedback frame the firmware wrote for the
//! next transaction, in order (what the host would have clocked out on MISO).
//!
//! Seed 004 (`EmuLink<TRANSFER_LEN>`): the same record format with `TRANSFER_LEN`-byte transfers,
//! in [`PI_SPI_TRANSFERS_FILE`] and [`PI_SPI_FEEDBACK_FILE`].
use super::FRAME_LEN;
use core::fmt::Write;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use cortex_m_semihosting::{debug, hio, syscall};
use protocol::pi_spi::TRANSFER_LEN;
use statemachine::Drive;

type Output = statemachine::Output<{ mcu::AXES }>;
use stm32f4xx_hal::pac;

/// Ticks to keep tracing after the file ended and BRAKE latched, before exiting QEMU.
const TAIL_TICKS: u32 = 15;

/// Set once `frames.bin` has ended.
static ENDED: AtomicBool = AtomicBool::new(false);
/// The tick at which the file had ended with BRAKE held (0 = not yet).
static ENDED_AT: AtomicU32 = AtomicU32::new(0);

fn open(name: &[u8], mode: usize) -> Option<usize> {
    // SAFETY: SYS_OPEN reads the NUL-terminated name (length excludes the NUL) and returns a
    // handle or -1. No memory is written.
    let fd = unsafe { syscall!(OPEN, name.as_ptr(), mode, name.len().saturating_sub(1)) };
    (fd != usize::MAX).then_some(fd)
}

/// Seed 000's frames from the host, NUL-terminated for SYS_OPEN.
pub const FRAMES_FILE: &[u8] = b"frames.bin\0";
/// Seed 000's feedback frames to the host.
pub const FEEDBACK_FILE: &[u8] = b"feedback.bin\0";
/// Seed 004's transfers from the host (Pi → STM32 `RxBuffer`s), NUL-terminated for SYS_OPEN.
pub const PI_SPI_TRANSFERS_FILE: &[u8] = b"pi_spi_transfers.bin\0";
/// Seed 004's transfers to the host (the `TxBuffer`s the firmware queued).
pub const PI_SPI_FEEDBACK_FILE: &[u8] = b"pi_spi_feedback.bin\0";

/// The emulated link of an `N`-byte transaction: records in from a host file, what the firmware
/// queued for the next transaction out to another.
pub struct EmuLink<const N: usize> {
    rx: Option<usize>,
    tx: Option<usize>,
}

impl EmuLink<FRAME_LEN> {
    /// Opens [`FRAMES_FILE`] and [`FEEDBACK_FILE`] (the peripherals are taken so the board init is
    /// the same as on the board).
    pub fn new(
        _spi: pac::SPI2,
        _dma: pac::DMA1,
        _rx: &'static mut [[u8; FRAME_LEN]; 2],
        _tx: &'static mut [[u8; FRAME_LEN]; 2],
        _rcc: &mut pac::RCC,
    ) -> Self {
        Self::open_files(FRAMES_FILE, FEEDBACK_FILE)
    }
}

impl EmuLink<TRANSFER_LEN> {
    /// Opens [`PI_SPI_TRANSFERS_FILE`] and [`PI_SPI_FEEDBACK_FILE`] (the peripherals are taken so
    /// the board init is the same as on the board).
    pub fn new(
        _spi: pac::SPI2,
        _dma: pac::DMA1,
        _rx: &'static mut [[u8; TRANSFER_LEN]; 2],
        _tx: &'static mut [[u8; TRANSFER_LEN]; 2],
        _rcc: &mut pac::RCC,
    ) -> Self {
        Self::open_files(PI_SPI_TRANSFERS_FILE, PI_SPI_FEEDBACK_FILE)
    }
}

impl<const N: usize> EmuLink<N> {
    fn open_files(rx: &[u8], tx: &[u8]) -> Self {
        Self {
            rx: open(rx, 1), // "rb"
            tx: open(tx, 5), // "wb"
        }
    }

    /// The next transaction's frame, `None` for a tick without one or after the end of the file.
    pub fn take_rx(&mut self) -> Option<[u8; N]> {
        let fd = self.rx?;
        // One record: the tag, then the N bytes that follow it whatever the tag (stable Rust has
        // no `[u8; 1 + N]`, so the two parts are read one after the other).
        let mut tag = [0u8; 1];
        let mut frame = [0u8; N];
        // SAFETY (both calls): SYS_READ writes at most the given length into the given buffer
        // and returns how many bytes it did not read (0 = all). The body is read only after a
        // whole tag.
        let short = unsafe { syscall!(READ, fd, tag.as_mut_ptr(), tag.len()) } != 0
            || unsafe { syscall!(READ, fd, frame.as_mut_ptr(), frame.len()) } != 0;
        if short {
            self.rx = None;
            ENDED.store(true, Ordering::Relaxed);
            return None;
        }
        (tag == [1]).then_some(frame)
    }

    /// The emulated link has no chip select: never cut short.
    pub fn resync_if_cut(&mut self) -> bool {
        false
    }

    /// Appends the feedback frame to the feedback file.
    pub fn put_tx(&mut self, frame: &[u8; N]) {
        if let Some(fd) = self.tx {
            // SAFETY: SYS_WRITE reads `frame.len()` bytes from `frame`; nothing is written.
            let _ = unsafe { syscall!(WRITE, fd, frame.as_ptr(), frame.len()) };
        }
    }
}

/// The emulator's stand-ins for the hardware triggers.
pub mod hooks {
    use super::*;

    /// The emulator has no ADC trigger: run the current loop once per speed sample.
    pub fn after_speed_sample() {
        rtic::pend(pac::Interrupt::ADC);
    }

    /// Prints one trace line, pends the link task (one transaction per tick from the host file),
    /// and exits QEMU a few ticks after the file ended and BRAKE latched.
    pub fn after_tick(tick: u32, out: &Output, safety: &mcu::Safety) {
        let [l, r] = out.drive.speeds().unwrap_or([statemachine::Speed::ZERO; 2]);
        let c = safety.ladder().counters();
        if let Ok(mut o) = hio::hstdout() {
            let _ = writeln!(
                o,
                "tick={} mode={:?} age={} drive={} left={} right={} valid={} rejected={} faults={:#06x}",
                tick,
                out.mode,
                out.age,
                if matches!(out.drive, Drive::Brake) { "BRAKE" } else { "RUN" },
                l,
                r,
                c.valid_frames,
                c.rejected_total(),
                out.faults.0,
            );
        }
        rtic::pend(pac::Interrupt::DMA1_STREAM3);
        exit_when_done(tick, matches!(out.drive, Drive::Brake));
    }

    /// Exits QEMU [`TAIL_TICKS`] ticks after the host file ended with `braked` held (every
    /// emulated SPI image).
    pub fn exit_when_done(tick: u32, braked: bool) {
        if !ENDED.load(Ordering::Relaxed) || !braked {
            ENDED_AT.store(0, Ordering::Relaxed);
            return;
        }
        let since = match ENDED_AT.load(Ordering::Relaxed) {
            0 => {
                ENDED_AT.store(tick, Ordering::Relaxed);
                tick
            }
            t => t,
        };
        if tick.wrapping_sub(since) >= TAIL_TICKS {
            debug::exit(debug::EXIT_SUCCESS);
        }
    }
}

//! Emulator support (feature `qemu`): link frames from a host file and a per-tick trace, both
//! through semihosting, so QEMU's `netduinoplus2` (no SPI/DMA model) runs the real tasks.
//!
//! File `frames.bin` in QEMU's working directory: one record per watchdog tick,
//! `tag (1 byte) ‖ frame (FRAME_LEN bytes)`; tag 1 = a transaction carrying that frame, tag 0 = no
//! transaction in this tick. End of file = the host stopped sending.

/// Without the `qemu` feature the emulator support is an empty placeholder.
#[cfg(not(feature = "qemu"))]
pub struct Emu;

#[cfg(not(feature = "qemu"))]
impl Emu {
    /// Nothing to open on the board.
    pub fn open() -> Self {
        Self
    }
}

#[cfg(feature = "qemu")]
pub use imp::*;

#[cfg(feature = "qemu")]
#[allow(unsafe_code)]
mod imp {
    use crate::board::FRAME_LEN;
    use core::fmt::Write;
    use cortex_m_semihosting::{debug, hio, syscall};
    use statemachine::{Drive, Ladder, Output};

    /// Ticks to keep tracing after the file ended and BRAKE latched, before exiting QEMU.
    const TAIL_TICKS: u32 = 15;

    /// The open frame file.
    pub struct Emu {
        fd: Option<usize>,
        ended_at: Option<u32>,
    }

    impl Emu {
        /// Opens `frames.bin` for reading (binary). A missing file means no frames at all.
        pub fn open() -> Self {
            let name = b"frames.bin\0";
            // SAFETY: SYS_OPEN reads the NUL-terminated name (length excludes the NUL) and returns a
            // handle or -1; mode 1 = "rb". No memory is written.
            let fd = unsafe { syscall!(OPEN, name.as_ptr(), 1, name.len().saturating_sub(1)) };
            Self {
                fd: (fd != usize::MAX).then_some(fd),
                ended_at: None,
            }
        }

        /// The next transaction's frame, `None` for a tick without one or after the end of the file.
        pub fn next_frame(&mut self) -> Option<[u8; FRAME_LEN]> {
            let fd = self.fd?;
            let mut rec = [0u8; 1 + FRAME_LEN];
            // SAFETY: SYS_READ writes at most `rec.len()` bytes into `rec` and returns how many it
            // did not read (0 = all).
            let left = unsafe { syscall!(READ, fd, rec.as_mut_ptr(), rec.len()) };
            if left != 0 {
                self.fd = None;
                return None;
            }
            let (tag, body) = rec.split_first()?;
            if *tag != 1 {
                return None;
            }
            let mut frame = [0u8; FRAME_LEN];
            frame.copy_from_slice(body);
            Some(frame)
        }

        /// True once the file has ended.
        pub fn ended(&self) -> bool {
            self.fd.is_none()
        }
    }

    /// Prints one trace line per tick and exits QEMU a few ticks after the link stopped and BRAKE latched.
    pub fn trace(tick: u32, out: &Output, ladder: &Ladder) {
        let (l, r) = match out.drive {
            Drive::Run { left, right } => (left, right),
            Drive::Brake => (statemachine::Speed::ZERO, statemachine::Speed::ZERO),
        };
        let c = ladder.counters();
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
    }

    /// Called by the tick after tracing: exits once the file ended and BRAKE has been held a while.
    pub fn maybe_exit(emu: &mut Emu, tick: u32, out: &Output) {
        if !emu.ended() || !matches!(out.drive, Drive::Brake) {
            emu.ended_at = None;
            return;
        }
        let since = *emu.ended_at.get_or_insert(tick);
        if tick.wrapping_sub(since) >= TAIL_TICKS {
            debug::exit(debug::EXIT_SUCCESS);
        }
    }
}

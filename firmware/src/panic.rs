//! What a panic does on the board: the bridges are braked first (from any context, without their
//! owner), the location is kept in RAM that survives the reset, then the MCU resets. At the next
//! boot [`boot`] reads the reset flags and that record, and counts the resets since power-on.

use core::mem::MaybeUninit;
use core::panic::PanicInfo;
use core::ptr::{addr_of, addr_of_mut};
use protocol::amr::ResetCause;

/// Marks a valid panic record ("PANC").
const MAGIC: u32 = 0x5041_4E43;
/// Marks a valid reset counter ("RSTC").
const COUNT_MAGIC: u32 = 0x5253_5443;

/// The record that survives a reset: panic magic, panic line, counter magic, resets since
/// power-on. In `.uninit`, which start-up does not clear; after a power-on its content is random,
/// so the magic words and the power-on flag decide what is believed.
#[allow(unsafe_code)] // a link section: the record must sit in RAM the reset leaves alone
#[link_section = ".uninit.RESET"]
static mut RECORD: MaybeUninit<[u32; 4]> = MaybeUninit::uninit();

/// Why the MCU last started, as the identity frame reports it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Boot {
    /// The reset cause.
    pub cause: ResetCause,
    /// Source line of the panic that caused it (0 if none).
    pub panic_line: u32,
    /// Resets since power-on.
    pub count: u32,
}

/// Reads and clears the reset flags (RCC_CSR) and the panic record, counts the reset.
#[allow(unsafe_code)]
pub fn boot(rcc: &stm32f4xx_hal::pac::RCC) -> Boot {
    let csr = rcc.csr().read().bits();
    // RMVF: clear the flags for the next boot.
    rcc.csr().modify(|_, w| w.rmvf().set_bit());
    // SAFETY: read once at boot, before any interrupt is enabled; the panic handler (the only
    // other writer) cannot run concurrently.
    let [magic, line, count_magic, count] =
        unsafe { addr_of!(RECORD).cast::<[u32; 4]>().read_volatile() };
    let panicked = magic == MAGIC;
    let cause = mcu::boot::reset_cause(csr, panicked);
    let count = match cause {
        ResetCause::PowerOn | ResetCause::Brownout => 0,
        _ if count_magic == COUNT_MAGIC => count.saturating_add(1),
        _ => 0,
    };
    // SAFETY: as above.
    unsafe {
        addr_of_mut!(RECORD)
            .cast::<[u32; 4]>()
            .write_volatile([0, 0, COUNT_MAGIC, count])
    };
    Boot {
        cause,
        panic_line: if panicked && cause == ResetCause::Panic {
            line
        } else {
            0
        },
        count,
    }
}

#[panic_handler]
#[allow(unsafe_code)]
fn panic(info: &PanicInfo) -> ! {
    cortex_m::interrupt::disable();
    crate::board::bridge::emergency_brake();
    let line = info.location().map_or(0, |l| l.line());
    // SAFETY: interrupts are off and this handler does not return: nothing else touches RECORD.
    unsafe {
        addr_of_mut!(RECORD)
            .cast::<[u32; 2]>()
            .write_volatile([MAGIC, line])
    };
    // No defmt here: the panic may have interrupted code that holds the logger, and a nested
    // log would panic again. The line is reported after the reset (identity frame, boot log).
    // Under the emulator a panic ends the run as a failure instead of a reset loop.
    #[cfg(feature = "qemu")]
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_FAILURE);
    cortex_m::peripheral::SCB::sys_reset()
}

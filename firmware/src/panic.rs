//! What a panic does on the board: the bridges are braked first (from any context, without their
//! owner), the location is kept in RAM that survives the reset, then the MCU resets. At the next
//! boot [`reset_cause`] reads the reset flags and that record.

use core::mem::MaybeUninit;
use core::panic::PanicInfo;
use core::ptr::{addr_of, addr_of_mut};

/// Marks a valid panic record ("PANC").
const MAGIC: u32 = 0x5041_4E43;

/// The panic record: magic and source line; in `.uninit`, which the reset does not clear.
#[allow(unsafe_code)] // a link section: the record must sit in RAM the reset leaves alone
#[link_section = ".uninit.PANIC"]
static mut RECORD: MaybeUninit<[u32; 2]> = MaybeUninit::uninit();

/// Why the MCU last reset, as read at boot.
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum ResetCause {
    /// Power-on or brown-out reset.
    PowerOn,
    /// The reset pin.
    Pin,
    /// The independent watchdog.
    IndependentWatchdog,
    /// A panic (the source line).
    Panic(u32),
    /// A software reset without a panic record.
    Software,
    /// None of the flags was set.
    Unknown,
}

/// Reads and clears the reset flags (RCC_CSR) and the panic record.
#[allow(unsafe_code)]
pub fn reset_cause(rcc: &stm32f4xx_hal::pac::RCC) -> ResetCause {
    let csr = rcc.csr().read().bits();
    // RMVF: clear the flags for the next boot.
    rcc.csr().modify(|_, w| w.rmvf().set_bit());
    // SAFETY: read and cleared once at boot, before any interrupt is enabled; the panic handler
    // (the only writer) cannot run concurrently.
    let rec = unsafe {
        let r = addr_of!(RECORD).cast::<[u32; 2]>().read_volatile();
        addr_of_mut!(RECORD)
            .cast::<[u32; 2]>()
            .write_volatile([0, 0]);
        r
    };
    let [magic, line] = rec;
    const PORRSTF: u32 = 1 << 27;
    const BORRSTF: u32 = 1 << 25;
    const PINRSTF: u32 = 1 << 26;
    const SFTRSTF: u32 = 1 << 28;
    const IWDGRSTF: u32 = 1 << 29;
    if csr & (PORRSTF | BORRSTF) != 0 {
        ResetCause::PowerOn
    } else if csr & IWDGRSTF != 0 {
        ResetCause::IndependentWatchdog
    } else if csr & SFTRSTF != 0 && magic == MAGIC {
        ResetCause::Panic(line)
    } else if csr & SFTRSTF != 0 {
        ResetCause::Software
    } else if csr & PINRSTF != 0 {
        ResetCause::Pin
    } else {
        ResetCause::Unknown
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
    defmt::error!("panic at line {=u32}: bridges braked, resetting", line);
    // Under the emulator a panic ends the run as a failure instead of a reset loop.
    #[cfg(feature = "qemu")]
    cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_FAILURE);
    cortex_m::peripheral::SCB::sys_reset()
}

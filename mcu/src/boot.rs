//! Why the MCU started: the reset flags of RCC_CSR (RM0090 §7.3.21) and the panic record
//! turned into the cause the identity frame reports.

use protocol::amr::ResetCause;

/// RCC_CSR flag: Brown-out reset.
pub const BORRSTF: u32 = 1 << 25;
/// RCC_CSR flag: Reset pin (set by every internal reset too).
pub const PINRSTF: u32 = 1 << 26;
/// RCC_CSR flag: Power-on / power-down reset.
pub const PORRSTF: u32 = 1 << 27;
/// RCC_CSR flag: Software reset.
pub const SFTRSTF: u32 = 1 << 28;
/// RCC_CSR flag: Independent watchdog.
pub const IWDGRSTF: u32 = 1 << 29;
/// RCC_CSR flag: Window watchdog.
pub const WWDGRSTF: u32 = 1 << 30;
/// RCC_CSR flag: Low-power management reset.
pub const LPWRRSTF: u32 = 1 << 31;

/// The cause from the reset flags and whether a panic record was found. Every internal reset also
/// pulls NRST, so the pin flag is looked at last.
pub const fn reset_cause(csr: u32, panicked: bool) -> ResetCause {
    if csr & PORRSTF != 0 {
        ResetCause::PowerOn
    } else if csr & BORRSTF != 0 {
        ResetCause::Brownout
    } else if csr & IWDGRSTF != 0 {
        ResetCause::IndependentWatchdog
    } else if csr & WWDGRSTF != 0 {
        ResetCause::WindowWatchdog
    } else if csr & LPWRRSTF != 0 {
        ResetCause::LowPower
    } else if csr & SFTRSTF != 0 && panicked {
        ResetCause::Panic
    } else if csr & SFTRSTF != 0 {
        ResetCause::Software
    } else if csr & PINRSTF != 0 {
        ResetCause::Pin
    } else {
        ResetCause::Unknown
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn causes_by_hand() {
        // A power-on sets POR, BOR and PIN together (RM0090: the internal reset drives NRST).
        assert_eq!(
            reset_cause(PORRSTF | BORRSTF | PINRSTF, false),
            ResetCause::PowerOn
        );
        assert_eq!(reset_cause(BORRSTF | PINRSTF, false), ResetCause::Brownout);
        assert_eq!(
            reset_cause(IWDGRSTF | PINRSTF, false),
            ResetCause::IndependentWatchdog
        );
        assert_eq!(
            reset_cause(WWDGRSTF | PINRSTF, false),
            ResetCause::WindowWatchdog
        );
        assert_eq!(reset_cause(LPWRRSTF | PINRSTF, false), ResetCause::LowPower);
        assert_eq!(reset_cause(SFTRSTF | PINRSTF, true), ResetCause::Panic);
        assert_eq!(reset_cause(SFTRSTF | PINRSTF, false), ResetCause::Software);
        assert_eq!(reset_cause(PINRSTF, false), ResetCause::Pin);
        // A stale panic record after a watchdog reset is not a panic.
        assert_eq!(
            reset_cause(IWDGRSTF | PINRSTF, true),
            ResetCause::IndependentWatchdog
        );
        assert_eq!(reset_cause(0, true), ResetCause::Unknown);
    }
}

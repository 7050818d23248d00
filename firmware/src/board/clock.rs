//! The clock security system: a failing HSE crystal must not leave the bridges switching at rates
//! that are no longer the ones the safety case assumes (the core falls back to the 16 MHz HSI, so
//! every tick would be 10.5 times longer).
//!
//! ```text
//!  HSE fails ─► CSS: system clock → HSI, NMI ─► bridges braked, gate driver off, core halts
//!            ─► no IWDG refresh ─► reset after ≤ 37.6 ms ─► boot reports IndependentWatchdog
//! ```
#![allow(unsafe_code)]

use stm32f4xx_hal::pac;

/// RCC_CR: clock security system enable.
const CR_CSSON: u32 = 1 << 19;
/// RCC_CIR: clear the clock security system interrupt flag.
const CIR_CSSC: u32 = 1 << 23;

/// Turns the clock security system on (after the HSE and PLL are running).
pub fn enable_css(rcc: &pac::RCC) {
    super::regs::rmw(rcc.cr(), 0, CR_CSSON);
}

/// The CSS interrupt (the NMI): brake, cut the gate driver, and halt until the IWDG resets.
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() {
    // SAFETY: only RCC_CIR's clear bit and GPIOD's bit-set/reset register are written; this
    // handler does not return, so no task resumes with the peripherals in a state it did not set.
    let (rcc, gpiod) = unsafe { (&*pac::RCC::ptr(), &*pac::GPIOD::ptr()) };
    super::regs::rmw(rcc.cir(), 0, CIR_CSSC);
    super::bridge::emergency_brake();
    // EN_GATE (PD0) low: the gate driver is off as well.
    super::regs::wr(gpiod.bsrr(), 1 << 16);
    // No defmt here: the NMI may have interrupted code that holds the logger.
    loop {
        cortex_m::asm::nop();
    }
}

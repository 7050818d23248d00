//! Timers: the 1 kHz tick (TIM2, also the µs clock of the feedback time stamps), the 10 kHz speed
//! loop (TIM5), the other boards' periodic timers (seed 001: TIM3; seed 004: the TIM7 tick), and
//! the independent watchdog.

use super::regs::*;
use super::{IWDG, SPEED_DIV, TICK_DIV};
use stm32f4xx_hal::pac;
use stm32f4xx_hal::rcc::{Enable, Reset};

/// A basic periodic interrupt from a general-purpose timer (update event).
pub struct Periodic<T> {
    tim: T,
}

macro_rules! periodic {
    ($tim:ident, $div:expr) => {
        impl Periodic<pac::$tim> {
            /// Starts the timer with the const divider and enables its update interrupt.
            pub fn new(tim: pac::$tim, rcc: &mut pac::RCC) -> Self {
                pac::$tim::enable(rcc);
                pac::$tim::reset(rcc);
                wr(tim.psc(), u32::from($div.0));
                wr(tim.arr(), u32::from($div.1));
                // URS: the UG below loads PSC without raising an interrupt.
                wr(tim.cr1(), CR1_URS);
                wr(tim.egr(), EGR_UG);
                wr(tim.sr(), 0);
                wr(tim.dier(), DIER_UIE);
                rmw(tim.cr1(), 0, CR1_CEN);
                Self { tim }
            }

            /// Clears the update flag (first thing in the handler, so the interrupt does not re-enter).
            pub fn clear(&self) {
                rmw(self.tim.sr(), SR_UIF, 0);
            }
        }
    };
}
periodic!(TIM2, TICK_DIV);
periodic!(TIM5, SPEED_DIV);
periodic!(TIM3, super::cdc::IMU_DIV);
periodic!(TIM7, super::pi_spi::TICK_DIV);

/// The independent watchdog: once started it cannot be stopped; a missing refresh resets the MCU.
pub struct Iwdg {
    iwdg: pac::IWDG,
}

impl Iwdg {
    /// Starts the IWDG with [`IWDG`] (20 ms nominal). While a debugger halts the core the IWDG is
    /// frozen, and so are TIM1/TIM8, whose outputs are then disabled as if MOE were cleared
    /// (RM0090 §38.16: DBG_TIM1_STOP, DBG_TIM8_STOP): a breakpoint never leaves a bridge switching.
    pub fn start(iwdg: pac::IWDG, dbg: &pac::DBGMCU) -> Self {
        rmw(dbg.apb1_fz(), 0, 1 << 12); // DBG_IWDG_STOP
        rmw(dbg.apb2_fz(), 0, 0b11); // DBG_TIM1_STOP | DBG_TIM8_STOP
        wr16(iwdg.kr(), 0x5555); // unlock PR/RLR
        wr16(iwdg.pr(), u16::from(IWDG.0));
        wr16(iwdg.rlr(), IWDG.1);
        // PVU/RVU clear within a few LSI periods (≈ 0.2 ms); bounded so a dead LSI cannot hang
        // init (the IWDG then runs on whatever it latched, which is still a watchdog).
        for _ in 0..200_000u32 {
            if iwdg.sr().read().bits() & 0b11 == 0 {
                break;
            }
        }
        wr16(iwdg.kr(), 0xAAAA);
        wr16(iwdg.kr(), 0xCCCC); // start
        Self { iwdg }
    }

    /// Refreshes the counter.
    pub fn feed(&mut self) {
        wr16(self.iwdg.kr(), 0xAAAA);
    }
}

/// Counts of the tick timer per tick (its auto-reload + 1).
pub const TICK_COUNTS: u32 = TICK_DIV.1 as u32 + 1;

/// Read-only view of the tick timer for time stamps, usable beside the tick task's ownership.
pub struct TickClock;

impl TickClock {
    /// The counter, then the update flag (in that order: see `mcu::timing::micros`).
    pub fn read(&self) -> (u32, bool) {
        // SAFETY: two reads of TIM2 status registers, no write; the tick task owns the writes.
        let t = unsafe { &*pac::TIM2::ptr() };
        let count = t.cnt().read().bits();
        let pending = t.sr().read().bits() & SR_UIF != 0;
        (count, pending)
    }
}

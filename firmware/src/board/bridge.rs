//! The two H-bridges on TIM1 (left) and TIM8 (right): complementary centre-aligned PWM with dead
//! time, the overcurrent comparator on the break inputs, brake = low sides on.

use super::regs::*;
use super::{DEAD_TIME_TICKS, PWM_ARR};
use control::{BridgeCompare, BridgeState};
use stm32f4xx_hal::pac;
use stm32f4xx_hal::rcc::{Enable, Reset};

/// The two H-bridges: TIM1 drives the left motor, TIM8 (slaved to TIM1) the right.
///
/// Brake = high sides off, low sides on (OCxM forced inactive, MOE = 1): the motor windings are
/// shorted and the motors brake dynamically. After an overcurrent break (BKIN, hardware clears
/// MOE) the outputs stay at their idle level, all switches off, until the ladder is re-armed.
pub struct Bridge {
    tim1: pac::TIM1,
    tim8: pac::TIM8,
    state: BridgeState,
}

impl Bridge {
    /// Configures both timers braked (MOE set, outputs forced inactive) and starts them in phase.
    pub fn new(tim1: pac::TIM1, tim8: pac::TIM8, rcc: &mut pac::RCC) -> Self {
        pac::TIM1::enable(rcc);
        pac::TIM1::reset(rcc);
        pac::TIM8::enable(rcc);
        pac::TIM8::reset(rcc);
        let arr = u32::from(PWM_ARR);
        for t in [&*tim1, &*tim8] {
            wr(t.psc(), 0);
            wr(t.arr(), arr);
            // One update per full up/down period (RCR = 1), so the update rate equals PWM_HZ.
            wr(t.rcr(), 1);
            wr(t.ccmr1_output(), ccmr1(OCM_FORCE_INACTIVE));
            wr(t.ccr1(), 0);
            wr(t.ccr2(), 0);
            // CC1E | CC1NE | CC2E | CC2NE, active high.
            wr(t.ccer(), (1 << 0) | (1 << 2) | (1 << 4) | (1 << 6));
            // Dead time, break enabled active low, off-state selection, lock level 1 (DTG, BKE,
            // BKP, AOE and OIS cannot change until reset). MOE stays off until `apply`.
            wr(
                t.bdtr(),
                u32::from(DEAD_TIME_TICKS) | BDTR_OSSI | BDTR_OSSR | BDTR_BKE | BDTR_LOCK1,
            );
            wr(t.egr(), EGR_UG);
            wr(t.cr1(), CR1_CMS_CENTER1 | CR1_ARPE);
        }
        // TIM1 CH4: compare near the top of the count = middle of the low-side conduction,
        // triggers the ADC injected conversion of the shunt currents (JEXTSEL = TIM1_CC4).
        wr(tim1.ccmr2_output(), (OCM_PWM1 << 12) | (OCPE << 8));
        wr(tim1.ccr4(), arr.saturating_sub(1));
        rmw(tim1.ccer(), 0, 1 << 12);
        // TIM8 starts on TIM1's enable (TRGO = enable), so both bridges switch in phase.
        wr(tim8.smcr(), SMCR_TRIGGER_ITR0);
        wr(tim1.cr2(), CR2_MMS_ENABLE);
        rmw(tim1.cr1(), 0, CR1_CEN);
        let mut b = Self {
            tim1,
            tim8,
            state: BridgeState::Run,
        };
        mcu::Bridge::apply(&mut b, BridgeState::Brake);
        b
    }
}

impl mcu::Bridge for Bridge {
    fn pwm_arr(&self) -> u16 {
        PWM_ARR
    }

    fn state(&self) -> BridgeState {
        self.state
    }

    fn break_tripped(&self) -> bool {
        let t1 = self.tim1.sr().read().bits() & SR_BIF != 0;
        let t8 = self.tim8.sr().read().bits() & SR_BIF != 0;
        t1 || t8
    }

    fn clear_break(&mut self) {
        for t in [&*self.tim1, &*self.tim8] {
            rmw(t.sr(), SR_BIF, 0);
        }
    }

    /// Brake takes effect at once (OCxM is not preloaded); Run starts with zero duty, the current
    /// loop sets it from the next period on.
    fn apply(&mut self, state: BridgeState) {
        if state == self.state {
            return;
        }
        let ocm = match state {
            BridgeState::Brake => OCM_FORCE_INACTIVE,
            BridgeState::Run => OCM_PWM1,
        };
        for t in [&*self.tim1, &*self.tim8] {
            wr(t.ccr1(), 0);
            wr(t.ccr2(), 0);
            wr(t.ccmr1_output(), ccmr1(ocm));
            // MOE can be set only while the break input is inactive; after a trip the hardware
            // keeps it cleared (outputs idle, all switches off) whatever is written here.
            rmw(t.bdtr(), 0, BDTR_MOE);
        }
        self.state = state;
    }

    /// No effect while braked: the outputs are forced.
    fn set(&mut self, [left, right]: [BridgeCompare; 2]) {
        if self.state != BridgeState::Run {
            return;
        }
        wr(self.tim1.ccr1(), u32::from(left.a));
        wr(self.tim1.ccr2(), u32::from(left.b));
        wr(self.tim8.ccr1(), u32::from(right.a));
        wr(self.tim8.ccr2(), u32::from(right.b));
    }
}

/// Cuts both bridges from any context, without the owner: outputs forced inactive (low sides on,
/// the motors brake dynamically), for the panic handler and the clock-failure NMI.
pub fn emergency_brake() {
    // SAFETY: only TIM1/TIM8's CCMR1 and BDTR are written, with the values `Bridge::apply(Brake)`
    // writes; called where the owner can no longer run (panic, NMI), so nothing races it.
    let (t1, t8) = unsafe { (&*pac::TIM1::ptr(), &*pac::TIM8::ptr()) };
    for t in [t1, t8] {
        wr(t.ccr1(), 0);
        wr(t.ccr2(), 0);
        wr(t.ccmr1_output(), ccmr1(OCM_FORCE_INACTIVE));
    }
}

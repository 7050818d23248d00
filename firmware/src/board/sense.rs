//! Measurements: the shunt-current ADC (ADC1 injected group, triggered by TIM1_CC4) and the two
//! quadrature encoders (TIM3, TIM4).

use super::regs::*;
use stm32f4xx_hal::pac;
use stm32f4xx_hal::rcc::{Enable, Reset};

/// Two quadrature encoders: TIM3 (left) and TIM4 (right) in encoder mode 3.
pub struct Encoders {
    tim3: pac::TIM3,
    tim4: pac::TIM4,
}

impl Encoders {
    /// Configures both counters (×4 decoding, input filter f_DTS/1 N = 8, full 16-bit range).
    pub fn new(tim3: pac::TIM3, tim4: pac::TIM4, rcc: &mut pac::RCC) -> Self {
        pac::TIM3::enable(rcc);
        pac::TIM3::reset(rcc);
        pac::TIM4::enable(rcc);
        pac::TIM4::reset(rcc);
        for t in [&*tim3, &*tim4] {
            // CC1S = CC2S = 01 (TI1, TI2), IC1F = IC2F = 0011.
            wr(
                t.ccmr1_input(),
                0b01 | (0b0011 << 4) | (0b01 << 8) | (0b0011 << 12),
            );
            wr(t.ccer(), 0);
            wr(t.smcr(), 0b011);
            wr(t.arr(), 0xFFFF);
            wr(t.cr1(), CR1_CEN);
        }
        Self { tim3, tim4 }
    }

    /// Raw counter values [left, right].
    #[cfg(not(feature = "qemu"))]
    pub fn read(&self) -> [u16; 2] {
        // The counters are 16-bit: the upper half of CNT reads as zero.
        [
            (self.tim3.cnt().read().bits() & 0xFFFF) as u16,
            (self.tim4.cnt().read().bits() & 0xFFFF) as u16,
        ]
    }

    /// Under the emulator the wheels stand still: QEMU models TIM3/TIM4 as free-running
    /// counters without encoder inputs, which would read as an implausible speed.
    #[cfg(feature = "qemu")]
    pub fn read(&self) -> [u16; 2] {
        let _ = (&self.tim3, &self.tim4);
        [0, 0]
    }
}

/// The shunt-current ADC: ADC1 injected group, channels 10 and 11, triggered by TIM1_CC4.
pub struct CurrentSense {
    adc: pac::ADC1,
}

impl CurrentSense {
    /// Configures ADC1 (12 bit, 15-cycle sampling, ADCCLK = PCLK2/4 = 21 MHz) with the end-of-
    /// injected-conversion interrupt enabled.
    pub fn new(adc: pac::ADC1, common: &pac::ADC_COMMON, rcc: &mut pac::RCC) -> Self {
        pac::ADC1::enable(rcc);
        pac::ADC1::reset(rcc);
        wr(common.ccr(), 0b01 << 16); // ADCPRE = /4
        wr(adc.smpr1(), 0b001 | (0b001 << 3)); // ch10, ch11: 15 cycles
                                               // JL = 1 (two conversions: JSQ3, JSQ4), JSQ3 = ch10, JSQ4 = ch11.
        wr(adc.jsqr(), (1 << 20) | (10 << 10) | (11 << 15));
        wr(adc.cr1(), (1 << 8) | (1 << 7)); // SCAN | JEOCIE
                                            // ADON, JEXTEN = rising edge, JEXTSEL = 0000 (TIM1_CC4).
        wr(adc.cr2(), 1 | (0b01 << 20));
        Self { adc }
    }

    /// Reads the two injected results [left, right] and clears the end-of-conversion flag.
    #[cfg(not(feature = "qemu"))]
    pub fn read(&self) -> [u16; 2] {
        let l = (self.adc.jdr1().read().bits() & 0x0FFF) as u16;
        let r = (self.adc.jdr2().read().bits() & 0x0FFF) as u16;
        rmw(self.adc.sr(), (1 << 2) | (1 << 3), 0); // JEOC, JSTRT
        [l, r]
    }

    /// Boot calibration, with the bridge braked (no current flows): waits for
    /// [`mcu::current::CALIBRATION_SAMPLES`] conversions of the running TIM1_CC4 trigger (3.2 ms)
    /// by polling the end-of-conversion flag, interrupts still masked. The wait is bounded: a
    /// trigger that never fires gives too few samples, which the calibration refuses.
    #[cfg(not(feature = "qemu"))]
    pub fn calibrate(&self) -> mcu::Calibration {
        let mut c = mcu::Calibration::new();
        // 168 MHz: about 10 cycles per poll, so 2 000 000 polls ≥ 100 ms, far above 3.2 ms.
        for _ in 0..2_000_000u32 {
            if c.count() >= mcu::current::CALIBRATION_SAMPLES {
                break;
            }
            if self.adc.sr().read().bits() & (1 << 2) != 0 {
                c.add(self.read());
            }
        }
        c
    }

    /// The emulator's ADC converts nothing useful: mid-scale readings (zero current).
    #[cfg(feature = "qemu")]
    pub fn calibrate(&self) -> mcu::Calibration {
        let mut c = mcu::Calibration::new();
        for _ in 0..mcu::current::CALIBRATION_SAMPLES {
            c.add(self.read());
        }
        c
    }

    /// The emulator's ADC converts nothing useful: report mid-scale (zero current).
    #[cfg(feature = "qemu")]
    pub fn read(&self) -> [u16; 2] {
        let _ = &self.adc;
        [2048, 2048]
    }
}

//! Board support: pin map, clocks and the register-level set-up of every peripheral the tasks use.
//!
//! # Pin map (STM32F407VGT6, LQFP100)
//!
//! | function                         | pin   | peripheral / AF        | notes                                      |
//! |----------------------------------|-------|------------------------|--------------------------------------------|
//! | left bridge half A high / low    | PE9 / PE8   | TIM1_CH1 / CH1N, AF1 | complementary, 500 ns dead time      |
//! | left bridge half B high / low    | PE11 / PE10 | TIM1_CH2 / CH2N, AF1 |                                      |
//! | right bridge half A high / low   | PC6 / PA7   | TIM8_CH1 / CH1N, AF3 | TIM8 started by TIM1 (ITR0), in phase |
//! | right bridge half B high / low   | PC7 / PB14  | TIM8_CH2 / CH2N, AF3 |                                      |
//! | overcurrent comparator (active low) | PE15 | TIM1_BKIN, AF1     | hardware PWM off, no software involved     |
//! | same comparator net              | PA6   | TIM8_BKIN, AF3         |                                            |
//! | left encoder A / B               | PB4 / PB5   | TIM3_CH1 / CH2, AF2 | encoder mode 3 (×4)                  |
//! | right encoder A / B              | PD12 / PD13 | TIM4_CH1 / CH2, AF2 |                                      |
//! | left / right shunt amplifier     | PC0 / PC1   | ADC1_IN10 / IN11 | injected group, triggered by TIM1_CC4    |
//! | gate-driver enable (EN_GATE)     | PD0   | output, push-pull      | external pull-down: low in reset = bridge off |
//! | holding-brake release            | PD1   | output, push-pull      | high releases the spring-applied brake     |
//! | gate-driver nFAULT               | PD2   | input, pull-up         | low = driver fault → Condition::Undervoltage |
//! | over-temperature warning nOTW    | PD3   | input, pull-up         | low = warning → Condition::ThermalWarning  |
//! | link from the Jetson: NSS / SCK  | PB12 / PB13 | SPI2, AF5        | slave, mode 0, 8 bit, MSB first            |
//! | link MISO / MOSI                 | PC2 / PC3   | SPI2, AF5        | DMA1 stream 4 (TX) / stream 3 (RX), ch 0   |
//! | SWD                              | PA13 / PA14 |                  | probe-rs, defmt over RTT                    |
//!
//! # Clocks and rates
//!
//! ```text
//!  HSE 8 MHz ±50 ppm ─PLL─► SYSCLK 168 MHz ─► APB2 84 MHz (timers ×2 = 168 MHz: TIM1, TIM8, ADC /4 = 21 MHz)
//!                                          └► APB1 42 MHz (timers ×2 = 84 MHz: TIM2, TIM3, TIM4, TIM5)
//!  TIM1  centre-aligned, ARR 4200 → 20 kHz PWM; CC4 at the top of the count triggers the ADC
//!        injected conversion → ADC interrupt → current_loop (20 kHz)
//!  TIM5  84 MHz / 8400 → 10 kHz update → speed_pid
//!  TIM2  84 MHz / (2·42000) → 1 kHz update → watchdog_tick
//!  IWDG  LSI 32 kHz nominal (17…47 kHz), /4, reload 159 → 20 ms nominal (13.6…37.6 ms)
//! ```
//!
//! Every rate is an exact divisor of its timer clock; the dividers are computed by
//! [`control::glue::timer_divider`] in `const` items, so an inexact rate fails the build.
//!
//! Under the `qemu` feature the clock tree is left at reset (HSI 16 MHz, no PLL): QEMU's
//! `netduinoplus2` does not model the RCC, and the HSE/PLL start-up would wait forever.
#![allow(unsafe_code)]

use control::glue::{center_aligned_arr, iwdg_setting, timer_divider, BridgeCompare, BridgeState};
use stm32f4xx_hal::pac;
use stm32f4xx_hal::rcc::{Enable, Reset};

/// System clock, Hz.
#[cfg(not(feature = "qemu"))]
pub const SYSCLK_HZ: u32 = 168_000_000;
/// System clock, Hz (reset clock: HSI).
#[cfg(feature = "qemu")]
pub const SYSCLK_HZ: u32 = 16_000_000;
/// Timer clock of APB1 timers (TIM2..TIM5): 2 × PCLK1 when the APB1 prescaler is not 1.
#[cfg(not(feature = "qemu"))]
pub const APB1_TIMER_HZ: u32 = 84_000_000;
/// Timer clock of APB1 timers at reset (prescalers 1).
#[cfg(feature = "qemu")]
pub const APB1_TIMER_HZ: u32 = 16_000_000;
/// Timer clock of APB2 timers (TIM1, TIM8).
pub const APB2_TIMER_HZ: u32 = SYSCLK_HZ;

/// PWM frequency and current-loop rate, Hz.
pub const PWM_HZ: u32 = 20_000;
/// Speed-loop rate, Hz.
pub const SPEED_HZ: u32 = 10_000;
/// Watchdog tick rate, Hz (the ladder's time base: one tick = 1 ms).
pub const TICK_HZ: u32 = 1_000;

/// TIM1/TIM8 auto-reload for centre-aligned PWM at [`PWM_HZ`].
pub const PWM_ARR: u16 = match center_aligned_arr(APB2_TIMER_HZ, PWM_HZ) {
    Some(a) => a,
    None => panic!("PWM rate is not an exact divisor of the timer clock"),
};
/// TIM5 divider for [`SPEED_HZ`].
pub const SPEED_DIV: (u16, u16) = match timer_divider(APB1_TIMER_HZ, SPEED_HZ) {
    Some(d) => d,
    None => panic!("speed-loop rate is not an exact divisor of the timer clock"),
};
/// TIM2 divider for [`TICK_HZ`].
pub const TICK_DIV: (u16, u16) = match timer_divider(APB1_TIMER_HZ, TICK_HZ) {
    Some(d) => d,
    None => panic!("tick rate is not an exact divisor of the timer clock"),
};
/// Nominal LSI frequency, Hz (DS8626: 17…47 kHz).
pub const LSI_HZ: u32 = 32_000;
/// IWDG timeout at the nominal LSI, ms.
pub const IWDG_TIMEOUT_MS: u32 = 20;
/// IWDG prescaler code and reload.
pub const IWDG: (u8, u16) = match iwdg_setting(IWDG_TIMEOUT_MS, LSI_HZ) {
    Some(s) => s,
    None => panic!("IWDG timeout out of range"),
};
/// Dead time in TIM1 clocks: 84 × 5.95 ns = 500 ns (BDTR.DTG, DTG[7] = 0 → DT = DTG × t_DTS).
pub const DEAD_TIME_TICKS: u8 = 84;
const _: () = assert!(DEAD_TIME_TICKS < 128);
// The speed loop must run a whole number of times per tick, the current loop per speed sample.
const _: () = assert!(SPEED_HZ % TICK_HZ == 0 && PWM_HZ % SPEED_HZ == 0);

// ---------------------------------------------------------------------------------------------
// Raw register access. The PAC's field writers are used where a register has few fields; whole
// register values below are built from named bits of RM0090 and written through these helpers.

/// Writes a whole 32-bit register.
fn wr<REG>(reg: &stm32f4::Reg<REG>, value: u32)
where
    REG: stm32f4::RegisterSpec<Ux = u32> + stm32f4::Writable + stm32f4::Resettable,
{
    // SAFETY: every caller passes a value assembled from the RM0090 bit definitions named beside
    // it; no reserved bit is set. The write has no memory-safety effect beyond the peripheral.
    reg.write(|w| unsafe { w.bits(value) });
}

/// Writes a whole 16-bit register.
fn wr16<REG>(reg: &stm32f4::Reg<REG>, value: u16)
where
    REG: stm32f4::RegisterSpec<Ux = u16> + stm32f4::Writable + stm32f4::Resettable,
{
    // SAFETY: as for `wr`: values come from the RM0090 bit definitions named at each call.
    reg.write(|w| unsafe { w.bits(value) });
}

/// Read-modify-write: clears `clear`, then sets `set`.
fn rmw<REG>(reg: &stm32f4::Reg<REG>, clear: u32, set: u32)
where
    REG: stm32f4::RegisterSpec<Ux = u32> + stm32f4::Writable + stm32f4::Readable,
{
    // SAFETY: as for `wr`: only documented bits of the register change.
    reg.modify(|r, w| unsafe { w.bits((r.bits() & !clear) | set) });
}

// RM0090 §17.4 (TIM1/TIM8) bit positions.
const CR1_CEN: u32 = 1 << 0;
const CR1_URS: u32 = 1 << 2;
const CR1_CMS_CENTER1: u32 = 0b01 << 5;
const CR1_ARPE: u32 = 1 << 7;
const CR2_MMS_ENABLE: u32 = 0b001 << 4;
const DIER_UIE: u32 = 1 << 0;
const SR_UIF: u32 = 1 << 0;
const SR_BIF: u32 = 1 << 7;
const EGR_UG: u32 = 1 << 0;
const OCM_PWM1: u32 = 0b110;
const OCM_FORCE_INACTIVE: u32 = 0b100;
const OCPE: u32 = 1 << 3;
const BDTR_LOCK1: u32 = 0b01 << 8;
const BDTR_OSSI: u32 = 1 << 10;
const BDTR_OSSR: u32 = 1 << 11;
const BDTR_BKE: u32 = 1 << 12;
const BDTR_MOE: u32 = 1 << 15;
const SMCR_TRIGGER_ITR0: u32 = 0b110; // SMS = trigger mode, TS = 000 (ITR0 = TIM1 for TIM8)

/// CCMR1 value putting channels 1 and 2 in output-compare mode `ocm` with preload.
const fn ccmr1(ocm: u32) -> u32 {
    (ocm << 4) | OCPE | (ocm << 12) | (OCPE << 8)
}

// ---------------------------------------------------------------------------------------------

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
        b.apply(BridgeState::Brake);
        b
    }

    /// The state last applied.
    pub fn state(&self) -> BridgeState {
        self.state
    }

    /// True if the break input tripped (overcurrent comparator); clears the flag when `clear`.
    pub fn tripped(&self, clear: bool) -> bool {
        let t1 = self.tim1.sr().read().bits() & SR_BIF != 0;
        let t8 = self.tim8.sr().read().bits() & SR_BIF != 0;
        if clear {
            for t in [&*self.tim1, &*self.tim8] {
                rmw(t.sr(), SR_BIF, 0);
            }
        }
        t1 || t8
    }

    /// Applies a bridge state. Brake takes effect at once (OCxM is not preloaded); Run starts
    /// with zero duty, the current loop sets it from the next period on.
    pub fn apply(&mut self, state: BridgeState) {
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

    /// Writes the duty of both motors (no effect while braked: the outputs are forced).
    pub fn set(&mut self, left: BridgeCompare, right: BridgeCompare) {
        if self.state != BridgeState::Run {
            return;
        }
        wr(self.tim1.ccr1(), u32::from(left.a));
        wr(self.tim1.ccr2(), u32::from(left.b));
        wr(self.tim8.ccr1(), u32::from(right.a));
        wr(self.tim8.ccr2(), u32::from(right.b));
    }
}

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

    /// The emulator's ADC converts nothing useful: report mid-scale (zero current).
    #[cfg(feature = "qemu")]
    pub fn read(&self) -> [u16; 2] {
        let _ = &self.adc;
        [2048, 2048]
    }
}

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

            /// The counter value (sub-period time stamp).
            pub fn count(&self) -> u32 {
                self.tim.cnt().read().bits()
            }
        }
    };
}
periodic!(TIM2, TICK_DIV);
periodic!(TIM5, SPEED_DIV);

/// The independent watchdog: once started it cannot be stopped; a missing refresh resets the MCU.
pub struct Iwdg {
    iwdg: pac::IWDG,
}

impl Iwdg {
    /// Starts the IWDG with [`IWDG`] (20 ms nominal) and freezes it while a debugger halts the core.
    pub fn start(iwdg: pac::IWDG, dbg: &pac::DBGMCU) -> Self {
        rmw(dbg.apb1_fz(), 0, 1 << 12); // DBG_IWDG_STOP
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

/// SPI2 slave with circular, double-buffered DMA: one [`FRAME_LEN`]-byte transaction per frame.
///
/// ```text
///  DMA1 stream 3 (RX, ch 0): SPI2 DR → rx[0] / rx[1]  alternately (DBM), transfer-complete IRQ
///  DMA1 stream 4 (TX, ch 0): tx[0] / tx[1] → SPI2 DR  alternately (DBM)
///  at TC: rx[1 − CT] holds the frame just received; tx[1 − CT] is free for the next feedback
/// ```
///
/// A byte slip (a glitch on SCK) shifts every following frame; each then fails its CRC, the
/// ladder brakes on comm loss after 10 ticks, and only a reset resynchronises (fail-safe, not
/// fail-operational; see proofs/SAFETY.md §7, F7).
pub struct Link {
    dma: pac::DMA1,
    _spi: pac::SPI2,
    rx: *mut [[u8; FRAME_LEN]; 2],
    tx: *mut [[u8; FRAME_LEN]; 2],
}

/// Bytes per SPI transaction.
pub const FRAME_LEN: usize = protocol::amr::FRAME_LEN;

// SAFETY: `Link` is moved once, from `init` into the one task that owns it; the raw pointers
// address 'static buffers that only that task and the DMA engine touch.
unsafe impl Send for Link {}

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

impl Link {
    /// Configures SPI2 as a mode-0 slave and both DMA streams; starts listening.
    pub fn new(
        spi: pac::SPI2,
        dma: pac::DMA1,
        rx: &'static mut [[u8; FRAME_LEN]; 2],
        tx: &'static mut [[u8; FRAME_LEN]; 2],
        rcc: &mut pac::RCC,
    ) -> Self {
        pac::SPI2::enable(rcc);
        pac::SPI2::reset(rcc);
        pac::DMA1::enable(rcc);
        let dr = spi.dr().as_ptr() as u32;
        let rx: *mut [[u8; FRAME_LEN]; 2] = rx;
        let tx: *mut [[u8; FRAME_LEN]; 2] = tx;
        let addr = |p: *mut [[u8; FRAME_LEN]; 2], i: usize| -> u32 {
            p.cast::<u8>().wrapping_add(i.wrapping_mul(FRAME_LEN)) as u32
        };
        let len = FRAME_LEN as u32;
        let rx_s = dma.st(3);
        wr(rx_s.par(), dr);
        wr(rx_s.m0ar(), addr(rx, 0));
        wr(rx_s.m1ar(), addr(rx, 1));
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
        let tx_s = dma.st(4);
        wr(tx_s.par(), dr);
        wr(tx_s.m0ar(), addr(tx, 0));
        wr(tx_s.m1ar(), addr(tx, 1));
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
        Self {
            dma,
            _spi: spi,
            rx,
            tx,
        }
    }

    /// Handles the transfer-complete interrupt: copies out the frame just received and returns it,
    /// or `None` after a transfer error (the stream is restarted and the frame is lost).
    pub fn take_rx(&mut self) -> Option<[u8; FRAME_LEN]> {
        let flags = self.dma.lisr().read().bits();
        wr(self.dma.lifcr(), DMA_S3_FLAGS);
        if flags & DMA_S3_TEIF != 0 {
            rmw(self.dma.st(3).cr(), 0, DMA_CR_EN);
            return None;
        }
        let ct = self.dma.st(3).cr().read().bits() & DMA_CR_CT != 0;
        let done = usize::from(!ct);
        // SAFETY: `rx` points to two 'static buffers; the DMA now writes buffer `ct`, so buffer
        // `done` is stable until the next transaction completes (≥ 256 µs away at 2 MHz, far
        // longer than this copy). The read is volatile because the DMA engine wrote it.
        let frame =
            unsafe { core::ptr::read_volatile(self.rx.cast::<[u8; FRAME_LEN]>().add(done)) };
        Some(frame)
    }

    /// Writes the feedback frame into the TX buffer the DMA is not sending.
    pub fn put_tx(&mut self, frame: &[u8; FRAME_LEN]) {
        let ct = self.dma.st(4).cr().read().bits() & DMA_CR_CT != 0;
        let idle = usize::from(!ct);
        // SAFETY: as in `take_rx`: buffer `idle` is not the DMA's current target.
        unsafe { core::ptr::write_volatile(self.tx.cast::<[u8; FRAME_LEN]>().add(idle), *frame) };
    }
}

/// Board GPIO: enable outputs and fault inputs.
pub struct Pins {
    /// Gate-driver enable (high = enabled).
    pub en_gate: stm32f4xx_hal::gpio::PD0<stm32f4xx_hal::gpio::Output>,
    /// Holding-brake release (high = released).
    pub brake_release: stm32f4xx_hal::gpio::PD1<stm32f4xx_hal::gpio::Output>,
    /// Gate-driver fault, active low.
    pub n_fault: stm32f4xx_hal::gpio::PD2<stm32f4xx_hal::gpio::Input>,
    /// Over-temperature warning, active low.
    pub n_otw: stm32f4xx_hal::gpio::PD3<stm32f4xx_hal::gpio::Input>,
}

/// Everything `init` hands to the tasks.
pub struct Board {
    /// Both H-bridges.
    pub bridge: Bridge,
    /// Both encoders.
    pub encoders: Encoders,
    /// Shunt ADC.
    pub adc: CurrentSense,
    /// SPI link to the Jetson.
    pub link: Link,
    /// 1 kHz tick timer.
    pub tick: Periodic<pac::TIM2>,
    /// 10 kHz speed-loop timer.
    pub speed: Periodic<pac::TIM5>,
    /// Enable outputs and fault inputs.
    pub pins: Pins,
}

/// Brings up clocks, pins and peripherals, bridge braked and gate driver disabled.
pub fn init(
    dp: pac::Peripherals,
    rx: &'static mut [[u8; FRAME_LEN]; 2],
    tx: &'static mut [[u8; FRAME_LEN]; 2],
) -> (Board, pac::IWDG, pac::DBGMCU) {
    use stm32f4xx_hal::prelude::*;
    use stm32f4xx_hal::rcc::Config;

    #[cfg(not(feature = "qemu"))]
    let mut rcc = dp.RCC.freeze(
        Config::hse(8.MHz())
            .sysclk(SYSCLK_HZ.Hz())
            .hclk(SYSCLK_HZ.Hz())
            .pclk1(42.MHz())
            .pclk2(84.MHz()),
    );
    #[cfg(feature = "qemu")]
    let mut rcc = {
        let _ = Config::hsi();
        dp.RCC.constrain()
    };

    let gpioa = dp.GPIOA.split(&mut rcc);
    let gpiob = dp.GPIOB.split(&mut rcc);
    let gpioc = dp.GPIOC.split(&mut rcc);
    let gpiod = dp.GPIOD.split(&mut rcc);
    let gpioe = dp.GPIOE.split(&mut rcc);

    // Gate driver off and holding brake applied before any PWM pin becomes an output.
    let mut en_gate = gpiod.pd0.into_push_pull_output();
    en_gate.set_low();
    let mut brake_release = gpiod.pd1.into_push_pull_output();
    brake_release.set_low();
    let n_fault = gpiod.pd2.into_pull_up_input();
    let n_otw = gpiod.pd3.into_pull_up_input();

    let rcc_regs: &mut pac::RCC = &mut rcc;
    let bridge = Bridge::new(dp.TIM1, dp.TIM8, rcc_regs);
    let encoders = Encoders::new(dp.TIM3, dp.TIM4, rcc_regs);
    let adc = CurrentSense::new(dp.ADC1, &dp.ADC_COMMON, rcc_regs);
    let link = Link::new(dp.SPI2, dp.DMA1, rx, tx, rcc_regs);
    let tick = Periodic::<pac::TIM2>::new(dp.TIM2, rcc_regs);
    let speed = Periodic::<pac::TIM5>::new(dp.TIM5, rcc_regs);

    // Pins last: the timers already hold the outputs braked when the pins connect.
    let _ = (
        gpioe.pe8.into_alternate::<1>(),
        gpioe.pe9.into_alternate::<1>(),
        gpioe.pe10.into_alternate::<1>(),
        gpioe.pe11.into_alternate::<1>(),
        gpioe.pe15.into_alternate::<1>(),
        gpioc.pc6.into_alternate::<3>(),
        gpioc.pc7.into_alternate::<3>(),
        gpioa.pa7.into_alternate::<3>(),
        gpiob.pb14.into_alternate::<3>(),
        gpioa.pa6.into_alternate::<3>(),
        gpiob.pb4.into_alternate::<2>(),
        gpiob.pb5.into_alternate::<2>(),
        gpiod.pd12.into_alternate::<2>(),
        gpiod.pd13.into_alternate::<2>(),
        gpioc.pc0.into_analog(),
        gpioc.pc1.into_analog(),
        gpiob.pb12.into_alternate::<5>(),
        gpiob.pb13.into_alternate::<5>(),
        gpioc.pc2.into_alternate::<5>(),
        gpioc.pc3.into_alternate::<5>(),
    );
    en_gate.set_high();

    let pins = Pins {
        en_gate,
        brake_release,
        n_fault,
        n_otw,
    };
    (
        Board {
            bridge,
            encoders,
            adc,
            link,
            tick,
            speed,
            pins,
        },
        dp.IWDG,
        dp.DBGMCU,
    )
}

//! The seed 004 board (`pi-spi`): four DC motors, four servos on a switchable 6 V rail, four
//! quadrature encoders, digital inputs DIN0–9 and a button, analog inputs 0–5, battery voltage and
//! an MPU6050, linked to a Raspberry Pi over SPI2 (the Pi is the master; one
//! [`TRANSFER_LEN`]-byte full-duplex exchange per transaction).
//!
//! # Pin map (STM32F407VGT6, LQFP100, ports A–E)
//!
//! | function                                   | pin                    | peripheral / AF           | notes                                              |
//! |--------------------------------------------|------------------------|---------------------------|----------------------------------------------------|
//! | motor 0 … 3 PWM                            | PC6 / PC7 / PC8 / PC9  | TIM8_CH1 … CH4, AF3       | [`super::cdc::Motors`] as on the seed 001 board, 20 kHz |
//! | motor 0 … 3 IN1 / IN2                      | PE0/PE1 … PE6/PE7      | output                    | motor k: IN1 on PE(2k), IN2 on PE(2k+1)             |
//! | driver standby (STBY, both drivers)        | PD0                    | output                    | external pull-down: drivers off in reset; high last in `init` |
//! | servo 0 … 3 signal                         | PE9 / PE11 / PE13 / PE14 | TIM1_CH1 … CH4, AF1     | 50 Hz, 1 µs resolution; compare 0 = held low        |
//! | servo 6 V rail enable (SERVO_6V0_ENABLE)   | PD1                    | output                    | external pull-down: rail off in reset; high = on    |
//! | encoder 0 A / B                            | PA15 / PB3             | TIM2_CH1 / CH2, AF1       | 32-bit counter; PA15/PB3 are JTDI/JTDO (SWD only is used) |
//! | encoder 1 A / B                            | PA0 / PA1              | TIM5_CH1 / CH2, AF2       | 32-bit counter                                     |
//! | encoder 2 A / B                            | PB4 / PB5              | TIM3_CH1 / CH2, AF2       | 16-bit counter, extended in software; PB4 is NJTRST |
//! | encoder 3 A / B                            | PD12 / PD13            | TIM4_CH1 / CH2, AF2       | 16-bit counter, extended in software                |
//! | analog 0 … 5                               | PA2 … PA7              | ADC1_IN2 … IN7            | analog k on PA(k+2), channel k+2; 144-cycle sampling |
//! | battery voltage                            | PC0                    | ADC1_IN10                 | raw 12-bit; 480-cycle sampling (divider source)     |
//! | DIN0 … DIN6                                | PD5 … PD11             | input, pull-down          | open input reads 0; 5 V tolerant (FT) pins          |
//! | DIN7 / DIN8                                | PD14 / PD15            | input, pull-down          |                                                    |
//! | DIN9                                       | PD3                    | input, pull-down          |                                                    |
//! | button                                     | PD2                    | input, pull-down          | push button to 3.3 V: pressed reads 1               |
//! | ESTOP loop                                 | PD4                    | input, pull-up, EXTI4     | as on every board: high = pressed or wire cut       |
//! | MPU6050 SCL / SDA                          | PB6 / PB7              | I2C1, AF4, 400 kHz        | [`super::cdc::Imu`], address 0x68                   |
//! | link NSS / SCK                             | PB12 / PB13            | SPI2, AF5; NSS also EXTI12 | slave, mode 0, 8 bit, MSB first; NSS rise resyncs |
//! | link MISO / MOSI                           | PB14 / PB15            | SPI2, AF5                 | DMA1 stream 4 (TX) / stream 3 (RX), channel 0       |
//! | SWD                                        | PA13 / PA14            |                           | probe-rs, defmt over RTT                            |
//!
//! Free: PA8–PA12, PB0–PB2, PB8–PB11, PC1–PC5, PC10–PC15, PE8, PE10, PE12, PE15.
//! EXTI lines in use: 4 (PD4) and 12 (PB12) only.
//!
//! # Timers and rates
//!
//! ```text
//!  TIM8  168 MHz, ARR 8399       20 kHz edge-aligned motor PWM (board::cdc::Motors)
//!  TIM1  168 MHz / 168 = 1 MHz, ARR 19 999 → 50 Hz servo frames, compare = pulse in µs
//!  TIM2, TIM5  encoder mode 3 (×4), 32-bit;  TIM3, TIM4  encoder mode 3, 16-bit (extended)
//!  TIM7  84 MHz / (2 · 42 000) → 1 kHz update: the tick (board::Periodic<TIM7>)
//!  TIM6  84 MHz / 84 = 1 MHz, free-running 16-bit µs counter, no interrupt (the seed's TIM6)
//!  IWDG  20 ms nominal (board::Iwdg), fed by the tick
//! ```
//!
//! The µs time stamp ([`UsClock::micros`]) is TIM6's count extended to 32 bits by the tick count:
//!
//! ```text
//!  TIM6   0 ……… 65535 │ 0 ……… 65535 │ 0 …            wraps every 65.536 ms
//!  TIM7   │ 1 ms │ 1 ms │ …                           started right after TIM6: tick n at ≥ n·1000 µs
//!  µs  =  the unique value ≡ TIM6 (mod 2¹⁶) in [ticks·1000 − 1000, ticks·1000 + 64 536)
//! ```
//!
//! exact while the tick task is less than 63 ms behind TIM7 (the 20 ms watchdog resets first).
//! `mcu::timing::micros` does not apply here: it takes the count of the tick timer itself (one
//! wrap per tick, as TIM2 on the seed 000 board); TIM6 is a separate, free-running counter.
//!
//! # Start-up
//!
//! [`init`] holds the drivers in standby (STBY low) and the servo rail off while it configures
//! the pins, shorts every motor through its IN lines, holds every servo line low, and only then
//! takes the drivers out of standby: from the first instruction after `init` the motors are
//! braked and the servos unpowered.
//!
//! Under the `qemu` feature the encoders and analog inputs read zero and the µs clock counts whole
//! ticks (QEMU's `netduinoplus2` models TIM2–TIM5 as plain counters and has no TIM6, TIM7 or ADC
//! scan), the IMU is absent, and the link reads transfers from a host file
//! (`board::emu::PI_SPI_TRANSFERS_FILE`). QEMU does not run TIM7 either: an emulator build of this
//! board needs another tick source.

use super::regs::*;
use super::{APB1_TIMER_HZ, APB2_TIMER_HZ};
use mcu::timing::timer_divider;
pub use protocol::pi_spi::TRANSFER_LEN;
use stm32f4xx_hal::gpio::{Input, Output, PD1};
use stm32f4xx_hal::pac;
use stm32f4xx_hal::rcc::{Enable, Reset};

pub use super::cdc::{Imu, Motors};

/// Servo channels.
pub const SERVOS: usize = 4;
/// Encoder channels.
pub const ENCODERS: usize = 4;
/// Analog inputs (besides the battery).
pub const ANALOG_INPUTS: usize = 6;

/// The tick rate of this board, Hz (the ladder's time base: one tick = 1 ms).
pub const TICK_HZ: u32 = 1_000;
/// Microseconds per tick.
pub const US_PER_TICK: u32 = 1_000_000 / TICK_HZ;
/// TIM7 divider for [`TICK_HZ`].
pub const TICK_DIV: (u16, u16) = match timer_divider(APB1_TIMER_HZ, TICK_HZ) {
    Some(d) => d,
    None => panic!("tick rate is not an exact divisor of the timer clock"),
};
const _: () = assert!(US_PER_TICK * TICK_HZ == 1_000_000);

/// Prescaler (PSC) that divides a timer clock down to 1 MHz; `None` unless exact and in range.
const fn psc_for_1mhz(timer_hz: u32) -> Option<u16> {
    match (
        timer_hz.checked_div(1_000_000),
        timer_hz.checked_rem(1_000_000),
    ) {
        (Some(d), Some(0)) if d >= 1 && d <= 65_536 => Some(d.wrapping_sub(1) as u16),
        _ => None,
    }
}

/// TIM6 prescaler: 1 MHz count.
pub const US_PSC: u16 = match psc_for_1mhz(APB1_TIMER_HZ) {
    Some(p) => p,
    None => panic!("APB1 timer clock is not a whole number of MHz"),
};
/// TIM1 prescaler: 1 MHz count, so a compare is a pulse width in µs.
pub const SERVO_PSC: u16 = match psc_for_1mhz(APB2_TIMER_HZ) {
    Some(p) => p,
    None => panic!("APB2 timer clock is not a whole number of MHz"),
};
/// Servo frame rate, Hz.
pub const SERVO_HZ: u32 = 50;
/// TIM1 auto-reload: 20 000 µs frames.
pub const SERVO_ARR: u16 = 19_999;
const _: () = assert!(1_000_000 / (SERVO_ARR as u32 + 1) == SERVO_HZ);
const _: () = assert!(1_000_000 % (SERVO_ARR as u32 + 1) == 0);

/// The link of this board: SPI2 with DMA, or transfers from a host file under the emulator.
#[cfg(not(feature = "qemu"))]
pub type PiLink = super::link::SpiLink<TRANSFER_LEN>;
/// The link of this board under the emulator: transfers from `board::emu::PI_SPI_TRANSFERS_FILE`.
#[cfg(feature = "qemu")]
pub type PiLink = super::emu::EmuLink<TRANSFER_LEN>;

// ---------------------------------------------------------------------------------------------
// Servos

const CCER_CC1E_TO_CC4E: u32 = 1 | (1 << 4) | (1 << 8) | (1 << 12);
/// GPIOE pins of the servo signals: PE9, PE11, PE13, PE14.
const SERVO_PINS: [u32; SERVOS] = [9, 11, 13, 14];

/// Four servo outputs on TIM1 CH1–CH4 and the 6 V servo rail.
///
/// ```text
///  pulse  ‾‾‾‾‾\_____________________________________‾‾‾‾‾\____   PWM mode 1: high while CNT < CCR
///         |<-CCR µs->|                                |
///         |<------------------ 20 000 µs ------------>|           CCR = 0: held low (no pulse)
/// ```
///
/// Compares are preloaded: a new pulse width takes effect at the next frame, so no pulse is ever
/// cut short or stretched by a write.
pub struct Servos {
    tim: pac::TIM1,
    rail: PD1<Output>,
}

impl Servos {
    /// TIM1 at 1 MHz, 50 Hz frames, every compare 0 (lines low), main output enabled; then the
    /// signal pins PE9/PE11/PE13/PE14 switch to AF1 (so they go from input straight to a driven
    /// low). The rail stays as it is given (low: off).
    pub fn new(tim: pac::TIM1, gpioe: &pac::GPIOE, rail: PD1<Output>, rcc: &mut pac::RCC) -> Self {
        pac::TIM1::enable(rcc);
        pac::TIM1::reset(rcc);
        pac::GPIOE::enable(rcc);
        wr(tim.psc(), u32::from(SERVO_PSC));
        wr(tim.arr(), u32::from(SERVO_ARR));
        wr(tim.ccmr1_output(), ccmr1(OCM_PWM1));
        wr(tim.ccmr2_output(), ccmr1(OCM_PWM1));
        for ccr in [tim.ccr1(), tim.ccr2(), tim.ccr3(), tim.ccr4()] {
            wr(ccr, 0);
        }
        wr(tim.ccer(), CCER_CC1E_TO_CC4E);
        wr(tim.bdtr(), BDTR_MOE);
        wr(tim.egr(), EGR_UG);
        wr(tim.cr1(), CR1_ARPE | CR1_CEN);
        // AF1 in AFRH (pins 8–15: 4 bits each), then MODER = 10 (alternate function).
        let (mut af_clear, mut af_set, mut mode_clear, mut mode_set) = (0u32, 0u32, 0u32, 0u32);
        for pin in SERVO_PINS {
            let af_shift = pin.wrapping_sub(8).wrapping_mul(4);
            af_clear |= 0xF_u32.wrapping_shl(af_shift);
            af_set |= 1_u32.wrapping_shl(af_shift);
            mode_clear |= 0b11_u32.wrapping_shl(pin.wrapping_mul(2));
            mode_set |= 0b10_u32.wrapping_shl(pin.wrapping_mul(2));
        }
        rmw(gpioe.afrh(), af_clear, af_set);
        rmw(gpioe.moder(), mode_clear, mode_set);
        Self { tim, rail }
    }

    /// Sets the rail and the four pulse widths in µs: 0 = no pulse (line held low); any other
    /// value is the compare, clamped to [`SERVO_ARR`] (the caller keeps it within 600–2600).
    /// The widths apply from the next 20 ms frame.
    pub fn set(&mut self, rail_on: bool, pulses_us: [u16; SERVOS]) {
        let [a, b, c, d] = pulses_us.map(|p| u32::from(p.min(SERVO_ARR)));
        let t = &self.tim;
        wr(t.ccr1(), a);
        wr(t.ccr2(), b);
        wr(t.ccr3(), c);
        wr(t.ccr4(), d);
        if rail_on {
            self.rail.set_high();
        } else {
            self.rail.set_low();
        }
    }

    /// Every pulse stopped at once (lines low now, not at the end of the frame) and the rail off.
    pub fn off(&mut self) {
        let t = &self.tim;
        for ccr in [t.ccr1(), t.ccr2(), t.ccr3(), t.ccr4()] {
            wr(ccr, 0);
        }
        // UG loads the zero compares now and restarts the frame: every line goes low at once.
        wr(t.egr(), EGR_UG);
        self.rail.set_low();
    }

    /// True while the 6 V rail is switched on.
    pub fn rail_on(&self) -> bool {
        self.rail.is_set_high()
    }
}

// ---------------------------------------------------------------------------------------------
// Encoders

/// Encoder-mode set-up of one timer: TI1/TI2 inputs with a filter, encoder mode 3, full range.
macro_rules! encoder_mode {
    ($t:expr, $arr:expr) => {{
        let t = &$t;
        // CC1S = CC2S = 01 (TI1, TI2), IC1F = IC2F = 0011 (f_CK_INT, N = 8).
        wr(
            t.ccmr1_input(),
            0b01 | (0b0011 << 4) | (0b01 << 8) | (0b0011 << 12),
        );
        wr(t.ccer(), 0);
        wr(t.smcr(), 0b011); // SMS = encoder mode 3 (count on both edges of both inputs)
        wr(t.arr(), $arr);
        wr(t.cr1(), CR1_CEN);
    }};
}

/// Counter width per channel as a shift: 0 for the 32-bit TIM2/TIM5, 16 for TIM3/TIM4.
const ENCODER_SHIFT: [u32; ENCODERS] = [0, 0, 16, 16];

/// Four quadrature decoders: encoder 0 TIM2, 1 TIM5 (32-bit), 2 TIM3, 3 TIM4 (16-bit).
///
/// [`Encoders::read`] returns cumulative counts that wrap like `i32`; the 16-bit counters are
/// extended by adding each read's wrapped difference, so they must be read at least once per
/// 32 767 counts (every tick is far more often than any wheel needs).
pub struct Encoders {
    tim2: pac::TIM2,
    tim5: pac::TIM5,
    tim3: pac::TIM3,
    tim4: pac::TIM4,
    last: [u32; ENCODERS],
    count: [i32; ENCODERS],
}

impl Encoders {
    /// Configures the four counters (×4 decoding, input filter N = 8), all starting at 0.
    pub fn new(
        tim2: pac::TIM2,
        tim3: pac::TIM3,
        tim4: pac::TIM4,
        tim5: pac::TIM5,
        rcc: &mut pac::RCC,
    ) -> Self {
        pac::TIM2::enable(rcc);
        pac::TIM2::reset(rcc);
        pac::TIM3::enable(rcc);
        pac::TIM3::reset(rcc);
        pac::TIM4::enable(rcc);
        pac::TIM4::reset(rcc);
        pac::TIM5::enable(rcc);
        pac::TIM5::reset(rcc);
        encoder_mode!(tim2, u32::MAX);
        encoder_mode!(tim5, u32::MAX);
        encoder_mode!(tim3, 0xFFFF);
        encoder_mode!(tim4, 0xFFFF);
        Self {
            tim2,
            tim5,
            tim3,
            tim4,
            last: [0; ENCODERS],
            count: [0; ENCODERS],
        }
    }

    /// Raw counters [encoder 0 … 3].
    #[cfg(not(feature = "qemu"))]
    fn raw(&self) -> [u32; ENCODERS] {
        [
            self.tim2.cnt().read().bits(),
            self.tim5.cnt().read().bits(),
            self.tim3.cnt().read().bits() & 0xFFFF,
            self.tim4.cnt().read().bits() & 0xFFFF,
        ]
    }

    /// Under the emulator the wheels stand still: QEMU models TIM2–TIM5 as free-running counters
    /// without encoder inputs.
    #[cfg(feature = "qemu")]
    fn raw(&self) -> [u32; ENCODERS] {
        let _ = (&self.tim2, &self.tim5, &self.tim3, &self.tim4);
        [0; ENCODERS]
    }

    /// Cumulative counts [encoder 0 … 3] since `new`, wrapping as `i32`.
    pub fn read(&mut self) -> [i32; ENCODERS] {
        let raw = self.raw();
        for (((c, l), r), s) in self
            .count
            .iter_mut()
            .zip(self.last.iter_mut())
            .zip(raw)
            .zip(ENCODER_SHIFT)
        {
            *c = c.wrapping_add(counter_delta(*l, r, s));
            *l = r;
        }
        self.count
    }
}

/// Signed difference `now − last` of a counter `32 − shift` bits wide, taking the shorter way
/// round (a 16-bit counter that wrapped from 65 535 to 2 moved +3).
pub const fn counter_delta(last: u32, now: u32, shift: u32) -> i32 {
    (now.wrapping_shl(shift)
        .wrapping_sub(last.wrapping_shl(shift)) as i32)
        .wrapping_shr(shift)
}

const _: () = assert!(counter_delta(65_535, 2, 16) == 3);
const _: () = assert!(counter_delta(2, 65_535, 16) == -3);
const _: () = assert!(counter_delta(100, 40_000, 16) == -25_636);
const _: () = assert!(counter_delta(u32::MAX, 1, 0) == 2);
const _: () = assert!(counter_delta(5, 3, 0) == -2);

// ---------------------------------------------------------------------------------------------
// Analog inputs and battery

/// ADC1 channels of analog 0 … 5, then the battery: the regular sequence, in order.
const ADC_SEQUENCE: [u32; ANALOG_INPUTS + 1] = [2, 3, 4, 5, 6, 7, 10];

/// One scan: raw 12-bit readings.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AnalogReading {
    /// Analog inputs 0 … 5 (the seed's `analogSensor`).
    pub analog: [u16; ANALOG_INPUTS],
    /// Battery divider (the seed's `batteryVoltage`, ADC1 channel 10).
    pub battery: u16,
}

/// ADC1's regular group: analog 0 … 5 (channels 2 … 7) and the battery (channel 10), one
/// software-started scan per call.
pub struct Analog {
    adc: pac::ADC1,
}

impl Analog {
    /// ADC1 on (ADCCLK = PCLK2 / 4 = 21 MHz), 12 bit, scan of 7 conversions with an
    /// end-of-conversion flag after each; 144-cycle sampling for the inputs, 480 for the battery.
    pub fn new(adc: pac::ADC1, common: &pac::ADC_COMMON, rcc: &mut pac::RCC) -> Self {
        pac::ADC1::enable(rcc);
        pac::ADC1::reset(rcc);
        // ADCPRE = /4.
        wr(common.ccr(), 0b01 << 16);
        // SMPR2: channels 2 … 7 at 144 cycles (code 110), 3 bits per channel.
        let smpr2 = [2u32, 3, 4, 5, 6, 7]
            .iter()
            .fold(0u32, |a, ch| a | 0b110_u32.wrapping_shl(ch.wrapping_mul(3)));
        wr(adc.smpr2(), smpr2);
        wr(adc.smpr1(), 0b111); // channel 10: 480 cycles
        let (mut sqr3, mut sqr2) = (0u32, 0u32);
        for (i, ch) in (0u32..).zip(ADC_SEQUENCE) {
            if i < 6 {
                sqr3 |= ch.wrapping_shl(i.wrapping_mul(5));
            } else {
                sqr2 |= ch.wrapping_shl(i.wrapping_sub(6).wrapping_mul(5));
            }
        }
        // L = conversions − 1.
        let len = ADC_SEQUENCE.len() as u32;
        wr(adc.sqr1(), len.wrapping_sub(1) << 20);
        wr(adc.sqr2(), sqr2);
        wr(adc.sqr3(), sqr3);
        wr(adc.cr1(), 1 << 8); // SCAN
        wr(adc.cr2(), 1 | (1 << 10)); // ADON, EOCS (flag after each conversion)
        Self { adc }
    }

    /// One scan, busy-waiting about 70 µs (6 × 7.4 µs + 23.4 µs): call it from a low-priority
    /// task. `None` if a conversion did not finish in time or a result was overwritten before it
    /// was read (a long preemption between two conversions).
    #[cfg(not(feature = "qemu"))]
    pub fn scan(&mut self) -> Option<AnalogReading> {
        // Polls per conversion before the scan is given up (a conversion takes at most 492 ADC
        // clocks, 23.4 µs, about 3 900 core cycles; a poll takes several).
        const ADC_POLLS: u32 = 10_000;
        const ADC_SR_EOC: u32 = 1 << 1;
        const ADC_SR_OVR: u32 = 1 << 5;
        const ADC_CR2_SWSTART: u32 = 1 << 30;
        let adc = &self.adc;
        wr(adc.sr(), 0);
        rmw(adc.cr2(), 0, ADC_CR2_SWSTART);
        let mut raw = [0u16; ANALOG_INPUTS + 1];
        for r in raw.iter_mut() {
            let mut done = false;
            for _ in 0..ADC_POLLS {
                let sr = adc.sr().read().bits();
                if sr & ADC_SR_OVR != 0 {
                    wr(adc.sr(), 0);
                    return None;
                }
                if sr & ADC_SR_EOC != 0 {
                    done = true;
                    break;
                }
            }
            if !done {
                return None;
            }
            // Reading DR clears EOC.
            *r = (adc.dr().read().bits() & 0x0FFF) as u16;
        }
        let [a0, a1, a2, a3, a4, a5, battery] = raw;
        Some(AnalogReading {
            analog: [a0, a1, a2, a3, a4, a5],
            battery,
        })
    }

    /// The emulator's ADC has no scan: every input reads 0.
    #[cfg(feature = "qemu")]
    pub fn scan(&mut self) -> Option<AnalogReading> {
        let _ = &self.adc;
        Some(AnalogReading::default())
    }
}

// ---------------------------------------------------------------------------------------------
// Digital inputs

/// DIN0 … DIN9 and the button on GPIOD, all inputs with pull-downs (see the pin map).
pub struct DigitalInputs {
    _pins: DinPins,
}

/// The pins [`DigitalInputs`] owns (held only so nothing else reconfigures them).
pub type DinPins = (
    [stm32f4xx_hal::gpio::ErasedPin<Input>; 9],
    stm32f4xx_hal::gpio::PD3<Input>,
    stm32f4xx_hal::gpio::PD2<Input>,
);

impl DigitalInputs {
    /// Takes the configured pins: DIN0 … DIN8 (PD5 … PD11, PD14, PD15), DIN9 (PD3), button (PD2).
    pub fn new(pins: DinPins) -> Self {
        Self { _pins: pins }
    }

    /// The seed's `digitalSensors`: bit k = DINk (k = 0 … 9), bit 10 = button; one read of the
    /// port, so all eleven are sampled at the same instant.
    pub fn read(&self) -> u16 {
        // SAFETY: a read of GPIOD's input data register; nothing is written.
        let idr = unsafe { (*pac::GPIOD::ptr()).idr().read().bits() };
        digital_sensors(idr)
    }
}

/// Bit 10 of `digitalSensors`: the button.
pub const BUTTON_BIT: u16 = 1 << 10;

/// `digitalSensors` from GPIOD's input data register: PD5 … PD11 → bits 0 … 6, PD14/PD15 → bits
/// 7/8, PD3 → bit 9, PD2 → bit 10; every other pin ignored.
pub const fn digital_sensors(idr: u32) -> u16 {
    let din0_6 = (idr >> 5) & 0x7F;
    let din7_8 = (idr >> 7) & 0x180;
    let din9 = (idr << 6) & 0x200;
    let button = (idr << 8) & 0x400;
    (din0_6 | din7_8 | din9 | button) as u16
}

const _: () = assert!(digital_sensors(0) == 0);
const _: () = assert!(digital_sensors(0xFFFF_FFFF) == 0x7FF);
// The pins that are not inputs (PD0, PD1, PD4 ESTOP, PD12/PD13 encoder) never show.
const _: () = assert!(digital_sensors((1 << 0) | (1 << 1) | (1 << 4) | (1 << 12) | (1 << 13)) == 0);
const _: () = assert!(digital_sensors(1 << 5) == 1 << 0 && digital_sensors(1 << 11) == 1 << 6);
const _: () = assert!(digital_sensors(1 << 14) == 1 << 7 && digital_sensors(1 << 15) == 1 << 8);
const _: () = assert!(digital_sensors(1 << 3) == 1 << 9 && digital_sensors(1 << 2) == BUTTON_BIT);

// ---------------------------------------------------------------------------------------------
// µs clock

/// Microseconds since the µs clock started, from the tick count and TIM6's 16-bit count
/// (wraps after 71.6 minutes, as the seed's `updateTime` does).
///
/// `ticks` counts the tick timer's updates (started right after TIM6, so tick n is counted no
/// earlier than n · `us_per_tick` µs); the result is the unique value congruent to `count`
/// modulo 2¹⁶ in `[ticks · us_per_tick − us_per_tick, … + 2¹⁶)`: exact while the tick count is
/// less than 2¹⁶ − 2 · `us_per_tick` µs (63.5 ms at 1 kHz) behind.
pub const fn micros_from_counter(ticks: u32, count: u16, us_per_tick: u32) -> u32 {
    let base = ticks.wrapping_mul(us_per_tick).wrapping_sub(us_per_tick);
    base.wrapping_add(count.wrapping_sub(base as u16) as u32)
}

const _: () = assert!(micros_from_counter(0, 0, 1000) == 0);
const _: () = assert!(micros_from_counter(0, 999, 1000) == 999);
// The tick counted right at its update, and a tick counted late.
const _: () = assert!(micros_from_counter(1, 1000, 1000) == 1000);
const _: () = assert!(micros_from_counter(0, 1500, 1000) == 1500);
// 62 ms late, TIM6 wrapped in between: 67 000 µs, TIM6 reads 67 000 − 65 536.
const _: () = assert!(micros_from_counter(5, 1464, 1000) == 67_000);
// Across the u32 wrap (2³² is a multiple of 2¹⁶): 200 µs past it.
const _: () = assert!(micros_from_counter(4_294_967, 200, 1000) == 200);
// Just before it.
const _: () = assert!(micros_from_counter(4_294_967, 65_340, 1000) == 4_294_967_100);

/// TIM6 as a free-running 1 MHz counter, read-only after [`UsClock::start`]; `Copy`, so every
/// task that time-stamps can hold one.
#[derive(Clone, Copy)]
pub struct UsClock(());

impl UsClock {
    /// Starts TIM6 at 1 MHz over its full 16-bit range, without interrupts. Start the tick timer
    /// right after it (see [`micros_from_counter`]).
    pub fn start(tim: pac::TIM6, rcc: &mut pac::RCC) -> Self {
        pac::TIM6::enable(rcc);
        pac::TIM6::reset(rcc);
        wr(tim.psc(), u32::from(US_PSC));
        wr(tim.arr(), 0xFFFF);
        // URS: the UG that loads PSC sets no flag; no interrupt is enabled either way.
        wr(tim.cr1(), CR1_URS);
        wr(tim.egr(), EGR_UG);
        wr(tim.sr(), 0);
        rmw(tim.cr1(), 0, CR1_CEN);
        Self(())
    }

    /// TIM6's count, µs modulo 2¹⁶.
    pub fn count(&self) -> u16 {
        // SAFETY: a read of TIM6's counter; `start` consumed the only handle, nothing writes it.
        let cnt = unsafe { (*pac::TIM6::ptr()).cnt().read().bits() };
        (cnt & 0xFFFF) as u16
    }

    /// The u32 µs time stamp (the seed's `updateTime`) for the current tick count.
    #[cfg(not(feature = "qemu"))]
    pub fn micros(&self, ticks: u32) -> u32 {
        micros_from_counter(ticks, self.count(), US_PER_TICK)
    }

    /// Under the emulator (no TIM6 model) the time stamp counts whole ticks.
    #[cfg(feature = "qemu")]
    pub fn micros(&self, ticks: u32) -> u32 {
        ticks.wrapping_mul(US_PER_TICK)
    }
}

// ---------------------------------------------------------------------------------------------
// Board

/// Everything `init` hands to the tasks of the seed 004 image.
pub struct PiSpiBoard {
    /// The four motor outputs (TIM8 and PE0 … PE7), every motor shorted.
    pub motors: Motors,
    /// The four servo outputs and the 6 V rail, off.
    pub servos: Servos,
    /// The four encoders.
    pub encoders: Encoders,
    /// Analog inputs 0 … 5 and the battery.
    pub analog: Analog,
    /// DIN0 … DIN9 and the button.
    pub inputs: DigitalInputs,
    /// The MPU6050.
    pub imu: Imu,
    /// The link to the Pi.
    pub link: PiLink,
    /// The local ESTOP input.
    pub estop: super::EstopPin,
    /// The link's chip select, for resynchronisation (EXTI12).
    pub nss: super::NssPin,
    /// 1 kHz tick timer (TIM7).
    pub tick: super::Periodic<pac::TIM7>,
    /// The µs clock (TIM6).
    pub clock: UsClock,
}

/// Brings up the seed 004 board: clocks, ESTOP input, drivers in standby and servo rail off
/// first; motors shorted, servo lines low, encoders, inputs, link; the µs clock and the tick
/// timer; the drivers leave standby last.
pub fn init(
    dp: pac::Peripherals,
    rx: &'static mut [[u8; TRANSFER_LEN]; 2],
    tx: &'static mut [[u8; TRANSFER_LEN]; 2],
) -> (PiSpiBoard, pac::IWDG, pac::DBGMCU) {
    use stm32f4xx_hal::gpio::{Edge, ExtiPin};
    use stm32f4xx_hal::prelude::*;

    let mut rcc = super::clocks(dp.RCC);
    let gpioa = dp.GPIOA.split(&mut rcc);
    let gpiob = dp.GPIOB.split(&mut rcc);
    let gpioc = dp.GPIOC.split(&mut rcc);
    let gpiod = dp.GPIOD.split(&mut rcc);

    // Drivers in standby and the servo rail off before any output pin is configured.
    let mut stby = gpiod.pd0.into_push_pull_output();
    stby.set_low();
    let mut rail = gpiod.pd1.into_push_pull_output();
    rail.set_low();

    let mut syscfg = dp.SYSCFG.constrain(&mut rcc);
    let mut exti = dp.EXTI;
    let estop = super::EstopPin::new(gpiod.pd4, &mut syscfg, &mut exti);
    // NSS stays in its SPI function; the EXTI still sees its level.
    let mut nss = gpiob.pb12.into_alternate::<5>();
    nss.make_interrupt_source(&mut syscfg);
    nss.trigger_on_edge(&mut exti, Edge::Rising);
    nss.enable_interrupt(&mut exti);

    #[cfg(not(feature = "qemu"))]
    let imu = Imu::new(dp.I2C1.i2c((gpiob.pb6, gpiob.pb7), 400.kHz(), &mut rcc));
    #[cfg(feature = "qemu")]
    let imu = {
        let _ = (dp.I2C1, gpiob.pb6, gpiob.pb7);
        Imu
    };

    let inputs = DigitalInputs::new((
        [
            gpiod.pd5.into_pull_down_input().erase(),
            gpiod.pd6.into_pull_down_input().erase(),
            gpiod.pd7.into_pull_down_input().erase(),
            gpiod.pd8.into_pull_down_input().erase(),
            gpiod.pd9.into_pull_down_input().erase(),
            gpiod.pd10.into_pull_down_input().erase(),
            gpiod.pd11.into_pull_down_input().erase(),
            gpiod.pd14.into_pull_down_input().erase(),
            gpiod.pd15.into_pull_down_input().erase(),
        ],
        gpiod.pd3.into_pull_down_input(),
        gpiod.pd2.into_pull_down_input(),
    ));

    let rcc_regs: &mut pac::RCC = &mut rcc;
    // Servo lines low (compares 0) before they connect; the rail stays off.
    let servos = Servos::new(dp.TIM1, &dp.GPIOE, rail, rcc_regs);
    // Every motor shorted through IN1 = IN2 = 1 (STBY still low).
    let motors = Motors::new(dp.TIM8, dp.GPIOE, rcc_regs);
    let encoders = Encoders::new(dp.TIM2, dp.TIM3, dp.TIM4, dp.TIM5, rcc_regs);
    let analog = Analog::new(dp.ADC1, &dp.ADC_COMMON, rcc_regs);
    let link = PiLink::new(dp.SPI2, dp.DMA1, rx, tx, rcc_regs);

    let _ = (
        gpioc.pc6.into_alternate::<3>(),
        gpioc.pc7.into_alternate::<3>(),
        gpioc.pc8.into_alternate::<3>(),
        gpioc.pc9.into_alternate::<3>(),
        gpioa.pa15.into_alternate::<1>(),
        gpiob.pb3.into_alternate::<1>(),
        gpioa.pa0.into_alternate::<2>(),
        gpioa.pa1.into_alternate::<2>(),
        gpiob.pb4.into_alternate::<2>(),
        gpiob.pb5.into_alternate::<2>(),
        gpiod.pd12.into_alternate::<2>(),
        gpiod.pd13.into_alternate::<2>(),
    );
    let _ = (
        gpioa.pa2.into_analog(),
        gpioa.pa3.into_analog(),
        gpioa.pa4.into_analog(),
        gpioa.pa5.into_analog(),
        gpioa.pa6.into_analog(),
        gpioa.pa7.into_analog(),
        gpioc.pc0.into_analog(),
        gpiob.pb13.into_alternate::<5>(),
        gpiob.pb14.into_alternate::<5>(),
        gpiob.pb15.into_alternate::<5>(),
    );

    // The µs clock, then the tick right after it (tick n no earlier than n ms on TIM6), as late
    // as possible so no tick is pending long before the tasks run.
    let clock = UsClock::start(dp.TIM6, rcc_regs);
    let tick = super::Periodic::<pac::TIM7>::new(dp.TIM7, rcc_regs);

    // Every motor is shorted by its IN lines, every servo line low, the rail off: the drivers
    // may leave standby.
    stby.set_high();
    (
        PiSpiBoard {
            motors,
            servos,
            encoders,
            analog,
            inputs,
            imu,
            link,
            estop,
            nss: super::NssPin(nss),
            tick,
            clock,
        },
        dp.IWDG,
        dp.DBGMCU,
    )
}

/// The interrupt vector of the `imu_read` task: UART4 is unused on this board, so the vector is
/// free; the tick pends it every [`IMU_PERIOD_TICKS`] (the tick is the IMU's timer).
pub const IMU_IRQ: pac::Interrupt = pac::Interrupt::UART4;
/// Ticks between two IMU and analog reads (100 Hz).
pub const IMU_PERIOD_TICKS: u32 = 10;

/// Emulator stand-ins for the triggers QEMU does not model (feature `qemu`): one link transfer
/// slot per tick from the host file, and the exit once the file ended with BRAKE held.
#[cfg(feature = "qemu")]
pub mod hooks {
    use stm32f4xx_hal::pac;

    /// After a tick: pends the link task (it reads the tick's record) and exits QEMU a few ticks
    /// after the file ended with the motors `braked`.
    pub fn after_tick(tick: u32, braked: bool) {
        rtic::pend(pac::Interrupt::DMA1_STREAM3);
        super::super::emu::hooks::exit_when_done(tick, braked);
    }

    /// QEMU does not run TIM7: SysTick at 1 kHz stands in for it (the handler pends TIM7).
    pub fn start_tick(mut syst: cortex_m::peripheral::SYST) {
        use cortex_m::peripheral::syst::SystClkSource;
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(super::super::SYSCLK_HZ / super::TICK_HZ - 1);
        syst.clear_current();
        syst.enable_interrupt();
        syst.enable_counter();
    }
}

/// Emulator hooks: nothing on the board (TIM7 ticks, the Pi clocks the transfers).
#[cfg(not(feature = "qemu"))]
pub mod hooks {
    /// After a tick: nothing.
    pub fn after_tick(_tick: u32, _braked: bool) {}
}

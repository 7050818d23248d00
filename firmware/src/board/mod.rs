//! Board support: pin map, clocks and the register-level set-up of every peripheral the tasks use,
//! one module per peripheral. The task bodies live in the `mcu` crate; these modules only move
//! numbers between registers and those bodies.
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
//! | ESTOP loop                       | PD4   | input, pull-up, EXTI4  | normally-closed contact to GND: high = pressed or wire cut |
//! | link from the Jetson: NSS / SCK  | PB12 / PB13 | SPI2, AF5; NSS also EXTI12 | slave, mode 0, 8 bit, MSB first; NSS rise resyncs |
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
//! [`mcu::timing::timer_divider`] in `const` items, so an inexact rate fails the build.
//!
//! Under the `qemu` feature the clock tree is left at reset (HSI 16 MHz, no PLL): QEMU's
//! `netduinoplus2` does not model the RCC, and the HSE/PLL start-up would wait forever.
#![allow(unsafe_code)]

pub mod bridge;
pub mod cdc;
#[cfg(not(feature = "qemu"))]
mod clock;
#[cfg(feature = "qemu")]
pub mod emu;
#[cfg(not(feature = "qemu"))]
pub mod link;
pub mod pi_spi;
mod regs;
pub mod sense;
pub mod teensy;
pub mod timers;
pub mod trace;
pub mod uart;
#[cfg(feature = "usb")]
pub mod usb;

pub use bridge::Bridge;
pub use sense::{CurrentSense, Encoders};
pub use timers::{Iwdg, Periodic, TickClock};

use mcu::timing::{center_aligned_arr, iwdg_setting, timer_divider};
use mcu::tuning::Tuning;
use stm32f4xx_hal::pac;

/// The link peripheral of this image: SPI2 with DMA on the board, frames from a host file under
/// the emulator (which models neither SPI slave mode nor DMA).
#[cfg(not(feature = "qemu"))]
pub type LinkHw = link::SpiLink<FRAME_LEN>;
/// The link peripheral of this image: frames from a host file under the emulator.
#[cfg(feature = "qemu")]
pub type LinkHw = emu::EmuLink<FRAME_LEN>;

/// This board's tuning (the simulator runs the same).
#[cfg(not(feature = "qemu"))]
pub const TUNING: Tuning = mcu::tuning::AMR;
/// Under the emulator the current loop is pended by the speed loop (QEMU has no ADC trigger), so
/// it runs 10 times per tick, not 20.
#[cfg(feature = "qemu")]
pub const TUNING: Tuning = Tuning {
    min_runs_per_tick: [9, 9],
    ..mcu::tuning::AMR
};

/// The identity the link answers an identity request with.
pub fn identity(boot: &crate::panic::Boot) -> protocol::amr::McuInfo {
    use protocol::amr::{git_hash_from_hex, BoardProfile, McuInfo};
    McuInfo {
        fw_version: crate::build::FW_VERSION,
        git_hash: git_hash_from_hex(crate::build::GIT_HASH),
        board: BoardProfile::AmrSpi,
        build_date: crate::build::BUILD_DATE,
        reset_cause: boot.cause,
        reset_count: boot.count,
        panic_line: boot.panic_line,
        seq: 0,
        dirty: crate::build::GIT_DIRTY,
    }
}

/// Bytes per link transaction.
pub const FRAME_LEN: usize = protocol::amr::FRAME_LEN;

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
/// APB2 peripheral clock (USART1, ADC).
#[cfg(not(feature = "qemu"))]
pub const PCLK2_HZ: u32 = 84_000_000;
/// APB2 peripheral clock at reset.
#[cfg(feature = "qemu")]
pub const PCLK2_HZ: u32 = 16_000_000;

/// PWM frequency and current-loop rate, Hz.
pub const PWM_HZ: u32 = TUNING.pwm_hz;
/// Speed-loop rate, Hz.
pub const SPEED_HZ: u32 = TUNING.speed_hz;
/// Watchdog tick rate, Hz (the ladder's time base: one tick = 1 ms).
pub const TICK_HZ: u32 = TUNING.tick_hz;

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
const _: () = assert!(SPEED_HZ.is_multiple_of(TICK_HZ) && PWM_HZ.is_multiple_of(SPEED_HZ));

const _: () = assert!(APB2_TIMER_HZ == TUNING.pwm_timer_hz || cfg!(feature = "qemu"));

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

impl Pins {
    /// Gate-driver fault line active.
    pub fn driver_fault(&self) -> bool {
        !cfg!(feature = "qemu") && self.n_fault.is_low()
    }

    /// Over-temperature warning line active.
    pub fn thermal_warning(&self) -> bool {
        !cfg!(feature = "qemu") && self.n_otw.is_low()
    }

    /// Holding-brake release output (high releases the spring-applied brake).
    pub fn set_brake_release(&mut self, released: bool) {
        if released {
            self.brake_release.set_high();
        } else {
            self.brake_release.set_low();
        }
    }
}

/// The ESTOP input's level, read from the tick without owning the pin (a GPIO input read).
pub fn estop_pressed() -> bool {
    // SAFETY: a read of GPIOD's input data register; nothing is written.
    let idr = unsafe { (*pac::GPIOD::ptr()).idr().read().bits() };
    !cfg!(feature = "qemu") && idr & (1 << 4) != 0
}

/// The link's chip select as an interrupt source (EXTI12, rising edge = end of a transaction).
pub struct NssPin(stm32f4xx_hal::gpio::PB12<stm32f4xx_hal::gpio::Alternate<5>>);

impl NssPin {
    /// Clears the EXTI pending bit (first thing in the handler).
    pub fn clear(&mut self) {
        use stm32f4xx_hal::gpio::ExtiPin;
        self.0.clear_interrupt_pending_bit();
    }
}

/// The local ESTOP input (EXTI4): a normally-closed contact to ground with a pull-up, so a
/// pressed button and a cut wire both read high.
pub struct EstopPin(stm32f4xx_hal::gpio::PD4<stm32f4xx_hal::gpio::Input>);

impl EstopPin {
    /// PD4 as the ESTOP input: pull-up, interrupt on both edges (every board has it).
    pub fn new(
        pin: stm32f4xx_hal::gpio::PD4,
        syscfg: &mut stm32f4xx_hal::syscfg::SysCfg,
        exti: &mut pac::EXTI,
    ) -> Self {
        use stm32f4xx_hal::gpio::{Edge, ExtiPin};
        let mut estop = pin.into_pull_up_input();
        estop.make_interrupt_source(syscfg);
        estop.trigger_on_edge(exti, Edge::RisingFalling);
        estop.enable_interrupt(exti);
        Self(estop)
    }

    /// True while pressed (or the loop is open).
    pub fn pressed(&self) -> bool {
        self.0.is_high()
    }

    /// Clears the EXTI pending bit (first thing in the handler).
    pub fn clear(&mut self) {
        use stm32f4xx_hal::gpio::ExtiPin;
        self.0.clear_interrupt_pending_bit();
    }
}

/// Everything `init` hands to the tasks.
pub struct Board {
    /// Both H-bridges.
    pub bridge: Bridge,
    /// Both encoders.
    pub encoders: Encoders,
    /// Shunt ADC.
    pub adc: CurrentSense,
    /// The link to the host.
    pub link: LinkHw,
    /// The local ESTOP input.
    pub estop: EstopPin,
    /// The link's chip select, for resynchronisation.
    pub nss: NssPin,
    /// 1 kHz tick timer.
    pub tick: Periodic<pac::TIM2>,
    /// 10 kHz speed-loop timer.
    pub speed: Periodic<pac::TIM5>,
    /// Enable outputs and fault inputs.
    pub pins: Pins,
}

/// The clock tree of every image: HSE 8 MHz → PLL → 168 MHz, APB1 42 MHz, APB2 84 MHz, with the
/// clock security system on (board); left at reset (HSI 16 MHz) under the emulator, whose RCC is
/// not modelled.
pub fn clocks(rcc: pac::RCC) -> stm32f4xx_hal::rcc::Rcc {
    use stm32f4xx_hal::prelude::*;
    use stm32f4xx_hal::rcc::Config;
    #[cfg(not(feature = "qemu"))]
    {
        let cfg = Config::hse(8.MHz())
            .sysclk(SYSCLK_HZ.Hz())
            .hclk(SYSCLK_HZ.Hz())
            .pclk1(42.MHz())
            .pclk2(84.MHz());
        // OTG FS needs 48 MHz from the main PLL (VCO 336 MHz: P = 2 for 168 MHz, Q = 7 for 48).
        #[cfg(feature = "usb")]
        let cfg = cfg.require_pll48clk();
        let rcc = rcc.freeze(cfg);
        clock::enable_css(&rcc);
        rcc
    }
    #[cfg(feature = "qemu")]
    {
        let _ = Config::hsi();
        rcc.constrain()
    }
}

/// Brings up clocks, pins and peripherals with the bridge braked. The gate driver stays disabled
/// while the pins are configured and is enabled last, once both timers hold their outputs forced
/// inactive: BRAKE itself (low sides on) needs a powered gate driver.
pub fn init(
    dp: pac::Peripherals,
    rx: &'static mut [[u8; FRAME_LEN]; 2],
    tx: &'static mut [[u8; FRAME_LEN]; 2],
) -> (Board, pac::IWDG, pac::DBGMCU) {
    use stm32f4xx_hal::gpio::{Edge, ExtiPin};
    use stm32f4xx_hal::prelude::*;

    let mut rcc = clocks(dp.RCC);

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
    let mut syscfg = dp.SYSCFG.constrain(&mut rcc);
    let mut exti = dp.EXTI;
    let estop = EstopPin::new(gpiod.pd4, &mut syscfg, &mut exti);
    // NSS stays in its SPI function; the EXTI still sees its level.
    let mut nss = gpiob.pb12.into_alternate::<5>();
    nss.make_interrupt_source(&mut syscfg);
    nss.trigger_on_edge(&mut exti, Edge::Rising);
    nss.enable_interrupt(&mut exti);

    let rcc_regs: &mut pac::RCC = &mut rcc;
    let bridge = Bridge::new(dp.TIM1, dp.TIM8, rcc_regs);
    let encoders = Encoders::new(dp.TIM3, dp.TIM4, rcc_regs);
    let adc = CurrentSense::new(dp.ADC1, &dp.ADC_COMMON, rcc_regs);
    let link = LinkHw::new(dp.SPI2, dp.DMA1, rx, tx, rcc_regs);
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
        gpiob.pb13.into_alternate::<5>(),
        gpioc.pc2.into_alternate::<5>(),
        gpioc.pc3.into_alternate::<5>(),
    );
    // Every PWM pin now follows a timer that holds it braked: power the gate driver so the
    // low sides conduct (dynamic brake) until the host arms the drive.
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
            estop,
            nss: NssPin(nss),
            tick,
            speed,
            pins,
        },
        dp.IWDG,
        dp.DBGMCU,
    )
}

/// Emulator hooks that stand in for the triggers QEMU does not model; nothing on the board.
#[cfg(not(feature = "qemu"))]
pub mod hooks {
    /// After a speed-loop sample (the ADC trigger on the board is TIM1_CC4).
    pub fn after_speed_sample() {}
    /// After a tick (the host clocks the SPI transactions on the board).
    pub fn after_tick(
        _ticks: u32,
        _out: &statemachine::Output<{ mcu::AXES }>,
        _safety: &mcu::Safety,
    ) {
    }
}
#[cfg(feature = "qemu")]
pub use emu::hooks;

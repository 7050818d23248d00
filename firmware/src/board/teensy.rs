//! The seed 003 board (`teensy` image): a four-joint arm on step/direction stepper drivers, an end
//! effector output, and the robust COBS + CRC link on USART1.
//!
//! # Pin map (STM32F407VGT6)
//!
//! | function                          | pin          | peripheral / AF          | notes                                         |
//! |-----------------------------------|--------------|--------------------------|-----------------------------------------------|
//! | joint 1 … 4 STEP                  | PE0 … PE3    | output                   | one pulse per step, ≥ 50 µs high              |
//! | joint 1 … 4 DIR                   | PE4 … PE7    | output                   | high = positive; set ≥ 0.7 µs before STEP     |
//! | drivers nENABLE (all four)        | PE8          | output                   | low = enabled (holding torque); external pull-up: off in reset |
//! | end effector                      | PE9          | output                   | high = on                                     |
//! | ESTOP loop                        | PD4          | input, pull-up, EXTI4    | as on every board                              |
//! | link TX / RX                      | PA9 / PA10   | USART1, AF7, 115 200 8N1 |                                               |
//! | SWD                               | PA13 / PA14  |                          | probe-rs, defmt over RTT                      |
//!
//! ```text
//!  TIM5  10 kHz step_gen       (mcu::teensy::StepGen: at most one step per joint per run)
//!  TIM2  1 kHz  watchdog_tick  (ladder tick, joint profiles, step targets)
//!  IWDG  20 ms nominal, fed by the tick
//! ```
//! Steppers: 200 full steps, 8 microsteps (`mcu::teensy::STEPS_PER_REV`).

use super::regs::*;
use mcu::teensy::{StepPulse, JOINTS};
use stm32f4xx_hal::pac;
use stm32f4xx_hal::rcc::Enable;

const STEP_MASK: u32 = 0x000F;
/// DIR of joint 1 on PE4, joint k on PE(3 + k).
const DIR_SHIFT: u32 = 4;
const NENABLE: u32 = 1 << 8;
const END_EFFECTOR: u32 = 1 << 9;
/// Core cycles between DIR and STEP: 0.7 µs at 168 MHz is 118.
const DIR_SETUP_CYCLES: u32 = 120;

const _: () = assert!(super::SPEED_HZ == mcu::teensy::STEP_HZ);

/// The step and direction lines of the four drivers.
pub struct Steppers {
    gpioe: pac::GPIOE,
}

impl Steppers {
    /// PE0 … PE9 as outputs: STEP low, drivers enabled (holding), end effector off.
    pub fn new(gpioe: pac::GPIOE, rcc: &mut pac::RCC) -> Self {
        pac::GPIOE::enable(rcc);
        wr(gpioe.bsrr(), (STEP_MASK | NENABLE | END_EFFECTOR) << 16);
        rmw(gpioe.moder(), 0xF_FFFF, 0x5_5555);
        Self { gpioe }
    }

    /// One run of the step generator: every STEP line low (ending the last pulse, 100 µs high),
    /// the DIR lines of the joints that step, then their STEP lines high.
    pub fn pulse(&mut self, p: &[StepPulse; JOINTS]) {
        wr(self.gpioe.bsrr(), STEP_MASK << 16);
        let (mut dir_set, mut dir_reset, mut step) = (0u32, 0u32, 0u32);
        for ((s, stp), dir) in p.iter().zip([1u32, 1 << 1, 1 << 2, 1 << 3]).zip([
            1u32 << DIR_SHIFT,
            1 << 5,
            1 << 6,
            1 << 7,
        ]) {
            match s {
                StepPulse::Idle => continue,
                StepPulse::Forward => dir_set |= dir,
                StepPulse::Backward => dir_reset |= dir,
            }
            step |= stp;
        }
        if step == 0 {
            return;
        }
        wr(self.gpioe.bsrr(), dir_set | (dir_reset << 16));
        cortex_m::asm::delay(DIR_SETUP_CYCLES);
        wr(self.gpioe.bsrr(), step);
    }
}

/// The end-effector output (PE9), written through the atomic set/reset register beside the step
/// lines' owner.
pub struct EndEffector;

impl EndEffector {
    /// Switches the end effector.
    pub fn set(&mut self, on: bool) {
        let bit = if on { END_EFFECTOR } else { END_EFFECTOR << 16 };
        // SAFETY: BSRR is write-only and each write changes only the lines whose bits are set:
        // this touches PE9 alone, which nothing else drives; the write cannot disturb the step
        // lines written by `Steppers` from a higher priority.
        unsafe { (*pac::GPIOE::ptr()).bsrr().write(|w| w.bits(bit)) };
    }
}

/// Everything `init` hands to the tasks of the `teensy` image.
pub struct TeensyBoard {
    /// Step and direction lines.
    pub steppers: Steppers,
    /// The end effector.
    pub end_effector: EndEffector,
    /// The local ESTOP input.
    pub estop: super::EstopPin,
    /// The link.
    pub uart: super::uart::Uart,
    /// 1 kHz tick timer.
    pub tick: super::Periodic<pac::TIM2>,
    /// 10 kHz step timer.
    pub step: super::Periodic<pac::TIM5>,
}

/// Brings up the seed 003 board with every joint holding where it stands.
pub fn init(dp: pac::Peripherals) -> (TeensyBoard, pac::IWDG, pac::DBGMCU) {
    use stm32f4xx_hal::prelude::*;
    let mut rcc = super::clocks(dp.RCC);
    let gpioa = dp.GPIOA.split(&mut rcc);
    let gpiod = dp.GPIOD.split(&mut rcc);
    let mut syscfg = dp.SYSCFG.constrain(&mut rcc);
    let mut exti = dp.EXTI;
    let estop = super::EstopPin::new(gpiod.pd4, &mut syscfg, &mut exti);
    let rcc_regs: &mut pac::RCC = &mut rcc;
    let steppers = Steppers::new(dp.GPIOE, rcc_regs);
    let uart = super::uart::Uart::new(dp.USART1, rcc_regs);
    let tick = super::Periodic::<pac::TIM2>::new(dp.TIM2, rcc_regs);
    let step = super::Periodic::<pac::TIM5>::new(dp.TIM5, rcc_regs);
    let _ = (
        gpioa.pa9.into_alternate::<7>(),
        gpioa.pa10.into_alternate::<7>(),
    );
    (
        TeensyBoard {
            steppers,
            end_effector: EndEffector,
            estop,
            uart,
            tick,
            step,
        },
        dp.IWDG,
        dp.DBGMCU,
    )
}

/// Renders a trace code (a step target).
pub fn trace_token(code: i32) -> super::trace::Token {
    super::trace::Token::Num(code)
}

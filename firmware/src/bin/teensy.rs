//! The `teensy` image (seed 003): the RTIC shell around the seed 003 board application
//! (`mcu::teensy`). Board: `firmware::board::teensy` (pin map, timers).
//!
//! ```text
//!  priority 5  estop_input    EXTI4 (PD4, both edges)  mcu::EstopInput::edge_then  step generator halted in the handler
//!  priority 3  step_gen       TIM5 update     10 kHz   mcu::teensy::StepGen::run   at most one step per joint
//!  priority 2  link_usart     USART1 (RXNE, TXE)       mcu::teensy::TeensyLinkTask::on_byte  byte → ladder → echo queued
//!  priority 2  watchdog_tick  TIM2 update      1 kHz   mcu::serial::tick, mcu::teensy::drive_joints  → step targets, IWDG
//!  idle        wfi
//! ```
//!
//! The ladder (`mcu::Safety<4>`) and the joint profiles are shared only by the two priority-2
//! tasks (`#[lock_free]`). Only the tick moves the step targets; the ESTOP handler can only halt
//! the step generator.
#![no_std]
#![no_main]
#![deny(unsafe_code)]

use firmware as _;

#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true)]
mod app {
    use firmware::board::teensy::{self, EndEffector, Steppers};
    use firmware::board::trace::Trace;
    use firmware::board::uart::Uart;
    use firmware::board::{self, EstopPin, Iwdg, Periodic};
    use mcu::serial::SerialTickInputs;
    use mcu::teensy::{BoardAction, Joints, StepGen, TeensyLinkTask, JOINTS};
    use mcu::{EstopInput, Safety};
    use statemachine::{Config, Position};
    use stm32f4xx_hal::pac;

    /// The arm's profile.
    const CONFIG: Config = Config::TEENSY;

    #[shared]
    struct Shared {
        /// Step counts and targets (ceiling 5).
        stepgen: StepGen,
        /// The local ESTOP input's latch (ceiling 5).
        estop: EstopInput,
        /// Ladder, tick count and trace, shared by the priority-2 tasks only.
        #[lock_free]
        safety: Safety<JOINTS>,
        /// The joints' profiles, shared by the priority-2 tasks only.
        #[lock_free]
        joints: Joints,
        /// The link task's state and its transmit queue, priority 2 only.
        #[lock_free]
        link: TeensyLinkTask,
        /// USART1, priority 2 only.
        #[lock_free]
        uart: Uart,
    }

    #[local]
    struct Local {
        estop_pin: EstopPin,
        steppers: Steppers,
        end_effector: EndEffector,
        tick_timer: Periodic<pac::TIM2>,
        step_timer: Periodic<pac::TIM5>,
        iwdg: Iwdg,
        trace: Trace,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        let boot = firmware::panic::boot(&cx.device.RCC);
        let (b, iwdg, dbg) = teensy::init(cx.device);
        let iwdg = Iwdg::start(iwdg, &dbg);
        defmt::info!(
            "teensy firmware up: reset {} (count {=u32}, panic line {=u32}); BRAKE latched until CAL",
            boot.cause,
            boot.count,
            boot.panic_line
        );
        // The joints start where the arm is at power-on: its zero (the seed's calibration pose).
        let joints = Joints::new([Position::ZERO; JOINTS], &CONFIG);
        (
            Shared {
                stepgen: StepGen::new(joints.step_targets()),
                estop: EstopInput::new(),
                safety: Safety::new(CONFIG),
                joints,
                link: TeensyLinkTask::new(),
                uart: b.uart,
            },
            Local {
                estop_pin: b.estop,
                steppers: b.steppers,
                end_effector: b.end_effector,
                tick_timer: b.tick,
                step_timer: b.step,
                iwdg,
                trace: Trace::new(),
            },
        )
    }

    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// ESTOP input. Priority 5 (highest), both edges of PD4: a press halts the step generator in
    /// this handler; the next tick latches ESTOP in the ladder.
    #[task(binds = EXTI4, priority = 5, shared = [stepgen, estop], local = [estop_pin])]
    fn estop_input(cx: estop_input::Context) {
        cx.local.estop_pin.clear();
        let pressed = cx.local.estop_pin.pressed();
        (cx.shared.stepgen, cx.shared.estop).lock(|g, e| e.edge_then(pressed, || g.halt()));
    }

    /// Step generator. Priority 3, 10 kHz: TIM5 update.
    #[task(binds = TIM5, priority = 3, shared = [stepgen], local = [step_timer, steppers])]
    fn step_gen(mut cx: step_gen::Context) {
        cx.local.step_timer.clear();
        let p = cx.shared.stepgen.lock(|g| g.run());
        cx.local.steppers.pulse(&p);
    }

    /// Link bytes in and out. Priority 2, USART1 (RXNE per received byte, TXE while echoes wait).
    #[task(binds = USART1, priority = 2, shared = [safety, joints, link, uart],
           local = [end_effector])]
    fn link_usart(cx: link_usart::Context) {
        let (safety, joints, link, uart) = (
            cx.shared.safety,
            cx.shared.joints,
            cx.shared.link,
            cx.shared.uart,
        );
        while let Some(b) = uart.read() {
            match link.on_byte(safety, b) {
                Some((_, BoardAction::EndEffector(on))) => cx.local.end_effector.set(on),
                Some((_, BoardAction::Accel(a))) => joints.set_accel(a),
                Some((_, BoardAction::None)) | None => {}
            }
        }
        uart.pump(&mut link.tx);
    }

    /// Watchdog tick. Priority 2, 1 kHz: TIM2 update, the ladder's time base.
    #[task(binds = TIM2, priority = 2, shared = [safety, joints, stepgen, estop, link, uart],
           local = [tick_timer, iwdg, trace])]
    fn watchdog_tick(mut cx: watchdog_tick::Context) {
        cx.local.tick_timer.clear();
        let inputs = SerialTickInputs {
            estop: cx.shared.estop.lock(|e| e.poll(board::estop_pressed())),
            undervoltage: false,
        };
        let safety = cx.shared.safety;
        let out = mcu::serial::tick(safety, &inputs);
        let joints = cx.shared.joints;
        let targets = (cx.shared.stepgen, cx.shared.estop)
            .lock(|g, e| mcu::teensy::drive_joints(joints, g, &out.drive, e.press_pending()));
        cx.shared.uart.pump(&mut cx.shared.link.tx);
        cx.local.iwdg.feed();
        cx.local
            .trace
            .tick(safety.ticks(), &out, safety, targets, teensy::trace_token);
    }
}

//! The `cdc` image (seed 001; USART1, or USB CDC ACM with feature `usb`): the RTIC shell around the seed 001 board application
//! (`mcu::cdc`). Board: `firmware::board::cdc` (pin map, timers, sensors).
//!
//! ```text
//!  priority 5  estop_input    EXTI4 (PD4, both edges)  mcu::EstopInput::edge_then  every motor shorted in the handler
//!  priority 2  link_usart     USART1 (RXNE, TXE)       mcu::cdc::CdcLinkTask::on_byte  byte → ladder → ACK/STATUS queued;
//!                                                       mcu::cdc::outputs_after_frame   a frame that braked (ESTOP): motors shorted at once
//!  (priority 2  link_usb      OTG_FS, feature `usb`:   the same body over USB CDC ACM)
//!  priority 2  watchdog_tick  TIM2 update      1 kHz   mcu::serial::tick, mcu::cdc::motor_outputs  → CCR, IN1/IN2, IWDG
//!  priority 1  imu_read       TIM3 update    100 Hz    mcu::cdc::imu_from_raw  MPU6050, battery → IMU_MPU6050
//!  idle        wfi
//! ```
//!
//! The ladder (`mcu::Safety<4>`) is shared only by the two priority-2 tasks, which never preempt
//! each other (`#[lock_free]`). A frame never moves the motors: only the tick drives them; the ESTOP
//! handler and a frame that braked the ladder (`ESTOP 1`) can only short them.
#![no_std]
#![no_main]
#![deny(unsafe_code)]

use firmware as _;

#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true)]
mod app {
    use firmware::board::cdc::{self, Imu, Motors, Port, Vbat, PWM_FULL};
    use firmware::board::trace::Trace;
    use firmware::board::{self, EstopPin, Iwdg, Periodic};
    use mcu::cdc::{
        imu_from_raw, motor_outputs, outputs_after_frame, BoardStatus, CdcLinkTask, IMU_SCALE,
        MOTORS,
    };
    use mcu::serial::SerialTickInputs;
    use mcu::{EstopInput, Safety};
    use stm32f4xx_hal::pac;

    #[shared]
    struct Shared {
        /// The four motor outputs (ceiling 5).
        motors: Motors,
        /// The local ESTOP input's latch (ceiling 5).
        estop: EstopInput,
        /// Ladder, tick count and trace, shared by the priority-2 tasks only.
        #[lock_free]
        safety: Safety<MOTORS>,
        /// The link task's state and its transmit queue (ceiling 2).
        link: CdcLinkTask,
        /// The link: USART1, or USB CDC ACM with feature `usb` (ceiling 2).
        port: Port,
        /// What STATUS reports of the board (ceiling 2).
        status: BoardStatus,
    }

    #[local]
    struct Local {
        estop_pin: EstopPin,
        tick_timer: Periodic<pac::TIM2>,
        imu_timer: Periodic<pac::TIM3>,
        imu: Imu,
        vbat: Vbat,
        iwdg: Iwdg,
        trace: Trace,
        imu_saturated: u32,
    }

    #[init(local = [port_mem: cdc::PortMem = cdc::PORT_MEM_INIT])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let boot = firmware::panic::boot(&cx.device.RCC);
        let (b, iwdg, dbg) = cdc::init(cx.device, cx.local.port_mem);
        let iwdg = Iwdg::start(iwdg, &dbg);
        defmt::info!(
            "cdc firmware up: reset {} (count {=u32}, panic line {=u32}); BRAKE latched until MOTOR_ENABLE",
            boot.cause,
            boot.count,
            boot.panic_line
        );
        (
            Shared {
                motors: b.motors,
                estop: EstopInput::new(),
                safety: Safety::new(statemachine::Config::CDC),
                link: CdcLinkTask::new(),
                port: b.port,
                status: BoardStatus::default(),
            },
            Local {
                estop_pin: b.estop,
                tick_timer: b.tick,
                imu_timer: b.imu_timer,
                imu: b.imu,
                vbat: b.vbat,
                iwdg,
                trace: Trace::new(),
                imu_saturated: 0,
            },
        )
    }

    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// ESTOP input. Priority 5 (highest), both edges of PD4: a press shorts every motor in this
    /// handler; the next tick latches ESTOP in the ladder.
    #[task(binds = EXTI4, priority = 5, shared = [motors, estop], local = [estop_pin])]
    fn estop_input(cx: estop_input::Context) {
        cx.local.estop_pin.clear();
        let pressed = cx.local.estop_pin.pressed();
        (cx.shared.motors, cx.shared.estop).lock(|m, e| e.edge_then(pressed, || m.brake()));
    }

    /// Link bytes in and out. Priority 2, USART1 (RXNE per received byte, TXE while replies wait).
    #[cfg(not(feature = "usb"))]
    #[task(binds = USART1, priority = 2, shared = [safety, link, port, status, motors])]
    fn link_usart(cx: link_usart::Context) {
        let safety = cx.shared.safety;
        let mut status = cx.shared.status;
        let mut motors = cx.shared.motors;
        let st = status.lock(|s| *s);
        (cx.shared.link, cx.shared.port).lock(|link, uart| {
            while let Some(b) = uart.read() {
                if let Some(m) = link
                    .on_byte(safety, b, &st)
                    .and_then(|out| outputs_after_frame(&out, PWM_FULL))
                {
                    motors.lock(|motors| motors.set(&m));
                }
            }
            uart.pump(&mut link.tx);
        });
    }

    /// Link bytes in and out over USB (feature `usb`). Priority 2, OTG FS (every USB event).
    #[cfg(feature = "usb")]
    #[task(binds = OTG_FS, priority = 2, shared = [safety, link, port, status, motors])]
    fn link_usb(cx: link_usb::Context) {
        let safety = cx.shared.safety;
        let mut status = cx.shared.status;
        let mut motors = cx.shared.motors;
        let st = status.lock(|s| *s);
        (cx.shared.link, cx.shared.port).lock(|link, usb| {
            usb.poll(|b| {
                if let Some(m) = link
                    .on_byte(safety, b, &st)
                    .and_then(|out| outputs_after_frame(&out, PWM_FULL))
                {
                    motors.lock(|motors| motors.set(&m));
                }
            });
            usb.pump(&mut link.tx);
        });
    }

    /// Watchdog tick. Priority 2, 1 kHz: TIM2 update, the ladder's time base.
    #[task(binds = TIM2, priority = 2, shared = [safety, motors, estop, link, port, status],
           local = [tick_timer, iwdg, trace])]
    fn watchdog_tick(mut cx: watchdog_tick::Context) {
        cx.local.tick_timer.clear();
        let inputs = SerialTickInputs {
            estop: cx.shared.estop.lock(|e| e.poll(board::estop_pressed())),
            undervoltage: false,
        };
        let safety = cx.shared.safety;
        let out = mcu::serial::tick(safety, &inputs);
        let outs = motor_outputs(&out.drive, PWM_FULL);
        (cx.shared.motors, cx.shared.estop).lock(|m, e| {
            if e.press_pending() {
                m.brake();
            } else {
                m.set(&outs);
            }
        });
        let t_ms = safety.ticks();
        let st = cx.shared.status.lock(|s| {
            s.t_ms = t_ms;
            *s
        });
        (cx.shared.link, cx.shared.port).lock(|l, u| {
            l.periodic(safety, &st);
            u.pump(&mut l.tx);
        });
        cx.local.iwdg.feed();
        cx.local.trace.tick(
            t_ms,
            &out,
            safety,
            cdc::trace_codes(&outs),
            cdc::trace_token,
        );
    }

    /// IMU and battery. Priority 1, 100 Hz: TIM3 update. The I2C read blocks only this task.
    #[task(binds = TIM3, priority = 1, shared = [link, port, status],
           local = [imu_timer, imu, vbat, imu_saturated])]
    fn imu_read(mut cx: imu_read::Context) {
        cx.local.imu_timer.clear();
        let vbat_mv = cx.local.vbat.read_mv().unwrap_or(0);
        let raw = cx.local.imu.read();
        let t_ms = cx.shared.status.lock(|s| {
            s.vbat_mv = vbat_mv;
            s.imu_ok = raw.is_some();
            s.t_ms
        });
        if let Some((accel, temp, gyro)) = raw {
            let (imu, saturated) = imu_from_raw(t_ms, accel, temp, gyro, &IMU_SCALE);
            if saturated {
                *cx.local.imu_saturated = cx.local.imu_saturated.saturating_add(1);
                defmt::warn!(
                    "IMU reading beyond the seed's i16 range, reported at its limit ({=u32} so far)",
                    *cx.local.imu_saturated
                );
            }
            (cx.shared.link, cx.shared.port).lock(|l, u| {
                l.send_imu(&imu);
                u.pump(&mut l.tx);
            });
        }
    }
}

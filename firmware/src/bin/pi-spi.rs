//! The `pi-spi` image (seed 004; SPI2 slave to a Raspberry Pi): the RTIC shell around the seed 004
//! board application (`mcu::pi_spi`). Board: `firmware::board::pi_spi` (pin map, timers, sensors).
//!
//! ```text
//!  priority 5  estop_input    EXTI4 (PD4, both edges)   mcu::EstopInput::edge_then   every motor shorted in the handler
//!  priority 2  spi_dma_done   DMA1_STREAM3 (RX TC)      mcu::pi_spi::PiSpiApp::on_transfer
//!                                                       shutdown bits first: motors shorted, servos off before it returns;
//!                                                       version, parity, decode → ladder; updates; the next TxBuffer
//!  priority 2  spi_nss_rise   EXTI15_10 (PB12 rising)   PiSpiApp::transfer_cut        a cut transaction: resync, counted
//!  priority 2  watchdog_tick  TIM7 update      1 kHz    mcu::pi_spi::PiSpiApp::tick   ladder tick → motor loops → TIM8, IN lines;
//!                                                       servos → TIM1, rail; IWDG; pends imu_read every 10th tick
//!  priority 1  imu_read       UART4 vector (pended)     PiSpiApp::imu_sample          MPU6050 and ADC scan (blocking, lowest priority)
//!  idle        wfi
//! ```
//!
//! The ladder (`mcu::Safety<4>`) and the link hardware are shared only by the priority-2 tasks,
//! which never preempt each other (`#[lock_free]`). Under the `qemu` feature SysTick stands in for
//! TIM7 and the tick pends the link task once per tick (one record of the host file).
#![no_std]
#![no_main]
#![deny(unsafe_code)]

use firmware as _;

#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true)]
mod app {
    use firmware::board::cdc::{trace_codes, trace_token, PWM_FULL};
    use firmware::board::pi_spi::{
        self, hooks, Analog, AnalogReading, DigitalInputs, Encoders, Imu, Motors, PiLink,
        PiSpiBoard, Servos, UsClock, IMU_IRQ, IMU_PERIOD_TICKS, TRANSFER_LEN,
    };
    use firmware::board::trace::Trace;
    use firmware::board::{self, EstopPin, Iwdg, NssPin, Periodic};
    use mcu::pi_spi::{PiSpiApp, PiSpiTickInputs, ServoOutputs, MOTORS, TUNING};
    use mcu::serial::SerialTickInputs;
    use mcu::{EstopInput, Safety};
    use statemachine::{Config, Drive};
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
        /// SPI2 and its DMA streams, priority-2 tasks only.
        #[lock_free]
        link_hw: PiLink,
        /// The board application (ceiling 2: the IMU task locks it).
        app: PiSpiApp,
        /// The servo outputs and the rail (ceiling 2).
        servos: Servos,
        /// The last ADC scan (ceiling 2).
        analog: AnalogReading,
    }

    #[local]
    struct Local {
        estop_pin: EstopPin,
        nss: NssPin,
        tick_timer: Periodic<pac::TIM7>,
        clock: UsClock,
        encoders: Encoders,
        inputs: DigitalInputs,
        adc: Analog,
        imu: Imu,
        iwdg: Iwdg,
        trace: Trace,
    }

    #[init(local = [
        rx_buf: [[u8; TRANSFER_LEN]; 2] = [[0; TRANSFER_LEN]; 2],
        tx_buf: [[u8; TRANSFER_LEN]; 2] = [[0; TRANSFER_LEN]; 2],
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let boot = firmware::panic::boot(&cx.device.RCC);
        let (b, iwdg, dbg) = pi_spi::init(cx.device, cx.local.rx_buf, cx.local.tx_buf);
        let PiSpiBoard {
            motors,
            servos,
            encoders,
            analog,
            inputs,
            imu,
            link,
            estop,
            nss,
            tick,
            clock,
        } = b;
        #[cfg(feature = "qemu")]
        hooks::start_tick(cx.core.SYST);
        #[cfg(not(feature = "qemu"))]
        let _ = cx.core;
        let iwdg = Iwdg::start(iwdg, &dbg);
        defmt::info!(
            "pi-spi firmware up: reset {} (count {=u32}, panic line {=u32}); BRAKE latched until a shutdown transfer and a clear one",
            boot.cause,
            boot.count,
            boot.panic_line
        );
        (
            Shared {
                motors,
                estop: EstopInput::new(),
                safety: Safety::new(Config::PI_SPI),
                link_hw: link,
                app: PiSpiApp::new(
                    &Config::PI_SPI,
                    &TUNING,
                    pi_spi::TICK_HZ / IMU_PERIOD_TICKS,
                    PWM_FULL,
                ),
                servos,
                analog: AnalogReading::default(),
            },
            Local {
                estop_pin: estop,
                nss,
                tick_timer: tick,
                clock,
                encoders,
                inputs,
                adc: analog,
                imu,
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

    /// ESTOP input. Priority 5 (highest), both edges of PD4: a press shorts every motor in this
    /// handler; the next tick latches ESTOP in the ladder.
    #[task(binds = EXTI4, priority = 5, shared = [motors, estop], local = [estop_pin])]
    fn estop_input(cx: estop_input::Context) {
        cx.local.estop_pin.clear();
        let pressed = cx.local.estop_pin.pressed();
        (cx.shared.motors, cx.shared.estop).lock(|m, e| e.edge_then(pressed, || m.brake()));
    }

    /// A transfer completed. Priority 2, DMA1 stream 3 transfer complete (one per 179-byte
    /// transaction): the shutdown bits act before this handler returns.
    #[task(binds = DMA1_STREAM3, priority = 2,
           shared = [safety, link_hw, app, motors, servos], local = [clock, inputs])]
    fn spi_dma_done(cx: spi_dma_done::Context) {
        let link_hw = cx.shared.link_hw;
        let Some(rx) = link_hw.take_rx() else {
            return;
        };
        let safety = cx.shared.safety;
        let now = cx.local.clock.micros(safety.ticks());
        let digital = cx.local.inputs.read();
        let mut tx = [0u8; TRANSFER_LEN];
        let mut app = cx.shared.app;
        let o = app.lock(|a| a.on_transfer(safety, &rx, now, digital, &mut tx));
        if o.motors_off {
            let mut motors = cx.shared.motors;
            motors.lock(|m| m.brake());
        }
        let mut servos = cx.shared.servos;
        servos.lock(|s| apply_servos(s, &o.servos));
        link_hw.put_tx(&tx);
    }

    /// The chip select rose. Priority 2, EXTI12 (PB12 rising edge): a transaction cut short
    /// re-arms the link at a transfer boundary and counts as a framing refusal.
    #[task(binds = EXTI15_10, priority = 2, shared = [safety, link_hw, app], local = [nss])]
    fn spi_nss_rise(mut cx: spi_nss_rise::Context) {
        cx.local.nss.clear();
        if cx.shared.link_hw.resync_if_cut() {
            let safety = cx.shared.safety;
            cx.shared.app.lock(|a| a.transfer_cut(safety));
        }
    }

    /// Watchdog tick. Priority 2, 1 kHz: TIM7 update (SysTick under the emulator), the ladder's
    /// time base and the motor loops' rate.
    #[task(binds = TIM7, priority = 2,
           shared = [safety, app, motors, estop, servos, analog],
           local = [tick_timer, encoders, iwdg, trace])]
    fn watchdog_tick(mut cx: watchdog_tick::Context) {
        cx.local.tick_timer.clear();
        let estop_change = cx.shared.estop.lock(|e| e.poll(board::estop_pressed()));
        let a = cx.shared.analog.lock(|a| *a);
        let inputs = PiSpiTickInputs {
            serial: SerialTickInputs {
                estop: estop_change,
                undervoltage: false,
            },
            counts: cx.local.encoders.read(),
            analog: a.analog.map(as_i16),
            battery: as_i16(a.battery),
        };
        let safety = cx.shared.safety;
        let pending = cx.shared.estop.lock(|e| e.press_pending());
        let o = cx.shared.app.lock(|app| app.tick(safety, pending, &inputs));
        // An ESTOP press after the poll keeps the motors shorted (its handler shorted them).
        (cx.shared.motors, cx.shared.estop).lock(|m, e| {
            if e.press_pending() {
                m.brake();
            } else {
                m.set(&o.motors);
            }
        });
        cx.shared.servos.lock(|s| apply_servos(s, &o.servos));
        cx.local.iwdg.feed();
        let t = safety.ticks();
        if t % IMU_PERIOD_TICKS == 0 {
            rtic::pend(IMU_IRQ);
        }
        cx.local
            .trace
            .tick(t, &o.out, safety, trace_codes(&o.motors), trace_token);
        hooks::after_tick(t, o.out.drive == Drive::Brake);
    }

    /// Emulator only: SysTick at 1 kHz stands in for TIM7, which QEMU does not run.
    #[cfg(feature = "qemu")]
    #[task(binds = SysTick, priority = 1)]
    fn emu_tick(_: emu_tick::Context) {
        rtic::pend(pac::Interrupt::TIM7);
    }

    /// IMU and analog inputs. Priority 1, 100 Hz: the UART4 vector, pended by the tick. The I2C
    /// read and the ADC scan block only this task.
    #[task(binds = UART4, priority = 1, shared = [app, analog], local = [adc, imu])]
    fn imu_read(mut cx: imu_read::Context) {
        if let Some(r) = cx.local.adc.scan() {
            cx.shared.analog.lock(|a| *a = r);
        }
        let raw = cx.local.imu.read().map(|(a, t, g)| (a, g, t));
        cx.shared.app.lock(|app| app.imu_sample(raw));
    }

    /// Writes the servo outputs: every line low at once and the rail off for [`ServoOutputs::OFF`],
    /// else the pulses from the next 20 ms frame.
    fn apply_servos(s: &mut Servos, o: &ServoOutputs) {
        if *o == ServoOutputs::OFF {
            s.off();
        } else {
            s.set(o.rail_on, o.pulses_us);
        }
    }

    /// A 12-bit ADC reading as the seed's `int16_t` (always fits: ≤ 4095).
    fn as_i16(raw: u16) -> i16 {
        i16::try_from(raw & 0x0FFF).unwrap_or(i16::MAX)
    }
}

//! The `amr-spi` image (seed 000): the RTIC shell around the seed 000 board application (crate
//! `mcu`). Each task binds its interrupt to one `mcu` body and moves values between the registers
//! (the `firmware` library's `board` modules) and that body; the simulator runs the same bodies.
//!
//! ```text
//!  priority 5  estop_input    EXTI4 (PD4, both edges)  mcu::EstopInput::edge     bridge braked in the handler
//!  priority 4  current_loop   ADC JEOC (TIM1_CC4) 20 kHz mcu::CurrentLoop::run    shunts → PI → compares, trip
//!  priority 3  speed_pid      TIM5 update        10 kHz  mcu::SpeedLoop::run      encoders → ramp → PID → current refs
//!  priority 2  spi_dma_done   DMA1 stream 3 TC   1 kHz   mcu::LinkTask::on_frame  frame → ladder → feedback frame
//!  priority 2  watchdog_tick  TIM2 update        1 kHz   mcu::TickTask::run       conditions → tick → bridge → IWDG
//!  idle        wfi
//! ```
//!
//! The safety core (`mcu::Safety`: ladder, tick count, trace) is shared only by the two
//! priority-2 tasks, which never preempt each other, so it needs no lock (`#[lock_free]`). A frame
//! never moves the drive (INV-8), so only the tick writes the bridge state; the current loop and
//! the ESTOP handler can only brake it.
#![no_std]
#![no_main]
#![deny(unsafe_code)]

use firmware as _;

#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true)]
mod app {
    use firmware::board::{
        self, hooks, Board, Bridge, CurrentSense, Encoders, EstopPin, LinkHw, NssPin, Periodic,
        TickClock, FRAME_LEN, TUNING,
    };
    use mcu::tick::TickInputs;
    use mcu::{
        Amps, CurrentLoop, EstopInput, LinkTask, Measurements, Runs, Safety, SpeedLoop, TickTask,
    };
    use statemachine::Speed;
    use stm32f4xx_hal::pac;

    #[shared]
    struct Shared {
        /// Both H-bridges (ceiling 5).
        bridge: Bridge,
        /// The local ESTOP input's latch (ceiling 5).
        estop: EstopInput,
        /// What the ladder last allowed: wheel setpoints, or `None` in BRAKE (ceiling 3).
        setpoint: Option<[Speed; 2]>,
        /// Current references from the speed loop to the current loop (ceiling 4).
        current_ref: [Amps; 2],
        /// Measurements for the feedback frame and the plausibility checks (ceiling 4).
        meas: Measurements,
        /// Run counters of the control tasks, checked before each IWDG refresh (ceiling 4).
        runs: Runs,
        /// Ladder, tick count and trace, shared by the priority-2 tasks only.
        #[lock_free]
        safety: Safety,
        /// The link peripheral, shared by the two priority-2 link tasks only.
        #[lock_free]
        link_hw: LinkHw,
        /// The link task's state, shared by the two priority-2 link tasks only.
        #[lock_free]
        link: LinkTask,
    }

    #[local]
    struct Local {
        adc: CurrentSense,
        current: CurrentLoop,
        encoders: Encoders,
        speed_timer: Periodic<pac::TIM5>,
        speed: SpeedLoop,
        nss: NssPin,
        clock: TickClock,
        tick_timer: Periodic<pac::TIM2>,
        tick: TickTask,
        pins: board::Pins,
        estop_pin: EstopPin,
        iwdg: board::Iwdg,
    }

    #[init(local = [
        rx_buf: [[u8; FRAME_LEN]; 2] = [[0; FRAME_LEN]; 2],
        tx_buf: [[u8; FRAME_LEN]; 2] = [[0; FRAME_LEN]; 2],
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let boot = firmware::panic::boot(&cx.device.RCC);
        let (b, iwdg, dbg) = board::init(cx.device, cx.local.rx_buf, cx.local.tx_buf);
        let Board {
            bridge,
            encoders,
            adc,
            link,
            estop,
            nss,
            tick,
            speed,
            pins,
        } = b;
        // Zero-current readings with the bridge braked, before the watchdog starts (≤ 100 ms).
        let offsets = adc.calibrate().offsets(&TUNING);
        match offsets {
            Ok(o) => defmt::info!(
                "current sensors calibrated: zero at {=u16} / {=u16}",
                o[0],
                o[1]
            ),
            Err(e) => defmt::error!(
                "current sensor calibration refused ({}): drive stays braked",
                e
            ),
        }
        let iwdg = board::Iwdg::start(iwdg, &dbg);
        defmt::info!(
            "firmware up: reset {} (count {=u32}, panic line {=u32}); BRAKE latched until the host arms it",
            boot.cause,
            boot.count,
            boot.panic_line
        );
        (
            Shared {
                bridge,
                estop: EstopInput::new(),
                setpoint: None,
                current_ref: [Amps::ZERO; 2],
                meas: Measurements::default(),
                runs: Runs::default(),
                safety: Safety::new(TUNING.ladder),
                link_hw: link,
                link: LinkTask::new(board::identity(&boot)),
            },
            Local {
                adc,
                current: CurrentLoop::calibrated(&TUNING, offsets),
                speed: SpeedLoop::new(&TUNING, encoders.read()),
                encoders,
                speed_timer: speed,
                nss,
                clock: TickClock,
                tick_timer: tick,
                tick: TickTask::new(&TUNING),
                pins,
                estop_pin: estop,
                iwdg,
            },
        )
    }

    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// ESTOP input. Priority 5 (highest), on both edges of PD4: a press brakes the bridge in this
    /// handler, before any other task runs; the next tick latches ESTOP in the ladder.
    #[task(binds = EXTI4, priority = 5, shared = [bridge, estop], local = [estop_pin])]
    fn estop_input(cx: estop_input::Context) {
        cx.local.estop_pin.clear();
        let pressed = cx.local.estop_pin.pressed();
        (cx.shared.bridge, cx.shared.estop).lock(|b, e| e.edge(b, pressed));
    }

    /// Current loop. Priority 4, 20 kHz: the ADC injected end-of-conversion interrupt, triggered by
    /// TIM1_CC4 once per PWM period, so every sample is taken at the same point of the cycle.
    #[task(binds = ADC, priority = 4, shared = [bridge, current_ref, meas, runs],
           local = [adc, current])]
    fn current_loop(mut cx: current_loop::Context) {
        let raw = cx.local.adc.read();
        let refs = cx.shared.current_ref.lock(|r| *r);
        let current = cx.local.current;
        let s = cx.shared.bridge.lock(|b| current.run(b, raw, refs));
        cx.shared.meas.lock(|m| m.record_current(&s));
        cx.shared
            .runs
            .lock(|r| r.current = r.current.wrapping_add(1));
    }

    /// Speed loop. Priority 3, 10 kHz: TIM5 update.
    #[task(binds = TIM5, priority = 3, shared = [setpoint, current_ref, meas, runs],
           local = [speed_timer, encoders, speed])]
    fn speed_pid(mut cx: speed_pid::Context) {
        cx.local.speed_timer.clear();
        let counts = cx.local.encoders.read();
        let sp = cx.shared.setpoint.lock(|s| *s);
        let s = cx.local.speed.run(counts, sp);
        cx.shared.current_ref.lock(|c| *c = s.refs);
        cx.shared.meas.lock(|m| m.record_speed(&s));
        cx.shared.runs.lock(|r| r.speed = r.speed.wrapping_add(1));
        hooks::after_speed_sample();
    }

    /// Link frame received. Priority 2, once per SPI transaction (1 kHz from the host): DMA1
    /// stream 3 transfer complete.
    #[task(binds = DMA1_STREAM3, priority = 2, shared = [safety, link_hw, link, meas],
           local = [clock])]
    fn spi_dma_done(mut cx: spi_dma_done::Context) {
        let link_hw = cx.shared.link_hw;
        let Some(frame) = link_hw.take_rx() else {
            return;
        };
        let safety = cx.shared.safety;
        let (count, pending) = cx.local.clock.read();
        let now = safety.micros(
            count,
            pending,
            board::timers::TICK_COUNTS,
            TUNING.us_per_tick(),
        );
        let m = cx.shared.meas.lock(|m| *m);
        let mut fb = [0u8; FRAME_LEN];
        cx.shared.link.on_frame(safety, &frame, &m, now, &mut fb);
        link_hw.put_tx(&fb);
    }

    /// Link chip select released. Priority 2 (never preempts `spi_dma_done`, which has the lower
    /// IRQ number and so runs first when both are pending at the end of a frame): a transaction
    /// cut short re-arms the link at a frame boundary and counts as a framing refusal.
    #[task(binds = EXTI15_10, priority = 2, shared = [safety, link_hw, link], local = [nss])]
    fn spi_nss_rise(cx: spi_nss_rise::Context) {
        cx.local.nss.clear();
        if cx.shared.link_hw.resync_if_cut() {
            cx.shared.link.transaction_cut(cx.shared.safety);
        }
    }

    /// Watchdog tick. Priority 2, 1 kHz: TIM2 update, the ladder's time base.
    #[task(binds = TIM2, priority = 2, shared = [safety, bridge, estop, setpoint, meas, runs],
           local = [tick_timer, tick, pins, iwdg])]
    fn watchdog_tick(mut cx: watchdog_tick::Context) {
        cx.local.tick_timer.clear();
        let pins = cx.local.pins;
        let inputs = TickInputs {
            meas: cx.shared.meas.lock(|m| m.take_for_tick()),
            driver_fault: pins.driver_fault(),
            thermal_warning: pins.thermal_warning(),
            estop: cx.shared.estop.lock(|e| e.poll(board::estop_pressed())),
            runs: cx.shared.runs.lock(|r| *r),
        };
        let safety = cx.shared.safety;
        let o = cx.local.tick.run(safety, &inputs);
        (cx.shared.bridge, cx.shared.estop).lock(|b, e| o.drive(b, e));
        cx.shared.setpoint.lock(|s| *s = o.setpoint());
        pins.set_brake_release(o.brake_release);
        if o.feed_watchdog {
            cx.local.iwdg.feed();
        }
        hooks::after_tick(safety.ticks(), &o.out, safety);
    }
}

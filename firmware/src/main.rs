//! Motor-controller firmware for the STM32F407: four hardware-priority RTIC tasks around the pure
//! `statemachine`, `protocol` and `control` crates.
//!
//! ```text
//!  priority 4  current_loop   ADC JEOC (TIM1_CC4)  20 kHz  shunt ADC → CurrentPi → TIM1/TIM8 compares
//!  priority 3  speed_pid      TIM5 update          10 kHz  encoders → RateLimiter → SpeedPid → current ref
//!  priority 2  spi_dma_done   DMA1 stream 3 TC      1 kHz  frame → decode → ladder → feedback frame
//!  priority 2  watchdog_tick  TIM2 update           1 kHz  ladder.step(Tick) → bridge (BRAKE now) → IWDG
//!  idle        wfi
//! ```
//!
//! The ladder is shared only by the two priority-2 tasks, which never preempt each other, so it
//! needs no lock (`#[lock_free]`). BRAKE is written to the bridge by whichever of them produced
//! it, inside that task: no later task has to run for the PWM to stop.
#![no_std]
#![no_main]
#![deny(unsafe_code)]

mod board;
mod emu;
mod glue;

use defmt_rtt as _;
use panic_probe as _;

#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true)]
mod app {
    use crate::board::{self, Board, Bridge, CurrentSense, Encoders, Link, Periodic, FRAME_LEN};
    use crate::glue::{self, Measurements, Runs};
    use control::glue::{adc_to_amps, bridge_compare, overcurrent, BridgeState, Liveness};
    use control::{Amps, CurrentPi, RateLimiter, SpeedEstimator, SpeedPid};
    use rtic::Mutex;
    use statemachine::{Config, Ladder, Output, Speed};
    use stm32f4xx_hal::pac;

    #[shared]
    struct Shared {
        /// Both H-bridges (ceiling 4).
        bridge: Bridge,
        /// What the ladder last allowed: wheel setpoints, or `None` in BRAKE (ceiling 3).
        setpoint: Option<[Speed; 2]>,
        /// Current references from the speed loop to the current loop (ceiling 4).
        current_ref: [Amps; 2],
        /// Measurements for the feedback frame and the plausibility checks (ceiling 4).
        meas: Measurements,
        /// Run counters of the control tasks, checked before each IWDG refresh (ceiling 4).
        runs: Runs,
        /// The safety ladder, shared by the two priority-2 tasks only.
        #[lock_free]
        ladder: Ladder,
    }

    #[local]
    struct Local {
        adc: CurrentSense,
        current_pis: [CurrentPi; 2],
        adc_offsets: [u16; 2],
        encoders: Encoders,
        speed_timer: Periodic<pac::TIM5>,
        limiters: [RateLimiter; 2],
        speed_pids: [SpeedPid; 2],
        estimators: [SpeedEstimator; 2],
        link: Link,
        feedback_seq: u32,
        tick_timer: Periodic<pac::TIM2>,
        pins: board::Pins,
        iwdg: board::Iwdg,
        liveness: Liveness<2>,
        ticks: u32,
        emu: crate::emu::Emu,
    }

    #[init(local = [
        rx_buf: [[u8; FRAME_LEN]; 2] = [[0; FRAME_LEN]; 2],
        tx_buf: [[u8; FRAME_LEN]; 2] = [[0; FRAME_LEN]; 2],
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let (b, iwdg, dbg) = board::init(cx.device, cx.local.rx_buf, cx.local.tx_buf);
        let Board {
            bridge,
            encoders,
            adc,
            link,
            tick,
            speed,
            pins,
        } = b;
        let counts = encoders.read();
        let p = glue::AXIS;
        let iwdg = board::Iwdg::start(iwdg, &dbg);
        defmt::info!("firmware up: ladder latched in BRAKE until the host arms it");
        (
            Shared {
                bridge,
                setpoint: None,
                current_ref: [Amps::ZERO; 2],
                meas: Measurements::default(),
                runs: Runs::default(),
                ladder: Ladder::new(Config::DEFAULT),
            },
            Local {
                adc,
                current_pis: [CurrentPi::new(p.current); 2],
                adc_offsets: [glue::ADC_ZERO; 2],
                encoders,
                speed_timer: speed,
                limiters: [RateLimiter::new(p.ref_step, Speed::ZERO); 2],
                speed_pids: [SpeedPid::new(p.speed); 2],
                estimators: counts.map(|c| SpeedEstimator::new(c, p.speed_scale)),
                link,
                feedback_seq: 0,
                tick_timer: tick,
                pins,
                iwdg,
                liveness: Liveness::new(),
                ticks: 0,
                emu: crate::emu::Emu::open(),
            },
        )
    }

    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// Current loop. Priority 4 (highest), 20 kHz: the ADC injected end-of-conversion interrupt,
    /// triggered by TIM1_CC4 once per PWM period, so every sample is taken at the same point of
    /// the switching cycle. Also watches the break flag (overcurrent comparator on BKIN).
    #[task(binds = ADC, priority = 4, shared = [bridge, current_ref, meas, runs],
           local = [adc, current_pis, adc_offsets])]
    fn current_loop(cx: current_loop::Context) {
        let raw = cx.local.adc.read();
        let offsets = *cx.local.adc_offsets;
        let amps = [
            adc_to_amps(raw[0], offsets[0], glue::AMPS_PER_COUNT),
            adc_to_amps(raw[1], offsets[1], glue::AMPS_PER_COUNT),
        ];
        let soft_trip = amps.iter().any(|i| overcurrent(*i, glue::TRIP_AMPS));
        let mut current_ref = cx.shared.current_ref;
        let refs = current_ref.lock(|r| *r);
        let pis = cx.local.current_pis;
        let mut bridge = cx.shared.bridge;
        let hard_trip = bridge.lock(|b| b.tripped(false));
        let tripped = soft_trip || hard_trip;
        bridge.lock(|b| {
            if tripped {
                // Software backstop of the hardware break: PWM off in this very period.
                b.apply(BridgeState::Brake);
            }
            if b.state() == BridgeState::Run {
                let l = pis[0].step(refs[0], amps[0]);
                let r = pis[1].step(refs[1], amps[1]);
                b.set(
                    bridge_compare(l, board::PWM_ARR),
                    bridge_compare(r, board::PWM_ARR),
                );
            } else {
                pis[0].reset(amps[0]);
                pis[1].reset(amps[1]);
            }
        });
        let mut meas = cx.shared.meas;
        meas.lock(|m| {
            m.currents = amps;
            m.overcurrent |= tripped;
        });
        let mut runs = cx.shared.runs;
        runs.lock(|r| r.current = r.current.wrapping_add(1));
    }

    /// Speed loop. Priority 3, 10 kHz: TIM5 update. Encoders → speed estimate → rate limiter →
    /// speed PID → current references for the current loop.
    #[task(binds = TIM5, priority = 3, shared = [setpoint, current_ref, meas, runs],
           local = [speed_timer, encoders, limiters, speed_pids, estimators])]
    fn speed_pid(cx: speed_pid::Context) {
        cx.local.speed_timer.clear();
        let counts = cx.local.encoders.read();
        let mut setpoint = cx.shared.setpoint;
        let sp = setpoint.lock(|s| *s);
        let mut speeds = [Speed::ZERO; 2];
        let mut refs = [Amps::ZERO; 2];
        for i in 0..2 {
            let (Some(est), Some(lim), Some(pid), Some(c)) = (
                cx.local.estimators.get_mut(i),
                cx.local.limiters.get_mut(i),
                cx.local.speed_pids.get_mut(i),
                counts.get(i),
            ) else {
                continue;
            };
            let w = est.update(*c);
            let r = match sp.and_then(|s| s.get(i).copied()) {
                Some(target) => pid.step(lim.step(target), w),
                None => {
                    lim.reset(Speed::ZERO);
                    pid.reset(w);
                    Amps::ZERO
                }
            };
            if let (Some(s), Some(o)) = (speeds.get_mut(i), refs.get_mut(i)) {
                *s = w;
                *o = r;
            }
        }
        let mut current_ref = cx.shared.current_ref;
        current_ref.lock(|c| *c = refs);
        let [el, er] = &*cx.local.estimators;
        let totals = [el.total(), er.total()];
        let mut meas = cx.shared.meas;
        meas.lock(|m| {
            m.speeds = speeds;
            m.encoders = totals;
        });
        let mut runs = cx.shared.runs;
        runs.lock(|r| r.speed = r.speed.wrapping_add(1));
        // The emulator has no ADC trigger: run the current loop from here (once per speed sample).
        #[cfg(feature = "qemu")]
        rtic::pend(pac::Interrupt::ADC);
    }

    /// Link frame received. Priority 2, once per SPI transaction (1 kHz from the host): DMA1
    /// stream 3 transfer complete. Decodes the frame (CRC, protobuf, version), feeds the ladder
    /// (`Event::Frame` or `Event::Rejected`), applies the result, and prepares the next feedback.
    #[task(binds = DMA1_STREAM3, priority = 2, shared = [ladder, bridge, setpoint, meas],
           local = [link, feedback_seq, emu])]
    fn spi_dma_done(cx: spi_dma_done::Context) {
        #[cfg(not(feature = "qemu"))]
        let frame = cx.local.link.take_rx();
        #[cfg(feature = "qemu")]
        let frame = cx.local.emu.next_frame();
        let Some(frame) = frame else {
            #[cfg(feature = "qemu")]
            {
                let out = cx.shared.ladder.output();
                let ticks = cx.shared.ladder.counters().ticks;
                crate::emu::maybe_exit(cx.local.emu, ticks, &out);
            }
            return;
        };
        let out = glue::on_frame(cx.shared.ladder, &frame);
        apply(&out, cx.shared.bridge, cx.shared.setpoint);
        let mut meas = cx.shared.meas;
        let m = meas.lock(|m| *m);
        let seq = *cx.local.feedback_seq;
        *cx.local.feedback_seq = seq.wrapping_add(1);
        let mut fb = [0u8; FRAME_LEN];
        glue::feedback(
            &m,
            &out,
            seq,
            cx.shared.ladder.last_valid().and_then(|s| s.seq),
            &mut fb,
        );
        cx.local.link.put_tx(&fb);
    }

    /// Watchdog tick. Priority 2, 1 kHz: TIM2 update, the ladder's time base. Reports board
    /// conditions, steps the ladder, writes BRAKE to the bridge in this same task, and refreshes
    /// the IWDG only if both control loops ran at their rates since the last tick.
    #[task(binds = TIM2, priority = 2, shared = [ladder, bridge, setpoint, meas, runs],
           local = [tick_timer, pins, iwdg, liveness, ticks])]
    fn watchdog_tick(cx: watchdog_tick::Context) {
        cx.local.tick_timer.clear();
        let ladder = cx.shared.ladder;
        let mut meas = cx.shared.meas;
        let m = meas.lock(|m| {
            let snapshot = *m;
            m.overcurrent = false;
            snapshot
        });
        let inputs = glue::Inputs {
            overcurrent: m.overcurrent,
            driver_fault: cx.local.pins.n_fault.is_low(),
            thermal_warning: cx.local.pins.n_otw.is_low(),
            speeds: m.speeds,
        };
        #[cfg(feature = "qemu")]
        let inputs = glue::Inputs {
            driver_fault: false,
            thermal_warning: false,
            ..inputs
        };
        let out = glue::on_tick(ladder, &inputs);
        let mut bridge = cx.shared.bridge;
        apply(&out, &mut bridge, cx.shared.setpoint);
        // Holding brake follows the ladder: released only while the speed loop drives.
        if out.mode == statemachine::Mode::Brake {
            cx.local.pins.brake_release.set_low();
        } else {
            cx.local.pins.brake_release.set_high();
        }
        if out.mode == statemachine::Mode::Brake {
            // While braked, clear the break flag once per tick: the break input is level
            // sensitive, so the flag comes straight back (and the current loop reports the
            // overcurrent again) for as long as the comparator holds BKIN low.
            bridge.lock(|b| b.tripped(true));
        }
        let mut runs = cx.shared.runs;
        let r = runs.lock(|r| *r);
        if cx
            .local
            .liveness
            .check([r.current, r.speed], glue::MIN_RUNS_PER_TICK)
        {
            cx.local.iwdg.feed();
        }
        *cx.local.ticks = cx.local.ticks.wrapping_add(1);
        #[cfg(feature = "qemu")]
        {
            crate::emu::trace(*cx.local.ticks, &out, &*ladder);
            // The emulator has no SPI: one link transaction per tick, from the host file.
            rtic::pend(pac::Interrupt::DMA1_STREAM3);
        }
    }

    /// Applies a ladder output: the bridge state at once, and the setpoints for the speed loop.
    fn apply(
        out: &Output,
        mut bridge: impl Mutex<T = Bridge>,
        mut setpoint: impl Mutex<T = Option<[Speed; 2]>>,
    ) {
        let state = control::glue::bridge_state(&out.drive);
        bridge.lock(|b| b.apply(state));
        let sp = match out.drive {
            statemachine::Drive::Run { left, right } => Some([left, right]),
            statemachine::Drive::Brake => None,
        };
        setpoint.lock(|s| *s = sp);
    }
}

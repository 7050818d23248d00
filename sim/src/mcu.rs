//! The simulated MCU: the firmware's tasks at their rates, calling the same pure crates
//! (`statemachine`, `protocol`, `control`) in the same order as the firmware.
//!
//! ```text
//!  task (rate)                    per call
//!  spi_dma_done  (per transfer)   decode frame → Event::Frame / Event::Rejected → prepare feedback
//!  estop_edge    (GPIO)           Event::Estop(Engage / Release)
//!  watchdog_tick (1 kHz)          Event::Tick → Output (mode, drive)
//!  speed_pid     (10 kHz)         encoders → speed estimate → plausibility (Condition EncoderFailure)
//!                                 → AxisLoop::speed_step(setpoint or None in BRAKE)
//!  current_loop  (20 kHz)         shunt → overcurrent check (Condition Overcurrent: BRAKE this step)
//!                                 → BRAKE: low sides on, PI reset; else AxisLoop::current_step → duty
//! ```
//! Within one 50 µs step the order is: SPI completion (if one happened), ESTOP edge, watchdog tick
//! (every 20th step), speed loop (every 2nd step), current loop.

use control::{AxisLoop, AxisParams, PidGains, Q};
use protocol::amr::{self, MotorFeedback, FRAME_LEN};
use statemachine::{Condition, Config, Drive, Estop, Event, Ladder, Output};

use crate::plant::BridgeDrive;

/// Firmware tuning used by the simulated MCU.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct McuParams {
    /// Ladder configuration.
    pub ladder: Config,
    /// Per-wheel control cascade.
    pub axis: AxisParams,
    /// Overcurrent trip level, A.
    pub trip_amps: f64,
    /// Encoder counts per wheel revolution.
    pub counts_per_rev: u32,
}

/// Floats to Q16.16 for tuning constants (saturating; the values here are small).
fn q(x: f64) -> Q {
    Q::saturating_from_num(x)
}

impl McuParams {
    /// Tuning for the default plant: speed PI 4 A/(rad/s), 40 A/rad (10 A limit); current PI
    /// 0.13 duty/A, 260 duty/(A·s) (≈ 1 kHz bandwidth for L = 0.5 mH, R = 1 Ω at 24 V).
    pub fn default_for(counts_per_rev: u32) -> Self {
        let ladder = Config::DEFAULT;
        let speed = PidGains {
            kp: q(4.0),
            ki_dt: q(40.0 * 1e-4),
            kd_dt: Q::ZERO,
            out_limit: q(10.0),
            i_limit: q(10.0),
            anti_windup: control::AntiWindup::Conditional,
        };
        let current = PidGains {
            kp: q(0.13),
            ki_dt: q(260.0 * 5e-5),
            kd_dt: Q::ZERO,
            out_limit: Q::ONE,
            i_limit: Q::ONE,
            anti_windup: control::AntiWindup::Conditional,
        };
        let stop = ladder.params().stop_decel_step;
        Self {
            ladder,
            axis: AxisParams {
                speed,
                current,
                // The ladder moves at most stop_decel_step per 1 ms tick; 10 speed samples per tick.
                ref_step: stop / 10,
                speed_scale: control::glue::speed_scale(counts_per_rev, 10_000).unwrap_or(Q::ZERO),
            },
            trip_amps: 15.0,
            counts_per_rev,
        }
    }
}

/// What the MCU did in one step that the simulator records.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepReport {
    /// A watchdog tick ran in this step.
    pub ticked: bool,
}

/// The MCU: the ladder, two control cascades, the feedback buffer and the MCU clock.
#[derive(Clone, Debug)]
pub struct Mcu {
    p: McuParams,
    /// The safety core.
    pub ladder: Ladder,
    axes: [AxisLoop; 2],
    /// Last ladder output.
    pub out: Output,
    /// Bridge state applied in the last current-loop step.
    pub bridge: [BridgeDrive; 2],
    /// Last duty per wheel (0 in BRAKE).
    pub duty: [f64; 2],
    /// Steps since reset.
    step_count: u64,
    /// The feedback frame the SPI DMA will shift out in the next transfer.
    pub tx_buffer: [u8; FRAME_LEN],
    fb_seq: u32,
    last_cmd_seq: u32,
    encoder_bad: bool,
    overcurrent: bool,
    /// Encoder counter offsets injected by glitches.
    pub glitch: [i32; 2],
    /// Measured currents (left, right), A, as the shunts report them.
    pub measured: [f64; 2],
}

impl Mcu {
    /// An MCU just out of reset (BRAKE latched, POWER_ON) with the encoder counters reading `counts`.
    pub fn new(p: McuParams, counts: [u16; 2]) -> Self {
        let ladder = Ladder::new(p.ladder);
        let out = ladder.output();
        let mut m = Self {
            p,
            ladder,
            axes: [
                AxisLoop::new(&p.axis, counts[0]),
                AxisLoop::new(&p.axis, counts[1]),
            ],
            out,
            bridge: [BridgeDrive::Short; 2],
            duty: [0.0; 2],
            step_count: 0,
            tx_buffer: [0; FRAME_LEN],
            fb_seq: 0,
            last_cmd_seq: 0,
            encoder_bad: false,
            overcurrent: false,
            glitch: [0; 2],
            measured: [0.0; 2],
        };
        m.prepare_feedback(0);
        m
    }

    /// The parameters.
    pub fn params(&self) -> &McuParams {
        &self.p
    }

    /// Speed estimates (left, right), rad/s.
    pub fn speed_estimate(&self) -> [f64; 2] {
        [self.axes[0].speed().to_num(), self.axes[1].speed().to_num()]
    }

    /// `spi_dma_done`: a command frame arrived. Returns true if the ladder accepted it as valid.
    pub fn on_frame(&mut self, frame: &[u8; FRAME_LEN], mcu_us: u64) -> bool {
        let before = self.ladder.counters().valid_frames;
        let decoded = amr::decode_command(frame);
        let event = protocol::event_from(decoded.map(|c| c.to_command()));
        self.out = self.ladder.step(event);
        let accepted = self.ladder.counters().valid_frames != before;
        if accepted {
            if let Ok(c) = decoded {
                self.last_cmd_seq = c.seq;
            }
        }
        self.prepare_feedback(mcu_us);
        accepted
    }

    fn prepare_feedback(&mut self, mcu_us: u64) {
        self.fb_seq = self.fb_seq.wrapping_add(1);
        let sp = self.speed_estimate();
        let fb = MotorFeedback {
            timestamp_us: mcu_us as u32,
            left_speed: sp[0] as f32,
            right_speed: sp[1] as f32,
            // A low-side shunt measures magnitude: the seed's rule "negative current = sensor failure".
            left_current: self.measured[0].abs() as f32,
            right_current: self.measured[1].abs() as f32,
            left_encoder: self.axes[0].encoder_total(),
            right_encoder: self.axes[1].encoder_total(),
            fault_flags: 0,
            seq: self.fb_seq,
            mode: 0,
            cmd_seq: self.last_cmd_seq,
        }
        .with_output(&self.ladder.output());
        amr::encode_feedback(&fb, &mut self.tx_buffer);
    }

    /// The ESTOP input changed.
    pub fn on_estop(&mut self, pressed: bool) {
        self.out = self.ladder.step(Event::Estop(if pressed {
            Estop::Engage
        } else {
            Estop::Release
        }));
    }

    /// One 50 µs step (20 kHz): the timer-driven tasks. `counts` are the encoder counters,
    /// `currents` the shunt readings, A.
    pub fn step(&mut self, counts: [u16; 2], currents: [f64; 2]) -> StepReport {
        let mut rep = StepReport::default();
        if self.step_count % 20 == 0 {
            self.out = self.ladder.step(Event::Tick);
            rep.ticked = true;
        }
        if self.step_count % 2 == 0 {
            self.speed_pid(counts);
        }
        self.current_loop(currents);
        self.step_count = self.step_count.wrapping_add(1);
        rep
    }

    fn speed_pid(&mut self, counts: [u16; 2]) {
        let sp = match self.out.drive {
            Drive::Run { left, right } => [Some(left), Some(right)],
            Drive::Brake => [None, None],
        };
        let v_max = self.p.ladder.params().v_max;
        let mut plausible = true;
        for k in 0..2 {
            let c = counts[k].wrapping_add(self.glitch[k] as u16);
            self.axes[k].speed_step(sp[k], c);
            plausible &= control::glue::speed_plausible(self.axes[k].speed(), v_max);
        }
        if plausible == self.encoder_bad {
            self.encoder_bad = !plausible;
            self.out = self.ladder.step(Event::Condition {
                condition: Condition::EncoderFailure,
                active: self.encoder_bad,
            });
        }
    }

    fn current_loop(&mut self, currents: [f64; 2]) {
        self.measured = currents;
        let trip = q(self.p.trip_amps);
        let over = currents
            .iter()
            .any(|&i| control::glue::overcurrent(q(i), trip));
        if over != self.overcurrent {
            self.overcurrent = over;
            self.out = self.ladder.step(Event::Condition {
                condition: Condition::Overcurrent,
                active: over,
            });
        }
        for k in 0..2 {
            let meas = q(currents[k]);
            match self.out.drive {
                Drive::Brake => {
                    self.axes[k].current_reset(meas);
                    self.bridge[k] = BridgeDrive::Short;
                    self.duty[k] = 0.0;
                }
                Drive::Run { .. } => {
                    let d: f64 = self.axes[k].current_step(meas).to_num();
                    self.bridge[k] = BridgeDrive::Pwm(d);
                    self.duty[k] = d;
                }
            }
        }
    }
}

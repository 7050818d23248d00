//! The simulated board: the board application (`mcu` crate, the same task bodies the firmware
//! runs) at the board's rates, with simulated peripherals in place of the registers.
//!
//! ```text
//!  task (rate)                body (crate mcu)           simulated peripheral
//!  spi_dma_done  (per frame)  LinkTask::on_frame         the frame the host sent; tx buffer
//!  estop_input   (edge)       EstopInput::edge           the ESTOP input level
//!  watchdog_tick (1 kHz)      TickTask::run              fault lines (inactive), IWDG feed record
//!  speed_pid     (10 kHz)     SpeedLoop::run             encoder counters of the plant (+ glitches)
//!  current_loop  (20 kHz)     CurrentLoop::run           shunt ADC: plant current → 12-bit counts
//! ```
//! Within one 50 µs step the order is: SPI completion (if one happened), ESTOP edge, watchdog tick
//! (every 20th step), speed loop (every 2nd step), current loop: the firmware's priorities, with
//! each interrupt's trigger at the start of the step.

use control::{BridgeState, Q};
use mcu::hw::RecordingBridge;
use mcu::tick::{Runs, TickInputs};
use mcu::tuning::Tuning;
use mcu::AXES;
use mcu::{Bridge, CurrentLoop, EstopInput, LinkTask, Measurements, Safety, SpeedLoop, TickTask};
use protocol::amr::{pack_fw_version, BoardProfile, McuInfo, ResetCause, FRAME_LEN};
use statemachine::Speed;

type Output = statemachine::Output<AXES>;

use crate::plant::{BridgeDrive, Plant, PlantParams};

/// The simulated firmware's version: the board application's.
const FW_VERSION: u32 = pack_fw_version(0, 1, 0);

/// Counts of the board's tick timer per 1 ms tick (TIM2 at 84 MHz, prescaler 2).
pub const TICK_COUNTS: u32 = 42_000;
/// Simulation steps (current-loop periods) per tick.
pub const STEPS_PER_TICK: u64 = 20;
/// Level of the hardware overcurrent comparator on the break input, A.
pub const COMPARATOR_AMPS: f64 = 15.0;

/// The AMR board's tuning (`mcu::tuning::AMR`) for the encoders of `plant`: its counts per
/// revolution and the speed scale they give at the speed loop's rate (the AMR figure if the
/// scale does not fit the fixed-point format).
pub fn amr_tuning(plant: &PlantParams) -> Tuning {
    Tuning {
        counts_per_rev: plant.counts_per_rev,
        speed_scale: control::sense::speed_scale(plant.counts_per_rev, mcu::tuning::AMR.speed_hz)
            .unwrap_or(mcu::tuning::AMR.speed_scale),
        ..mcu::tuning::AMR
    }
}

/// The encoder counters (left, right) as the board's timers read the plant's wheels.
pub fn encoder_counters(plant: &Plant) -> [u16; 2] {
    [plant.encoder_counter(0), plant.encoder_counter(1)]
}

/// The simulated H-bridges: what the firmware's TIM1/TIM8 registers would hold.
pub type SimBridge = RecordingBridge;

/// How the plant sees each bridge: the average duty of the compare values, or shorted.
pub fn bridge_drive(b: &SimBridge) -> [BridgeDrive; 2] {
    let arr = f64::from(b.arr.max(1));
    b.compares.map(|c| match b.state {
        BridgeState::Brake => BridgeDrive::Short,
        BridgeState::Run => BridgeDrive::Pwm((f64::from(c.a) - f64::from(c.b)) / arr),
    })
}

/// What the board did in one step that the simulator records.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepReport {
    /// A watchdog tick ran in this step.
    pub ticked: bool,
    /// The tick refreshed the IWDG.
    pub fed_watchdog: bool,
}

/// The board: task state as the firmware holds it, and the simulated peripherals.
#[derive(Clone, Debug)]
pub struct SimBoard {
    tuning: Tuning,
    safety: Safety,
    link: LinkTask,
    tick: TickTask,
    speed: SpeedLoop,
    current: CurrentLoop,
    estop: EstopInput,
    estop_level: bool,
    meas: Measurements,
    setpoint: Option<[Speed; 2]>,
    refs: [control::Amps; 2],
    runs: Runs,
    /// Last ladder output.
    pub out: Output,
    /// The bridges.
    pub bridge: SimBridge,
    /// Steps since reset.
    step_count: u64,
    /// The feedback frame the SPI DMA will shift out in the next transfer.
    pub tx_buffer: [u8; FRAME_LEN],
    /// Encoder counter offsets injected by glitches.
    pub glitch: [i32; 2],
    /// Shunt currents (left, right), A, as the ADC saw them.
    pub measured: [f64; 2],
}

impl SimBoard {
    /// A board just out of reset (BRAKE latched, POWER_ON) with the encoder counters reading
    /// `counts`; `reset` is why it started and how many resets came since power-on, as the
    /// firmware reports them in its identity. Zero-current offsets are calibrated as the firmware
    /// does: the mean reading with the bridge braked, which here is the nominal bias.
    pub fn new(tuning: Tuning, counts: [u16; 2], reset: (ResetCause, u32)) -> Self {
        let safety = Safety::new(tuning.ladder);
        let arr = tuning.pwm_arr().unwrap_or(1);
        // Boot calibration as the firmware does it: readings with the bridge braked (no current).
        let mut cal = mcu::Calibration::new();
        for _ in 0..mcu::current::CALIBRATION_SAMPLES {
            cal.add([tuning.adc_zero; 2]);
        }
        let mut b = Self {
            tuning,
            out: safety.output(),
            safety,
            link: LinkTask::new(McuInfo {
                fw_version: FW_VERSION,
                board: BoardProfile::AmrSpi,
                reset_cause: reset.0,
                reset_count: reset.1,
                ..McuInfo::default()
            }),
            tick: TickTask::new(&tuning),
            speed: SpeedLoop::new(&tuning, counts),
            current: CurrentLoop::calibrated(&tuning, cal.offsets(&tuning)),
            estop: EstopInput::new(),
            estop_level: false,
            meas: Measurements::default(),
            setpoint: None,
            refs: [Q::ZERO; 2],
            runs: Runs::default(),
            bridge: SimBridge::new(arr),
            step_count: 0,
            tx_buffer: [0; FRAME_LEN],
            glitch: [0; 2],
            measured: [0.0; 2],
        };
        let out = b.out;
        b.link.feedback(&out, &b.meas, 0, &mut b.tx_buffer);
        b
    }

    /// The safety core (ladder, tick count, trace).
    pub fn safety(&self) -> &Safety {
        &self.safety
    }

    /// Speed estimates (left, right), rad/s.
    pub fn speed_estimate(&self) -> [f64; 2] {
        self.meas.speeds.map(|s| s.to_num())
    }

    /// Duty per wheel as the bridges apply it (0 when braked).
    pub fn duty(&self) -> [f64; 2] {
        bridge_drive(&self.bridge).map(|d| match d {
            BridgeDrive::Pwm(x) => x,
            BridgeDrive::Short => 0.0,
        })
    }

    /// The board's clock as the firmware reads it in this step: µs since reset, from the tick
    /// count and the tick timer's counter. A tick due in this step has not run yet when the SPI
    /// completion runs (it is taken first), so its update flag is pending.
    pub fn now_us(&self) -> u32 {
        let phase = self.step_count % STEPS_PER_TICK;
        let count = phase as u32 * (TICK_COUNTS / STEPS_PER_TICK as u32);
        let pending = phase == 0 && self.step_count > 0;
        self.safety
            .micros(count, pending, TICK_COUNTS, self.tuning.us_per_tick())
    }

    /// `spi_dma_done`: a command frame arrived. Returns whether the ladder accepted it as valid
    /// and the time stamp the next feedback frame carries.
    pub fn on_frame(&mut self, frame: &[u8; FRAME_LEN]) -> (bool, u32) {
        let before = self.safety.ladder().counters().valid_frames;
        let now = self.now_us();
        self.out = self.link.on_frame(
            &mut self.safety,
            frame,
            &self.meas,
            now,
            &mut self.tx_buffer,
        );
        (self.safety.ladder().counters().valid_frames != before, now)
    }

    /// The ESTOP input's level (pressed = true); an edge runs the input's handler.
    pub fn set_estop(&mut self, pressed: bool) {
        if pressed != self.estop_level {
            self.estop_level = pressed;
            self.estop.edge(&mut self.bridge, pressed);
        }
    }

    /// One 50 µs step: the timer-driven tasks. `counts` are the encoder counters, `currents` the
    /// true shunt currents, A.
    pub fn step(&mut self, counts: [u16; 2], currents: [f64; 2]) -> StepReport {
        let mut rep = StepReport::default();
        // The comparator on the break input acts on the true current, without software.
        if currents.iter().any(|i| i.abs() >= COMPARATOR_AMPS) {
            self.bridge.tripped = true;
            self.bridge.apply(BridgeState::Brake);
        }
        if self.step_count.is_multiple_of(STEPS_PER_TICK) && self.step_count > 0 {
            let inputs = TickInputs {
                meas: self.meas.take_for_tick(),
                driver_fault: false,
                thermal_warning: false,
                estop: self.estop.poll(self.estop_level),
                runs: self.runs,
            };
            let o = self.tick.run(&mut self.safety, &inputs);
            o.drive(&mut self.bridge, &self.estop);
            self.setpoint = o.setpoint();
            self.out = o.out;
            rep.ticked = true;
            rep.fed_watchdog = o.feed_watchdog;
        }
        if self.step_count.is_multiple_of(2) {
            let c = [0, 1].map(|k| counts[k].wrapping_add(self.glitch[k] as u16));
            let s = self.speed.run(c, self.setpoint);
            self.meas.record_speed(&s);
            self.refs = s.refs;
            self.runs.speed = self.runs.speed.wrapping_add(1);
        }
        self.measured = currents;
        let raw = currents.map(|i| self.adc_counts(i));
        let s = self.current.run(&mut self.bridge, raw, self.refs);
        self.meas.record_current(&s);
        self.runs.current = self.runs.current.wrapping_add(1);
        self.step_count = self.step_count.wrapping_add(1);
        rep
    }

    /// The 12-bit reading of the shunt amplifier for a current, A (saturates at the rails).
    fn adc_counts(&self, amps: f64) -> u16 {
        let per = self.tuning.amps_per_count.to_num::<f64>();
        let c = f64::from(self.tuning.adc_zero) + (amps / per).round();
        c.clamp(0.0, 4095.0) as u16
    }
}

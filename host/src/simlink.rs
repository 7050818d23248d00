//! The simulated seed 000 board behind the host's [`Transport`]: `motorlink`'s own link code
//! (the [`Bridge`](crate::Bridge) in a [`Link`]) talks to the board application of crate `mcu`
//! running on the simulator's board (`sim::board::SimBoard`) against its motor and robot plant
//! (`sim::plant::Plant`), so every AMR-link verb can run with no board.
//!
//! One exchange is one SPI transaction, as the firmware's `spi_dma_done` sees it:
//!
//! ```text
//!  board time  T ─── CS↓ ─ 64 B @ 2 MHz ─ CS↑ (T + 300 µs) ──────────────── T + 1 ms ── next exchange
//!  MISO         the feedback prepared at the previous CS↑ (the DMA's tx buffer)
//!  spi_dma_done                       on_frame: decode → ladder → next feedback
//!  tasks        current loop 20 kHz, speed loop 10 kHz, watchdog tick 1 kHz, all the time
//! ```
//!
//! Board time advances in the simulator's 50 µs steps (one current-loop period; the plant is
//! integrated over the same step). Where it comes from is the [`SimClock`]:
//! - [`SimClock::Lockstep`]: each exchange takes one board millisecond (the transfer's 300 µs
//!   up to `spi_dma_done`, then the rest of the millisecond), and [`SimMcu::idle`] lets more pass
//!   with no frame. Nothing depends on the wall clock: a run is deterministic, and a starved host
//!   thread on a loaded machine cannot fake a comm loss. Run the bridge on the board's clock with
//!   [`Link::sim_cycle`] (or [`Link::exchange_at`] with [`SimMcu::now_us`]).
//! - [`SimClock::Wall`]: before each exchange the board catches up with the wall time since it
//!   was created (at most [`SimConfig::max_catch_up_ms`] at once), so its 1 kHz ticks follow
//!   wall time and a host that stops sending sees the board brake as a real one would.

use std::time::{Duration, Instant};

use protocol::amr::{ResetCause, FRAME_LEN};
use sim::board::{amr_tuning, bridge_drive, encoder_counters, SimBoard, STEPS_PER_TICK};
use sim::plant::{BridgeDrive, Plant, PlantParams};
use sim::runner::STEP_S;
use statemachine::Mode;

use crate::bridge::Diagnostic;
use crate::link::Link;
use crate::transport::{LinkError, Transport};

/// Board steps (50 µs) from the start of a transaction to `spi_dma_done`: chip select falls 5 µs
/// after the host starts, 64 bytes at 2 MHz take 256 µs, and the completion runs at the first step
/// at or after CS↑ (261 µs): the sixth step, 300 µs.
pub const TRANSFER_STEPS: u64 = 6;

/// Microseconds per board step.
const STEP_US: u64 = 50;

/// Host time from the start of a lockstep transaction to the moment the host has the feedback,
/// µs: the transfer up to `spi_dma_done` ([`TRANSFER_STEPS`] steps).
pub const LOCKSTEP_RECV_US: u64 = TRANSFER_STEPS * STEP_US;

/// Where the board's time comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimClock {
    /// The board's ticks follow wall time (interactive use).
    Wall,
    /// One board millisecond per exchange or per millisecond of [`SimMcu::idle`] (tests,
    /// recording): deterministic.
    Lockstep,
}

/// How to build a [`SimMcu`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimConfig {
    /// Where board time comes from.
    pub clock: SimClock,
    /// The motors and the robot (the default is the AMR robot the host's default geometry
    /// describes: 0.08 m wheels 0.40 m apart).
    pub plant: PlantParams,
    /// Wall clock only: the most board time one catch-up runs, ms. A host that did not exchange
    /// for longer finds the board's clock behind the wall by the difference (its ladder braked
    /// long before), instead of waiting for minutes of simulation.
    pub max_catch_up_ms: u64,
}

impl SimConfig {
    /// The AMR robot on the given clock.
    pub fn new(clock: SimClock) -> Self {
        Self {
            clock,
            plant: PlantParams::default(),
            max_catch_up_ms: 1_000,
        }
    }
}

/// The plant's ground truth and the board's state, for checking what the host believes.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Truth {
    /// Board time since reset, µs.
    pub board_us: u64,
    /// True wheel speeds (left, right), rad/s.
    pub wheel_radps: [f64; 2],
    /// True motor currents (left, right), A.
    pub current_a: [f64; 2],
    /// Robot forward speed, m/s.
    pub v_mps: f64,
    /// Robot yaw rate, rad/s.
    pub w_radps: f64,
    /// Pose x, m (start at the origin facing +x).
    pub x_m: f64,
    /// Pose y, m.
    pub y_m: f64,
    /// Heading, rad.
    pub theta_rad: f64,
    /// Path length travelled, m.
    pub odometer_m: f64,
    /// The ladder's rung on the board now.
    pub mode: u8,
    /// Both bridges braked (low sides on).
    pub braked: bool,
    /// The ESTOP input's level.
    pub estop: bool,
}

/// The simulated AMR-SPI board (seed 000 link) as a [`Transport`].
#[derive(Clone, Debug)]
pub struct SimMcu {
    cfg: SimConfig,
    board: SimBoard,
    plant: Plant,
    estop: bool,
    steps: u64,
    start: Instant,
    exchanges: u64,
}

impl SimMcu {
    /// A board just out of a power-on reset (BRAKE latched, as the firmware starts) on a robot at
    /// rest, or why the plant's geometry is refused.
    pub fn new(cfg: SimConfig) -> Result<Self, LinkError> {
        let plant = Plant::try_new(cfg.plant).map_err(|e| {
            LinkError::Configure(
                "sim".into(),
                format!("plant geometry refused: {e:?} (wheel radius 1 mm to 10 m, wheelbase 1 cm to 64 m)"),
            )
        })?;
        Ok(Self::build(cfg, plant))
    }

    /// The AMR robot in lockstep.
    pub fn lockstep() -> Self {
        Self::build(SimConfig::new(SimClock::Lockstep), Plant::default())
    }

    /// The AMR robot on wall time.
    pub fn wall() -> Self {
        Self::build(SimConfig::new(SimClock::Wall), Plant::default())
    }

    fn build(cfg: SimConfig, plant: Plant) -> Self {
        Self {
            board: SimBoard::new(
                amr_tuning(&plant.p),
                encoder_counters(&plant),
                (ResetCause::PowerOn, 0),
            ),
            cfg,
            plant,
            estop: false,
            steps: 0,
            start: Instant::now(),
            exchanges: 0,
        }
    }

    /// The configuration it was built with.
    pub fn config(&self) -> SimConfig {
        self.cfg
    }

    /// Board time since reset, µs (in lockstep, the host's clock too).
    pub fn now_us(&self) -> u64 {
        self.steps.saturating_mul(STEP_US)
    }

    /// Exchanges so far.
    pub fn exchanges(&self) -> u64 {
        self.exchanges
    }

    /// The simulated board (ladder, counters, bridges, the feedback it will send next).
    pub fn board(&self) -> &SimBoard {
        &self.board
    }

    /// The plant's ground truth now.
    pub fn truth(&self) -> Truth {
        let p = &self.plant;
        Truth {
            board_us: self.now_us(),
            wheel_radps: p.wheel_speeds(),
            current_a: p.current,
            v_mps: p.v,
            w_radps: p.w,
            x_m: p.x,
            y_m: p.y,
            theta_rad: p.theta,
            odometer_m: p.odometer,
            mode: self.board.out.mode as u8,
            braked: bridge_drive(&self.board.bridge)
                .iter()
                .all(|d| matches!(d, BridgeDrive::Short)),
            estop: self.estop,
        }
    }

    /// The ladder's rung on the board now.
    pub fn mode(&self) -> Mode {
        self.board.out.mode
    }

    /// Sets the board's ESTOP input (pressed = true). An edge runs the input's interrupt handler
    /// at once (it brakes the bridges); the next watchdog tick takes the level to the ladder.
    pub fn set_estop(&mut self, pressed: bool) {
        self.estop = pressed;
        self.board.set_estop(pressed);
    }

    /// Lets `ms` milliseconds of board time pass with no frame (a comm loss while it lasts). In
    /// lockstep the board runs them at once; on wall time this sleeps and the board catches up.
    pub fn idle(&mut self, ms: u64) {
        match self.cfg.clock {
            SimClock::Lockstep => self.run_steps(ms.saturating_mul(STEPS_PER_TICK)),
            SimClock::Wall => {
                std::thread::sleep(Duration::from_millis(ms));
                self.catch_up();
            }
        }
    }

    /// Runs the board and the plant for `n` steps: the board's timer tasks on the encoder counts
    /// and currents of the plant, then the plant under the bridges as they are switched.
    fn run_steps(&mut self, n: u64) {
        for _ in 0..n {
            let counts = encoder_counters(&self.plant);
            self.board.step(counts, self.plant.current);
            self.plant
                .step(STEP_S, bridge_drive(&self.board.bridge), [0.0; 2]);
            self.steps = self.steps.saturating_add(1);
        }
    }

    /// Wall clock: runs the board up to the wall time since creation (at most the configured
    /// catch-up; the rest is dropped).
    fn catch_up(&mut self) {
        let wall_us = u64::try_from(self.start.elapsed().as_micros()).unwrap_or(u64::MAX);
        let due = (wall_us / STEP_US).saturating_sub(self.steps);
        let cap = self.cfg.max_catch_up_ms.saturating_mul(STEPS_PER_TICK);
        if due > cap {
            // Drop what is beyond the cap: the board's clock falls behind the wall by it.
            let dropped = Duration::from_micros(due.saturating_sub(cap).saturating_mul(STEP_US));
            self.start = self.start.checked_add(dropped).unwrap_or(self.start);
        }
        self.run_steps(due.min(cap));
    }
}

impl Transport for SimMcu {
    /// One SPI transaction: `rx` gets the feedback frame the board prepared at the previous one,
    /// and the board's `spi_dma_done` takes `tx`. Frames are 64 bytes each way.
    fn exchange(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
        let (Ok(frame), true) = (<&[u8; FRAME_LEN]>::try_from(tx), rx.len() == FRAME_LEN) else {
            return Err(LinkError::Io(
                "sim".into(),
                std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    format!(
                        "the AMR link moves {FRAME_LEN}-byte frames; got {} out and {} in",
                        tx.len(),
                        rx.len()
                    ),
                ),
            ));
        };
        self.exchanges = self.exchanges.saturating_add(1);
        match self.cfg.clock {
            SimClock::Lockstep => {
                rx.copy_from_slice(&self.board.tx_buffer);
                self.run_steps(TRANSFER_STEPS);
                self.board.on_frame(frame);
                self.run_steps(STEPS_PER_TICK.saturating_sub(TRANSFER_STEPS));
            }
            SimClock::Wall => {
                self.catch_up();
                rx.copy_from_slice(&self.board.tx_buffer);
                self.board.on_frame(frame);
            }
        }
        Ok(())
    }

    fn name(&self) -> &str {
        "sim"
    }
}

impl Link<SimMcu> {
    /// One cycle against the simulated board: in lockstep one exchange at once on the board's
    /// clock (sent at [`SimMcu::now_us`], received [`LOCKSTEP_RECV_US`] later); on wall time the
    /// link's own 1 kHz pacing and clock ([`Link::cycle`]).
    pub fn sim_cycle(&mut self) -> Result<Vec<(u64, Diagnostic)>, LinkError> {
        match self.transport.cfg.clock {
            SimClock::Lockstep => {
                let t = self.transport.now_us();
                self.exchange_at(t, t.saturating_add(LOCKSTEP_RECV_US))
            }
            SimClock::Wall => self.cycle(),
        }
    }
}

#[cfg(test)]
mod tests;

//! The firmware's own glue between the tasks and the pure crates: frame → ladder, board inputs →
//! ladder conditions, measurements → feedback frame, and the control parameters of this board.
//!
//! No register access here; every function takes plain values, so the same code runs under the
//! emulator and on the board (and could run on the host with the `protocol` crate alone).

use crate::board::{FRAME_LEN, SPEED_HZ};
use control::glue::{speed_plausible, AxisParams};
use control::{Amps, AntiWindup, PidGains, Q};
use protocol::amr::{decode_command, encode_feedback, MotorFeedback};
use statemachine::{Condition, Event, Ladder, Output, Speed};

/// Shunt current sensing: 3.3 V / 4096 counts / (5 mΩ × gain 20) = 8.06 mA per count.
pub const AMPS_PER_COUNT: Q = Q::lit("0.0080566");
/// ADC reading at zero current (amplifier biased at mid-scale).
pub const ADC_ZERO: u16 = 2048;
/// Software overcurrent trip, A (the hardware comparator on BKIN trips at 15 A, faster).
pub const TRIP_AMPS: Amps = Q::lit("14");
/// Encoder counts per wheel revolution (1024-line encoder, ×4 decoding).
pub const COUNTS_PER_REV: u32 = 4096;
/// Runs per 1 ms tick that the control loops must reach for the IWDG to be refreshed
/// ([current_loop, speed_pid]; nominal 20 and 10, or 10 and 10 under the emulator).
#[cfg(not(feature = "qemu"))]
pub const MIN_RUNS_PER_TICK: [u32; 2] = [18, 9];
/// Runs per tick under the emulator, where the current loop is pended by the speed loop.
#[cfg(feature = "qemu")]
pub const MIN_RUNS_PER_TICK: [u32; 2] = [9, 9];

/// Speed-scale of the estimator for this encoder at the speed-loop rate.
const SPEED_SCALE: Q = {
    // 2π · 10 000 / (4096 · 16) = 0.958737 rad/s per count (control::glue::speed_scale checks it).
    Q::lit("0.958737")
};
const _: () = assert!(COUNTS_PER_REV == 4096 && SPEED_HZ == 10_000);

/// Controller parameters of both wheels (motor: K_t ≈ 0.1 N·m/A, wheel inertia ≈ 0.02 kg·m²,
/// L = 1 mH, R = 0.5 Ω, 24 V bus): speed loop ≈ 30 Hz, current loop ≈ 300 Hz closed-loop bandwidth.
pub const AXIS: AxisParams = AxisParams {
    speed: PidGains {
        kp: Q::lit("1.2"),
        ki_dt: Q::lit("0.0024"), // Ki = 24 A/rad × 1e-4 s
        kd_dt: Q::ZERO,
        out_limit: Q::lit("12"),
        i_limit: Q::lit("12"),
        anti_windup: AntiWindup::Conditional,
    },
    current: PidGains {
        kp: Q::lit("0.083"),
        ki_dt: Q::lit("0.0021"), // Ki = 41.7 /(A·s) × 5e-5 s
        kd_dt: Q::ZERO,
        out_limit: Q::lit("0.95"),
        i_limit: Q::lit("0.95"),
        anti_windup: AntiWindup::Conditional,
    },
    // The ladder's accel_step (0.05 rad/s per 1 ms tick) spread over 10 speed samples.
    ref_step: Q::lit("0.005"),
    speed_scale: SPEED_SCALE,
};

/// Everything the loops measured, for the feedback frame and the ladder's plausibility checks.
#[derive(Clone, Copy, Debug, Default)]
pub struct Measurements {
    /// Wheel speeds, rad/s [left, right].
    pub speeds: [Speed; 2],
    /// Motor currents, A.
    pub currents: [Amps; 2],
    /// Cumulative encoder counts.
    pub encoders: [i32; 2],
    /// An overcurrent (software trip or hardware break) was seen since the last tick.
    pub overcurrent: bool,
}

/// How often each control task ran (wrapping), for the IWDG liveness check.
#[derive(Clone, Copy, Debug, Default)]
pub struct Runs {
    /// current_loop runs.
    pub current: u32,
    /// speed_pid runs.
    pub speed: u32,
}

/// Board inputs sampled once per tick.
#[derive(Clone, Copy, Debug)]
pub struct Inputs {
    /// Overcurrent since the last tick.
    pub overcurrent: bool,
    /// Gate-driver fault line active (reported as undervoltage: the driver's UVLO is its most
    /// common cause; either way the bridge cannot be controlled).
    pub driver_fault: bool,
    /// Over-temperature warning line active.
    pub thermal_warning: bool,
    /// Last speed estimates.
    pub speeds: [Speed; 2],
}

/// One link transaction: decode and hand the result to the ladder.
pub fn on_frame(ladder: &mut Ladder, frame: &[u8; FRAME_LEN]) -> Output {
    let event = match decode_command(frame) {
        Ok(cmd) => Event::Frame(cmd.to_command()),
        Err(reason) => Event::Rejected(reason),
    };
    ladder.step(event)
}

/// One watchdog tick: board conditions as level events, then the tick itself.
pub fn on_tick(ladder: &mut Ladder, inputs: &Inputs) -> Output {
    let v_max = ladder.config().params().v_max;
    let encoder_bad = inputs.speeds.iter().any(|s| !speed_plausible(*s, v_max));
    for (condition, active) in [
        (Condition::Overcurrent, inputs.overcurrent),
        (Condition::Undervoltage, inputs.driver_fault),
        (Condition::ThermalWarning, inputs.thermal_warning),
        (Condition::EncoderFailure, encoder_bad),
    ] {
        let _ = ladder.step(Event::Condition { condition, active });
    }
    ladder.step(Event::Tick)
}

/// Builds the feedback frame for the next transaction.
pub fn feedback(
    m: &Measurements,
    out: &Output,
    seq: u32,
    cmd_seq: Option<u32>,
    frame: &mut [u8; FRAME_LEN],
) {
    let [sl, sr] = m.speeds;
    let [il, ir] = m.currents;
    let [el, er] = m.encoders;
    let fb = MotorFeedback {
        timestamp_us: 0,
        left_speed: sl.to_num(),
        right_speed: sr.to_num(),
        left_current: il.to_num(),
        right_current: ir.to_num(),
        left_encoder: el,
        right_encoder: er,
        fault_flags: 0,
        seq,
        mode: 0,
        cmd_seq: cmd_seq.unwrap_or(0),
    }
    .with_output(out);
    encode_feedback(&fb, frame);
}

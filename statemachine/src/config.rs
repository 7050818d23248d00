//! Validated ladder configuration: one per link profile. Thresholds in watchdog ticks (1 kHz on every
//! board), speeds and steps in rad/s, duties in fractions of full scale, positions in rad.
//!
//! Each profile promises a comm-loss bound: BRAKE at the `brake_after`-th tick after the last valid
//! frame (earlier if the frame asked for a shorter `timeout`). In wall time, from the arrival of that
//! frame to the bridge braked (`proofs/SAFETY.md` §7):
//!
//! ```text
//!   frame arrives          tick 1 (age 1)                       tick b (age b): BRAKE     bridge braked
//!        │<── φ ∈ (0, 1 ms] ──>│<──────────── (b − 1) ms ───────────>│<──── R < 1 ms ────>│
//!   bound = φ + (b − 1) ms + R  ≤  b ms + R  <  (b + 1) ms
//! ```
//!
//! So a profile that promises "BRAKE within T ms" sets `brake_after` = T − 1: seed 000's 10 ms is the
//! 9th tick, seed 001's `timeout_ms` = 200 the 199th.

use crate::types::{AxisMode, Duty, ModeSet, Position, Speed};

/// The largest `brake_after` of a 1 kHz profile (a frame every tick): BRAKE strictly within 10 ms of
/// the last valid frame (9 ms + φ-free margin: see the module diagram).
pub const MAX_BRAKE_AFTER_1KHZ: u16 = 9;

/// The largest `brake_after` of any profile, the board maximum: BRAKE strictly within 250 ms of the
/// last valid frame, whatever `timeout_ms` a host sends.
pub const BOARD_MAX_BRAKE_AFTER: u16 = 249;

/// The largest `v_max` accepted, rad/s at the wheel (well inside the Q16.16 range, so sums of two speeds never saturate).
pub const V_MAX_CEILING: Speed = Speed::const_from_int(1000);

/// The largest |travel limit| accepted, rad (so position differences never saturate Q16.16).
pub const TRAVEL_CEILING: Position = Position::const_from_int(10_000);

/// The longest quality window accepted, in ticks (one minute at 1 kHz).
pub const MAX_WINDOW: u16 = 60_000;

/// The age threshold (ticks) that keeps a frame's `timeout_ms` strictly: BRAKE at the
/// (`timeout_ms` − 1)-th tick comes before `timeout_ms` has passed (module diagram). `None` for 0,
/// which no frame may ask for (the ladder refuses it); 1 ms becomes the first tick.
pub const fn brake_age_for_timeout_ms(timeout_ms: u16) -> Option<u16> {
    match timeout_ms {
        0 => None,
        1 => Some(1),
        t => Some(t.saturating_sub(1)),
    }
}

/// Raw configuration values before validation; [`Config::new`] checks them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConfigParams {
    /// Ticks between two frames of a healthy link (1 for a 1 kHz link, 20 for 50 Hz).
    pub frame_period: u16,
    /// Ticks since the last valid frame before HOLD; more than `frame_period`. Seed 000: "2 missed
    /// cycles"; with a frame every tick the age is 1 at each tick, so two missed frames make age 3.
    pub hold_after: u16,
    /// Ticks since the last valid frame before STOP.
    pub stop_after: u16,
    /// Ticks since the last valid frame before BRAKE: at most [`MAX_BRAKE_AFTER_1KHZ`] for a 1 kHz
    /// profile, [`BOARD_MAX_BRAKE_AFTER`] for any. A frame's own `timeout` may only lower it.
    pub brake_after: u16,
    /// Largest speed magnitude accepted from the host (velocity targets, position caps), rad/s.
    pub v_max: Speed,
    /// Speed magnitude allowed in REDUCED, rad/s (seed: 50 % of v_max).
    pub reduced_limit: Speed,
    /// Largest change between two consecutive valid velocity commands, rad/s per tick (max acceleration × 1 ms).
    pub max_cmd_step: Speed,
    /// Largest change of a speed setpoint or cap per tick in NORMAL and REDUCED, rad/s.
    pub accel_step: Speed,
    /// Deceleration per tick in HOLD, rad/s (gentle: the host may come back).
    pub hold_decel_step: Speed,
    /// Deceleration per tick in STOP, rad/s.
    pub stop_decel_step: Speed,
    /// Largest duty magnitude accepted from the host (fraction of full scale, ≤ 1).
    pub duty_max: Duty,
    /// Duty magnitude allowed in REDUCED.
    pub duty_reduced: Duty,
    /// Largest change of an applied duty per tick, in every rung (toward the target in NORMAL and
    /// REDUCED, toward zero in HOLD and STOP).
    pub duty_step: Duty,
    /// Lowest position target accepted, rad.
    pub travel_lo: Position,
    /// Highest position target accepted, rad.
    pub travel_hi: Position,
    /// The drive modes the link's host may ask for.
    pub modes: ModeSet,
    /// Strikes (refused frames and entries into HOLD) within one window that degrade NORMAL to REDUCED.
    pub strike_limit: u16,
    /// Window length in ticks: counting strikes, and the clean time REDUCED needs before NORMAL.
    pub window: u16,
}

/// 50 rad/s² × 1 ms = 0.05 rad/s per tick (Q16.16 bits: 0.05 × 65536 ≈ 3277).
const STEP_50: Speed = Speed::from_bits(3277);
/// 20 rad/s² × 1 ms.
const STEP_20: Speed = Speed::from_bits(1311);
/// 100 rad/s² × 1 ms.
const STEP_100: Speed = Speed::from_bits(6554);
/// Full duty in 200 ms: 0.005 per tick (Q16.16 bits ≈ 328).
const DUTY_STEP: Duty = Duty::from_bits(328);

impl ConfigParams {
    /// Seed 000, the 1 kHz AMR SPI link: HOLD after 2 missed cycles (age 3), STOP at 5, BRAKE at the
    /// 9th tick (strictly within 10 ms); 20 rad/s, half in REDUCED; 50 rad/s² command acceleration,
    /// 100 rad/s² STOP deceleration; 3 strikes per 1 s window; velocity only.
    pub const AMR_SPI: Self = Self {
        frame_period: 1,
        hold_after: 3,
        stop_after: 5,
        brake_after: 9,
        v_max: Speed::const_from_int(20),
        reduced_limit: Speed::const_from_int(10),
        max_cmd_step: STEP_50,
        accel_step: STEP_50,
        hold_decel_step: STEP_20,
        stop_decel_step: STEP_100,
        duty_max: Duty::ONE,
        duty_reduced: Duty::from_bits(1 << 15),
        duty_step: DUTY_STEP,
        travel_lo: Position::const_from_int(-100),
        travel_hi: Position::const_from_int(100),
        modes: ModeSet::VELOCITY,
        strike_limit: 3,
        window: 1000,
    };

    /// The seed's defaults: [`Self::AMR_SPI`].
    pub const DEFAULT: Self = Self::AMR_SPI;

    /// Seed 001, USB CDC at 50 Hz with `timeout_ms`: HOLD after 2 missed frames (age 41), STOP at 61,
    /// BRAKE at the board maximum (249) unless the frame's `timeout_ms` asks for earlier (200 → 199);
    /// open-loop duty (`pwm` / 1000), coast on `pwm = 0`; half duty in REDUCED.
    pub const CDC: Self = Self {
        frame_period: 20,
        hold_after: 41,
        stop_after: 61,
        brake_after: BOARD_MAX_BRAKE_AFTER,
        modes: ModeSet::of(AxisMode::Duty).with(AxisMode::Coast),
        ..Self::AMR_SPI
    };

    /// Seed 003, the Teensy serial arm at 50 Hz: motor angles (position mode, joints within ±π rad)
    /// under a speed cap, coast when calibrating; thresholds as [`Self::CDC`].
    pub const TEENSY: Self = Self {
        frame_period: 20,
        hold_after: 41,
        stop_after: 61,
        brake_after: BOARD_MAX_BRAKE_AFTER,
        // ±π rad: 3.14159 × 65536 ≈ 205887.
        travel_lo: Position::from_bits(-205_887),
        travel_hi: Position::from_bits(205_887),
        modes: ModeSet::of(AxisMode::Position).with(AxisMode::Coast),
        ..Self::AMR_SPI
    };

    /// Seed 004, the Raspberry Pi SPI link at 100 Hz: HOLD after 2 missed transfers (age 21), STOP at
    /// 31, BRAKE at the 49th tick (strictly within 50 ms); every mode (OFF = coast, PASSIV_BRAKE =
    /// short, PWM = duty, MAV = velocity, MTP = position under `motorTarget`'s cap).
    pub const PI_SPI: Self = Self {
        frame_period: 10,
        hold_after: 21,
        stop_after: 31,
        brake_after: 49,
        modes: ModeSet::ALL,
        ..Self::AMR_SPI
    };
}

impl Default for ConfigParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Why a configuration was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum ConfigError {
    /// Thresholds must satisfy 1 ≤ hold_after < stop_after < brake_after.
    ThresholdOrder = 1,
    /// brake_after exceeds [`MAX_BRAKE_AFTER_1KHZ`] (1 kHz profile) or [`BOARD_MAX_BRAKE_AFTER`].
    BrakeTooLate = 2,
    /// v_max must be positive and at most [`V_MAX_CEILING`].
    VMax = 3,
    /// reduced_limit must be positive and at most v_max.
    ReducedLimit = 4,
    /// Every step must be positive and at most v_max.
    Step = 5,
    /// strike_limit must be at least 1.
    StrikeLimit = 6,
    /// window must be between 1 and [`MAX_WINDOW`] ticks.
    Window = 7,
    /// frame_period must be at least 1 and below hold_after (a frame on time never starts HOLD).
    FramePeriod = 8,
    /// 0 < duty_step ≤ duty_max ≤ 1 and 0 < duty_reduced ≤ duty_max.
    Duty = 9,
    /// −[`TRAVEL_CEILING`] ≤ travel_lo < travel_hi ≤ [`TRAVEL_CEILING`].
    Travel = 10,
    /// At least one mode, and only the five defined.
    Modes = 11,
}

const fn step_ok(step: Speed, v_max: Speed) -> bool {
    step.to_bits() > 0 && step.to_bits() <= v_max.to_bits()
}

/// A configuration that passed every check; the only kind the ladder accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Config(ConfigParams);

/// A profile's configuration, checked at compile time (a broken one fails the build).
macro_rules! checked {
    ($p:expr) => {
        match Config::new($p) {
            Ok(c) => c,
            Err(_) => panic!("a profile's configuration is invalid"),
        }
    };
}

impl Config {
    /// Checks `p` and wraps it, or says which rule it breaks.
    pub const fn new(p: ConfigParams) -> Result<Self, ConfigError> {
        if !(p.hold_after >= 1 && p.hold_after < p.stop_after && p.stop_after < p.brake_after) {
            return Err(ConfigError::ThresholdOrder);
        }
        if p.frame_period == 0 || p.frame_period >= p.hold_after {
            return Err(ConfigError::FramePeriod);
        }
        let brake_max = if p.frame_period == 1 {
            MAX_BRAKE_AFTER_1KHZ
        } else {
            BOARD_MAX_BRAKE_AFTER
        };
        if p.brake_after > brake_max {
            return Err(ConfigError::BrakeTooLate);
        }
        if !(p.v_max.to_bits() > 0 && p.v_max.to_bits() <= V_MAX_CEILING.to_bits()) {
            return Err(ConfigError::VMax);
        }
        if !(p.reduced_limit.to_bits() > 0 && p.reduced_limit.to_bits() <= p.v_max.to_bits()) {
            return Err(ConfigError::ReducedLimit);
        }
        let vmax = p.v_max;
        if !(step_ok(p.max_cmd_step, vmax)
            && step_ok(p.accel_step, vmax)
            && step_ok(p.hold_decel_step, vmax)
            && step_ok(p.stop_decel_step, vmax))
        {
            return Err(ConfigError::Step);
        }
        if !(p.duty_max.to_bits() <= Duty::ONE.to_bits()
            && step_ok(p.duty_step, p.duty_max)
            && step_ok(p.duty_reduced, p.duty_max))
        {
            return Err(ConfigError::Duty);
        }
        if !(p.travel_lo.to_bits() < p.travel_hi.to_bits()
            && p.travel_lo.to_bits() >= TRAVEL_CEILING.saturating_neg().to_bits()
            && p.travel_hi.to_bits() <= TRAVEL_CEILING.to_bits())
        {
            return Err(ConfigError::Travel);
        }
        if p.modes.0 == 0 || p.modes.0 & !ModeSet::ALL.0 != 0 {
            return Err(ConfigError::Modes);
        }
        if p.strike_limit == 0 {
            return Err(ConfigError::StrikeLimit);
        }
        if p.window == 0 || p.window > MAX_WINDOW {
            return Err(ConfigError::Window);
        }
        Ok(Self(p))
    }

    /// Seed 000's profile ([`ConfigParams::AMR_SPI`]), checked at compile time.
    pub const AMR_SPI: Self = checked!(ConfigParams::AMR_SPI);
    /// Seed 001's profile ([`ConfigParams::CDC`]), checked at compile time.
    pub const CDC: Self = checked!(ConfigParams::CDC);
    /// Seed 003's profile ([`ConfigParams::TEENSY`]), checked at compile time.
    pub const TEENSY: Self = checked!(ConfigParams::TEENSY);
    /// Seed 004's profile ([`ConfigParams::PI_SPI`]), checked at compile time.
    pub const PI_SPI: Self = checked!(ConfigParams::PI_SPI);
    /// Every profile the firmware ships.
    pub const PROFILES: [Self; 4] = [Self::AMR_SPI, Self::CDC, Self::TEENSY, Self::PI_SPI];
    /// The seed's defaults: [`Self::AMR_SPI`].
    pub const DEFAULT: Self = Self::AMR_SPI;

    /// The checked values.
    pub const fn params(&self) -> &ConfigParams {
        &self.0
    }

    /// True for a 1 kHz profile (a frame every tick), whose bound is strictly within 10 ms.
    pub const fn is_1khz(&self) -> bool {
        self.0.frame_period == 1
    }

    /// The comm-loss bound this profile promises, in ms from the arrival of the last valid frame to
    /// the bridge braked, given the tick task's worst-case response R < 1 ms: `brake_after` + 1
    /// (strict). 10 for seed 000.
    pub const fn comm_loss_bound_ms(&self) -> u16 {
        self.0.brake_after.saturating_add(1)
    }

    /// The largest change of a speed setpoint or cap in one tick outside BRAKE (INV-8's bound).
    pub const fn max_tick_step(&self) -> Speed {
        let p = &self.0;
        let mut m = p.accel_step;
        if p.hold_decel_step.to_bits() > m.to_bits() {
            m = p.hold_decel_step;
        }
        if p.stop_decel_step.to_bits() > m.to_bits() {
            m = p.stop_decel_step;
        }
        m
    }
}

impl Default for Config {
    fn default() -> Self {
        Self::DEFAULT
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_is_the_seed() {
        let p = Config::DEFAULT.params();
        assert_eq!((p.hold_after, p.stop_after, p.brake_after), (3, 5, 9));
        assert_eq!(p.reduced_limit * 2, p.v_max);
        assert_eq!(Config::DEFAULT.comm_loss_bound_ms(), 10);
    }

    /// Each profile's promise in ms (from the seeds): seed 000 10 ms, seed 001 the board maximum 250 ms
    /// (a frame's `timeout_ms` lowers it), seed 003 likewise, seed 004 50 ms; only seed 000 is 1 kHz.
    #[test]
    fn each_profile_states_its_bound() {
        let bounds: [(Config, u16, bool); 4] = [
            (Config::AMR_SPI, 10, true),
            (Config::CDC, 250, false),
            (Config::TEENSY, 250, false),
            (Config::PI_SPI, 50, false),
        ];
        for (c, ms, fast) in bounds {
            assert_eq!(c.comm_loss_bound_ms(), ms, "{c:?}");
            assert_eq!(c.is_1khz(), fast);
            if c.is_1khz() {
                assert!(
                    c.comm_loss_bound_ms() <= 10,
                    "1 kHz profiles brake within 10 ms"
                );
            }
        }
        // Seed 001's example: timeout_ms = 200 brakes at the 199th tick, strictly within 200 ms.
        assert_eq!(brake_age_for_timeout_ms(200), Some(199));
        assert_eq!(brake_age_for_timeout_ms(1), Some(1));
        assert_eq!(brake_age_for_timeout_ms(0), None);
    }

    #[test]
    fn refuses_each_broken_rule() {
        let d = ConfigParams::DEFAULT;
        let cases: [(ConfigParams, ConfigError); 14] = [
            (
                ConfigParams {
                    frame_period: 3,
                    ..d
                },
                ConfigError::FramePeriod,
            ),
            (
                ConfigParams {
                    frame_period: 0,
                    ..d
                },
                ConfigError::FramePeriod,
            ),
            (
                ConfigParams {
                    duty_max: Duty::ONE + Duty::from_bits(1),
                    ..d
                },
                ConfigError::Duty,
            ),
            (
                ConfigParams {
                    travel_lo: d.travel_hi,
                    ..d
                },
                ConfigError::Travel,
            ),
            (
                ConfigParams {
                    modes: ModeSet(0),
                    ..d
                },
                ConfigError::Modes,
            ),
            (
                ConfigParams { hold_after: 0, ..d },
                ConfigError::ThresholdOrder,
            ),
            (
                ConfigParams { stop_after: 3, ..d },
                ConfigError::ThresholdOrder,
            ),
            (
                ConfigParams {
                    brake_after: 5,
                    ..d
                },
                ConfigError::ThresholdOrder,
            ),
            (
                ConfigParams {
                    brake_after: 10,
                    ..d
                },
                ConfigError::BrakeTooLate,
            ),
            (
                ConfigParams {
                    v_max: Speed::ZERO,
                    ..d
                },
                ConfigError::VMax,
            ),
            (
                ConfigParams {
                    reduced_limit: Speed::from_num(21),
                    ..d
                },
                ConfigError::ReducedLimit,
            ),
            (
                ConfigParams {
                    stop_decel_step: Speed::ZERO,
                    ..d
                },
                ConfigError::Step,
            ),
            (
                ConfigParams {
                    strike_limit: 0,
                    ..d
                },
                ConfigError::StrikeLimit,
            ),
            (ConfigParams { window: 0, ..d }, ConfigError::Window),
        ];
        for (p, e) in cases {
            assert_eq!(Config::new(p), Err(e), "{p:?}");
        }
    }

    #[test]
    fn max_tick_step_is_the_largest_step() {
        assert_eq!(
            Config::DEFAULT.max_tick_step(),
            ConfigParams::DEFAULT.stop_decel_step
        );
    }
}

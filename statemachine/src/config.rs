//! Validated ladder configuration: thresholds in watchdog ticks, speeds and steps in rad/s.

use crate::types::Speed;

/// The largest `brake_after` a configuration may have: comm loss must brake within 10 ticks (10 ms at 1 kHz).
pub const MAX_BRAKE_AFTER: u16 = 10;

/// The largest `v_max` accepted, rad/s at the wheel (well inside the Q16.16 range, so sums of two speeds never saturate).
pub const V_MAX_CEILING: Speed = Speed::const_from_int(1000);

/// The longest quality window accepted, in ticks (one minute at 1 kHz).
pub const MAX_WINDOW: u16 = 60_000;

/// Raw configuration values before validation; [`Config::new`] checks them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConfigParams {
    /// Ticks since the last valid frame before HOLD. Seed: "2 missed cycles"; with a frame every tick the age
    /// is 1 at each tick, so two missed frames make age 3.
    pub hold_after: u16,
    /// Ticks since the last valid frame before STOP.
    pub stop_after: u16,
    /// Ticks since the last valid frame before BRAKE (seed: 10 ms); at most [`MAX_BRAKE_AFTER`].
    pub brake_after: u16,
    /// Largest wheel speed magnitude accepted from the host, rad/s.
    pub v_max: Speed,
    /// Speed magnitude allowed in REDUCED, rad/s (seed: 50 % of v_max).
    pub reduced_limit: Speed,
    /// Largest change between two consecutive valid commands, rad/s per tick (max acceleration × 1 ms).
    pub max_cmd_step: Speed,
    /// Largest change of the applied setpoint per tick in NORMAL and REDUCED, rad/s.
    pub accel_step: Speed,
    /// Deceleration per tick in HOLD, rad/s (gentle: the host may come back).
    pub hold_decel_step: Speed,
    /// Deceleration per tick in STOP, rad/s.
    pub stop_decel_step: Speed,
    /// Strikes (refused frames and entries into HOLD) within one window that degrade NORMAL to REDUCED.
    pub strike_limit: u16,
    /// Window length in ticks: counting strikes, and the clean time REDUCED needs before NORMAL.
    pub window: u16,
}

impl ConfigParams {
    /// The seed's figures: HOLD after 2 missed cycles (age 3), STOP at 5, BRAKE at 10; 20 rad/s, half in REDUCED;
    /// 50 rad/s² command acceleration, 100 rad/s² STOP deceleration; 3 strikes per 1 s window.
    pub const DEFAULT: Self = Self {
        hold_after: 3,
        stop_after: 5,
        brake_after: 10,
        v_max: Speed::const_from_int(20),
        reduced_limit: Speed::const_from_int(10),
        // 50 rad/s² × 1 ms = 0.05 rad/s per tick (Q16.16 bits: 0.05 × 65536 ≈ 3277).
        max_cmd_step: Speed::from_bits(3277),
        accel_step: Speed::from_bits(3277),
        // HOLD: 20 rad/s² (0.02 rad/s per tick).
        hold_decel_step: Speed::from_bits(1311),
        // STOP: 100 rad/s² (0.1 rad/s per tick).
        stop_decel_step: Speed::from_bits(6554),
        strike_limit: 3,
        window: 1000,
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
    /// brake_after exceeds [`MAX_BRAKE_AFTER`].
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
}

const fn step_ok(step: Speed, v_max: Speed) -> bool {
    step.to_bits() > 0 && step.to_bits() <= v_max.to_bits()
}

/// A configuration that passed every check; the only kind the ladder accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Config(ConfigParams);

impl Config {
    /// Checks `p` and wraps it, or says which rule it breaks.
    pub const fn new(p: ConfigParams) -> Result<Self, ConfigError> {
        if !(p.hold_after >= 1 && p.hold_after < p.stop_after && p.stop_after < p.brake_after) {
            return Err(ConfigError::ThresholdOrder);
        }
        if p.brake_after > MAX_BRAKE_AFTER {
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
        if p.strike_limit == 0 {
            return Err(ConfigError::StrikeLimit);
        }
        if p.window == 0 || p.window > MAX_WINDOW {
            return Err(ConfigError::Window);
        }
        Ok(Self(p))
    }

    /// The seed's defaults ([`ConfigParams::DEFAULT`]), checked at compile time.
    pub const DEFAULT: Self = match Self::new(ConfigParams::DEFAULT) {
        Ok(c) => c,
        Err(_) => panic!("default configuration is invalid"),
    };

    /// The checked values.
    pub const fn params(&self) -> &ConfigParams {
        &self.0
    }

    /// The largest change of the applied setpoint in one tick outside BRAKE (INV-8's bound).
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
        assert_eq!((p.hold_after, p.stop_after, p.brake_after), (3, 5, 10));
        assert_eq!(p.reduced_limit * 2, p.v_max);
    }

    #[test]
    fn refuses_each_broken_rule() {
        let d = ConfigParams::DEFAULT;
        let cases: [(ConfigParams, ConfigError); 9] = [
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
                    brake_after: 11,
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

//! The board's tuning, in one place: loop rates, controller gains, the speed-loop ramp derived from
//! the ladder's configuration, trip levels, ADC and encoder scaling. The firmware and the simulator
//! both build their task state from a [`Tuning`]; neither has numbers of its own.

use control::{AntiWindup, PidGains, Q};
use statemachine::{Config, Speed};

/// Everything the task bodies need to know about one board and its motors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tuning {
    /// The ladder's configuration (thresholds in ticks, speed limits and steps per tick).
    pub ladder: Config,
    /// Clock of the PWM timers (TIM1/TIM8 on APB2), Hz.
    pub pwm_timer_hz: u32,
    /// Current-loop and PWM rate, Hz.
    pub pwm_hz: u32,
    /// Speed-loop rate, Hz.
    pub speed_hz: u32,
    /// Watchdog tick rate, Hz (the ladder's time base).
    pub tick_hz: u32,
    /// Speed controller: wheel speed error (rad/s) → motor current reference (A).
    pub speed: PidGains,
    /// Current controller: current error (A) → duty.
    pub current: PidGains,
    /// Shunt current sensing gain, A per ADC count.
    pub amps_per_count: Q,
    /// Nominal ADC reading at zero current (the amplifier's mid-scale bias).
    pub adc_zero: u16,
    /// Largest distance of a calibrated zero-current reading from `adc_zero` that is believed;
    /// further off, the sensor is taken as faulty (see [`Tuning::calibrated_offset`]).
    pub adc_offset_tolerance: u16,
    /// Software overcurrent trip level, A (the hardware comparator trips faster, a little higher).
    pub trip_amps: Q,
    /// Encoder counts per wheel revolution (after ×4 decoding).
    pub counts_per_rev: u32,
    /// Encoder scale: rad/s per count across the speed estimator's window at `speed_hz`
    /// (`control::sense::speed_scale`; a test checks the two agree).
    pub speed_scale: Q,
    /// Runs per tick the control loops must reach for the IWDG to be refreshed
    /// [current_loop, speed_pid].
    pub min_runs_per_tick: [u32; 2],
}

/// The AMR drive board (seed 000): STM32F407, two brushed 24 V gearmotors (R = 1 Ω, L = 0.5 mH,
/// Kt = Ke = 0.04 N·m/A, 20:1, 4096-count encoders on the wheel side), 5 mΩ shunts with ×20
/// amplifiers on a 3.3 V 12-bit ADC. The simulator's default plant is this motor.
///
/// Speed PI: 4 A per rad/s, 40 A/rad (Ki·dt at 10 kHz), 10 A limit; current PI: 0.13 duty/A,
/// 260 /(A·s) (Ki·dt at 20 kHz), ≈ 1 kHz closed-loop bandwidth for L/R = 0.5 ms at 24 V, duty
/// limited to 0.95 so the gate driver's bootstrap capacitors recharge every period.
pub const AMR: Tuning = Tuning {
    ladder: Config::DEFAULT,
    pwm_timer_hz: 168_000_000,
    pwm_hz: 20_000,
    speed_hz: 10_000,
    tick_hz: 1_000,
    speed: PidGains {
        kp: Q::lit("4"),
        ki_dt: Q::lit("0.004"),
        kd_dt: Q::ZERO,
        out_limit: Q::lit("10"),
        i_limit: Q::lit("10"),
        anti_windup: AntiWindup::Conditional,
    },
    current: PidGains {
        kp: Q::lit("0.13"),
        ki_dt: Q::lit("0.013"),
        kd_dt: Q::ZERO,
        out_limit: Q::lit("0.95"),
        i_limit: Q::lit("0.95"),
        anti_windup: AntiWindup::Conditional,
    },
    // 3.3 V / 4096 counts / (5 mΩ × 20) = 8.0566 mA per count: ±16.5 A full scale around mid-scale.
    amps_per_count: Q::lit("0.0080566"),
    adc_zero: 2048,
    // ±100 counts = ±0.8 A of amplifier offset (datasheet-class ±2 % of full scale, with margin).
    adc_offset_tolerance: 100,
    trip_amps: Q::lit("14"),
    counts_per_rev: 4096,
    // 2π · 10 000 / (4096 · 16) = 0.958737 rad/s per count.
    speed_scale: Q::lit("0.958737"),
    // Nominal 20 and 10 runs per 1 ms tick; one missed run each is tolerated.
    min_runs_per_tick: [18, 9],
};

const _: () =
    assert!(AMR.pwm_hz.is_multiple_of(AMR.speed_hz) && AMR.speed_hz.is_multiple_of(AMR.tick_hz));
const _: () = assert!(AMR.pwm_arr().is_some());

impl Tuning {
    /// Auto-reload of the centre-aligned PWM timers, `None` if the rate does not divide the clock.
    pub const fn pwm_arr(&self) -> Option<u16> {
        crate::timing::center_aligned_arr(self.pwm_timer_hz, self.pwm_hz)
    }

    /// Microseconds per watchdog tick.
    pub const fn us_per_tick(&self) -> u32 {
        match 1_000_000u32.checked_div(self.tick_hz) {
            Some(us) => us,
            None => 0,
        }
    }

    /// Speed-loop samples per watchdog tick.
    pub const fn speed_samples_per_tick(&self) -> u32 {
        match self.speed_hz.checked_div(self.tick_hz) {
            Some(0) | None => 1,
            Some(n) => n,
        }
    }

    /// Current-loop samples per speed-loop sample.
    pub const fn current_samples_per_speed(&self) -> u32 {
        match self.pwm_hz.checked_div(self.speed_hz) {
            Some(0) | None => 1,
            Some(n) => n,
        }
    }

    /// The speed loop's reference ramp per sample: the ladder's largest change per tick
    /// ([`Config::max_tick_step`]) spread over the samples of one tick, rounded up, so the ramp
    /// interpolates between the ladder's setpoints and never lags them (a smaller step would make
    /// STOP decelerate slower on the board than the ladder commands).
    pub const fn ref_step(&self) -> Speed {
        let per_tick = self.ladder.max_tick_step().to_bits();
        let n = self.speed_samples_per_tick() as i32;
        // per_tick > 0 (Config refuses non-positive steps) and n ≥ 1: the ceiling division is exact.
        let bits = match per_tick.checked_add(n.saturating_sub(1)) {
            Some(s) => match s.checked_div(n) {
                Some(b) => b,
                None => per_tick,
            },
            None => per_tick,
        };
        Speed::from_bits(bits)
    }

    /// The zero-current reading to use for one shunt, from the mean reading taken at boot with the
    /// bridge braked (no current flows): the measurement if it is within `adc_offset_tolerance` of
    /// `adc_zero`, or `None` (a sensor fault: the board stays braked).
    pub const fn calibrated_offset(&self, mean_reading: u16) -> Option<u16> {
        let d = mean_reading.abs_diff(self.adc_zero);
        if d <= self.adc_offset_tolerance {
            Some(mean_reading)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encoder_scale_matches_its_formula() {
        let exact = control::sense::speed_scale(AMR.counts_per_rev, AMR.speed_hz).unwrap();
        let d = (exact.to_bits() - AMR.speed_scale.to_bits()).abs();
        assert!(d <= 1, "speed_scale {} vs {exact}", AMR.speed_scale);
    }

    #[test]
    fn ramp_covers_the_ladder_step_in_one_tick() {
        // STOP is the ladder's steepest step: 0.1 rad/s per tick (6554 bits). Ten samples per
        // tick must cover it: 656 bits each (6560 ≥ 6554), not the 0.005 rad/s (328 bits) that
        // would take two ticks.
        assert_eq!(AMR.ladder.max_tick_step().to_bits(), 6554);
        assert_eq!(AMR.speed_samples_per_tick(), 10);
        assert_eq!(AMR.ref_step().to_bits(), 656);
        assert!(AMR.ref_step().to_bits() * 10 >= AMR.ladder.params().stop_decel_step.to_bits());
    }

    #[test]
    fn rates_by_hand() {
        // TIM1/TIM8 at 168 MHz, centre-aligned 20 kHz: 168e6 / (2 · 20e3) = 4200 counts.
        assert_eq!(AMR.pwm_arr(), Some(4200));
        // 20 kHz current loop, 10 kHz speed loop, 1 kHz tick.
        assert_eq!(AMR.current_samples_per_speed(), 2);
        assert_eq!(AMR.us_per_tick(), 1000);
    }

    #[test]
    fn gains_are_valid() {
        assert!(AMR.speed.is_valid() && AMR.current.is_valid());
        assert!(AMR.current.out_limit <= Q::ONE);
    }

    #[test]
    fn offsets_by_hand() {
        assert_eq!(AMR.calibrated_offset(2048), Some(2048));
        assert_eq!(AMR.calibrated_offset(2148), Some(2148));
        assert_eq!(AMR.calibrated_offset(1948), Some(1948));
        assert_eq!(AMR.calibrated_offset(2149), None);
        assert_eq!(AMR.calibrated_offset(0), None);
        assert_eq!(AMR.calibrated_offset(4095), None);
    }
}

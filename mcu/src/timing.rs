//! Timer, watchdog and time-stamp arithmetic as `const fn`s: the firmware evaluates the
//! configuration ones in `const` items (an inexact rate fails the build), the tests check them here.

/// Timer prescaler and auto-reload for an update rate: `clk / ((psc + 1) · (arr + 1)) = rate`.
///
/// Picks the smallest prescaler that makes ARR fit 16 bits. `None` if the rate is zero, above the
/// clock, or not an exact divisor of it (a rate error would break the tick-to-millisecond argument
/// of the safety case, so inexact rates are refused rather than rounded).
// Configuration arithmetic, evaluated in `const` items of the firmware: every divisor is checked
// non-zero and every product bounded in the comments (a violation would fail the build, not the MCU).
#[allow(clippy::arithmetic_side_effects)]
pub const fn timer_divider(clk_hz: u32, rate_hz: u32) -> Option<(u16, u16)> {
    let total = match clk_hz.checked_div(rate_hz) {
        Some(t) if t >= 1 && clk_hz.is_multiple_of(rate_hz) => t,
        _ => return None,
    };
    let mut psc: u32 = 1;
    while psc <= 65_536 {
        // psc ≥ 1, so the remainder and quotient cannot fail; both results are ≤ 65_536 here.
        if total % psc == 0 && total / psc <= 65_536 {
            return Some((
                psc.saturating_sub(1) as u16,
                (total / psc).saturating_sub(1) as u16,
            ));
        }
        psc = psc.saturating_add(1);
    }
    None
}

/// Auto-reload for a centre-aligned PWM timer: the counter runs up and down, one period is
/// 2·ARR clocks, so ARR = clk / (2 · f_pwm). `None` unless exact and within 16 bits.
#[allow(clippy::arithmetic_side_effects)] // as for `timer_divider`
pub const fn center_aligned_arr(clk_hz: u32, pwm_hz: u32) -> Option<u16> {
    let two_f = match pwm_hz.checked_mul(2) {
        Some(v) if v > 0 => v,
        _ => return None,
    };
    match clk_hz.checked_div(two_f) {
        Some(arr) if arr >= 1 && arr <= 65_535 && clk_hz.is_multiple_of(two_f) => Some(arr as u16),
        _ => None,
    }
}

/// Independent-watchdog setting: prescaler register code (0 → /4 … 6 → /256) and 12-bit reload.
///
/// The timeout is `4·2^code · (reload + 1) / f_LSI`. Chooses the smallest prescaler whose reload
/// fits for the requested timeout at the *nominal* LSI; returns `(code, reload)`.
#[allow(clippy::arithmetic_side_effects)] // as for `timer_divider`
pub const fn iwdg_setting(timeout_ms: u32, lsi_hz: u32) -> Option<(u8, u16)> {
    let mut code: u8 = 0;
    while code <= 6 {
        let div = 4u64 << code;
        // ticks = timeout · f_LSI / (1000 · div); the product of two u32 fits u64.
        let ticks = match (timeout_ms as u64 * lsi_hz as u64).checked_div(1000 * div) {
            Some(t) => t,
            None => return None,
        };
        if ticks >= 1 && ticks <= 4096 {
            return Some((code, ticks.saturating_sub(1) as u16));
        }
        code = code.saturating_add(1);
    }
    None
}

/// The IWDG timeout in microseconds for a setting and an LSI frequency (0 if `lsi_hz` is 0).
#[allow(clippy::arithmetic_side_effects)] // as for `timer_divider`
pub const fn iwdg_timeout_us(code: u8, reload: u16, lsi_hz: u32) -> u64 {
    let div = 4u64 << (code & 7);
    // ≤ 512 · 4096 · 10⁶ < 2⁴¹: no overflow.
    match (div * (reload as u64 + 1) * 1_000_000).checked_div(lsi_hz as u64) {
        Some(t) => t,
        None => 0,
    }
}

/// Microseconds since boot from the tick count and the tick timer's counter, for the feedback
/// frame's `timestamp_us` (wraps after 71.6 minutes, as the wire field does).
///
/// ```text
///  tick timer  0 ───────────── period−1 │ 0 ──── …          one update (wrap) per 1 ms tick
///  ticks       n                        │ n+1 (when watchdog_tick has run)
///  read order: count first, then the update flag; a flag seen with a small count means the wrap
///  happened before the count was read but the tick task has not counted it yet.
/// ```
///
/// `count` is the counter value, `update_pending` the timer's update flag read after it,
/// `counts_per_tick` the timer period in counts and `us_per_tick` the tick length in µs.
pub const fn micros(
    ticks: u32,
    count: u32,
    update_pending: bool,
    counts_per_tick: u32,
    us_per_tick: u32,
) -> u32 {
    let period = if counts_per_tick == 0 {
        1
    } else {
        counts_per_tick
    };
    let count = if count >= period {
        period.saturating_sub(1)
    } else {
        count
    };
    let ticks = if update_pending && count < period / 2 {
        ticks.wrapping_add(1)
    } else {
        ticks
    };
    // count < period, so count · us_per_tick / period < us_per_tick; the product fits u64.
    let sub = match (count as u64)
        .saturating_mul(us_per_tick as u64)
        .checked_div(period as u64)
    {
        Some(s) => s,
        None => 0,
    };
    ticks.wrapping_mul(us_per_tick).wrapping_add(sub as u32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timer_dividers() {
        // 84 MHz, 1 kHz: 84 000 clocks = (psc+1)(arr+1); the smallest psc with arr ≤ 65535 is 2.
        assert_eq!(timer_divider(84_000_000, 1_000), Some((1, 41_999)));
        assert_eq!(timer_divider(84_000_000, 10_000), Some((0, 8_399)));
        assert_eq!(timer_divider(16_000_000, 1_000), Some((0, 15_999)));
        assert_eq!(timer_divider(84_000_000, 9), None);
        assert_eq!(timer_divider(84_000_000, 0), None);
        // 1 000 001 Hz / 1 kHz = 1000.001: inexact, refused (not rounded to 1000).
        assert_eq!(timer_divider(1_000_001, 1_000), None);
        // A rate above the clock.
        assert_eq!(timer_divider(1_000, 2_000), None);
        // 168 MHz centre-aligned at 20 kHz: 168e6 / 40e3 = 4200.
        assert_eq!(center_aligned_arr(168_000_000, 20_000), Some(4200));
        assert_eq!(center_aligned_arr(168_000_000, 1), None);
    }

    #[test]
    fn iwdg_by_hand() {
        // 32 kHz nominal LSI, 50 ms: /4 gives 400 ticks → reload 399, 50 ms.
        assert_eq!(iwdg_setting(50, 32_000), Some((0, 399)));
        assert_eq!(iwdg_timeout_us(0, 399, 32_000), 50_000);
        // LSI is 17..47 kHz over temperature and parts (DS8626): the same setting spans 34..94 ms.
        assert_eq!(iwdg_timeout_us(0, 399, 47_000), 34_042);
        assert_eq!(iwdg_timeout_us(0, 399, 17_000), 94_117);
        // 1 s needs /8: 32000·1/8 = 4000 → reload 3999.
        assert_eq!(iwdg_setting(1000, 32_000), Some((1, 3999)));
        // And back: /8 · 4000 counts at 32 kHz is 1 s; /256 · 4096 is 32.768 s.
        assert_eq!(iwdg_timeout_us(1, 3999, 32_000), 1_000_000);
        assert_eq!(iwdg_timeout_us(6, 4095, 32_000), 32_768_000);
    }

    #[test]
    fn micros_by_hand() {
        // 84 000 counts per 1 ms tick: 42 000 counts is half a millisecond.
        assert_eq!(micros(7, 42_000, false, 84_000, 1000), 7_500);
        assert_eq!(micros(7, 0, false, 84_000, 1000), 7_000);
        assert_eq!(micros(7, 83_999, false, 84_000, 1000), 7_999);
        // The timer wrapped but the tick task has not run yet: the count belongs to tick 8.
        assert_eq!(micros(7, 84, true, 84_000, 1000), 8_001);
        // Flag set after a late count read: the count still belongs to tick 7.
        assert_eq!(micros(7, 83_990, true, 84_000, 1000), 7_999);
        // Only a count below half a period is taken as after the wrap; half a period is before it.
        assert_eq!(micros(7, 41_999, true, 84_000, 1000), 8_499);
        assert_eq!(micros(7, 42_000, true, 84_000, 1000), 7_500);
        // Wraps like the u32 wire field.
        assert_eq!(
            micros(4_294_967, 296_000 / 1000 * 84, false, 84_000, 1000),
            0
        );
    }

    #[test]
    fn micros_never_goes_back_across_a_wrap() {
        // Walk through two ticks in steps of 7 counts, reading the count before the flag, with the
        // tick task running a little after each wrap: time only moves forward.
        let period = 84_000u32;
        let mut ticks = 0u32;
        let mut pending = false;
        let mut last = 0u32;
        let mut c = 0u32;
        for step in 0..30_000u32 {
            c += 7;
            if c >= period {
                c -= period;
                pending = true;
            }
            // The tick task runs 300 counts after the wrap and clears the flag.
            if pending && c >= 300 {
                ticks += 1;
                pending = false;
            }
            let now = micros(ticks, c, pending, period, 1000);
            assert!(now >= last, "time went back at step {step}: {last} → {now}");
            last = now;
        }
        assert!(last >= 2000);
    }
}

//! `motorlink teleop`: the keyboard's twist, as a pure state machine over key presses and time.
//!
//! Keys step the forward speed v (w/s, up/down) and the yaw rate ω (a/d, left/right) within the
//! limits; space sets both to zero. The twist is sent only while keys keep arriving: for
//! `hold` after the last key. A terminal repeats a held key (after its repeat delay, typically
//! 250 to 660 ms, then some 25 to 40 times a second), so holding a key keeps the robot going, and
//! a key press repeated within [`REPEAT_US`] of the same key's previous one counts as that key
//! held, not as another step: tap to change the speed, hold to keep it.
//!
//! ```text
//!  key ─┐ (tap: step)      ┌ held: repeats keep it alive, no step
//!  sent ████████████████████████████████████░░░░░░░░ (hold after the last key: not sent)
//!  bridge target  (v, ω) ……………………………………………………… 200 ms later stale ⇒ 0, ramped down at the slew limit
//! ```
//!
//! When nothing is sent, the bridge's own 200 ms staleness rule sets the target to zero, so a
//! dead terminal, a closed ssh session or a hung keyboard stops the robot; the twist shown is then
//! reset to zero, so the next key starts from standstill.

/// A key, as teleop reads it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Key {
    /// Faster forward (w, up arrow).
    Up,
    /// Slower / backward (s, down arrow).
    Down,
    /// Turn left: ω up (a, left arrow).
    Left,
    /// Turn right: ω down (d, right arrow).
    Right,
    /// Zero twist (space).
    Zero,
    /// Quit (q, Esc, Ctrl-C).
    Quit,
    /// Stop by a frame gap: the MCU brakes (x).
    Estop,
    /// Re-arm after BRAKE (r).
    Rearm,
    /// Any other key: keeps the command alive, changes nothing.
    Other,
}

/// A press of the same key within this long of its previous press is the terminal repeating a
/// held key, µs.
pub const REPEAT_US: u64 = 100_000;

/// Teleop's limits and steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TeleopConfig {
    /// Largest |v|, m/s.
    pub max_v: f64,
    /// Largest |ω|, rad/s.
    pub max_w: f64,
    /// v step per key, m/s.
    pub step_v: f64,
    /// ω step per key, rad/s.
    pub step_w: f64,
    /// How long after the last key the twist is still sent, µs.
    pub hold_us: u64,
}

impl TeleopConfig {
    /// 0.5 m/s and 1.5 rad/s at most, steps of 0.05 m/s and 0.25 rad/s, held 750 ms (above the
    /// usual key repeat delays).
    pub const DEFAULT: Self = Self {
        max_v: 0.5,
        max_w: 1.5,
        step_v: 0.05,
        step_w: 0.25,
        hold_us: 750_000,
    };
}

/// The teleop state.
#[derive(Clone, Debug, PartialEq)]
pub struct Teleop {
    cfg: TeleopConfig,
    v: f64,
    w: f64,
    last_key_us: Option<u64>,
    last_step: Option<(Key, u64)>,
}

impl Teleop {
    /// Standing, nothing pressed.
    pub fn new(cfg: TeleopConfig) -> Self {
        Self {
            cfg,
            v: 0.0,
            w: 0.0,
            last_key_us: None,
            last_step: None,
        }
    }

    /// A key arrived at `now_us`.
    pub fn key(&mut self, key: Key, now_us: u64) {
        self.last_key_us = Some(now_us);
        let (dv, dw) = match key {
            Key::Up => (self.cfg.step_v, 0.0),
            Key::Down => (-self.cfg.step_v, 0.0),
            Key::Left => (0.0, self.cfg.step_w),
            Key::Right => (0.0, -self.cfg.step_w),
            Key::Zero | Key::Estop | Key::Rearm => {
                self.zero(now_us);
                return;
            }
            Key::Quit | Key::Other => return,
        };
        let held = self
            .last_step
            .is_some_and(|(k, t)| k == key && now_us.saturating_sub(t) < REPEAT_US);
        self.last_step = Some((key, now_us));
        if held {
            return;
        }
        self.v = round(clamp(self.v + dv, self.cfg.max_v));
        self.w = round(clamp(self.w + dw, self.cfg.max_w));
    }

    /// Zero twist (still alive: the robot is told to stand).
    pub fn zero(&mut self, now_us: u64) {
        self.v = 0.0;
        self.w = 0.0;
        self.last_key_us = Some(now_us);
        self.last_step = None;
    }

    fn alive(&self, now_us: u64) -> bool {
        self.last_key_us
            .is_some_and(|t| now_us.saturating_sub(t) <= self.cfg.hold_us)
    }

    /// The twist to send at `now_us`, or `None` when no key came for `hold` (the twist is then
    /// forgotten: the next key starts from zero).
    pub fn command(&mut self, now_us: u64) -> Option<(f64, f64)> {
        if self.alive(now_us) {
            Some((self.v, self.w))
        } else {
            self.v = 0.0;
            self.w = 0.0;
            self.last_step = None;
            None
        }
    }

    /// What the view shows: (v, ω, being sent).
    pub fn shown(&self, now_us: u64) -> (f64, f64, bool) {
        (self.v, self.w, self.alive(now_us))
    }
}

fn clamp(x: f64, max: f64) -> f64 {
    x.clamp(-max, max)
}

/// Rounds to 1e-9, so repeated steps land on their multiples (0.1 + 0.05 − 0.15 = 0).
fn round(x: f64) -> f64 {
    (x * 1e9).round() / 1e9
}

#[cfg(test)]
#[allow(clippy::float_cmp, clippy::arithmetic_side_effects)]
mod tests {
    use super::*;

    const MS: u64 = 1000;

    #[test]
    fn taps_step_within_the_limits() {
        let mut t = Teleop::new(TeleopConfig::DEFAULT);
        // Three taps 200 ms apart: 0.15 m/s.
        for k in 0..3 {
            t.key(Key::Up, k * 200 * MS);
        }
        assert_eq!(t.command(400 * MS), Some((0.15, 0.0)));
        // Twenty more taps: capped at 0.5.
        for k in 3..23 {
            t.key(Key::Up, k * 200 * MS);
        }
        assert_eq!(t.command(4400 * MS).map(|c| c.0), Some(0.5));
        // Left turns: 0.25 rad/s each, capped at 1.5; right brings it back.
        for k in 23..33 {
            t.key(Key::Left, k * 200 * MS);
        }
        assert_eq!(t.command(6400 * MS).map(|c| c.1), Some(1.5));
        t.key(Key::Right, 6600 * MS);
        assert_eq!(t.command(6600 * MS), Some((0.5, 1.25)));
        t.key(Key::Zero, 6800 * MS);
        assert_eq!(t.command(6800 * MS), Some((0.0, 0.0)));
    }

    #[test]
    fn a_held_key_keeps_the_twist_alive_without_stepping_again() {
        let mut t = Teleop::new(TeleopConfig::DEFAULT);
        t.key(Key::Up, 0);
        // The terminal's repeat delay (500 ms), then repeats every 33 ms for two seconds.
        let mut now = 500 * MS;
        t.key(Key::Up, now);
        while now < 2500 * MS {
            now += 33 * MS;
            t.key(Key::Up, now);
            assert_eq!(t.command(now), Some((0.1, 0.0)), "at {now}");
        }
    }

    #[test]
    fn without_keys_the_twist_is_no_longer_sent_and_is_forgotten() {
        let mut t = Teleop::new(TeleopConfig::DEFAULT);
        assert_eq!(t.command(0), None, "nothing pressed, nothing sent");
        t.key(Key::Up, 0);
        assert_eq!(t.command(750 * MS), Some((0.05, 0.0)));
        assert_eq!(t.command(751 * MS), None);
        assert_eq!(t.shown(751 * MS), (0.0, 0.0, false));
        // The next key starts from zero.
        t.key(Key::Up, 2000 * MS);
        assert_eq!(t.command(2000 * MS), Some((0.05, 0.0)));
    }

    #[test]
    fn other_keys_keep_it_alive_and_change_nothing() {
        let mut t = Teleop::new(TeleopConfig::DEFAULT);
        t.key(Key::Down, 0);
        t.key(Key::Other, 700 * MS);
        assert_eq!(t.command(1400 * MS), Some((-0.05, 0.0)));
    }
}

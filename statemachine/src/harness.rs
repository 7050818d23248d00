//! One harness body, two drivers: Kani's symbolic values under `cargo kani`, and biased pseudo-random
//! values under `cargo test`, so a machine without Kani still checks every property.
//!
//! A harness body takes `&mut impl Source`, draws its inputs from it, narrows them with
//! [`assume!`](crate::assume) and marks interesting cases with [`cover!`](crate::cover). Under Kani
//! `cover!` is `kani::cover!` (the proof reports it SATISFIED or UNSATISFIABLE); under `cargo test`
//! [`Twin`] records which covers fired and [`Report::assert_covered`] fails the test if one never did.

use crate::types::Speed;

/// Where a harness draws its inputs from.
pub trait Source {
    /// Any `u8`.
    fn u8(&mut self) -> u8;
    /// Any `u16`.
    fn u16(&mut self) -> u16;
    /// Any `u32`.
    fn u32(&mut self) -> u32;
    /// Any `bool`.
    fn bool(&mut self) -> bool;
    /// Any `f32` bit pattern, NaN and infinities included.
    fn f32(&mut self) -> f32;
    /// Narrows the inputs: returns false if the case must be skipped (tests); under Kani it assumes and returns true.
    fn assume(&mut self, cond: bool) -> bool;
    /// Records a cover point (tests); a no-op under Kani, where `kani::cover!` reports it.
    fn record(&mut self, cond: bool, name: &'static str);

    /// Any `i32`.
    fn i32(&mut self) -> i32 {
        self.u32() as i32
    }
    /// Any Q16.16 speed bit pattern.
    fn speed(&mut self) -> Speed {
        Speed::from_bits(self.i32())
    }
    /// Any speed in `-max ..= max` (max ≥ 0). Kani: any value, assumed in range; tests: biased to the ends.
    fn speed_within(&mut self, max: Speed) -> Speed;
    /// Any `N` bytes. Kani: one symbolic array, with no loop to unwind.
    fn bytes<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        for b in out.iter_mut() {
            *b = self.u8();
        }
        out
    }
    /// A value in `0..n` (n ≥ 1); used to pick among enum variants.
    fn below(&mut self, n: u8) -> u8 {
        self.u8().checked_rem(n).unwrap_or(0)
    }
    /// A value in `0..n` (n ≥ 1; 0 for n = 0).
    fn u16_below(&mut self, n: u16) -> u16 {
        self.u16().checked_rem(n).unwrap_or(0)
    }
}

/// Skips (tests) or excludes (Kani) the cases where the condition is false.
#[macro_export]
macro_rules! assume {
    ($src:expr, $cond:expr) => {
        if !$crate::harness::Source::assume(&mut *$src, $cond) {
            return;
        }
    };
}

/// A reachability check against vacuity: `kani::cover!` under Kani, a recorded hit under tests.
#[macro_export]
macro_rules! cover {
    ($src:expr, $cond:expr, $msg:literal) => {{
        let c: bool = $cond;
        #[cfg(kani)]
        {
            kani::cover!(c, $msg);
        }
        $crate::harness::Source::record(&mut *$src, c, $msg);
    }};
}

/// A harness assertion with a static message naming the property: `kani::assert` under Kani, so a
/// failing proof reports the message (Kani prints a placeholder for `assert!`'s panic message),
/// `assert!` under `cargo test`.
#[macro_export]
macro_rules! check {
    ($cond:expr, $msg:literal) => {{
        let c: bool = $cond;
        #[cfg(kani)]
        kani::assert(c, $msg);
        #[cfg(not(kani))]
        assert!(c, $msg);
    }};
}

/// A harness's failure with a static message naming the property: under Kani `kani::panic`, so a
/// failing proof reports the message (Kani prints a placeholder for `panic!`'s in `no_std`
/// crates), `panic!` under `cargo test`. For a path a property rules out, where `check!` would
/// need a value to go on with.
#[macro_export]
macro_rules! fail {
    ($msg:literal) => {{
        #[cfg(kani)]
        {
            kani::panic($msg)
        }
        #[cfg(not(kani))]
        {
            panic!($msg)
        }
    }};
}

/// Symbolic inputs for Kani.
#[cfg(kani)]
pub struct KaniSource;

#[cfg(kani)]
impl Source for KaniSource {
    fn u8(&mut self) -> u8 {
        kani::any()
    }
    fn u16(&mut self) -> u16 {
        kani::any()
    }
    fn u32(&mut self) -> u32 {
        kani::any()
    }
    fn bool(&mut self) -> bool {
        kani::any()
    }
    fn f32(&mut self) -> f32 {
        kani::any()
    }
    fn bytes<const N: usize>(&mut self) -> [u8; N] {
        kani::any()
    }
    // Bits compared, not `fixed`'s operators: the same order, without their type-level calls in
    // every trace (`ladder::in_range`).
    fn speed_within(&mut self, max: Speed) -> Speed {
        let s: i32 = kani::any();
        kani::assume(s <= max.to_bits() && s >= max.saturating_neg().to_bits());
        Speed::from_bits(s)
    }
    // A comparison instead of the remainder: the same values, without a divider in the formula.
    fn below(&mut self, n: u8) -> u8 {
        let v: u8 = kani::any();
        kani::assume(v < n || (n == 0 && v == 0));
        v
    }
    fn u16_below(&mut self, n: u16) -> u16 {
        let v: u16 = kani::any();
        kani::assume(v < n || (n == 0 && v == 0));
        v
    }
    fn assume(&mut self, cond: bool) -> bool {
        kani::assume(cond);
        true
    }
    fn record(&mut self, _cond: bool, _name: &'static str) {}
}

const MAX_COVERS: usize = 48;

/// Pseudo-random inputs for the `cargo test` twin of a harness, biased toward edge values
/// (0, 1, MAX, sign boundaries, small numbers, NaN/∞) where bugs live.
pub struct Twin {
    state: u64,
    covers: [(&'static str, u32, u32); MAX_COVERS],
    n_covers: usize,
    accepted: bool,
}

/// What a twin run saw: how many cases ran past every `assume!`, and each cover's hit count.
pub struct Report {
    /// Cases generated.
    pub cases: u32,
    /// Cases that passed every assumption and ran to the end.
    pub accepted: u32,
    covers: [(&'static str, u32, u32); MAX_COVERS],
    n_covers: usize,
}

impl Report {
    /// Fails if any cover point was evaluated but never true, if fewer than `expected` cover points
    /// were seen, or if no case got past the assumptions (a vacuous twin).
    #[track_caller]
    pub fn assert_covered(&self, expected: usize) {
        assert!(self.accepted > 0, "no case passed the assumptions");
        assert_eq!(
            self.n_covers,
            expected,
            "cover points seen: {:?}",
            self.names()
        );
        for (name, _seen, hit) in self.covers.iter().take(self.n_covers) {
            assert!(*hit > 0, "cover never satisfied: {name}");
        }
    }

    fn names(&self) -> [&'static str; MAX_COVERS] {
        let mut out = [""; MAX_COVERS];
        for (o, c) in out.iter_mut().zip(self.covers.iter().take(self.n_covers)) {
            *o = c.0;
        }
        out
    }
}

// The twin driver runs on the host only; its arithmetic is on random bits and wraps or saturates by design.
#[allow(clippy::arithmetic_side_effects)]
impl Twin {
    /// A source seeded with `seed` (runs are reproducible).
    pub const fn new(seed: u64) -> Self {
        Self {
            state: seed,
            covers: [("", 0, 0); MAX_COVERS],
            n_covers: 0,
            accepted: true,
        }
    }

    /// Runs `body` on `cases` generated inputs and reports what it saw.
    pub fn run(seed: u64, cases: u32, mut body: impl FnMut(&mut Self)) -> Report {
        let mut t = Self::new(seed);
        let mut accepted = 0u32;
        for _ in 0..cases {
            t.accepted = true;
            body(&mut t);
            if t.accepted {
                accepted = accepted.saturating_add(1);
            }
        }
        Report {
            cases,
            accepted,
            covers: t.covers,
            n_covers: t.n_covers,
        }
    }

    /// Runs `body` once for each index `0..cases`, in order, and reports what it saw: a test that
    /// enumerates a finite input (a bit of a frame, a byte value) passes the index, the source
    /// still drawing anything else and recording the covers.
    pub fn each(seed: u64, cases: u32, mut body: impl FnMut(&mut Self, u32)) -> Report {
        let mut i = 0;
        Self::run(seed, cases, |t| {
            body(t, i);
            i += 1;
        })
    }

    fn next(&mut self) -> u64 {
        // splitmix64
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn biased(&mut self, max: u64) -> u64 {
        let r = self.next();
        match r % 8 {
            0 => {
                let edges = [0, 1, 2, max, max.wrapping_sub(1), max / 2, max / 2 + 1];
                edges
                    .get((r >> 8) as usize % edges.len())
                    .copied()
                    .unwrap_or(0)
            }
            1 | 2 => (r >> 8) % 16,
            _ => (r >> 8) & max,
        }
    }
}

#[allow(clippy::arithmetic_side_effects)]
impl Source for Twin {
    fn u8(&mut self) -> u8 {
        self.biased(u8::MAX.into()) as u8
    }
    fn u16(&mut self) -> u16 {
        self.biased(u16::MAX.into()) as u16
    }
    fn u32(&mut self) -> u32 {
        self.biased(u32::MAX.into()) as u32
    }
    fn bool(&mut self) -> bool {
        self.next() & 1 == 1
    }
    fn f32(&mut self) -> f32 {
        let r = self.next();
        match r % 8 {
            0 => {
                let special = [
                    f32::NAN,
                    f32::INFINITY,
                    f32::NEG_INFINITY,
                    0.0,
                    -0.0,
                    f32::MAX,
                    f32::MIN,
                ];
                special
                    .get((r >> 8) as usize % special.len())
                    .copied()
                    .unwrap_or(0.0)
            }
            1 | 2 => ((r >> 16) as u32 % 100_000) as f32 / 1000.0 - 50.0,
            3 | 4 => ((r >> 16) as u32 % 201) as f32 * 0.5 - 50.0,
            _ => f32::from_bits((r >> 16) as u32),
        }
    }
    fn speed_within(&mut self, max: Speed) -> Speed {
        let m = i64::from(max.to_bits().max(0));
        let r = self.next();
        let bits = match r % 6 {
            0 => m,
            1 => -m,
            2 => 0,
            3 => (r >> 8) as i64 % 16 - 8,
            _ => ((r >> 8) % (2 * m as u64 + 1)) as i64 - m,
        };
        Speed::from_bits(bits.clamp(-m, m) as i32)
    }
    fn assume(&mut self, cond: bool) -> bool {
        if !cond {
            self.accepted = false;
        }
        cond
    }
    fn record(&mut self, cond: bool, name: &'static str) {
        let n = self.n_covers;
        let slot = self.covers.iter().take(n).position(|c| c.0 == name);
        let idx = match slot {
            Some(i) => i,
            None if n < MAX_COVERS => {
                self.n_covers = n + 1;
                if let Some(c) = self.covers.get_mut(n) {
                    c.0 = name;
                }
                n
            }
            None => return,
        };
        if let Some(c) = self.covers.get_mut(idx) {
            c.1 = c.1.saturating_add(1);
            if cond {
                c.2 = c.2.saturating_add(1);
            }
        }
    }
}

/// Generators shared by the harnesses of this crate and of `proofs`: each draws every field from a
/// [`Source`], so under Kani they stand for *all* values, and under tests for many biased ones.
pub mod arbitrary {
    use super::Source;
    use crate::config::{Config, ConfigParams, BOARD_MAX_BRAKE_AFTER, TRAVEL_CEILING};
    use crate::ladder::{Counters, Estop, Event, Ladder, Source as Origin};
    use crate::types::{
        AxisCommand, AxisMode, Command, Condition, FaultFlags, Mode, ModeSet, RejectReason, Speed,
    };
    use crate::validate::{AxisSetpoint, Setpoint};

    /// One of the shipped profiles ([`Config::PROFILES`]).
    pub fn profile(src: &mut impl Source) -> Config {
        let i = usize::from(src.below(Config::PROFILES.len() as u8));
        Config::PROFILES.get(i).copied().unwrap_or(Config::DEFAULT)
    }

    /// The configurations the harnesses range over. Under Kani: each shipped profile
    /// ([`Config::PROFILES`], concrete numbers, so the solver works on constants: the proofs are
    /// per profile, and a new profile joins the list to be proven). Under `cargo test`: a shipped
    /// profile half the time, otherwise any configuration [`Config::new`] accepts, so the twins also
    /// exercise the rules on configurations no profile uses yet.
    pub fn config(src: &mut impl Source) -> Option<Config> {
        if cfg!(kani) || src.bool() {
            return Some(profile(src));
        }
        any_config(src)
    }

    /// Any configuration [`Config::new`] accepts (`None` for the values it refuses).
    pub fn any_config(src: &mut impl Source) -> Option<Config> {
        // Every value is drawn so that each valid configuration is reachable (under Kani every one
        // is); ordering and signs are arranged by construction so the tests meet valid ones often.
        let pos = |src: &mut _, max: Speed| Source::speed_within(src, max).saturating_abs();
        let v_max = pos(src, crate::config::V_MAX_CEILING);
        let duty_max = pos(src, Speed::ONE);
        let gap = |src: &mut _| src_u16_below(src, BOARD_MAX_BRAKE_AFTER.saturating_add(2));
        let frame_period = gap(src);
        let hold_after = frame_period.saturating_add(gap(src));
        let stop_after = hold_after.saturating_add(gap(src));
        let brake_after = stop_after.saturating_add(gap(src));
        let (a, b) = (
            src.speed_within(TRAVEL_CEILING),
            src.speed_within(TRAVEL_CEILING),
        );
        let p = ConfigParams {
            frame_period,
            hold_after,
            stop_after,
            brake_after,
            v_max,
            reduced_limit: pos(src, v_max),
            max_cmd_step: pos(src, v_max),
            accel_step: pos(src, v_max),
            hold_decel_step: pos(src, v_max),
            stop_decel_step: pos(src, v_max),
            duty_max,
            duty_reduced: pos(src, duty_max),
            duty_step: pos(src, duty_max),
            travel_lo: a.min(b),
            travel_hi: a.max(b),
            modes: ModeSet(src.u8() & ModeSet::ALL.0),
            strike_limit: src.u16(),
            window: src.u16(),
        };
        Config::new(p).ok()
    }

    fn src_u16_below(src: &mut impl Source, n: u16) -> u16 {
        src.u16_below(n)
    }

    /// Any drive mode.
    pub fn axis_mode(src: &mut impl Source) -> AxisMode {
        let i = usize::from(src.below(AxisMode::ALL.len() as u8));
        AxisMode::ALL.get(i).copied().unwrap_or(AxisMode::Coast)
    }

    /// Any drive mode of `set` (non-empty): a drawn mode, or the set's first one if it is not in it.
    pub fn axis_mode_in(src: &mut impl Source, set: ModeSet) -> AxisMode {
        let m = axis_mode(src);
        if set.contains(m) {
            return m;
        }
        AxisMode::ALL
            .into_iter()
            .find(|m| set.contains(*m))
            .unwrap_or(AxisMode::Coast)
    }

    /// Any value an axis in mode `m` may hold under `p` (the ladder's `applied`).
    pub fn applied_for(src: &mut impl Source, p: &ConfigParams, m: AxisMode) -> Speed {
        match m {
            AxisMode::Coast | AxisMode::Short => Speed::ZERO,
            AxisMode::Duty => src.speed_within(p.duty_max),
            AxisMode::Velocity => src.speed_within(p.v_max),
            AxisMode::Position => src.speed_within(p.v_max).saturating_abs(),
        }
    }

    /// Any position within the travel of `p` (bits compared, as in `speed_within`).
    pub fn position_in(src: &mut impl Source, p: &ConfigParams) -> Speed {
        let x = src.speed_within(TRAVEL_CEILING);
        if x.to_bits() < p.travel_lo.to_bits() {
            p.travel_lo
        } else if x.to_bits() > p.travel_hi.to_bits() {
            p.travel_hi
        } else {
            x
        }
    }

    /// Any command, NaN and out-of-range numbers, unsupported modes and a zero timeout included.
    pub fn command<const N: usize>(src: &mut impl Source) -> Command<N> {
        let mut axes = [AxisCommand::COAST; N];
        #[allow(clippy::indexing_slicing)]
        for i in 0..N {
            axes[i] = AxisCommand {
                mode: axis_mode(src),
                target: src.f32(),
                cap: src.f32(),
            };
        }
        Command {
            axes,
            enable: src.bool(),
            seq: if src.bool() { Some(src.u32()) } else { None },
            timeout: if src.bool() { Some(src.u16()) } else { None },
        }
    }

    /// Any setpoint validation could have produced under `cfg`.
    pub fn setpoint<const N: usize>(src: &mut impl Source, cfg: &Config) -> Setpoint<N> {
        let p = cfg.params();
        let mut axes = [AxisSetpoint::passive(AxisMode::Coast); N];
        #[allow(clippy::indexing_slicing)]
        for i in 0..N {
            // Under Kani `axis_mode` alone is every mode (so for this and each choice below: the
            // twins' shortcuts are values the last choice already takes, and as choices they
            // would add selectors, and here a remainder, to every formula).
            let mode = if !cfg!(kani) && src.bool() {
                axis_mode_in(src, p.modes)
            } else {
                axis_mode(src)
            };
            axes[i] = match mode {
                AxisMode::Coast | AxisMode::Short => AxisSetpoint::passive(mode),
                AxisMode::Duty => AxisSetpoint {
                    mode,
                    target: src.speed_within(p.duty_max),
                    cap: Speed::ZERO,
                },
                AxisMode::Velocity => AxisSetpoint {
                    mode,
                    target: src.speed_within(p.v_max),
                    cap: Speed::ZERO,
                },
                AxisMode::Position => AxisSetpoint {
                    mode,
                    target: position_in(src, p),
                    cap: src.speed_within(p.v_max).saturating_abs(),
                },
            };
        }
        Setpoint {
            axes,
            enable: src.bool(),
            seq_value: src.u32(),
            has_seq: src.bool(),
            brake_after: src_u16_below(src, p.brake_after).saturating_add(1),
        }
    }

    /// Any refusal reason.
    pub fn reason(src: &mut impl Source) -> RejectReason {
        let i = usize::from(src.below(RejectReason::ALL.len() as u8));
        RejectReason::ALL
            .get(i)
            .copied()
            .unwrap_or(RejectReason::Crc)
    }

    /// Any board condition.
    pub fn condition(src: &mut impl Source) -> Condition {
        let i = usize::from(src.below(Condition::ALL.len() as u8));
        Condition::ALL
            .get(i)
            .copied()
            .unwrap_or(Condition::Overcurrent)
    }

    /// Any command source.
    pub fn origin(src: &mut impl Source) -> Origin {
        let i = usize::from(src.below(Origin::ALL.len() as u8));
        Origin::ALL.get(i).copied().unwrap_or(Origin::Local)
    }

    /// Any event.
    pub fn event<const N: usize>(src: &mut impl Source) -> Event<N> {
        match src.below(7) {
            0 => Event::Tick,
            1 => Event::Frame(command(src)),
            2 => Event::Rejected(reason(src)),
            3 => Event::Condition {
                condition: condition(src),
                active: src.bool(),
            },
            4 => Event::Estop {
                source: origin(src),
                action: if src.bool() {
                    Estop::Engage
                } else {
                    Estop::Release
                },
            },
            5 => Event::Shutdown(src.bool()),
            _ => Event::Rearm(origin(src)),
        }
    }

    /// Any event that is not a valid frame: what the ladder sees while the link is lost
    /// (refusals, faults, operator actions, and frames that cannot validate: a zero timeout).
    pub fn event_without_valid_frame<const N: usize>(src: &mut impl Source) -> Event<N> {
        match event(src) {
            Event::Frame(c) => Event::Frame(Command {
                timeout: Some(0),
                ..c
            }),
            e => e,
        }
    }

    /// Any mode.
    pub fn mode(src: &mut impl Source) -> Mode {
        match src.below(5) {
            0 => Mode::Normal,
            1 => Mode::Reduced,
            2 => Mode::Hold,
            3 => Mode::Stop,
            _ => Mode::Brake,
        }
    }

    /// Any ladder state under `cfg`; callers `assume!` [`Ladder::is_valid`]. Fields the invariant pins to
    /// each other (brake latch and mode, ESTOP owners and flag) are drawn together so the tests waste fewer cases.
    pub fn ladder<const N: usize>(src: &mut impl Source, cfg: Config) -> Ladder<N> {
        let p = *cfg.params();
        let mode = mode(src);
        let brake_latched = mode == Mode::Brake;
        let mut rejected = [0u32; RejectReason::ALL.len()];
        #[allow(clippy::indexing_slicing)]
        for i in 0..rejected.len() {
            rejected[i] = src.u32();
        }
        let mut applied = [Speed::ZERO; N];
        let mut axis_modes = [AxisMode::Coast; N];
        let mut held = [p.travel_lo; N];
        #[allow(clippy::indexing_slicing)]
        for i in 0..N {
            let m = if !cfg!(kani) && src.bool() {
                axis_mode_in(src, p.modes)
            } else {
                axis_mode(src)
            };
            axis_modes[i] = m;
            if !brake_latched {
                applied[i] = applied_for(src, &p, m);
            }
            held[i] = position_in(src, &p);
        }
        let estop_owners = src.u8() & src.u8() & 0b111;
        // Sparse bits for the tests; still every value under Kani (x & y & z covers all of u16).
        let mut active = FaultFlags(src.u16() & src.u16() & src.u16());
        active = if estop_owners != 0 {
            active.union(FaultFlags::ESTOP)
        } else {
            active.without(FaultFlags::ESTOP)
        };
        // The profile's own threshold is among the second choice's (`Config::new` keeps it ≥ 3).
        let brake_after = if !cfg!(kani) && src.bool() {
            p.brake_after
        } else {
            src_u16_below(src, p.brake_after).saturating_add(1)
        };
        Ladder {
            cfg,
            mode,
            applied,
            axis_modes,
            held,
            last: setpoint(src, &cfg),
            has_last: src.bool(),
            brake_after,
            prev_enable: src.bool(),
            // Ages just below each threshold are where the rungs change: drawn often for the tests.
            age: match if cfg!(kani) { 5 } else { src.below(6) } {
                0 => u16::from(src.below(12)),
                1 => src_u16_below(src, brake_after),
                2 => p.hold_after.saturating_sub(1),
                3 => p.stop_after.saturating_sub(1),
                4 => brake_after.saturating_sub(1),
                _ => src.u16(),
            },
            brake_latched,
            latch_causes: if brake_latched {
                FaultFlags(src.u16())
            } else {
                FaultFlags::NONE
            },
            active,
            estop_owners,
            estop_released_by: match src.below(4) {
                0 => None,
                _ => Some(origin(src)),
            },
            rearm_pending: src.bool(),
            degraded: src.bool(),
            // `u16_below`: a remainder in the twins, a comparison under Kani (the same values
            // without a divider in the formula).
            clean_ticks: src_u16_below(src, p.window),
            window_pos: src_u16_below(src, p.window),
            window_strikes: src.u16(),
            counters: Counters {
                ticks: src.u32(),
                valid_frames: src.u32(),
                rejected,
                missed_ticks: src.u32(),
                hold_entries: src.u32(),
                brake_entries: src.u32(),
                rearms: src.u32(),
                rearm_refused: src.u32(),
                estop_release_refused: src.u32(),
            },
        }
    }
}

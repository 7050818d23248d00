//! The ladder fuzzed against the reference model of `tests/ladder_model` (written from
//! `proofs/SAFETY.md`'s rules): the same event sequence goes to `Ladder<N>` and to the model, and
//! after every event they must agree on the rung, the latch and its causes, the link quality
//! (LINK_DEGRADED), the age and the threshold, the command held (the model validates each frame
//! itself), the ESTOP holders, and each axis's mode, applied value and drive, which the model
//! recomputes from the rules and which must be equal bit for bit (see the model's checks).
//!
//! Under `cargo test` the target runs a bounded number of random inputs (bolero's random engine);
//! `cargo xtask fuzz` runs it coverage-guided (libFuzzer through `cargo bolero`).
//!
//! Each input picks a profile (`Config::PROFILES`, sometimes with a short strike window so that
//! the REDUCED rules are reached in a short sequence), the axis count (2 or 4), then events: ticks
//! (often several in a row), frames from a small menu of values (valid ones, stale sequence
//! numbers, out-of-range, NaN, modes the profile refuses, zero and short timeouts), frames refused
//! below the ladder, conditions, ESTOP engage and release from every source, shutdown, re-arms
//! (also followed at once by a frame and a tick, so that inputs leave BRAKE often).
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::panic,
    missing_docs
)]

mod ladder_model;

use ladder_model::{step_both, Model};
use statemachine::{
    AxisCommand, AxisMode, Command, Condition, Config, ConfigParams, Estop, Event, Ladder,
    RejectReason, Source,
};
use std::sync::atomic::{AtomicU64, Ordering};

/// Reads the fuzzer's bytes, 0 once they run out.
struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn u8(&mut self) -> u8 {
        let (&b, rest) = self.0.split_first().unwrap_or((&0, &[]));
        self.0 = rest;
        b
    }
    fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

/// Values a frame's axis may carry: small ramps, the limits' neighbourhood, beyond them, NaN.
const VALUES: [f32; 12] = [
    0.0,
    0.04,
    -0.04,
    0.5,
    -0.5,
    0.3,
    3.0,
    -3.0,
    9.0,
    25.0,
    f32::NAN,
    f32::INFINITY,
];

fn axis(b: &mut Bytes) -> AxisCommand {
    let m = b.u8();
    let target = VALUES[usize::from(m >> 4) % VALUES.len()];
    let cap = VALUES[usize::from(b.u8()) % VALUES.len()].abs();
    let mode = AxisMode::ALL[usize::from(m & 0x0F) % AxisMode::ALL.len()];
    AxisCommand { target, cap, mode }
}

struct Gen {
    seq: u32,
    uniform_mode: Option<AxisMode>,
}

fn command<const N: usize>(b: &mut Bytes, g: &mut Gen) -> Command<N> {
    let flags = b.u8();
    let mut axes = [AxisCommand::COAST; N];
    if flags & 0x01 != 0 {
        // One axis command for every axis: a profile's own mode most of the time.
        let mut a = axis(b);
        if let Some(m) = g.uniform_mode {
            a.mode = m;
        }
        axes = [a; N];
    } else {
        for a in &mut axes {
            *a = axis(b);
        }
    }
    // Sequence numbers: the next one mostly, sometimes a repeat, an older one or none.
    let seq = match (flags >> 1) & 0x07 {
        0 => None,
        1 => Some(g.seq),
        2 => Some(g.seq.wrapping_sub(3)),
        _ => {
            g.seq = g.seq.wrapping_add(1);
            Some(g.seq)
        }
    };
    let timeout = match (flags >> 4) & 0x03 {
        0 | 1 => None,
        2 => Some(u16::from(b.u8() % 12)),
        _ => Some(u16::from(b.u8())),
    };
    Command {
        axes,
        seq,
        timeout,
        enable: flags & 0xC0 != 0x40,
    }
}

fn event<const N: usize>(b: &mut Bytes, g: &mut Gen) -> Vec<Event<N>> {
    let k = b.u8();
    match k % 16 {
        0..=4 => vec![Event::Tick; usize::from(k >> 4) + 1],
        5..=8 => vec![Event::Frame(command(b, g)), Event::Tick],
        // A re-arm request and a frame: a way out of BRAKE within a few bytes.
        9 if k & 0x80 != 0 => vec![
            Event::Rearm(Source::ALL[usize::from(k >> 4) % 3]),
            Event::Frame(command(b, g)),
            Event::Tick,
        ],
        9 => vec![Event::Frame(command(b, g))],
        10 => vec![Event::Rejected(
            RejectReason::ALL[usize::from(k >> 4) % RejectReason::ALL.len()],
        )],
        11 => vec![Event::Condition {
            condition: Condition::ALL[usize::from(k >> 4) % Condition::ALL.len()],
            active: b.u8() & 1 == 1,
        }],
        12 => vec![Event::Estop {
            source: Source::ALL[usize::from(k >> 4) % 3],
            action: if k & 0x80 != 0 {
                Estop::Engage
            } else {
                Estop::Release
            },
        }],
        13 => vec![Event::Shutdown(k & 0x10 != 0)],
        14 => vec![Event::Rearm(Source::ALL[usize::from(k >> 4) % 3])],
        _ => vec![Event::Tick; 10 + usize::from(k >> 4) * 4],
    }
}

fn config(b: &mut Bytes) -> Config {
    let c = b.u8();
    let base = Config::PROFILES[usize::from(c) % Config::PROFILES.len()];
    if c & 0x80 == 0 {
        return base;
    }
    // A short window reaches the REDUCED rules within a short input.
    let p = ConfigParams {
        window: 2 + u16::from(b.u8() % 30),
        strike_limit: 1 + u16::from(c >> 4 & 0x03),
        ..*base.params()
    };
    Config::new(p).unwrap_or(base)
}

/// Events after which the ladder was on each rung (`Mode as usize`), and re-arms that released BRAKE.
static RUNGS: [AtomicU64; 5] = [const { AtomicU64::new(0) }; 5];
static RELEASES: AtomicU64 = AtomicU64::new(0);

/// Runs one input through the ladder and the model; returns the number of events.
fn run<const N: usize>(cfg: Config, b: &mut Bytes) -> u64 {
    let mut ladder = Ladder::<N>::new(cfg);
    let mut model = Model::<N>::new(cfg, ladder.age());
    let own = AxisMode::ALL
        .into_iter()
        .find(|&m| cfg.params().modes.contains(m) && !m.is_passive());
    let mut g = Gen {
        seq: 0,
        uniform_mode: own,
    };
    let mut n = 0;
    while !b.is_empty() {
        for e in event::<N>(b, &mut g) {
            step_both(&mut ladder, &mut model, e);
            RUNGS[ladder.mode() as usize].fetch_add(1, Ordering::Relaxed);
            n += 1;
        }
    }
    RELEASES.fetch_add(u64::from(ladder.counters().rearms), Ordering::Relaxed);
    n
}

#[test]
fn fuzz_ladder_against_model() {
    static N: AtomicU64 = AtomicU64::new(0);
    static EVENTS: AtomicU64 = AtomicU64::new(0);
    bolero::check!()
        .with_max_len(256)
        .with_iterations(20_000)
        .for_each(|input: &[u8]| {
            N.fetch_add(1, Ordering::Relaxed);
            let mut b = Bytes(input);
            let cfg = config(&mut b);
            let n = if b.u8() & 1 == 0 {
                run::<2>(cfg, &mut b)
            } else {
                run::<4>(cfg, &mut b)
            };
            EVENTS.fetch_add(n, Ordering::Relaxed);
        });
    let rungs = RUNGS.each_ref().map(|r| r.load(Ordering::Relaxed));
    eprintln!(
        "fuzz ladder_against_model: {} executions, {} events, no disagreement; events on NORMAL, \
         REDUCED, HOLD, STOP, BRAKE: {rungs:?}; re-arms that released BRAKE: {}",
        N.load(Ordering::Relaxed),
        EVENTS.load(Ordering::Relaxed),
        RELEASES.load(Ordering::Relaxed),
    );
    // Not vacuous: the inputs leave BRAKE and reach every rung.
    assert!(
        rungs.iter().all(|&r| r > 0),
        "a rung never reached: {rungs:?}"
    );
    assert!(RELEASES.load(Ordering::Relaxed) > 0);
}

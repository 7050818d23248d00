//! Randomised campaign: many short runs, each losing the link at a random moment, checking that
//! every comm-loss BRAKE reached the bridge strictly within the profile's bound of the last valid
//! frame (`Config::comm_loss_bound_ms`, 10 ms for seed 000; SAFETY.md SR-16). Exits with status 1
//! if any run did not.
//!
//! `cargo run --release -p sim --example campaign -- [runs] [threads]` (default 1 000 000 runs).
//! Each run: arm, drive, random corruption (0 … 1e-2), clock drift (±50 ppm), host jitter, then
//! at a random time the host stops (GC pause) or the link is cut, for 15 ms.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::arithmetic_side_effects,
    clippy::indexing_slicing
)]

use motorlink::SimHost;
use sim::rng::Rng;
use sim::scenario::{CmdVelSegment, Expect, Fault, HostSettings, Profile, Request, Scenario};

#[derive(Default, Clone, Copy)]
struct Tally {
    runs: u64,
    braked: u64,
    within_10ms_of_onset: u64,
    within_10ms_of_last_frame: u64,
    max_after_onset_ms: f64,
    max_after_last_frame_ms: f64,
    min_after_last_frame_ms: f64,
    bridge_within_bound: u64,
    bridge_beyond_bound: u64,
    max_bridge_after_last_frame_ms: f64,
    corrupted_applied: u64,
    corrupted_sent: u64,
}

fn scenario(i: u64) -> Scenario {
    let mut r = Rng::new(0xC0FFEE ^ i.wrapping_mul(0x9E37_79B9));
    let at = 0.020 + r.uniform() * 0.010;
    let loss = if r.chance(0.5) {
        Fault::GcPause {
            at_s: at,
            duration_s: 0.015,
        }
    } else {
        Fault::LinkCut {
            at_s: at,
            duration_s: 0.015,
        }
    };
    let rate = if r.chance(0.5) {
        0.0
    } else {
        10f64.powf(-4.0 + 2.0 * r.uniform())
    };
    Scenario {
        name: format!("campaign-{i}"),
        description: String::new(),
        duration_s: at + 0.016,
        seed: i,
        trace_every_ms: 1,
        host: HostSettings {
            send_jitter_us: 100.0 * r.uniform(),
            recv_jitter_us: 100.0 * r.uniform(),
            preempt_rate: 0.01 * r.uniform(),
            ..HostSettings::default()
        },
        plant: Default::default(),
        requests: vec![Request::Arm {
            at_s: 0.0005 * r.uniform(),
        }],
        cmd_vel: vec![CmdVelSegment {
            from_s: 0.0,
            to_s: 1.0,
            v: 0.1 + r.uniform(),
            w: r.uniform() - 0.5,
        }],
        faults: vec![
            loss,
            Fault::Corruption {
                rate,
                from_s: 0.0,
                to_s: f64::INFINITY,
                feedback: true,
            },
            Fault::ClockDrift {
                mcu_ppm: 100.0 * r.uniform() - 50.0,
                host_ppm: 0.0,
            },
        ],
        expect: Expect::default(),
        profile: Profile::AmrSpi,
        serial: Default::default(),
        cdc: Default::default(),
        teensy: Default::default(),
        pi_spi: Default::default(),
    }
}

fn work(from: u64, to: u64, progress: bool) -> Tally {
    let mut t = Tally {
        min_after_last_frame_ms: f64::INFINITY,
        ..Tally::default()
    };
    let n = to - from;
    for i in from..to {
        let sc = scenario(i);
        let mut host = SimHost::new();
        let s = sim::run(&sc, &mut host, sim::RunOptions::default(), None)
            .unwrap()
            .summary;
        t.runs += 1;
        t.corrupted_applied += s.corrupted_applied;
        t.corrupted_sent += s.corrupted_sent;
        if let Some(b) = s.brake_ms {
            t.braked += 1;
            t.max_after_onset_ms = t.max_after_onset_ms.max(b);
            if b <= 10.0 {
                t.within_10ms_of_onset += 1;
            }
        }
        if let Some(b) = s.brake_after_last_frame_ms {
            t.max_after_last_frame_ms = t.max_after_last_frame_ms.max(b);
            t.min_after_last_frame_ms = t.min_after_last_frame_ms.min(b);
            if b <= 10.0 {
                t.within_10ms_of_last_frame += 1;
            }
        }
        let bound = f64::from(mcu::tuning::AMR.ladder.comm_loss_bound_ms());
        if let Some(b) = s.bridge_brake_after_last_frame_ms {
            t.max_bridge_after_last_frame_ms = t.max_bridge_after_last_frame_ms.max(b);
            if b < bound {
                t.bridge_within_bound += 1;
            } else {
                t.bridge_beyond_bound += 1;
            }
        }
        if progress && (i - from + 1).is_multiple_of((n / 20).max(1)) {
            eprintln!("  {:>3.0} %", 100.0 * (i - from + 1) as f64 / n as f64);
        }
    }
    t
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let runs: u64 = args
        .get(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(1_000_000);
    let threads: u64 = args.get(2).and_then(|a| a.parse().ok()).unwrap_or(2).max(1);
    let start = std::time::Instant::now();
    let chunk = runs.div_ceil(threads);
    let handles: Vec<_> = (0..threads)
        .map(|k| {
            let from = k * chunk;
            let to = ((k + 1) * chunk).min(runs);
            std::thread::spawn(move || work(from, to, k == 0))
        })
        .collect();
    let mut t = Tally {
        min_after_last_frame_ms: f64::INFINITY,
        ..Tally::default()
    };
    for h in handles {
        let x = h.join().expect("worker");
        t.runs += x.runs;
        t.braked += x.braked;
        t.within_10ms_of_onset += x.within_10ms_of_onset;
        t.within_10ms_of_last_frame += x.within_10ms_of_last_frame;
        t.max_after_onset_ms = t.max_after_onset_ms.max(x.max_after_onset_ms);
        t.max_after_last_frame_ms = t.max_after_last_frame_ms.max(x.max_after_last_frame_ms);
        t.min_after_last_frame_ms = t.min_after_last_frame_ms.min(x.min_after_last_frame_ms);
        t.bridge_within_bound += x.bridge_within_bound;
        t.bridge_beyond_bound += x.bridge_beyond_bound;
        t.max_bridge_after_last_frame_ms = t
            .max_bridge_after_last_frame_ms
            .max(x.max_bridge_after_last_frame_ms);
        t.corrupted_applied += x.corrupted_applied;
        t.corrupted_sent += x.corrupted_sent;
    }
    println!("runs with a 15 ms comm loss:            {}", t.runs);
    println!("braked:                                 {}", t.braked);
    println!(
        "braked within 10 ms of the loss onset:  {}",
        t.within_10ms_of_onset
    );
    println!(
        "braked within 10 ms of the last frame:  {}",
        t.within_10ms_of_last_frame
    );
    println!(
        "BRAKE after onset, worst:               {:.3} ms",
        t.max_after_onset_ms
    );
    println!(
        "BRAKE after last valid frame, range:    {:.3} .. {:.3} ms",
        t.min_after_last_frame_ms, t.max_after_last_frame_ms
    );
    let bound = mcu::tuning::AMR.ladder.comm_loss_bound_ms();
    println!(
        "bridge braked < {bound} ms after the last frame: {} of {} comm-loss BRAKEs (worst {:.3} ms)",
        t.bridge_within_bound,
        t.bridge_within_bound + t.bridge_beyond_bound,
        t.max_bridge_after_last_frame_ms
    );
    println!(
        "corrupted frames sent / applied:        {} / {}",
        t.corrupted_sent, t.corrupted_applied
    );
    println!(
        "wall time:                              {:.1} s",
        start.elapsed().as_secs_f64()
    );
    if t.bridge_beyond_bound > 0 || t.bridge_within_bound == 0 {
        eprintln!(
            "FAIL: a comm-loss BRAKE reached the bridge outside the profile's bound (or none did)"
        );
        std::process::exit(1);
    }
}

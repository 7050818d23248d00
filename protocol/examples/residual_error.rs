//! Residual error rate of the seed 000 frame: corrupts valid command frames at random and counts how
//! many still pass CRC, decoding and validation (`statemachine::validate`).
//!
//! `cargo run --release -p protocol --example residual_error [FRAMES] [SEED]` (default 10^8 frames).
//! Four corruption classes, a quarter of the frames each: one flipped bit; a burst of 2–32 bits
//! (first and last flipped, the inside random); 2–8 bytes replaced by random values; a whole frame of
//! random bytes. CRC-16 detects every single-bit error and every burst up to 16 bits; for the other
//! patterns the expectation is about 2^-16 of the frames passing the CRC.
#![allow(
    clippy::arithmetic_side_effects,
    clippy::indexing_slicing,
    clippy::unwrap_used,
    missing_docs
)]

use protocol::amr::{self, MotorCommand, FRAME_LEN};
use statemachine::{validate, Config, Speed};

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        // xorshift64*
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

#[derive(Default, Clone, Copy)]
struct Counts {
    frames: u64,
    changed: u64,
    crc_pass: u64,
    decoded: u64,
    validated: u64,
    validated_and_different: u64,
}

fn add(a: &mut Counts, b: &Counts) {
    a.frames += b.frames;
    a.changed += b.changed;
    a.crc_pass += b.crc_pass;
    a.decoded += b.decoded;
    a.validated += b.validated;
    a.validated_and_different += b.validated_and_different;
}

const CLASSES: [&str; 4] = [
    "single bit",
    "burst 2-32 bits",
    "2-8 random bytes",
    "random frame",
];

fn corrupt(class: usize, f: &mut [u8; FRAME_LEN], rng: &mut Rng) {
    match class {
        0 => {
            let bit = rng.below(FRAME_LEN as u64 * 8) as usize;
            f[bit / 8] ^= 1 << (bit % 8);
        }
        1 => {
            let len = 2 + rng.below(31) as usize;
            let start = rng.below((FRAME_LEN * 8 - len + 1) as u64) as usize;
            let pattern = rng.next() | 1 | (1 << (len - 1));
            for i in 0..len {
                if pattern >> i & 1 == 1 {
                    let bit = start + i;
                    f[bit / 8] ^= 0x80 >> (bit % 8);
                }
            }
        }
        2 => {
            let k = 2 + rng.below(7);
            for _ in 0..k {
                let i = rng.below(FRAME_LEN as u64) as usize;
                f[i] = rng.next() as u8;
            }
        }
        _ => {
            for b in f.iter_mut() {
                *b = rng.next() as u8;
            }
        }
    }
}

fn run(class: usize, frames: u64, seed: u64) -> Counts {
    let mut rng = Rng(seed | 1);
    let cfg = Config::DEFAULT;
    let allowance = Speed::from_num(40);
    let mut c = Counts::default();
    let mut base = [0u8; FRAME_LEN];
    let mut cmd = MotorCommand::default();
    for i in 0..frames {
        if i % 16 == 0 {
            cmd = MotorCommand {
                timestamp_us: rng.next() as u32,
                left_speed_cmd: (rng.below(40_000) as f32 - 20_000.0) / 1000.0,
                right_speed_cmd: (rng.below(40_000) as f32 - 20_000.0) / 1000.0,
                control_mode: 1,
                enable: true,
                seq: rng.next() as u32,
                request: 0,
            };
            amr::encode_command(&cmd, &mut base);
        }
        let mut f = base;
        corrupt(class, &mut f, &mut rng);
        c.frames += 1;
        if f == base {
            continue;
        }
        c.changed += 1;
        let crc_ok = protocol::crc16::checksum(&f[..amr::CRC_OFFSET])
            == u16::from_le_bytes([f[amr::CRC_OFFSET], f[amr::CRC_OFFSET + 1]]);
        if !crc_ok {
            continue;
        }
        c.crc_pass += 1;
        let Ok(d) = amr::decode_command(&f) else {
            continue;
        };
        c.decoded += 1;
        if d.to_command()
            .is_ok_and(|c| validate(&c, None, allowance, &cfg).is_ok())
        {
            c.validated += 1;
            if format!("{d:?}") != format!("{cmd:?}") {
                c.validated_and_different += 1;
            }
        }
    }
    c
}

fn main() {
    let total: u64 = std::env::args()
        .nth(1)
        .map_or(100_000_000, |s| s.parse().unwrap());
    let seed: u64 = std::env::args()
        .nth(2)
        .map_or(0x5EED, |s| s.parse().unwrap());
    let per_class = total / 4;
    println!("{total} corrupted seed-000 command frames ({per_class} per class), seed {seed}");
    println!(
        "{:<18} {:>12} {:>12} {:>10} {:>9} {:>9} {:>10} {:>11}",
        "class", "frames", "changed", "crc pass", "expected", "decoded", "validated", "val.+diff"
    );
    let mut all = Counts::default();
    for (class, name) in CLASSES.iter().enumerate() {
        // Two threads per class (the machine has two cores).
        let halves: Vec<Counts> = std::thread::scope(|s| {
            let h: Vec<_> = (0..2u64)
                .map(|t| {
                    s.spawn(move || {
                        run(
                            class,
                            per_class / 2,
                            seed ^ ((class as u64) << 32) ^ (t << 48),
                        )
                    })
                })
                .collect();
            h.into_iter().map(|j| j.join().unwrap()).collect()
        });
        let mut c = Counts::default();
        for h in &halves {
            add(&mut c, h);
        }
        let expected = if class == 0 {
            0.0
        } else {
            c.changed as f64 / 65536.0
        };
        println!(
            "{:<18} {:>12} {:>12} {:>10} {:>9.1} {:>9} {:>10} {:>11}",
            name,
            c.frames,
            c.changed,
            c.crc_pass,
            expected,
            c.decoded,
            c.validated,
            c.validated_and_different
        );
        add(&mut all, &c);
    }
    println!(
        "{:<18} {:>12} {:>12} {:>10} {:>9} {:>9} {:>10} {:>11}",
        "total",
        all.frames,
        all.changed,
        all.crc_pass,
        "",
        all.decoded,
        all.validated,
        all.validated_and_different
    );
    println!(
        "undetected rate after CRC: {:.3e} per corrupted frame (2^-16 = {:.3e}); after decode + validate: {:.3e}",
        all.crc_pass as f64 / all.changed as f64,
        1.0 / 65536.0,
        all.validated as f64 / all.changed as f64
    );
}

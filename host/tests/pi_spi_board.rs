//! The seed 004 verbs against the real board application: `motorlink`'s `ping` and `drive
//! --kind pi-spi` over a fake spidev whose other end is `mcu::pi_spi::PiSpiApp` with a
//! `Safety<4>`, ticked at 1 kHz by wall time, with crude motors that turn the wheels the duty
//! asks for.
//!
//! ```text
//!  motorlink ─ exchange(RxBuffer) ─▶ PiSpiApp::on_transfer ─▶ Safety<4> ◀── PiSpiApp::tick (1 kHz, wall time)
//!            ◀── the TxBuffer prepared at the previous transfer (the DMA's double buffer)
//! ```
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::panic,
    missing_docs
)]

use std::time::Instant;

use mcu::pi_spi::{PiSpiApp, PiSpiTickInputs, MOTORS, RAD_PER_COUNT, TUNING};
use mcu::Safety;
use motorlink::cli::device::Verdict;
use motorlink::cli::pi::{self, PiDriveArgs, PiDrivePlan};
use motorlink::transport::{LinkError, Transport};
use protocol::pi_spi::TRANSFER_LEN;
use serde_json::Value;
use statemachine::{Config, FaultFlags, Mode, RejectReason};

/// Full duty on the fake board's motor timer.
const FULL: u16 = 1000;

struct FakePi {
    safety: Safety<MOTORS>,
    app: PiSpiApp,
    /// What the next transfer clocks out (prepared at the previous one).
    next_tx: [u8; TRANSFER_LEN],
    started: Instant,
    ticks: u64,
    angle: [f64; MOTORS],
    /// Ticks that ran with some motor driven (not coasting, not shorted).
    driven_ticks: u64,
    /// The modes seen after each tick.
    modes: Vec<Mode>,
}

impl FakePi {
    fn new() -> Self {
        Self {
            safety: Safety::new(Config::PI_SPI),
            app: PiSpiApp::new(&Config::PI_SPI, &TUNING, 100, FULL),
            next_tx: [0; TRANSFER_LEN],
            started: Instant::now(),
            ticks: 0,
            angle: [0.0; MOTORS],
            driven_ticks: 0,
            modes: Vec::new(),
        }
    }

    /// The ticks due by wall time (at most 20 at once: a starved thread slips, it does not burst).
    fn catch_up(&mut self) {
        let due = self.started.elapsed().as_millis() as u64;
        let mut n = 0;
        while self.ticks < due && n < 20 {
            self.tick();
            n += 1;
        }
        if self.ticks < due {
            self.ticks = due;
        }
    }

    fn tick(&mut self) {
        self.ticks += 1;
        let counts = self
            .angle
            .map(|a| (a / f64::from(RAD_PER_COUNT)).floor() as i32);
        let inputs = PiSpiTickInputs {
            counts,
            ..PiSpiTickInputs::default()
        };
        let o = self.app.tick(&mut self.safety, false, &inputs);
        self.modes.push(o.out.mode);
        let mut driven = false;
        for (a, m) in self.angle.iter_mut().zip(o.motors) {
            let duty = match (m.in1, m.in2) {
                (true, false) => f64::from(m.ccr) / f64::from(FULL),
                (false, true) => -f64::from(m.ccr) / f64::from(FULL),
                _ => 0.0,
            };
            driven |= duty != 0.0;
            // 30 rad/s at full duty, no inertia: enough for the host to see the counts move.
            *a += 30.0 * duty * 0.001;
        }
        if driven {
            self.driven_ticks += 1;
        }
    }
}

impl Transport for FakePi {
    fn exchange(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), LinkError> {
        self.catch_up();
        rx.copy_from_slice(&self.next_tx);
        let buf: [u8; TRANSFER_LEN] = tx.try_into().expect("a whole transfer");
        let now = (self.ticks * 1000) as u32;
        let mut out = [0u8; TRANSFER_LEN];
        self.app
            .on_transfer(&mut self.safety, &buf, now, 0, &mut out);
        self.next_tx = out;
        Ok(())
    }

    fn name(&self) -> &str {
        "fake pi-spi board"
    }
}

#[test]
fn ping_is_answered_and_changes_nothing_on_the_board() {
    let mut board = FakePi::new();
    let mut lines: Vec<Value> = Vec::new();
    let v = pi::run_ping(&mut board, 5, &mut |l| lines.push(l)).unwrap();
    assert_eq!(v, Verdict::Done, "{lines:?}");
    let c = board.safety.ladder().counters();
    assert_eq!(c.valid_frames, 0, "a version-0 buffer is never a command");
    assert_eq!(c.rejected[RejectReason::Version.index()], 5);
    assert_eq!(board.safety.mode(), Mode::Brake);
}

#[test]
fn drive_re_arms_the_board_drives_the_motors_and_leaves_it_shut_down() {
    let mut board = FakePi::new();
    let args = PiDriveArgs {
        modes: Some("pwm".into()),
        targets: Some("120".into()),
        servo_modes: Some("enabled".into()),
        servo_pos: Some("1500".into()),
        ..PiDriveArgs::default()
    };
    let plan = PiDrivePlan::new(&args, 100.0, 1.5).unwrap();
    let mut lines: Vec<Value> = Vec::new();
    let v = pi::run_drive(&mut board, &plan, &mut || false, &mut |l| lines.push(l)).unwrap();
    assert_eq!(
        v,
        Verdict::Done,
        "the host saw the wheels turn: {:?}",
        lines.last()
    );
    let c = board.safety.ladder().counters();
    assert_eq!(
        c.rearms, 1,
        "one explicit re-arm: the shutdown bit's 1 → 0 edge"
    );
    assert!(
        board.driven_ticks > 500,
        "driven for {} ticks",
        board.driven_ticks
    );
    assert!(
        board.modes.contains(&Mode::Reduced),
        "REDUCED after the re-arm"
    );
    // The final transfer carried both shutdown bits: braked at once, servos off, rail cut.
    assert_eq!(board.safety.mode(), Mode::Brake);
    assert!(board
        .safety
        .ladder()
        .faults()
        .contains(FaultFlags::SHUTDOWN));
    assert!(board.app.servo().shutdown);
    // Whatever the host does next, a tick keeps the motors shorted.
    board.tick();
    assert_eq!(board.safety.mode(), Mode::Brake);
    let refused: u32 = board.safety.ladder().counters().rejected_total();
    assert_eq!(refused, 0, "every buffer the verb sent was valid");
}

//! Task-level tests of the board application: the bodies the firmware and the simulator both run,
//! driven here tick by tick as the board's interrupts would drive them.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::panic
)]

use control::{BridgeState, Q};
use mcu::hw::RecordingBridge;
use mcu::tick::TickInputs;
use mcu::tuning::AMR;
use mcu::{CurrentLoop, EstopInput, LinkTask, Measurements, Safety, SpeedLoop, TickTask};
use protocol::amr::{
    decode_feedback, decode_mcu_frame, encode_command, BoardProfile, McuFrame, McuInfo,
    MotorCommand, ResetCause, FRAME_LEN, REQUEST_IDENTITY,
};
use statemachine::{Mode, Speed};

const IDENTITY: McuInfo = McuInfo {
    fw_version: 0x0001_0203,
    git_hash: 0xdead_beef,
    board: BoardProfile::AmrSpi,
    build_date: 20261130,
    reset_cause: ResetCause::Panic,
    reset_count: 3,
    panic_line: 42,
    seq: 0,
    dirty: false,
};

/// The board's task state, stepped at the board's rates.
struct Board {
    safety: Safety,
    link: LinkTask,
    tick: TickTask,
    speed: SpeedLoop,
    current: CurrentLoop,
    estop: EstopInput,
    bridge: RecordingBridge,
    meas: Measurements,
    setpoint: Option<[Speed; 2]>,
    seq: u32,
    tx: [u8; FRAME_LEN],
}

impl Board {
    fn new() -> Self {
        Self {
            safety: Safety::new(AMR.ladder),
            link: LinkTask::new(IDENTITY),
            tick: TickTask::new(&AMR),
            speed: SpeedLoop::new(&AMR, [0, 0]),
            current: CurrentLoop::new(&AMR, [AMR.adc_zero; 2]),
            estop: EstopInput::new(),
            bridge: RecordingBridge::new(AMR.pwm_arr().unwrap()),
            meas: Measurements::default(),
            setpoint: None,
            seq: 0,
            tx: [0; FRAME_LEN],
        }
    }

    fn frame(&mut self, left: f32, right: f32, enable: bool, now_us: u32) {
        self.frame_asking(left, right, enable, now_us, 0);
    }

    fn frame_asking(&mut self, left: f32, right: f32, enable: bool, now_us: u32, request: u32) {
        self.seq += 1;
        let mut f = [0u8; FRAME_LEN];
        encode_command(
            &MotorCommand {
                timestamp_us: 0,
                left_speed_cmd: left,
                right_speed_cmd: right,
                control_mode: 1,
                enable,
                seq: self.seq,
                request,
            },
            &mut f,
        );
        self.link
            .on_frame(&mut self.safety, &f, &self.meas, now_us, &mut self.tx);
    }

    /// One tick with no fault inputs and loops that ran at their rates.
    fn tick(&mut self) -> mcu::TickOutcome {
        let inputs = TickInputs {
            meas: self.meas.take_for_tick(),
            estop: self.estop.poll(false),
            runs: mcu::Runs {
                current: self.safety.ticks().wrapping_add(1) * 20,
                speed: self.safety.ticks().wrapping_add(1) * 10,
            },
            ..TickInputs::default()
        };
        let o = self.tick.run(&mut self.safety, &inputs);
        o.drive(&mut self.bridge, &self.estop);
        self.setpoint = o.setpoint();
        o
    }

    /// Ten speed-loop samples (one tick's worth) with the wheels standing still.
    fn speed_samples(&mut self) {
        for _ in 0..AMR.speed_samples_per_tick() {
            let s = self.speed.run([0, 0], self.setpoint);
            self.meas.record_speed(&s);
        }
    }

    /// Arms and ramps both wheels to `target` rad/s with fresh frames every tick.
    fn drive_at(&mut self, target: f32) {
        self.frame(0.0, 0.0, false, 0);
        self.tick();
        let mut v = 0.0f32;
        for _ in 0..2000 {
            v = (v + 0.04).min(target);
            self.frame(v, v, true, 0);
            self.tick();
            self.speed_samples();
        }
    }
}

#[test]
fn stop_ramp_on_the_board_equals_the_ladders() {
    let mut b = Board::new();
    b.drive_at(5.0);
    assert_eq!(b.safety.mode(), Mode::Normal);
    assert_eq!(b.speed.references(), [Speed::from_num(5); 2]);
    // The link goes silent: HOLD, then STOP; after every tick's speed samples, the speed loop's
    // reference must have reached the setpoint the ladder applied at that tick (the board's
    // ramp may not lag the ladder's deceleration).
    let mut stop_ticks = 0;
    for _ in 0..9 {
        let o = b.tick();
        b.speed_samples();
        if let Some(setpoint) = o.out.drive.speeds() {
            assert_eq!(b.speed.references(), setpoint, "mode {:?}", o.out.mode);
            if o.out.mode == Mode::Stop {
                stop_ticks += 1;
            }
        }
    }
    assert!(stop_ticks >= 4, "STOP seen for {stop_ticks} ticks");
    // And a commanded stop (enable = 0 keeps frames fresh: STOP for as long as it lasts) reaches
    // zero at the ladder's 0.1 rad/s per tick, not slower.
    let mut b = Board::new();
    b.drive_at(5.0);
    let mut ticks = 0;
    while b.speed.references()[0] > Speed::ZERO && ticks < 200 {
        b.frame(0.0, 0.0, false, 0);
        b.tick();
        b.speed_samples();
        ticks += 1;
        let applied = b.safety.ladder().applied();
        assert_eq!(b.speed.references(), applied, "tick {ticks}");
    }
    // 5 rad/s at 0.1 rad/s per tick: 50 ticks (plus one for the mode change).
    assert!((50..=51).contains(&ticks), "{ticks} ticks to stop");
}

#[test]
fn feedback_timestamps_advance_in_microseconds() {
    let mut b = Board::new();
    let counts_per_tick = 42_000;
    let mut last: Option<(u32, u32)> = None;
    for k in 0..50u32 {
        // A transaction a third of the way through each tick.
        let now = b.safety.micros(
            counts_per_tick / 3,
            false,
            counts_per_tick,
            AMR.us_per_tick(),
        );
        b.frame(0.0, 0.0, false, now);
        let fb = decode_feedback(&b.tx).unwrap();
        assert_eq!(fb.timestamp_us, 1000 * k + 333, "tick {k}");
        if let Some((ts, seq)) = last {
            assert_eq!(fb.timestamp_us - ts, 1000);
            assert_eq!(fb.seq, seq + 1);
        }
        last = Some((fb.timestamp_us, fb.seq));
        b.tick();
    }
}

#[test]
fn feedback_reports_signed_currents() {
    let mut b = Board::new();
    // 1241 counts below the zero reading: −10 A through the left shunt (driving backwards).
    let s = b.current.run(
        &mut b.bridge,
        [AMR.adc_zero - 1241, AMR.adc_zero + 620],
        [Q::ZERO; 2],
    );
    b.meas.record_current(&s);
    b.frame(0.0, 0.0, false, 0);
    let fb = decode_feedback(&b.tx).unwrap();
    assert!((fb.left_current + 10.0).abs() < 0.01, "{}", fb.left_current);
    assert!(
        (fb.right_current - 5.0).abs() < 0.01,
        "{}",
        fb.right_current
    );
    assert!(!s.tripped);
}

#[test]
fn feedback_reports_wheel_speeds_and_encoder_counts() {
    let mut b = Board::new();
    // Left +2 counts per speed sample, right −1, for 40 samples (more than the 16-sample window).
    let (mut l, mut r) = (0u16, 0u16);
    for _ in 0..40 {
        l = l.wrapping_add(2);
        r = r.wrapping_sub(1);
        let s = b.speed.run([l, r], None);
        b.meas.record_speed(&s);
    }
    b.frame(0.0, 0.0, false, 0);
    let fb = decode_feedback(&b.tx).unwrap();
    // 2 counts per 0.1 ms = 20 000 counts/s = 20 000 / 4096 rev/s = 30.68 rad/s; −1: −15.34.
    let per_count = AMR.speed_hz as f32 / AMR.counts_per_rev as f32 * core::f32::consts::TAU;
    assert!(
        (fb.left_speed - 2.0 * per_count).abs() < 0.01,
        "{}",
        fb.left_speed
    );
    assert!(
        (fb.right_speed + per_count).abs() < 0.01,
        "{}",
        fb.right_speed
    );
    assert_eq!((fb.left_encoder, fb.right_encoder), (80, -40));
}

#[test]
fn overcurrent_brakes_the_bridge_in_the_same_run_and_latches_at_the_tick() {
    let mut b = Board::new();
    b.drive_at(2.0);
    assert_eq!(b.bridge.state, BridgeState::Run);
    // 15 A: 1862 counts above zero.
    let s = b.current.run(
        &mut b.bridge,
        [AMR.adc_zero, AMR.adc_zero + 1862],
        [Q::ZERO; 2],
    );
    assert!(s.tripped);
    assert_eq!(
        b.bridge.state,
        BridgeState::Brake,
        "braked in the current loop itself"
    );
    b.meas.record_current(&s);
    b.frame(2.0, 2.0, true, 0);
    let o = b.tick();
    assert_eq!(o.out.mode, Mode::Brake);
    assert_eq!(b.bridge.state, BridgeState::Brake);
    // The hardware break alone trips too.
    let mut b = Board::new();
    b.drive_at(2.0);
    b.bridge.tripped = true;
    assert!(
        b.current
            .run(&mut b.bridge, [AMR.adc_zero; 2], [Q::ZERO; 2])
            .tripped
    );
    assert_eq!(b.bridge.state, BridgeState::Brake);
}

#[test]
fn estop_brakes_in_its_handler_and_a_late_press_is_not_undone_by_the_tick() {
    let mut b = Board::new();
    b.drive_at(2.0);
    // The tick polls the input (released), then the press comes before it drives the bridge.
    let inputs = TickInputs {
        estop: b.estop.poll(false),
        runs: mcu::Runs {
            current: u32::MAX,
            speed: u32::MAX,
        },
        ..TickInputs::default()
    };
    b.frame(2.0, 2.0, true, 0);
    let o = b.tick.run(&mut b.safety, &inputs);
    assert_eq!(o.bridge, BridgeState::Run);
    b.estop.edge(&mut b.bridge, true);
    assert_eq!(b.bridge.state, BridgeState::Brake);
    o.drive(&mut b.bridge, &b.estop);
    assert_eq!(
        b.bridge.state,
        BridgeState::Brake,
        "the tick must not restart a braked bridge"
    );
    // The next tick latches ESTOP in the ladder.
    let o = b.tick();
    assert_eq!(o.out.mode, Mode::Brake);
    assert!(o.out.faults.contains(statemachine::FaultFlags::ESTOP));
    assert!(!o.brake_release);
}

#[test]
fn a_stalled_loop_stops_the_watchdog_refresh() {
    let mut b = Board::new();
    let mut inputs = TickInputs {
        runs: mcu::Runs {
            current: 20,
            speed: 10,
        },
        ..TickInputs::default()
    };
    assert!(b.tick.run(&mut b.safety, &inputs).feed_watchdog);
    inputs.runs = mcu::Runs {
        current: 40,
        speed: 18,
    };
    assert!(
        !b.tick.run(&mut b.safety, &inputs).feed_watchdog,
        "speed loop ran 8 of 10"
    );
    inputs.runs = mcu::Runs {
        current: 60,
        speed: 28,
    };
    assert!(b.tick.run(&mut b.safety, &inputs).feed_watchdog);
}

#[test]
fn the_trace_records_the_arming_and_the_comm_loss() {
    let mut b = Board::new();
    b.drive_at(1.0);
    for _ in 0..12 {
        b.tick();
    }
    use mcu::trace::Record;
    let records: Vec<Record> = b.safety.trace().iter().map(|e| e.record).collect();
    assert!(records.contains(&Record::Rearmed), "{records:?}");
    assert!(
        records.contains(&Record::Mode {
            from: Mode::Stop,
            to: Mode::Brake
        }),
        "{records:?}"
    );
    assert!(records.iter().any(
        |r| matches!(r, Record::Latched(c) if c.contains(statemachine::FaultFlags::COMM_LOST))
    ));
}

#[test]
fn an_identity_request_is_answered_in_the_next_slot_and_only_there() {
    let mut b = Board::new();
    b.frame(0.0, 0.0, false, 0);
    let first = decode_feedback(&b.tx).unwrap();
    b.frame_asking(0.0, 0.0, false, 0, REQUEST_IDENTITY);
    let McuFrame::Info(info) = decode_mcu_frame(&b.tx).unwrap() else {
        panic!(
            "no identity in the slot after the request: {:?}",
            decode_mcu_frame(&b.tx)
        );
    };
    assert_eq!(
        info,
        McuInfo {
            seq: first.seq + 1,
            ..IDENTITY
        }
    );
    // The frame itself still reached the ladder, and the next slot is feedback again, numbered on.
    assert_eq!(b.safety.ladder().counters().valid_frames, 2);
    b.frame(0.0, 0.0, false, 0);
    let next = decode_feedback(&b.tx).unwrap();
    assert_eq!(next.seq, first.seq + 2);
    // An unknown request value is ignored, the command still applies.
    b.frame_asking(0.0, 0.0, false, 0, 7);
    assert!(decode_feedback(&b.tx).is_ok());
    assert_eq!(b.safety.ladder().counters().valid_frames, 4);
}

#[test]
fn a_cut_transaction_is_a_framing_refusal_that_moves_nothing() {
    let mut b = Board::new();
    b.drive_at(1.0);
    let before = *b.safety.ladder();
    b.link.transaction_cut(&mut b.safety);
    let after = b.safety.ladder();
    assert_eq!(
        after
            .counters()
            .rejected(statemachine::RejectReason::Framing),
        before
            .counters()
            .rejected(statemachine::RejectReason::Framing)
            + 1
    );
    assert_eq!(after.applied(), before.applied());
    assert_eq!(after.last_valid(), before.last_valid());
    assert_eq!(after.age(), before.age());
}

#[test]
fn feedback_echoes_the_sequence_number_of_the_last_accepted_command_only() {
    let mut b = Board::new();
    b.frame(0.0, 0.0, false, 0);
    b.frame(0.0, 0.0, false, 0);
    assert_eq!(decode_feedback(&b.tx).unwrap().cmd_seq, 2);
    // A frame with its CRC broken is refused: the echo stays at the last accepted command.
    let mut f = [0u8; FRAME_LEN];
    encode_command(
        &MotorCommand {
            timestamp_us: 0,
            left_speed_cmd: 0.0,
            right_speed_cmd: 0.0,
            control_mode: 1,
            enable: false,
            seq: 99,
            request: 0,
        },
        &mut f,
    );
    f[FRAME_LEN - 1] ^= 1;
    b.link.on_frame(&mut b.safety, &f, &b.meas, 0, &mut b.tx);
    assert_eq!(b.safety.ladder().counters().valid_frames, 2);
    assert_eq!(decode_feedback(&b.tx).unwrap().cmd_seq, 2);
}

#[test]
fn the_trace_records_one_rearm_per_arming_not_one_per_step() {
    let mut b = Board::new();
    // 2000 ticks and frames of driving after a single arming.
    b.drive_at(1.0);
    use mcu::trace::Record;
    let records: Vec<Record> = b.safety.trace().iter().map(|e| e.record).collect();
    let rearms = records.iter().filter(|r| **r == Record::Rearmed).count();
    assert_eq!(rearms, 1, "{records:?}");
    // Nothing else changed while driving: every record is from the arming.
    assert_eq!(
        b.safety.trace().total() as usize,
        records.len(),
        "{records:?}"
    );
}

#[test]
fn the_tick_clears_the_break_flag_only_while_braked() {
    let mut b = Board::new();
    b.drive_at(1.0);
    assert_eq!(b.bridge.state, BridgeState::Run);
    // While running the flag stays for the current loop to see and brake on.
    b.bridge.tripped = true;
    b.frame(1.0, 1.0, true, 0);
    b.tick();
    assert!(b.bridge.tripped);
    // Braked (power-on BRAKE of a fresh board): the tick clears it; the comparator would set it
    // again if the overcurrent were still there.
    let mut b = Board::new();
    b.bridge.tripped = true;
    b.tick();
    assert_eq!(b.bridge.state, BridgeState::Brake);
    assert!(!b.bridge.tripped);
}

#[test]
fn loops_that_reach_exactly_their_minimum_runs_keep_the_watchdog_fed() {
    let mut b = Board::new();
    let [min_current, min_speed] = AMR.min_runs_per_tick;
    let mut inputs = TickInputs {
        runs: mcu::Runs {
            current: min_current,
            speed: min_speed,
        },
        ..TickInputs::default()
    };
    assert!(b.tick.run(&mut b.safety, &inputs).feed_watchdog);
    // One run short on the current loop only.
    inputs.runs = mcu::Runs {
        current: 2 * min_current - 1,
        speed: 2 * min_speed,
    };
    assert!(!b.tick.run(&mut b.safety, &inputs).feed_watchdog);
}

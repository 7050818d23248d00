//! Fuzz targets, one per decoder (bolero). Under `cargo test` each runs a bounded number of random
//! inputs; for a longer run set `BOLERO_RANDOM_ITERATIONS` (see protocol/README.md), e.g.
//! `BOLERO_RANDOM_ITERATIONS=2000000 cargo test --release -p protocol --test fuzz -- --nocapture`.
//! Every target also checks that whatever decodes re-encodes to the same message.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    missing_docs
)]

use protocol::{amr, cdc, crc16, pi_spi, teensy};
use statemachine::RejectReason;
use std::sync::atomic::{AtomicU64, Ordering};

fn report(name: &str, n: &AtomicU64) {
    eprintln!(
        "fuzz {name}: {} executions, no finding",
        n.load(Ordering::Relaxed)
    );
}

fn frame64(input: &[u8], fix_crc: bool) -> [u8; amr::FRAME_LEN] {
    let mut f = [0u8; amr::FRAME_LEN];
    let n = input.len().min(amr::FRAME_LEN);
    f[..n].copy_from_slice(&input[..n]);
    if fix_crc {
        let crc = crc16::checksum(&f[..amr::CRC_OFFSET]);
        f[amr::CRC_OFFSET..].copy_from_slice(&crc.to_be_bytes());
    }
    f
}

#[test]
fn fuzz_amr_command() {
    static N: AtomicU64 = AtomicU64::new(0);
    bolero::check!()
        .with_max_len(amr::FRAME_LEN)
        .for_each(|input: &[u8]| {
            N.fetch_add(1, Ordering::Relaxed);
            for fix in [false, true] {
                let f = frame64(input, fix);
                if let Ok(c) = amr::decode_command(&f) {
                    let mut g = [0u8; amr::FRAME_LEN];
                    amr::encode_command(&c, &mut g);
                    let d = amr::decode_command(&g).unwrap();
                    assert_eq!(format!("{c:?}"), format!("{d:?}"));
                }
            }
        });
    report("amr_command", &N);
}

#[test]
fn fuzz_amr_feedback() {
    static N: AtomicU64 = AtomicU64::new(0);
    bolero::check!()
        .with_max_len(amr::FRAME_LEN)
        .for_each(|input: &[u8]| {
            N.fetch_add(1, Ordering::Relaxed);
            for fix in [false, true] {
                let f = frame64(input, fix);
                if let Ok(fb) = amr::decode_feedback(&f) {
                    let mut g = [0u8; amr::FRAME_LEN];
                    amr::encode_feedback(&fb, &mut g);
                    assert_eq!(
                        format!("{fb:?}"),
                        format!("{:?}", amr::decode_feedback(&g).unwrap())
                    );
                }
            }
        });
    report("amr_feedback", &N);
}

/// Every 64-byte input through `decode_info` and `decode_mcu_frame`: no panic, whatever decodes
/// re-encodes to the same message, and the two decoders agree on which frames are info frames.
#[test]
fn fuzz_amr_info() {
    static N: AtomicU64 = AtomicU64::new(0);
    bolero::check!()
        .with_max_len(amr::FRAME_LEN)
        .for_each(|input: &[u8]| {
            N.fetch_add(1, Ordering::Relaxed);
            for fix in [false, true] {
                let f = frame64(input, fix);
                let info = amr::decode_info(&f);
                let any = amr::decode_mcu_frame(&f);
                match any {
                    Ok(amr::McuFrame::Info(i)) => {
                        assert_eq!(info, Ok(i));
                        assert_eq!(amr::decode_feedback(&f), Err(RejectReason::Version));
                    }
                    Ok(amr::McuFrame::Feedback(fb)) => {
                        let direct = amr::decode_feedback(&f).unwrap();
                        assert_eq!(format!("{fb:?}"), format!("{direct:?}"));
                    }
                    // A frame refused as feedback for its version is refused for what the info
                    // decoder found; any other refusal is the feedback decoder's.
                    Err(e) => match amr::decode_feedback(&f).map(|_| ()) {
                        Err(RejectReason::Version) => assert_eq!(info.map(|_| ()), Err(e)),
                        other => assert_eq!(other, Err(e)),
                    },
                }
                if let Ok(i) = info {
                    let mut g = [0u8; amr::FRAME_LEN];
                    amr::encode_info(&i, &mut g);
                    assert_eq!(amr::decode_info(&g), Ok(i));
                }
            }
        });
    report("amr_info", &N);
}

#[test]
fn fuzz_cdc() {
    static N: AtomicU64 = AtomicU64::new(0);
    bolero::check!()
        .with_max_len(2 * cdc::MAX_FRAME_LEN)
        .for_each(|input: &[u8]| {
            N.fetch_add(1, Ordering::Relaxed);
            if let Ok(m) = cdc::decode_frame(input) {
                let mut out = [0u8; cdc::MAX_FRAME_LEN];
                let n = m.encode(&mut out);
                assert_eq!(cdc::decode_frame(&out[..n]), Ok(m));
            }
            let mut dec = cdc::StreamDecoder::new();
            let mut seen = 0u32;
            for r in dec.feed(input) {
                if r.is_ok() {
                    seen += 1;
                }
            }
            assert!(dec.buffered() <= cdc::MAX_FRAME_LEN);
            assert_eq!(dec.stats().frames, seen);
        });
    report("cdc", &N);
}

#[test]
fn fuzz_pi_spi() {
    static N: AtomicU64 = AtomicU64::new(0);
    bolero::check!()
        .with_max_len(pi_spi::RX_LEN)
        .for_each(|input: &[u8]| {
            N.fetch_add(1, Ordering::Relaxed);
            let mut rx = [0u8; pi_spi::RX_LEN];
            let n = input.len().min(pi_spi::RX_LEN);
            rx[..n].copy_from_slice(&input[..n]);
            rx[0] = pi_spi::TRANSFER_VERSION; // get past the version check most of the time
            if let Ok(d) = pi_spi::decode_rx(&rx) {
                let mut g = [0u8; pi_spi::RX_LEN];
                pi_spi::encode_rx(&d, &mut g);
                assert_eq!(g, rx);
            }
            let _ = pi_spi::shutdown_raw(&rx);
            let mut tx = [0u8; pi_spi::TX_LEN];
            let n = input.len().min(pi_spi::TX_LEN);
            tx[..n].copy_from_slice(&input[..n]);
            if let Ok(d) = pi_spi::decode_tx(&tx) {
                let mut g = [0u8; pi_spi::TX_LEN];
                pi_spi::encode_tx(&d, &mut g);
                assert_eq!(g, tx);
            }
        });
    report("pi_spi", &N);
}

#[test]
fn fuzz_teensy() {
    static N: AtomicU64 = AtomicU64::new(0);
    type Msg = teensy::CmdMsg<4>;
    bolero::check!()
        .with_max_len(3 * teensy::ROBUST_BUF)
        .for_each(|input: &[u8]| {
            N.fetch_add(1, Ordering::Relaxed);
            if let Ok(m) = Msg::decode_legacy(input) {
                let mut out = [0u8; Msg::LEGACY_LEN];
                m.encode_legacy(&mut out).unwrap();
                assert_eq!(&out[..], input);
            }
            if let Ok(m) = Msg::decode_robust(input) {
                let mut out = [0u8; teensy::ROBUST_BUF];
                let n = m.encode_robust(&mut out).unwrap();
                assert_eq!(Msg::decode_robust(&out[..n]), Ok(m));
            }
            let mut dec = teensy::RobustDecoder::<4>::new();
            for &b in input {
                let _ = dec.push(b);
            }
        });
    report("teensy", &N);
}

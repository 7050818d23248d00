//! [`SerialTransport`] on a real pseudo-terminal pair: the device end is opened as a serial port
//! would be, the other end plays the MCU (or QEMU's `-serial pty`).
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects,
    clippy::panic
)]

use super::*;
use std::fs::File;
use std::os::fd::AsFd;
use std::time::Instant;

/// A pty pair in its initial (cooked, echoing) mode: the MCU's end and the device path.
fn pty() -> (File, String) {
    let p = nix::pty::openpty(None, None).unwrap();
    let path = nix::unistd::ttyname(p.slave.as_fd()).unwrap();
    // Only the path is needed: the transport opens the device itself, as motorlink does.
    drop(p.slave);
    (File::from(p.master), path.to_string_lossy().into_owned())
}

/// Reads from `s` until `n` bytes have come or `within` has passed.
fn read_n(s: &mut SerialTransport, n: usize, within: Duration) -> Vec<u8> {
    let end = Instant::now() + within;
    let mut got = Vec::new();
    let mut buf = [0u8; 512];
    while got.len() < n && Instant::now() < end {
        let k = s.read_some(&mut buf).unwrap();
        got.extend_from_slice(&buf[..k]);
    }
    got
}

/// Every byte value, then again the ones a cooked terminal acts on (CR, LF, ^C, ^D, ^S/^Q, ^Z,
/// DEL, NUL).
fn all_bytes() -> Vec<u8> {
    (0..=255u8)
        .chain([b'\r', b'\n', 3, 4, 0x11, 0x13, 0x1a, 0x7f, 0])
        .collect()
}

#[test]
fn a_pty_carries_every_byte_unchanged_both_ways_without_echo() {
    let (mut mcu, path) = pty();
    let mut s = SerialTransport::open(&path, 115_200, Duration::from_millis(20)).unwrap();
    let bytes = all_bytes();

    // Device → host: no CR/LF translation, no line buffering, no signal characters.
    mcu.write_all(&bytes).unwrap();
    assert_eq!(read_n(&mut s, bytes.len(), Duration::from_secs(2)), bytes);

    // Host → device: no output processing; and what the MCU sent was not echoed back to it.
    s.write_all(&bytes).unwrap();
    let mut got = vec![0u8; bytes.len()];
    mcu.read_exact(&mut got).unwrap();
    assert_eq!(
        got, bytes,
        "exactly the written bytes, and no echo before them"
    );
    assert_eq!(
        read_n(&mut s, 1, Duration::from_millis(50)),
        b"",
        "nothing echoed back to the host either"
    );
}

#[test]
fn a_reopened_pty_drops_stale_bytes_and_keeps_the_reply_that_follows_the_write() {
    let (mut mcu, path) = pty();
    let s = SerialTransport::open(&path, 115_200, Duration::from_millis(20)).unwrap();
    drop(s);
    // Sent while no process held the device (QEMU keeps sending STATUS between two motorlink runs).
    mcu.write_all(b"stale").unwrap();
    std::thread::sleep(Duration::from_millis(20));

    let mut s = SerialTransport::open(&path, 115_200, Duration::from_millis(20)).unwrap();
    s.write_all(b"ping").unwrap();
    let mut req = [0u8; 4];
    mcu.read_exact(&mut req).unwrap();
    assert_eq!(&req, b"ping");
    // The reply comes at once, before the host's next read.
    mcu.write_all(b"reply").unwrap();
    assert_eq!(read_n(&mut s, 5, Duration::from_secs(2)), b"reply");
}

#[test]
fn a_second_opener_is_refused_while_the_first_holds_the_device() {
    let (_mcu, path) = pty();
    let _first = SerialTransport::open(&path, 115_200, Duration::from_millis(20)).unwrap();
    let Err(e) = SerialTransport::open(&path, 115_200, Duration::from_millis(20)) else {
        panic!("two openers of one device");
    };
    assert!(matches!(e, LinkError::Open(..)), "{e}");
}

#[test]
fn the_read_timeout_can_be_changed() {
    let (_mcu, path) = pty();
    let mut s = SerialTransport::open(&path, 115_200, Duration::from_millis(500)).unwrap();
    s.set_read_timeout(Duration::from_millis(5)).unwrap();
    let t = Instant::now();
    assert_eq!(s.read_some(&mut [0u8; 8]).unwrap(), 0);
    assert!(
        t.elapsed() < Duration::from_millis(400),
        "{:?}",
        t.elapsed()
    );
}

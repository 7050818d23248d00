//! `motorlink info --capture` end to end: the binary's output and exit status for a capture that
//! holds an `McuInfo` frame among feedback and corrupted frames, and for one that holds none.
#![allow(
    clippy::unwrap_used,
    clippy::indexing_slicing,
    clippy::arithmetic_side_effects
)]

use std::process::Command;

use protocol::amr::{self, BoardProfile, McuInfo, MotorFeedback, ResetCause, FRAME_LEN};

fn feedback(seq: u32) -> [u8; FRAME_LEN] {
    let mut f = [0u8; FRAME_LEN];
    let fb = MotorFeedback {
        timestamp_us: seq * 1000,
        right_current: -4.0,
        seq,
        ..MotorFeedback::default()
    };
    amr::encode_feedback(&fb, &mut f);
    f
}

fn write(name: &str, frames: &[[u8; FRAME_LEN]]) -> std::path::PathBuf {
    let path = std::env::temp_dir().join(format!("motorlink-it-{}-{name}.bin", std::process::id()));
    std::fs::write(&path, frames.concat()).unwrap();
    path
}

fn motorlink(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_motorlink"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn info_from_a_capture() {
    let info = McuInfo {
        fw_version: amr::pack_fw_version(2, 0, 7),
        git_hash: amr::git_hash_from_hex("0badc0de"),
        board: BoardProfile::PiSpi,
        build_date: 20_270_102,
        reset_cause: ResetCause::Brownout,
        reset_count: 1,
        panic_line: 0,
        seq: 11,
        dirty: false,
    };
    let mut info_frame = [0u8; FRAME_LEN];
    amr::encode_info(&info, &mut info_frame);
    let mut corrupted = feedback(12);
    corrupted[20] ^= 0x80;
    let path = write("ok", &[feedback(10), info_frame, corrupted, feedback(13)]);
    let p = path.to_str().unwrap();

    let (code, out, err) = motorlink(&["info", "--capture", p]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("firmware     2.0.7 (git 0badc0de)"), "{out}");
    assert!(out.contains("board        PiSpi"), "{out}");
    assert!(out.contains("built        2027-01-02"), "{out}");
    assert!(out.contains("reset cause  Brownout (code 6)"), "{out}");
    assert!(
        out.contains("2 feedback, 1 McuInfo, refused: 1 Crc"),
        "{out}"
    );

    let (code, out, _) = motorlink(&["info", "--capture", p, "--json"]);
    assert_eq!(code, 0);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["identities"][0]["reset_cause"], "brownout");
    assert_eq!(v["identities"][0]["board"], "pi_spi");
    std::fs::remove_file(&path).unwrap();
}

#[test]
fn no_info_frame_exits_non_zero_with_the_reason() {
    let path = write("none", &[feedback(1), feedback(2)]);
    let (code, out, err) = motorlink(&["info", "--capture", path.to_str().unwrap()]);
    std::fs::remove_file(&path).unwrap();
    assert_ne!(code, 0);
    assert!(out.is_empty(), "{out}");
    assert!(
        err.contains("no McuInfo frame") && err.contains("2 feedback"),
        "{err}"
    );
    // Neither source given: clap refuses, naming both.
    let (code, _, err) = motorlink(&["info"]);
    assert_ne!(code, 0);
    assert!(
        err.contains("--capture") && err.contains("--device"),
        "{err}"
    );
}

/// Bytes the real firmware image wrote under QEMU (`firmware/qemu/run.sh` keeps them in
/// `target/qemu/feedback.bin`): the first command of that run asked for the identity.
#[test]
fn info_from_the_firmware_s_own_capture() {
    let p = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/qemu-amr-feedback.bin"
    );
    let (code, out, err) = motorlink(&["info", "--capture", p, "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let id = &v["identities"][0];
    // The workspace's firmware crate is 0.1.0, built for the seed 000 SPI board; QEMU models no
    // reset flags, so the cause is unknown and nothing was counted.
    assert_eq!(id["fw_version"], "0.1.0", "{out}");
    assert_eq!(id["board"], "amr_spi", "{out}");
    assert_eq!(id["reset_cause"], "unknown", "{out}");
    assert_eq!(id["reset_count"], 0, "{out}");
    assert_eq!(id["seq"], 1, "{out}");
    assert_ne!(id["git_hash"], "00000000", "{out}");
    let (code, out, _) = motorlink(&["info", "--capture", p]);
    assert_eq!(code, 0);
    assert!(
        out.contains("45 feedback, 1 McuInfo, none refused"),
        "{out}"
    );
}

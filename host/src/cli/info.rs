//! `motorlink info`: which firmware runs on the MCU and why it last reset, read from its `McuInfo`
//! frame, either in a capture of feedback-slot frames or live over the seed 000 SPI link.
//!
//! The MCU sends an `McuInfo` in the feedback slot instead of a `MotorFeedback` after a command
//! whose `request` is [`REQUEST_IDENTITY`] (see `protocol::amr`):
//!
//! ```text
//!  MOSI   cmd s (request 1)   cmd s+1 (request 1)   ...
//!  MISO   feedback            McuInfo               (stop: answered)
//! ```
//! Live, every command asks (enable 0, speeds 0, mode 0, a fresh `seq`), so a lost frame costs one
//! millisecond, not the answer; the first frame that decodes as `McuInfo` ends the query.

use std::collections::BTreeMap;

use protocol::amr::{
    self, BoardProfile, McuFrame, McuInfo, MotorCommand, ResetCause, FRAME_LEN, REQUEST_IDENTITY,
};
use serde::Serialize;
use statemachine::validate::seq_is_newer;

use crate::transport::Transport;

/// One identity as `motorlink info` prints it: the `McuInfo` fields made readable, and where it was
/// found.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct Identity {
    /// Index of the (first) frame that carried it: in the capture, or the exchange number live.
    pub frame: usize,
    /// Consecutive info frames with this identity (the `seq` may differ).
    pub frames: usize,
    /// `major.minor.patch`.
    pub fw_version: String,
    /// `fw_version` as sent: `major << 16 | minor << 8 | patch`.
    pub fw_version_raw: u32,
    /// The first 8 hex digits of the firmware's commit; `None` when the build did not know it.
    pub git_hash: Option<String>,
    /// The build tree had uncommitted changes.
    pub dirty: bool,
    /// The link profile the image was built for.
    pub board: BoardProfile,
    /// `YYYY-MM-DD`; `None` when unknown (0), the raw number if it is not a date.
    pub build_date: Option<String>,
    /// Why the MCU last started.
    pub reset_cause: ResetCause,
    /// [`ResetCause`] wire value.
    pub reset_cause_code: u8,
    /// Resets since power-on.
    pub reset_count: u32,
    /// Source line of the last panic; `None` if none is recorded.
    pub panic_line: Option<u32>,
    /// The feedback sequence number the (first) info frame took.
    pub seq: u32,
}

impl Identity {
    /// The readable form of `info`, found at `frame`.
    pub fn new(frame: usize, info: &McuInfo) -> Self {
        let (major, minor, patch) = info.fw_version_parts();
        let (y, m, d) = info.build_date_parts();
        let build_date = match info.build_date {
            0 => None,
            _ if (1..=12).contains(&m) && (1..=31).contains(&d) => {
                Some(format!("{y:04}-{m:02}-{d:02}"))
            }
            raw => Some(format!("{raw} (not YYYYMMDD)")),
        };
        Self {
            frame,
            frames: 1,
            fw_version: format!("{major}.{minor}.{patch}"),
            fw_version_raw: info.fw_version,
            git_hash: (info.git_hash != 0).then(|| format!("{:08x}", info.git_hash)),
            dirty: info.dirty,
            board: info.board,
            build_date,
            reset_cause: info.reset_cause,
            reset_cause_code: info.reset_cause as u8,
            reset_count: info.reset_count,
            panic_line: (info.panic_line != 0).then_some(info.panic_line),
            seq: info.seq,
        }
    }

    /// True if `other` describes the same firmware and reset (everything but where and `seq`).
    fn same_as(&self, other: &Self) -> bool {
        let key = |i: &Self| {
            (
                i.fw_version_raw,
                i.git_hash.clone(),
                i.dirty,
                i.board,
                i.build_date.clone(),
                i.reset_cause,
                i.reset_count,
                i.panic_line,
            )
        };
        key(self) == key(other)
    }

    /// Several lines for a person.
    pub fn human(&self) -> String {
        let git = match &self.git_hash {
            Some(h) => format!("git {h}"),
            None => "git hash unknown".into(),
        };
        let dirty = if self.dirty {
            ", built from a tree with uncommitted changes"
        } else {
            ""
        };
        let panic = match self.panic_line {
            Some(line) => format!("at line {line}"),
            None => "none recorded".into(),
        };
        format!(
            "  firmware     {} ({git}{dirty})\n  board        {:?} ({})\n  built        {}\n  reset cause  {:?} (code {})\n  resets       {} since power-on\n  last panic   {panic}\n  seq          {}",
            self.fw_version,
            self.board,
            board_link(self.board),
            self.build_date.as_deref().unwrap_or("unknown"),
            self.reset_cause,
            self.reset_cause_code,
            self.reset_count,
            self.seq,
        )
    }
}

/// The link each board profile speaks.
fn board_link(b: BoardProfile) -> &'static str {
    match b {
        BoardProfile::AmrSpi => "AMR SPI link, Jetson",
        BoardProfile::Cdc => "USB CDC four-motor link",
        BoardProfile::Teensy => "Teensy serial link",
        BoardProfile::PiSpi => "Raspberry Pi SPI link",
    }
}

/// What a capture of feedback-slot frames holds.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct CaptureScan {
    /// Whole 64-byte frames.
    pub frames: usize,
    /// Frames that decoded as `MotorFeedback`.
    pub feedback: usize,
    /// Frames that decoded as `McuInfo`.
    pub info: usize,
    /// Frames refused, by `RejectReason` name.
    pub refused: BTreeMap<String, usize>,
    /// Bytes after the last whole frame.
    pub trailing_bytes: usize,
    /// Each identity, in order; a new entry whenever it differs from the one before (an MCU reset
    /// or a reflash during the capture shows as a second entry).
    pub identities: Vec<Identity>,
}

/// Reads `bytes` as concatenated 64-byte frames from the start (MISO as captured, one CS-low
/// period per frame) and decodes each as the MCU's feedback-slot frame.
pub fn scan_capture(bytes: &[u8]) -> CaptureScan {
    let mut scan = CaptureScan::default();
    let chunks = bytes.chunks_exact(FRAME_LEN);
    scan.trailing_bytes = chunks.remainder().len();
    for (i, chunk) in chunks.enumerate() {
        let Ok(frame) = <&[u8; FRAME_LEN]>::try_from(chunk) else {
            continue;
        };
        scan.frames = scan.frames.saturating_add(1);
        match amr::decode_mcu_frame(frame) {
            Ok(McuFrame::Feedback(_)) => scan.feedback = scan.feedback.saturating_add(1),
            Ok(McuFrame::Info(info)) => {
                scan.info = scan.info.saturating_add(1);
                let id = Identity::new(i, &info);
                match scan.identities.last_mut() {
                    Some(last) if last.same_as(&id) => last.frames = last.frames.saturating_add(1),
                    _ => scan.identities.push(id),
                }
            }
            Err(reason) => {
                let n = scan.refused.entry(format!("{reason:?}")).or_insert(0);
                *n = n.saturating_add(1);
            }
        }
    }
    scan
}

/// The byte offset (1 to 63) at which the most frames of `bytes` decode, if any decode there: a
/// capture that did not start at a frame boundary.
fn misaligned_offset(bytes: &[u8]) -> Option<(usize, usize)> {
    (1..FRAME_LEN)
        .map(|off| {
            let n = bytes
                .get(off..)
                .unwrap_or(&[])
                .chunks_exact(FRAME_LEN)
                .filter_map(|c| <&[u8; FRAME_LEN]>::try_from(c).ok())
                .filter(|f| amr::decode_mcu_frame(f).is_ok())
                .count();
            (off, n)
        })
        .filter(|&(_, n)| n > 0)
        .max_by_key(|&(_, n)| n)
}

/// `{"Crc":2,"Framing":1}` as `2 Crc, 1 Framing`.
fn refused_text(refused: &BTreeMap<String, usize>) -> String {
    if refused.is_empty() {
        return "none refused".into();
    }
    let parts: Vec<String> = refused.iter().map(|(r, n)| format!("{n} {r}")).collect();
    format!("refused: {}", parts.join(", "))
}

/// One line: what the frames were.
fn scan_line(scan: &CaptureScan) -> String {
    let trailing = if scan.trailing_bytes > 0 {
        format!(", {} bytes after the last whole frame", scan.trailing_bytes)
    } else {
        String::new()
    };
    format!(
        "{} frames of {FRAME_LEN} bytes: {} feedback, {} McuInfo, {}{trailing}",
        scan.frames,
        scan.feedback,
        scan.info,
        refused_text(&scan.refused)
    )
}

/// `motorlink info --capture`: the identities in `bytes` (read from `name`), as text or JSON; an
/// error naming what the capture held if no frame is an `McuInfo`.
pub fn info_capture(name: &str, bytes: &[u8], json: bool) -> Result<String, String> {
    let scan = scan_capture(bytes);
    if scan.identities.is_empty() {
        let mut why = if scan.frames == 0 {
            format!(
                "{name} holds no whole {FRAME_LEN}-byte frame ({} bytes)",
                bytes.len()
            )
        } else {
            format!("no McuInfo frame in {name}: {}", scan_line(&scan))
        };
        if let Some((off, n)) = misaligned_offset(bytes) {
            why.push_str(&format!(
                "; {n} frames decode when read from byte {off}: the capture did not start at a frame boundary, drop its first {off} bytes"
            ));
        }
        why.push_str(
            ". The MCU sends McuInfo in the feedback slot only after a command with request = 1: capture while `motorlink info --device` asks, or use it directly",
        );
        return Err(why);
    }
    if json {
        return serde_json::to_string_pretty(&scan).map_err(|e| format!("cannot print JSON: {e}"));
    }
    let mut out = String::new();
    for id in &scan.identities {
        let repeat = if id.frames > 1 {
            format!(", and {} more like it", id.frames.saturating_sub(1))
        } else {
            String::new()
        };
        out.push_str(&format!(
            "McuInfo at frame {}{repeat}:\n{}\n",
            id.frame,
            id.human()
        ));
    }
    if scan.identities.len() > 1 {
        out.push_str("The identity changed during the capture: the MCU reset or was reflashed.\n");
    }
    out.push_str(&format!("capture: {}", scan_line(&scan)));
    Ok(out)
}

/// [`info_capture`] of the file at `path`.
pub fn info_capture_file(path: &std::path::Path, json: bool) -> Result<String, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    info_capture(&path.display().to_string(), &bytes, json)
}

/// What a live query saw before it got its answer (or gave up).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct QueryLog {
    /// Exchanges made.
    pub exchanges: usize,
    /// Answers that were feedback (the request not answered yet, or not understood).
    pub feedback: usize,
    /// Answers refused, by `RejectReason` name.
    pub refused: BTreeMap<String, usize>,
    /// The last `cmd_seq` a feedback reported (the MCU's last accepted command).
    pub last_cmd_seq: Option<u32>,
}

/// Why a live query ended without an identity.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum QueryError {
    /// The transport failed (its message says what to check).
    Transport(String),
    /// Every exchange was made and none answered with an `McuInfo`.
    NoAnswer(QueryLog),
}

/// The command that asks for the identity: drive disabled, speeds 0, mode 0, `seq`.
pub fn identity_command(seq: u32, timestamp_us: u32) -> MotorCommand {
    MotorCommand {
        timestamp_us,
        seq,
        request: REQUEST_IDENTITY,
        ..MotorCommand::default()
    }
}

/// Asks the MCU behind `transport` for its `McuInfo`: up to `max_exchanges` exchanges, each a
/// command from [`identity_command`] after `pace()` (which waits for the next slot and returns the
/// host's µs clock). Sequence numbers start at `first_seq` and move past any `cmd_seq` the MCU
/// reports, so the commands are fresh to its validation (it refuses a repeated or older `seq`).
/// Returns the identity (its `frame` is the exchange that brought it) and the log; a transport
/// failure ends the query at once.
pub fn query_info<T: Transport + ?Sized>(
    transport: &mut T,
    first_seq: u32,
    max_exchanges: usize,
    mut pace: impl FnMut() -> u32,
) -> Result<(Identity, QueryLog), QueryError> {
    let mut log = QueryLog::default();
    let mut seq = first_seq;
    let mut tx = [0u8; FRAME_LEN];
    let mut rx = [0u8; FRAME_LEN];
    for i in 0..max_exchanges {
        let now = pace();
        amr::encode_command(&identity_command(seq, now), &mut tx);
        transport
            .exchange(&tx, &mut rx)
            .map_err(|e| QueryError::Transport(e.to_string()))?;
        log.exchanges = i.saturating_add(1);
        seq = seq.wrapping_add(1);
        match amr::decode_mcu_frame(&rx) {
            Ok(McuFrame::Info(info)) => return Ok((Identity::new(i, &info), log)),
            Ok(McuFrame::Feedback(fb)) => {
                log.feedback = log.feedback.saturating_add(1);
                log.last_cmd_seq = Some(fb.cmd_seq);
                if !seq_is_newer(seq, fb.cmd_seq) {
                    seq = fb.cmd_seq.wrapping_add(1);
                }
            }
            Err(reason) => {
                let n = log.refused.entry(format!("{reason:?}")).or_insert(0);
                *n = n.saturating_add(1);
            }
        }
    }
    Err(QueryError::NoAnswer(log))
}

/// `motorlink info --device`: [`query_info`] over `transport`, printed as text or JSON, or an error
/// that says what came back instead.
pub fn info_live<T: Transport + ?Sized>(
    transport: &mut T,
    first_seq: u32,
    max_exchanges: usize,
    json: bool,
    pace: impl FnMut() -> u32,
) -> Result<String, String> {
    let device = transport.name().to_string();
    match query_info(transport, first_seq, max_exchanges, pace) {
        Ok((id, log)) => {
            if json {
                serde_json::to_string_pretty(
                    &serde_json::json!({"device": device, "identity": id, "query": log}),
                )
                .map_err(|e| format!("cannot print JSON: {e}"))
            } else {
                Ok(format!(
                    "McuInfo from {device} (after {} exchanges):\n{}",
                    log.exchanges,
                    id.human()
                ))
            }
        }
        Err(QueryError::Transport(e)) => Err(e),
        Err(QueryError::NoAnswer(log)) => {
            let hint = if log.feedback > 0 {
                format!(
                    "the MCU answers with feedback but never with McuInfo: its firmware does not know the identity request (MotorCommand field 9), or it refuses our commands (its last accepted cmd_seq is {})",
                    log.last_cmd_seq.unwrap_or(0)
                )
            } else {
                "nothing valid came back: check the wiring, SPI mode 0, the clock (--speed), and that the firmware runs".into()
            };
            Err(format!(
                "no McuInfo from {device} in {} exchanges: {} feedback, {}; {hint}",
                log.exchanges,
                log.feedback,
                refused_text(&log.refused)
            ))
        }
    }
}

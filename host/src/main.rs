//! `motorlink`: run the simulator, decode/encode frames, monitor and ping a real MCU, drive a serial
//! board (seed 001), an arm (seed 003) or a Raspberry Pi's STM32 over SPI2 (seed 004, `--kind pi-spi`).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// `println!` that never panics: a closed pipe (`motorlink decode … | head`) ends the program quietly,
/// any other write error ends it with a message and exit code 1.
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        if let Err(e) = writeln!(std::io::stdout().lock(), $($arg)*) {
            if e.kind() == std::io::ErrorKind::BrokenPipe {
                std::process::exit(0);
            }
            eprintln!("motorlink: cannot write to standard output: {e}");
            std::process::exit(1);
        }
    }};
}

use clap::{Args, Parser, Subcommand, ValueEnum};
use motorlink::bridge::{Bridge, BridgeConfig};
use motorlink::cli::amr_link::{self, AmrLinkArgs, AmrOpts};
use motorlink::cli::device::{self, CdcVerb, DrivePlan, MovePlan, SendHex, TeensyVerb};
use motorlink::cli::exit::{Exit, Failure, OrExit, Run};
use motorlink::cli::pi;
use motorlink::cli::{self, FrameKind};
use motorlink::link::Link;
use motorlink::loopstats::{self, Goal, LoopStats};
use motorlink::pacing::Pacer;
use motorlink::serial::{CdcLink, TeensyLink};
use motorlink::simlink::{SimClock, SimConfig, SimMcu};
use motorlink::transport::{NullTransport, SerialTransport, SpiTransport, Transport};
use motorlink::SimHost;
use protocol::amr::{self, MotorFeedback, FRAME_LEN};
use protocol::cdc;
use serde_json::Value;
use sim::report;
use sim::scenario::{self, Scenario};
use statemachine::Estop;

#[derive(Parser)]
#[command(
    name = "motorlink",
    version,
    after_help = motorlink::cli::exit::TABLE,
    about = "Host side of the AMR motor controller: simulator, frame tools, device monitor, serial board verbs, the Raspberry Pi SPI link's verbs (ping, monitor, drive --kind pi-spi), and the operator's verbs of the AMR SPI link (list, arm, rearm, disarm, estop, drive --v --w, teleop, top; --sim for the simulated board)"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Kind {
    /// The AMR SPI link (Linux spidev, 64-byte frames at 1 kHz), 2 MHz mode 0.
    Spi,
    /// The USB CDC four-motor link (serial / USB CDC, `AA 55` frames): PING, IMU, STATUS, ACK.
    Serial,
    /// The Teensy serial link (robust frames: COBS + CRC); monitor only listens.
    Teensy,
    /// The Raspberry Pi SPI link (spidev to the STM32's SPI2): 179-byte full-duplex transfers, 2 MHz mode 0.
    PiSpi,
}

/// The serial link kinds of the board verbs.
#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum SerialKind {
    /// The USB CDC four-motor link (`AA 55` frames): ping, enable, estop, drive, send-hex.
    Serial,
    /// The Teensy serial link (robust frames): ping, move, cal, endeff, config, send-hex.
    Teensy,
    /// The Raspberry Pi SPI link over spidev (the device is /dev/spidevB.C): drive (and ping, monitor).
    PiSpi,
    /// The AMR SPI link over spidev (/dev/spidevB.C): drive --v --w, estop (and arm,
    /// disarm, rearm, teleop, top).
    Spi,
}

/// What every board verb takes.
#[derive(Args)]
struct SerialArgs {
    /// Serial device: /dev/ttyACM0, /dev/ttyUSB0, or a pty such as /dev/pts/5 (QEMU -serial pty).
    device: String,
    /// Link kind; each verb defaults to the protocol it speaks.
    #[arg(long, value_enum)]
    kind: Option<SerialKind>,
    /// Baud rate (a USB CDC device and a pty ignore it).
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    /// How long to wait for each reply (ACK, echo, STATUS), ms.
    #[arg(long, default_value_t = 500)]
    wait_ms: u64,
}

/// The link of `drive` and `estop`: a serial board, a spidev device (--kind pi-spi, --kind spi),
/// or the simulated AMR board (--sim, no device).
#[derive(Args)]
struct AnyLinkArgs {
    /// Device: serial (/dev/ttyACM0, /dev/ttyUSB0, a pty such as /dev/pts/5) or spidev
    /// (/dev/spidev0.0 with --kind spi or pi-spi); none with --sim.
    device: Option<String>,
    /// Link kind; each verb defaults to the protocol it speaks (--v, --w and --sim imply spi).
    #[arg(long, value_enum)]
    kind: Option<SerialKind>,
    /// Baud rate (a USB CDC device and a pty ignore it).
    #[arg(long, default_value_t = 115_200)]
    baud: u32,
    /// How long to wait for each reply (ACK, echo, STATUS), ms.
    #[arg(long, default_value_t = 500)]
    wait_ms: u64,
}

impl AnyLinkArgs {
    /// The serial board's link (a device is required).
    fn serial(self) -> Result<SerialArgs, Failure> {
        Ok(SerialArgs {
            device: self
                .device
                .ok_or_else(|| Failure::usage("give the device (e.g. /dev/ttyACM0)"))?,
            kind: self.kind,
            baud: self.baud,
            wait_ms: self.wait_ms,
        })
    }
}

/// `on` / `off`.
#[derive(Clone, Copy, ValueEnum)]
enum OnOff {
    /// Switch on.
    On,
    /// Switch off.
    Off,
}

/// ESTOP action.
#[derive(Clone, Copy, ValueEnum)]
enum EstopArg {
    /// Engage and latch (the board brakes at once).
    Engage,
    /// Release the link's own ESTOP (the board stays braked until re-armed).
    Release,
}

/// Output and exit status of the board verbs (also in host/README.md).
const VERB_HELP: &str = "Output: one JSON object per line on stdout, each with t_ms (milliseconds since the verb
started): every frame received ({\"message\":{..}}; a refused frame: {\"error\":..} or
{\"reason\":..}), and as the last line the result, with \"verdict\": \"done\" | \"refused\" | \"no_reply\".

Exit status:
  0   done: the board answered and did it (ACK result 0, echo cmd_success 1, replies came)
  1   refused by the board (ACK result != 0, echo cmd_success 0)
  64  bad argument (checked before the device is opened: nothing is sent)
  69  the device cannot be opened, or no reply within --wait-ms
  74  I/O error during the run
  (the whole table: motorlink --help)

The device is opened exclusively in raw mode; bytes that arrived before the open are dropped, so
each run sees only replies to itself. Several runs in sequence on one pty (QEMU -serial pty) work.";

// Parsed once per run: the size of the largest verb (drive's options) does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
enum Cmd {
    /// Run the built-in scenarios (or the given scenario files) and write traces, table and plots.
    Sim {
        /// Scenario files (TOML) or built-in names; default: every built-in scenario.
        scenarios: Vec<String>,
        /// Output directory.
        #[arg(long, default_value = "out/sim")]
        out: PathBuf,
        /// Run each scenario for this long, s, instead of its own duration. Expectations that
        /// depend on the scenario's own duration are then not judged, and listed as such after
        /// the table: shorter, all but never_brake, max_corrupted_applied, max_servo_violations;
        /// longer, those measured at the end (moving_at_end, final_mode, max_clock_error_us, ...).
        #[arg(long)]
        duration: Option<f64>,
        /// Skip the SVG plots.
        #[arg(long)]
        no_plots: bool,
        /// List the built-in scenarios and exit.
        #[arg(long)]
        list: bool,
    },
    /// Decode one frame (hex, spaces allowed) to JSON; cdc and teensy-robust also take a capture.
    #[command(after_long_help = cli::SHAPES)]
    Decode {
        /// Frame type.
        #[arg(long, value_enum)]
        frame: FrameKind,
        /// The bytes in hex (e.g. from a logic-analyser capture); `-` reads them from standard
        /// input (any number of lines; spaces, ':' and ',' allowed).
        hex: String,
        /// Joints in a Teensy serial link's CmdMsg (MAX_SUPPORTED_MTRS), 1 to 16.
        #[arg(long, default_value_t = cli::DEFAULT_MOTORS)]
        motors: usize,
    },
    /// Encode a JSON message to a frame in hex.
    #[command(after_long_help = cli::SHAPES)]
    Encode {
        /// Frame type.
        #[arg(long, value_enum)]
        frame: FrameKind,
        /// The message as JSON (field names as `decode` prints them; see --help).
        json: String,
        /// Joints in a Teensy serial link's CmdMsg (MAX_SUPPORTED_MTRS), 1 to 16.
        #[arg(long, default_value_t = cli::DEFAULT_MOTORS)]
        motors: usize,
    },
    /// Run the 1 kHz bridge disarmed against a device and print feedback and diagnostics.
    ///
    /// --kind spi|serial|teensy: what the port held before the run is discarded, so every line is
    /// news; if no valid frame arrives within --seconds, a warning on stderr and exit status 75
    /// (try again: board off, unplugged, wrong --kind or baud rate).
    ///
    /// --kind pi-spi: transfers the board ignores (transferVersion 0) at --hz for --seconds or
    /// --count transfers, every TxBuffer received printed as a JSON line ({"transfer":k,"tx":{..}};
    /// one that does not decode: {"transfer":k,"error":"version","version_byte":..,"hint":..},
    /// counted, never fatal); last line {"verdict":"done"|"no_reply",..}: done if update_time
    /// advanced. Ctrl-C ends it with the last line.
    Monitor {
        /// Device path (/dev/spidev0.0 or /dev/ttyACM0).
        device: String,
        /// Link kind.
        #[arg(long, value_enum, default_value = "spi")]
        kind: Kind,
        /// SPI clock, Hz (default 2000000) or baud rate (default 115200).
        #[arg(long, visible_alias = "baud")]
        speed: Option<u32>,
        /// How long, s.
        #[arg(long, visible_alias = "duration", default_value_t = 5.0)]
        seconds: f64,
        /// Transfers per second (--kind pi-spi; default 100).
        #[arg(long)]
        hz: Option<f64>,
        /// Stop after this many transfers instead of --seconds (--kind pi-spi).
        #[arg(long)]
        count: Option<u64>,
        /// Joints in a Teensy serial link's CmdMsg (--kind teensy), 1 to 16 (MAX_SUPPORTED_MTRS).
        #[arg(long, default_value_t = cli::DEFAULT_MOTORS)]
        motors: usize,
        #[command(flatten)]
        rt: RtArgs,
    },
    /// Exchange a few frames with a device and report round trips.
    ///
    /// --kind spi: command/feedback exchanges, with the MCU time and the clock offset (text lines),
    /// then the round trip's min/avg/max. --kind serial: PING, answered by a STATUS (or an ACK of
    /// PING). --kind teensy: ENDEFF_OFF, answered by its echo (the Teensy serial link has no probe
    /// message; switching the end effector off is the safe, idempotent round trip, but it does
    /// switch it off). Before each probe the input is discarded, so the reply is the first
    /// matching message that arrives after the probe: a periodic STATUS, or the late reply of an
    /// earlier probe, is never counted. Serial kinds print JSON lines: {"ping":i,
    /// "round_trip_us":..,"reply":{..}} or {"ping":i,"no_reply_ms":..}, then the verdict with
    /// "round_trip_us":{"min","avg","max"} over the replies of the --count pings and
    /// "discarded_bytes"; exit status 69 if nothing answered.
    ///
    /// --kind pi-spi: at least two transfers, 10 ms apart, of a buffer the board answers but
    /// ignores (every byte 0: transferVersion 0), so a ping never changes what the robot does. Lines
    /// {"ping":i,"round_trip_us":..,"tx":{..},"advanced":..} (or "error" and a "hint": all 0x00 or
    /// 0xFF bytes mean no board), then the verdict: done if update_time advanced, no_reply if
    /// nothing decoded or the board's timestamp is frozen ("stale":true).
    #[command(after_long_help = VERB_HELP)]
    Ping {
        /// Device path.
        device: String,
        /// Link kind.
        #[arg(long, value_enum, default_value = "spi")]
        kind: Kind,
        /// SPI clock, Hz (default 2000000) or baud rate (default 115200).
        #[arg(long, visible_alias = "baud")]
        speed: Option<u32>,
        /// Exchanges.
        #[arg(long, default_value_t = 10)]
        count: u32,
        /// How long to wait for each reply, ms (serial kinds).
        #[arg(long, default_value_t = 200)]
        wait_ms: u64,
        /// Joints in a Teensy serial link's CmdMsg (--kind teensy), 1 to 16.
        #[arg(long, default_value_t = cli::DEFAULT_MOTORS)]
        motors: usize,
    },
    /// USB CDC four-motor link: MOTOR_ENABLE on|off, wait for its ACK (exit 1 if the board refuses it).
    ///
    /// `on` asks the board to leave BRAKE; it does so only when fresh SET_MOTOR_PWM frames follow
    /// before its comm-loss threshold, so to drive use `drive --enable`, which sends both. The
    /// board refuses `on` (ACK result 1) while an ESTOP or another latching cause is active. Last
    /// line: {"verdict":..,"sent":{..},"reply":{"type":"ack","msg_id":2,"result":0},"round_trip_us":..}.
    #[command(after_long_help = VERB_HELP)]
    Enable {
        /// on: re-arm (MOTOR_ENABLE 1); off: stop (MOTOR_ENABLE 0).
        #[arg(value_enum)]
        state: OnOff,
        #[command(flatten)]
        link: SerialArgs,
    },
    /// USB CDC four-motor link: ESTOP engage|release, wait for its ACK. AMR SPI link (--kind spi,
    /// --sim): brake by a frame gap, or check that no ESTOP holds (--release).
    ///
    /// USB CDC four-motor link: engage latches BRAKE at once. release clears this link's ESTOP; the board stays
    /// braked until re-armed (`drive --enable`). Last line as for `enable` (msg_id 3).
    ///
    /// AMR SPI link (`estop [--release] DEVICE --kind spi`, or `estop [--release] --sim`): the link
    /// has no ESTOP message; the board's ESTOP is its own input. `estop` stops sending frames for
    /// 20 ms: the ladder goes HOLD at 2 ms, STOP at 5 and BRAKE (latched, COMM_LOST) at 10 ms, the
    /// fastest stop a host can cause; then enable-0 frames read the feedback back. Exit 0 if the
    /// MCU shows BRAKE, 1 if not. Clear the latch with `rearm`. `estop --release` releases nothing
    /// (there is nothing of the host's to release): it reads the feedback and exits 0 if no ESTOP
    /// holds, 1 if the board's ESTOP input is still engaged (release it at the robot; `rearm` is
    /// refused by the board until then).
    #[command(after_long_help = VERB_HELP)]
    Estop {
        /// engage | release (USB CDC four-motor link). On the AMR link optional (engage unless --release), and
        /// the device may come first: `estop /dev/spidev0.0 --kind spi`.
        action: Option<String>,
        #[command(flatten)]
        link: AnyLinkArgs,
        /// The same as the action `release`.
        #[arg(long, conflicts_with = "action")]
        release: bool,
        #[command(flatten)]
        amr: AmrOpts,
    },
    /// USB CDC four-motor link: send SET_MOTOR_PWM at a fixed rate for a while, then stop sending.
    /// AMR SPI link (--kind spi, --sim): drive a twist (--v, --w).
    ///
    /// Frames go out on absolute deadlines (--hz; the first at once) for --seconds; every STATUS,
    /// IMU and ACK received is printed. Then nothing more is sent: the board brakes on its own
    /// within --timeout-ms. The arguments are checked before the device is opened: |pwm| <= 1000,
    /// timeout from one frame period to 65535 ms, 0 < hz <= 1000.
    ///
    /// --enable: MOTOR_ENABLE 1 right after the first frame, its ACK awaited while the frames keep
    /// coming (the board keeps a re-arm only until the first frame, at most 249 ms); refused: stop sending, exit 1;
    /// no ACK within --wait-ms: stop sending, exit 69.
    ///
    /// First line {"sending":{..},"frames":..,"hz":..,"enable":..}; last line {"verdict":..,
    /// "frames_sent":..,"enable":{"reply":..,"round_trip_us":..}|null,"received":{"status":..,
    /// "status_motor_enabled":..,"status_estop_latched":..,"imu":..,"ack":..,"other":..,"errors":..,
    /// "last_status":{..}},"decoder":{..},"pacing":{..},"stopped_early":..}. Exit 3 also if a drive
    /// of 0.2 s or more received no valid frame at all (the board sends STATUS every 100 ms).
    ///
    /// --kind pi-spi (the Raspberry Pi SPI link, device /dev/spidevB.C): one transfer with the motor shutdown bit
    /// set and every motor OFF (carrying the one-shot updates --odom-reset, --kinematics,
    /// --pid-speed, each sent exactly once), then the command buffer (--modes, --targets, --goals,
    /// --servo-modes, --servo-pos; shutdown bits clear: the bit's 1->0 edge is the board's re-arm)
    /// at --hz (default 100) for --seconds, then one buffer with both shutdown bits set and every
    /// motor OFF; that last buffer is also sent on Ctrl-C (SIGINT, SIGTERM, SIGHUP) and after a
    /// failed transfer. Arguments are checked before the device is opened (exit 64): an enabled
    /// servo's position must be 600..=2600, a pwm duty within +-399, --hz above 20.4 (the board
    /// brakes 49 ms after the last valid transfer). Lines: {"sending":{..},..}, then
    /// {"transfer":k,"tx":{..}} (every --every-th) or {"transfer":k,"error":..}, last
    /// {"verdict":..,"transfers":{"arm","command","shutdown"},"commanded":[..],"moved":[..],
    /// "decoded":..,"errors":..,"update_time":{..},"stale":..,"pacing":{..},"interrupted":..}.
    /// Verdict: no_reply (exit 69) if update_time never advanced (no TxBuffer decoded, or a stale
    /// board); refused (exit 1) if commands ran for 0.2 s or more, some motor was commanded to move
    /// and none of those changed motor.position; done (exit 0) otherwise.
    ///
    /// AMR SPI link (`drive DEVICE --kind spi --v V --w W`, or `drive --sim --v V --w W`): runs the
    /// 1 kHz bridge, arms (enable 0, then the 0->1 edge; the MCU must leave BRAKE within 0.5 s, else
    /// exit 1 with the faults that hold it), commands the twist (v m/s, w rad/s, within the wheels'
    /// 18 rad/s) for --seconds, then commands zero until the wheels stand and sends enable 0
    /// (STOP); the same on Ctrl-C. Prints a summary of the MCU's feedback (distance and heading
    /// from the wheel speeds, means over the second half, peaks, modes seen, diagnostics); --json
    /// prints it as one object. Exit 0 done, 1 the MCU braked or refused to arm, 69 no feedback.
    #[command(after_long_help = VERB_HELP)]
    Drive {
        #[command(flatten)]
        link: AnyLinkArgs,
        /// Duties of motors 1 to 4, -1000 ..= 1000 (full scale), e.g. --pwm 300,-300,0,0 (required
        /// for --kind serial).
        #[arg(long, allow_hyphen_values = true)]
        pwm: Option<String>,
        /// The frame's timeout_ms: the board brakes if no new frame comes within it (--kind serial).
        #[arg(long, default_value_t = 200)]
        timeout_ms: u32,
        /// Frames per second (default 50; --kind pi-spi: transfers per second, default 100).
        #[arg(long)]
        hz: Option<f64>,
        /// How long to send, s.
        #[arg(long, visible_alias = "duration", default_value_t = 1.0)]
        seconds: f64,
        /// Re-arm first (MOTOR_ENABLE 1 after the first frame; its ACK is checked). --kind pi-spi
        /// always re-arms (the shutdown bit's 1->0 edge).
        #[arg(long)]
        enable: bool,
        #[command(flatten)]
        pi: pi::PiDriveArgs,
        /// AMR link: forward speed, m/s.
        #[arg(long = "v", allow_hyphen_values = true)]
        amr_v: Option<f64>,
        /// AMR link: yaw rate, rad/s (counter-clockwise positive).
        #[arg(long = "w", allow_hyphen_values = true)]
        amr_w: Option<f64>,
        #[command(flatten)]
        amr: AmrOpts,
    },
    /// List serial ports and spidev devices, with the link kinds (--kind) each can serve.
    ///
    /// Serial ports come from the serialport crate's enumeration (sysfs: USB VID:PID,
    /// manufacturer, product, serial number), spidev devices from /dev/spidev*. --json:
    /// {"devices":[{"path","bus","vid","pid","manufacturer","product","serial_number",
    /// "kinds":[..],"note"}]}.
    List {
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// AMR SPI link: arm (enable 0, then the 0->1 edge, then fresh frames) and report whether the
    /// MCU left BRAKE.
    ///
    /// The drive stays armed only while frames keep coming: after the MCU's answer this verb
    /// commands zero and enable 0 (STOP), and when it exits the board latches BRAKE (COMM_LOST)
    /// 10 ms after its last frame. Use it to check that the drive can be armed; drive with
    /// `drive` or `teleop`. Exit 0 the MCU left BRAKE, 1 it stayed (the faults holding it and what
    /// to do are printed), 69 no valid feedback (or no device), 64 a bad argument, 74 a failed exchange.
    Arm {
        #[command(flatten)]
        link: AmrLinkArgs,
    },
    /// AMR SPI link: enable 0 (the ladder's STOP: zero speed under the speed loop, bounded
    /// deceleration) until the wheels stand, at most --seconds; report the MCU's mode.
    ///
    /// Exit 0 the MCU left NORMAL/REDUCED and the wheels stand, 1 they still turn, 69 no feedback.
    /// When the verb exits its frames end and the board latches BRAKE 10 ms later.
    Disarm {
        #[command(flatten)]
        link: AmrLinkArgs,
        /// The longest wait for the wheels to stand, s.
        #[arg(long, default_value_t = 2.0)]
        seconds: f64,
    },
    /// AMR SPI link: clear a BRAKE latch (the ladder's rule: an explicit re-arm, the enable 0->1
    /// edge, plus fresh valid frames); the MCU decides.
    ///
    /// Runs the bridge until the MCU's feedback shows it out of BRAKE or 0.5 s pass, and reports
    /// what it did. Exit 0 the MCU left BRAKE (or was not in BRAKE), 1 it stayed in BRAKE (a
    /// latching cause is active: a held ESTOP input, overcurrent, ...; printed with what to do),
    /// 69 no valid feedback. Then commands zero and enable 0; the board brakes again (COMM_LOST)
    /// 10 ms after the verb's last frame: on this link a drive is armed while frames flow.
    Rearm {
        #[command(flatten)]
        link: AmrLinkArgs,
    },
    /// AMR SPI link: live view in the terminal (mode, feedback age, wheel speeds, currents,
    /// faults, link counters, clock sync, plots of the wheel speeds and the mode).
    ///
    /// Watches only: it sends enable-0 frames (the MCU needs frames to answer; enable 0 never
    /// moves the robot) and never arms. Ends with q, Esc, Ctrl-C or --seconds; the terminal is
    /// always restored, then the run's summary is printed (--json: as one object). The `monitor`
    /// verb prints JSON lines instead.
    Top {
        #[command(flatten)]
        link: AmrLinkArgs,
        /// Stop after this long, s (default: until q).
        #[arg(long)]
        seconds: Option<f64>,
    },
    /// AMR SPI link: drive with the keyboard, in the live view of `top`.
    ///
    /// Arms at start. w/s or up/down step v by 0.05 m/s, a/d or left/right step w by 0.25 rad/s
    /// (within --max-v, --max-w); space: zero; x: stop by a frame gap (BRAKE latched); r: re-arm;
    /// q, Esc or Ctrl-C: command zero, wait for the wheels to stand, enable 0, quit. The twist is
    /// sent only while keys keep coming: for --hold-ms after the last key (a held key repeats, and
    /// repeats of the same key within 100 ms keep it alive without stepping again). Then nothing is
    /// sent and the bridge's 200 ms cmd_vel staleness rule ramps the wheels to zero, so a dead
    /// terminal or a lost ssh session stops the robot; the twist is forgotten (the next key starts
    /// from zero). The terminal is always restored.
    Teleop {
        #[command(flatten)]
        link: AmrLinkArgs,
        /// Largest forward speed, m/s.
        #[arg(long, default_value_t = amr_link::teleop::TeleopConfig::DEFAULT.max_v)]
        max_v: f64,
        /// Largest yaw rate, rad/s.
        #[arg(long, default_value_t = amr_link::teleop::TeleopConfig::DEFAULT.max_w)]
        max_w: f64,
        /// How long the twist is still sent after the last key, ms.
        #[arg(long, default_value_t = 750)]
        hold_ms: u64,
        /// Stop after this long, s (default: until q).
        #[arg(long)]
        seconds: Option<f64>,
    },
    /// Teensy serial link: MTRS to absolute angles at a fixed rate (or once), checking every echo.
    ///
    /// Every echo must come back with cmd_success 1: a refusal stops the sending at once (exit 1),
    /// an echo missing --wait-ms after its command stops it too (exit 69). cmd_success 1 means the
    /// board took the command; the arm moves only once re-armed (--cal, or an earlier `cal` with
    /// MTRS frames kept fresh) and only while frames keep coming (it holds, then brakes, within
    /// 250 ms of the last).
    ///
    /// --cal: CAL right after the first MTRS, its echo checked while moving. --once: one MTRS (with
    /// --cal: one before the CAL and one after it). --relative sends is_relative 1 (this board
    /// refuses relative moves: exit 1).
    ///
    /// Last line {"verdict":..,"mtrs_sent":..,"echoes_ok":..,"echoes_refused":..,
    /// "echoes_missing":..,"cal":{"reply":..,"round_trip_us":..}|null,"received":{..},
    /// "decoder":{..},"pacing":{..},"stopped_early":..}.
    #[command(after_long_help = VERB_HELP)]
    Move {
        #[command(flatten)]
        link: SerialArgs,
        /// One absolute angle per joint, degrees, e.g. --angles 10,-20,0,45.
        #[arg(long, allow_hyphen_values = true)]
        angles: String,
        /// Speed cap, deg/s.
        #[arg(long)]
        speed: i32,
        /// Re-arm first (CAL after the first MTRS).
        #[arg(long)]
        cal: bool,
        /// Send one MTRS instead of repeating.
        #[arg(long)]
        once: bool,
        /// Relative angles (is_relative 1).
        #[arg(long)]
        relative: bool,
        /// Frames per second.
        #[arg(long, default_value_t = 50.0)]
        hz: f64,
        /// How long to send, s.
        #[arg(long, default_value_t = 1.0)]
        seconds: f64,
        /// Joints of the arm (MAX_SUPPORTED_MTRS), 1 to 16.
        #[arg(long, default_value_t = cli::DEFAULT_MOTORS)]
        motors: usize,
    },
    /// Teensy serial link: CAL, the explicit re-arm; wait for its echo.
    ///
    /// The arm leaves BRAKE only when fresh MTRS frames follow before its comm-loss threshold: to
    /// move, use `move --cal`. Last line {"verdict":..,"sent":{..},"reply":{..},"round_trip_us":..}.
    #[command(after_long_help = VERB_HELP)]
    Cal {
        #[command(flatten)]
        link: SerialArgs,
        /// Joints of the arm, 1 to 16.
        #[arg(long, default_value_t = cli::DEFAULT_MOTORS)]
        motors: usize,
    },
    /// Teensy serial link: ENDEFF_ON / ENDEFF_OFF, wait for the echo.
    #[command(after_long_help = VERB_HELP)]
    Endeff {
        /// on or off.
        #[arg(value_enum)]
        state: OnOff,
        #[command(flatten)]
        link: SerialArgs,
        /// Joints of the arm, 1 to 16.
        #[arg(long, default_value_t = cli::DEFAULT_MOTORS)]
        motors: usize,
    },
    /// Teensy serial link: CONFIG, the joints' acceleration; wait for the echo (refused above the board's limit).
    #[command(after_long_help = VERB_HELP)]
    Config {
        #[command(flatten)]
        link: SerialArgs,
        /// Acceleration, deg/s^2 (mtr_accel_deg_s_s).
        #[arg(long, allow_hyphen_values = true)]
        accel: i32,
        /// Joints of the arm, 1 to 16.
        #[arg(long, default_value_t = cli::DEFAULT_MOTORS)]
        motors: usize,
    },
    /// Write raw bytes (hex) to a serial board, then print whatever arrives within --listen-ms.
    ///
    /// For fault injection: a corrupted frame, a truncated one, garbage. The bytes go out exactly
    /// as given; replies are decoded as --kind (default serial). First line {"sent_hex":..,
    /// "bytes":..}; last line {"verdict":"done","received":{..},"decoder":{..}}: always exit 0
    /// unless the device fails. Build frames with `motorlink encode`.
    #[command(after_long_help = VERB_HELP)]
    SendHex {
        #[command(flatten)]
        link: SerialArgs,
        /// The bytes in hex (spaces, ':' and ',' allowed), e.g. aa55030100fda7 (an ESTOP release
        /// whose CRC is broken; the valid one is aa55030100fda6).
        hex: String,
        /// How long to listen after the write, ms.
        #[arg(long, default_value_t = 300)]
        listen_ms: u64,
        /// Joints in a Teensy serial link's CmdMsg (--kind teensy), 1 to 16.
        #[arg(long, default_value_t = cli::DEFAULT_MOTORS)]
        motors: usize,
    },
    /// Print the MCU's firmware identity and reset cause (the AMR SPI link's McuInfo), from a capture or live.
    ///
    /// --capture FILE reads a binary file of concatenated 64-byte MISO frames (one per CS-low period,
    /// as a logic analyser or spidev records them) and prints every McuInfo frame in it. --device
    /// asks the MCU: it sends commands with request = 1 and the drive disabled (enable 0, speeds 0,
    /// mode 0), one per millisecond, until an McuInfo comes back or --timeout-ms passes. None found:
    /// exit status 65 (capture; 66 if the file cannot be read) or 69 (device), with the reason.
    #[command(group(clap::ArgGroup::new("source").required(true).args(["capture", "device"])))]
    Info {
        /// Binary capture of feedback-slot frames (MISO), 64 bytes each, starting at a frame boundary.
        #[arg(long, value_name = "FILE")]
        capture: Option<PathBuf>,
        /// spidev device to ask (e.g. /dev/spidev0.0); the drive is disabled while it runs.
        #[arg(long, value_name = "DEVICE")]
        device: Option<String>,
        /// SPI clock, Hz (--device).
        #[arg(long, default_value_t = 2_000_000)]
        speed: u32,
        /// Give up after this long, ms (one exchange per ms; --device).
        #[arg(long, default_value_t = 200)]
        timeout_ms: u32,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Run the 1 kHz bridge of the AMR SPI link and record every exchange to MCAP (ROS 2) or CSV.
    ///
    /// The bridge sends cmd_vel (--v m/s, --w rad/s) in every exchange for --seconds (2000
    /// exchanges for 2 s), armed at the start if either is not 0 (else the drive stays disabled
    /// and the MCU's reports are recorded). --sim: the simulated board (the board application and
    /// a robot plant) in lockstep, one board millisecond per exchange, so the file is the same on
    /// every run. A device: /dev/spidevB.C at --speed Hz, paced at 1 kHz on wall time; afterwards
    /// 50 disarmed exchanges (not recorded) let the board ramp down before the silence brakes it.
    ///
    /// FILE.mcap (profile ros2, message encoding cdr, schema encoding ros2msg, uncompressed), one
    /// message per exchange on /cmd_vel (geometry_msgs/msg/Twist), /odom (nav_msgs/msg/Odometry:
    /// pose integrated from the encoders, twist from the measured wheel speeds; frames odom and
    /// base_link) and /joint_states (sensor_msgs/msg/JointState: wheel angle, speed, motor current
    /// in A as effort) for each valid feedback, /motorlink/frames (JSON, no schema: index,
    /// t_send_us, t_recv_us, tx and rx in hex); and every 100 exchanges /diagnostics
    /// (diagnostic_msgs/msg/DiagnosticArray: "motorlink: mcu" mode, fault flags by name, feedback
    /// age, sequence numbers; "motorlink: link" arming state and the bridge's diagnostics since the
    /// last one; "motorlink: clock" sync and offset). Times: the host time the feedback came in
    /// (UNIX time on a device; the board's clock from 0 in --sim).
    ///
    /// FILE.csv: a header line, then one row per exchange (command, feedback, mode and faults by
    /// name, odometry, arming state, clock sync, diagnostics; in --sim also the plant's truth).
    ///
    /// Last line on stdout: {"out":..,"exchanges":..,"feedback":..,"diagnostics":..}. Ctrl-C
    /// (SIGINT, SIGTERM, SIGHUP) ends the recording early with a complete file. Exit 64 on a bad
    /// argument (checked before the device is opened), 69 if the device cannot be opened, 74 on a
    /// failed exchange or write (the file is completed up to it).
    Record {
        /// spidev device of the AMR link (/dev/spidevB.C); none with --sim.
        device: Option<String>,
        /// Output file: .mcap or .csv.
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
        /// Record against the simulated board (lockstep, deterministic) instead of a device.
        #[arg(long)]
        sim: bool,
        /// SPI clock, Hz.
        #[arg(long, default_value_t = 2_000_000)]
        speed: u32,
        /// How long, s (1000 exchanges per second).
        #[arg(long, default_value_t = 10.0, allow_negative_numbers = true)]
        seconds: f64,
        /// cmd_vel forward speed, m/s.
        #[arg(long = "v", default_value_t = 0.0, allow_negative_numbers = true)]
        v: f64,
        /// cmd_vel yaw rate, rad/s.
        #[arg(long = "w", default_value_t = 0.0, allow_negative_numbers = true)]
        w: f64,
    },
    /// Measure the original Python 1 kHz loop and the Rust bridge loop side by side on this machine.
    ///
    /// In one invocation, one after the other, each for --seconds: first the original Jetson
    /// bridge's loop in Python (a script under host/scripts/, built into this binary and run
    /// with --python: a time.sleep(0.001)-paced loop doing the callback's work, the transfer answered by
    /// a fixed feedback frame), then the Rust bridge loop (absolute deadlines, the same work,
    /// against a device that answers at once) on its own bridge thread. One after the other, not
    /// at once: both loops on a shared machine at the same time would measure how they disturb
    /// each other (the Rust loop busy-waits before each deadline), not each loop. No device is
    /// needed.
    ///
    /// Per loop: periods, the share outside 1 ms +- 0.2 ms (the AMR SPI link's contract), skipped
    /// deadlines (a period of p ms leaves floor(p) - 1 deadlines without a command), the
    /// p50/p90/p99/p99.9/max period, and whether the loop kept the window; then the goal: Rust
    /// with at least 10x fewer periods outside the window than Python (compared by share, since
    /// the loops complete different numbers of periods). Exit 1 if the goal is not met, 69 if
    /// Python cannot be run (give --python or --rust-only).
    ///
    /// --rt: the bridge thread asks for SCHED_FIFO at --rt-priority and mlockall(MCL_CURRENT |
    /// MCL_FUTURE); --cpu N pins it to CPU N. Whatever is not permitted falls back with one
    /// warning on stderr each.
    LoopBench {
        /// How long each loop runs, s (above 0).
        #[arg(long, default_value_t = 60.0, allow_negative_numbers = true)]
        seconds: f64,
        /// Print one JSON object instead of the table.
        #[arg(long)]
        json: bool,
        /// Python interpreter for the original loop.
        #[arg(long, default_value = "python3")]
        python: String,
        /// Run only the Rust bridge loop (no comparison).
        #[arg(long)]
        rust_only: bool,
        #[command(flatten)]
        rt: RtArgs,
    },
    /// Run the ROS 2 node: cmd_vel into the 1 kHz bridge; odom, /tf, joint_states, /diagnostics out.
    ///
    /// Pure-Rust DDS (RustDDS): no ROS installation needed; ROS 2 tools on the same network and
    /// domain see the node. Subscribes `cmd_vel` (geometry_msgs/Twist, or TwistStamped with
    /// `topics.cmd_vel_stamped`); a command older than 200 ms is replaced by zero. Publishes `odom`
    /// (nav_msgs/Odometry), the odom -> base_link TF on `/tf`, `joint_states` and `/diagnostics`
    /// (mode, arming state, cmd_vel age, fault flags by name, link counters, clock sync). Services:
    /// `~/arm` and `~/estop` (std_srvs/SetBool), `~/disarm` and `~/rearm` (std_srvs/Trigger); each
    /// reply says what the MCU did. `battery_state` and `imu/data_raw` are not published: the AMR
    /// SPI feedback carries no battery or IMU data.
    ///
    /// Signals: SIGUSR1 stops every exchange (ESTOP: the MCU brakes on comm loss) and disarms,
    /// SIGUSR2 resumes them (still disarmed), SIGINT/SIGTERM disarm, send 50 frames with
    /// enable = 0 and exit. Parameters: a ROS 2 parameter file (example: host/ros/params.yaml).
    Ros {
        /// Parameter file (`<node name>: ros__parameters: {...}`); default: built-in defaults.
        #[arg(long)]
        params: Option<PathBuf>,
        /// Run against the simulated MCU (lockstep clock) instead of the device.
        #[arg(long)]
        sim: bool,
        /// spidev device; overrides the parameter `device`.
        #[arg(long)]
        device: Option<String>,
        /// Start the arming sequence at once (as a call of `~/arm` would).
        #[arg(long)]
        arm: bool,
        /// Do not ask for SCHED_FIFO on the bridge thread.
        #[arg(long)]
        no_realtime: bool,
        /// Check the parameter file, print the parameters as JSON and exit.
        #[arg(long)]
        check: bool,
    },
}

/// Real-time settings of a 1 kHz loop's thread (see `host/src/rt.rs`).
#[derive(Args)]
struct RtArgs {
    /// Ask for SCHED_FIFO (at --rt-priority) and mlockall for the 1 kHz loop's thread; each
    /// setting not permitted falls back with one warning.
    #[arg(long)]
    rt: bool,
    /// SCHED_FIFO priority with --rt, 1 to 99.
    #[arg(long, default_value_t = motorlink::rt::DEFAULT_PRIORITY)]
    rt_priority: i32,
    /// Pin the 1 kHz loop's thread to this CPU.
    #[arg(long)]
    cpu: Option<usize>,
}

impl RtArgs {
    /// The checked options (a usage error otherwise).
    fn options(&self) -> Result<motorlink::rt::RtOptions, Failure> {
        motorlink::rt::RtOptions::new(self.rt, self.rt_priority, self.cpu).or_exit(Exit::Usage)
    }
}

/// A duration from user input: negative or NaN is zero, too large is a year.
fn secs(s: f64) -> Duration {
    Duration::try_from_secs_f64(s.max(0.0)).unwrap_or(Duration::from_secs(365 * 24 * 3600))
}

/// A scenario error with its exit status: a file that cannot be read is missing input, the rest
/// is refused data.
fn scenario_failure(e: &scenario::ScenarioError) -> Failure {
    let exit = match e {
        scenario::ScenarioError::Io(..) => Exit::NoInput,
        _ => Exit::DataRefused,
    };
    Failure::new(exit, e.to_string())
}

fn load_scenarios(args: &[String]) -> Result<Vec<Scenario>, Failure> {
    if args.is_empty() {
        return scenario::builtin().map_err(|e| scenario_failure(&e));
    }
    args.iter()
        .map(|a| {
            if let Some((_, text)) = scenario::BUILTIN.iter().find(|(n, _)| n == a) {
                Scenario::from_toml(text, a).map_err(|e| scenario_failure(&e))
            } else if Path::new(a).exists() {
                Scenario::load(Path::new(a)).map_err(|e| scenario_failure(&e))
            } else {
                let names: Vec<&str> = scenario::BUILTIN.iter().map(|(n, _)| *n).collect();
                Err(Failure::new(
                    Exit::NoInput,
                    format!(
                        "'{a}' is neither a scenario file nor a built-in scenario ({})",
                        names.join(", ")
                    ),
                ))
            }
        })
        .collect()
}

fn run_sim(
    args: &[String],
    out: &Path,
    duration: Option<f64>,
    plots: bool,
) -> Result<bool, Failure> {
    if let Some(d) = duration {
        if !(d.is_finite() && d > 0.0) {
            return Err(Failure::usage(
                "--duration must be a positive number of seconds",
            ));
        }
    }
    // With --duration, what depends on a scenario's own duration is not judged (and said so).
    let runs: Vec<(Scenario, Vec<&str>, f64)> = load_scenarios(args)?
        .into_iter()
        .map(|sc| {
            let own = sc.duration_s;
            let (sc, not_judged) = match duration {
                Some(d) => sc.with_duration(d),
                None => (sc, Vec::new()),
            };
            (sc, not_judged, own)
        })
        .collect();
    std::fs::create_dir_all(out)
        .map_err(|e| format!("cannot create {}: {e}; choose another --out", out.display()))
        .or_exit(Exit::Io)?;
    let mut results = Vec::new();
    let mut unjudged = String::new();
    for (sc, not_judged, own) in &runs {
        if !not_judged.is_empty() {
            unjudged.push_str(&format!(
                "not judged {}: {} (they depend on the scenario's own duration, {own} s; this run: {} s)\n",
                sc.name,
                not_judged.join(", "),
                sc.duration_s
            ));
        }
        eprintln!(
            "running {} ({} s simulated): {}",
            sc.name, sc.duration_s, sc.description
        );
        let trace_path = out.join(format!("{}.csv", sc.name));
        let file = std::fs::File::create(&trace_path)
            .map_err(|e| format!("cannot write {}: {e}", trace_path.display()))
            .or_exit(Exit::Io)?;
        let mut w = std::io::BufWriter::new(file);
        let mut host = SimHost::new();
        let opts = sim::RunOptions {
            progress: true,
            keep_series: plots,
        };
        let r = sim::run(sc, &mut host, opts, Some(&mut w))
            .map_err(|e| format!("writing {}: {e}", trace_path.display()))
            .or_exit(Exit::Io)?;
        if plots {
            let svg = out.join(format!("{}.svg", sc.name));
            report::plot(&svg, &sc.name, &sc.description, &r)
                .map_err(|e| format!("plot {}: {e}", svg.display()))
                .or_exit(Exit::Io)?;
        }
        let failures = r.summary.check(sc);
        results.push((r.summary, failures));
    }
    let mut table = report::table(&results);
    table.push_str(&unjudged);
    print!("{table}");
    let write = |name: &str, text: &str| {
        let p = out.join(name);
        std::fs::write(&p, text)
            .map_err(|e| format!("cannot write {}: {e}", p.display()))
            .or_exit(Exit::Io)
    };
    write("summary.txt", &table)?;
    write("summary.csv", &report::csv(&results))?;
    out!(
        "\ntraces, plots and summary in {}/ (summary.txt, summary.csv, <scenario>.csv, <scenario>.svg)",
        out.display()
    );
    Ok(results.iter().all(|(_, f)| f.is_empty()))
}

fn open_spi(device: &str, speed: u32) -> Result<Box<dyn Transport>, Failure> {
    Ok(Box::new(
        SpiTransport::open(device, speed).or_exit(Exit::Unavailable)?,
    ))
}

fn open_serial(device: &str, baud: u32) -> Result<SerialTransport, Failure> {
    SerialTransport::open(device, baud, Duration::from_millis(20)).or_exit(Exit::Unavailable)
}

fn elapsed_ms(t0: Instant) -> u64 {
    u64::try_from(t0.elapsed().as_millis()).unwrap_or(u64::MAX)
}

/// USB CDC four-motor link: PING every 100 ms, print every received message with the ladder event it maps to.
fn monitor_cdc(device: &str, baud: u32, seconds: f64) -> Run {
    let mut link = CdcLink::new(open_serial(device, baud)?);
    // Bytes that arrived before this run are not news: drop them, so t_ms 0 is a fresh frame.
    link.discard_input().or_exit(Exit::Io)?;
    let t0 = Instant::now();
    let end = t0.checked_add(secs(seconds)).unwrap_or(t0);
    let mut last_ping: Option<Instant> = None;
    while Instant::now() < end {
        if last_ping.is_none_or(|t| t.elapsed() >= Duration::from_millis(100)) {
            link.send(&cdc::Message::Ping).or_exit(Exit::Io)?;
            last_ping = Some(Instant::now());
        }
        for m in link.poll().or_exit(Exit::Io)? {
            let event = m.to_event().map(|e| format!("{e:?}"));
            out!(
                "{}",
                serde_json::json!({"t_ms": elapsed_ms(t0), "message": cli::CdcJson::from(m), "event": event})
            );
        }
        for e in link.errors.drain(..) {
            out!(
                "{}",
                serde_json::json!({"t_ms": elapsed_ms(t0), "error": format!("{e:?}"), "code": e as u8,
                    "reason": format!("{:?}", e.reason()), "reason_code": e.reason() as u8})
            );
        }
    }
    let stats = link.stats();
    eprintln!("{}", serde_json::json!({"device": device, "stats": stats}));
    silence(device, seconds, u64::from(stats.frames))
}

/// The end of a monitor run: `frames` frames decoded in `seconds`; none is a warning and
/// [`Exit::Temporary`].
fn silence(device: &str, seconds: f64, frames: u64) -> Run {
    if frames > 0 {
        return Ok(Exit::Ok);
    }
    eprintln!(
        "warning: no frame from {device} in {seconds} s: check that the board runs and is connected, the link kind (--kind) and the baud rate"
    );
    Ok(Exit::Temporary)
}

/// Teensy serial link: listen and print every robust frame received. (The outer `Result` is the motor count's,
/// for `with_motors!`; it is checked before this runs.)
fn monitor_teensy<const N: usize>(device: &str, baud: u32, seconds: f64) -> Result<Run, String> {
    Ok(monitor_teensy_n::<N>(device, baud, seconds))
}

fn monitor_teensy_n<const N: usize>(device: &str, baud: u32, seconds: f64) -> Run {
    let mut link = TeensyLink::<_, N>::new(open_serial(device, baud)?);
    // Bytes that arrived before this run are not news: drop them, so t_ms 0 is a fresh frame.
    link.discard_input().or_exit(Exit::Io)?;
    let t0 = Instant::now();
    let end = t0.checked_add(secs(seconds)).unwrap_or(t0);
    while Instant::now() < end {
        for m in link.poll().or_exit(Exit::Io)? {
            out!(
                "{}",
                serde_json::json!({"t_ms": elapsed_ms(t0), "message": cli::CmdMsgJson::from(&m)})
            );
        }
        for r in link.errors.drain(..) {
            out!(
                "{}",
                serde_json::json!({"t_ms": elapsed_ms(t0), "reason": format!("{r:?}"), "reason_code": r as u8})
            );
        }
    }
    let stats = link.stats();
    eprintln!("{}", serde_json::json!({"device": device, "stats": stats}));
    silence(device, seconds, u64::from(stats.frames))
}

struct Boxed(Box<dyn Transport>);
impl Transport for Boxed {
    fn exchange(&mut self, tx: &[u8], rx: &mut [u8]) -> Result<(), motorlink::LinkError> {
        self.0.exchange(tx, rx)
    }
    fn name(&self) -> &str {
        self.0.name()
    }
}

/// The default `--speed` of a link kind: SPI 2 MHz, serial 115200 baud.
fn default_speed(kind: Kind) -> u32 {
    match kind {
        Kind::Spi | Kind::PiSpi => 2_000_000,
        Kind::Serial | Kind::Teensy => 115_200,
    }
}

/// What `monitor` was asked.
struct MonitorArgs<'a> {
    device: &'a str,
    kind: Kind,
    speed: Option<u32>,
    seconds: f64,
    hz: Option<f64>,
    count: Option<u64>,
    motors: usize,
    rt: &'a RtArgs,
}

/// `--motors`: 1 to the protocol's limit, checked before anything is opened.
fn check_motors(motors: usize) -> Result<(), Failure> {
    if (1..=protocol::teensy::MAX_MOTORS).contains(&motors) {
        Ok(())
    } else {
        Err(Failure::usage(format!(
            "--motors {motors} is not supported; give 1 to {} (protocol::teensy::MAX_MOTORS)",
            protocol::teensy::MAX_MOTORS
        )))
    }
}

/// `--seconds` of a run: above 0, finite, at most a day.
fn check_seconds(seconds: f64) -> Result<(), Failure> {
    if seconds.is_finite() && seconds > 0.0 && seconds <= device::MAX_SECONDS {
        Ok(())
    } else {
        Err(Failure::usage(format!(
            "--seconds {seconds}: give a duration above 0 and at most {} s",
            device::MAX_SECONDS
        )))
    }
}

fn monitor(a: &MonitorArgs<'_>) -> Run {
    let (device, kind, seconds, motors) = (a.device, a.kind, a.seconds, a.motors);
    let speed = a.speed.unwrap_or(default_speed(kind));
    if kind == Kind::PiSpi {
        if a.rt.rt || a.rt.cpu.is_some() {
            return Err(Failure::usage(
                "--rt and --cpu are for the 1 kHz loop of --kind spi",
            ));
        }
        let plan = pi::MonitorPlan::new(a.hz.unwrap_or(pi::DEFAULT_HZ), seconds, a.count)
            .or_exit(Exit::Usage)?;
        let mut dev = SpiTransport::open(device, speed).or_exit(Exit::Unavailable)?;
        let v = with_stop(|stop, sink| pi::run_monitor(&mut dev, &plan, stop, sink))
            .or_exit(Exit::Io)?;
        return Ok(v.into());
    }
    if a.hz.is_some() || a.count.is_some() {
        return Err(Failure::usage("--hz and --count are for --kind pi-spi"));
    }
    let rt = a.rt.options()?;
    if kind != Kind::Spi && rt != motorlink::rt::RtOptions::default() {
        return Err(Failure::usage(
            "--rt and --cpu are for the 1 kHz loop of --kind spi",
        ));
    }
    if kind == Kind::Spi {
        // This thread runs the 1 kHz bridge loop below.
        for w in motorlink::rt::apply(&rt).warnings {
            eprintln!("{w}");
        }
    }
    if kind == Kind::Teensy {
        check_motors(motors)?;
    }
    monitor_other(device, kind, speed, seconds, motors)
}

fn monitor_other(device: &str, kind: Kind, speed: u32, seconds: f64, motors: usize) -> Run {
    match kind {
        Kind::Spi | Kind::PiSpi => {}
        Kind::Serial => return monitor_cdc(device, speed, seconds),
        Kind::Teensy => {
            return motorlink::with_motors!(motors, monitor_teensy(device, speed, seconds))
                .or_exit(Exit::Usage)?;
        }
    }
    let t = open_spi(device, speed)?;
    let mut link = Link::new(Boxed(t), Bridge::new(BridgeConfig::DEFAULT));
    // Who answers: the first command asks for the MCU's identity (printed when it arrives).
    link.bridge.request_identity();
    let mut info = None;
    let mut last_print = 0u64;
    let end = std::time::Instant::now()
        .checked_add(secs(seconds))
        .unwrap_or_else(std::time::Instant::now);
    while std::time::Instant::now() < end {
        let diags = link.cycle().or_exit(Exit::Io)?;
        for (t, d) in diags {
            out!("{}", serde_json::json!({"t_us": t, "diagnostic": d}));
        }
        let now = link.now_us();
        if link.bridge.mcu_info() != info {
            info = link.bridge.mcu_info();
            out!("{}", serde_json::json!({"t_us": now, "mcu_info": info}));
        }
        if now.saturating_sub(last_print) >= 100_000 {
            last_print = now;
            if let Some(fb) = link.bridge.last_feedback {
                out!("{}", serde_json::json!({"t_us": now, "feedback": fb}));
            }
        }
    }
    eprintln!("loop: {}", link.pacer.stats.summary());
    let frames = link
        .bridge
        .stats
        .feedback_ok
        .saturating_add(link.bridge.stats.info_frames);
    silence(device, seconds, frames)
}

/// `record`: checks every argument before the device is opened.
fn record(
    device: Option<&str>,
    out: &Path,
    sim: bool,
    speed: u32,
    seconds: f64,
    (v, w): (f64, f64),
) -> Run {
    use motorlink::record::{self, Format, RecordConfig, RecordPlan};
    let plan = RecordPlan::new(seconds, v, w).map_err(|e| Failure::usage(e.to_string()))?;
    Format::from_path(out).map_err(|e| Failure::usage(e.to_string()))?;
    let summary = match (sim, device) {
        (true, None) => {
            let mut signals = pi::Signals::block().or_exit(Exit::Io)?;
            record::record_sim(out, &plan, RecordConfig::default(), &mut || {
                signals.received()
            })
        }
        (false, Some(dev)) => {
            let mut signals = pi::Signals::block().or_exit(Exit::Io)?;
            let t = open_spi(dev, speed)?;
            let mut link = Link::new(Boxed(t), Bridge::new(BridgeConfig::DEFAULT));
            let origin = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
            let cfg = RecordConfig {
                time_origin_ns: origin,
                ..RecordConfig::default()
            };
            record::record_link(&mut link, out, &plan, cfg, &mut || signals.received())
        }
        (true, Some(d)) => {
            return Err(Failure::usage(format!(
                "record: give a device or --sim, not both (got {d} and --sim)"
            )))
        }
        (false, None) => {
            return Err(Failure::usage(
                "record: give the AMR link's device (/dev/spidevB.C) or --sim",
            ))
        }
    }
    .map_err(|e| Failure::new(Exit::Io, e.to_string()))?;
    out!(
        "{}",
        serde_json::json!({
            "out": out.display().to_string(),
            "exchanges": summary.exchanges,
            "feedback": summary.feedback,
            "diagnostics": summary.diagnostics,
        })
    );
    Ok(Exit::Ok)
}

/// What `ping` was asked.
struct PingArgs<'a> {
    device: &'a str,
    kind: Kind,
    speed: Option<u32>,
    count: u32,
    wait: Duration,
    motors: usize,
}

fn ping(a: &PingArgs<'_>) -> Run {
    let (device, count) = (a.device, a.count);
    let speed = a.speed.unwrap_or(default_speed(a.kind));
    match a.kind {
        Kind::Spi => {}
        Kind::PiSpi => {
            let mut dev = SpiTransport::open(device, speed).or_exit(Exit::Unavailable)?;
            let v = pi::run_ping(&mut dev, count, &mut print_line).or_exit(Exit::Io)?;
            return Ok(v.into());
        }
        Kind::Serial => {
            let port = open_serial(device, speed)?;
            let v = device::run_cdc(port, &CdcVerb::Ping { count }, a.wait, &mut print_line)
                .or_exit(Exit::Io)?;
            return Ok(v.into());
        }
        Kind::Teensy => {
            check_motors(a.motors)?;
            let port = open_serial(device, speed)?;
            let verb = TeensyVerb::Ping { count };
            let v = device::run_teensy(port, a.motors, &verb, a.wait, &mut print_line)
                .or_exit(Exit::Io)?;
            return Ok(v.into());
        }
    }
    let t = open_spi(device, speed)?;
    let mut link = Link::new(Boxed(t), Bridge::new(BridgeConfig::DEFAULT));
    let mut rtts: Vec<u64> = Vec::new();
    for i in 0..count {
        let t0 = link.now_us();
        let r = link.cycle();
        let t1 = link.now_us();
        match r {
            Ok(_) => match link.bridge.last_feedback {
                Some(fb) => {
                    rtts.push(t1.saturating_sub(t0));
                    out!(
                        "{i}: {} us, MCU time {} us, mode {}, faults {:#06x}, offset estimate {:?} us",
                        t1.saturating_sub(t0),
                        fb.timestamp_us,
                        fb.mode,
                        fb.fault_flags,
                        link.bridge.clock.offset_at(t1 as f64).map(|o| o.round())
                    );
                }
                None => out!("{i}: reply did not decode (see diagnostics)"),
            },
            Err(e) => out!("{i}: {e}"),
        }
    }
    if let (Some(min), Some(max)) = (rtts.iter().min(), rtts.iter().max()) {
        let avg = rtts.iter().sum::<u64>() as f64 / rtts.len() as f64;
        out!(
            "round trip over {} of {count} exchanges: min {min} us, avg {avg:.0} us, max {max} us",
            rtts.len()
        );
    }
    if rtts.is_empty() {
        return Err(Failure::new(Exit::Unavailable, format!(
            "no valid reply from {device} in {count} exchanges: check wiring, SPI mode 0, and that the firmware runs"
        )));
    }
    Ok(Exit::Ok)
}

/// Prints one JSON line of a board verb.
fn print_line(v: Value) {
    out!("{v}");
}

/// Runs `verb` with a stop flag raised by SIGINT, SIGTERM, SIGHUP or a closed standard output, and a
/// sink that never exits the process: a paced Raspberry Pi SPI verb must end with its last buffer and line.
fn with_stop(
    verb: impl FnOnce(
        &mut dyn FnMut() -> bool,
        &mut dyn FnMut(Value),
    ) -> Result<device::Verdict, String>,
) -> Result<device::Verdict, String> {
    let mut signals = pi::Signals::block()?;
    let closed = std::cell::Cell::new(false);
    let mut sink = |v: Value| {
        use std::io::Write as _;
        if writeln!(std::io::stdout().lock(), "{v}").is_err() {
            closed.set(true);
        }
    };
    let mut stop = || closed.get() || signals.received();
    verb(&mut stop, &mut sink)
}

/// `drive --kind pi-spi`.
fn pi_drive(
    link: &SerialArgs,
    pwm_given: bool,
    args: &pi::PiDriveArgs,
    hz: Option<f64>,
    seconds: f64,
) -> Run {
    if pwm_given {
        return Err(Failure::usage("--pwm is the USB CDC four-motor drive's; for --kind pi-spi give --modes pwm --targets D (duty -399..=399); nothing was sent"));
    }
    let speed = args.speed.unwrap_or(default_speed(Kind::PiSpi));
    let hz = hz.unwrap_or(pi::DEFAULT_HZ);
    // The same check pi::drive makes before it opens the device: a bad argument is a usage error.
    pi::PiDrivePlan::new(args, hz, seconds).or_exit(Exit::Usage)?;
    let open_failed = std::cell::Cell::new(false);
    let open = || {
        SpiTransport::open(&link.device, speed).map_err(|e| {
            open_failed.set(true);
            e.to_string()
        })
    };
    match with_stop(|stop, sink| pi::drive(args, hz, seconds, open, stop, sink)) {
        Ok(v) => Ok(v.into()),
        Err(e) if open_failed.get() => Err(Failure::new(Exit::Unavailable, e)),
        Err(e) => Err(Failure::new(Exit::Io, e)),
    }
}

/// Checks that a verb's `--kind` is the protocol it speaks.
fn expect_kind(kind: Option<SerialKind>, want: SerialKind, instead: &str) -> Result<(), Failure> {
    match kind {
        Some(SerialKind::Spi) if want != SerialKind::Spi => Err(Failure::usage(NOT_AMR)),
        Some(SerialKind::PiSpi) if want != SerialKind::PiSpi => Err(Failure::usage(NOT_PI)),
        Some(k) if k != want => Err(Failure::usage(instead)),
        _ => Ok(()),
    }
}

/// Opens the device of a board verb and runs a USB CDC four-motor link verb on it.
fn cdc_verb(link: &SerialArgs, verb: &CdcVerb) -> Run {
    let port = open_serial(&link.device, link.baud)?;
    let wait = Duration::from_millis(link.wait_ms);
    let v = device::run_cdc(port, verb, wait, &mut print_line).or_exit(Exit::Io)?;
    Ok(v.into())
}

/// Opens the device of a board verb and runs a Teensy serial link verb on it.
fn teensy_verb(link: &SerialArgs, motors: usize, verb: &TeensyVerb) -> Run {
    check_motors(motors)?;
    let port = open_serial(&link.device, link.baud)?;
    let wait = Duration::from_millis(link.wait_ms);
    let v = device::run_teensy(port, motors, verb, wait, &mut print_line).or_exit(Exit::Io)?;
    Ok(v.into())
}

const NOT_TEENSY: &str =
    "this verb speaks the USB CDC four-motor link (--kind serial); for a Teensy serial link arm use move, cal, endeff, config";
const NOT_PI: &str =
    "the Raspberry Pi SPI link (--kind pi-spi) has the verbs ping, monitor and drive (ping and monitor never command the motors)";
const NOT_AMR: &str =
    "the AMR SPI link (--kind spi) has the verbs drive --v --w, estop, arm, disarm, rearm, teleop, top";
const NOT_SERIAL: &str =
    "this verb speaks the Teensy serial link (--kind teensy); for a USB CDC four-motor board use enable, estop, drive";

/// Runs one of the board verbs (everything but sim, decode, encode, monitor, ping, info, loop-bench).
fn board_verb(cmd: Cmd) -> Run {
    let on = |s: OnOff| matches!(s, OnOff::On);
    match cmd {
        Cmd::Enable { state, link } => {
            expect_kind(link.kind, SerialKind::Serial, NOT_TEENSY)?;
            cdc_verb(&link, &CdcVerb::Enable(on(state)))
        }
        Cmd::Estop {
            action,
            link,
            release,
            amr,
        } => {
            let word = |w: &str| match w {
                "engage" => Some(EstopArg::Engage),
                "release" => Some(EstopArg::Release),
                _ => None,
            };
            let mut link = link;
            let action = match action {
                Some(a) if word(&a).is_none() && link.device.is_none() => {
                    link.device = Some(a);
                    None
                }
                Some(a) => Some(word(&a).ok_or_else(|| {
                    Failure::usage(format!(
                        "estop: '{a}' is neither engage nor release; nothing was sent"
                    ))
                })?),
                None => None,
            };
            if amr.sim || link.kind == Some(SerialKind::Spi) {
                let release = release || matches!(action, Some(EstopArg::Release));
                let verb = if release {
                    amr_link::Verb::EstopRelease
                } else {
                    amr_link::Verb::Estop
                };
                return amr_link::exec(
                    verb,
                    link.device.as_deref(),
                    amr_link::DEFAULT_SPI_HZ,
                    &amr,
                );
            }
            let action = match (action, release) {
                (Some(a), _) => a,
                (None, true) => EstopArg::Release,
                (None, false) => return Err(Failure::usage("estop needs engage or release (USB CDC four-motor link), or --kind spi / --sim for the AMR SPI link")),
            };
            let link = link.serial()?;
            expect_kind(link.kind, SerialKind::Serial, NOT_TEENSY)?;
            let a = match action {
                EstopArg::Engage => Estop::Engage,
                EstopArg::Release => Estop::Release,
            };
            cdc_verb(&link, &CdcVerb::Estop(a))
        }
        Cmd::Drive {
            link,
            pwm,
            timeout_ms,
            hz,
            seconds,
            enable,
            pi,
            amr_v,
            amr_w,
            amr,
        } => {
            let amr_given = amr.sim || amr_v.is_some() || amr_w.is_some();
            if link.kind == Some(SerialKind::Spi) || (link.kind.is_none() && amr_given) {
                if pwm.is_some() || enable || hz.is_some() {
                    return Err(Failure::usage("--pwm, --enable and --hz are the serial drive's; the AMR link takes --v and --w; nothing was sent"));
                }
                if let Some(flag) = pi.first_given().filter(|f| *f != "--speed") {
                    return Err(Failure::usage(format!("{flag} is an option of drive --kind pi-spi; the AMR link takes --v and --w; nothing was sent")));
                }
                if amr_v.is_none() && amr_w.is_none() {
                    return Err(Failure::usage(
                        "drive on the AMR link needs --v (m/s) and/or --w (rad/s), e.g. --v 0.3",
                    ));
                }
                let verb = amr_link::Verb::Drive {
                    v: amr_v.unwrap_or(0.0),
                    w: amr_w.unwrap_or(0.0),
                    seconds,
                };
                let speed = pi.speed.unwrap_or(amr_link::DEFAULT_SPI_HZ);
                return amr_link::exec(verb, link.device.as_deref(), speed, &amr);
            }
            if amr_given {
                return Err(Failure::usage(
                    "--v, --w and --sim are the AMR link's (--kind spi); nothing was sent",
                ));
            }
            let link = link.serial()?;
            if link.kind == Some(SerialKind::PiSpi) {
                return pi_drive(&link, pwm.is_some(), &pi, hz, seconds);
            }
            expect_kind(link.kind, SerialKind::Serial, NOT_TEENSY)?;
            if let Some(flag) = pi.first_given() {
                return Err(Failure::usage(format!("{flag} is an option of drive --kind pi-spi; this is a USB CDC four-motor drive (--kind serial): give --pwm")));
            }
            let pwm = pwm.ok_or_else(|| Failure::usage("drive --kind serial needs --pwm: the duties of motors 1 to 4, e.g. --pwm 300,-300,0,0"))?;
            let pwm = device::parse_list(&pwm, "--pwm").or_exit(Exit::Usage)?;
            let plan = DrivePlan::new(&pwm, timeout_ms, hz.unwrap_or(50.0), seconds, enable)
                .or_exit(Exit::Usage)?;
            cdc_verb(&link, &CdcVerb::Drive(plan))
        }
        Cmd::Move {
            link,
            angles,
            speed,
            cal,
            once,
            relative,
            hz,
            seconds,
            motors,
        } => {
            expect_kind(link.kind, SerialKind::Teensy, NOT_SERIAL)?;
            check_motors(motors)?;
            let angles = device::parse_list(&angles, "--angles").or_exit(Exit::Usage)?;
            let plan = MovePlan::new(&angles, motors, speed, relative, hz, seconds, once, cal)
                .or_exit(Exit::Usage)?;
            teensy_verb(&link, motors, &TeensyVerb::Move(plan))
        }
        Cmd::Cal { link, motors } => {
            expect_kind(link.kind, SerialKind::Teensy, NOT_SERIAL)?;
            teensy_verb(&link, motors, &TeensyVerb::Cal)
        }
        Cmd::Endeff {
            state,
            link,
            motors,
        } => {
            expect_kind(link.kind, SerialKind::Teensy, NOT_SERIAL)?;
            teensy_verb(&link, motors, &TeensyVerb::Endeff(on(state)))
        }
        Cmd::Config {
            link,
            accel,
            motors,
        } => {
            expect_kind(link.kind, SerialKind::Teensy, NOT_SERIAL)?;
            teensy_verb(
                &link,
                motors,
                &TeensyVerb::Config {
                    accel_deg_s2: accel,
                },
            )
        }
        Cmd::SendHex {
            link,
            hex,
            listen_ms,
            motors,
        } => {
            let h = SendHex {
                bytes: cli::parse_hex(&hex).or_exit(Exit::Usage)?,
                listen: Duration::from_millis(listen_ms),
            };
            match link.kind.unwrap_or(SerialKind::Serial) {
                SerialKind::Serial => cdc_verb(&link, &CdcVerb::SendHex(h)),
                SerialKind::Teensy => teensy_verb(&link, motors, &TeensyVerb::SendHex(h)),
                SerialKind::PiSpi => Err(Failure::usage(NOT_PI)),
                SerialKind::Spi => Err(Failure::usage(NOT_AMR)),
            }
        }
        Cmd::List { json } => amr_link::exec_list(json),
        Cmd::Arm { link } => amr_link::exec(
            amr_link::Verb::Arm,
            link.device.as_deref(),
            link.speed,
            &link.opts,
        ),
        Cmd::Rearm { link } => amr_link::exec(
            amr_link::Verb::Rearm,
            link.device.as_deref(),
            link.speed,
            &link.opts,
        ),
        Cmd::Top { link, seconds } => amr_link::exec_tui(
            None,
            link.device.as_deref(),
            link.speed,
            &link.opts,
            seconds,
        ),
        Cmd::Teleop {
            link,
            max_v,
            max_w,
            hold_ms,
            seconds,
        } => amr_link::exec_tui(
            Some(amr_link::teleop::TeleopConfig {
                max_v,
                max_w,
                hold_us: hold_ms.saturating_mul(1000),
                ..amr_link::teleop::TeleopConfig::DEFAULT
            }),
            link.device.as_deref(),
            link.speed,
            &link.opts,
            seconds,
        ),
        Cmd::Disarm { link, seconds } => amr_link::exec(
            amr_link::Verb::Disarm(seconds),
            link.device.as_deref(),
            link.speed,
            &link.opts,
        ),
        _ => Err(Failure::usage("internal: not a board verb")),
    }
}

fn info(
    capture: Option<&Path>,
    device: Option<&str>,
    speed: u32,
    timeout_ms: u32,
    json: bool,
) -> Run {
    let text = if let Some(path) = capture {
        let bytes = std::fs::read(path)
            .map_err(|e| format!("cannot read {}: {e}", path.display()))
            .or_exit(Exit::NoInput)?;
        cli::info::info_capture(&path.display().to_string(), &bytes, json)
            .or_exit(Exit::DataRefused)?
    } else if let Some(device) = device {
        let mut spi = SpiTransport::open(device, speed).or_exit(Exit::Unavailable)?;
        let mut pacer = Pacer::contract();
        let t0 = Instant::now();
        // A start that differs from run to run; the query moves past the MCU's last accepted seq anyway.
        let first_seq = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(1, |d| d.subsec_nanos() | 1);
        let exchanges = usize::try_from(timeout_ms.max(1)).unwrap_or(usize::MAX);
        cli::info::info_live(&mut spi, first_seq, exchanges, json, || {
            pacer.wait();
            u32::try_from(t0.elapsed().as_micros() & u128::from(u32::MAX)).unwrap_or(0)
        })
        .or_exit(Exit::Unavailable)?
    } else {
        return Err(Failure::usage(
            "give --capture FILE or --device /dev/spidevX.Y",
        ));
    };
    out!("{text}");
    Ok(Exit::Ok)
}

/// The hex argument of `decode`: as given, or `-` for everything on standard input.
fn hex_argument(hex: String) -> Result<String, String> {
    if hex != "-" {
        return Ok(hex);
    }
    let mut text = String::new();
    std::io::Read::read_to_string(&mut std::io::stdin().lock(), &mut text)
        .map_err(|e| format!("cannot read the hex from standard input: {e}"))?;
    if text.trim().is_empty() {
        return Err("standard input held no hex digits; pipe the bytes in hex, e.g. `echo aa55... | motorlink decode --frame cdc -`".into());
    }
    Ok(text)
}

/// The original loop, as the CLI runs it (`python3 - SECONDS` with this on standard input).
const SEED_LOOP_PY: &str = include_str!("../scripts/seed_loop.py");

/// One loop's result in `loop-bench`.
struct Measured {
    name: &'static str,
    stats: LoopStats,
    extra: Value,
}

/// Runs the original Python loop for `seconds` and returns its periods, µs.
fn python_loop(python: &str, seconds: f64) -> Result<Vec<f64>, Failure> {
    use std::io::Write as _;
    let mut child = std::process::Command::new(python)
        .arg("-")
        .arg(seconds.to_string())
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .map_err(|e| {
            Failure::new(
                Exit::Unavailable,
                format!("cannot run {python}: {e}; give --python PATH, or --rust-only"),
            )
        })?;
    if let Some(mut stdin) = child.stdin.take() {
        stdin
            .write_all(SEED_LOOP_PY.as_bytes())
            .map_err(|e| format!("cannot hand the loop to {python}: {e}"))
            .or_exit(Exit::Io)?;
    }
    let out = child
        .wait_with_output()
        .map_err(|e| format!("{python} failed: {e}"))
        .or_exit(Exit::Io)?;
    if !out.status.success() {
        return Err(Failure::new(
            Exit::Unavailable,
            format!(
                "{python} ended with {}; give --python PATH, or --rust-only",
                out.status
            ),
        ));
    }
    let v: Value = serde_json::from_slice(&out.stdout)
        .map_err(|e| format!("the Python loop printed no JSON: {e}"))
        .or_exit(Exit::Io)?;
    Ok(v.get("periods_us")
        .and_then(Value::as_array)
        .map(|a| a.iter().filter_map(Value::as_f64).collect())
        .unwrap_or_default())
}

/// Runs the Rust bridge loop for `seconds` on its own thread with `rt`; returns the real-time
/// report, the periods (µs) and the pacer's own skipped-deadline count.
fn rust_loop(
    seconds: f64,
    rt: motorlink::rt::RtOptions,
) -> Result<(motorlink::rt::RtReport, Vec<f64>, u64), Failure> {
    let bridge = std::thread::Builder::new()
        .name("bridge".into())
        .spawn(move || {
            let report = motorlink::rt::apply(&rt);
            for w in &report.warnings {
                eprintln!("{w}");
            }
            // The same work as on the robot (IK, encode, decode, checks), against a device that
            // answers a valid feedback frame at once.
            let mut reply = [0u8; FRAME_LEN];
            amr::encode_feedback(&MotorFeedback::default(), &mut reply);
            let mut link = Link::new(
                NullTransport {
                    reply: reply.to_vec(),
                },
                Bridge::new(BridgeConfig::DEFAULT),
            );
            link.pacer = Pacer::contract();
            let expected = (seconds * 1000.0).ceil() as usize;
            link.pacer
                .keep_periods(expected.saturating_add(expected / 10));
            link.run_for(secs(seconds), |_| {})
                .map_err(|e| e.to_string())?;
            let skipped = link.pacer.stats.skipped;
            Ok::<_, String>((report, std::mem::take(&mut link.pacer.periods), skipped))
        })
        .map_err(|e| format!("cannot start the bridge thread: {e}"))
        .or_exit(Exit::Io)?;
    bridge
        .join()
        .map_err(|_| Failure::new(Exit::Io, "the bridge thread panicked"))?
        .or_exit(Exit::Io)
}

fn loop_bench(seconds: f64, json: bool, python: &str, rust_only: bool, rt: &RtArgs) -> Run {
    check_seconds(seconds)?;
    let rt = rt.options()?;
    let mut loops = Vec::new();
    if !rust_only {
        eprintln!("loop-bench: the Python loop for {seconds} s ...");
        let periods = python_loop(python, seconds)?;
        let stats = LoopStats::from_periods(&periods)
            .ok_or_else(|| Failure::new(Exit::Io, "the Python loop measured no period"))?;
        loops.push(Measured {
            name: "python-sleep-1ms",
            stats,
            extra: serde_json::json!({"paced_by": "time.sleep(0.001) after the work"}),
        });
    }
    eprintln!("loop-bench: the Rust bridge loop for {seconds} s ...");
    let (report, periods, pacer_skipped) = rust_loop(seconds, rt)?;
    let stats = LoopStats::from_periods(&periods)
        .ok_or_else(|| Failure::new(Exit::Io, "the Rust loop measured no period"))?;
    loops.push(Measured {
        name: "rust-absolute-deadline",
        stats,
        extra: serde_json::json!({"paced_by": "absolute 1 ms deadlines (sleep, then spin the last 150 us)",
            "pacer_skipped_deadlines": pacer_skipped, "rt": report}),
    });
    let goal = match loops.as_slice() {
        [py, rs] => Some(loopstats::goal(&py.stats, &rs.stats)),
        _ => None,
    };
    let order: Vec<&str> = loops.iter().map(|m| m.name).collect();
    if json {
        let list: Vec<Value> = loops
            .iter()
            .map(|m| {
                serde_json::json!({"impl": m.name, "stats": m.stats,
                    "keeps_window": m.stats.keeps_window(), "details": m.extra})
            })
            .collect();
        out!(
            "{}",
            serde_json::json!({"seconds_each": seconds, "mode": "sequential", "order": order,
                "why_sequential": SEQUENTIAL_WHY,
                "window_us": {"nominal": loopstats::NOMINAL_US, "tolerance": loopstats::TOLERANCE_US},
                "loops": list, "goal_factor": loopstats::GOAL_FACTOR, "goal": goal})
        );
    } else {
        out!(
            "loop-bench: {seconds} s each, one after the other ({}), window {} +- {} us",
            order.join(", then "),
            loopstats::NOMINAL_US,
            loopstats::TOLERANCE_US
        );
        out!(
            "{:<24} {:>8} {:>18} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9}  window",
            "loop",
            "periods",
            "outside",
            "skipped",
            "p50 us",
            "p90 us",
            "p99 us",
            "p99.9 us",
            "max us"
        );
        for m in &loops {
            let s = &m.stats;
            out!(
                "{:<24} {:>8} {:>8} ({:>6.3} %) {:>8} {:>8.1} {:>8.1} {:>8.1} {:>8.1} {:>9.1}  {}",
                m.name,
                s.periods,
                s.outside,
                100.0 * s.outside_share,
                s.skipped_deadlines,
                s.p50_us,
                s.p90_us,
                s.p99_us,
                s.p999_us,
                s.max_us,
                if s.keeps_window() { "kept" } else { "missed" }
            );
        }
        let verdict = match goal {
            None => "not judged (--rust-only)".to_string(),
            Some(Goal::Met { factor: Some(f) }) => format!("met ({f:.1}x fewer by share)"),
            Some(Goal::Met { factor: None }) => "met (Rust had no period outside)".into(),
            Some(Goal::NotMet { factor: Some(f) }) => format!("NOT met ({f:.2}x)"),
            Some(Goal::NotMet { factor: None }) => "NOT met".into(),
            Some(Goal::NotMeasurable) => "not measurable (neither loop left the window)".into(),
        };
        out!(
            "goal: Rust >= {}x fewer periods outside the window than Python: {verdict}",
            loopstats::GOAL_FACTOR
        );
        out!("why one after the other: {SEQUENTIAL_WHY}");
    }
    Ok(match goal {
        Some(Goal::NotMet { .. }) => Exit::Failed,
        _ => Exit::Ok,
    })
}

/// Why `loop-bench` runs the loops one after the other.
const SEQUENTIAL_WHY: &str = "at the same time the two loops would share this machine's cores (the Rust loop busy-waits before each deadline, the Python one burns CPU in its callback) and measure how they disturb each other; one after the other, each meets the same machine alone";

/// `decode`: the frame (or capture) as JSON; a capture without a frame is refused data.
fn decode(frame: FrameKind, hex: String, motors: usize) -> Run {
    if is_teensy(frame) {
        check_motors(motors)?;
    }
    let hex = hex_argument(hex).or_exit(Exit::Io)?;
    let d = cli::decode_report(frame, &hex, motors).or_exit(Exit::DataRefused)?;
    out!("{}", d.json);
    match d.no_frame {
        None => Ok(Exit::Ok),
        Some(why) => Err(Failure::data(why)),
    }
}

/// `encode`: the JSON message as a frame in hex.
fn encode(frame: FrameKind, json: &str, motors: usize) -> Run {
    if is_teensy(frame) {
        check_motors(motors)?;
    }
    let hex = cli::encode(frame, json, motors).or_exit(Exit::DataRefused)?;
    out!("{hex}");
    Ok(Exit::Ok)
}

/// The frame kinds whose size depends on `--motors`.
fn is_teensy(frame: FrameKind) -> bool {
    matches!(frame, FrameKind::TeensyLegacy | FrameKind::TeensyRobust)
}

/// `sim`: the scenarios' table; exit 1 if an expectation failed.
fn sim_verb(
    scenarios: &[String],
    out: &Path,
    duration: Option<f64>,
    no_plots: bool,
    list: bool,
) -> Run {
    if list {
        for (n, text) in scenario::BUILTIN {
            let d = Scenario::from_toml(text, n)
                .map(|s| s.description)
                .unwrap_or_default();
            out!("{n:20} {d}");
        }
        return Ok(Exit::Ok);
    }
    if run_sim(scenarios, out, duration, !no_plots)? {
        Ok(Exit::Ok)
    } else {
        eprintln!("some scenario expectations failed (see FAIL lines above)");
        Ok(Exit::Failed)
    }
}

/// Parses the command line; a usage error exits 64 (clap's own would be 2), help and version 0.
fn parse() -> Result<Cli, ExitCode> {
    Cli::try_parse().map_err(|e| {
        let _ = e.print();
        if e.use_stderr() {
            ExitCode::from(Exit::Usage.code())
        } else {
            ExitCode::SUCCESS
        }
    })
}

/// What `ros` was asked.
struct RosArgs<'a> {
    params: Option<&'a Path>,
    sim: bool,
    device: Option<String>,
    arm: bool,
    realtime: bool,
    check: bool,
}

fn ros_node(a: &RosArgs<'_>) -> Run {
    use motorlink::ros;
    // Before any thread starts: every thread inherits the blocked signals.
    let signals = ros::block_signals().or_exit(Exit::Io)?;
    let file = match a.params {
        Some(p) if !p.exists() => {
            return Err(Failure::new(
                Exit::NoInput,
                format!("{}: no such parameter file", p.display()),
            ))
        }
        Some(p) => {
            ros::params::load(p).map_err(|e| Failure::new(Exit::DataRefused, e.to_string()))?
        }
        None => ros::ParamFile {
            node_name: ros::params::DEFAULT_NODE_NAME.into(),
            params: ros::Params::default(),
        },
    };
    let mut params = file.params;
    if let Some(d) = &a.device {
        params.device.clone_from(d);
    }
    if a.check {
        out!(
            "{}",
            serde_json::json!({"node_name": file.node_name, "params": params})
        );
        return Ok(Exit::Ok);
    }
    let (transport, hardware_id): (Box<dyn ros::NodeTransport + Send>, String) = if a.sim {
        // The simulated robot has the parameters' geometry and encoders.
        let mut cfg = SimConfig::new(SimClock::Lockstep);
        cfg.plant.wheel_radius_m = params.geometry.wheel_radius_m;
        cfg.plant.wheelbase_m = params.geometry.wheelbase_m;
        cfg.plant.counts_per_rev = params.geometry.encoder_counts_per_rev;
        let sim = SimMcu::new(cfg).map_err(|e| Failure::new(Exit::DataRefused, e.to_string()))?;
        (Box::new(sim), "sim (lockstep)".into())
    } else {
        let t = SpiTransport::open(&params.device, params.spi_hz).or_exit(Exit::Unavailable)?;
        (Box::new(t), params.device.clone())
    };
    let setup = ros::node_setup(file.node_name, params, hardware_id, a.arm, a.realtime);
    ros::run(&setup, transport, signals)
        .map(|()| Exit::Ok)
        .or_exit(Exit::Io)
}

fn main() -> ExitCode {
    let cli = match parse() {
        Ok(cli) => cli,
        Err(code) => return code,
    };
    let r: Run = match cli.cmd {
        Cmd::Sim {
            scenarios,
            out,
            duration,
            no_plots,
            list,
        } => sim_verb(&scenarios, &out, duration, no_plots, list),
        Cmd::Decode { frame, hex, motors } => decode(frame, hex, motors),
        Cmd::Encode {
            frame,
            json,
            motors,
        } => encode(frame, &json, motors),
        Cmd::Monitor {
            device,
            kind,
            speed,
            seconds,
            hz,
            count,
            motors,
            rt,
        } => monitor(&MonitorArgs {
            device: &device,
            kind,
            speed,
            seconds,
            hz,
            count,
            motors,
            rt: &rt,
        }),
        Cmd::Ping {
            device,
            kind,
            speed,
            count,
            wait_ms,
            motors,
        } => ping(&PingArgs {
            device: &device,
            kind,
            speed,
            count,
            wait: Duration::from_millis(wait_ms),
            motors,
        }),
        Cmd::Info {
            capture,
            device,
            speed,
            timeout_ms,
            json,
        } => info(
            capture.as_deref(),
            device.as_deref(),
            speed,
            timeout_ms,
            json,
        ),
        Cmd::LoopBench {
            seconds,
            json,
            python,
            rust_only,
            rt,
        } => loop_bench(seconds, json, &python, rust_only, &rt),
        Cmd::Record {
            device,
            out,
            sim,
            speed,
            seconds,
            v,
            w,
        } => record(device.as_deref(), &out, sim, speed, seconds, (v, w)),
        Cmd::Ros {
            params,
            sim,
            device,
            arm,
            no_realtime,
            check,
        } => ros_node(&RosArgs {
            params: params.as_deref(),
            sim,
            device,
            arm,
            realtime: !no_realtime,
            check,
        }),
        verb => board_verb(verb),
    };
    match r {
        Ok(exit) => ExitCode::from(exit.code()),
        Err(f) => {
            eprintln!("error: {}", f.message);
            ExitCode::from(f.exit.code())
        }
    }
}

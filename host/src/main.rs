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
use motorlink::cli::device::{self, CdcVerb, DrivePlan, MovePlan, SendHex, TeensyVerb};
use motorlink::cli::pi;
use motorlink::cli::{self, FrameKind};
use motorlink::link::Link;
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
    about = "Host side of the AMR motor controller: simulator, frame tools, device monitor, serial board verbs, and the Raspberry Pi SPI verbs of seed 004 (ping, monitor, drive --kind pi-spi)"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Kind {
    /// Linux spidev (seed 000), 2 MHz mode 0.
    Spi,
    /// Serial / USB CDC speaking seed 001 (`AA 55` frames): PING, IMU, STATUS, ACK.
    Serial,
    /// Serial to a Teensy speaking seed 003 robust frames (COBS + CRC); monitor only listens.
    Teensy,
    /// Raspberry Pi spidev to the STM32's SPI2 (seed 004): 179-byte full-duplex transfers, 2 MHz mode 0.
    PiSpi,
}

/// The serial link kinds of the board verbs.
#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum SerialKind {
    /// Seed 001 (`AA 55` frames): ping, enable, estop, drive, send-hex.
    Serial,
    /// Seed 003 robust frames: ping, move, cal, endeff, config, send-hex.
    Teensy,
    /// Seed 004 over spidev (the device is /dev/spidevB.C): drive (and ping, monitor).
    PiSpi,
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
  0  done: the board answered and did it (ACK result 0, echo cmd_success 1, replies came)
  1  refused by the board (ACK result != 0, echo cmd_success 0)
  2  error: bad argument (nothing is sent), the device cannot be opened, an I/O error
  3  no reply within --wait-ms

The device is opened exclusively in raw mode; bytes that arrived before the open are dropped, so
each run sees only replies to itself. Several runs in sequence on one pty (QEMU -serial pty) work.";

#[derive(Subcommand)]
enum Cmd {
    /// Run the built-in scenarios (or the given scenario files) and write traces, table and plots.
    Sim {
        /// Scenario files (TOML) or built-in names; default: every built-in scenario.
        scenarios: Vec<String>,
        /// Output directory.
        #[arg(long, default_value = "out/sim")]
        out: PathBuf,
        /// Override each scenario's duration, s.
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
        /// The bytes in hex (e.g. from a logic-analyser capture).
        hex: String,
        /// Motors in a seed 003 CmdMsg (MAX_SUPPORTED_MTRS), 1 to 16.
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
        /// Motors in a seed 003 CmdMsg (MAX_SUPPORTED_MTRS), 1 to 16.
        #[arg(long, default_value_t = cli::DEFAULT_MOTORS)]
        motors: usize,
    },
    /// Run the 1 kHz bridge disarmed against a device and print feedback and diagnostics.
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
        /// Motors in a seed 003 CmdMsg (--kind teensy).
        #[arg(long, default_value_t = cli::DEFAULT_MOTORS)]
        motors: usize,
    },
    /// Exchange a few frames with a device and report round trips.
    ///
    /// --kind spi: seed 000 command/feedback exchanges, with the MCU time and the clock offset
    /// (text lines). --kind serial: PING, answered by a STATUS (or an ACK of PING). --kind teensy:
    /// ENDEFF_OFF, answered by its echo (seed 003 has no probe message; switching the end effector
    /// off is the safe, idempotent round trip, but it does switch it off). Serial kinds print JSON
    /// lines: {"ping":i,"round_trip_us":..,"reply":{..}} or {"ping":i,"no_reply_ms":..}, then the
    /// verdict with the round-trip statistics; exit status 3 if nothing answered.
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
        /// Motors in a seed 003 CmdMsg (--kind teensy).
        #[arg(long, default_value_t = cli::DEFAULT_MOTORS)]
        motors: usize,
    },
    /// Seed 001: MOTOR_ENABLE on|off, wait for its ACK (exit 1 if the board refuses it).
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
    /// Seed 001: ESTOP engage|release, wait for its ACK.
    ///
    /// engage latches BRAKE at once. release clears this link's ESTOP; the board stays braked
    /// until re-armed (`drive --enable`). Last line as for `enable` (msg_id 3).
    #[command(after_long_help = VERB_HELP)]
    Estop {
        /// engage or release.
        #[arg(value_enum)]
        action: EstopArg,
        #[command(flatten)]
        link: SerialArgs,
    },
    /// Seed 001: send SET_MOTOR_PWM at a fixed rate for a while, then stop sending.
    ///
    /// Frames go out on absolute deadlines (--hz; the first at once) for --seconds; every STATUS,
    /// IMU and ACK received is printed. Then nothing more is sent: the board brakes on its own
    /// within --timeout-ms. The arguments are checked before the device is opened: |pwm| <= 1000,
    /// timeout from one frame period to 65535 ms, 0 < hz <= 1000.
    ///
    /// --enable: MOTOR_ENABLE 1 right after the first frame, its ACK awaited while the frames keep
    /// coming (the board keeps a re-arm only until the first frame, at most 249 ms); refused: stop sending, exit 1;
    /// no ACK within --wait-ms: stop sending, exit 3.
    ///
    /// First line {"sending":{..},"frames":..,"hz":..,"enable":..}; last line {"verdict":..,
    /// "frames_sent":..,"enable":{"reply":..,"round_trip_us":..}|null,"received":{"status":..,
    /// "status_motor_enabled":..,"status_estop_latched":..,"imu":..,"ack":..,"other":..,"errors":..,
    /// "last_status":{..}},"decoder":{..},"pacing":{..},"stopped_early":..}. Exit 3 also if a drive
    /// of 0.2 s or more received no valid frame at all (the board sends STATUS every 100 ms).
    ///
    /// --kind pi-spi (seed 004, device /dev/spidevB.C): one transfer with the motor shutdown bit
    /// set and every motor OFF (carrying the one-shot updates --odom-reset, --kinematics,
    /// --pid-speed, each sent exactly once), then the command buffer (--modes, --targets, --goals,
    /// --servo-modes, --servo-pos; shutdown bits clear: the bit's 1->0 edge is the board's re-arm)
    /// at --hz (default 100) for --seconds, then one buffer with both shutdown bits set and every
    /// motor OFF; that last buffer is also sent on Ctrl-C (SIGINT, SIGTERM, SIGHUP) and after a
    /// failed transfer. Arguments are checked before the device is opened (exit 2): an enabled
    /// servo's position must be 600..=2600, a pwm duty within +-399, --hz above 20.4 (the board
    /// brakes 49 ms after the last valid transfer). Lines: {"sending":{..},..}, then
    /// {"transfer":k,"tx":{..}} (every --every-th) or {"transfer":k,"error":..}, last
    /// {"verdict":..,"transfers":{"arm","command","shutdown"},"commanded":[..],"moved":[..],
    /// "decoded":..,"errors":..,"update_time":{..},"stale":..,"pacing":{..},"interrupted":..}.
    /// Verdict: no_reply (exit 3) if update_time never advanced (no TxBuffer decoded, or a stale
    /// board); refused (exit 1) if commands ran for 0.2 s or more, some motor was commanded to move
    /// and none of those changed motor.position; done (exit 0) otherwise.
    #[command(after_long_help = VERB_HELP)]
    Drive {
        #[command(flatten)]
        link: SerialArgs,
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
    },
    /// Seed 003: MTRS to absolute angles at a fixed rate (or once), checking every echo.
    ///
    /// Every echo must come back with cmd_success 1: a refusal stops the sending at once (exit 1),
    /// an echo missing --wait-ms after its command stops it too (exit 3). cmd_success 1 means the
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
    /// Seed 003: CAL, the explicit re-arm; wait for its echo.
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
    /// Seed 003: ENDEFF_ON / ENDEFF_OFF, wait for the echo.
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
    /// Seed 003: CONFIG, the joints' acceleration; wait for the echo (refused above the board's limit).
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
        /// Motors in a seed 003 CmdMsg (--kind teensy), 1 to 16.
        #[arg(long, default_value_t = cli::DEFAULT_MOTORS)]
        motors: usize,
    },
    /// Print the MCU's firmware identity and reset cause (seed 000 McuInfo), from a capture or live.
    ///
    /// --capture FILE reads a binary file of concatenated 64-byte MISO frames (one per CS-low period,
    /// as a logic analyser or spidev records them) and prints every McuInfo frame in it. --device
    /// asks the MCU: it sends commands with request = 1 and the drive disabled (enable 0, speeds 0,
    /// mode 0), one per millisecond, until an McuInfo comes back or --timeout-ms passes. Exit status
    /// 2 with the reason if none is found.
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
    /// Measure the 1 kHz loop's period and deadline misses on this machine (no device needed).
    LoopBench {
        /// How long, s.
        #[arg(long, default_value_t = 60.0)]
        seconds: f64,
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

/// A duration from user input: negative or NaN is zero, too large is a year.
fn secs(s: f64) -> Duration {
    Duration::try_from_secs_f64(s.max(0.0)).unwrap_or(Duration::from_secs(365 * 24 * 3600))
}

fn load_scenarios(args: &[String]) -> Result<Vec<Scenario>, String> {
    if args.is_empty() {
        return scenario::builtin().map_err(|e| e.to_string());
    }
    args.iter()
        .map(|a| {
            if let Some((_, text)) = scenario::BUILTIN.iter().find(|(n, _)| n == a) {
                Scenario::from_toml(text, a).map_err(|e| e.to_string())
            } else if Path::new(a).exists() {
                Scenario::load(Path::new(a)).map_err(|e| e.to_string())
            } else {
                let names: Vec<&str> = scenario::BUILTIN.iter().map(|(n, _)| *n).collect();
                Err(format!(
                    "'{a}' is neither a scenario file nor a built-in scenario ({})",
                    names.join(", ")
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
) -> Result<bool, String> {
    let mut scenarios = load_scenarios(args)?;
    if let Some(d) = duration {
        if !(d.is_finite() && d > 0.0) {
            return Err("--duration must be a positive number of seconds".into());
        }
        for s in &mut scenarios {
            s.duration_s = d;
        }
    }
    std::fs::create_dir_all(out)
        .map_err(|e| format!("cannot create {}: {e}; choose another --out", out.display()))?;
    let mut results = Vec::new();
    for sc in &scenarios {
        eprintln!(
            "running {} ({} s simulated): {}",
            sc.name, sc.duration_s, sc.description
        );
        let trace_path = out.join(format!("{}.csv", sc.name));
        let file = std::fs::File::create(&trace_path)
            .map_err(|e| format!("cannot write {}: {e}", trace_path.display()))?;
        let mut w = std::io::BufWriter::new(file);
        let mut host = SimHost::new();
        let opts = sim::RunOptions {
            progress: true,
            keep_series: plots,
        };
        let r = sim::run(sc, &mut host, opts, Some(&mut w))
            .map_err(|e| format!("writing {}: {e}", trace_path.display()))?;
        if plots {
            let svg = out.join(format!("{}.svg", sc.name));
            report::plot(
                &svg,
                &format!("{}: {}", sc.name, short(&sc.description)),
                &r,
            )
            .map_err(|e| format!("plot {}: {e}", svg.display()))?;
        }
        let failures = r.summary.check(sc);
        results.push((r.summary, failures));
    }
    let table = report::table(&results);
    print!("{table}");
    let write = |name: &str, text: &str| {
        let p = out.join(name);
        std::fs::write(&p, text).map_err(|e| format!("cannot write {}: {e}", p.display()))
    };
    write("summary.txt", &table)?;
    write("summary.csv", &report::csv(&results))?;
    out!(
        "\ntraces, plots and summary in {}/ (summary.txt, summary.csv, <scenario>.csv, <scenario>.svg)",
        out.display()
    );
    Ok(results.iter().all(|(_, f)| f.is_empty()))
}

fn short(s: &str) -> String {
    let first = s.split(". ").next().unwrap_or(s);
    first.chars().take(90).collect()
}

fn open_spi(device: &str, speed: u32) -> Result<Box<dyn Transport>, String> {
    Ok(Box::new(
        SpiTransport::open(device, speed).map_err(|e| e.to_string())?,
    ))
}

fn open_serial(device: &str, baud: u32) -> Result<SerialTransport, String> {
    SerialTransport::open(device, baud, Duration::from_millis(20)).map_err(|e| e.to_string())
}

fn elapsed_ms(t0: Instant) -> u64 {
    u64::try_from(t0.elapsed().as_millis()).unwrap_or(u64::MAX)
}

/// Seed 001: PING every 100 ms, print every received message with the ladder event it maps to.
fn monitor_cdc(device: &str, baud: u32, seconds: f64) -> Result<(), String> {
    let mut link = CdcLink::new(open_serial(device, baud)?);
    let t0 = Instant::now();
    let end = t0.checked_add(secs(seconds)).unwrap_or(t0);
    let mut last_ping: Option<Instant> = None;
    while Instant::now() < end {
        if last_ping.is_none_or(|t| t.elapsed() >= Duration::from_millis(100)) {
            link.send(&cdc::Message::Ping).map_err(|e| e.to_string())?;
            last_ping = Some(Instant::now());
        }
        for m in link.poll().map_err(|e| e.to_string())? {
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
    eprintln!(
        "{}",
        serde_json::json!({"device": device, "stats": link.stats()})
    );
    Ok(())
}

/// Seed 003: listen and print every robust frame received.
fn monitor_teensy<const N: usize>(device: &str, baud: u32, seconds: f64) -> Result<(), String> {
    let mut link = TeensyLink::<_, N>::new(open_serial(device, baud)?);
    let t0 = Instant::now();
    let end = t0.checked_add(secs(seconds)).unwrap_or(t0);
    while Instant::now() < end {
        for m in link.poll().map_err(|e| e.to_string())? {
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
    eprintln!(
        "{}",
        serde_json::json!({"device": device, "stats": link.stats()})
    );
    Ok(())
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
}

fn monitor(a: &MonitorArgs<'_>) -> Result<u8, String> {
    let (device, kind, seconds, motors) = (a.device, a.kind, a.seconds, a.motors);
    let speed = a.speed.unwrap_or(default_speed(kind));
    if kind == Kind::PiSpi {
        let plan = pi::MonitorPlan::new(a.hz.unwrap_or(pi::DEFAULT_HZ), seconds, a.count)?;
        let mut dev = SpiTransport::open(device, speed).map_err(|e| e.to_string())?;
        let v = with_stop(|stop, sink| pi::run_monitor(&mut dev, &plan, stop, sink))?;
        return Ok(v.exit_code());
    }
    if a.hz.is_some() || a.count.is_some() {
        return Err("--hz and --count are for --kind pi-spi".into());
    }
    monitor_other(device, kind, speed, seconds, motors).map(|()| 0)
}

fn monitor_other(
    device: &str,
    kind: Kind,
    speed: u32,
    seconds: f64,
    motors: usize,
) -> Result<(), String> {
    match kind {
        Kind::Spi | Kind::PiSpi => {}
        Kind::Serial => return monitor_cdc(device, speed, seconds),
        Kind::Teensy => {
            return match motors {
                1 => monitor_teensy::<1>(device, speed, seconds),
                2 => monitor_teensy::<2>(device, speed, seconds),
                3 => monitor_teensy::<3>(device, speed, seconds),
                4 => monitor_teensy::<4>(device, speed, seconds),
                6 => monitor_teensy::<6>(device, speed, seconds),
                8 => monitor_teensy::<8>(device, speed, seconds),
                n => Err(format!("--motors {n}: monitor supports 1, 2, 3, 4, 6, 8")),
            }
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
        let diags = link.cycle().map_err(|e| e.to_string())?;
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
    Ok(())
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

fn ping(a: &PingArgs<'_>) -> Result<u8, String> {
    let (device, count) = (a.device, a.count);
    let speed = a.speed.unwrap_or(default_speed(a.kind));
    match a.kind {
        Kind::Spi => {}
        Kind::PiSpi => {
            let mut dev = SpiTransport::open(device, speed).map_err(|e| e.to_string())?;
            return Ok(pi::run_ping(&mut dev, count, &mut print_line)?.exit_code());
        }
        Kind::Serial => {
            let port = open_serial(device, speed)?;
            let v = device::run_cdc(port, &CdcVerb::Ping { count }, a.wait, &mut print_line)?;
            return Ok(v.exit_code());
        }
        Kind::Teensy => {
            let port = open_serial(device, speed)?;
            let verb = TeensyVerb::Ping { count };
            let v = device::run_teensy(port, a.motors, &verb, a.wait, &mut print_line)?;
            return Ok(v.exit_code());
        }
    }
    let t = open_spi(device, speed)?;
    let mut link = Link::new(Boxed(t), Bridge::new(BridgeConfig::DEFAULT));
    let mut ok = 0u32;
    for i in 0..count {
        let t0 = link.now_us();
        let r = link.cycle();
        let t1 = link.now_us();
        match r {
            Ok(_) => match link.bridge.last_feedback {
                Some(fb) => {
                    ok = ok.saturating_add(1);
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
    if ok == 0 {
        return Err(format!(
            "no valid reply from {device} in {count} exchanges: check wiring, SPI mode 0, and that the firmware runs"
        ));
    }
    Ok(0)
}

/// Prints one JSON line of a board verb.
fn print_line(v: Value) {
    out!("{v}");
}

/// Runs `verb` with a stop flag raised by SIGINT, SIGTERM, SIGHUP or a closed standard output, and a
/// sink that never exits the process: a paced seed 004 verb must end with its last buffer and line.
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
) -> Result<u8, String> {
    if pwm_given {
        return Err("--pwm is the seed 001 drive's; for --kind pi-spi give --modes pwm --targets D (duty -399..=399); nothing was sent".into());
    }
    let speed = args.speed.unwrap_or(default_speed(Kind::PiSpi));
    let open = || SpiTransport::open(&link.device, speed).map_err(|e| e.to_string());
    let hz = hz.unwrap_or(pi::DEFAULT_HZ);
    let v = with_stop(|stop, sink| pi::drive(args, hz, seconds, open, stop, sink))?;
    Ok(v.exit_code())
}

/// Checks that a verb's `--kind` is the protocol it speaks.
fn expect_kind(kind: Option<SerialKind>, want: SerialKind, instead: &str) -> Result<(), String> {
    match kind {
        Some(SerialKind::PiSpi) if want != SerialKind::PiSpi => Err(NOT_PI.into()),
        Some(k) if k != want => Err(instead.to_string()),
        _ => Ok(()),
    }
}

/// Opens the device of a board verb and runs a seed 001 verb on it.
fn cdc_verb(link: &SerialArgs, verb: &CdcVerb) -> Result<u8, String> {
    let port = open_serial(&link.device, link.baud)?;
    let wait = Duration::from_millis(link.wait_ms);
    Ok(device::run_cdc(port, verb, wait, &mut print_line)?.exit_code())
}

/// Opens the device of a board verb and runs a seed 003 verb on it.
fn teensy_verb(link: &SerialArgs, motors: usize, verb: &TeensyVerb) -> Result<u8, String> {
    let port = open_serial(&link.device, link.baud)?;
    let wait = Duration::from_millis(link.wait_ms);
    Ok(device::run_teensy(port, motors, verb, wait, &mut print_line)?.exit_code())
}

const NOT_TEENSY: &str =
    "this verb speaks seed 001 (--kind serial); for a seed 003 arm use move, cal, endeff, config";
const NOT_PI: &str =
    "seed 004 (--kind pi-spi) has the verbs ping, monitor and drive (ping and monitor never command the motors)";
const NOT_SERIAL: &str =
    "this verb speaks seed 003 (--kind teensy); for a seed 001 board use enable, estop, drive";

/// Runs one of the board verbs (everything but sim, decode, encode, monitor, ping, info, loop-bench).
fn board_verb(cmd: Cmd) -> Result<u8, String> {
    let on = |s: OnOff| matches!(s, OnOff::On);
    match cmd {
        Cmd::Enable { state, link } => {
            expect_kind(link.kind, SerialKind::Serial, NOT_TEENSY)?;
            cdc_verb(&link, &CdcVerb::Enable(on(state)))
        }
        Cmd::Estop { action, link } => {
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
        } => {
            if link.kind == Some(SerialKind::PiSpi) {
                return pi_drive(&link, pwm.is_some(), &pi, hz, seconds);
            }
            expect_kind(link.kind, SerialKind::Serial, NOT_TEENSY)?;
            if let Some(flag) = pi.first_given() {
                return Err(format!("{flag} is an option of drive --kind pi-spi; this is a seed 001 drive (--kind serial): give --pwm"));
            }
            let pwm = pwm.ok_or("drive --kind serial needs --pwm: the duties of motors 1 to 4, e.g. --pwm 300,-300,0,0")?;
            let pwm = device::parse_list(&pwm, "--pwm")?;
            let plan = DrivePlan::new(&pwm, timeout_ms, hz.unwrap_or(50.0), seconds, enable)?;
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
            let angles = device::parse_list(&angles, "--angles")?;
            let plan = MovePlan::new(&angles, motors, speed, relative, hz, seconds, once, cal)?;
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
                bytes: cli::parse_hex(&hex)?,
                listen: Duration::from_millis(listen_ms),
            };
            match link.kind.unwrap_or(SerialKind::Serial) {
                SerialKind::Serial => cdc_verb(&link, &CdcVerb::SendHex(h)),
                SerialKind::Teensy => teensy_verb(&link, motors, &TeensyVerb::SendHex(h)),
                SerialKind::PiSpi => Err(NOT_PI.into()),
            }
        }
        _ => Err("internal: not a board verb".into()),
    }
}

fn info(
    capture: Option<&Path>,
    device: Option<&str>,
    speed: u32,
    timeout_ms: u32,
    json: bool,
) -> Result<(), String> {
    let text = if let Some(path) = capture {
        cli::info::info_capture_file(path, json)?
    } else if let Some(device) = device {
        let mut spi = SpiTransport::open(device, speed).map_err(|e| e.to_string())?;
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
        })?
    } else {
        return Err("give --capture FILE or --device /dev/spidevX.Y".into());
    };
    out!("{text}");
    Ok(())
}

fn loop_bench(seconds: f64) -> Result<(), String> {
    // The same work as on the robot (IK, encode, decode, checks), against a device that answers
    // a valid feedback frame instantly.
    let mut reply = [0u8; FRAME_LEN];
    amr::encode_feedback(&MotorFeedback::default(), &mut reply);
    let mut link = Link::new(
        NullTransport {
            reply: reply.to_vec(),
        },
        Bridge::new(BridgeConfig::DEFAULT),
    );
    link.pacer = Pacer::contract();
    link.run_for(secs(seconds), |_| {})
        .map_err(|e| e.to_string())?;
    let s = &link.pacer.stats;
    out!("{}", s.summary());
    out!(
        "{}",
        serde_json::json!({"impl": "rust-absolute-deadline", "seconds": seconds, "periods": s.count,
            "misses": s.misses, "miss_rate": s.miss_rate(), "mean_us": s.mean_us(), "std_us": s.std_us(),
            "min_us": s.min_us, "max_us": s.max_us, "skipped": s.skipped})
    );
    Ok(())
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

fn ros_node(a: &RosArgs<'_>) -> Result<u8, String> {
    use motorlink::ros;
    // Before any thread starts: every thread inherits the blocked signals.
    let signals = ros::block_signals()?;
    let file = match a.params {
        Some(p) => ros::params::load(p).map_err(|e| e.to_string())?,
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
        return Ok(0);
    }
    let (transport, hardware_id): (Box<dyn ros::NodeTransport + Send>, String) = if a.sim {
        // The simulated robot has the parameters' geometry and encoders.
        let mut cfg = SimConfig::new(SimClock::Lockstep);
        cfg.plant.wheel_radius_m = params.geometry.wheel_radius_m;
        cfg.plant.wheelbase_m = params.geometry.wheelbase_m;
        cfg.plant.counts_per_rev = params.geometry.encoder_counts_per_rev;
        let sim = SimMcu::new(cfg).map_err(|e| e.to_string())?;
        (Box::new(sim), "sim (lockstep)".into())
    } else {
        let t = SpiTransport::open(&params.device, params.spi_hz).map_err(|e| e.to_string())?;
        (Box::new(t), params.device.clone())
    };
    let setup = ros::node_setup(file.node_name, params, hardware_id, a.arm, a.realtime);
    ros::run(&setup, transport, signals).map(|()| 0)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let r: Result<u8, String> = match cli.cmd {
        Cmd::Sim {
            scenarios,
            out,
            duration,
            no_plots,
            list,
        } => {
            if list {
                for (n, text) in scenario::BUILTIN {
                    let d = Scenario::from_toml(text, n)
                        .map(|s| s.description)
                        .unwrap_or_default();
                    out!("{n:20} {d}");
                }
                Ok(0)
            } else {
                run_sim(&scenarios, &out, duration, !no_plots).map(|ok| {
                    if !ok {
                        eprintln!("some scenario expectations failed (see FAIL lines above)");
                    }
                    u8::from(!ok)
                })
            }
        }
        Cmd::Decode { frame, hex, motors } => cli::decode(frame, &hex, motors).map(|s| {
            out!("{s}");
            0
        }),
        Cmd::Encode {
            frame,
            json,
            motors,
        } => cli::encode(frame, &json, motors).map(|s| {
            out!("{s}");
            0
        }),
        Cmd::Monitor {
            device,
            kind,
            speed,
            seconds,
            hz,
            count,
            motors,
        } => monitor(&MonitorArgs {
            device: &device,
            kind,
            speed,
            seconds,
            hz,
            count,
            motors,
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
        )
        .map(|()| 0),
        Cmd::LoopBench { seconds } => loop_bench(seconds).map(|()| 0),
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
        Ok(code) => ExitCode::from(code),
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(device::EXIT_ERROR)
        }
    }
}

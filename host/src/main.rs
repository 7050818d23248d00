//! `motorlink`: run the simulator, decode/encode frames, monitor and ping a real MCU.

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

use clap::{Parser, Subcommand, ValueEnum};
use motorlink::bridge::{Bridge, BridgeConfig};
use motorlink::cli::{self, FrameKind};
use motorlink::link::Link;
use motorlink::pacing::Pacer;
use motorlink::serial::{CdcLink, TeensyLink};
use motorlink::transport::{NullTransport, SerialTransport, SpiTransport, Transport};
use motorlink::SimHost;
use protocol::amr::{self, MotorFeedback, FRAME_LEN};
use protocol::cdc;
use sim::report;
use sim::scenario::{self, Scenario};

#[derive(Parser)]
#[command(
    name = "motorlink",
    version,
    about = "Host side of the AMR motor controller: simulator, frame tools, device monitor"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Clone, Copy, ValueEnum)]
enum Kind {
    /// Linux spidev (seed 000), 2 MHz mode 0.
    Spi,
    /// Serial / USB CDC speaking seed 001 (`AA 55` frames): PING, IMU, STATUS, ACK.
    Serial,
    /// Serial to a Teensy speaking seed 003 robust frames (COBS + CRC); monitor only listens.
    Teensy,
}

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
    Monitor {
        /// Device path (/dev/spidev0.0 or /dev/ttyACM0).
        device: String,
        /// Link kind.
        #[arg(long, value_enum, default_value = "spi")]
        kind: Kind,
        /// SPI clock (Hz) or baud rate.
        #[arg(long, default_value_t = 2_000_000)]
        speed: u32,
        /// How long, s.
        #[arg(long, default_value_t = 5.0)]
        seconds: f64,
        /// Motors in a seed 003 CmdMsg (--kind teensy).
        #[arg(long, default_value_t = cli::DEFAULT_MOTORS)]
        motors: usize,
    },
    /// Exchange a few frames with a device and report round trip and clock offset.
    Ping {
        /// Device path.
        device: String,
        /// Link kind.
        #[arg(long, value_enum, default_value = "spi")]
        kind: Kind,
        /// SPI clock (Hz) or baud rate.
        #[arg(long, default_value_t = 2_000_000)]
        speed: u32,
        /// Exchanges.
        #[arg(long, default_value_t = 10)]
        count: u32,
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

fn ping_cdc(device: &str, baud: u32, count: u32) -> Result<(), String> {
    let mut link = CdcLink::new(open_serial(device, baud)?);
    let mut ok = 0u32;
    for i in 0..count {
        match link.ping(Duration::from_millis(200)) {
            Ok(r) => {
                ok = ok.saturating_add(1);
                out!(
                    "{i}: {} us, reply {}",
                    r.round_trip.as_micros(),
                    serde_json::json!(cli::CdcJson::from(r.reply))
                );
            }
            Err(e) => out!("{i}: {e}"),
        }
    }
    eprintln!("{}", serde_json::json!({"stats": link.stats()}));
    if ok == 0 {
        return Err(format!(
            "no ACK or STATUS from {device} in {count} PINGs: check the baud rate and that the firmware speaks seed 001"
        ));
    }
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

fn monitor(
    device: &str,
    kind: Kind,
    speed: u32,
    seconds: f64,
    motors: usize,
) -> Result<(), String> {
    match kind {
        Kind::Spi => {}
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

fn ping(device: &str, kind: Kind, speed: u32, count: u32) -> Result<(), String> {
    match kind {
        Kind::Spi => {}
        Kind::Serial => return ping_cdc(device, speed, count),
        Kind::Teensy => {
            return Err(
                "ping speaks seed 001 (--kind serial) or seed 000 (--kind spi); a Teensy has no probe message: use monitor --kind teensy".into(),
            )
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
    Ok(())
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

fn main() -> ExitCode {
    let cli = Cli::parse();
    let r = match cli.cmd {
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
                Ok(true)
            } else {
                run_sim(&scenarios, &out, duration, !no_plots)
            }
        }
        Cmd::Decode { frame, hex, motors } => cli::decode(frame, &hex, motors).map(|s| {
            out!("{s}");
            true
        }),
        Cmd::Encode {
            frame,
            json,
            motors,
        } => cli::encode(frame, &json, motors).map(|s| {
            out!("{s}");
            true
        }),
        Cmd::Monitor {
            device,
            kind,
            speed,
            seconds,
            motors,
        } => monitor(&device, kind, speed, seconds, motors).map(|()| true),
        Cmd::Ping {
            device,
            kind,
            speed,
            count,
        } => ping(&device, kind, speed, count).map(|()| true),
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
        .map(|()| true),
        Cmd::LoopBench { seconds } => loop_bench(seconds).map(|()| true),
    };
    match r {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => {
            eprintln!("some scenario expectations failed (see FAIL lines above)");
            ExitCode::FAILURE
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}

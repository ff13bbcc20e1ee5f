//! `ddct log`: decode, record, replay and convert bus logs (candump text or MDF 4).

mod convert;
mod decode;

use super::args::{open_can, Source};
use super::{announce_ready, runtime, shutdown_signal};
use anyhow::{bail, Context};
use clap::Subcommand;
use ddct::can::candump::{LogError, LogReader, LogRecord, LogWriter};
use ddct::can::decode::LogDecoder;
use ddct::can::log::record::record as record_frames;
use ddct::can::logfile::{self, LogFormat};
use ddct::can::replay::{self, Pace};
use ddct::can::Bus;
use decode::{decode, wall_clock, Format};
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

#[derive(Debug, Subcommand)]
pub enum LogCmd {
    /// Decode a candump log with the DBC, with the E2E verdict of every frame. On a terminal,
    /// a progress bar on stderr (a spinner with the frame count for standard input).
    Decode {
        /// The log (`-` for standard input): `candump -l` / `-L` lines, or candump's screen
        /// output (`candump vcan0`, `-t a`, `-x`, `-a`), whose lines without a time are stamped
        /// as they are read (`candump vcan0 | ddct log decode -`).
        file: PathBuf,
        /// Output format.
        #[arg(long, value_enum, default_value_t = Format::Table)]
        format: Format,
        /// Only frames of these messages (names or ids like 0x130); repeatable.
        #[arg(long = "message", short = 'm')]
        messages: Vec<String>,
        /// No `gap:` notice per message that fell silent (the E2E summary stays).
        #[arg(long, short = 'q')]
        quiet: bool,
        /// Decode with this DBC file instead of the built-in contract (dbc/ddct.dbc): every
        /// message of it, Intel and Motorola signals, value tables, multiplexing. The E2E
        /// verdict is computed only for the contract's E2E messages with the same id and signal
        /// layout, `n/a` for the others; `-m` takes this DBC's names and ids.
        #[arg(long, value_name = "FILE")]
        dbc: Option<PathBuf>,
        /// Write the output to this file instead of standard output (required for Parquet).
        #[arg(
            long,
            short = 'o',
            value_name = "FILE",
            required_if_eq("format", "parquet")
        )]
        out: Option<PathBuf>,
    },
    /// A live view of the bus: per message the latest decoded values (states, gears and fault
    /// codes by name), frames, rate, age of the last frame and E2E errors; redrawn four times a
    /// second on a terminal, printed once at the end otherwise.
    Monitor {
        /// Where to listen, as candump takes it: a CAN interface (`vcan0`), a candump log or
        /// candump's screen output, or `-` for standard input (`candump vcan0 | ddct log
        /// monitor -`). A name that is neither an existing file nor an existing interface is
        /// refused with what to do.
        #[arg(conflicts_with = "iface", required_unless_present = "iface")]
        source: Option<std::ffi::OsString>,
        /// The CAN interface, as a flag (the same as giving it positionally).
        #[arg(long)]
        iface: Option<String>,
        /// Stop after this many seconds (default: until SIGINT/SIGTERM or the end of the input).
        #[arg(long, value_parser = super::args::seconds)]
        duration: Option<Duration>,
    },
    /// Cycle-time statistics per message of a candump -l log (p50/p99/min/max intervals).
    Stats {
        /// The candump -l log file.
        file: PathBuf,
        /// JSON instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Record every frame of a SocketCAN interface into a candump -l log; at exit, the frames
    /// per id and those the kernel dropped because the receive queue was full.
    Record {
        /// CAN interface, e.g. vcan0 (positional like candump's, or as `--iface`).
        #[arg(
            value_parser = super::args::can_iface,
            conflicts_with = "iface",
            required_unless_present = "iface"
        )]
        interface: Option<String>,
        /// The CAN interface, as a flag (the same as giving it positionally).
        #[arg(long, value_parser = super::args::can_iface)]
        iface: Option<String>,
        /// Output log file.
        #[arg(long)]
        out: PathBuf,
        /// Stop after this many frames.
        #[arg(long)]
        count: Option<u64>,
        /// Stop after this many seconds.
        #[arg(long, value_parser = super::args::seconds)]
        duration: Option<Duration>,
        /// Once the socket is open and the signal handlers installed, write the pid to this file
        /// (a bench script waits for it before the traffic starts).
        #[arg(long)]
        ready_file: Option<PathBuf>,
    },
    /// Send the frames of a candump -l log on a SocketCAN interface, at the log's own timing
    /// (absolute deadlines from the first frame) unless `--max-rate`; on a terminal, a progress
    /// bar on stderr.
    Replay {
        /// The candump -l log file.
        file: PathBuf,
        /// CAN interface, e.g. vcan0.
        #[arg(long)]
        iface: String,
        /// Play the log's timing this many times faster (0.5: half speed).
        #[arg(long, default_value_t = 1.0, value_parser = parse_speed, conflicts_with = "max_rate")]
        speed: f64,
        /// Ignore the log's timing: send as fast as the interface takes the frames.
        #[arg(long)]
        max_rate: bool,
        /// With `--max-rate`: at least this many microseconds between frames.
        #[arg(long, default_value_t = 0, requires = "max_rate")]
        interval_us: u64,
        /// Play the log this many times; each pass starts one median frame interval after the
        /// last frame of the one before.
        #[arg(long = "loop", default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
        passes: u32,
    },
    /// Convert a log between candump `-l` text (`.log`), MDF 4 bus logging (`.mf4`), CSV
    /// (`.csv`) and Parquet (`.parquet`), the output's format taken from its extension (the
    /// input, candump text or MDF 4, is recognised by content). CSV and Parquet hold one row
    /// per decoded signal as `ddct log decode` writes them, or one per frame with `--frames`.
    Convert {
        /// The log to read: candump `-l` text or an MDF 4 file.
        input: PathBuf,
        /// The file to write (`.log`, `.mf4`, `.csv` or `.parquet`); written beside it first and
        /// renamed into place when complete.
        output: PathBuf,
        /// CSV and Parquet: one row per frame (time_s, iface, id, extended, remote, dlc, data)
        /// instead of one per decoded signal.
        #[arg(long)]
        frames: bool,
    },
    /// Plot chosen signals of a candump log over time (an SVG; speeds and other numbers share a
    /// panel per unit, states and gears as labelled lanes, fault codes marked, dropouts left
    /// open), optionally overlaid (dashed) on the lockstep simulation of the scenario the run
    /// played. Time counts from the plant's first DCT_Sensors frame in both.
    Plot {
        /// The log: candump `-l`/`-L` lines or candump's screen output.
        file: PathBuf,
        /// Signals to draw, `Signal` or `Message.Signal`; repeatable (default: engine and input
        /// shaft speeds, clutch 1 torque and its reference, clutch 1 position and its request,
        /// TCU state and gear).
        #[arg(long = "signal", short = 's')]
        signals: Vec<String>,
        /// Overlay the lockstep simulation of this scenario (e.g. the one `ddct bench` ran).
        #[arg(long)]
        sim: Option<PathBuf>,
        /// TCU calibration of the simulation (default: the built-in one).
        #[arg(long, requires = "sim")]
        config: Option<PathBuf>,
        /// The SVG file to write (default: the log's name with `.svg`).
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

pub fn run(cmd: LogCmd) -> anyhow::Result<ExitCode> {
    match cmd {
        LogCmd::Decode {
            file,
            format,
            messages,
            quiet,
            dbc,
            out,
        } => decode(
            &file,
            format,
            &messages,
            quiet,
            dbc.as_deref(),
            out.as_deref(),
        ),
        LogCmd::Stats { file, json } => stats(&file, json),
        LogCmd::Convert {
            input,
            output,
            frames,
        } => convert::convert(&input, &output, frames),
        LogCmd::Plot {
            file,
            signals,
            sim,
            config,
            out,
        } => plot(&file, &signals, sim.as_deref(), config.as_deref(), out),
        LogCmd::Monitor {
            source,
            iface,
            duration,
        } => {
            let source = match (source, iface) {
                (_, Some(i)) => Source::Iface(i),
                (Some(s), None) => Source::resolve(&s).map_err(anyhow::Error::msg)?,
                (None, None) => bail!("ddct log monitor: give an interface, a log file or -"),
            };
            monitor(&source, duration)
        }
        LogCmd::Record {
            interface,
            iface,
            out,
            count,
            duration,
            ready_file,
        } => {
            let Some(iface) = interface.or(iface) else {
                bail!("ddct log record: give the CAN interface, e.g. `ddct log record vcan0`")
            };
            record(&iface, &out, count, duration, ready_file.as_deref())
        }
        LogCmd::Replay {
            file,
            iface,
            speed,
            max_rate,
            interval_us,
            passes,
        } => {
            let pace = if max_rate {
                Pace::MaxRate { interval_us }
            } else {
                Pace::Log { speed }
            };
            replay(&file, &iface, pace, passes)
        }
    }
}

fn open_input(file: &PathBuf) -> anyhow::Result<Box<dyn BufRead>> {
    if file.as_os_str() == "-" {
        return Ok(Box::new(BufReader::new(std::io::stdin())));
    }
    let f = File::open(file).with_context(|| format!("{}", file.display()))?;
    Ok(Box::new(BufReader::new(f)))
}

/// Every frame of an MDF file, a candump log or candump's screen output (`-`: standard input);
/// the first malformed line is an error.
fn read_any_format(file: &PathBuf) -> anyhow::Result<Vec<LogRecord>> {
    if file.as_os_str() != "-" && logfile::detect(file)? == LogFormat::Mf4 {
        return Ok(logfile::read_all(file)?);
    }
    let mut records = Vec::new();
    for item in LogReader::any_format(open_input(file)?, Box::new(wall_clock)) {
        match item {
            Ok(r) => records.push(r),
            Err(LogError::Line { line, kind }) => bail!("{}:{line}: {kind}", file.display()),
            Err(LogError::InputLost { line, frames }) => eprintln!(
                "{}:{line}: the logger lost {frames} frame(s) here (DROPCOUNT)",
                file.display()
            ),
            Err(e) => return Err(e).with_context(|| format!("{}", file.display())),
        }
    }
    Ok(records)
}

fn plot(
    file: &PathBuf,
    signals: &[String],
    sim: Option<&std::path::Path>,
    config: Option<&std::path::Path>,
    out: Option<PathBuf>,
) -> anyhow::Result<ExitCode> {
    use ddct::sim::logplot::{self, SignalRef};
    let names: Vec<&str> = if signals.is_empty() {
        logplot::DEFAULT_SIGNALS.to_vec()
    } else {
        signals.iter().map(String::as_str).collect()
    };
    let wanted = names
        .iter()
        .map(|n| SignalRef::parse(n).with_context(|| format!("--signal {n}")))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let records = read_any_format(file)?;
    if records.is_empty() {
        bail!("{}: no frame in the log", file.display());
    }
    let bus = logplot::traces(records.iter().map(|r| (r.timestamp, &r.frame)), &wanted);
    let (sim_traces, title) = match sim {
        Some(path) => {
            let cfg = super::args::tcu_config(config)?;
            let sc = ddct::sim::SimScenario::load(path)?;
            let pb = super::spinner(format!("simulating {} ({} s)", sc.name, sc.duration_s));
            let run = ddct::sim::run_scenario(&sc, &cfg, &ddct::sim::SimOptions::default());
            pb.finish_and_clear();
            let t = logplot::traces(run.frames.iter().map(|(t, f)| (*t, f)), &wanted);
            (
                Some(t),
                format!(
                    "{} (solid) and the lockstep simulation of {} (dashed)",
                    file.display(),
                    sc.name
                ),
            )
        }
        None => (None, file.display().to_string()),
    };
    let out = out.unwrap_or_else(|| file.with_extension("svg"));
    let svg = logplot::figure(&title, &bus, sim_traces.as_ref());
    std::fs::write(&out, &svg).with_context(|| format!("writing {}", out.display()))?;
    println!("wrote {} ({} kB)", out.display(), svg.len().div_ceil(1000));
    Ok(ExitCode::SUCCESS)
}

fn stats(file: &std::path::Path, as_json: bool) -> anyhow::Result<ExitCode> {
    let records = logfile::read_all(file)?;
    let stats = ddct::can::decode::cycle_stats(&records);
    if as_json {
        println!("{}", ddct::can::log::stats::json(&stats));
    } else {
        print!("{}", ddct::can::log::stats::table(&stats));
    }
    Ok(ExitCode::SUCCESS)
}

/// Redraw period of `ddct log monitor` on a terminal.
const MONITOR_REDRAW: Duration = Duration::from_millis(250);

/// Draws the monitor: on a terminal over the previous drawing, else appended.
fn draw(text: &str, tty: bool) {
    if tty {
        eprint!("\x1b[H\x1b[2J");
        print!("{text}");
        let _ = std::io::stdout().flush();
    } else {
        println!("{text}");
    }
}

fn monitor(source: &Source, limit: Option<Duration>) -> anyhow::Result<ExitCode> {
    use std::io::IsTerminal as _;
    let tty = std::io::stdout().is_terminal();
    let mut decoder = LogDecoder::default();
    let mut mon = ddct::can::monitor::Monitor::default();
    let started = Instant::now();
    let mut last_draw = Instant::now();
    let mut now = Duration::ZERO;
    let file = match source {
        Source::Stdin => PathBuf::from("-"),
        Source::File(f) => f.clone(),
        Source::Iface(iface) => return monitor_live(iface, limit, tty, decoder, mon),
    };
    for item in LogReader::any_format(open_input(&file)?, Box::new(wall_clock)) {
        match item {
            Ok(r) => {
                now = r.timestamp;
                mon.push(&decoder.decode(&r));
            }
            Err(LogError::Line { line, kind }) => {
                eprintln!("{}:{line}: {kind}", file.display())
            }
            Err(LogError::InputLost { frames, .. }) => decoder.input_lost(frames),
            Err(e) => return Err(e).with_context(|| format!("{}", file.display())),
        }
        if tty && last_draw.elapsed() >= MONITOR_REDRAW {
            draw(&mon.render(now), tty);
            last_draw = Instant::now();
        }
        if limit.is_some_and(|l| started.elapsed() >= l) {
            break;
        }
    }
    draw(&mon.render(now), tty);
    Ok(ExitCode::SUCCESS)
}

/// The monitor on a live interface, until a signal or `limit`.
fn monitor_live(
    iface: &str,
    limit: Option<Duration>,
    tty: bool,
    mut decoder: LogDecoder,
    mut mon: ddct::can::monitor::Monitor,
) -> anyhow::Result<ExitCode> {
    let rt = runtime()?;
    rt.block_on(async {
        let mut bus = open_can(iface)?;
        let stop = shutdown_signal();
        tokio::pin!(stop);
        let deadline = async {
            match limit {
                Some(l) => tokio::time::sleep(l).await,
                None => std::future::pending().await,
            }
        };
        tokio::pin!(deadline);
        let mut tick = tokio::time::interval(MONITOR_REDRAW);
        loop {
            tokio::select! {
                rx = bus.recv() => {
                    let rx = rx?;
                    let rec = ddct::can::candump::LogRecord {
                        timestamp: rx.timestamp,
                        iface: iface.to_string(),
                        frame: rx.frame,
                        direction: None,
                    };
                    mon.push(&decoder.decode(&rec));
                }
                _ = tick.tick(), if tty => draw(&mon.render(wall_clock()), tty),
                _ = &mut deadline => break,
                _ = &mut stop => break,
            }
        }
        anyhow::Ok(())
    })?;
    draw(&mon.render(wall_clock()), tty);
    Ok(ExitCode::SUCCESS)
}

/// Receive queue asked for by `ddct log record` (bytes).
const RECORD_RCVBUF: usize = 16 << 20;

fn record(
    iface: &str,
    out: &PathBuf,
    count: Option<u64>,
    duration: Option<Duration>,
    ready_file: Option<&std::path::Path>,
) -> anyhow::Result<ExitCode> {
    let file = File::create(out).with_context(|| format!("{}", out.display()))?;
    let mut writer = LogWriter::new(BufWriter::new(file));
    let rt = runtime()?;
    let (rec, drops) = rt.block_on(async {
        let mut bus = open_can(iface)?;
        // A recorder the host deschedules for a while must not lose frames: 16 MiB of receive
        // queue (minutes of a 10 ms bus) where the kernel grants it.
        if let Err(e) = bus.set_recv_buffer(RECORD_RCVBUF) {
            tracing::warn!("{e}: the default receive queue may drop frames under load");
        }
        let stop = shutdown_signal();
        announce_ready(ready_file)?;
        let rec = record_frames(&mut bus, iface, &mut writer, count, duration, stop).await?;
        let drops = bus.kernel_drops();
        anyhow::Ok((rec, drops))
    })?;
    let (n, per_id) = (rec.frames, rec.per_id);
    eprintln!("recorded {n} frame(s) from {iface} into {}", out.display());
    for (id, k) in &per_id {
        let name = ddct::can::messages::message_def(*id).map_or("-", |d| d.name);
        eprintln!("  {id:03X} {name:<16} {k}");
    }
    match drops {
        Ok(d) => eprintln!("dropped by the kernel (receive queue full): {d}"),
        Err(e) => eprintln!("dropped by the kernel: unknown ({e})"),
    }
    Ok(ExitCode::SUCCESS)
}

/// `--speed`: a finite factor above zero.
fn parse_speed(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if v.is_finite() && v > 0.0 && v <= 1e6 {
        Ok(v)
    } else {
        Err(format!(
            "{s}: a factor above 0 and at most 1e6 (use --max-rate to ignore the timing)"
        ))
    }
}

fn replay(
    file: &std::path::Path,
    iface: &str,
    pace: Pace,
    passes: u32,
) -> anyhow::Result<ExitCode> {
    let records = logfile::read_all(file)?;
    let rt = runtime()?;
    let pb = super::bar((records.len() * passes as usize) as u64, "frames");
    pb.set_message(format!(" sent on {iface}"));
    let sent = rt.block_on(async {
        let mut bus = open_can(iface)?;
        anyhow::Ok(replay::play(&mut bus, &records, pace, passes, || pb.inc(1)).await?)
    });
    pb.finish_and_clear();
    let sent = sent?;
    eprintln!("sent {sent} frame(s) on {iface}");
    Ok(ExitCode::SUCCESS)
}

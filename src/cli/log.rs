//! `ddct log`: decode, record, replay and convert bus logs (candump text or MDF 4).

mod convert;
mod csv;

use super::args::{open_can, Source};
use super::{announce_ready, runtime, shutdown_signal};
use anyhow::{bail, Context};
use clap::{Subcommand, ValueEnum};
use ddct::can::candump::{LogError, LogReader, LogRecord, LogWriter};
use ddct::can::columnar::{SignalRow, SignalWriter};
use ddct::can::decode::{DecodedFrame, LogDecoder};
use ddct::can::decode_csv::{CsvFrame, CsvRows, CsvSignal, CSV_HEADER};
use ddct::can::e2e::E2eConfig;
use ddct::can::logfile::{self, LogFormat};
use ddct::can::mf4::Mf4Error;
use ddct::can::runtime_dbc::{self, RuntimeDbc};
use ddct::can::socketcan::MMSG_BATCH;
use ddct::can::Bus;
use indicatif::ProgressBar;
use serde_json::json;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, IsTerminal as _, Write};
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

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Format {
    /// One line per frame: time, interface, id, message, E2E verdict, signals with units.
    Table,
    /// One row per signal: time_s,iface,id,message,signal,value,unit,e2e.
    Csv,
    /// One JSON object per frame (JSON lines).
    Json,
    /// The CSV's rows and columns as a Parquet table (`--out FILE`; pandas, polars and DuckDB
    /// read it directly): time_s and value as f64, id as u32, the rest as strings; a frame
    /// with no signal has an empty signal and a null value.
    Parquet,
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

/// The ids `-m/--message` selects: names or hex ids of the built-in contract, or of the `--dbc`
/// file when one is given.
fn wanted_filter(messages: &[String], dbc: Option<&RuntimeDbc>) -> anyhow::Result<Vec<u32>> {
    messages
        .iter()
        .map(|m| {
            let t = m.trim_start_matches("0x").trim_start_matches("0X");
            let id = u32::from_str_radix(t, 16).ok();
            match dbc {
                Some(db) => db
                    .message_by_name(m)
                    .map(|d| d.id)
                    .or(id.filter(|id| db.messages.iter().any(|d| d.id == *id)))
                    .with_context(|| {
                        format!(
                            "--message {m}: not a message name or id of {}",
                            db.path.display()
                        )
                    }),
                None => ddct::can::messages::message_by_name(m)
                    .map(|def| u32::from(def.id))
                    .or(id.filter(|id| ddct::can::messages::message_def(*id).is_some()))
                    .with_context(|| {
                        format!("--message {m}: not a message name or id of the contract")
                    }),
            }
        })
        .collect()
}

/// Seconds since the Unix epoch now: the time of a screen line that carries none.
fn wall_clock() -> Duration {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default()
}

/// One decoded frame as `ddct log decode` prints it, from the built-in decoder or a `--dbc`
/// file.
struct Shown<'a> {
    timestamp: Duration,
    iface: &'a str,
    id: u32,
    name: Option<&'a str>,
    /// The E2E verdict's name; `n/a` where a `--dbc` decode does not compute it.
    e2e: &'static str,
    signals: Vec<ShownSignal<'a>>,
    error: Option<String>,
}

struct ShownSignal<'a> {
    name: &'a str,
    value: f64,
    /// The value as the table shows it (a value-table name or the number at its resolution);
    /// formatted only for the table (empty for CSV and JSON, which print the value).
    text: String,
    label: Option<&'a str>,
    unit: &'a str,
    in_range: bool,
}

/// The E2E field of a frame whose verdict a `--dbc` decode does not compute.
const E2E_NOT_COMPUTED: &str = "n/a";

impl<'a> Shown<'a> {
    fn builtin(d: &'a DecodedFrame, with_text: bool) -> Self {
        Shown {
            timestamp: d.timestamp,
            iface: &d.iface,
            id: d.id,
            name: d.message.map(|m| m.name),
            e2e: d.e2e.as_str(),
            signals: d
                .signals
                .iter()
                .map(|s| ShownSignal {
                    name: s.signal.name,
                    value: s.value,
                    text: if with_text {
                        s.display_value()
                    } else {
                        String::new()
                    },
                    label: s.label,
                    unit: s.signal.unit,
                    in_range: s.in_range,
                })
                .collect(),
            error: d.error.as_ref().map(|e| e.to_string()),
        }
    }

    fn runtime(r: &'a LogRecord, d: &runtime_dbc::Decoded<'a>, with_text: bool) -> Self {
        Shown {
            timestamp: r.timestamp,
            iface: &r.iface,
            id: r.frame.raw_id(),
            name: d.message.map(|m| m.name.as_str()),
            e2e: d.e2e.map_or(E2E_NOT_COMPUTED, |v| v.as_str()),
            signals: d
                .signals
                .iter()
                .map(|s| ShownSignal {
                    name: &s.signal.name,
                    value: s.value,
                    text: if with_text {
                        s.display_value()
                    } else {
                        String::new()
                    },
                    label: s.label,
                    unit: &s.signal.unit,
                    in_range: s.in_range,
                })
                .collect(),
            error: d.issue.as_ref().map(|e| e.to_string()),
        }
    }
}

/// Standard output that takes the progress bar off the terminal while it writes, for when the
/// decoded lines and the bar share one terminal. Only whole lines go out (the bar is drawn after
/// the last one; a line cut at a buffer boundary would be erased with it).
struct AroundBar {
    pb: ProgressBar,
    out: std::io::Stdout,
    partial: Vec<u8>,
}

impl AroundBar {
    fn emit(&mut self, upto: usize) -> std::io::Result<()> {
        let (out, partial) = (&mut self.out, &mut self.partial);
        self.pb.suspend(|| {
            out.write_all(&partial[..upto])?;
            out.flush()
        })?;
        partial.drain(..upto);
        Ok(())
    }
}

impl Write for AroundBar {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.partial.extend_from_slice(buf);
        if let Some(last) = self.partial.iter().rposition(|b| *b == b'\n') {
            self.emit(last + 1)?;
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.emit(self.partial.len())
    }
}

/// The log to decode with its progress display (stderr, terminal only): a bar by bytes for a
/// file; for standard input a spinner counting frames (`per_frame`: the caller counts them).
struct DecodeInput {
    reader: Box<dyn BufRead>,
    pb: ProgressBar,
    per_frame: bool,
}

fn open_decode_input(file: &PathBuf) -> anyhow::Result<DecodeInput> {
    if file.as_os_str() == "-" {
        return Ok(DecodeInput {
            reader: Box::new(BufReader::new(std::io::stdin())),
            pb: super::counter("decoding standard input", "frames"),
            per_frame: true,
        });
    }
    let f = File::open(file).with_context(|| format!("{}", file.display()))?;
    let len = f.metadata().map(|m| m.len()).unwrap_or(0);
    let pb = super::byte_bar(len, format!("decoding {}", file.display()));
    Ok(DecodeInput {
        reader: Box::new(BufReader::new(pb.wrap_read(f))),
        pb,
        per_frame: false,
    })
}

/// The decoder of `ddct log decode`: the built-in contract or a `--dbc` file.
enum AnyDecoder<'a> {
    Builtin(LogDecoder),
    Runtime(runtime_dbc::Decoder<'a>),
}

impl AnyDecoder<'_> {
    /// The logger lost `frames` frames before the next one (none: nothing to tell).
    fn input_lost(&mut self, frames: u64) {
        match self {
            _ if frames == 0 => {}
            AnyDecoder::Builtin(d) => d.input_lost(frames),
            AnyDecoder::Runtime(d) => d.input_lost(frames),
        }
    }
}

/// Why an item of the input is not a frame.
enum Unread {
    /// A malformed line or frame: named (after the file name), counted and skipped.
    Skip(String),
    /// The logger before us lost this many frames here (candump -d's `DROPCOUNT`).
    Lost(u64),
    /// The input cannot be read further.
    Fatal(anyhow::Error),
}

impl From<LogError> for Unread {
    fn from(e: LogError) -> Self {
        match e {
            LogError::Line { line, kind } => Unread::Skip(format!(":{line}: {kind}")),
            LogError::InputLost { frames, .. } => Unread::Lost(frames),
            other => Unread::Fatal(other.into()),
        }
    }
}

impl From<Mf4Error> for Unread {
    fn from(e: Mf4Error) -> Self {
        match e {
            Mf4Error::Frame { .. } => Unread::Skip(format!(": {e}")),
            other => Unread::Fatal(other.into()),
        }
    }
}

/// What `ddct log decode` tells about the log besides the decoded frames.
struct Decoding<'a> {
    file: &'a std::path::Path,
    pb: ProgressBar,
    /// Standard input: the progress counts frames.
    per_frame: bool,
    /// The ids `-m` selects (empty: all).
    filter: Vec<u32>,
    bad_lines: usize,
    /// Frames by E2E verdict (a handful of verdicts: a list, not a map, per frame).
    verdicts: Vec<(&'static str, usize)>,
    /// Frames the logger reported lost (DROPCOUNT lines) and not yet told to the decoder.
    lost_pending: u64,
    /// DROPCOUNT lines read.
    loss_lines: usize,
}

impl Decoding<'_> {
    fn wanted(&self, id: u32) -> bool {
        self.filter.is_empty() || self.filter.contains(&id)
    }

    /// A line or frame that could not be read: named on stderr, counted.
    fn bad_item(&mut self, what: &str) {
        self.bad_lines += 1;
        self.pb
            .suspend(|| eprintln!("{}{what}", self.file.display()));
    }

    /// The record of a log item; a malformed line or frame is named, counted and skipped
    /// (`None`), any other error ends the decode naming the file.
    fn record<T, E: Into<Unread>>(&mut self, item: Result<T, E>) -> anyhow::Result<Option<T>> {
        match item.map_err(Into::into) {
            Ok(r) => Ok(Some(r)),
            Err(Unread::Skip(what)) => {
                self.bad_item(&what);
                Ok(None)
            }
            Err(Unread::Lost(frames)) => {
                self.lost_pending += frames;
                self.loss_lines += 1;
                Ok(None)
            }
            Err(Unread::Fatal(e)) => Err(e).with_context(|| format!("{}", self.file.display())),
        }
    }

    /// Frames read: the progress on standard input.
    fn frames_read(&self, n: u64) {
        if self.per_frame {
            self.pb.inc(n);
        }
    }

    fn verdict(&mut self, e2e: &'static str) {
        match self.verdicts.iter_mut().find(|(v, _)| *v == e2e) {
            Some((_, n)) => *n += 1,
            None => self.verdicts.push((e2e, 1)),
        }
    }
}

/// Whether an error is the reader of the output going away (`ddct log decode … | head`).
fn broken_pipe(e: &anyhow::Error) -> bool {
    e.downcast_ref::<std::io::Error>()
        .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
}

fn decode(
    file: &PathBuf,
    format: Format,
    messages: &[String],
    quiet: bool,
    dbc: Option<&std::path::Path>,
    out_path: Option<&std::path::Path>,
) -> anyhow::Result<ExitCode> {
    let runtime = dbc.map(RuntimeDbc::load).transpose()?;
    let create =
        |p: &std::path::Path| File::create(p).with_context(|| format!("creating {}", p.display()));
    let mut parquet = match (format, out_path) {
        (Format::Parquet, Some(p)) => Some(SignalWriter::new(BufWriter::new(create(p)?))?),
        _ => None,
    };
    let filter = wanted_filter(messages, runtime.as_ref())?;
    // An MDF file is read whole, then decoded frame by frame like a candump log.
    let mf4 = match file.as_os_str() != "-" && logfile::detect(file)? == LogFormat::Mf4 {
        true => Some(logfile::open_mf4(file)?),
        false => None,
    };
    let DecodeInput {
        reader,
        pb,
        per_frame,
    } = open_decode_input(file)?;
    let text_file = match (out_path, &parquet) {
        (Some(p), None) => Some(create(p)?),
        _ => None,
    };
    let mut out = BufWriter::new(text_sink(text_file, &pb));
    let mut decoder = match &runtime {
        Some(db) => AnyDecoder::Runtime(runtime_dbc::Decoder::new(db, E2eConfig::default())),
        None => AnyDecoder::Builtin(LogDecoder::default()),
    };
    let mut reader = LogReader::any_format(reader, Box::new(wall_clock));
    let mut run = Decoding {
        file,
        pb,
        per_frame,
        filter,
        bad_lines: 0,
        verdicts: Vec::new(),
        lost_pending: 0,
        loss_lines: 0,
    };
    let decoded = match (&mut decoder, format) {
        (AnyDecoder::Builtin(dec), Format::Csv) if mf4.is_none() => {
            csv::csv_builtin(&mut reader, dec, &mut run, &mut out)
        }
        (dec, _) => match mf4 {
            Some(frames) => frame_by_frame(frames, dec, format, &mut run, &mut out, &mut parquet),
            None => frame_by_frame(
                reader.by_ref(),
                dec,
                format,
                &mut run,
                &mut out,
                &mut parquet,
            ),
        },
    }
    .and_then(|()| Ok(out.flush()?));
    match decoded {
        Err(e) if broken_pipe(&e) => return Ok(ExitCode::SUCCESS),
        other => other?,
    }
    run.pb.finish_and_clear();
    if let (Some(w), Some(p)) = (parquet, out_path) {
        let rows = w
            .finish()
            .with_context(|| format!("writing {}", p.display()))?;
        eprintln!("{}: {rows} rows", p.display());
    }
    let (gaps, lost) = match &decoder {
        AnyDecoder::Builtin(dec) => (dec.gaps(), dec.frames_lost()),
        AnyDecoder::Runtime(dec) => (dec.gaps(), dec.frames_lost()),
    };
    report_decoding(&run, gaps, lost, quiet)
}

/// Where `ddct log decode` writes text: the `--out` file, else standard output (around the
/// progress bar when both are on a terminal).
fn text_sink(file: Option<File>, pb: &ProgressBar) -> Box<dyn Write + Send> {
    let stdout = std::io::stdout();
    match file {
        Some(f) => Box::new(f),
        None if stdout.is_terminal() && !pb.is_hidden() => Box::new(AroundBar {
            pb: pb.clone(),
            out: stdout,
            partial: Vec::new(),
        }),
        None => Box::new(stdout),
    }
}

/// What the input itself says of frames missing from it: the logger's DROPCOUNT lines (the
/// counter gaps they explain are `missing_input`, not the bus's), or, reading a pipe without
/// them, that a reader falling behind loses frames too and how to have candump say so.
fn report_input_loss(run: &Decoding<'_>, lost: u64, skipped: Option<usize>) {
    if run.loss_lines > 0 {
        eprintln!(
            "input: the logger lost {lost} frame(s) before ddct read them ({} DROPCOUNT \
             line(s)); the counter gaps they explain are counted as missing_input, not as the \
             bus's E2E errors",
            run.loss_lines
        );
    } else if run.file.as_os_str() == "-" && skipped.is_some() {
        eprintln!(
            "input: standard input said nothing of frames it lost; a candump that falls behind \
             loses frames too, and they show as counter_skipped here: run `candump -d` so that \
             its DROPCOUNT lines tell its own losses from the bus's"
        );
    }
}

/// The summary of `ddct log decode` on stderr: frames by E2E verdict, the silences (unless
/// `quiet`), the malformed lines (exit code 2).
fn report_decoding(
    run: &Decoding<'_>,
    gaps: &[ddct::can::decode::Gap<'_>],
    lost: u64,
    quiet: bool,
) -> anyhow::Result<ExitCode> {
    let by_name: BTreeMap<_, _> = run.verdicts.iter().copied().collect();
    let summary: Vec<String> = by_name.iter().map(|(k, v)| format!("{k} {v}")).collect();
    eprintln!("frames by E2E verdict: {}", summary.join(", "));
    report_input_loss(run, lost, by_name.get("counter_skipped").copied());
    for g in gaps.iter().filter(|_| !quiet) {
        eprintln!(
            "gap: {} silent from {:.6} to {:.6} s ({} ms)",
            g.message,
            g.from.as_secs_f64(),
            g.to.as_secs_f64(),
            (g.to - g.from).as_millis()
        );
    }
    if run.bad_lines > 0 {
        eprintln!(
            "{}: {} malformed line(s) or frame(s)",
            run.file.display(),
            run.bad_lines
        );
        return Ok(ExitCode::from(2));
    }
    Ok(ExitCode::SUCCESS)
}

/// Every other format and the `--dbc` decoder: each frame decoded into a [`Shown`] and written
/// as the format asks.
fn frame_by_frame<E: Into<Unread>, W: Write + Send>(
    items: impl Iterator<Item = Result<LogRecord, E>>,
    decoder: &mut AnyDecoder<'_>,
    format: Format,
    run: &mut Decoding<'_>,
    out: &mut impl Write,
    parquet: &mut Option<SignalWriter<W>>,
) -> anyhow::Result<()> {
    let mut rows = CsvRows::new();
    if format == Format::Csv {
        out.write_all(CSV_HEADER.as_bytes())?;
    }
    for item in items {
        let Some(rec) = run.record(item)? else {
            continue;
        };
        decoder.input_lost(std::mem::take(&mut run.lost_pending));
        run.frames_read(1);
        // Every frame goes through the decoder (its E2E and gap tracking); only the selected
        // ones are turned into output.
        let wanted = run.wanted(rec.frame.raw_id());
        let table = format == Format::Table;
        let builtin;
        let runtime_decoded;
        let d = match decoder {
            AnyDecoder::Builtin(dec) => {
                builtin = dec.decode(&rec);
                if !wanted {
                    continue;
                }
                Shown::builtin(&builtin, table)
            }
            AnyDecoder::Runtime(dec) => {
                runtime_decoded = dec.decode(&rec);
                if !wanted {
                    continue;
                }
                Shown::runtime(&rec, &runtime_decoded, table)
            }
        };
        run.verdict(d.e2e);
        match format {
            Format::Table => writeln!(out, "{}", table_line(&d))?,
            Format::Csv => write_csv(out, &mut rows, &d)?,
            Format::Json => writeln!(out, "{}", json_line(&d))?,
            Format::Parquet => {
                if let Some(w) = parquet.as_mut() {
                    push_parquet(w, &d)?;
                }
            }
        }
    }
    Ok(())
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
        let arr: Vec<_> = stats
            .iter()
            .map(|s| {
                json!({"id": s.id, "name": s.name, "nominal_ms": s.nominal_ms, "frames": s.frames,
                       "mean_ms": s.mean_ms, "p50_ms": s.p50_ms, "p99_ms": s.p99_ms, "min_ms": s.min_ms, "max_ms": s.max_ms})
            })
            .collect();
        println!("{}", serde_json::Value::Array(arr));
    } else {
        println!(
            "{:<6} {:<14} {:>7} {:>7} {:>8} {:>8} {:>8} {:>8}",
            "id", "message", "frames", "nominal", "p50 ms", "p99 ms", "min ms", "max ms"
        );
        for s in &stats {
            println!(
                "0x{:03X}  {:<14} {:>7} {:>7} {:>8.3} {:>8.3} {:>8.3} {:>8.3}",
                s.id,
                s.name.unwrap_or("?"),
                s.frames,
                s.nominal_ms.map_or("-".to_string(), |m| format!("{m} ms")),
                s.p50_ms,
                s.p99_ms,
                s.min_ms,
                s.max_ms
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn table_line(d: &Shown<'_>) -> String {
    let name = d.name.unwrap_or("?");
    let mut s = format!(
        "({:.6}) {} {:03X} {:<14} e2e={:<16}",
        d.timestamp.as_secs_f64(),
        d.iface,
        d.id,
        name,
        d.e2e
    );
    for sig in &d.signals {
        let unit = if sig.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", sig.unit)
        };
        let flag = if sig.in_range { "" } else { "(!)" };
        s.push_str(&format!(" {}={}{unit}{flag}", sig.name, sig.text));
    }
    if let Some(e) = &d.error {
        s.push_str(&format!("  error: {e}"));
    }
    s
}

/// Appends a frame's rows (one per signal, as the CSV's) to the Parquet table.
fn push_parquet<'a, W: Write + Send>(w: &mut SignalWriter<W>, d: &Shown<'a>) -> anyhow::Result<()> {
    let row = |signal: &'a str, value: f64, unit: &'a str| -> SignalRow<'a> {
        SignalRow {
            time_s: d.timestamp.as_secs_f64(),
            iface: d.iface,
            id: d.id,
            message: d.name.unwrap_or(""),
            signal,
            value,
            unit,
            e2e: d.e2e,
        }
    };
    if d.signals.is_empty() {
        w.push(&row("", f64::NAN, ""))?;
    }
    for s in &d.signals {
        w.push(&row(s.name, s.value, s.unit))?;
    }
    Ok(())
}

/// Writes a frame's CSV rows (one per signal) through the reused rows `rows`.
fn write_csv(out: &mut impl Write, rows: &mut CsvRows, d: &Shown<'_>) -> std::io::Result<()> {
    rows.clear();
    let frame = CsvFrame {
        timestamp: d.timestamp,
        iface: d.iface,
        id: d.id,
        message: d.name.unwrap_or(""),
        e2e: d.e2e,
    };
    let signals = d.signals.iter().map(|s| CsvSignal {
        name: s.name,
        value: s.value,
        unit: s.unit,
    });
    rows.push_frame(&frame, signals);
    out.write_all(rows.text())
}

fn json_line(d: &Shown<'_>) -> String {
    let signals: serde_json::Map<String, serde_json::Value> = d
        .signals
        .iter()
        .map(|s| (s.name.to_string(), json!(s.value)))
        .collect();
    let labels: serde_json::Map<String, serde_json::Value> = d
        .signals
        .iter()
        .filter_map(|s| s.label.map(|l| (s.name.to_string(), json!(l))))
        .collect();
    json!({
        "t": d.timestamp.as_secs_f64(),
        "iface": d.iface,
        "id": d.id,
        "name": d.name,
        "signals": signals,
        "labels": labels,
        "e2e": d.e2e,
        "error": d.error,
    })
    .to_string()
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

/// After a wake-up the recorder reads everything queued (in `recvmmsg` batches) and then waits
/// this long before it looks again: it needs no latency (every frame carries its kernel
/// timestamp, and the queue holds minutes), and a wake-up per frame of a flood took the CPU the
/// daemons under test need (User-Mode Linux: tens of µs per system call, one CPU).
const RECORD_PACE: Duration = Duration::from_millis(5);

/// Frames read per recorder wake-up at most (the rest on the next one).
const RECORD_BATCH: usize = 1024;

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
    let (n, per_id, drops) = rt.block_on(async {
        let mut bus = open_can(iface)?;
        // A recorder the host deschedules for a while must not lose frames: 16 MiB of receive
        // queue (minutes of a 10 ms bus) where the kernel grants it.
        if let Err(e) = bus.set_recv_buffer(RECORD_RCVBUF) {
            tracing::warn!("{e}: the default receive queue may drop frames under load");
        }
        let deadline = duration.map(|d| tokio::time::Instant::now() + d);
        let stop = shutdown_signal();
        announce_ready(ready_file)?;
        tokio::pin!(stop);
        let mut n = 0u64;
        let mut per_id: BTreeMap<u32, u64> = BTreeMap::new();
        let mut last_flush = Instant::now();
        let mut batch = Vec::with_capacity(RECORD_BATCH);
        loop {
            if count.is_some_and(|c| n >= c) {
                break;
            }
            let until_deadline = async {
                match deadline {
                    Some(d) => tokio::time::sleep_until(d).await,
                    None => std::future::pending().await,
                }
            };
            let flush_tick = tokio::time::sleep(Duration::from_millis(200));
            tokio::select! {
                rx = bus.recv() => {
                    batch.push(rx);
                    while !bus.try_recv_many(MMSG_BATCH, &mut batch) && batch.len() < RECORD_BATCH {}
                    for rx in batch.drain(..) {
                        if count.is_some_and(|c| n >= c) {
                            break;
                        }
                        let rx = rx?;
                        writer.write_frame(rx.timestamp, iface, &rx.frame, None)?;
                        n += 1;
                        *per_id.entry(rx.frame.raw_id()).or_default() += 1;
                    }
                    if last_flush.elapsed() > Duration::from_millis(200) {
                        writer.flush()?;
                        last_flush = Instant::now();
                    }
                    tokio::time::sleep(RECORD_PACE).await;
                }
                _ = flush_tick => { writer.flush()?; last_flush = Instant::now(); }
                _ = until_deadline => break,
                _ = &mut stop => break,
            }
        }
        writer.flush()?;
        let drops = bus.kernel_drops();
        anyhow::Ok((n, per_id, drops))
    })?;
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

/// How `ddct log replay` spaces the frames.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Pace {
    /// The log's own timing, `speed` times faster.
    Log { speed: f64 },
    /// As fast as the interface takes them, at least `interval_us` apart.
    MaxRate { interval_us: u64 },
}

fn replay(
    file: &std::path::Path,
    iface: &str,
    pace: Pace,
    passes: u32,
) -> anyhow::Result<ExitCode> {
    let records = logfile::read_all(file)?;
    let rt = runtime()?;
    let stamps: Vec<Duration> = records.iter().map(|r| r.timestamp).collect();
    let pb = super::bar((records.len() * passes as usize) as u64, "frames");
    pb.set_message(format!(" sent on {iface}"));
    let sent = rt.block_on(async {
        let mut bus = open_can(iface)?;
        let start = tokio::time::Instant::now();
        let mut next = start;
        let mut sent = 0usize;
        let frames = records.iter().cycle().take(records.len() * passes as usize);
        for (r, at) in frames.zip(ddct::can::replay::schedule(&stamps, passes)) {
            match pace {
                Pace::Log { speed } => {
                    tokio::time::sleep_until(start + at.div_f64(speed)).await;
                }
                Pace::MaxRate { interval_us } if interval_us > 0 => {
                    tokio::time::sleep_until(next).await;
                    next += Duration::from_micros(interval_us);
                }
                Pace::MaxRate { .. } => {}
            }
            bus.send(r.frame).await?;
            sent += 1;
            pb.inc(1);
        }
        anyhow::Ok(sent)
    });
    pb.finish_and_clear();
    let sent = sent?;
    eprintln!("sent {sent} frame(s) on {iface}");
    Ok(ExitCode::SUCCESS)
}

//! `ddct log decode`: a log (candump text, candump's screen output or MDF 4) decoded with the
//! built-in contract or a `--dbc` file and written as a table, CSV, JSON lines or Parquet, then
//! what the log itself said on stderr: frames by E2E verdict, silences, the logger's losses and
//! the malformed lines.

use super::csv;
use super::decoding::{Decoding, Unread};
use anyhow::Context;
use clap::ValueEnum;
use ddct::can::candump::{LogReader, LogRecord};
use ddct::can::columnar::{SignalRow, SignalWriter};
use ddct::can::decode::{DecodedFrame, LogDecoder};
use ddct::can::decode_csv::{CsvFrame, CsvRows, CsvSignal, CSV_HEADER};
use ddct::can::e2e::E2eConfig;
use ddct::can::logfile::{self, LogFormat};
use ddct::can::runtime_dbc::{self, RuntimeDbc};
use indicatif::ProgressBar;
use serde_json::json;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, IsTerminal as _, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

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
pub(super) fn wall_clock() -> Duration {
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
            pb: crate::cli::counter("decoding standard input", "frames"),
            per_frame: true,
        });
    }
    let f = File::open(file).with_context(|| format!("{}", file.display()))?;
    let len = f.metadata().map(|m| m.len()).unwrap_or(0);
    let pb = crate::cli::byte_bar(len, format!("decoding {}", file.display()));
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

/// Whether an error is the reader of the output going away (`ddct log decode … | head`).
fn broken_pipe(e: &anyhow::Error) -> bool {
    e.downcast_ref::<std::io::Error>()
        .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe)
}

pub(super) fn decode(
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

//! `ddct log decode`: opens the log (candump text, candump's screen output or MDF 4), the
//! `--dbc` file and the output, shows the progress, and runs the library's decode
//! ([`ddct::can::log::decode`]); then what the log itself said on stderr: frames by E2E
//! verdict, silences, the logger's losses and the malformed lines.

use anyhow::{anyhow, Context};
use clap::ValueEnum;
use ddct::can::candump::LogReader;
use ddct::can::columnar::SignalWriter;
use ddct::can::decode::LogDecoder;
use ddct::can::e2e::E2eConfig;
use ddct::can::log::{self, AnyDecoder, DecodeError, LogInput, Progress, Tally};
use ddct::can::logfile::{self, LogFormat};
use ddct::can::runtime_dbc::{self, RuntimeDbc};
use indicatif::ProgressBar;
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

impl From<Format> for log::Format {
    fn from(f: Format) -> Self {
        match f {
            Format::Table => log::Format::Table,
            Format::Csv => log::Format::Csv,
            Format::Json => log::Format::Json,
            Format::Parquet => log::Format::Parquet,
        }
    }
}

/// Seconds since the Unix epoch now: the time of a screen line that carries none.
pub(super) fn wall_clock() -> Duration {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap_or_default()
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

/// The progress of a decode on stderr: frames counted on the bar, notes written around it.
struct Bar(ProgressBar);

impl Progress for Bar {
    fn frames(&self, n: u64) {
        self.0.inc(n);
    }

    fn note(&self, line: &str) {
        self.0.suspend(|| eprintln!("{line}"));
    }
}

/// The log to decode with its progress display (stderr, terminal only): a bar by bytes for a
/// file; for standard input a spinner counting frames (`per_frame`: the decode counts them).
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
    let filter =
        log::message_ids(messages, runtime.as_ref()).map_err(|e| anyhow!("--message {e}"))?;
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
    let input = match mf4 {
        Some(frames) => LogInput::Mf4(frames),
        None => LogInput::Text(LogReader::any_format(reader, Box::new(wall_clock))),
    };
    let progress = Bar(pb);
    let mut tally = Tally::new(file, &progress, per_frame, filter);
    let decoded = log::decode(
        input,
        &mut decoder,
        format.into(),
        &mut tally,
        &mut out,
        parquet.as_mut(),
    )
    .and_then(|()| out.flush().map_err(DecodeError::from));
    match decoded {
        Err(e) if e.is_broken_pipe() => return Ok(ExitCode::SUCCESS),
        other => other?,
    }
    progress.0.finish_and_clear();
    if let (Some(w), Some(p)) = (parquet, out_path) {
        let rows = w
            .finish()
            .with_context(|| format!("writing {}", p.display()))?;
        eprintln!("{}: {rows} rows", p.display());
    }
    let (gaps, lost) = decoder.gaps_and_lost();
    for line in tally.summary(gaps, lost, quiet) {
        eprintln!("{line}");
    }
    Ok(match tally.bad_lines() {
        0 => ExitCode::SUCCESS,
        _ => ExitCode::from(2),
    })
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

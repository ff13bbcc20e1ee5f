//! `ddct log convert IN OUT`: a log between candump `-l` text, MDF 4, CSV and Parquet, the
//! output format taken from OUT's extension; the input (candump text or MDF 4) by content.
//! The output is written beside OUT and renamed into place once complete.

use super::decode::{decode, Format};
use anyhow::{bail, Context};
use ddct::can::candump::{LogRecord, LogWriter};
use ddct::can::columnar_frames::FrameWriter;
use ddct::can::logfile;
use ddct::can::mf4::Mf4Writer;
use embedded_can::Frame as _;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// What `ddct log convert` writes, by the output's extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutFormat {
    /// `.log`: candump `-l` text.
    Candump,
    /// `.mf4`: MDF 4.1 bus logging.
    Mf4,
    /// `.csv`: decoded signals (as `ddct log decode --format csv`), or frames with `--frames`.
    Csv,
    /// `.parquet`: decoded signals (as `ddct log decode --format parquet`), or frames.
    Parquet,
}

impl OutFormat {
    /// The format of `path` by its extension (case-insensitive).
    pub fn of(path: &Path) -> anyhow::Result<Self> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        Ok(match ext.as_deref() {
            Some("log") => OutFormat::Candump,
            Some("mf4") => OutFormat::Mf4,
            Some("csv") => OutFormat::Csv,
            Some("parquet") => OutFormat::Parquet,
            _ => bail!(
                "{}: unknown output format; the extension must be .log, .mf4, .csv or .parquet",
                path.display()
            ),
        })
    }
}

/// Converts `input` into `output`.
pub fn convert(input: &PathBuf, output: &Path, frames: bool) -> anyhow::Result<ExitCode> {
    let format = OutFormat::of(output)?;
    if frames && matches!(format, OutFormat::Candump | OutFormat::Mf4) {
        bail!("--frames is for .csv and .parquet output (a .log or .mf4 holds frames already)");
    }
    if input.as_path() == output {
        bail!(
            "{}: the input and the output are the same file",
            output.display()
        );
    }
    let part = output.with_file_name(format!(
        ".{}.part",
        output.file_name().and_then(|n| n.to_str()).unwrap_or("out")
    ));
    let written = match (format, frames) {
        (OutFormat::Csv, false) => signals(input, Format::Csv, &part),
        (OutFormat::Parquet, false) => signals(input, Format::Parquet, &part),
        _ => frames_out(input, format, &part),
    };
    let code = match written {
        Ok(code) => code,
        Err(e) => {
            let _ = std::fs::remove_file(&part);
            return Err(e);
        }
    };
    std::fs::rename(&part, output)
        .with_context(|| format!("renaming {} to {}", part.display(), output.display()))?;
    Ok(code)
}

/// Decoded signals, as `ddct log decode` writes them.
fn signals(input: &PathBuf, format: Format, out: &Path) -> anyhow::Result<ExitCode> {
    let code = decode(input, format, &[], true, None, Some(out))?;
    if code != ExitCode::SUCCESS {
        bail!(
            "{}: malformed lines (named above): nothing written",
            input.display()
        );
    }
    Ok(code)
}

/// Frames as a candump log, an MDF file, or a CSV or Parquet table of frames.
fn frames_out(input: &Path, format: OutFormat, out: &Path) -> anyhow::Result<ExitCode> {
    let records = logfile::read_all(input)?;
    let file = File::create(out).with_context(|| format!("creating {}", out.display()))?;
    let mut w = BufWriter::new(file);
    match format {
        OutFormat::Candump => {
            let mut log = LogWriter::new(&mut w);
            for r in &records {
                log.write(r)?;
            }
            log.flush()?;
        }
        OutFormat::Mf4 => {
            let mut mdf = Mf4Writer::new();
            for r in &records {
                mdf.push(r);
            }
            mdf.finish(&mut w)?;
        }
        OutFormat::Csv => frames_csv(&records, &mut w)?,
        OutFormat::Parquet => {
            let mut table = FrameWriter::new(&mut w)?;
            for r in &records {
                table.push(r)?;
            }
            table.finish()?;
        }
    }
    w.flush()
        .with_context(|| format!("writing {}", out.display()))?;
    eprintln!("{}: {} frames", input.display(), records.len());
    Ok(ExitCode::SUCCESS)
}

/// The header of the frame CSV.
pub const FRAMES_CSV_HEADER: &str = "time_s,iface,id,extended,remote,dlc,data\n";

/// One row per frame: the time as candump writes it, the id in hex, the data as hex bytes.
fn frames_csv(records: &[LogRecord], out: &mut impl Write) -> std::io::Result<()> {
    out.write_all(FRAMES_CSV_HEADER.as_bytes())?;
    for r in records {
        let f = &r.frame;
        write!(
            out,
            "{}.{:06},{},0x{:X},{},{},{},",
            r.timestamp.as_secs(),
            r.timestamp.subsec_micros(),
            r.iface,
            f.raw_id(),
            u8::from(f.is_extended()),
            u8::from(f.is_remote_frame()),
            f.dlc()
        )?;
        for b in f.bytes() {
            write!(out, "{b:02X}")?;
        }
        out.write_all(b"\n")?;
    }
    Ok(())
}

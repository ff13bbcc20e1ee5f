//! `ddct log convert`'s frames: a log's records written as candump `-l` text, MDF 4, or a CSV or
//! Parquet table of frames ([`write_frames`]), the format named by the output's extension
//! ([`OutFormat::of`]). Decoded-signal CSV and Parquet are a decode run's ([`super::decode()`]).

use crate::can::candump::{LogRecord, LogWriter};
use crate::can::columnar::ColumnarError;
use crate::can::columnar_frames::FrameWriter;
use crate::can::mf4::{Mf4Error, Mf4Writer};
use embedded_can::Frame as _;
use std::io::Write;
use std::path::Path;
use thiserror::Error;

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

/// An output name whose extension names no format.
#[derive(Debug, Error)]
#[error("{0}: unknown output format; the extension must be .log, .mf4, .csv or .parquet")]
pub struct UnknownFormat(pub String);

/// Why frames could not be written.
#[derive(Debug, Error)]
pub enum ConvertError {
    #[error(transparent)]
    Io(#[from] std::io::Error),
    #[error(transparent)]
    Parquet(#[from] ColumnarError),
    #[error(transparent)]
    Mf4(#[from] Mf4Error),
}

impl OutFormat {
    /// The format of `path` by its extension (case-insensitive).
    pub fn of(path: &Path) -> Result<Self, UnknownFormat> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        Ok(match ext.as_deref() {
            Some("log") => OutFormat::Candump,
            Some("mf4") => OutFormat::Mf4,
            Some("csv") => OutFormat::Csv,
            Some("parquet") => OutFormat::Parquet,
            _ => return Err(UnknownFormat(path.display().to_string())),
        })
    }
}

/// Writes `records` to `out` as frames in `format` (CSV and Parquet: one row per frame).
pub fn write_frames(
    records: &[LogRecord],
    format: OutFormat,
    out: &mut (impl Write + Send),
) -> Result<(), ConvertError> {
    match format {
        OutFormat::Candump => {
            let mut log = LogWriter::new(&mut *out);
            for r in records {
                log.write(r)?;
            }
            log.flush()?;
        }
        OutFormat::Mf4 => {
            let mut mdf = Mf4Writer::new();
            for r in records {
                mdf.push(r);
            }
            mdf.finish(&mut *out)?;
        }
        OutFormat::Csv => frames_csv(records, out)?,
        OutFormat::Parquet => {
            let mut table = FrameWriter::new(&mut *out)?;
            for r in records {
                table.push(r)?;
            }
            table.finish()?;
        }
    }
    Ok(())
}

/// The header of the frame CSV.
const FRAMES_CSV_HEADER: &str = "time_s,iface,id,extended,remote,dlc,data\n";

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

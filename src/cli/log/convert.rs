//! `ddct log convert IN OUT`: a log between candump `-l` text, MDF 4, CSV and Parquet, the
//! output format taken from OUT's extension; the input (candump text or MDF 4) by content.
//! The output is written beside OUT and renamed into place once complete; the frames are
//! written by [`ddct::can::log::convert`], the decoded signals by `ddct log decode`'s run.

use super::decode::{decode, Format};
use anyhow::{bail, Context};
use ddct::can::log::convert::{write_frames, OutFormat};
use ddct::can::logfile;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

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
    write_frames(&records, format, &mut w)?;
    w.flush()
        .with_context(|| format!("writing {}", out.display()))?;
    eprintln!("{}: {} frames", input.display(), records.len());
    Ok(ExitCode::SUCCESS)
}

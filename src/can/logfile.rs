//! A bus log on disk in either format ddct reads frames from: candump text (`-l`/`-L`) or an
//! MDF 4 bus-logging file, told apart by content (an MDF file starts with `MDF     `), so a
//! log keeps working whatever its name.

use super::candump::{LogError, LogReader, LogRecord};
use super::mf4::{self, Mf4Error, Mf4Frames};
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// The format of a log file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogFormat {
    Candump,
    Mf4,
}

/// A log that could not be read, naming the file (and the line or frame).
#[derive(Debug, Error)]
pub enum LogFileError {
    #[error("{}: {source}", file.display())]
    Io {
        file: PathBuf,
        source: std::io::Error,
    },
    #[error("{}:{line}: {kind}", file.display())]
    Line {
        file: PathBuf,
        line: usize,
        kind: super::candump::LineError,
    },
    #[error("{}: {source}", file.display())]
    Mf4 { file: PathBuf, source: Mf4Error },
    /// A `candump -d` `DROPCOUNT` line: the logger lost frames, so the record has holes.
    #[error("{}:{line}: the logger lost {frames} frame(s) here (DROPCOUNT): the record has a hole", file.display())]
    InputLost {
        file: PathBuf,
        line: usize,
        frames: u64,
    },
}

impl LogFileError {
    fn from_log(file: &Path, e: LogError) -> Self {
        match e {
            LogError::Line { line, kind } => LogFileError::Line {
                file: file.into(),
                line,
                kind,
            },
            LogError::Io(source) => LogFileError::Io {
                file: file.into(),
                source,
            },
            LogError::InputLost { line, frames } => LogFileError::InputLost {
                file: file.into(),
                line,
                frames,
            },
        }
    }
}

/// The format of `path` by its first bytes.
pub fn detect(path: &Path) -> Result<LogFormat, LogFileError> {
    let io = |source| LogFileError::Io {
        file: path.into(),
        source,
    };
    let mut head = [0u8; 8];
    let mut f = std::fs::File::open(path).map_err(io)?;
    let mut n = 0;
    while n < head.len() {
        match f.read(&mut head[n..]).map_err(io)? {
            0 => break,
            k => n += k,
        }
    }
    Ok(if mf4::is_mdf(&head[..n]) {
        LogFormat::Mf4
    } else {
        LogFormat::Candump
    })
}

/// The frames of an MDF file (read into memory, then given in time order).
pub fn open_mf4(path: &Path) -> Result<Mf4Frames, LogFileError> {
    let bytes = std::fs::read(path).map_err(|source| LogFileError::Io {
        file: path.into(),
        source,
    })?;
    mf4::read(&bytes).map_err(|source| LogFileError::Mf4 {
        file: path.into(),
        source,
    })
}

/// Every frame of a log in either format; the first malformed line or frame is an error.
pub fn read_all(path: &Path) -> Result<Vec<LogRecord>, LogFileError> {
    match detect(path)? {
        LogFormat::Mf4 => open_mf4(path)?
            .map(|r| {
                r.map_err(|source| LogFileError::Mf4 {
                    file: path.into(),
                    source,
                })
            })
            .collect(),
        LogFormat::Candump => {
            let f = std::fs::File::open(path).map_err(|source| LogFileError::Io {
                file: path.into(),
                source,
            })?;
            LogReader::new(BufReader::new(f))
                .map(|r| r.map_err(|e| LogFileError::from_log(path, e)))
                .collect()
        }
    }
}

/// When a log starts: an MDF file's header start time, a candump log's first frame; `None` for
/// a file that is neither (e.g. a CSV record) or that cannot be read.
pub fn start_time(path: &Path) -> Option<std::time::Duration> {
    match detect(path).ok()? {
        LogFormat::Mf4 => {
            let mut head = [0u8; mf4::START_TIME_AT + 8];
            let mut f = std::fs::File::open(path).ok()?;
            f.read_exact(&mut head).ok()?;
            mf4::start_time_ns(&head).map(std::time::Duration::from_nanos)
        }
        LogFormat::Candump => {
            let f = std::fs::File::open(path).ok()?;
            LogReader::new(BufReader::new(f))
                .take(16)
                .find_map(Result::ok)
                .map(|r| r.timestamp)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::candump::{format_record, parse_line};
    use crate::can::mf4::Mf4Writer;

    fn temp(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("ddct_logfile_{}_{name}", std::process::id()))
    }

    #[test]
    /// Standard, extended, remote and empty frames on two interfaces, with directions on one
    /// (a log has them on every line or on none).
    fn both_formats_read_the_same_frames_whatever_the_name() {
        let lines = [
            "(1700000000.000100) vcan0 100#0102030405060708",
            "(1700000000.001234) vcan0 1ABCDEF0#DEAD",
            "(1700000000.002000) can1 7E1#R T",
            "(1700000000.002000) vcan0 7E9#",
            "(1700000001.000000) can1 123#11 R",
            "(1700000001.500000) vcan0 110#00",
        ];
        let records: Vec<LogRecord> = lines.iter().map(|l| parse_line(l).unwrap()).collect();
        let text = temp("a.mf4"); // candump text under an .mf4 name
        std::fs::write(&text, lines.join("\n")).unwrap();
        let mdf = temp("b.log"); // MDF under a .log name
        let mut w = Mf4Writer::new();
        for r in &records {
            w.push(r);
        }
        w.finish(std::fs::File::create(&mdf).unwrap()).unwrap();
        let from_text = read_all(&text).unwrap();
        let from_mdf = read_all(&mdf).unwrap();
        let starts = (start_time(&text), start_time(&mdf));
        let _ = (std::fs::remove_file(&text), std::fs::remove_file(&mdf));
        assert_eq!(from_text, records);
        let shown = |v: &[LogRecord]| v.iter().map(format_record).collect::<Vec<_>>();
        assert_eq!(shown(&from_mdf), shown(&records));
        let first = std::time::Duration::from_micros(1_700_000_000_000_100);
        assert_eq!(starts, (Some(first), Some(first)));
    }

    #[test]
    fn a_truncated_mdf_file_is_an_error_naming_it() {
        let path = temp("cut.mf4");
        let mut w = Mf4Writer::new();
        w.push(&parse_line("(1.000000) vcan0 100#01").unwrap());
        let mut bytes = Vec::new();
        w.finish(&mut bytes).unwrap();
        for cut in [10, 100, bytes.len() - 9] {
            std::fs::write(&path, &bytes[..cut]).unwrap();
            let e = read_all(&path).unwrap_err().to_string();
            assert!(e.starts_with(&path.display().to_string()), "{e}");
        }
        let _ = std::fs::remove_file(&path);
    }
}

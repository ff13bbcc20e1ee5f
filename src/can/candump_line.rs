//! What a candump line is made of, shared by the log reader ([`super::candump`]) and the
//! screen-format parser ([`super::candump_screen`]): the direction flag, what can be wrong with a
//! line, and the `seconds.micros` time column.

use super::frame::FrameError;
use std::time::Duration;
use thiserror::Error;

/// Direction flag of newer candump logs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    Rx,
    Tx,
}

/// What is wrong with a log line.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum LineError {
    #[error("expected '(seconds.micros)' at the start")]
    Timestamp,
    #[error("timestamp must have 6 digits of microseconds")]
    Micros,
    #[error("missing interface name")]
    Iface,
    #[error("missing 'ID#DATA'")]
    Frame,
    #[error("bad CAN id '{0}' (3 hex digits for standard, 8 for extended)")]
    Id(String),
    #[error("bad data '{0}' (pairs of hex digits, at most 8 bytes)")]
    Data(String),
    #[error("CAN FD frames are not supported")]
    CanFd,
    #[error("{have} of the {dlc} data bytes the length announces")]
    Short { have: usize, dlc: usize },
    #[error("a date-time stamp (candump -t A); log with -t a, -L or -l for seconds")]
    DateTime,
    #[error("unexpected trailing text '{0}'")]
    Trailing(String),
    #[error("{0}")]
    BadFrame(#[from] FrameError),
}

/// The `seconds.micros` inside a candump time column's parentheses (`-l`, `-L`, `-t a`).
pub(crate) fn parse_timestamp(ts: &str) -> Result<Duration, LineError> {
    let (secs, micros) = ts.split_once('.').ok_or(LineError::Timestamp)?;
    if secs.is_empty() || secs.len() > 20 || !secs.bytes().all(|b| b.is_ascii_digit()) {
        return Err(LineError::Timestamp);
    }
    if micros.len() != 6 || !micros.bytes().all(|b| b.is_ascii_digit()) {
        return Err(LineError::Micros);
    }
    let secs: u64 = secs.parse().map_err(|_| LineError::Timestamp)?;
    let micros: u32 = micros.parse().map_err(|_| LineError::Micros)?;
    Ok(Duration::new(secs, micros * 1000))
}

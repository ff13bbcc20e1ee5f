//! candump log files (`candump -l` format): `(1436509052.249713) vcan0 044#2A366C2BBA`.
//!
//! Output is exactly that format: seconds zero-padded to 10 digits, 6-digit microseconds, 3 hex
//! digits for standard ids and 8 for extended ids, uppercase hex data, remote frames as `#R`.
//! Input also accepts an optional trailing ` R`/` T` (receive/transmit direction) and lower-case
//! hex; a malformed line is an error naming its line number. CAN FD lines (`##`) are rejected.
//! [`LogReader::any_format`] also reads candump's screen output ([`super::candump_screen`]).

use super::frame::{CanFrame, FrameError};
use embedded_can::Frame as _;
use std::fmt::Write as _;
use std::io::{self, BufRead, Write};
use std::time::Duration;
use thiserror::Error;

/// Direction flag of newer candump logs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    Rx,
    Tx,
}

/// One log line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogRecord {
    /// Time since the Unix epoch (microsecond resolution).
    pub timestamp: Duration,
    pub iface: String,
    pub frame: CanFrame,
    pub direction: Option<Direction>,
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

/// A log error naming the file position.
#[derive(Debug, Error)]
pub enum LogError {
    #[error("line {line}: {kind}")]
    Line { line: usize, kind: LineError },
    #[error("reading log: {0}")]
    Io(#[from] io::Error),
}

fn hex_val(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'a'..=b'f' => Some(c - b'a' + 10),
        b'A'..=b'F' => Some(c - b'A' + 10),
        _ => None,
    }
}

fn parse_hex_u32(s: &str) -> Option<u32> {
    if s.is_empty() || s.len() > 8 {
        return None;
    }
    s.bytes()
        .try_fold(0u32, |acc, c| Some(acc << 4 | u32::from(hex_val(c)?)))
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

/// Parses one line of a candump log.
pub fn parse_line(line: &str) -> Result<LogRecord, LineError> {
    let line = line.trim_end_matches(['\r', '\n']);
    let rest = line.strip_prefix('(').ok_or(LineError::Timestamp)?;
    let close = rest.find(')').ok_or(LineError::Timestamp)?;
    let timestamp = parse_timestamp(&rest[..close])?;

    let mut fields = rest[close + 1..].split_ascii_whitespace();
    let iface = fields.next().ok_or(LineError::Iface)?;
    let frame_txt = fields.next().ok_or(LineError::Frame)?;
    let direction = match fields.next() {
        None => None,
        Some("R") => Some(Direction::Rx),
        Some("T") => Some(Direction::Tx),
        Some(other) => return Err(LineError::Trailing(other.to_string())),
    };
    if let Some(extra) = fields.next() {
        return Err(LineError::Trailing(extra.to_string()));
    }
    if iface.contains('#') {
        return Err(LineError::Iface);
    }
    let (id_txt, data_txt) = frame_txt.split_once('#').ok_or(LineError::Frame)?;
    if data_txt.starts_with('#') {
        return Err(LineError::CanFd);
    }
    let id = parse_hex_u32(id_txt).ok_or_else(|| LineError::Id(id_txt.to_string()))?;
    let frame = if let Some(r) = data_txt.strip_prefix('R') {
        let dlc = match r {
            "" => 0,
            d if d.len() == 1 => usize::from(
                hex_val(d.as_bytes()[0]).ok_or_else(|| LineError::Data(data_txt.into()))?,
            ),
            _ => return Err(LineError::Data(data_txt.to_string())),
        };
        let fid = if id_txt.len() == 3 {
            CanFrame::standard(id as u16, &[])?.id()
        } else {
            CanFrame::extended(id, &[])?.id()
        };
        CanFrame::remote(fid, dlc)?
    } else {
        let bytes = data_txt.as_bytes();
        if bytes.len() % 2 != 0 || bytes.len() > 16 {
            return Err(LineError::Data(data_txt.to_string()));
        }
        let mut data = [0u8; 8];
        for (i, pair) in bytes.chunks(2).enumerate() {
            let hi = hex_val(pair[0]).ok_or_else(|| LineError::Data(data_txt.into()))?;
            let lo = hex_val(pair[1]).ok_or_else(|| LineError::Data(data_txt.into()))?;
            data[i] = hi << 4 | lo;
        }
        let data = &data[..bytes.len() / 2];
        match id_txt.len() {
            3 if id <= 0x7FF => CanFrame::standard(id as u16, data)?,
            8 => CanFrame::extended(id, data)?,
            _ => return Err(LineError::Id(id_txt.to_string())),
        }
    };
    Ok(LogRecord {
        timestamp,
        iface: iface.to_string(),
        frame,
        direction,
    })
}

/// Formats one record exactly as `candump -l` does (no direction flag unless the record has one).
pub fn format_record(r: &LogRecord) -> String {
    let mut s = String::with_capacity(48);
    push_line(&mut s, r.timestamp, &r.iface, &r.frame, r.direction);
    s
}

/// Appends one `candump -l` line (without the newline) to `s`.
fn push_line(
    s: &mut String,
    timestamp: Duration,
    iface: &str,
    frame: &CanFrame,
    direction: Option<Direction>,
) {
    let _ = write!(
        s,
        "({:010}.{:06}) {} ",
        timestamp.as_secs(),
        timestamp.subsec_micros(),
        iface
    );
    if frame.is_extended() {
        let _ = write!(s, "{:08X}#", frame.raw_id());
    } else {
        let _ = write!(s, "{:03X}#", frame.raw_id());
    }
    if frame.is_remote_frame() {
        s.push('R');
        if frame.dlc() > 0 {
            let _ = write!(s, "{:X}", frame.dlc());
        }
    } else {
        for b in frame.bytes() {
            let _ = write!(s, "{b:02X}");
        }
    }
    match direction {
        Some(Direction::Rx) => s.push_str(" R"),
        Some(Direction::Tx) => s.push_str(" T"),
        None => {}
    }
}

/// The time a line without one is stamped with (seconds since the Unix epoch).
pub type ArrivalClock = Box<dyn FnMut() -> Duration>;

/// Reads records from a candump log, one `Result` per non-empty line.
pub struct LogReader<R> {
    input: R,
    line_no: usize,
    buf: String,
    /// `Some`: screen-format lines are read too, stamped by this clock when they carry no time.
    arrival: Option<ArrivalClock>,
}

impl<R: BufRead> LogReader<R> {
    /// Reads `candump -l` / `-L` logs only.
    pub fn new(input: R) -> Self {
        Self {
            input,
            line_no: 0,
            buf: String::new(),
            arrival: None,
        }
    }

    /// Reads `candump -l` / `-L` lines and candump's screen output (`candump vcan0`, `-t a`,
    /// `-t z`, `-x`, `-a`); a screen line without a time is stamped with `arrival()` as it is
    /// read, so a live pipe (`candump vcan0 | …`) gets the times the frames came through.
    pub fn any_format(input: R, arrival: ArrivalClock) -> Self {
        Self {
            arrival: Some(arrival),
            ..Self::new(input)
        }
    }

    fn parse(&mut self) -> Result<LogRecord, LineError> {
        let log = parse_line(&self.buf);
        let Some(arrival) = self.arrival.as_mut() else {
            return log;
        };
        if log.is_ok() || self.buf.contains('#') {
            return log;
        }
        let s = super::candump_screen::parse_screen_line(&self.buf)?;
        Ok(LogRecord {
            timestamp: s.timestamp.unwrap_or_else(arrival),
            iface: s.iface,
            frame: s.frame,
            direction: s.direction,
        })
    }
}

impl<R: BufRead> Iterator for LogReader<R> {
    type Item = Result<LogRecord, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            self.buf.clear();
            self.line_no += 1;
            match self.input.read_line(&mut self.buf) {
                Ok(0) => return None,
                Ok(_) => {}
                Err(e) if e.kind() == io::ErrorKind::InvalidData => {
                    return Some(Err(LogError::Line {
                        line: self.line_no,
                        kind: LineError::Timestamp,
                    }))
                }
                Err(e) => return Some(Err(e.into())),
            }
            if self.buf.trim().is_empty() {
                continue;
            }
            let line = self.line_no;
            return Some(self.parse().map_err(|kind| LogError::Line { line, kind }));
        }
    }
}

/// Writes records in `candump -l` format; flushes on [`LogWriter::flush`] and on drop.
pub struct LogWriter<W: Write> {
    out: W,
    /// The line being written, reused (no allocation per frame).
    line: String,
}

impl<W: Write> LogWriter<W> {
    pub fn new(out: W) -> Self {
        Self {
            out,
            line: String::with_capacity(64),
        }
    }
    pub fn write(&mut self, r: &LogRecord) -> io::Result<()> {
        self.write_frame(r.timestamp, &r.iface, &r.frame, r.direction)
    }
    /// Writes one frame without building a [`LogRecord`].
    pub fn write_frame(
        &mut self,
        timestamp: Duration,
        iface: &str,
        frame: &CanFrame,
        direction: Option<Direction>,
    ) -> io::Result<()> {
        self.line.clear();
        push_line(&mut self.line, timestamp, iface, frame, direction);
        self.line.push('\n');
        self.out.write_all(self.line.as_bytes())
    }
    pub fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }
    pub fn into_inner(self) -> W {
        self.out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: &str = "(1436509052.249713) vcan0 044#2A366C2BBA";

    #[test]
    fn round_trips_the_reference_line() {
        let r = parse_line(SAMPLE).unwrap();
        assert_eq!(r.timestamp, Duration::new(1436509052, 249_713_000));
        assert_eq!(r.iface, "vcan0");
        assert_eq!(r.frame.raw_id(), 0x44);
        assert_eq!(r.frame.bytes(), &[0x2A, 0x36, 0x6C, 0x2B, 0xBA]);
        assert_eq!(format_record(&r), SAMPLE);
    }

    #[test]
    fn accepts_variants() {
        let r = parse_line("(0000000001.000001) can1 12345678#deadbeef T\n").unwrap();
        assert!(r.frame.is_extended());
        assert_eq!(r.direction, Some(Direction::Tx));
        assert_eq!(
            format_record(&r),
            "(0000000001.000001) can1 12345678#DEADBEEF T"
        );
        let r = parse_line("(1.000000) vcan0 123#").unwrap();
        assert_eq!(r.frame.dlc(), 0);
        assert_eq!(format_record(&r), "(0000000001.000000) vcan0 123#");
        let r = parse_line("(1.000000) vcan0 123#R4 R").unwrap();
        assert!(r.frame.is_remote_frame());
        assert_eq!(format_record(&r), "(0000000001.000000) vcan0 123#R4 R");
    }

    #[test]
    fn rejects_with_reasons() {
        for (line, want) in [
            ("1436509052.249713 vcan0 044#2A", LineError::Timestamp),
            ("(1436509052.2497) vcan0 044#2A", LineError::Micros),
            ("(1.000000)", LineError::Iface),
            ("(1.000000) vcan0", LineError::Frame),
            ("(1.000000) vcan0 44#2A", LineError::Id("44".into())),
            ("(1.000000) vcan0 800#2A", LineError::Id("800".into())),
            ("(1.000000) vcan0 044#2A3", LineError::Data("2A3".into())),
            (
                "(1.000000) vcan0 044#000000000000000000",
                LineError::Data("000000000000000000".into()),
            ),
            ("(1.000000) vcan0 044##1AA", LineError::CanFd),
            ("(1.000000) vcan0 044#2A X", LineError::Trailing("X".into())),
        ] {
            assert_eq!(parse_line(line), Err(want), "{line}");
        }
    }

    #[test]
    fn any_format_reads_log_and_screen_lines_and_stamps_untimed_ones_on_arrival() {
        let text = format!(
            "{SAMPLE}\n  vcan0  130   [1]  07\n (1.000002)  vcan0  131   [0]  \n  vcan0  132  [1]\n"
        );
        let mut tick = 0u64;
        let clock = Box::new(move || {
            tick += 1;
            Duration::from_secs(100 + tick)
        });
        let items: Vec<_> = LogReader::any_format(text.as_bytes(), clock).collect();
        let r: Vec<_> = items[..3].iter().map(|i| i.as_ref().unwrap()).collect();
        assert_eq!(r[0].timestamp, Duration::new(1436509052, 249_713_000));
        assert_eq!(
            (r[1].frame.raw_id(), r[1].timestamp),
            (0x130, Duration::from_secs(101))
        );
        assert_eq!(r[2].timestamp, Duration::new(1, 2000));
        match &items[3] {
            Err(LogError::Line { line, kind }) => {
                assert_eq!((*line, kind), (4, &LineError::Short { have: 0, dlc: 1 }))
            }
            other => panic!("{other:?}"),
        }
        // The strict reader refuses screen lines.
        assert!(LogReader::new("  vcan0  130   [1]  07\n".as_bytes())
            .next()
            .unwrap()
            .is_err());
    }

    #[test]
    fn reader_names_lines() {
        let text = format!("{SAMPLE}\n\n{SAMPLE}\ngarbage\n");
        let items: Vec<_> = LogReader::new(text.as_bytes()).collect();
        assert_eq!(items.len(), 3);
        assert!(items[0].is_ok() && items[1].is_ok());
        match &items[2] {
            Err(LogError::Line { line, .. }) => assert_eq!(*line, 4),
            other => panic!("{other:?}"),
        }
    }
}

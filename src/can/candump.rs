//! candump log files (`candump -l` format): `(1436509052.249713) vcan0 044#2A366C2BBA`.
//!
//! Output is exactly that format: seconds zero-padded to 10 digits, 6-digit microseconds, 3 hex
//! digits for standard ids and 8 for extended ids, uppercase hex data, remote frames as `#R`.
//! Input also accepts an optional trailing ` R`/` T` (receive/transmit direction) and lower-case
//! hex; a malformed line is an error naming its line number. CAN FD lines (`##`) are rejected.
//! [`LogReader::any_format`] also reads candump's screen output ([`super::candump_screen`]).
//! [`LogReader`] reads the log in large blocks and parses a line in the form candump writes in
//! place ([`parse_canonical`]); any other line goes through [`parse_line`] with its reasons.

use super::candump_line::parse_timestamp;
pub use super::candump_line::{Direction, LineError};
use super::frame::CanFrame;
use super::lines::BlockLines;
use embedded_can::Frame as _;
use std::fmt::Write as _;
use std::io::{self, Read, Write};
use std::time::Duration;
use thiserror::Error;

/// One log line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogRecord {
    /// Time since the Unix epoch (microsecond resolution).
    pub timestamp: Duration,
    pub iface: String,
    pub frame: CanFrame,
    pub direction: Option<Direction>,
}

/// One log line read without copying its interface name (see [`LogReader::next_ref`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecordRef<'a> {
    /// Time since the Unix epoch (microsecond resolution).
    pub timestamp: Duration,
    pub iface: &'a str,
    pub frame: CanFrame,
    pub direction: Option<Direction>,
}

impl RecordRef<'_> {
    /// The record with its own copy of the interface name.
    pub fn to_record(&self) -> LogRecord {
        LogRecord {
            timestamp: self.timestamp,
            iface: self.iface.to_string(),
            frame: self.frame,
            direction: self.direction,
        }
    }
}

impl LogRecord {
    /// The record as a [`RecordRef`].
    pub fn view(&self) -> RecordRef<'_> {
        RecordRef {
            timestamp: self.timestamp,
            iface: &self.iface,
            frame: self.frame,
            direction: self.direction,
        }
    }
}

/// A log error naming the file position.
#[derive(Debug, Error)]
pub enum LogError {
    #[error("line {line}: {kind}")]
    Line { line: usize, kind: LineError },
    /// Not an error of the log: the logger before us lost `frames` frames here (a `candump -d`
    /// `DROPCOUNT` line), so a counter gap after it may be missing input rather than the bus's.
    #[error("line {line}: the logger lost {frames} frame(s) here (DROPCOUNT)")]
    InputLost { line: usize, frames: u64 },
    #[error("reading log: {0}")]
    Io(#[from] io::Error),
}

/// The frames a `candump -d` `DROPCOUNT` line reports lost ("DROPCOUNT: dropped 3 CAN frames on
/// 'vcan0' socket (total drops 7)"); `None` for any other line.
pub(crate) fn dropcount(line: &str) -> Option<u64> {
    let rest = line.trim().strip_prefix("DROPCOUNT: dropped ")?;
    rest.split_whitespace().next()?.parse().ok()
}

/// The value of each byte as a hex digit (either case); `NOT_HEX` for the others.
const HEX_DIGITS: [u8; 256] = {
    let mut t = [NOT_HEX; 256];
    let mut c = 0;
    while c < 10 {
        t[b'0' as usize + c] = c as u8;
        c += 1;
    }
    let mut c = 0;
    while c < 6 {
        t[b'a' as usize + c] = 10 + c as u8;
        t[b'A' as usize + c] = 10 + c as u8;
        c += 1;
    }
    t
};
const NOT_HEX: u8 = 0xFF;

fn hex_val(c: u8) -> Option<u8> {
    let v = HEX_DIGITS[usize::from(c)];
    (v != NOT_HEX).then_some(v)
}

fn parse_hex_u32(s: &str) -> Option<u32> {
    if s.is_empty() || s.len() > 8 {
        return None;
    }
    s.bytes()
        .try_fold(0u32, |acc, c| Some(acc << 4 | u32::from(hex_val(c)?)))
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

/// Parses a line in the form `candump -l` (and [`format_record`]) writes it, without allocating:
/// `(SECONDS.MICROS) IFACE ID#DATA` with an optional ` R`/` T`, one space between the fields,
/// 3 hex digits of a standard id or 8 of an extended one, and the line end (`\n`, `\r\n`).
/// `None` for any other line, which [`parse_line`] judges with its reasons; on every line this
/// accepts, [`parse_line`] gives the same record.
pub fn parse_canonical(line: &[u8]) -> Option<RecordRef<'_>> {
    let line = line.strip_suffix(b"\n").unwrap_or(line);
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    let (timestamp, rest) = canonical_timestamp(line.strip_prefix(b"(")?)?;
    let (iface, rest) = canonical_iface(rest)?;
    let (frame, rest) = canonical_frame(rest)?;
    let direction = match rest {
        b"" => None,
        b" R" => Some(Direction::Rx),
        b" T" => Some(Direction::Tx),
        _ => return None,
    };
    Some(RecordRef {
        timestamp,
        iface,
        frame,
        direction,
    })
}

/// `SECONDS.MICROS) ` (1 to 19 digits of seconds, 6 of microseconds) and what follows it.
fn canonical_timestamp(s: &[u8]) -> Option<(Duration, &[u8])> {
    let int_digits = s.iter().take(20).take_while(|c| c.is_ascii_digit()).count();
    if int_digits == 0 || int_digits > 19 {
        return None;
    }
    let (secs, rest) = s.split_at(int_digits);
    let (frac, rest) = rest.split_first_chunk::<9>()?;
    if frac[0] != b'.' || frac[7..] != *b") " {
        return None;
    }
    let micros = decimal(&frac[1..7])?;
    Some((Duration::new(decimal(secs)?, micros as u32 * 1000), rest))
}

/// The value of a run of decimal digits (at most 19: no overflow).
fn decimal(digits: &[u8]) -> Option<u64> {
    digits.iter().try_fold(0u64, |acc, c| {
        c.is_ascii_digit().then(|| acc * 10 + u64::from(c - b'0'))
    })
}

/// `IFACE ` (printable ASCII but `#`) and what follows it.
fn canonical_iface(s: &[u8]) -> Option<(&str, &[u8])> {
    let len = s
        .iter()
        .take_while(|c| c.is_ascii_graphic() && **c != b'#')
        .count();
    let (name, rest) = s.split_at(len);
    if len == 0 {
        return None;
    }
    Some((std::str::from_utf8(name).ok()?, rest.strip_prefix(b" ")?))
}

/// `ID#DATA` (3 hex digits of an id up to 7FF, or 8 up to 1FFFFFFF; pairs of hex digits, at
/// most 8) as a data frame, and what follows it.
fn canonical_frame(s: &[u8]) -> Option<(CanFrame, &[u8])> {
    let id_len = s
        .iter()
        .take(9)
        .take_while(|c| hex_val(**c).is_some())
        .count();
    let id = s[..id_len].iter().fold(0u32, |acc, c| {
        acc << 4 | u32::from(HEX_DIGITS[usize::from(*c)])
    });
    let mut rest = s[id_len..].strip_prefix(b"#")?;
    let mut data = [0u8; 8];
    let mut len = 0;
    while let [hi, lo, tail @ ..] = rest {
        let (Some(hi), Some(lo)) = (hex_val(*hi), hex_val(*lo)) else {
            break;
        };
        *data.get_mut(len)? = hi << 4 | lo;
        len += 1;
        rest = tail;
    }
    let frame = match id_len {
        3 if id <= 0x7FF => CanFrame::standard(id as u16, &data[..len]).ok()?,
        8 => CanFrame::extended(id, &data[..len]).ok()?,
        _ => return None,
    };
    Some((frame, rest))
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
pub(crate) type ArrivalClock = Box<dyn FnMut() -> Duration>;

/// Reads records from a candump log, one `Result` per non-empty line. The log is read in large
/// blocks; a line in the form candump writes is parsed in place ([`parse_canonical`]), any other
/// by [`parse_line`] (and the screen parser with [`LogReader::any_format`]).
pub struct LogReader<R> {
    lines: BlockLines<R>,
    /// `Some`: screen-format lines are read too, stamped by this clock when they carry no time.
    arrival: Option<ArrivalClock>,
    /// The record of the last line outside the canonical form.
    other: Option<LogRecord>,
}

impl<R: Read> LogReader<R> {
    /// Reads `candump -l` / `-L` logs only.
    pub fn new(input: R) -> Self {
        Self {
            lines: BlockLines::new(input),
            arrival: None,
            other: None,
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

    /// The next record, its interface name borrowed from the reader (no allocation for a line
    /// in the canonical form); `None` at the end of the log.
    pub fn next_ref(&mut self) -> Option<Result<RecordRef<'_>, LogError>> {
        let (line_no, range) = match self.next_nonblank() {
            Ok(Some(line)) => line,
            Ok(None) => return None,
            Err(e) => return Some(Err(e.into())),
        };
        let line = self.lines.get(range);
        if let Some(r) = parse_canonical(line) {
            return Some(Ok(r));
        }
        if let Some(frames) = std::str::from_utf8(line).ok().and_then(dropcount) {
            return Some(Err(LogError::InputLost {
                line: line_no,
                frames,
            }));
        }
        // Not UTF-8: what reading it as a line of text reported.
        let parsed = std::str::from_utf8(line)
            .map_err(|_| LineError::Timestamp)
            .and_then(|text| parse_other(text, self.arrival.as_mut()));
        Some(match parsed {
            Ok(r) => Ok(self.other.insert(r).view()),
            Err(kind) => Err(LogError::Line {
                line: line_no,
                kind,
            }),
        })
    }

    /// The next line that is not blank (only white space), with its number.
    fn next_nonblank(&mut self) -> io::Result<Option<(usize, std::ops::Range<usize>)>> {
        loop {
            let Some((no, range)) = self.lines.next_line()? else {
                return Ok(None);
            };
            if !is_blank(self.lines.get(range.clone())) {
                return Ok(Some((no, range)));
            }
        }
    }
}

/// Whether a line is white space only (a line that is not UTF-8 is not).
fn is_blank(line: &[u8]) -> bool {
    match line.first() {
        Some(b) if b.is_ascii() && !b.is_ascii_whitespace() => false,
        _ => std::str::from_utf8(line).is_ok_and(|s| s.trim().is_empty()),
    }
}

/// A line outside the canonical form: [`parse_line`]'s verdict, or with `arrival` (screen
/// format read too) the screen parser's for a line without `#`, stamped by `arrival` when it
/// carries no time.
fn parse_other(line: &str, arrival: Option<&mut ArrivalClock>) -> Result<LogRecord, LineError> {
    let log = parse_line(line);
    let Some(arrival) = arrival else {
        return log;
    };
    if log.is_ok() || line.contains('#') {
        return log;
    }
    let s = super::candump_screen::parse_screen_line(line)?;
    Ok(LogRecord {
        timestamp: s.timestamp.unwrap_or_else(arrival),
        iface: s.iface,
        frame: s.frame,
        direction: s.direction,
    })
}

impl<R: Read> Iterator for LogReader<R> {
    type Item = Result<LogRecord, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_ref().map(|r| r.map(|r| r.to_record()))
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

    /// candump -d's drop notices (can-utils candump.c) are the logger's losses, with their line.
    #[test]
    fn dropcount_lines_are_input_losses() {
        assert_eq!(
            dropcount("DROPCOUNT: dropped 3 CAN frames on 'vcan0' socket (total drops 7)"),
            Some(3)
        );
        assert_eq!(
            dropcount("DROPCOUNT: dropped 1 CAN frame on 'vcan0' socket (total drops 1)"),
            Some(1)
        );
        assert_eq!(dropcount("(1.0) vcan0 100#00"), None);
        let log = "  vcan0  100   [1]  00\nDROPCOUNT: dropped 2 CAN frames on 'vcan0' socket (total drops 2)\n  vcan0  100   [1]  01\n";
        let mut r = LogReader::any_format(log.as_bytes(), Box::new(|| Duration::ZERO));
        assert!(r.next().unwrap().is_ok());
        match r.next().unwrap() {
            Err(LogError::InputLost { line: 2, frames: 2 }) => {}
            other => panic!("{other:?}"),
        }
        assert!(r.next().unwrap().is_ok());
    }

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

    /// xorshift64*: a seeded stream of test inputs.
    struct Rng(u64);
    impl Rng {
        fn below(&mut self, n: usize) -> usize {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 33) as usize % n
        }
    }

    #[test]
    fn canonical_lines_parse_in_place_as_parse_line_parses_them() {
        let lines = [
            SAMPLE.to_string(),
            "(0000000001.000001) can1 12345678#deadbeef T\n".into(),
            "(1.000000) vcan0 123#\r\n".into(),
            "(1.000000) vcan0 7FF#0011223344556677 R".into(),
            "(9999999999999999999.999999) a)b 000#00".into(),
        ];
        for line in &lines {
            let r = parse_canonical(line.as_bytes()).expect(line);
            assert_eq!(Ok(r.to_record()), parse_line(line), "{line}");
        }
        // Mutations of canonical lines: whatever the in-place parser accepts, parse_line reads
        // the same; every line candump writes it accepts.
        let alphabet = b"0123456789abcdefABCDEFR#(). \t\r\n-xT";
        let mut rng = Rng(0x5DEE_CE66);
        let mut accepted = 0;
        for _ in 0..200_000 {
            let mut line = lines[rng.below(lines.len())].clone().into_bytes();
            for _ in 0..=rng.below(3) {
                let pos = rng.below(line.len() + 1);
                let c = alphabet[rng.below(alphabet.len())];
                match rng.below(3) {
                    0 => line.insert(pos, c),
                    1 if pos < line.len() => line[pos] = c,
                    _ if pos < line.len() => {
                        line.remove(pos);
                    }
                    _ => {}
                }
            }
            let text = String::from_utf8(line).unwrap();
            if let Some(r) = parse_canonical(text.as_bytes()) {
                assert_eq!(Ok(r.to_record()), parse_line(&text), "{text:?}");
                assert_eq!(
                    parse_canonical(format_record(&r.to_record()).as_bytes()),
                    Some(r)
                );
                accepted += 1;
            }
        }
        assert!(accepted > 10_000, "{accepted}");
    }

    #[test]
    fn lines_outside_the_canonical_form_keep_parse_line_s_verdict() {
        for line in [
            "(1.000000)  vcan0 123#00",
            "(1.000000) vcan0 123#00 ",
            "(1.000000) vcan0 123#R",
            "(1.000000) vcan0 800#00",
            "(1.000000) vcan0 1234#00",
            "(1.000000) vcan0 3FFFFFFF#00",
            "(00000000000000000001.000000) vcan0 123#00",
            "(1.000000) vcan0 123#0011223344556677889",
            "(1.000000)\tvcan0 123#00",
        ] {
            assert_eq!(parse_canonical(line.as_bytes()), None, "{line}");
        }
        // The general parser still reads the ones that are valid.
        let r = LogReader::new("(1.000000)  vcan0 123#00\n(1.000000) vcan0 123#R2\n".as_bytes());
        let ids: Vec<_> = r.map(|r| r.unwrap().frame.raw_id()).collect();
        assert_eq!(ids, [0x123, 0x123]);
    }

    #[test]
    fn reader_skips_blank_lines_and_names_lines_that_are_not_text() {
        let mut bytes = format!("{SAMPLE}\n \t\n\u{a0}\u{2003}\r\n").into_bytes();
        bytes.extend_from_slice(b"(1.000000) vcan0 \xff#00\n\n");
        bytes.extend_from_slice(SAMPLE.as_bytes());
        let mut reader = LogReader::new(&bytes[..]);
        let first = reader.next_ref().unwrap().unwrap();
        assert_eq!(first.iface, "vcan0");
        match reader.next_ref() {
            Some(Err(LogError::Line { line: 4, kind })) => assert_eq!(kind, LineError::Timestamp),
            other => panic!("{other:?}"),
        }
        assert_eq!(reader.next().unwrap().unwrap(), parse_line(SAMPLE).unwrap());
        assert!(reader.next_ref().is_none());
    }
}

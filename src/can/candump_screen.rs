//! candump's screen formats, what `candump vcan0` prints when not logging:
//! `  vcan0  123   [8]  11 22 33 44 55 66 77 88`, optionally after a `(seconds.micros)` time
//! (`-t a`, `-t z`; `-t d` deltas are read as given), with `-x`'s `RX`/`TX` and flag columns
//! and `-a`'s trailing ASCII column. Remote frames read `remote request`. `-t A` dates and CAN FD
//! lengths (`[08]`) are refused naming why. A line without a time has none: the reader stamps it
//! on arrival ([`super::candump::LogReader::any_format`]).

use super::candump_line::{parse_timestamp, Direction, LineError};
use super::frame::CanFrame;
use embedded_can::Frame as _;
use std::time::Duration;

/// One screen-format line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct ScreenLine {
    /// The `(seconds.micros)` column when candump printed one (`-t a` or `-t z`).
    pub timestamp: Option<Duration>,
    pub iface: String,
    pub frame: CanFrame,
    pub direction: Option<Direction>,
}

fn hex_byte(t: &str) -> Option<u8> {
    (t.len() == 2).then(|| u8::from_str_radix(t, 16).ok())?
}

/// `seconds.micros` inside the parentheses of `-t a` / `-t z`.
fn parse_time(t: &str) -> Result<Duration, LineError> {
    if t.contains(['-', ':', ' ']) {
        return Err(LineError::DateTime);
    }
    parse_timestamp(t)
}

/// Parses one line of candump's screen output.
pub(crate) fn parse_screen_line(line: &str) -> Result<ScreenLine, LineError> {
    let line = line.trim();
    let (timestamp, rest) = match line.strip_prefix('(') {
        Some(r) => {
            let close = r.find(')').ok_or(LineError::Timestamp)?;
            (Some(parse_time(&r[..close])?), &r[close + 1..])
        }
        None => (None, line),
    };
    let mut tokens = rest.split_ascii_whitespace().peekable();
    let iface = tokens.next().ok_or(LineError::Iface)?;
    let direction = match tokens.peek().copied() {
        Some("RX") => Some(Direction::Rx),
        Some("TX") => Some(Direction::Tx),
        _ => None,
    };
    if direction.is_some() {
        tokens.next();
        // `-x` flag columns: one character each (`-`, `B`, `E`, `L`); ids have 3 or 8.
        while tokens.peek().is_some_and(|t| t.len() == 1) {
            tokens.next();
        }
    }
    let id_txt = tokens.next().ok_or(LineError::Frame)?;
    let id = u32::from_str_radix(id_txt, 16).map_err(|_| LineError::Id(id_txt.to_string()))?;
    let dlc_txt = tokens.next().ok_or(LineError::Frame)?;
    let dlc_inner = dlc_txt
        .strip_prefix('[')
        .and_then(|t| t.strip_suffix(']'))
        .ok_or_else(|| LineError::Data(dlc_txt.to_string()))?;
    if dlc_inner.len() == 2 {
        return Err(LineError::CanFd);
    }
    let dlc: usize = dlc_inner
        .parse()
        .ok()
        .filter(|n| *n <= 8)
        .ok_or_else(|| LineError::Data(dlc_txt.to_string()))?;
    let make_id = |data: &[u8]| match id_txt.len() {
        3 if id <= 0x7FF => Ok(CanFrame::standard(id as u16, data)?),
        8 => Ok(CanFrame::extended(id, data)?),
        _ => Err(LineError::Id(id_txt.to_string())),
    };
    let frame = if tokens.peek() == Some(&"remote") {
        tokens.next();
        if tokens.next() != Some("request") {
            return Err(LineError::Data("remote".into()));
        }
        CanFrame::remote(make_id(&[])?.id(), dlc)?
    } else {
        let mut data = [0u8; 8];
        for (i, d) in data.iter_mut().enumerate().take(dlc) {
            let t = tokens.next().ok_or(LineError::Short { have: i, dlc })?;
            *d = hex_byte(t).ok_or_else(|| LineError::Data(t.to_string()))?;
        }
        make_id(&data[..dlc])?
    };
    // `-a`: the bytes again as ASCII in quotes; it may contain spaces, so it ends the line.
    if let Some(t) = tokens.next() {
        if !t.starts_with('\'') {
            return Err(LineError::Trailing(t.to_string()));
        }
    }
    Ok(ScreenLine {
        timestamp,
        iface: iface.to_string(),
        frame,
        direction,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    // Lines as candump (can-utils 2023.03) prints them; tests/hil checks a live one.
    #[test]
    fn reads_candumps_default_output() {
        let l = parse_screen_line("  vcan0  130   [8]  2A 36 6C 2B BA 00 01 FF").unwrap();
        assert_eq!(l.timestamp, None);
        assert_eq!(l.iface, "vcan0");
        assert_eq!(l.frame.raw_id(), 0x130);
        assert_eq!(
            l.frame.bytes(),
            &[0x2A, 0x36, 0x6C, 0x2B, 0xBA, 0x00, 0x01, 0xFF]
        );
        let l = parse_screen_line("  vcan0  12345678   [0]  ").unwrap();
        assert!(l.frame.is_extended());
        assert_eq!(l.frame.dlc(), 0);
    }

    #[test]
    fn reads_times_directions_ascii_and_remote_frames() {
        let l = parse_screen_line(" (1436509052.249713)  vcan0  044   [2]  2A 36   '*6'").unwrap();
        assert_eq!(l.timestamp, Some(Duration::new(1436509052, 249_713_000)));
        assert_eq!(l.frame.bytes(), &[0x2A, 0x36]);
        let l = parse_screen_line("  vcan0  TX - -  123   [1]  05").unwrap();
        assert_eq!(l.direction, Some(Direction::Tx));
        assert_eq!(l.frame.bytes(), &[5]);
        let l = parse_screen_line("  vcan0  123   [4]  remote request").unwrap();
        assert!(l.frame.is_remote_frame());
        assert_eq!(l.frame.dlc(), 4);
    }

    #[test]
    fn refuses_with_reasons() {
        for (line, want) in [
            (
                "  vcan0  130   [08]  00 00 00 00 00 00 00 00",
                LineError::CanFd,
            ),
            (
                "  vcan0  130   [3]  00 00",
                LineError::Short { have: 2, dlc: 3 },
            ),
            ("  vcan0  130   [9]  00", LineError::Data("[9]".into())),
            ("  vcan0  13   [1]  00", LineError::Id("13".into())),
            ("  vcan0  800   [1]  00", LineError::Id("800".into())),
            ("  vcan0  130   [1]  0G", LineError::Data("0G".into())),
            (
                "  vcan0  130   [1]  00 11",
                LineError::Trailing("11".into()),
            ),
            (
                "(2015-07-10 08:17:32.249713)  vcan0  130   [1]  00",
                LineError::DateTime,
            ),
            ("", LineError::Iface),
            ("  vcan0", LineError::Frame),
        ] {
            assert_eq!(parse_screen_line(line), Err(want), "{line:?}");
        }
    }
}

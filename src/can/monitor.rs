//! The state behind `ddct log monitor`: per message of the bus, the latest decoded values
//! (enumerations by name: TcuState, gears, fault codes), the frame count, the rate over the last
//! second, the E2E errors by kind and the age of the last frame. Pure: frames go in with their
//! time, a snapshot comes out as text; the shell reads the bus or stdin and redraws.

use super::codec::DecodedSignal;
use super::decode::{DecodedFrame, E2eVerdict};
use std::collections::{BTreeMap, VecDeque};
use std::fmt::Write as _;
use std::time::Duration;

/// One message's line of the monitor.
#[derive(Debug, Clone, Default)]
struct Entry {
    name: &'static str,
    frames: u64,
    /// Arrival times within the last second (for the rate).
    recent: VecDeque<Duration>,
    last: Duration,
    /// The latest frame's signals (formatted only when drawn: the bus is faster than the screen).
    signals: Vec<DecodedSignal>,
    /// E2E failures by kind (`bad_crc`, `counter_jump`, …).
    e2e_errors: BTreeMap<&'static str, u64>,
    /// Frames the strict decode refused (DLC, range, value table).
    decode_errors: u64,
    /// Counter gaps the input's own losses explain (not the bus's errors).
    missing_input: u64,
}

/// Latest values and statistics per CAN id.
#[derive(Debug, Default)]
pub struct Monitor {
    by_id: BTreeMap<u32, Entry>,
}

const WINDOW: Duration = Duration::from_secs(1);

impl Monitor {
    /// Takes one decoded frame.
    pub fn push(&mut self, d: &DecodedFrame) {
        let e = self.by_id.entry(d.id).or_default();
        e.name = d.message.map_or("(not in the DBC)", |m| m.name);
        e.frames += 1;
        e.last = d.timestamp;
        e.recent.push_back(d.timestamp);
        while e
            .recent
            .front()
            .is_some_and(|t| d.timestamp.saturating_sub(*t) > WINDOW)
        {
            e.recent.pop_front();
        }
        match d.e2e {
            E2eVerdict::Failed(err) => *e.e2e_errors.entry(err.kind()).or_default() += 1,
            E2eVerdict::MissingInput { .. } => e.missing_input += 1,
            _ => {}
        }
        e.decode_errors += u64::from(d.error.is_some());
        e.signals.clear();
        e.signals.extend_from_slice(&d.signals);
    }

    /// Frames of `id` within the last second before `now` (frames per second).
    pub fn rate(&self, id: u32, now: Duration) -> f64 {
        self.by_id.get(&id).map_or(0.0, |e| {
            e.recent
                .iter()
                .filter(|t| now.saturating_sub(**t) <= WINDOW)
                .count() as f64
        })
    }

    /// The monitor as text at time `now`: one line per message (id, name, frames, rate, age of
    /// the last frame, E2E and decode errors), its latest values indented below.
    pub fn render(&self, now: Duration) -> String {
        let mut s = format!(
            "{:<4} {:<16} {:>8} {:>7} {:>8}  {}\n",
            "id", "message", "frames", "rate/s", "age ms", "errors"
        );
        for (id, e) in &self.by_id {
            let mut errors: Vec<String> = e
                .e2e_errors
                .iter()
                .map(|(k, n)| format!("{k} {n}"))
                .collect();
            if e.decode_errors > 0 {
                errors.push(format!("decode {}", e.decode_errors));
            }
            if e.missing_input > 0 {
                errors.push(format!("(input lost: {} gap(s))", e.missing_input));
            }
            let age = now.saturating_sub(e.last).as_millis();
            let _ = writeln!(
                s,
                "{id:03X}  {:<16} {:>8} {:>7.0} {:>8}  {}",
                e.name,
                e.frames,
                self.rate(*id, now),
                age,
                if errors.is_empty() {
                    "-".to_string()
                } else {
                    errors.join(", ")
                }
            );
            if !e.signals.is_empty() {
                s.push_str("     ");
                for sig in &e.signals {
                    let unit = sig.signal.unit;
                    let sep = if unit.is_empty() { "" } else { " " };
                    let flag = if sig.in_range { "" } else { "(!)" };
                    let _ = write!(
                        s,
                        " {}={}{sep}{unit}{flag} ",
                        sig.signal.name,
                        sig.display_value()
                    );
                }
                s.truncate(s.trim_end().len());
                s.push('\n');
            }
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::candump::LogRecord;
    use crate::can::decode::LogDecoder;
    use crate::can::e2e::protect;
    use crate::can::frame::CanFrame;
    use crate::can::messages::{ids, TcuState, TcuStatus};

    fn record(t: Duration, data: [u8; 8]) -> LogRecord {
        LogRecord {
            timestamp: t,
            iface: "vcan0".into(),
            frame: CanFrame::standard(ids::TCU_STATUS, &data).unwrap(),
            direction: None,
        }
    }

    /// 150 TCU_Status frames (state Drive) every 10 ms from the generated encoder with E2E, then
    /// one with a corrupted CRC.
    #[test]
    fn counts_rates_errors_and_shows_latest_values_by_name() {
        let mut dec = LogDecoder::default();
        let mut mon = Monitor::default();
        let status = TcuStatus {
            tcu_state: TcuState::Drive,
            ..Default::default()
        };
        let mut t = Duration::ZERO;
        for k in 0..150u64 {
            let mut d = status.encode().unwrap();
            protect(ids::TCU_STATUS, &mut d, (k % 16) as u8);
            t = Duration::from_millis(1000 + 10 * k);
            mon.push(&dec.decode(&record(t, d)));
        }
        let id = u32::from(ids::TCU_STATUS);
        assert_eq!(mon.rate(id, t), 101.0);
        let text = mon.render(t);
        assert!(text.contains("TCU_Status"), "{text}");
        assert!(text.contains("     150 "), "{text}");
        assert!(text.contains("TcuState=Drive"), "{text}");
        assert!(!text.contains("bad_crc"), "{text}");
        let mut d = status.encode().unwrap();
        protect(ids::TCU_STATUS, &mut d, 6);
        d[crate::can::e2e::CRC_BYTE] ^= 0xFF;
        mon.push(&dec.decode(&record(t + Duration::from_millis(10), d)));
        let text = mon.render(t + Duration::from_millis(510));
        assert!(text.contains("bad_crc 1"), "{text}");
        assert!(text.contains("     500  "), "age of the last frame: {text}");
        // Two seconds later the rate has fallen to nothing.
        assert_eq!(mon.rate(id, t + Duration::from_secs(2)), 0.0);
    }
}

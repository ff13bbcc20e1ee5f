//! Decoding logged frames with the contract: every signal's physical value (with labels for
//! enumerations), the strict-decode verdict (DLC, ranges, value tables) and the E2E verdict per
//! frame, plus per-message gaps longer than the E2E timeout.

use super::candump::LogRecord;
use super::codec::{CodecError, DecodedSignal, MessageDef};
use super::e2e::{E2eChecker, E2eConfig, E2eError};
use super::frame::CanFrame;
use super::messages::{message_def, Message};
use embedded_can::Frame as _;
use std::time::Duration;

/// E2E verdict of one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum E2eVerdict {
    Ok,
    NotProtected,
    /// The frame is not a message of the contract (unknown id, extended or remote frame).
    NotInContract,
    Failed(E2eError),
    /// A counter gap the logger's own losses explain ([`InputLoss`]): frames missing from the
    /// input, not an error of the bus.
    MissingInput {
        skipped: u8,
    },
}

impl E2eVerdict {
    /// Short machine-readable name: `ok`, `not_protected`, `not_in_contract`, `bad_crc`, …
    pub fn as_str(&self) -> &'static str {
        match self {
            E2eVerdict::Ok => "ok",
            E2eVerdict::NotProtected => "not_protected",
            E2eVerdict::NotInContract => "not_in_contract",
            E2eVerdict::Failed(e) => e.kind(),
            E2eVerdict::MissingInput { .. } => "missing_input",
        }
    }
}

/// Frames the logger lost before the decoder read them (candump -d's `DROPCOUNT` lines), and
/// the counter gaps they explain: a message's counter gap of k frames after losses of at least
/// k frames since its previous frame is [`E2eVerdict::MissingInput`], not an error of the bus.
#[derive(Debug, Default, Clone)]
pub struct InputLoss {
    /// Frames lost so far.
    total: u64,
    /// Per message id: `total` when its last frame was read.
    seen_at: std::collections::HashMap<u32, u64>,
}

impl InputLoss {
    /// The logger lost `frames` frames here.
    pub fn lost(&mut self, frames: u64) {
        self.total += frames;
    }

    /// Frames lost so far.
    pub fn total(&self) -> u64 {
        self.total
    }

    /// The verdict of a frame of `id` once the losses are accounted for.
    pub fn explain(&mut self, id: u32, verdict: E2eVerdict) -> E2eVerdict {
        let since = self
            .seen_at
            .insert(id, self.total)
            .map_or(0, |at| self.total - at);
        match verdict {
            E2eVerdict::Failed(E2eError::CounterSkipped { skipped, .. })
                if since >= u64::from(skipped) =>
            {
                E2eVerdict::MissingInput { skipped }
            }
            v => v,
        }
    }
}

/// One decoded log frame.
#[derive(Debug, Clone, PartialEq)]
pub struct DecodedFrame {
    pub timestamp: Duration,
    pub iface: String,
    pub id: u32,
    pub message: Option<&'static MessageDef>,
    /// Every signal, decoded leniently (values outside the DBC range are shown and flagged).
    pub signals: Vec<DecodedSignal>,
    pub e2e: E2eVerdict,
    /// Why the strict decode rejected the frame, if it did.
    pub error: Option<CodecError>,
}

/// What [`LogDecoder::track`] finds in a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameFound {
    pub message: Option<&'static MessageDef>,
    pub e2e: E2eVerdict,
}

/// Why the strict decode rejects a frame whose contract message is `message` (`None`: not in
/// the contract), if it does; extended and remote frames are simply outside the contract. A
/// transport message (ISO-TP, XCP: no signals) is never rejected: its bytes, and with an
/// unpadded transfer its length, are the protocol's.
fn strict_error(frame: &CanFrame, message: Option<&MessageDef>) -> Option<CodecError> {
    let id = frame.raw_id();
    match message {
        Some(def) if def.signals.is_empty() => None,
        Some(_) => Message::decode(id, frame.bytes()).err(),
        None => (!frame.is_extended() && !frame.is_remote_frame())
            .then_some(CodecError::UnknownId { id }),
    }
}

/// A message that went silent for longer than the E2E timeout.
#[derive(Debug, Clone, PartialEq)]
pub struct Gap<'a> {
    pub message: &'a str,
    pub from: Duration,
    pub to: Duration,
}

/// The silences of a frame sequence, shared by the built-in and the `--dbc` decoders: per
/// message (`K`: a small number, the id or the index of the message) the time last seen, and
/// every interval of at least `timeout_cycles` of the message's cycle (messages without a cycle
/// are never silent).
#[derive(Debug)]
pub(crate) struct Silences<'a, K> {
    /// By key: the time last seen (a table, not a hash map: one look-up per frame).
    last_seen: Vec<Option<Duration>>,
    gaps: Vec<Gap<'a>>,
    key: std::marker::PhantomData<K>,
}

impl<K> Default for Silences<'_, K> {
    fn default() -> Self {
        Silences {
            last_seen: Vec::new(),
            gaps: Vec::new(),
            key: std::marker::PhantomData,
        }
    }
}

impl<'a, K: Into<usize>> Silences<'a, K> {
    /// Message `key` (named `name`, cycle `cycle_ms`) seen at `t`.
    pub fn seen(&mut self, key: K, name: &'a str, cycle_ms: u64, timeout_cycles: u64, t: Duration) {
        let key = key.into();
        if key >= self.last_seen.len() {
            self.last_seen.resize(key + 1, None);
        }
        let limit = Duration::from_millis(cycle_ms * timeout_cycles);
        if let Some(last) = self.last_seen[key].replace(t) {
            if cycle_ms > 0 && t.saturating_sub(last) >= limit {
                self.gaps.push(Gap {
                    message: name,
                    from: last,
                    to: t,
                });
            }
        }
    }

    /// Silences longer than the timeout seen so far.
    pub fn gaps(&self) -> &[Gap<'a>] {
        &self.gaps
    }
}

/// Stateful decoder of a frame sequence (the E2E counter state carries over between frames).
pub struct LogDecoder {
    checker: Option<E2eChecker>,
    config: E2eConfig,
    silences: Silences<'static, u16>,
    loss: InputLoss,
}

impl Default for LogDecoder {
    fn default() -> Self {
        Self::new(E2eConfig::default())
    }
}

impl LogDecoder {
    pub fn new(config: E2eConfig) -> Self {
        Self {
            checker: None,
            config,
            silences: Silences::default(),
            loss: InputLoss::default(),
        }
    }

    /// The logger before this decoder lost `frames` frames here (a `DROPCOUNT` line).
    pub fn input_lost(&mut self, frames: u64) {
        self.loss.lost(frames);
    }

    /// Frames the logger reported lost so far.
    pub fn frames_lost(&self) -> u64 {
        self.loss.total()
    }

    /// Decodes one record.
    pub fn decode(&mut self, r: &LogRecord) -> DecodedFrame {
        let found = self.track(r.timestamp, &r.frame);
        // A payload of the wrong length has no signals (the strict decode names the error).
        let signals = found
            .message
            .and_then(|def| def.decode_lenient(r.frame.bytes()).ok())
            .unwrap_or_default();
        DecodedFrame {
            timestamp: r.timestamp,
            iface: r.iface.clone(),
            id: r.frame.raw_id(),
            message: found.message,
            signals,
            e2e: found.e2e,
            error: strict_error(&r.frame, found.message),
        }
    }

    /// What [`LogDecoder::decode`] finds in a frame seen at `timestamp` but its signals, the
    /// interface name and the strict decode's error (for output that decodes the signals as it
    /// needs them and shows neither): the contract's message and the E2E verdict. The E2E and
    /// silence tracking advance as with [`LogDecoder::decode`]; no allocation.
    pub fn track(&mut self, timestamp: Duration, frame: &CanFrame) -> FrameFound {
        let id = frame.raw_id();
        let def = (!frame.is_extended() && !frame.is_remote_frame())
            .then(|| message_def(id))
            .flatten();
        let Some(def) = def else {
            return FrameFound {
                message: None,
                e2e: E2eVerdict::NotInContract,
            };
        };
        let checker = self
            .checker
            .get_or_insert_with(|| E2eChecker::all(self.config, timestamp));
        let e2e = if def.e2e {
            let v = match checker.check(timestamp, id, frame.bytes()) {
                Ok(()) => E2eVerdict::Ok,
                Err(e) => E2eVerdict::Failed(e),
            };
            self.loss.explain(id, v)
        } else {
            E2eVerdict::NotProtected
        };
        self.silences.seen(
            def.id,
            def.name,
            u64::from(def.cycle_ms),
            u64::from(self.config.timeout_cycles),
            timestamp,
        );
        FrameFound {
            message: Some(def),
            e2e,
        }
    }

    /// Silences longer than the E2E timeout seen so far.
    pub fn gaps(&self) -> &[Gap<'static>] {
        self.silences.gaps()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::candump::parse_line;
    use crate::can::e2e::E2eSender;
    use crate::can::messages::{ids, EngStatus};
    use crate::can::CanFrame;

    fn rec(t_ms: u64, id: u16, data: &[u8]) -> LogRecord {
        LogRecord {
            timestamp: Duration::from_millis(t_ms),
            iface: "vcan0".into(),
            frame: CanFrame::standard(id, data).unwrap(),
            direction: None,
        }
    }

    /// `track` advances the E2E and silence state as `decode` does and finds the same message
    /// and verdict; `values_into` gives `decode`'s values.
    #[test]
    fn track_and_values_agree_with_decode() {
        let mut tx = E2eSender::new();
        let (mut full, mut tracked) = (LogDecoder::default(), LogDecoder::default());
        let mut values = Vec::new();
        for k in 0..60u64 {
            let mut d = EngStatus {
                eng_speed: 800.0 + k as f64,
                ..Default::default()
            }
            .encode()
            .unwrap();
            // Every seventh frame repeats its counter; a silence after the 30th.
            if k % 7 != 0 {
                tx.protect(ids::ENG_STATUS, &mut d);
            }
            let t = 10 * k + if k > 30 { 500 } else { 0 };
            let frames = [
                rec(t, ids::ENG_STATUS, &d),
                rec(t, ids::BENCH_TORQUE, &d[..(k % 9) as usize]),
                rec(t, 0x7FF, &[1]),
            ];
            for r in &frames {
                let f = full.decode(r);
                let found = tracked.track(r.timestamp, &r.frame);
                assert_eq!((found.message, found.e2e), (f.message, f.e2e));
                values.clear();
                if let Some(def) = found.message {
                    let _ = def.values_into(r.frame.bytes(), &mut values);
                }
                let want: Vec<f64> = f.signals.iter().map(|s| s.value).collect();
                assert_eq!(values, want);
            }
        }
        assert_eq!(tracked.gaps(), full.gaps());
        assert!(!full.gaps().is_empty());
    }

    /// A counter gap the logger's DROPCOUNT explains is missing input; a gap larger than the
    /// frames lost, or one with no loss before it, is still the bus's `counter_skipped`.
    #[test]
    fn counter_gaps_after_input_losses_are_missing_input() {
        let mut tx = E2eSender::new();
        let mut dec = LogDecoder::default();
        let mut next = |skip: u8, t: u64| {
            let mut d = EngStatus::default().encode().unwrap();
            for _ in 0..=skip {
                tx.protect(ids::ENG_STATUS, &mut d);
            }
            rec(t, ids::ENG_STATUS, &d)
        };
        let verdict = |dec: &mut LogDecoder, r: &LogRecord| dec.decode(r).e2e;
        assert_eq!(verdict(&mut dec, &next(0, 0)), E2eVerdict::Ok);
        // The bus skipped two frames, nothing lost on the way: an error of the bus.
        assert_eq!(verdict(&mut dec, &next(2, 10)).as_str(), "counter_skipped");
        // The logger lost three frames, the message skipped two: missing input.
        dec.input_lost(3);
        assert_eq!(
            verdict(&mut dec, &next(2, 20)),
            E2eVerdict::MissingInput { skipped: 2 }
        );
        // The loss is spent on that message: its next gap is the bus's again.
        assert_eq!(verdict(&mut dec, &next(1, 30)).as_str(), "counter_skipped");
        // A gap longer than the frames lost is not explained.
        dec.input_lost(1);
        assert_eq!(verdict(&mut dec, &next(4, 40)).as_str(), "counter_skipped");
        assert_eq!(dec.frames_lost(), 4);
    }

    #[test]
    fn verdicts_and_gaps() {
        let mut tx = E2eSender::new();
        let mut d = EngStatus {
            eng_speed: 800.0,
            ..Default::default()
        }
        .encode()
        .unwrap();
        let mut dec = LogDecoder::default();
        tx.protect(ids::ENG_STATUS, &mut d);
        let f = dec.decode(&rec(0, ids::ENG_STATUS, &d));
        assert_eq!(f.e2e, E2eVerdict::Ok);
        assert_eq!(f.signals[0].value, 800.0);
        assert_eq!(f.error, None);
        // Same counter again, 50 ms later: repeated counter and a gap.
        let f = dec.decode(&rec(50, ids::ENG_STATUS, &d));
        assert_eq!(f.e2e.as_str(), "counter_repeated");
        assert_eq!(dec.gaps().len(), 1);
        let f = dec.decode(&rec(60, ids::BENCH_TORQUE, &[0; 8]));
        assert_eq!(f.e2e, E2eVerdict::NotProtected);
        let f = dec.decode(&rec(60, ids::BENCH_TORQUE, &[0; 7]));
        assert!(matches!(f.error, Some(CodecError::WrongDlc { .. })));
        let f = dec.decode(&parse_line("(1.000000) vcan0 7FF#00").unwrap());
        assert_eq!(
            (f.e2e, f.error),
            (
                E2eVerdict::NotInContract,
                Some(CodecError::UnknownId { id: 0x7FF })
            )
        );
    }

    #[test]
    fn transport_frames_are_named_without_signals_or_error() {
        let mut dec = LogDecoder::default();
        // A padded single frame and an unpadded one: both are the protocol's to judge.
        for bytes in [
            &[0x02, 0x10, 0x03, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA][..],
            &[0x02, 0x3E, 0x00],
        ] {
            let f = dec.decode(&rec(0, ids::TCU_DIAG_REQ, bytes));
            assert_eq!(f.message.map(|m| m.name), Some("TCU_DiagReq"));
            assert!(f.signals.is_empty());
            assert_eq!((f.e2e, f.error), (E2eVerdict::NotProtected, None));
        }
    }
}

/// Cycle-time statistics of one message in a log.
#[derive(Debug, Clone, PartialEq)]
pub struct CycleStats {
    pub id: u32,
    pub name: Option<&'static str>,
    /// The contract's cycle time (ms), if the message is in the contract.
    pub nominal_ms: Option<u32>,
    pub frames: usize,
    pub mean_ms: f64,
    pub p50_ms: f64,
    pub p99_ms: f64,
    pub min_ms: f64,
    pub max_ms: f64,
}

/// Per-message intervals between consecutive frames (nearest-rank percentiles), by id.
pub fn cycle_stats<'a>(records: impl IntoIterator<Item = &'a LogRecord>) -> Vec<CycleStats> {
    let mut times: std::collections::BTreeMap<u32, Vec<Duration>> =
        std::collections::BTreeMap::new();
    for r in records {
        times.entry(r.frame.raw_id()).or_default().push(r.timestamp);
    }
    times
        .into_iter()
        .map(|(id, ts)| {
            let mut dt: Vec<f64> = ts
                .windows(2)
                .map(|w| w[1].saturating_sub(w[0]).as_secs_f64() * 1e3)
                .collect();
            dt.sort_by(f64::total_cmp);
            let pct = |q: f64| {
                if dt.is_empty() {
                    f64::NAN
                } else {
                    let rank = ((q * dt.len() as f64).ceil() as usize).clamp(1, dt.len());
                    dt[rank - 1]
                }
            };
            let def = message_def(id);
            CycleStats {
                id,
                name: def.map(|d| d.name),
                nominal_ms: def.map(|d| d.cycle_ms),
                frames: ts.len(),
                mean_ms: if dt.is_empty() {
                    f64::NAN
                } else {
                    dt.iter().sum::<f64>() / dt.len() as f64
                },
                p50_ms: pct(0.5),
                p99_ms: pct(0.99),
                min_ms: dt.first().copied().unwrap_or(f64::NAN),
                max_ms: dt.last().copied().unwrap_or(f64::NAN),
            }
        })
        .collect()
}

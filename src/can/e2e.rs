//! End-to-end protection of the contract's messages (DESIGN.md §3): a 4-bit alive counter in the
//! high nibble of byte 6 and CRC-8/SAE-J1850 (poly 0x1D, init 0xFF, xor-out 0xFF) over the id's
//! two little-endian bytes followed by bytes 0–6, stored in byte 7.
//!
//! Which messages are protected comes from the DBC (`MessageDef::e2e`: the message has both an
//! `AliveCounter` and a `Crc` signal). The sender side is [`E2eSender`]; the receiver side is
//! [`E2eChecker`], which reports per message a bad CRC, a repeated or skipped counter and a
//! timeout (by default 3 missed cycles). Time is an argument: the checker never reads a clock.

use super::messages::{message_def, MESSAGES};
use std::time::Duration;
use thiserror::Error;

pub use super::messages::e2e_layout::{COUNTER_BYTE, CRC_BYTE};
/// Alive counter modulus.
pub(crate) const COUNTER_MODULUS: u8 = 16;

/// CRC-8/SAE-J1850 (poly 0x1D, init 0xFF, xor-out 0xFF) from the maintained `crc` crate.
const CRC8: crc::Crc<u8> = crc::Crc::<u8>::new(&crc::CRC_8_SAE_J1850);

/// CRC-8/SAE-J1850 of a byte string (check value of "123456789" is 0x4B).
pub fn crc8_sae_j1850(bytes: &[u8]) -> u8 {
    CRC8.checksum(bytes)
}

/// The E2E CRC of a payload: over the id's two little-endian bytes and bytes 0–6.
pub fn e2e_crc(id: u16, data: &[u8; 8]) -> u8 {
    let mut d = CRC8.digest();
    d.update(&id.to_le_bytes());
    d.update(&data[..CRC_BYTE]);
    d.finalize()
}

/// Whether a frame's data carry the right E2E CRC for `id` (eight bytes, CRC in the last).
pub(crate) fn crc_ok(id: u16, data: &[u8]) -> bool {
    <&[u8; 8]>::try_from(data).is_ok_and(|d| d[CRC_BYTE] == e2e_crc(id, d))
}

/// Writes the alive counter (mod 16) and the CRC into an encoded payload.
pub fn protect(id: u16, data: &mut [u8; 8], counter: u8) {
    data[COUNTER_BYTE] = (data[COUNTER_BYTE] & 0x0F) | ((counter % COUNTER_MODULUS) << 4);
    data[CRC_BYTE] = e2e_crc(id, data);
}

/// The alive counter of a payload.
pub fn counter_of(data: &[u8; 8]) -> u8 {
    data[COUNTER_BYTE] >> 4
}

/// Whether a message id is E2E-protected in the contract.
pub(crate) fn is_protected(id: u32) -> bool {
    message_def(id).is_some_and(|m| m.e2e)
}

/// Sender side: one counter per protected message.
#[derive(Debug, Clone, Default)]
pub struct E2eSender {
    counters: Vec<(u16, u8)>,
}

impl E2eSender {
    pub fn new() -> Self {
        Self::default()
    }

    /// Protects `data` with the next counter of message `id` (ids that are not protected in the
    /// contract are left untouched). Returns the counter used, if any.
    pub fn protect(&mut self, id: u16, data: &mut [u8; 8]) -> Option<u8> {
        if !is_protected(u32::from(id)) {
            return None;
        }
        let slot = match self.counters.iter().position(|(i, _)| *i == id) {
            Some(p) => p,
            None => {
                self.counters.push((id, 0));
                self.counters.len() - 1
            }
        };
        let c = self.counters[slot].1;
        protect(id, data, c);
        self.counters[slot].1 = (c + 1) % COUNTER_MODULUS;
        Some(c)
    }
}

/// A per-frame or per-message E2E finding.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum E2eError {
    #[error("{message}: CRC {found:#04x}, expected {expected:#04x}")]
    BadCrc {
        message: &'static str,
        expected: u8,
        found: u8,
    },
    #[error("{message}: alive counter {counter} repeated")]
    CounterRepeated { message: &'static str, counter: u8 },
    #[error("{message}: alive counter {found}, expected {expected} ({skipped} frame(s) skipped)")]
    CounterSkipped {
        message: &'static str,
        expected: u8,
        found: u8,
        skipped: u8,
    },
    #[error("{message}: no valid frame for {elapsed_ms} ms ({cycles} cycles of {cycle_ms} ms)")]
    Timeout {
        message: &'static str,
        elapsed_ms: u64,
        cycle_ms: u32,
        cycles: u32,
    },
    #[error("{message}: DLC {found}, E2E needs 8")]
    WrongDlc { message: &'static str, found: usize },
    #[error("id {id:#x} is not an E2E-protected message of the contract")]
    NotProtected { id: u32 },
}

impl E2eError {
    /// A short machine-readable name of the finding.
    pub fn kind(&self) -> &'static str {
        match self {
            E2eError::BadCrc { .. } => "bad_crc",
            E2eError::CounterRepeated { .. } => "counter_repeated",
            E2eError::CounterSkipped { .. } => "counter_skipped",
            E2eError::Timeout { .. } => "timeout",
            E2eError::WrongDlc { .. } => "wrong_dlc",
            E2eError::NotProtected { .. } => "not_protected",
        }
    }
}

/// Receiver configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct E2eConfig {
    /// A message times out when no valid frame arrived for this many cycles.
    pub timeout_cycles: u32,
}

impl Default for E2eConfig {
    fn default() -> Self {
        Self { timeout_cycles: 3 }
    }
}

#[derive(Debug, Clone, Copy)]
struct Track {
    id: u16,
    name: &'static str,
    cycle_ms: u32,
    last_counter: Option<u8>,
    last_valid: Option<Duration>,
    /// Time the checker started watching (timeouts count from here before the first frame).
    since: Duration,
}

/// Receiver side: checks every protected message's CRC, counter sequence and timeout.
#[derive(Debug, Clone)]
pub struct E2eChecker {
    config: E2eConfig,
    tracks: Vec<Track>,
}

impl E2eChecker {
    /// Watches every E2E-protected message of the contract, starting at `now`.
    pub fn all(config: E2eConfig, now: Duration) -> Self {
        Self::for_ids(config, now, MESSAGES.iter().filter(|m| m.e2e).map(|m| m.id))
    }

    /// Watches the given protected messages (others are ignored), starting at `now`.
    pub fn for_ids(config: E2eConfig, now: Duration, ids: impl IntoIterator<Item = u16>) -> Self {
        let tracks = ids
            .into_iter()
            .filter_map(|id| message_def(u32::from(id)))
            .filter(|m| m.e2e)
            .map(|m| Track {
                id: m.id,
                name: m.name,
                cycle_ms: m.cycle_ms,
                last_counter: None,
                last_valid: None,
                since: now,
            })
            .collect();
        Self { config, tracks }
    }

    /// Checks one received frame. A bad CRC leaves the counter state alone; a skipped counter
    /// re-synchronises on the received one (the next consecutive frame is valid again).
    pub fn check(&mut self, now: Duration, id: u32, data: &[u8]) -> Result<(), E2eError> {
        let Some(track) = self.tracks.iter_mut().find(|t| u32::from(t.id) == id) else {
            return Err(E2eError::NotProtected { id });
        };
        let Ok(payload) = <&[u8; 8]>::try_from(data) else {
            return Err(E2eError::WrongDlc {
                message: track.name,
                found: data.len(),
            });
        };
        let expected = e2e_crc(track.id, payload);
        if payload[CRC_BYTE] != expected {
            return Err(E2eError::BadCrc {
                message: track.name,
                expected,
                found: payload[CRC_BYTE],
            });
        }
        let counter = counter_of(payload);
        let previous = track.last_counter.replace(counter);
        match previous {
            Some(p) if p == counter => Err(E2eError::CounterRepeated {
                message: track.name,
                counter,
            }),
            Some(p) if (p + 1) % COUNTER_MODULUS != counter => Err(E2eError::CounterSkipped {
                message: track.name,
                expected: (p + 1) % COUNTER_MODULUS,
                found: counter,
                skipped: (counter + COUNTER_MODULUS - p - 1) % COUNTER_MODULUS,
            }),
            _ => {
                track.last_valid = Some(now);
                Ok(())
            }
        }
    }

    /// Timeout of one message at `now`, if it has one.
    pub fn timeout(&self, now: Duration, id: u16) -> Option<E2eError> {
        let t = self.tracks.iter().find(|t| t.id == id)?;
        self.track_timeout(t, now)
    }

    fn track_timeout(&self, t: &Track, now: Duration) -> Option<E2eError> {
        let reference = t.last_valid.unwrap_or(t.since);
        let elapsed = now.saturating_sub(reference);
        let limit =
            Duration::from_millis(u64::from(t.cycle_ms) * u64::from(self.config.timeout_cycles));
        (t.cycle_ms > 0 && elapsed >= limit).then_some(E2eError::Timeout {
            message: t.name,
            elapsed_ms: elapsed.as_millis() as u64,
            cycle_ms: t.cycle_ms,
            cycles: self.config.timeout_cycles,
        })
    }

    /// Every message that has timed out at `now`.
    pub fn timeouts(&self, now: Duration) -> impl Iterator<Item = E2eError> + '_ {
        self.tracks
            .iter()
            .filter_map(move |t| self.track_timeout(t, now))
    }

    /// Time of the last valid frame of a message.
    pub fn last_valid(&self, id: u16) -> Option<Duration> {
        self.tracks
            .iter()
            .find(|t| t.id == id)
            .and_then(|t| t.last_valid)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::messages::{ids, EngStatus};

    #[test]
    fn crc_check_value() {
        assert_eq!(crc8_sae_j1850(b"123456789"), 0x4B);
        assert_eq!(crc8_sae_j1850(b""), 0x00);
    }

    fn frame(counter: u8) -> [u8; 8] {
        let mut d = EngStatus {
            eng_speed: 1500.0,
            eng_torque_act: 42.0,
            ..Default::default()
        }
        .encode()
        .unwrap();
        protect(ids::ENG_STATUS, &mut d, counter);
        d
    }

    #[test]
    fn sequence_findings() {
        let ms = Duration::from_millis;
        let id = u32::from(ids::ENG_STATUS);
        let mut c = E2eChecker::all(E2eConfig::default(), ms(0));
        assert_eq!(c.check(ms(10), id, &frame(14)), Ok(()));
        assert_eq!(c.check(ms(20), id, &frame(15)), Ok(()));
        assert_eq!(c.check(ms(30), id, &frame(0)), Ok(()), "wraps at 16");
        assert!(matches!(
            c.check(ms(40), id, &frame(0)),
            Err(E2eError::CounterRepeated { counter: 0, .. })
        ));
        assert!(matches!(
            c.check(ms(50), id, &frame(3)),
            Err(E2eError::CounterSkipped {
                expected: 1,
                found: 3,
                skipped: 2,
                ..
            })
        ));
        assert_eq!(c.check(ms(60), id, &frame(4)), Ok(()), "resynchronised");
        let mut bad = frame(5);
        bad[0] ^= 1;
        assert!(matches!(
            c.check(ms(70), id, &bad),
            Err(E2eError::BadCrc { .. })
        ));
        assert_eq!(
            c.check(ms(80), id, &frame(5)),
            Ok(()),
            "bad CRC does not advance the counter"
        );
        assert!(c.timeout(ms(109), ids::ENG_STATUS).is_none());
        assert!(matches!(
            c.timeout(ms(110), ids::ENG_STATUS),
            Some(E2eError::Timeout { elapsed_ms: 30, .. })
        ));
        assert!(matches!(
            c.check(ms(1), id, &frame(6)[..7]),
            Err(E2eError::WrongDlc { found: 7, .. })
        ));
        assert!(matches!(
            c.check(ms(1), 0x140, &[0; 8]),
            Err(E2eError::NotProtected { id: 0x140 })
        ));
    }

    #[test]
    fn sender_counts_per_message() {
        let mut s = E2eSender::new();
        let mut d = [0u8; 8];
        for k in 0..20u8 {
            assert_eq!(s.protect(ids::ENG_STATUS, &mut d), Some(k % 16));
            assert_eq!(counter_of(&d), k % 16);
            assert_eq!(d[CRC_BYTE], e2e_crc(ids::ENG_STATUS, &d));
        }
        assert_eq!(s.protect(ids::DCT_SENSORS, &mut d), Some(0));
        assert_eq!(s.protect(ids::BENCH_TORQUE, &mut d), None);
    }
}

/// One sample frame per message and case: every signal at its min, mid or max value; protected
/// messages carry the case's alive counter and the CRC computed here. Used by round-trip tests
/// and by the cross-tool check against cantools. The transport ids (ISO-TP, XCP), which have no
/// signals, have no sample.
pub fn sample_frames() -> Vec<SampleFrame> {
    use super::codec::SampleCase;
    let mut out = Vec::new();
    for def in MESSAGES.iter().filter(|m| !m.signals.is_empty()) {
        for case in SampleCase::ALL {
            let mut values: Vec<f64> = def.signals.iter().map(|s| s.sample(case)).collect();
            let crc_index = def.signal_index("Crc").filter(|_| def.e2e);
            if let Some(ci) = crc_index {
                values[ci] = 0.0;
            }
            let Ok(mut data) = def.encode_values(&values) else {
                continue;
            };
            if let Some(ci) = crc_index {
                let counter = counter_of(&data);
                protect(def.id, &mut data, counter);
                values[ci] = f64::from(data[CRC_BYTE]);
            }
            out.push(SampleFrame {
                def,
                case,
                values,
                data,
            });
        }
    }
    out
}

/// See [`sample_frames`].
#[derive(Debug, Clone, PartialEq)]
pub struct SampleFrame {
    pub def: &'static super::codec::MessageDef,
    pub case: super::codec::SampleCase,
    pub values: Vec<f64>,
    pub data: [u8; 8],
}

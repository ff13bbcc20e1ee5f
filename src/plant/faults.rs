//! Fault injection on the plant's own frames, per message and time window `[from_s, to_s)` of
//! simulated time (no `to_s`: until the end). Configured as `[[faults]]` tables:
//!
//! | kind | effect on the frames of `message` inside the window | extra keys |
//! |---|---|---|
//! | `drop` | frames are lost (every `every`-th one, default all); the alive counter still advances, so a receiver sees skipped counters | `every` |
//! | `delay` | frames are sent `delay_ms` later than their cycle | `delay_ms` (1 ..= 1000) |
//! | `freeze_counter` | the alive counter repeats its last value (CRC valid) | — |
//! | `corrupt_crc` | the CRC byte is wrong (XOR 0x5A) | — |
//! | `stop` | the sender is silent; the counter does not advance (it resumes where it stopped) | — |
//! | `implausible` | `signal` carries `value` (physical; saturated to the signal's bits, may lie outside the DBC range), E2E valid | `signal`, `value` |
//!
//! `freeze_counter` and `corrupt_crc` need an E2E-protected message. Only messages the plant sends
//! can be faulted.

use super::error::PlantError;
use crate::can::codec::MessageDef;
use crate::can::messages::{message_by_name, message_def};
use crate::ranges::Ranged;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Duration;

/// Latest time a fault may start or end (s): about 30 years of simulated time.
const MAX_TIME_S: f64 = 1e9;

/// Fault kinds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultKind {
    Drop,
    Delay,
    FreezeCounter,
    CorruptCrc,
    Stop,
    Implausible,
}

impl FaultKind {
    pub const ALL: [FaultKind; 6] = [
        FaultKind::Drop,
        FaultKind::Delay,
        FaultKind::FreezeCounter,
        FaultKind::CorruptCrc,
        FaultKind::Stop,
        FaultKind::Implausible,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            FaultKind::Drop => "drop",
            FaultKind::Delay => "delay",
            FaultKind::FreezeCounter => "freeze_counter",
            FaultKind::CorruptCrc => "corrupt_crc",
            FaultKind::Stop => "stop",
            FaultKind::Implausible => "implausible",
        }
    }

    pub fn parse(s: &str) -> Option<FaultKind> {
        FaultKind::ALL.into_iter().find(|k| k.as_str() == s)
    }
}

/// One validated fault.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fault {
    pub message: &'static MessageDef,
    pub kind: FaultKind,
    pub from: Duration,
    pub to: Option<Duration>,
    /// `delay`: how much later.
    pub delay: Duration,
    /// `drop`: drop every n-th frame of the window (1: all).
    pub every: u32,
    /// `implausible`: signal index and physical value.
    pub signal: Option<usize>,
    pub value: f64,
}

impl Fault {
    /// Whether the window contains `t`.
    pub fn active(&self, t: Duration) -> bool {
        t >= self.from && self.to.is_none_or(|to| t < to)
    }

    /// Raw bits of the implausible value of the signal (saturated to the signal's bit range).
    pub fn implausible_raw(&self) -> Option<(usize, i64)> {
        let si = self.signal?;
        let s = &self.message.signals[si];
        let raw = ((self.value - s.offset) / s.factor).round();
        let (lo, hi) = s.raw_limits();
        Some((si, raw.clamp(lo as f64, hi as f64) as i64))
    }
}

/// The `[[faults]]` table as written.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct FaultSpec {
    /// Message name (e.g. "DCT_Sensors") or id (e.g. "0x130").
    pub message: String,
    pub kind: String,
    pub from_s: f64,
    #[serde(default)]
    pub to_s: Option<f64>,
    #[serde(default)]
    pub delay_ms: Option<f64>,
    #[serde(default)]
    pub every: Option<u32>,
    #[serde(default)]
    pub signal: Option<String>,
    #[serde(default)]
    pub value: Option<f64>,
}

// The allowed range of every number of a `[[faults]]` table (`crate::ranges`).
crate::ranges!(FaultSpec as f, "faults" {
    from_s: [0.0, MAX_TIME_S],
    to_s: [f.from_s, MAX_TIME_S],
    delay_ms: [1.0, 1000.0],
});

/// Where a `[[faults]]` entry is: its file and index, for the errors that name its keys.
struct Entry<'a> {
    path: &'a Path,
    index: usize,
}

impl Entry<'_> {
    /// An error of the entry's key `k` (`faults[i].k`).
    fn err(&self, k: &str, reason: String) -> PlantError {
        PlantError::key(self.path, format!("faults[{}].{k}", self.index), reason)
    }

    /// An error when the key `k`, which `kind` does not use, is `present`.
    fn unused(&self, k: &str, present: bool, kind: FaultKind) -> Result<(), PlantError> {
        if present {
            Err(self.err(k, format!("does not apply to kind {}", kind.as_str())))
        } else {
            Ok(())
        }
    }
}

/// Whether a signal is the E2E protection rather than data.
fn is_e2e_signal(name: &str) -> bool {
    matches!(name, "AliveCounter" | "Crc")
}

impl FaultSpec {
    /// Validates against the contract and the messages the plant sends (`sent` ids).
    pub fn validate(&self, path: &Path, index: usize, sent: &[u16]) -> Result<Fault, PlantError> {
        let at = Entry { path, index };
        let def = self.message_def(&at, sent)?;
        let kind = FaultKind::parse(&self.kind).ok_or_else(|| {
            at.err(
                "kind",
                format!(
                    "`{}` is not a fault kind ({})",
                    self.kind,
                    FaultKind::ALL.map(|k| k.as_str()).join(", ")
                ),
            )
        })?;
        self.check_ranges_in(&format!("faults[{index}]"))
            .map_err(|e| PlantError::range(path, e))?;
        if self.to_s == Some(self.from_s) {
            return Err(at.err("to_s", "must be later than from_s".into()));
        }
        if matches!(kind, FaultKind::FreezeCounter | FaultKind::CorruptCrc) && !def.e2e {
            return Err(at.err(
                "kind",
                format!(
                    "{} needs an E2E-protected message; {} has no alive counter and CRC",
                    kind.as_str(),
                    def.name
                ),
            ));
        }
        let delay = self.delay(&at, kind)?;
        let every = self.every(&at, kind)?;
        let (signal, value) = self.implausible(&at, kind, def)?;
        Ok(Fault {
            message: def,
            kind,
            from: Duration::from_secs_f64(self.from_s),
            to: self.to_s.map(Duration::from_secs_f64),
            delay,
            every,
            signal,
            value,
        })
    }

    /// The faulted message, by name or hexadecimal id, among those the plant sends.
    fn message_def(&self, at: &Entry, sent: &[u16]) -> Result<&'static MessageDef, PlantError> {
        let def = message_by_name(&self.message)
            .or_else(|| {
                let t = self
                    .message
                    .trim_start_matches("0x")
                    .trim_start_matches("0X");
                u32::from_str_radix(t, 16).ok().and_then(message_def)
            })
            .ok_or_else(|| {
                at.err(
                    "message",
                    format!("`{}` is not a message of the contract", self.message),
                )
            })?;
        if !sent.contains(&def.id) {
            return Err(at.err(
                "message",
                format!("the plant does not send {} in this mode", def.name),
            ));
        }
        Ok(def)
    }

    /// `delay`'s `delay_ms` (required there, refused elsewhere).
    fn delay(&self, at: &Entry, kind: FaultKind) -> Result<Duration, PlantError> {
        if kind != FaultKind::Delay {
            at.unused("delay_ms", self.delay_ms.is_some(), kind)?;
            return Ok(Duration::ZERO);
        }
        let d = self
            .delay_ms
            .ok_or_else(|| at.err("delay_ms", "missing (delay in ms)".into()))?;
        Ok(Duration::from_secs_f64(d * 1e-3))
    }

    /// `drop`'s `every` (default 1: every frame; refused elsewhere).
    fn every(&self, at: &Entry, kind: FaultKind) -> Result<u32, PlantError> {
        if kind != FaultKind::Drop {
            at.unused("every", self.every.is_some(), kind)?;
            return Ok(1);
        }
        let n = self.every.unwrap_or(1);
        if n == 0 {
            return Err(at.err("every", "must be at least 1".into()));
        }
        Ok(n)
    }

    /// `implausible`'s data signal (by name) and physical value: anything the signal's bits can
    /// carry, inside or outside the DBC range (both refused for other kinds).
    fn implausible(
        &self,
        at: &Entry,
        kind: FaultKind,
        def: &MessageDef,
    ) -> Result<(Option<usize>, f64), PlantError> {
        if kind != FaultKind::Implausible {
            at.unused("signal", self.signal.is_some(), kind)?;
            at.unused("value", self.value.is_some(), kind)?;
            return Ok((None, 0.0));
        }
        let name = self
            .signal
            .as_deref()
            .ok_or_else(|| at.err("signal", "missing (signal name)".into()))?;
        let si = def
            .signal_index(name)
            .filter(|&i| !is_e2e_signal(def.signals[i].name))
            .ok_or_else(|| {
                at.err(
                    "signal",
                    format!(
                        "`{name}` is not a data signal of {} ({})",
                        def.name,
                        def.signals
                            .iter()
                            .map(|s| s.name)
                            .filter(|n| !is_e2e_signal(n))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                )
            })?;
        let v = self
            .value
            .filter(|v| v.is_finite())
            .ok_or_else(|| at.err("value", "missing or not finite (physical value)".into()))?;
        let s = &def.signals[si];
        let (lo, hi) = s.raw_limits();
        let (a, b) = (s.physical(lo), s.physical(hi));
        let (lo, hi) = (a.min(b), a.max(b));
        if !(lo..=hi).contains(&v) {
            return Err(at.err(
                "value",
                format!("{v} cannot be sent in {} ({lo} ..= {hi})", s.name),
            ));
        }
        Ok((Some(si), v))
    }
}

/// Parses `[[faults]]` entries of a TOML document (a plant config or a faults file).
pub(crate) fn parse_faults(
    path: &Path,
    doc: &toml::Table,
    sent: &[u16],
) -> Result<Vec<Fault>, PlantError> {
    let Some(v) = doc.get("faults") else {
        return Ok(Vec::new());
    };
    let arr = v
        .as_array()
        .ok_or_else(|| PlantError::key(path, "faults", "must be an array of tables [[faults]]"))?;
    arr.iter()
        .enumerate()
        .map(|(i, item)| {
            let spec: FaultSpec = item.clone().try_into().map_err(|e: toml::de::Error| {
                let name = format!("faults[{i}]");
                let key = match item {
                    toml::Value::Table(t) => crate::toml_key::refused_path::<FaultSpec>(&name, t),
                    _ => name,
                };
                PlantError::key(path, key, e.message().to_string())
            })?;
            spec.validate(path, i, sent)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::messages::ids;

    const SENT: &[u16] = &[ids::ENG_STATUS, ids::DCT_SENSORS, ids::BENCH_TORQUE];

    fn parse(text: &str) -> Result<Vec<Fault>, PlantError> {
        let doc: toml::Table = text.parse().unwrap();
        parse_faults(Path::new("f.toml"), &doc, SENT)
    }

    #[test]
    fn valid_faults() {
        let f = parse(
            "[[faults]]\nmessage = \"DCT_Sensors\"\nkind = \"implausible\"\nfrom_s = 1\nto_s = 2\n\
             signal = \"HousingTemp\"\nvalue = 215\n\
             [[faults]]\nmessage = \"0x100\"\nkind = \"delay\"\nfrom_s = 0.5\ndelay_ms = 25\n",
        )
        .unwrap();
        assert_eq!(f.len(), 2);
        assert_eq!(f[0].kind, FaultKind::Implausible);
        // 215 °C, the top of 8 bits of 1 °C from −40 (raw 255), beyond the DBC's range.
        assert_eq!(f[0].implausible_raw(), Some((3, 255)));
        assert!(f[0].active(Duration::from_millis(1000)));
        assert!(!f[0].active(Duration::from_millis(2000)));
        assert_eq!(f[1].delay, Duration::from_millis(25));
        assert!(f[1].active(Duration::from_secs(99)));
    }

    #[test]
    fn invalid_faults_name_the_key() {
        let cases = [
            ("message = \"TCU_Status\"\nkind = \"drop\"\nfrom_s = 0", "faults[0].message"),
            ("message = \"BENCH_Torque\"\nkind = \"corrupt_crc\"\nfrom_s = 0", "faults[0].kind"),
            ("message = \"ENG_Status\"\nkind = \"melt\"\nfrom_s = 0", "faults[0].kind"),
            ("message = \"ENG_Status\"\nkind = \"delay\"\nfrom_s = 0", "faults[0].delay_ms"),
            ("message = \"ENG_Status\"\nkind = \"drop\"\nfrom_s = 2\nto_s = 1", "faults[0].to_s"),
            (
                "message = \"ENG_Status\"\nkind = \"implausible\"\nfrom_s = 0\nsignal = \"Crc\"\nvalue = 1",
                "faults[0].signal",
            ),
            ("message = \"ENG_Status\"\nkind = \"stop\"\nfrom_s = 0\nvalue = 1", "faults[0].value"),
            (
                "message = \"DCT_Sensors\"\nkind = \"implausible\"\nfrom_s = 0\nsignal = \"HousingTemp\"\nvalue = 500",
                "faults[0].value",
            ),
            ("message = \"ENG_Status\"\nkind = \"stop\"\nfrom = 0", "faults[0]"),
            ("message = \"ENG_Status\"\nkind = \"drop\"\nfrom_s = 0\nevery = 0", "faults[0].every"),
            (
                "message = \"ENG_Status\"\nkind = \"delay\"\nfrom_s = 0\ndelay_ms = 5\nevery = 2",
                "faults[0].every",
            ),
            ("message = \"ENG_Status\"\nkind = \"drop\"\nfrom_s = 0\ndelay_ms = 5", "faults[0].delay_ms"),
            ("message = \"0x7ff\"\nkind = \"drop\"\nfrom_s = 0", "faults[0].message"),
        ];
        for (body, key) in cases {
            let e = parse(&format!("[[faults]]\n{body}\n")).unwrap_err();
            assert!(
                matches!(&e, PlantError::Key { key: k, .. } if k == key),
                "{body}: {e}"
            );
        }
    }
}

//! Signal packing for the contract's messages: Intel (little-endian) signals of up to 64 bits in
//! an 8-byte payload, physical = raw · factor + offset, range checks against the DBC.
//!
//! The tables (`MessageDef`, `SignalDef`) are generated from `dbc/ddct.dbc` by `build.rs`; this
//! module holds the hand-written logic they share, so no scale or offset is written by hand.

use thiserror::Error;

/// A signal as generated from the DBC.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignalDef {
    pub name: &'static str,
    pub start_bit: u32,
    pub length: u32,
    pub signed: bool,
    pub factor: f64,
    pub offset: f64,
    pub min: f64,
    pub max: f64,
    pub unit: &'static str,
    pub receivers: &'static [&'static str],
    pub values: &'static [(u64, &'static str)],
    pub comment: &'static str,
}

/// A message as generated from the DBC.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MessageDef {
    pub id: u16,
    pub name: &'static str,
    pub dlc: usize,
    pub sender: &'static str,
    pub cycle_ms: u32,
    /// Carries `AliveCounter` and `Crc` (E2E protected).
    pub e2e: bool,
    pub comment: &'static str,
    pub signals: &'static [SignalDef],
}

/// Why a payload could not be encoded or decoded.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CodecError {
    #[error("{message}: expected DLC {expected}, got {found}")]
    WrongDlc {
        message: &'static str,
        expected: usize,
        found: usize,
    },
    #[error("{message}.{signal}: value {value} outside the DBC range {min}..={max}")]
    OutOfRange {
        message: &'static str,
        signal: &'static str,
        value: f64,
        min: f64,
        max: f64,
    },
    #[error("{message}.{signal}: value is not finite")]
    NotFinite {
        message: &'static str,
        signal: &'static str,
    },
    #[error("{message}.{signal}: raw value {raw} is not in the value table")]
    UnknownValue {
        message: &'static str,
        signal: &'static str,
        raw: u64,
    },
    #[error("id {id:#x} is not a message of the contract")]
    UnknownId { id: u32 },
}

impl SignalDef {
    fn mask(&self) -> u64 {
        if self.length >= 64 {
            u64::MAX
        } else {
            (1u64 << self.length) - 1
        }
    }

    /// The raw bits of this signal in a little-endian payload word, unsigned.
    pub fn raw_unsigned(&self, payload: u64) -> u64 {
        (payload >> self.start_bit) & self.mask()
    }

    /// The raw value, sign-extended when the signal is signed.
    pub fn raw_value(&self, payload: u64) -> i64 {
        let u = self.raw_unsigned(payload);
        if self.signed && self.length < 64 && (u >> (self.length - 1)) & 1 == 1 {
            (u | !self.mask()) as i64
        } else {
            u as i64
        }
    }

    /// Physical value of a raw value.
    pub fn physical(&self, raw: i64) -> f64 {
        raw as f64 * self.factor + self.offset
    }

    /// Physical value of this signal in a payload word (no range check).
    pub fn decode_physical(&self, payload: u64) -> f64 {
        self.physical(self.raw_value(payload))
    }

    /// The value-table label of a raw value, if any.
    pub fn label(&self, raw: u64) -> Option<&'static str> {
        self.values.iter().find(|(r, _)| *r == raw).map(|(_, l)| *l)
    }

    /// Smallest and largest raw value the bits can hold.
    pub fn raw_limits(&self) -> (i64, i64) {
        if self.signed {
            (
                -(1i64 << (self.length - 1)),
                (1i64 << (self.length - 1)) - 1,
            )
        } else {
            (0, self.mask() as i64)
        }
    }

    /// Half a resolution step, the tolerance of range checks on quantised values.
    pub fn half_lsb(&self) -> f64 {
        self.factor.abs() * 0.5
    }

    fn in_range(&self, v: f64) -> bool {
        let tol = 1e-9 * (1.0 + self.max.abs().max(self.min.abs()));
        v >= self.min - tol && v <= self.max + tol
    }

    /// Raw value for a physical value (rounded to the nearest step), range-checked.
    pub fn to_raw(&self, message: &'static str, v: f64) -> Result<i64, CodecError> {
        if !v.is_finite() {
            return Err(CodecError::NotFinite {
                message,
                signal: self.name,
            });
        }
        let out_of_range = || CodecError::OutOfRange {
            message,
            signal: self.name,
            value: v,
            min: self.min,
            max: self.max,
        };
        if !self.in_range(v) {
            return Err(out_of_range());
        }
        let raw = ((v - self.offset) / self.factor).round();
        let (lo, hi) = self.raw_limits();
        if raw < lo as f64 || raw > hi as f64 {
            return Err(out_of_range());
        }
        Ok(raw as i64)
    }

    /// ORs the encoded raw value into a payload word.
    pub fn insert(&self, payload: &mut u64, raw: i64) {
        let bits = (raw as u64) & self.mask();
        *payload &= !(self.mask() << self.start_bit);
        *payload |= bits << self.start_bit;
    }
}

impl MessageDef {
    /// Checks the DLC and returns the payload as a little-endian word.
    pub fn payload(&self, data: &[u8]) -> Result<u64, CodecError> {
        if data.len() != self.dlc {
            return Err(CodecError::WrongDlc {
                message: self.name,
                expected: self.dlc,
                found: data.len(),
            });
        }
        let mut bytes = [0u8; 8];
        bytes[..data.len()].copy_from_slice(data);
        Ok(u64::from_le_bytes(bytes))
    }

    /// Physical value of signal `si`, rejected when outside the DBC range (by more than half a
    /// step).
    pub fn signal_checked(&self, si: usize, payload: u64) -> Result<f64, CodecError> {
        let s = &self.signals[si];
        let v = s.decode_physical(payload);
        let tol = s.half_lsb();
        if v < s.min - tol || v > s.max + tol {
            return Err(CodecError::OutOfRange {
                message: self.name,
                signal: s.name,
                value: v,
                min: s.min,
                max: s.max,
            });
        }
        Ok(v)
    }

    /// Range check of a physical value for signal `si`.
    pub fn check(&self, si: usize, v: f64) -> Result<(), CodecError> {
        self.signals[si].to_raw(self.name, v).map(|_| ())
    }

    /// Encodes physical value `v` of signal `si` into the payload word.
    pub fn put(&self, si: usize, payload: &mut u64, v: f64) -> Result<(), CodecError> {
        let s = &self.signals[si];
        let raw = s.to_raw(self.name, v)?;
        s.insert(payload, raw);
        Ok(())
    }

    /// Index of a signal by name.
    pub fn signal_index(&self, name: &str) -> Option<usize> {
        self.signals.iter().position(|s| s.name == name)
    }

    /// Every signal's physical value without range checks, for display of any payload of the
    /// right length.
    pub fn decode_lenient(&self, data: &[u8]) -> Result<Vec<DecodedSignal>, CodecError> {
        let payload = self.payload(data)?;
        Ok(self
            .signals
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let raw = s.raw_value(payload);
                let value = s.physical(raw);
                DecodedSignal {
                    signal: s,
                    raw,
                    value,
                    label: s.label(raw as u64),
                    in_range: self.signal_checked(i, payload).is_ok()
                        && (s.values.is_empty() || s.label(raw as u64).is_some()),
                }
            })
            .collect())
    }

    /// The physical values of [`MessageDef::decode_lenient`] alone, every signal's in order,
    /// appended to `out` (nothing on an error): many frames' values into one vector.
    pub fn values_into(&self, data: &[u8], out: &mut Vec<f64>) -> Result<(), CodecError> {
        let payload = self.payload(data)?;
        out.extend(self.signals.iter().map(|s| s.decode_physical(payload)));
        Ok(())
    }
}

/// One decoded signal for display.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DecodedSignal {
    pub signal: &'static SignalDef,
    pub raw: i64,
    pub value: f64,
    pub label: Option<&'static str>,
    pub in_range: bool,
}

impl DecodedSignal {
    /// Value as text: the label for enumerations, otherwise the number with the resolution's
    /// decimals.
    pub fn display_value(&self) -> String {
        if let Some(l) = self.label {
            return l.to_string();
        }
        let decimals = decimals_of(self.signal.factor);
        format!("{:.*}", decimals, self.value)
    }
}

/// Number of decimals needed to show a quantity of the given resolution exactly.
pub(crate) fn decimals_of(factor: f64) -> usize {
    let mut d = 0;
    let mut f = factor.abs();
    while d < 9 && (f - f.round()).abs() > 1e-9 {
        f *= 10.0;
        d += 1;
    }
    d
}

impl MessageDef {
    /// Encodes physical values given in signal order (range-checked).
    pub fn encode_values(&self, values: &[f64]) -> Result<[u8; 8], CodecError> {
        let mut payload = 0u64;
        for (si, v) in values.iter().enumerate().take(self.signals.len()) {
            self.put(si, &mut payload, *v)?;
        }
        Ok(payload.to_le_bytes())
    }
}

/// A representative value of a signal for encode/decode round trips and cross-tool checks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SampleCase {
    Min,
    Mid,
    Max,
}

impl SampleCase {
    pub const ALL: [SampleCase; 3] = [SampleCase::Min, SampleCase::Mid, SampleCase::Max];
    pub fn as_str(self) -> &'static str {
        match self {
            SampleCase::Min => "min",
            SampleCase::Mid => "mid",
            SampleCase::Max => "max",
        }
    }
}

impl SignalDef {
    /// The signal's minimum, maximum or a mid value, quantised to its resolution; for
    /// enumerations the lowest, middle or highest entry of the value table.
    pub fn sample(&self, case: SampleCase) -> f64 {
        if !self.values.is_empty() {
            let n = self.values.len();
            let i = match case {
                SampleCase::Min => 0,
                SampleCase::Mid => n / 2,
                SampleCase::Max => n - 1,
            };
            return self.values[i].0 as f64;
        }
        let target = match case {
            SampleCase::Min => self.min,
            SampleCase::Mid => 0.5 * (self.min + self.max),
            SampleCase::Max => self.max,
        };
        let (lo, hi) = self.raw_limits();
        let mut raw = ((target - self.offset) / self.factor).round() as i64;
        raw = raw.clamp(lo, hi);
        // Stay inside [min, max] after quantisation.
        while self.physical(raw) > self.max + 1e-12 && raw > lo {
            raw -= 1;
        }
        while self.physical(raw) < self.min - 1e-12 && raw < hi {
            raw += 1;
        }
        self.physical(raw)
    }
}

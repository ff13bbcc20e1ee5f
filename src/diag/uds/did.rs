//! The TCU's data identifiers (ISO 14229-1 clause 11.2 ReadDataByIdentifier, 11.7
//! WriteDataByIdentifier; annex C.1 for the 0xF18C/0xF195/0xF197 identification DIDs), parsed
//! from their 16-bit number and encoded as the doc's DID table says: values as big-endian
//! IEEE-754 `f32`, identification strings as 16 ASCII bytes padded with spaces.

use crate::diag::values::{Calibration, Measurement};

/// Identification strings (ISO 14229-1 annex C.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Identification {
    /// 0xF18C ECU serial number.
    SerialNumber,
    /// 0xF195 system supplier ECU software version number.
    SoftwareVersion,
    /// 0xF197 system name.
    SystemName,
}

/// One data identifier of the TCU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Did {
    /// 0xF18C, 0xF195, 0xF197.
    Identification(Identification),
    /// 0x0100 + i: measurement i of [`Measurement::ALL`].
    Measurement(Measurement),
    /// 0x0120: the TCU time of the latest step (s); also in the DTC snapshot record.
    TcuTime,
    /// 0x0200 + i: calibration i of [`Calibration::ALL`].
    Calibration(Calibration),
    /// 0x0300 + i: the learned kiss point of clutch i + 1 (0 or 1).
    LearnedKiss(usize),
}

/// Length of an identification string on the bus.
pub(crate) const IDENTIFICATION_LEN: usize = 16;

const MEASUREMENT_BASE: u16 = 0x0100;
const TCU_TIME: u16 = 0x0120;
const CALIBRATION_BASE: u16 = 0x0200;
const LEARNED_KISS_BASE: u16 = 0x0300;

impl Did {
    /// The DID of a 16-bit number (`None`: not supported, NRC 0x31).
    pub fn from_u16(n: u16) -> Option<Did> {
        match n {
            0xF18C => Some(Did::Identification(Identification::SerialNumber)),
            0xF195 => Some(Did::Identification(Identification::SoftwareVersion)),
            0xF197 => Some(Did::Identification(Identification::SystemName)),
            TCU_TIME => Some(Did::TcuTime),
            0x0100..=0x01FF => Measurement::ALL
                .get(usize::from(n - MEASUREMENT_BASE))
                .map(|m| Did::Measurement(*m)),
            0x0200..=0x02FF => Calibration::ALL
                .get(usize::from(n - CALIBRATION_BASE))
                .map(|c| Did::Calibration(*c)),
            0x0300 | 0x0301 => Some(Did::LearnedKiss(usize::from(n - LEARNED_KISS_BASE))),
            _ => None,
        }
    }

    /// Its 16-bit number.
    pub fn number(self) -> u16 {
        let index = |i: Option<usize>| u16::try_from(i.unwrap_or(0)).unwrap_or(0);
        match self {
            Did::Identification(Identification::SerialNumber) => 0xF18C,
            Did::Identification(Identification::SoftwareVersion) => 0xF195,
            Did::Identification(Identification::SystemName) => 0xF197,
            Did::Measurement(m) => {
                MEASUREMENT_BASE + index(Measurement::ALL.iter().position(|x| *x == m))
            }
            Did::TcuTime => TCU_TIME,
            Did::Calibration(c) => {
                CALIBRATION_BASE + index(Calibration::ALL.iter().position(|x| *x == c))
            }
            Did::LearnedKiss(i) => LEARNED_KISS_BASE + index(Some(i)),
        }
    }

    /// Every DID, in number order of each group.
    pub fn all() -> Vec<Did> {
        let mut v: Vec<Did> = Measurement::ALL
            .iter()
            .map(|m| Did::Measurement(*m))
            .collect();
        v.push(Did::TcuTime);
        v.extend(Calibration::ALL.iter().map(|c| Did::Calibration(*c)));
        v.extend([Did::LearnedKiss(0), Did::LearnedKiss(1)]);
        v.extend(
            [
                Identification::SerialNumber,
                Identification::SoftwareVersion,
                Identification::SystemName,
            ]
            .map(Did::Identification),
        );
        v
    }
}

/// A value as the 4 bytes of a big-endian `f32` (NaN stays NaN).
pub(crate) fn f32_be(v: f64) -> [u8; 4] {
    (v as f32).to_be_bytes()
}

/// A string as [`IDENTIFICATION_LEN`] ASCII bytes: truncated, padded with spaces, a non-ASCII
/// or control character replaced by `?`.
pub(crate) fn ascii16(s: &str) -> [u8; IDENTIFICATION_LEN] {
    let mut out = [b' '; IDENTIFICATION_LEN];
    for (o, c) in out.iter_mut().zip(s.chars()) {
        *o = if c.is_ascii() && !c.is_ascii_control() {
            c as u8
        } else {
            b'?'
        };
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_round_trip_and_match_the_doc() {
        for d in Did::all() {
            assert_eq!(Did::from_u16(d.number()), Some(d), "{d:?}");
        }
        assert_eq!(
            Did::Measurement(Measurement::Clutch1TempEst).number(),
            0x0100
        );
        assert_eq!(Did::Measurement(Measurement::FaultCode).number(), 0x0112);
        assert_eq!(Did::Calibration(Calibration::ClutchKp).number(), 0x0200);
        assert_eq!(Did::Calibration(Calibration::CompSlip).number(), 0x0207);
        assert_eq!(Did::from_u16(0x0113), None);
        assert_eq!(Did::from_u16(0x0208), None);
        assert_eq!(Did::from_u16(0x0302), None);
        assert_eq!(Did::from_u16(0xF190), None);
    }

    #[test]
    fn ascii_is_padded_truncated_and_clean() {
        assert_eq!(&ascii16("ddct TCU"), b"ddct TCU        ");
        assert_eq!(&ascii16("0123456789abcdefXYZ"), b"0123456789abcdef");
        assert_eq!(&ascii16("é\n"), b"??              ");
    }
}

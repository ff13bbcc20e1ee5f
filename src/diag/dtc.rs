//! The fault memory of the TCU (ISO 14229-1 clause 12 and annex D): one DTC per TCU fault
//! code ([`TABLE`], documented in docs/diagnostics.md "Fault memory"), each with the DTC status
//! byte of annex D.2, the snapshot record 0x01 taken at the first failure (12.3.5.5,
//! `DTCSnapshotRecord`) and the extended data records 0x01 (occurrence counter) and 0x02
//! (aging counter) (12.3.5.7, `DTCExtDataRecord`).
//!
//! A pure core, [`memory::FaultMemory`]: `update` once per TCU step with the time as an
//! argument, `start_operation_cycle` at each start of the daemon (an operation cycle is one run,
//! start to stop or ECUReset), `clear` for ClearDiagnosticInformation (12.2). Serialized as JSON
//! with a format version (`to_bytes`, `from_bytes`); the file is `super::store`'s.
//!
//! Status bits (annex D.2) as this memory sets them:
//! - testFailed (0): the fault is the TCU's active fault in the step; cleared when the test
//!   passes and at the start of an operation cycle (the result of a past cycle is not kept).
//! - testFailedThisOperationCycle (1), pendingDTC (2), testFailedSinceLastClear (5): set on a
//!   failure; pendingDTC is cleared at the start of a cycle after a cycle whose test completed
//!   without failure.
//! - confirmedDTC (3): after [`CONFIRMATION_TIME`] of consecutive failed steps, measured from the
//!   last step at which the test did not fail; cleared after [`AGING_CYCLES`] completed cycles
//!   without failure (the aging counter, extended data 0x02).
//! - testNotCompletedSinceLastClear (4), testNotCompletedThisOperationCycle (6): cleared when
//!   the test runs (the TCU's inputs are all fresh, or the fault is active).
//! - warningIndicatorRequested (7): never.

use std::fmt;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::can::messages::FaultCode;
use crate::diag::uds::did::Did;
use crate::diag::values::{Measurement, Snapshot};

mod serde_nan;

/// The status bits (ISO 14229-1 annex D.2).
pub mod status {
    pub const TEST_FAILED: u8 = 0x01;
    pub const TEST_FAILED_THIS_OPERATION_CYCLE: u8 = 0x02;
    pub const PENDING_DTC: u8 = 0x04;
    pub const CONFIRMED_DTC: u8 = 0x08;
    pub const TEST_NOT_COMPLETED_SINCE_LAST_CLEAR: u8 = 0x10;
    pub const TEST_FAILED_SINCE_LAST_CLEAR: u8 = 0x20;
    pub const TEST_NOT_COMPLETED_THIS_OPERATION_CYCLE: u8 = 0x40;
    pub const WARNING_INDICATOR_REQUESTED: u8 = 0x80;
}
use status::*;

/// The status bits this memory supports (all but warningIndicatorRequested).
pub(crate) const STATUS_AVAILABILITY_MASK: u8 = 0x7F;
/// The status after a clear (and of a DTC never tested): both "not completed" bits.
pub(crate) const STATUS_AFTER_CLEAR: u8 =
    TEST_NOT_COMPLETED_SINCE_LAST_CLEAR | TEST_NOT_COMPLETED_THIS_OPERATION_CYCLE;
/// How long a fault fails in consecutive steps before its DTC is confirmed.
pub const CONFIRMATION_TIME: Duration = Duration::from_millis(100);
/// Completed operation cycles without failure after which a confirmed DTC ages out.
pub const AGING_CYCLES: u8 = 40;
/// The groupOfDTC of ClearDiagnosticInformation meaning "all groups".
pub const GROUP_ALL: u32 = 0xFF_FFFF;
/// The version of the serialized format.
pub const FORMAT_VERSION: u32 = 1;

/// The module's errors.
#[derive(Debug, thiserror::Error)]
pub enum DtcError {
    #[error("no DTC or group {0:#08X} in the fault memory")]
    UnknownDtc(u32),
    #[error("the fault memory is not valid JSON of its format")]
    Json(#[from] serde_json::Error),
    #[error("fault memory format version {found}, this program reads version {FORMAT_VERSION}")]
    UnsupportedVersion { found: u32 },
    #[error("the fault memory holds DTC {0:#08X}, which the TCU does not have")]
    UnknownInFile(u32),
    #[error("the fault memory holds DTC {0:#08X} twice")]
    Duplicate(u32),
}

/// A 3-byte DTC: the 2-byte SAE J2012 code and the failure type byte (ISO 14229-1 D.1,
/// `DTCFormatIdentifier` 0x01).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Dtc(u32);

impl Dtc {
    /// The DTC of its three bytes' value (`None` above 0xFFFFFF).
    pub const fn new(value: u32) -> Option<Dtc> {
        if value <= 0xFF_FFFF {
            Some(Dtc(value))
        } else {
            None
        }
    }

    /// The DTC of a 2-byte SAE J2012 code (e.g. 0xC100 for U0100) and a failure type byte.
    pub const fn sae(code: u16, failure_type: u8) -> Dtc {
        Dtc(((code as u32) << 8) | failure_type as u32)
    }

    /// Its value (0 ..= 0xFFFFFF).
    pub const fn value(self) -> u32 {
        self.0
    }

    /// Its three bytes, high first.
    pub fn bytes(self) -> [u8; 3] {
        let [_, a, b, c] = self.0.to_be_bytes();
        [a, b, c]
    }

    /// The DTC of three bytes.
    pub fn from_bytes(b: [u8; 3]) -> Dtc {
        Dtc(u32::from_be_bytes([0, b[0], b[1], b[2]]))
    }
}

impl fmt::Display for Dtc {
    /// The SAE form, e.g. `U0100-87`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [hi, lo, ftb] = self.bytes();
        let letter = ['P', 'C', 'B', 'U'][usize::from(hi >> 6)];
        write!(
            f,
            "{letter}{}{:X}{lo:02X}-{ftb:02X}",
            (hi >> 4) & 0x3,
            hi & 0xF
        )
    }
}

/// Fault code → DTC (the table of docs/diagnostics.md "Fault memory").
pub const TABLE: [(FaultCode, Dtc); 22] = [
    (FaultCode::EngStatusTimeout, Dtc::sae(0xC100, 0x87)), // U0100-87
    (FaultCode::EngStatusCrc, Dtc::sae(0xC401, 0x83)),     // U0401-83
    (FaultCode::EngStatusCounter, Dtc::sae(0xC401, 0x82)), // U0401-82
    (FaultCode::SensorsTimeout, Dtc::sae(0xD100, 0x87)),   // U1100-87
    (FaultCode::SensorsCrc, Dtc::sae(0xD401, 0x83)),       // U1401-83
    (FaultCode::SensorsCounter, Dtc::sae(0xD401, 0x82)),   // U1401-82
    (FaultCode::ActuatorsTimeout, Dtc::sae(0xD101, 0x87)), // U1101-87
    (FaultCode::ActuatorsCrc, Dtc::sae(0xD402, 0x83)),     // U1402-83
    (FaultCode::ActuatorsCounter, Dtc::sae(0xD402, 0x82)), // U1402-82
    (FaultCode::PedalTimeout, Dtc::sae(0xD102, 0x87)),     // U1102-87
    (FaultCode::PedalCrc, Dtc::sae(0xD403, 0x83)),         // U1403-83
    (FaultCode::PedalCounter, Dtc::sae(0xD403, 0x82)),     // U1403-82
    (FaultCode::ImplausibleSpeed, Dtc::sae(0x0715, 0x64)), // P0715-64
    (FaultCode::ImplausibleTemp, Dtc::sae(0x0711, 0x64)),  // P0711-64
    (FaultCode::ImplausiblePosition, Dtc::sae(0x0806, 0x64)), // P0806-64
    (FaultCode::ClutchOverTempWarning, Dtc::sae(0x0218, 0x4B)), // P0218-4B
    (FaultCode::ClutchOverTempLimit, Dtc::sae(0x0218, 0x98)), // P0218-98
    (FaultCode::InternalNonFinite, Dtc::sae(0x0613, 0x49)), // P0613-49
    (FaultCode::SensorsStaleTime, Dtc::sae(0xD401, 0x81)), // U1401-81
    (FaultCode::ImplausibleGear, Dtc::sae(0x0730, 0x64)),  // P0730-64
    (FaultCode::ImplausibleLever, Dtc::sae(0x0705, 0x64)), // P0705-64
    (FaultCode::SecondSender, Dtc::sae(0xC001, 0x81)),     // U0001-81
];

/// The DTC of a fault code (`None` for [`FaultCode::None`]).
pub fn dtc_of(fault: FaultCode) -> Option<Dtc> {
    TABLE.iter().find(|(f, _)| *f == fault).map(|(_, d)| *d)
}

/// The operating conditions at a DTC's first failure (snapshot record 0x01).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FreezeFrame {
    /// TCU time (s).
    #[serde(with = "serde_nan")]
    pub t_s: f64,
    #[serde(with = "serde_nan")]
    pub engine_rpm: f64,
    #[serde(with = "serde_nan")]
    pub out_rpm: f64,
    /// Estimated clutch temperatures (°C).
    #[serde(with = "serde_nan")]
    pub clutch1_temp_c: f64,
    #[serde(with = "serde_nan")]
    pub clutch2_temp_c: f64,
    /// Measured bearing positions (mm).
    #[serde(with = "serde_nan")]
    pub clutch1_pos_mm: f64,
    #[serde(with = "serde_nan")]
    pub clutch2_pos_mm: f64,
    /// TcuState (raw).
    pub state: u8,
    /// GearActive (raw, 7 reverse).
    pub gear: u8,
    #[serde(with = "serde_nan")]
    pub pedal_pct: f64,
}

impl FreezeFrame {
    /// The conditions of a step.
    pub fn capture(s: &Snapshot) -> FreezeFrame {
        FreezeFrame {
            t_s: s.t_s,
            engine_rpm: s.engine_rpm,
            out_rpm: s.out_rpm,
            clutch1_temp_c: s.theta_est_c[0],
            clutch2_temp_c: s.theta_est_c[1],
            clutch1_pos_mm: s.x_mm[0],
            clutch2_pos_mm: s.x_mm[1],
            state: s.state as u8,
            gear: s.gear_active.code(),
            pedal_pct: s.pedal_pct,
        }
    }

    /// The record's data identifiers and values, in record order (docs/diagnostics.md).
    pub fn identifiers(&self) -> [(Did, f64); 10] {
        use Measurement::*;
        [
            (Did::TcuTime, self.t_s),
            (Did::Measurement(EngineSpeed), self.engine_rpm),
            (Did::Measurement(OutShaftSpeed), self.out_rpm),
            (Did::Measurement(Clutch1TempEst), self.clutch1_temp_c),
            (Did::Measurement(Clutch2TempEst), self.clutch2_temp_c),
            (Did::Measurement(Clutch1Pos), self.clutch1_pos_mm),
            (Did::Measurement(Clutch2Pos), self.clutch2_pos_mm),
            (
                Did::Measurement(Measurement::TcuState),
                f64::from(self.state),
            ),
            (Did::Measurement(GearActive), f64::from(self.gear)),
            (Did::Measurement(AccelPedal), self.pedal_pct),
        ]
    }
}

/// What the memory holds for one DTC.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DtcRecord {
    /// The status byte (annex D.2).
    pub status: u8,
    /// Operation cycles in which the DTC failed (extended data 0x01), saturating at 255.
    pub occurrences: u8,
    /// Completed cycles without failure since the last failure, while confirmed (extended
    /// data 0x02).
    pub aging: u8,
    /// Snapshot record 0x01: the first failure since the last clear.
    pub freeze: Option<FreezeFrame>,
    /// When the current run of failed steps began (not stored).
    failing_since: Option<Duration>,
}

impl Default for DtcRecord {
    fn default() -> Self {
        DtcRecord {
            status: STATUS_AFTER_CLEAR,
            occurrences: 0,
            aging: 0,
            freeze: None,
            failing_since: None,
        }
    }
}

pub mod memory;

#[cfg(test)]
mod tests;

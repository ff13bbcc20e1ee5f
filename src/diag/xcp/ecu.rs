//! What the XCP slave needs of the ECU ([`XcpEcu`]): its calibrations and its last snapshot.

use crate::diag::values::{Calibration, Snapshot};

/// What the slave needs of the ECU (the TCU integration implements it).
pub trait XcpEcu {
    /// The calibration's current value.
    fn calibration(&self, cal: Calibration) -> f64;
    /// Sets a calibration (validated by the ECU; `Err` with the reason if refused).
    fn set_calibration(&mut self, cal: Calibration, value: f64) -> Result<(), String>;
    /// The last step's snapshot, for UPLOAD of measurements (`None` before the first step:
    /// measurements read NaN).
    fn snapshot(&self) -> Option<Snapshot>;
}

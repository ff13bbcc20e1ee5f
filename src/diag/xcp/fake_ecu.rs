//! A fake ECU for the XCP tests ([`FakeEcu`]): calibrations in an array, no TCU behind it.

use super::ecu::XcpEcu;
use crate::diag::values::{Calibration, Snapshot};

/// A fake ECU: calibrations in an array, range-checked against the table's limits.
#[derive(Debug, Clone)]
pub(crate) struct FakeEcu {
    pub cals: [f64; 8],
    pub snap: Option<Snapshot>,
}

impl FakeEcu {
    pub fn new() -> FakeEcu {
        FakeEcu {
            cals: Calibration::ALL.map(|c| c.meta().min),
            snap: None,
        }
    }
}

/// The index of a calibration in [`Calibration::ALL`] (and in [`FakeEcu::cals`]).
pub(super) fn idx(cal: Calibration) -> usize {
    Calibration::ALL.iter().position(|c| *c == cal).unwrap_or(0)
}

impl XcpEcu for FakeEcu {
    fn calibration(&self, cal: Calibration) -> f64 {
        self.cals[idx(cal)]
    }
    fn set_calibration(&mut self, cal: Calibration, value: f64) -> Result<(), String> {
        let m = cal.meta();
        if !(m.min..=m.max).contains(&value) {
            return Err(format!("{} out of range", m.name));
        }
        self.cals[idx(cal)] = value;
        Ok(())
    }
    fn snapshot(&self) -> Option<Snapshot> {
        self.snap
    }
}

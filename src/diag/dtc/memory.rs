//! [`FaultMemory`]: the status byte of each DTC through the TCU's steps and operation cycles
//! (ISO 14229-1 annex D.2), ClearDiagnosticInformation (12.2), and the serialized form.

use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::*;

/// The fault memory: one [`DtcRecord`] per row of [`TABLE`].
#[derive(Debug, Clone, PartialEq)]
pub struct FaultMemory {
    records: [DtcRecord; TABLE.len()],
    dirty: bool,
    /// The time of the previous step in this operation cycle.
    last_update: Option<Duration>,
}

impl Default for FaultMemory {
    fn default() -> Self {
        FaultMemory::new()
    }
}

/// One DTC in the serialized form.
#[derive(Debug, Serialize, Deserialize)]
struct StoredDtc {
    dtc: u32,
    /// The SAE form, for a human reading the file (ignored on reading).
    #[serde(default, skip_deserializing)]
    name: String,
    status: u8,
    occurrences: u8,
    aging: u8,
    freeze: Option<FreezeFrame>,
}

/// The serialized form.
#[derive(Debug, Serialize, Deserialize)]
struct Stored {
    version: u32,
    dtcs: Vec<StoredDtc>,
}

impl FaultMemory {
    /// An empty memory: every DTC untested since the last clear.
    pub fn new() -> FaultMemory {
        FaultMemory {
            records: [DtcRecord::default(); TABLE.len()],
            dirty: false,
            last_update: None,
        }
    }

    /// Every DTC with its fault code and record, in table order.
    pub fn records(&self) -> impl Iterator<Item = (FaultCode, Dtc, &DtcRecord)> {
        TABLE
            .iter()
            .zip(self.records.iter())
            .map(|((f, d), r)| (*f, *d, r))
    }

    /// The record of a DTC.
    pub fn record(&self, dtc: Dtc) -> Option<&DtcRecord> {
        self.records()
            .find(|(_, d, _)| *d == dtc)
            .map(|(_, _, r)| r)
    }

    /// The status byte of a fault code's DTC (`None` for [`FaultCode::None`]).
    pub fn status_of(&self, fault: FaultCode) -> Option<u8> {
        self.records()
            .find(|(f, _, _)| *f == fault)
            .map(|(_, _, r)| r.status)
    }

    /// One TCU step: `fault` is the TCU's active fault, `inputs_fresh` whether all its inputs
    /// are fresh (a test runs when they are, or when its fault is active), `snapshot` the
    /// step's values (for the snapshot record of a first failure).
    pub fn update(
        &mut self,
        now: Duration,
        fault: FaultCode,
        inputs_fresh: bool,
        snapshot: &Snapshot,
    ) {
        let previous = self.last_update.unwrap_or(now);
        for ((code, _), r) in TABLE.iter().zip(self.records.iter_mut()) {
            let failed = *code == fault;
            if !(failed || inputs_fresh) {
                r.failing_since = None;
                continue;
            }
            let before = (
                r.status & !TEST_FAILED,
                r.occurrences,
                r.aging,
                r.freeze.is_some(),
            );
            r.status &=
                !(TEST_NOT_COMPLETED_SINCE_LAST_CLEAR | TEST_NOT_COMPLETED_THIS_OPERATION_CYCLE);
            if failed {
                fail(r, now, previous, snapshot);
            } else {
                r.status &= !TEST_FAILED;
                r.failing_since = None;
            }
            let after = (
                r.status & !TEST_FAILED,
                r.occurrences,
                r.aging,
                r.freeze.is_some(),
            );
            self.dirty |= before != after;
        }
        self.last_update = Some(now);
    }

    /// The start of an operation cycle (a start of the daemon): closes the previous cycle
    /// (pending and aging) and marks every test not completed in this one.
    pub fn start_operation_cycle(&mut self) {
        for r in self.records.iter_mut() {
            let before = (r.status, r.aging);
            let completed = r.status & TEST_NOT_COMPLETED_THIS_OPERATION_CYCLE == 0;
            let failed = r.status & TEST_FAILED_THIS_OPERATION_CYCLE != 0;
            if completed && !failed {
                r.status &= !PENDING_DTC;
                if r.status & CONFIRMED_DTC != 0 {
                    r.aging = r.aging.saturating_add(1);
                    if r.aging >= AGING_CYCLES {
                        r.status &= !CONFIRMED_DTC;
                        r.aging = 0;
                    }
                }
            }
            r.status &= !(TEST_FAILED | TEST_FAILED_THIS_OPERATION_CYCLE);
            r.status |= TEST_NOT_COMPLETED_THIS_OPERATION_CYCLE;
            r.failing_since = None;
            self.dirty |= before != (r.status, r.aging);
        }
        self.last_update = None;
    }

    /// ClearDiagnosticInformation: all DTCs ([`GROUP_ALL`]) or one.
    pub fn clear(&mut self, group: u32) -> Result<(), DtcError> {
        if group == GROUP_ALL {
            self.records = [DtcRecord::default(); TABLE.len()];
        } else {
            let i = TABLE
                .iter()
                .position(|(_, d)| d.value() == group)
                .ok_or(DtcError::UnknownDtc(group))?;
            if let Some(r) = self.records.get_mut(i) {
                *r = DtcRecord::default();
            }
        }
        self.dirty = true;
        Ok(())
    }

    /// Whether the memory changed since [`FaultMemory::mark_saved`] (or its loading); the
    /// test-failed bit alone does not count, it is not kept across cycles.
    pub fn is_dirty(&self) -> bool {
        self.dirty
    }

    /// The memory was saved.
    pub fn mark_saved(&mut self) {
        self.dirty = false;
    }

    /// The serialized form (JSON with [`FORMAT_VERSION`]).
    pub fn to_bytes(&self) -> Result<Vec<u8>, DtcError> {
        let stored = Stored {
            version: FORMAT_VERSION,
            dtcs: self
                .records()
                .map(|(_, d, r)| StoredDtc {
                    dtc: d.value(),
                    name: d.to_string(),
                    status: r.status,
                    occurrences: r.occurrences,
                    aging: r.aging,
                    freeze: r.freeze,
                })
                .collect(),
        };
        let mut bytes = serde_json::to_vec_pretty(&stored)?;
        bytes.push(b'\n');
        Ok(bytes)
    }

    /// A memory from its serialized form (not dirty). A DTC the file lacks is untested.
    pub fn from_bytes(bytes: &[u8]) -> Result<FaultMemory, DtcError> {
        let stored: Stored = serde_json::from_slice(bytes)?;
        if stored.version != FORMAT_VERSION {
            return Err(DtcError::UnsupportedVersion {
                found: stored.version,
            });
        }
        let mut memory = FaultMemory::new();
        let mut seen = [false; TABLE.len()];
        for s in stored.dtcs {
            let i = TABLE
                .iter()
                .position(|(_, d)| d.value() == s.dtc)
                .ok_or(DtcError::UnknownInFile(s.dtc))?;
            let (Some(seen), Some(r)) = (seen.get_mut(i), memory.records.get_mut(i)) else {
                continue;
            };
            if std::mem::replace(seen, true) {
                return Err(DtcError::Duplicate(s.dtc));
            }
            r.status = s.status & STATUS_AVAILABILITY_MASK;
            r.occurrences = s.occurrences;
            r.aging = s.aging;
            r.freeze = s.freeze;
        }
        Ok(memory)
    }
}

/// A failed step of one DTC.
fn fail(r: &mut DtcRecord, now: Duration, previous: Duration, snapshot: &Snapshot) {
    if r.status & TEST_FAILED_THIS_OPERATION_CYCLE == 0 {
        r.occurrences = r.occurrences.saturating_add(1);
    }
    r.aging = 0;
    r.status |=
        TEST_FAILED | TEST_FAILED_THIS_OPERATION_CYCLE | PENDING_DTC | TEST_FAILED_SINCE_LAST_CLEAR;
    if r.freeze.is_none() {
        r.freeze = Some(FreezeFrame::capture(snapshot));
    }
    let since = *r.failing_since.get_or_insert(previous);
    if now.saturating_sub(since) >= CONFIRMATION_TIME {
        r.status |= CONFIRMED_DTC;
    }
}

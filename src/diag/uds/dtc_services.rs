//! ReadDTCInformation (ISO 14229-1 clause 12.3) sub-functions 0x01 reportNumberOfDTCByStatusMask,
//! 0x02 reportDTCByStatusMask, 0x04 reportDTCSnapshotRecordByDTCNumber, 0x06
//! reportDTCExtDataRecordByDTCNumber and 0x0A reportSupportedDTC; ClearDiagnosticInformation
//! (12.2), over [`FaultMemory`].

use super::did::f32_be;
use super::nrc::Nrc;
use super::request::Request;
use crate::diag::dtc::memory::FaultMemory;
use crate::diag::dtc::{Dtc, DtcRecord, STATUS_AVAILABILITY_MASK};

/// DTCFormatIdentifier ISO_14229-1_DTCFormat.
const FORMAT_ISO_14229_1: u8 = 0x01;
/// The snapshot record number of the first failure.
const SNAPSHOT_RECORD: u8 = 0x01;
/// Extended data record numbers: occurrence and aging counters.
const OCCURRENCE_RECORD: u8 = 0x01;
const AGING_RECORD: u8 = 0x02;
/// "All records" for 0x04 and 0x06.
const ALL_RECORDS: u8 = 0xFF;

/// 0x19.
pub(super) fn read_dtc_information(req: &Request, memory: &FaultMemory) -> Result<Vec<u8>, Nrc> {
    let expected_len = match req.sub {
        0x01 | 0x02 => 3,
        0x04 | 0x06 => 6,
        0x0A => 2,
        _ => return Err(Nrc::SubFunctionNotSupported),
    };
    if req.bytes.len() != expected_len {
        return Err(Nrc::IncorrectMessageLength);
    }
    let mut r = vec![req.sid.response(), req.sub];
    let arg = |i: usize| req.bytes.get(i).copied().unwrap_or(0);
    match req.sub {
        0x01 => {
            let n = by_mask(memory, arg(2)).count();
            let [hi, lo] = u16::try_from(n).unwrap_or(u16::MAX).to_be_bytes();
            r.extend([STATUS_AVAILABILITY_MASK, FORMAT_ISO_14229_1, hi, lo]);
        }
        0x02 => {
            r.push(STATUS_AVAILABILITY_MASK);
            for (dtc, rec) in by_mask(memory, arg(2)) {
                r.extend(dtc.bytes());
                r.push(rec.status & STATUS_AVAILABILITY_MASK);
            }
        }
        0x0A => {
            r.push(STATUS_AVAILABILITY_MASK);
            for (_, dtc, rec) in memory.records() {
                r.extend(dtc.bytes());
                r.push(rec.status & STATUS_AVAILABILITY_MASK);
            }
        }
        _ => {
            let dtc = Dtc::from_bytes([arg(2), arg(3), arg(4)]);
            let rec = memory.record(dtc).ok_or(Nrc::RequestOutOfRange)?;
            r.extend(dtc.bytes());
            r.push(rec.status & STATUS_AVAILABILITY_MASK);
            if req.sub == 0x04 {
                snapshot_records(&mut r, rec, arg(5))?;
            } else {
                extended_records(&mut r, rec, arg(5))?;
            }
        }
    }
    Ok(r)
}

/// The DTCs whose status has a bit of `mask` (within the availability mask).
fn by_mask(memory: &FaultMemory, mask: u8) -> impl Iterator<Item = (Dtc, &DtcRecord)> {
    memory
        .records()
        .filter(move |(_, _, r)| r.status & mask & STATUS_AVAILABILITY_MASK != 0)
        .map(|(_, d, r)| (d, r))
}

/// `01 NN (DIDhi DIDlo value[4])*` when the first failure was captured; nothing otherwise.
fn snapshot_records(r: &mut Vec<u8>, rec: &DtcRecord, number: u8) -> Result<(), Nrc> {
    if !matches!(number, SNAPSHOT_RECORD | ALL_RECORDS) {
        return Err(Nrc::RequestOutOfRange);
    }
    if let Some(frame) = &rec.freeze {
        let ids = frame.identifiers();
        r.push(SNAPSHOT_RECORD);
        r.push(u8::try_from(ids.len()).unwrap_or(u8::MAX));
        for (did, v) in ids {
            r.extend(did.number().to_be_bytes());
            r.extend(f32_be(v));
        }
    }
    Ok(())
}

/// `01 occurrences`, `02 aging`, or both for 0xFF.
fn extended_records(r: &mut Vec<u8>, rec: &DtcRecord, number: u8) -> Result<(), Nrc> {
    match number {
        OCCURRENCE_RECORD => r.extend([OCCURRENCE_RECORD, rec.occurrences]),
        AGING_RECORD => r.extend([AGING_RECORD, rec.aging]),
        ALL_RECORDS => r.extend([OCCURRENCE_RECORD, rec.occurrences, AGING_RECORD, rec.aging]),
        _ => return Err(Nrc::RequestOutOfRange),
    }
    Ok(())
}

/// 0x14 `14 G G G`: `54`.
pub(super) fn clear(req: &Request, memory: &mut FaultMemory) -> Result<Vec<u8>, Nrc> {
    let [_, a, b, c] = req.bytes else {
        return Err(Nrc::IncorrectMessageLength);
    };
    memory
        .clear(u32::from_be_bytes([0, *a, *b, *c]))
        .map_err(|_| Nrc::RequestOutOfRange)?;
    Ok(vec![req.sid.response()])
}

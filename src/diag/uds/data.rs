//! ReadDataByIdentifier (ISO 14229-1 clause 11.2) and WriteDataByIdentifier (11.7) over the
//! DIDs of [`super::did`]: a read skips unsupported DIDs and answers 0x31 only when none is
//! supported (11.2.3); a write reaches the calibrations only, in the extended session with
//! security unlocked, range-checked (0x31).

use super::did::{ascii16, f32_be, Did};
use super::ecu::UdsEcu;
use super::nrc::Nrc;
use super::request::Request;
use crate::diag::isotp::MAX_PAYLOAD;

/// The value bytes of a DID.
fn value(did: Did, ecu: &impl UdsEcu) -> Vec<u8> {
    let snapshot = ecu.snapshot();
    match did {
        Did::Identification(id) => ascii16(&ecu.identification(id)).to_vec(),
        Did::Measurement(m) => f32_be(snapshot.map_or(f64::NAN, |s| m.value(&s))).to_vec(),
        Did::TcuTime => f32_be(snapshot.map_or(f64::NAN, |s| s.t_s)).to_vec(),
        Did::Calibration(c) => f32_be(ecu.calibration(c)).to_vec(),
        Did::LearnedKiss(i) => f32_be(ecu.learned_kiss_point(i).unwrap_or(f64::NAN)).to_vec(),
    }
}

/// 0x22: `62 (DIDhi DIDlo value)*`.
pub(super) fn read_data(req: &Request, ecu: &impl UdsEcu) -> Result<Vec<u8>, Nrc> {
    let dids = req.bytes.get(1..).unwrap_or_default();
    if dids.is_empty() || dids.len() % 2 != 0 {
        return Err(Nrc::IncorrectMessageLength);
    }
    let mut response = vec![req.sid.response()];
    let mut any = false;
    for pair in dids.chunks_exact(2) {
        let &[hi, lo] = pair else {
            continue;
        };
        let Some(did) = Did::from_u16(u16::from_be_bytes([hi, lo])) else {
            continue;
        };
        any = true;
        response.extend_from_slice(pair);
        response.extend(value(did, ecu));
        if response.len() > MAX_PAYLOAD {
            return Err(Nrc::ResponseTooLong);
        }
    }
    if !any {
        return Err(Nrc::RequestOutOfRange);
    }
    Ok(response)
}

/// 0x2E: `6E DIDhi DIDlo` (`unlocked`: security level 1 is unlocked).
pub(super) fn write_data(
    req: &Request,
    unlocked: bool,
    ecu: &mut impl UdsEcu,
) -> Result<Vec<u8>, Nrc> {
    let (Some(&hi), Some(&lo)) = (req.bytes.get(1), req.bytes.get(2)) else {
        return Err(Nrc::IncorrectMessageLength);
    };
    if req.bytes.len() < 4 {
        return Err(Nrc::IncorrectMessageLength);
    }
    let Some(Did::Calibration(cal)) = Did::from_u16(u16::from_be_bytes([hi, lo])) else {
        return Err(Nrc::RequestOutOfRange);
    };
    if !unlocked {
        return Err(Nrc::SecurityAccessDenied);
    }
    let raw = req
        .bytes
        .get(3..)
        .and_then(|v| <[u8; 4]>::try_from(v).ok())
        .ok_or(Nrc::IncorrectMessageLength)?;
    let v = f64::from(f32::from_be_bytes(raw));
    let meta = cal.meta();
    if !(v >= meta.min && v <= meta.max) {
        return Err(Nrc::RequestOutOfRange);
    }
    ecu.set_calibration(cal, v)
        .map_err(|_| Nrc::RequestOutOfRange)?;
    Ok(vec![req.sid.response(), hi, lo])
}

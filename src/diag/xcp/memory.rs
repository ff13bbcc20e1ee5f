//! The XCP slave's memory map, derived from [`crate::diag::values`]: address granularity BYTE,
//! address extension 0, Intel byte order.
//!
//! | area | addresses | content | read (UPLOAD, SHORT_UPLOAD, DAQ) | write (DOWNLOAD) |
//! |---|---|---|---|---|
//! | measurements | [`MEASUREMENT_BASE`](crate::diag::values::MEASUREMENT_BASE) + 4·i | `f32` LE of measurement i of the last [`Snapshot`] (NaN before the first step) | any byte range | `ERR_WRITE_PROTECTED` |
//! | calibrations | [`CALIBRATION_BASE`] + 4·i | `f32` LE of calibration i of the ECU | any byte range | whole aligned `f32`s only, range-checked |
//! | texts | [`TEXT_BASE`] … | the event channel names and GET_ID texts (ASCII), read after GET_DAQ_EVENT_INFO / GET_ID set the MTA to them | any byte range | `ERR_WRITE_PROTECTED` |
//! | anything else | | | `ERR_ACCESS_DENIED` | `ERR_ACCESS_DENIED` |
//!
//! A write of a calibration goes through [`XcpEcu::set_calibration`]; a value outside the
//! calibration's declared limits, not finite, or refused by the ECU is `ERR_OUT_OF_RANGE` and
//! changes nothing. A write that covers part of an `f32` (misaligned or not a multiple of 4
//! bytes) is `ERR_OUT_OF_RANGE`: the slave keeps no shadow bytes between commands. Reading a
//! range is all or nothing: one byte outside the map and the whole access is refused.

use super::ecu::XcpEcu;
use super::packet::ErrorCode;
use crate::diag::values::{Calibration, Measurement, Snapshot, CALIBRATION_BASE};

/// Start of the read-only text area (event channel names, GET_ID texts).
pub const TEXT_BASE: u32 = 0x0003_0000;

/// Name of event channel 0 (the TCU's 10 ms cycle).
pub(crate) const EVENT_NAME: &str = "10ms";
/// GET_ID type 0 (ASCII text identifying the slave).
pub(crate) const ID_ASCII: &str = "ddct virtual TCU";
/// GET_ID type 1 (the ASAM MC2 file name without path and extension: `ddct.a2l`).
pub(crate) const ID_A2L_NAME: &str = "ddct";

/// The texts of the text area, each at its address.
const TEXTS: [(u32, &str); 3] = [
    (TEXT_BASE, EVENT_NAME),
    (TEXT_BASE + 256, ID_ASCII),
    (TEXT_BASE + 0x200, ID_A2L_NAME),
];

/// The address of the text for GET_ID type `id_type`, with its length; `None` for a type the
/// slave has no text for.
pub(crate) fn id_text(id_type: u8) -> Option<(u32, u32)> {
    let (addr, text) = match id_type {
        0 => TEXTS[1],
        1 => TEXTS[2],
        _ => return None,
    };
    Some((addr, text.len() as u32))
}

/// The address and length of an event channel's name.
pub(crate) fn event_name(event: u16) -> Option<(u32, u32)> {
    (event == 0).then_some((TEXTS[0].0, EVENT_NAME.len() as u32))
}

/// Bytes of the measurement area.
pub(crate) fn measurement_area_len() -> u32 {
    4 * Measurement::ALL.len() as u32
}

/// Bytes of the calibration area.
pub(crate) fn calibration_area_len() -> u32 {
    4 * Calibration::ALL.len() as u32
}

/// The byte at `addr`, `None` outside the map.
fn byte_at(addr: u32, snapshot: Option<&Snapshot>, ecu: &impl XcpEcu) -> Option<u8> {
    let word_addr = addr & !3;
    let lane = (addr & 3) as usize;
    if let Some(m) = Measurement::at(word_addr) {
        let v = snapshot.map_or(f32::NAN, |s| m.value(s) as f32);
        return Some(v.to_le_bytes()[lane]);
    }
    if let Some(c) = Calibration::at(word_addr) {
        return Some((ecu.calibration(c) as f32).to_le_bytes()[lane]);
    }
    TEXTS.iter().find_map(|(base, text)| {
        let off = addr.checked_sub(*base)?;
        text.as_bytes().get(off as usize).copied()
    })
}

/// Reads `len` bytes from `addr`: `ERR_ACCESS_DENIED` if any byte is outside the map (or the
/// range wraps around the address space).
pub fn read(
    addr: u32,
    len: u8,
    snapshot: Option<&Snapshot>,
    ecu: &impl XcpEcu,
) -> Result<Vec<u8>, ErrorCode> {
    (0..u32::from(len))
        .map(|i| {
            let a = addr.checked_add(i).ok_or(ErrorCode::AccessDenied)?;
            byte_at(a, snapshot, ecu).ok_or(ErrorCode::AccessDenied)
        })
        .collect()
}

/// Whether `len` bytes from `addr` are all readable (the check of WRITE_DAQ).
pub(crate) fn readable(addr: u32, len: u8, ecu: &impl XcpEcu) -> bool {
    read(addr, len, None, ecu).is_ok()
}

/// Writes `data` at `addr`: whole aligned calibrations only (see the module doc).
pub fn write(addr: u32, data: &[u8], ecu: &mut impl XcpEcu) -> Result<(), ErrorCode> {
    let end = addr
        .checked_add(data.len() as u32)
        .ok_or(ErrorCode::AccessDenied)?;
    let cal_end = CALIBRATION_BASE + calibration_area_len();
    if addr < CALIBRATION_BASE || end > cal_end {
        let readable_here = read(addr, data.len().min(255) as u8, None, ecu).is_ok();
        return Err(if readable_here && !data.is_empty() {
            ErrorCode::WriteProtected
        } else {
            ErrorCode::AccessDenied
        });
    }
    if addr % 4 != 0 || data.len() % 4 != 0 {
        return Err(ErrorCode::OutOfRange);
    }
    let mut values = Vec::with_capacity(data.len() / 4);
    for (k, chunk) in data.chunks_exact(4).enumerate() {
        let cal = Calibration::at(addr + 4 * k as u32).ok_or(ErrorCode::AccessDenied)?;
        let v = f64::from(f32::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3]]));
        let meta = cal.meta();
        if !v.is_finite() || v < meta.min || v > meta.max {
            return Err(ErrorCode::OutOfRange);
        }
        values.push((cal, v));
    }
    apply(values, ecu)
}

/// Sets the checked values; if the ECU refuses one, the ones already set are put back.
fn apply(values: Vec<(Calibration, f64)>, ecu: &mut impl XcpEcu) -> Result<(), ErrorCode> {
    let mut done: Vec<(Calibration, f64)> = Vec::new();
    for (cal, v) in values {
        let old = ecu.calibration(cal);
        if ecu.set_calibration(cal, v).is_err() {
            for (c, o) in done.into_iter().rev() {
                // Restoring a value the ECU held: accepted by the same validation.
                let _ = ecu.set_calibration(c, o);
            }
            return Err(ErrorCode::OutOfRange);
        }
        done.push((cal, old));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::fake_ecu::FakeEcu;
    use super::*;
    use crate::diag::values::MEASUREMENT_BASE;

    #[test]
    fn the_areas_follow_the_values_table() {
        assert_eq!(measurement_area_len(), 4 * 19);
        assert_eq!(calibration_area_len(), 4 * 8);
        let ecu = FakeEcu::new();
        // Straddling the end of the measurement area.
        let last = MEASUREMENT_BASE + measurement_area_len() - 2;
        assert_eq!(read(last, 2, None, &ecu).map(|v| v.len()), Ok(2));
        assert_eq!(read(last, 3, None, &ecu), Err(ErrorCode::AccessDenied));
        assert_eq!(read(u32::MAX, 2, None, &ecu), Err(ErrorCode::AccessDenied));
        // Before the first step a measurement reads NaN.
        assert_eq!(
            read(MEASUREMENT_BASE, 4, None, &ecu),
            Ok(f32::NAN.to_le_bytes().to_vec())
        );
        assert_eq!(read(TEXT_BASE, 4, None, &ecu), Ok(b"10ms".to_vec()));
    }

    #[test]
    fn writes_are_whole_calibrations() {
        let mut ecu = FakeEcu::new();
        let kp = Calibration::ClutchKp.address();
        assert_eq!(write(kp, &12.5f32.to_le_bytes(), &mut ecu), Ok(()));
        assert_eq!(ecu.calibration(Calibration::ClutchKp), 12.5);
        assert_eq!(write(kp + 1, &[0; 4], &mut ecu), Err(ErrorCode::OutOfRange));
        assert_eq!(write(kp, &[0; 2], &mut ecu), Err(ErrorCode::OutOfRange));
        assert_eq!(
            write(MEASUREMENT_BASE, &[0; 4], &mut ecu),
            Err(ErrorCode::WriteProtected)
        );
        assert_eq!(
            write(TEXT_BASE, &[0; 4], &mut ecu),
            Err(ErrorCode::WriteProtected)
        );
        assert_eq!(write(0x10, &[0; 4], &mut ecu), Err(ErrorCode::AccessDenied));
        assert_eq!(ecu.calibration(Calibration::ClutchKp), 12.5);
    }
}

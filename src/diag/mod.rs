//! Diagnostics on the bus (issue 16): the ISO 15765-2 transport (`isotp`), the table of the
//! TCU's measurements and calibrations reachable on the bus (`values`), the UDS server of
//! ISO 14229-1 (`uds`) with the fault memory of its clause 12 and annex D (`dtc`) and the
//! fault memory's file (`store`, the only file IO here); the XCP slave builds on them too.
//! Pure cores like the TCU's: time is an argument.

pub mod a2l;
pub mod dtc;
pub mod ecu;
pub mod isotp;
pub mod stack;
pub mod store;
pub mod uds;
pub mod values;
pub mod xcp;

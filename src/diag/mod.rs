//! Diagnostics on the bus (issue 16): the ISO 15765-2 transport (`isotp`), the table of the
//! TCU's measurements and calibrations reachable on the bus (`values`); the UDS server
//! (ISO 14229-1) and the XCP slave build on them. Pure cores like the TCU's.

pub mod a2l;
pub mod isotp;
pub mod values;
pub mod xcp;

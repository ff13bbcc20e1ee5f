//! Diagnostics on the bus (issue 16): the ISO 15765-2 transport (`isotp`), a pure core like the
//! TCU's. The UDS server (ISO 14229-1) and the XCP slave build on it.

pub mod isotp;

//! An XCP on CAN slave (ASAM MCD-1 XCP 1.x) as a pure core: the shell passes each CRO received
//! on `TCU_XCP_CRO` (0x7F0) with the time to [`XcpSlave::handle_cro`] and sends the answer on
//! `TCU_XCP_DTO` (0x7F1); after each TCU step it calls [`XcpSlave::on_event`] for event channel
//! 0 ("10ms") and sends the DAQ packets. Nothing here reads a clock or a socket; the ECU is
//! reached through [`XcpEcu`].
//!
//! - [`packet`]: command and error codes, the CRO layouts, response and error packets.
//! - [`memory`]: the memory map from [`crate::diag::values`] (measurements, calibrations as
//!   `f32` Intel) and its read and write rules.
//! - [`daq`]: dynamic DAQ lists, their allocation and the DAQ packets (DTO).
//! - [`slave`]: the command processor.
//!
//! Written against the master pyxcp 0.29.14 (source at christoph2/pyxcp 22b6c60; its `Master`
//! and `DaqProcessor.setup`; PyPI's latest is 0.29.20, to be pinned and checked): CONNECT,
//! GET_STATUS, GET_COMM_MODE_INFO, GET_ID + UPLOAD, SET_MTA + UPLOAD, SHORT_UPLOAD, DOWNLOAD; the
//! DAQ setup GET_DAQ_PROCESSOR_INFO, GET_DAQ_RESOLUTION_INFO, FREE_DAQ, ALLOC_DAQ, ALLOC_ODT
//! (each list), ALLOC_ODT_ENTRY (each ODT), SET_DAQ_PTR + WRITE_DAQ (each non-empty ODT),
//! SET_DAQ_LIST_MODE and START_STOP_DAQ_LIST(select) (each list), START_STOP_SYNCH(start
//! selected) and, to stop, START_STOP_SYNCH(stop all).

pub mod daq;
mod ecu;
#[cfg(test)]
mod fake_ecu;
pub mod memory;
pub mod packet;
pub mod slave;

pub use ecu::XcpEcu;
pub use packet::{Command, ErrorCode, Request};
pub use slave::XcpSlave;

#[cfg(test)]
pub(crate) mod tests;

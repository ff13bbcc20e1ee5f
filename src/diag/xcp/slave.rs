//! The XCP slave's command processor: the session (CONNECT / DISCONNECT), the memory transfer
//! address (MTA) and the answers to each command of [`super::packet`], with the DAQ lists of
//! [`super::daq`] and the memory map of [`super::memory`].
//!
//! Positive responses (after `FF`; words and double words Intel):
//!
//! | command | response parameters |
//! |---|---|
//! | CONNECT | RESOURCE 0x05 (CAL/PAG, DAQ), COMM_MODE_BASIC 0x80 (Intel, granularity BYTE, no slave block mode, GET_COMM_MODE_INFO available), MAX_CTO 8, MAX_DTO 8 (2), protocol layer 1, transport layer 1 |
//! | GET_STATUS | session status (0x40 DAQ_RUNNING), protection 0 (nothing locked), state number 0, session configuration id 0 (2) |
//! | GET_COMM_MODE_INFO | reserved, COMM_MODE_OPTIONAL 0, reserved, MAX_BS 0, MIN_ST 0, QUEUE_SIZE 0, driver version 0x10 |
//! | GET_ID | mode 0 (upload the text from the MTA), reserved (2), length (4); the MTA is set to the text |
//! | UPLOAD, SHORT_UPLOAD | n bytes (n ≤ MAX_CTO − 1 = 7); the MTA advances by n |
//! | GET_DAQ_PROCESSOR_INFO | properties 0x13 (dynamic, prescaler, timestamps), MAX_DAQ 4 (2), MAX_EVENT_CHANNEL 1 (2), MIN_DAQ 0, DAQ_KEY_BYTE 0 (absolute ODT number as PID) |
//! | GET_DAQ_RESOLUTION_INFO | granularity DAQ 1, max entry DAQ 7, granularity STIM 1, max entry STIM 0, timestamp mode 0x34 (4 bytes, not fixed, unit 1 µs), ticks 1 (2) |
//! | GET_DAQ_EVENT_INFO | properties 0x84 (DAQ, consistency per event channel), MAX_DAQ_LIST 4, name length, cycle 10, unit 6 (1 ms), priority 0; the MTA is set to the name |
//! | GET_DAQ_LIST_INFO | properties 0x04 (DAQ), MAX_ODT 32, MAX_ODT_ENTRIES 7, fixed event 0 (2) |
//! | GET_DAQ_LIST_MODE | mode, reserved (2), event (2), prescaler, priority |
//! | START_STOP_DAQ_LIST | first PID |
//! | READ_DAQ | bit offset 0xFF, size, extension 0, address (4) |
//! | GET_DAQ_CLOCK | reserved (3), timestamp (4), the µs ticks of `now` |
//! | others | none |
//!
//! SYNCH answers `FE 00` (ERR_CMD_SYNCH). Before CONNECT every command but CONNECT is ignored
//! (no response); a CONNECT while connected is answered again and keeps the session. DISCONNECT
//! stops and frees the DAQ lists. UPLOAD / SHORT_UPLOAD / DOWNLOAD with n = 0 or beyond the CTO
//! (7, resp. 6 for DOWNLOAD) are `ERR_OUT_OF_RANGE`; a DOWNLOAD shorter than its n is
//! `ERR_CMD_SYNTAX`. An address extension other than 0 is `ERR_OUT_OF_RANGE`.

use std::time::Duration;

use super::daq::{self, DaqTables};
use super::ecu::XcpEcu;
use super::memory;
use super::packet::{self, ErrorCode, Request};
use crate::diag::values::Snapshot;

/// Bytes of a CTO (MAX_CTO).
pub(crate) const MAX_CTO: usize = 8;
/// CONNECT: the resources (bit 0 CAL/PAG, bit 2 DAQ).
pub(crate) const RESOURCE: u8 = 0x05;
/// CONNECT: COMM_MODE_BASIC (bit 7 OPTIONAL; byte order Intel, granularity BYTE: 0).
pub(crate) const COMM_MODE_BASIC: u8 = 0x80;
/// XCP protocol layer version (major of 1.x) and transport layer version (XCP on CAN 1.x).
pub(crate) const PROTOCOL_LAYER_VERSION: u8 = 0x01;
pub(crate) const TRANSPORT_LAYER_VERSION: u8 = 0x01;
/// Cycle of event channel 0 (ms).
pub(crate) const EVENT_CYCLE_MS: u8 = 10;

/// The XCP slave.
#[derive(Debug, Clone, Default)]
pub struct XcpSlave {
    connected: bool,
    mta: u32,
    daq: DaqTables,
}

type Answer = Result<Vec<u8>, ErrorCode>;

fn ok(params: &[u8]) -> Answer {
    Ok(packet::positive(params))
}

fn ticks(now: Duration) -> [u8; 4] {
    (now.as_micros() as u32).to_le_bytes()
}

impl XcpSlave {
    pub fn new() -> XcpSlave {
        XcpSlave::default()
    }

    /// Whether a master is connected.
    pub fn connected(&self) -> bool {
        self.connected
    }

    /// Whether a DAQ list is running.
    pub fn daq_running(&self) -> bool {
        self.daq.running()
    }

    /// The answer to one CRO (the response or error packet), `None` when there is none (empty
    /// packet, or any command but CONNECT before CONNECT).
    pub fn handle_cro(
        &mut self,
        now: Duration,
        cro: &[u8],
        ecu: &mut impl XcpEcu,
    ) -> Option<Vec<u8>> {
        let decoded = packet::decode(cro)?;
        let connect = matches!(decoded, Ok(Request::Connect { .. }));
        if !self.connected && !connect {
            return None;
        }
        let answer = decoded.and_then(|req| self.dispatch(now, req, ecu));
        Some(answer.unwrap_or_else(packet::error))
    }

    /// The DAQ packets of the running lists bound to `event` (channel 0: the 10 ms cycle).
    pub fn on_event(
        &mut self,
        now: Duration,
        event: u16,
        snapshot: &Snapshot,
        ecu: &impl XcpEcu,
    ) -> Vec<Vec<u8>> {
        if !self.connected {
            return Vec::new();
        }
        self.daq.sample(now, event, snapshot, ecu)
    }

    fn dispatch(&mut self, now: Duration, req: Request<'_>, ecu: &mut impl XcpEcu) -> Answer {
        match req {
            Request::Connect { .. } => {
                self.connected = true;
                let [d0, d1] = (daq::MAX_DTO as u16).to_le_bytes();
                ok(&[
                    RESOURCE,
                    COMM_MODE_BASIC,
                    MAX_CTO as u8,
                    d0,
                    d1,
                    PROTOCOL_LAYER_VERSION,
                    TRANSPORT_LAYER_VERSION,
                ])
            }
            Request::Disconnect => {
                self.connected = false;
                self.daq.free();
                ok(&[])
            }
            Request::GetStatus => {
                let session = if self.daq.running() { 0x40 } else { 0 };
                ok(&[session, 0, 0, 0, 0])
            }
            Request::Synch => Err(ErrorCode::CmdSynch),
            Request::GetCommModeInfo => ok(&[0, 0, 0, 0, 0, 0, 0x10]),
            Request::GetId { id_type } => {
                let (addr, len) = memory::id_text(id_type).unwrap_or((self.mta, 0));
                self.mta = addr;
                let l = len.to_le_bytes();
                ok(&[0, 0, 0, l[0], l[1], l[2], l[3]])
            }
            Request::SetMta { ext, address } => {
                check_ext(ext)?;
                self.mta = address;
                ok(&[])
            }
            Request::Upload { n } => self.upload(self.mta, n, ecu),
            Request::ShortUpload { n, ext, address } => {
                check_ext(ext)?;
                self.upload(address, n, ecu)
            }
            Request::Download { n, data } => self.download(n, data, ecu),
            other => self.dispatch_daq(now, other, ecu),
        }
    }

    fn upload(&mut self, addr: u32, n: u8, ecu: &impl XcpEcu) -> Answer {
        if n == 0 || usize::from(n) > MAX_CTO - 1 {
            return Err(ErrorCode::OutOfRange);
        }
        let snapshot = ecu.snapshot();
        let data = memory::read(addr, n, snapshot.as_ref(), ecu)?;
        self.mta = addr.wrapping_add(u32::from(n));
        Ok(packet::positive(&data))
    }

    /// DOWNLOAD of `n` bytes at the MTA; `data` is everything after `F0 n`.
    fn download(&mut self, n: u8, data: &[u8], ecu: &mut impl XcpEcu) -> Answer {
        let n = usize::from(n);
        if n == 0 || n > MAX_CTO - 2 {
            return Err(ErrorCode::OutOfRange);
        }
        let bytes = data.get(..n).ok_or(ErrorCode::CmdSyntax)?;
        memory::write(self.mta, bytes, ecu)?;
        self.mta = self.mta.wrapping_add(n as u32);
        ok(&[])
    }

    fn dispatch_daq(&mut self, now: Duration, req: Request<'_>, ecu: &mut impl XcpEcu) -> Answer {
        match req {
            Request::GetDaqProcessorInfo => {
                let [m0, m1] = daq::MAX_DAQ_LISTS.to_le_bytes();
                ok(&[0x13, m0, m1, 1, 0, 0, 0])
            }
            Request::GetDaqResolutionInfo => ok(&[1, daq::MAX_ODT_ENTRY_SIZE, 1, 0, 0x34, 1, 0]),
            Request::GetDaqEventInfo { event } => {
                let (addr, len) = memory::event_name(event).ok_or(ErrorCode::OutOfRange)?;
                self.mta = addr;
                let max_lists = daq::MAX_DAQ_LISTS as u8;
                ok(&[0x84, max_lists, len as u8, EVENT_CYCLE_MS, 6, 0])
            }
            Request::GetDaqListInfo { daq } => ok(&self.daq.list_info(daq)?),
            Request::GetDaqClock => {
                let t = ticks(now);
                ok(&[0, 0, 0, t[0], t[1], t[2], t[3]])
            }
            Request::FreeDaq => {
                self.daq.free();
                ok(&[])
            }
            Request::AllocDaq { count } => self.daq.alloc_daq(count).and_then(|()| ok(&[])),
            Request::AllocOdt { daq, count } => {
                self.daq.alloc_odt(daq, count).and_then(|()| ok(&[]))
            }
            Request::AllocOdtEntry { daq, odt, count } => self
                .daq
                .alloc_odt_entry(daq, odt, count)
                .and_then(|()| ok(&[])),
            Request::SetDaqPtr { daq, odt, entry } => {
                self.daq.set_ptr(daq, odt, entry).and_then(|()| ok(&[]))
            }
            Request::WriteDaq {
                bit_offset,
                size,
                ext,
                address,
            } => self
                .daq
                .write(bit_offset, size, ext, address, ecu)
                .and_then(|()| ok(&[])),
            Request::ReadDaq => ok(&self.daq.read()?),
            Request::ClearDaqList { daq } => self.daq.clear(daq).and_then(|()| ok(&[])),
            Request::SetDaqListMode {
                mode,
                daq,
                event,
                prescaler,
                priority,
            } => self
                .daq
                .set_mode(mode, daq, event, prescaler, priority)
                .and_then(|()| ok(&[])),
            Request::GetDaqListMode { daq } => ok(&self.daq.get_mode(daq)?),
            Request::StartStopDaqList { mode, daq } => ok(&[self.daq.start_stop(mode, daq)?]),
            Request::StartStopSynch { mode } => {
                self.daq.start_stop_synch(mode).and_then(|()| ok(&[]))
            }
            // Handled by `dispatch`.
            _ => Err(ErrorCode::CmdUnknown),
        }
    }
}

fn check_ext(ext: u8) -> Result<(), ErrorCode> {
    if ext == 0 {
        Ok(())
    } else {
        Err(ErrorCode::OutOfRange)
    }
}

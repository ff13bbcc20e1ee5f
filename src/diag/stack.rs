//! The TCU's diagnostic side on the bus as one pure core, in the style of [`crate::tcu::Tcu`]:
//! the shell hands it the diagnostic frames it receives ([`DiagStack::handle_frame`]), tells it
//! about each TCU step ([`DiagStack::after_step`]: the fault memory's tests and the XCP event of
//! the 10 ms cycle), sends what [`DiagStack::poll_transmit`] gives and wakes it at
//! [`DiagStack::poll_timeout`]. Time is an argument; nothing here reads a clock or touches a
//! socket or a file.
//!
//! - UDS (ISO 14229-1) on ISO-TP (ISO 15765-2): physical requests on TCU_DiagReq, functional
//!   ones (single frames) on DIAG_FunctionalReq, responses on TCU_DiagResp.
//! - XCP on CAN: commands on TCU_XcpCro, responses and DAQ packets on TCU_XcpDto.
//! - The fault memory: a DTC per TCU fault code, tested at every step.
//!
//! The values the protocols read and write are the TCU's, through [`TcuEcu`].

use super::dtc::memory::FaultMemory;
use super::ecu::TcuEcu;
use super::isotp::{IsoTp, IsoTpConfig};
use super::uds::{ResetKind, UdsServer};
use super::values::Snapshot;
use super::xcp::XcpSlave;
use crate::can::messages::{ids, TcuState};
use crate::can::CanFrame;
use crate::tcu::{Tcu, TcuOutputs};
use std::collections::VecDeque;
use std::time::Duration;

/// The fault memory's tests are enabled once the TCU has left Init (every input seen valid) or
/// this long after its start, whichever comes first: a bench whose plant starts a moment after
/// the TCU logs no lost-communication DTC for it, a plant that never comes still does.
pub(crate) const TEST_ENABLE_AFTER: Duration = Duration::from_secs(2);

/// The XCP event channel of the TCU's 10 ms cycle.
pub(crate) const CYCLE_EVENT: u16 = 0;

/// The ids the diagnostic side listens to (a SocketCAN filter adds them to the TCU's inputs).
pub const REQUEST_IDS: [u16; 3] = [
    ids::DIAG_FUNCTIONAL_REQ,
    ids::TCU_DIAG_REQ,
    ids::TCU_XCP_CRO,
];

/// How the diagnostic side is set up.
#[derive(Debug, Clone, PartialEq)]
pub struct DiagConfig {
    /// ECU serial number (DID 0xF18C).
    pub serial: String,
    /// The TCU's ISO-TP settings (block size and STmin asked of a tester, padding, timeouts).
    pub isotp: IsoTpConfig,
    /// Seed of the SecurityAccess seeds' generator (the shell draws it at start).
    pub seed: u64,
}

impl Default for DiagConfig {
    fn default() -> Self {
        DiagConfig {
            serial: "DDCT-0001".into(),
            isotp: IsoTpConfig {
                block_size: 8,
                ..IsoTpConfig::default()
            },
            seed: 0x5eed,
        }
    }
}

/// The diagnostic side: transport, UDS server, XCP slave, fault memory.
#[derive(Debug)]
pub struct DiagStack {
    tp: IsoTp,
    uds: UdsServer,
    xcp: XcpSlave,
    memory: FaultMemory,
    /// XCP packets to send, as frames on TCU_XcpDto (first come first).
    xcp_out: VecDeque<CanFrame>,
    snapshot: Option<Snapshot>,
    /// The fault memory's tests run (see [`TEST_ENABLE_AFTER`]).
    tests_enabled: bool,
    serial: String,
    rng: u64,
    reset: Option<ResetKind>,
}

impl DiagStack {
    /// The diagnostic side with the fault memory `memory` (loaded by the shell).
    pub fn new(cfg: DiagConfig, memory: FaultMemory) -> Self {
        DiagStack {
            tp: IsoTp::new(cfg.isotp),
            uds: UdsServer::new(),
            xcp: XcpSlave::new(),
            memory,
            xcp_out: VecDeque::new(),
            snapshot: None,
            tests_enabled: false,
            serial: cfg.serial,
            rng: cfg.seed,
            reset: None,
        }
    }

    /// Whether `id` is one of the diagnostic requests.
    pub fn handles(id: u16) -> bool {
        REQUEST_IDS.contains(&id)
    }

    /// A received diagnostic frame at `now`; frames of other ids are ignored.
    pub fn handle_frame(&mut self, now: Duration, frame: &CanFrame, tcu: &mut Tcu) {
        let data = frame.bytes();
        match frame.standard_id() {
            Some(ids::TCU_DIAG_REQ) => {
                if let Some(req) = self.tp.handle_frame(now, data) {
                    self.serve(now, &req, false, tcu);
                }
            }
            Some(ids::DIAG_FUNCTIONAL_REQ) => {
                if let Some(req) = self.tp.handle_functional(data) {
                    self.serve(now, &req, true, tcu);
                }
            }
            Some(ids::TCU_XCP_CRO) => {
                let mut ecu = TcuEcu::new(tcu, self.snapshot, &self.serial, &mut self.rng);
                if let Some(resp) = self.xcp.handle_cro(now, data, &mut ecu) {
                    self.push_xcp(&resp);
                }
            }
            _ => {}
        }
    }

    /// One UDS request: the response goes out on ISO-TP (a transfer still under way is
    /// abandoned: the tester asked again).
    fn serve(&mut self, now: Duration, req: &[u8], functional: bool, tcu: &mut Tcu) {
        let mut ecu = TcuEcu::new(tcu, self.snapshot, &self.serial, &mut self.rng);
        let resp = self
            .uds
            .handle(now, req, functional, &mut ecu, &mut self.memory);
        if let Some(resp) = resp {
            // A response longer than ISO-TP carries is cut by the server; a send error here
            // means a transfer under way, which the new response replaces.
            if self.tp.send(now, &resp).is_err() {
                self.tp.abort_send();
                let _ = self.tp.send(now, &resp);
            }
        }
        if let Some(kind) = self.uds.take_reset() {
            self.reset = Some(kind);
        }
    }

    fn push_xcp(&mut self, packet: &[u8]) {
        // The slave's packets are at most MAX_DTO (8) bytes; a longer one is a slave bug and dropped.
        if let Ok(f) = CanFrame::standard(ids::TCU_XCP_DTO, packet) {
            self.xcp_out.push_back(f);
        }
    }

    /// After each TCU step at core time `core_now`: the fault memory's tests on this step's
    /// fault code (timed in the core's time, so a lockstep bench confirms in exact cycles) and
    /// the XCP event of the cycle at `now` (DAQ packets stamped on the diagnostic side's time).
    pub fn after_step(
        &mut self,
        now: Duration,
        core_now: Duration,
        out: &TcuOutputs,
        tcu: &mut Tcu,
    ) {
        let snapshot = Snapshot::new(out, tcu.kiss_points());
        self.snapshot = Some(snapshot);
        self.tests_enabled |= out.trace.state != TcuState::Init || core_now >= TEST_ENABLE_AFTER;
        if self.tests_enabled {
            let fresh = tcu.health(core_now).all_fresh;
            self.memory
                .update(core_now, out.trace.fault, fresh, &snapshot);
        }
        let ecu = TcuEcu::new(tcu, self.snapshot, &self.serial, &mut self.rng);
        let packets = self.xcp.on_event(now, CYCLE_EVENT, &snapshot, &ecu);
        for p in packets {
            self.push_xcp(&p);
        }
    }

    /// The next frame to send: XCP packets first (a DAQ sample belongs to its cycle), then the
    /// ISO-TP frames due at `now` (STmin and the tester's block size paced by the transport).
    pub fn poll_transmit(&mut self, now: Duration) -> Option<CanFrame> {
        if let Some(f) = self.xcp_out.pop_front() {
            return Some(f);
        }
        let f = self.tp.poll_transmit(now)?;
        CanFrame::standard(ids::TCU_DIAG_RESP, f.bytes()).ok()
    }

    /// The frame the last [`DiagStack::poll_transmit`] gave left at `at`: ISO-TP's STmin counts
    /// from there ([`IsoTp::sent`]).
    pub fn sent(&mut self, at: Duration) {
        self.tp.sent(at);
    }

    /// When the core must run by itself next (ISO-TP pacing and timeouts, the UDS session's S3
    /// timer, the SecurityAccess delay).
    pub fn poll_timeout(&self) -> Option<Duration> {
        match (self.tp.poll_timeout(), self.uds.poll_timeout()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Runs the timers due at `now` (leaving the extended session on S3 stops a running
    /// routine of the TCU's).
    pub fn handle_timeout(&mut self, now: Duration, tcu: &mut Tcu) {
        self.tp.handle_timeout(now);
        let mut ecu = TcuEcu::new(tcu, self.snapshot, &self.serial, &mut self.rng);
        self.uds.handle_timeout(now, &mut ecu);
    }

    /// An ECUReset whose response has gone out: the shell restarts the TCU core and starts a new
    /// operation cycle of the fault memory ([`DiagStack::restarted`]).
    pub fn take_reset(&mut self) -> Option<ResetKind> {
        if self.tp.sending() {
            return None;
        }
        self.reset.take()
    }

    /// The TCU core was restarted (an ECUReset): a new operation cycle.
    pub fn restarted(&mut self) {
        self.memory.start_operation_cycle();
        self.snapshot = None;
        self.tests_enabled = false;
        self.xcp_out.clear();
    }

    /// The fault memory (the shell saves it when it changed).
    pub fn memory(&self) -> &FaultMemory {
        &self.memory
    }

    /// The fault memory after the shell saved it.
    pub fn memory_saved(&mut self) {
        self.memory.mark_saved();
    }

    /// The transport's counters (dropped frames, timeouts).
    pub fn isotp_counters(&self) -> &super::isotp::Counters {
        self.tp.counters()
    }
}

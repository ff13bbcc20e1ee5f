//! The UDS server of the TCU (ISO 14229-1) as a pure core: the shell hands it each request
//! reassembled by ISO-TP ([`super::isotp`]) with the time as an argument and sends back what it
//! returns; nothing here reads a clock or touches a socket.
//!
//! - Request handling follows the general server response behaviour of ISO 14229-1 clause 7.5
//!   (figure 5): SID supported (0x11), SID supported in the active session (0x7F), minimum
//!   length (0x13), sub-function supported (0x12) and supported in the active session (0x7E),
//!   then the service's own checks. A functional request gets no 0x11, 0x12, 0x31, 0x7E or
//!   0x7F (7.5); the suppress-positive-response bit (8.2.2) silences positive responses only.
//! - Sessions (10.2): default and extended; the S3 timer (5 s, ISO 14229-2 clause 9.2) returns
//!   to the default session. Leaving the extended session locks security and stops a running
//!   kiss-point routine.
//! - SecurityAccess (10.4) in [`security`], data identifiers (11.2, 11.7) in [`did`] and
//!   `data`, RoutineControl (14.2) in `routine`, ReadDTCInformation and
//!   ClearDiagnosticInformation (12.2, 12.3) in `dtc_services` over [`crate::diag::dtc`].
//!
//! The contract (ids, services, NRCs, DIDs, the routine) is docs/diagnostics.md.

mod data;
pub mod did;
mod dtc_services;
pub mod ecu;
pub mod nrc;
mod request;
mod routine;
pub mod security;
#[cfg(test)]
mod tests;

use std::time::Duration;

pub use did::{Did, Identification};
pub use ecu::{RoutineRefusal, RoutineState, UdsEcu};
pub use nrc::{Nrc, Sid};
pub use security::Security;

use crate::diag::dtc::memory::FaultMemory;
use data::{read_data, write_data};
use request::Request;

/// S3: a non-default session without requests falls back to the default session after this.
pub(crate) const S3: Duration = Duration::from_secs(5);
/// P2 announced in the DiagnosticSessionControl response (ms).
pub(crate) const P2_MS: u16 = 50;
/// P2* announced in the DiagnosticSessionControl response (ms; sent in units of 10 ms).
pub(crate) const P2_STAR_MS: u16 = 5000;

/// The suppress-positive-response bit of a sub-function byte.
const SUPPRESS: u8 = 0x80;

/// A diagnostic session (ISO 14229-1 10.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Session {
    /// 0x01.
    Default,
    /// 0x03.
    Extended,
}

impl Session {
    /// The session of a sub-function (`None`: not supported, 0x02 programming included).
    pub fn from_sub_function(sub: u8) -> Option<Session> {
        match sub {
            0x01 => Some(Session::Default),
            0x03 => Some(Session::Extended),
            _ => None,
        }
    }

    /// Its sub-function byte.
    pub fn code(self) -> u8 {
        match self {
            Session::Default => 0x01,
            Session::Extended => 0x03,
        }
    }
}

/// The reset an ECUReset asked for (ISO 14229-1 10.3); the shell restarts the core after
/// sending the response.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ResetKind {
    /// 0x01 hardReset (extended session only).
    Hard,
    /// 0x03 softReset.
    Soft,
}

/// The UDS server: session, security, the routine's sequence and a pending reset.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UdsServer {
    session: Session,
    /// When the non-default session expires.
    s3_deadline: Option<Duration>,
    security: Security,
    /// Whether the kiss-point routine was started through this server.
    routine_started: bool,
    reset: Option<ResetKind>,
}

impl Default for UdsServer {
    fn default() -> Self {
        UdsServer::new()
    }
}

impl UdsServer {
    /// A server in the default session, security locked.
    pub fn new() -> UdsServer {
        UdsServer {
            session: Session::Default,
            s3_deadline: None,
            security: Security::default(),
            routine_started: false,
            reset: None,
        }
    }

    /// The active session.
    pub fn session(&self) -> Session {
        self.session
    }

    /// Whether security level 1 is unlocked.
    pub fn is_unlocked(&self) -> bool {
        self.security.is_unlocked()
    }

    /// Handles one request (`functional`: it came on the functional id 0x7DF). `None`: no
    /// response (a suppressed positive response, a functional request's suppressed NRC, an
    /// empty request).
    pub fn handle(
        &mut self,
        now: Duration,
        request: &[u8],
        functional: bool,
        ecu: &mut impl UdsEcu,
        memory: &mut FaultMemory,
    ) -> Option<Vec<u8>> {
        let &sid = request.first()?;
        if self.session != Session::Default {
            self.s3_deadline = Some(now + S3);
        }
        let suppress = Sid::from_request(sid).is_some_and(|s| s.has_sub_function())
            && request.get(1).is_some_and(|b| b & SUPPRESS != 0);
        match self.dispatch(now, request, ecu, memory) {
            Ok(_) if suppress => None,
            Ok(response) => Some(response),
            Err(nrc) if functional && nrc.suppressed_on_functional() => None,
            Err(nrc) => Some(nrc.response(sid)),
        }
    }

    fn dispatch(
        &mut self,
        now: Duration,
        bytes: &[u8],
        ecu: &mut impl UdsEcu,
        memory: &mut FaultMemory,
    ) -> Result<Vec<u8>, Nrc> {
        let sid = bytes
            .first()
            .and_then(|b| Sid::from_request(*b))
            .ok_or(Nrc::ServiceNotSupported)?;
        if sid.needs_extended_session() && self.session == Session::Default {
            return Err(Nrc::ServiceNotSupportedInActiveSession);
        }
        let sub = if sid.has_sub_function() {
            bytes.get(1).ok_or(Nrc::IncorrectMessageLength)? & !SUPPRESS
        } else {
            0
        };
        let req = Request { sid, bytes, sub };
        match sid {
            Sid::DiagnosticSessionControl => self.session_control(now, &req, ecu),
            Sid::EcuReset => self.ecu_reset(&req),
            Sid::TesterPresent => tester_present(&req),
            Sid::SecurityAccess => self.security_access(now, &req, ecu),
            Sid::ReadDataByIdentifier => read_data(&req, ecu),
            Sid::WriteDataByIdentifier => write_data(&req, self.security.is_unlocked(), ecu),
            Sid::RoutineControl => self.routine_control(&req, ecu),
            Sid::ReadDtcInformation => dtc_services::read_dtc_information(&req, memory),
            Sid::ClearDiagnosticInformation => dtc_services::clear(&req, memory),
        }
    }

    /// 0x10: `50 SS P2hi P2lo P2*hi P2*lo` (P2* in 10 ms).
    fn session_control(
        &mut self,
        now: Duration,
        req: &Request,
        ecu: &mut impl UdsEcu,
    ) -> Result<Vec<u8>, Nrc> {
        let new = Session::from_sub_function(req.sub).ok_or(Nrc::SubFunctionNotSupported)?;
        if req.bytes.len() != 2 {
            return Err(Nrc::IncorrectMessageLength);
        }
        self.enter(new, ecu);
        if new != Session::Default {
            self.s3_deadline = Some(now + S3);
        }
        let [p2_hi, p2_lo] = P2_MS.to_be_bytes();
        let [p2s_hi, p2s_lo] = (P2_STAR_MS / 10).to_be_bytes();
        Ok(vec![
            req.sid.response(),
            new.code(),
            p2_hi,
            p2_lo,
            p2s_hi,
            p2s_lo,
        ])
    }

    /// Enters a session: security locks; leaving the extended session stops the routine.
    fn enter(&mut self, new: Session, ecu: &mut impl UdsEcu) {
        self.security.lock();
        if new == Session::Default {
            self.s3_deadline = None;
            if ecu.kiss_routine() == RoutineState::Running {
                ecu.stop_kiss_routine();
            }
        }
        self.session = new;
    }

    /// 0x11: `51 RR`; the reset is taken by [`UdsServer::take_reset`].
    fn ecu_reset(&mut self, req: &Request) -> Result<Vec<u8>, Nrc> {
        let kind = match req.sub {
            0x01 => ResetKind::Hard,
            0x03 => ResetKind::Soft,
            _ => return Err(Nrc::SubFunctionNotSupported),
        };
        if kind == ResetKind::Hard && self.session == Session::Default {
            return Err(Nrc::SubFunctionNotSupportedInActiveSession);
        }
        if req.bytes.len() != 2 {
            return Err(Nrc::IncorrectMessageLength);
        }
        self.reset = Some(kind);
        Ok(vec![req.sid.response(), req.sub])
    }

    /// 0x27: `67 01 seed` or `67 02`.
    fn security_access(
        &mut self,
        now: Duration,
        req: &Request,
        ecu: &mut impl UdsEcu,
    ) -> Result<Vec<u8>, Nrc> {
        match (req.sub, req.bytes.len()) {
            (0x01, 2) => {
                let seed = self.security.request_seed(now, || ecu.seed())?;
                let mut r = vec![req.sid.response(), req.sub];
                r.extend_from_slice(&seed);
                Ok(r)
            }
            (0x02, 6) => {
                let key = req
                    .bytes
                    .get(2..6)
                    .and_then(|k| <[u8; 4]>::try_from(k).ok())
                    .ok_or(Nrc::IncorrectMessageLength)?;
                self.security.send_key(now, u32::from_be_bytes(key))?;
                Ok(vec![req.sid.response(), req.sub])
            }
            (0x01 | 0x02, _) => Err(Nrc::IncorrectMessageLength),
            _ => Err(Nrc::SubFunctionNotSupported),
        }
    }

    /// The reset an ECUReset asked for, once (the shell restarts the core after sending the
    /// response).
    pub fn take_reset(&mut self) -> Option<ResetKind> {
        self.reset.take()
    }

    /// When [`UdsServer::handle_timeout`] has something to do: the S3 timeout of a
    /// non-default session or the end of the security delay.
    pub fn poll_timeout(&self) -> Option<Duration> {
        match (self.s3_deadline, self.security.deadline()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Expires the S3 timer (back to the default session: security locked, a running
    /// kiss-point routine stopped) and the security delay.
    pub fn handle_timeout(&mut self, now: Duration, ecu: &mut impl UdsEcu) {
        if self.s3_deadline.is_some_and(|t| now >= t) {
            self.enter(Session::Default, ecu);
        }
        self.security.handle_timeout(now);
    }
}

/// 0x3E: `7E 00`.
fn tester_present(req: &Request) -> Result<Vec<u8>, Nrc> {
    if req.sub != 0x00 {
        return Err(Nrc::SubFunctionNotSupported);
    }
    if req.bytes.len() != 2 {
        return Err(Nrc::IncorrectMessageLength);
    }
    Ok(vec![req.sid.response(), 0x00])
}

//! A UDS tester on the bus (ISO 14229-1 client side over ISO 15765-2): the shell of
//! [`crate::diag::isotp::IsoTp`] on a [`Bus`], for `ddct diag` and for tests that talk to the
//! TCU daemon without a python tester. Requests go to TCU_DiagReq, responses come on
//! TCU_DiagResp (the bus should be filtered to it); a "response pending" (NRC 0x78) extends the
//! wait from P2 to P2* (ISO 14229-2).

use crate::can::messages::ids;
use crate::can::{Bus, BusError, CanFrame};
use crate::diag::isotp::{IsoTp, IsoTpConfig, SendError};
use std::time::Duration;
use tokio::time::Instant;

/// How long a tester waits for a response (P2_client) and after a "response pending" (P2*).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TesterTiming {
    pub p2: Duration,
    pub p2_star: Duration,
}

impl Default for TesterTiming {
    /// Generous values for a bench under load: 1 s and 5 s.
    fn default() -> Self {
        TesterTiming {
            p2: Duration::from_secs(1),
            p2_star: Duration::from_secs(5),
        }
    }
}

/// Why a request got no response.
#[derive(Debug, thiserror::Error)]
pub enum TesterError {
    #[error("no response to {sid:#04x} within {waited:?}")]
    Timeout { sid: u8, waited: Duration },
    #[error("the request could not be sent")]
    Send(#[from] SendError),
    #[error("bus error")]
    Bus(#[from] BusError),
}

/// A tester on one bus.
pub struct UdsTester<B: Bus> {
    bus: B,
    tp: IsoTp,
    timing: TesterTiming,
    start: Instant,
}

impl<B: Bus> UdsTester<B> {
    pub fn new(bus: B, isotp: IsoTpConfig, timing: TesterTiming) -> Self {
        UdsTester {
            bus,
            tp: IsoTp::new(isotp),
            timing,
            start: Instant::now(),
        }
    }

    fn now(&self) -> Duration {
        self.start.elapsed()
    }

    /// Sends `request` and returns the response (positive, or a negative `7F SID NRC` other than
    /// "response pending").
    pub async fn request(&mut self, request: &[u8]) -> Result<Vec<u8>, TesterError> {
        let sid = request.first().copied().unwrap_or(0);
        self.tp.send(self.now(), request)?;
        let mut wait = self.timing.p2;
        let mut deadline = Instant::now() + wait;
        loop {
            self.transmit().await?;
            let tp_at = self
                .tp
                .poll_timeout()
                .map(|d| self.start + d)
                .unwrap_or(deadline);
            tokio::select! {
                rx = self.bus.recv() => {
                    let rx = rx?;
                    if rx.frame.standard_id() != Some(ids::TCU_DIAG_RESP) {
                        continue;
                    }
                    let Some(msg) = self.tp.handle_frame(self.now(), rx.frame.bytes()) else {
                        continue;
                    };
                    if msg.len() >= 3 && msg[0] == 0x7F && msg[1] == sid && msg[2] == 0x78 {
                        wait = self.timing.p2_star;
                        deadline = Instant::now() + wait;
                        continue;
                    }
                    return Ok(msg);
                }
                _ = tokio::time::sleep_until(tp_at.min(deadline)) => {
                    self.tp.handle_timeout(self.now());
                    if Instant::now() >= deadline {
                        return Err(TesterError::Timeout { sid, waited: wait });
                    }
                }
            }
        }
    }

    /// Sends the frames the transport has due (the first frame, consecutive frames as the
    /// server's flow control allows, flow controls of a long response).
    async fn transmit(&mut self) -> Result<(), TesterError> {
        while let Some(f) = self.tp.poll_transmit(self.now()) {
            if let Ok(frame) = CanFrame::standard(ids::TCU_DIAG_REQ, f.bytes()) {
                self.bus.send(frame).await?;
            }
            self.tp.sent(self.now());
        }
        Ok(())
    }
}

//! The TCU as the UDS server's and the XCP slave's ECU: the values they read and write are the
//! core's ([`Tcu`]) — its latest step's [`Snapshot`], its calibration
//! ([`Tcu::set_calibration`]: validated, effective at the next cycle) and its kiss-point routine.

use super::uds::{Identification, RoutineRefusal, RoutineState, UdsEcu};
use super::values::{Calibration, Snapshot};
use super::xcp::XcpEcu;
use crate::tcu::routine::{Condition, RoutineRefusal as TcuRefusal, RoutineState as TcuRoutine};
use crate::tcu::Tcu;

/// The software version read by UDS (DID 0xF195).
pub(crate) const SOFTWARE_VERSION: &str = concat!("ddct ", env!("CARGO_PKG_VERSION"));

/// The system name read by UDS (DID 0xF197).
pub(crate) const SYSTEM_NAME: &str = "ddct TCU";

/// The TCU seen by the protocols, for the length of one request or step.
pub struct TcuEcu<'a> {
    tcu: &'a mut Tcu,
    snapshot: Option<Snapshot>,
    serial: &'a str,
    rng: &'a mut u64,
}

impl<'a> TcuEcu<'a> {
    pub fn new(
        tcu: &'a mut Tcu,
        snapshot: Option<Snapshot>,
        serial: &'a str,
        rng: &'a mut u64,
    ) -> Self {
        TcuEcu {
            tcu,
            snapshot,
            serial,
            rng,
        }
    }
}

/// splitmix64: the SecurityAccess seeds (not cryptographic; the seed/key of a bench ECU).
fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The TCU's refusal as the server's (all of them NRC 0x22, conditionsNotCorrect; the clutch
/// number is checked by the server before).
fn refusal(r: TcuRefusal) -> RoutineRefusal {
    match r {
        TcuRefusal::Condition(Condition::NotAtStandstill) => RoutineRefusal::NotAtStandstill,
        TcuRefusal::Condition(Condition::LeverNotParkOrNeutral) => {
            RoutineRefusal::LeverNotParkOrNeutral
        }
        TcuRefusal::Condition(Condition::EngineNotRunning) => RoutineRefusal::EngineNotRunning,
        TcuRefusal::Condition(Condition::FaultOrSafeState | Condition::PedalPressed)
        | TcuRefusal::InvalidClutch(_) => RoutineRefusal::FaultActive,
        TcuRefusal::AlreadyRunning => RoutineRefusal::AlreadyRunning,
    }
}

impl XcpEcu for TcuEcu<'_> {
    fn calibration(&self, cal: Calibration) -> f64 {
        cal.get(self.tcu.config())
    }

    fn set_calibration(&mut self, cal: Calibration, value: f64) -> Result<(), String> {
        self.tcu
            .set_calibration(cal, value)
            .map_err(|e| e.to_string())
    }

    fn snapshot(&self) -> Option<Snapshot> {
        self.snapshot
    }
}

impl UdsEcu for TcuEcu<'_> {
    fn snapshot(&self) -> Option<Snapshot> {
        self.snapshot
    }

    fn identification(&self, id: Identification) -> String {
        match id {
            Identification::SerialNumber => self.serial.to_string(),
            Identification::SoftwareVersion => SOFTWARE_VERSION.to_string(),
            Identification::SystemName => SYSTEM_NAME.to_string(),
        }
    }

    fn calibration(&self, cal: Calibration) -> f64 {
        cal.get(self.tcu.config())
    }

    fn set_calibration(&mut self, cal: Calibration, value: f64) -> Result<(), String> {
        self.tcu
            .set_calibration(cal, value)
            .map_err(|e| e.to_string())
    }

    fn learned_kiss_point(&self, clutch: usize) -> Option<f64> {
        self.tcu
            .learned_kiss_points()
            .get(clutch)
            .copied()
            .flatten()
    }

    fn start_kiss_routine(&mut self, clutch: usize) -> Result<(), RoutineRefusal> {
        self.tcu.start_kiss_point_routine(clutch).map_err(refusal)
    }

    fn stop_kiss_routine(&mut self) {
        self.tcu.stop_kiss_point_routine();
    }

    fn kiss_routine(&self) -> RoutineState {
        match self.tcu.kiss_point_routine() {
            TcuRoutine::Idle => RoutineState::Idle,
            TcuRoutine::Running { .. } => RoutineState::Running,
            TcuRoutine::Done { kiss_mm, .. } => RoutineState::Done { kiss_mm },
            TcuRoutine::Aborted { reason, .. } => RoutineState::Aborted {
                reason: reason.code(),
            },
        }
    }

    fn seed(&mut self) -> u32 {
        // Never 0: a zero seed means "already unlocked" (ISO 14229-1 10.4).
        loop {
            let s = (splitmix64(self.rng) >> 32) as u32;
            if s != 0 {
                return s;
            }
        }
    }
}

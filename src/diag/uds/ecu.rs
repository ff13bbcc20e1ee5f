//! What the UDS server (ISO 14229-1) asks of the TCU: the values behind the data identifiers
//! (clause 11), the kiss-point routine (clause 14.2, RoutineControl 0x0201) and the seeds of
//! SecurityAccess (clause 10.4). The server owns sessions, security and the encoding; the ECU
//! owns the values. The TCU integration implements [`UdsEcu`]; the tests have a fake.

use super::did::Identification;
use crate::diag::values::{Calibration, Snapshot};

/// Why the ECU refuses to start the kiss-point routine (NRC 0x22 conditionsNotCorrect).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RoutineRefusal {
    /// The vehicle is moving.
    NotAtStandstill,
    /// The lever is neither in P nor in N.
    LeverNotParkOrNeutral,
    /// The engine is not running.
    EngineNotRunning,
    /// A fault is active.
    FaultActive,
    /// The routine already runs.
    AlreadyRunning,
}

/// The state of the kiss-point routine, as `31 03 02 01` reports it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RoutineState {
    /// Never started (status byte 0).
    Idle,
    /// Running (1).
    Running,
    /// Done: the learned kiss point (mm) (2).
    Done { kiss_mm: f64 },
    /// Aborted, with the ECU's reason byte (3).
    Aborted { reason: u8 },
}

/// The TCU as the UDS server sees it.
pub trait UdsEcu {
    /// The latest step (`None` before the first).
    fn snapshot(&self) -> Option<Snapshot>;
    /// Serial number, software version, system name.
    fn identification(&self, id: Identification) -> String;
    /// The current value of a calibration.
    fn calibration(&self, cal: Calibration) -> f64;
    /// A checked calibration write, effective at the next cycle (`Err`: NRC 0x31).
    fn set_calibration(&mut self, cal: Calibration, value: f64) -> Result<(), String>;
    /// The learned kiss point of clutch 0 or 1 (mm), `None` if never learned.
    fn learned_kiss_point(&self, clutch: usize) -> Option<f64>;
    /// Starts the kiss-point adaptation of clutch 0 or 1.
    fn start_kiss_routine(&mut self, clutch: usize) -> Result<(), RoutineRefusal>;
    /// Stops the routine (the clutch reopens); nothing if it does not run.
    fn stop_kiss_routine(&mut self);
    /// The routine's state.
    fn kiss_routine(&self) -> RoutineState;
    /// A new SecurityAccess seed (the shell draws it at random; never 0 for a locked level).
    fn seed(&mut self) -> u32;
}

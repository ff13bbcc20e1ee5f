//! RoutineControl (ISO 14229-1 clause 14.2) of routine 0x0201, the kiss-point adaptation:
//! `31 01 02 01 CC` start for clutch CC (1 or 2; refused with 0x22 when the ECU's conditions
//! do not hold), `31 02 02 01` stop, `31 03 02 01` results (`71 03 02 01 ST kiss[4]`, ST 0 idle,
//! 1 running, 2 done, 3 aborted + the reason byte). Stop and results of a routine never started
//! answer 0x24.

use super::did::f32_be;
use super::ecu::{RoutineState, UdsEcu};
use super::{Nrc, Request, UdsServer};

/// The kiss-point adaptation routine.
pub(crate) const KISS_POINT_ROUTINE: u16 = 0x0201;

impl UdsServer {
    /// 0x31.
    pub(super) fn routine_control(
        &mut self,
        req: &Request,
        ecu: &mut impl UdsEcu,
    ) -> Result<Vec<u8>, Nrc> {
        if !matches!(req.sub, 0x01..=0x03) {
            return Err(Nrc::SubFunctionNotSupported);
        }
        let (Some(&hi), Some(&lo)) = (req.bytes.get(2), req.bytes.get(3)) else {
            return Err(Nrc::IncorrectMessageLength);
        };
        if u16::from_be_bytes([hi, lo]) != KISS_POINT_ROUTINE {
            return Err(Nrc::RequestOutOfRange);
        }
        let expected_len = if req.sub == 0x01 { 5 } else { 4 };
        if req.bytes.len() != expected_len {
            return Err(Nrc::IncorrectMessageLength);
        }
        let mut response = vec![req.sid.response(), req.sub, hi, lo];
        if req.sub == 0x01 {
            let clutch = match req.bytes.get(4) {
                Some(1) => 0,
                Some(2) => 1,
                _ => return Err(Nrc::RequestOutOfRange),
            };
            ecu.start_kiss_routine(clutch)
                .map_err(|_| Nrc::ConditionsNotCorrect)?;
            self.routine_started = true;
            return Ok(response);
        }
        if !self.routine_started && ecu.kiss_routine() == RoutineState::Idle {
            return Err(Nrc::RequestSequenceError);
        }
        if req.sub == 0x02 {
            ecu.stop_kiss_routine();
            return Ok(response);
        }
        let (status, kiss_mm, reason) = match ecu.kiss_routine() {
            RoutineState::Idle => (0, f64::NAN, None),
            RoutineState::Running => (1, f64::NAN, None),
            RoutineState::Done { kiss_mm } => (2, kiss_mm, None),
            RoutineState::Aborted { reason } => (3, f64::NAN, Some(reason)),
        };
        response.push(status);
        response.extend(f32_be(kiss_mm));
        response.extend(reason);
        Ok(response)
    }
}

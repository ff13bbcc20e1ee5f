//! The UDS server against a fake ECU. Every expected response is written by hand from
//! ISO 14229-1 and docs/diagnostics.md (f32 bytes from the IEEE-754 encoding, keys from the
//! doc's formula worked out by hand), never computed by the code under test.

use std::time::Duration;

use super::*;
use crate::can::messages::FaultCode;
use crate::diag::values::{Calibration, Snapshot};

struct FakeEcu {
    snapshot: Option<Snapshot>,
    cals: [f64; 8],
    kiss: [Option<f64>; 2],
    routine: RoutineState,
    refuse: Option<RoutineRefusal>,
    started: Vec<usize>,
    stops: usize,
    seeds: Vec<u32>,
}

impl FakeEcu {
    fn new() -> FakeEcu {
        FakeEcu {
            snapshot: None,
            cals: [20.0, 400.0, 5.0, 50.0, 1.0, 150.0, 1.0, 0.0],
            kiss: [Some(4.375), None],
            routine: RoutineState::Idle,
            refuse: None,
            started: Vec::new(),
            stops: 0,
            seeds: vec![
                0x1234_5678,
                0xA1B2_C3D4,
                0x0000_0001,
                0x0000_0002,
                0x0000_0003,
            ],
        }
    }
}

fn index(cal: Calibration) -> usize {
    Calibration::ALL.iter().position(|c| *c == cal).unwrap_or(0)
}

impl UdsEcu for FakeEcu {
    fn snapshot(&self) -> Option<Snapshot> {
        self.snapshot
    }
    fn identification(&self, id: Identification) -> String {
        match id {
            Identification::SerialNumber => "SN-0042".into(),
            Identification::SoftwareVersion => "ddct 0.1.0".into(),
            Identification::SystemName => "ddct TCU".into(),
        }
    }
    fn calibration(&self, cal: Calibration) -> f64 {
        self.cals[index(cal)]
    }
    fn set_calibration(&mut self, cal: Calibration, value: f64) -> Result<(), String> {
        // The TCU's own validation refuses a warning above its limit (say 200 °C here).
        if cal == Calibration::OverTempWarn && value > 200.0 {
            return Err("over_temp_warn_c above over_temp_limit_c".into());
        }
        self.cals[index(cal)] = value;
        Ok(())
    }
    fn learned_kiss_point(&self, clutch: usize) -> Option<f64> {
        self.kiss.get(clutch).copied().flatten()
    }
    fn start_kiss_routine(&mut self, clutch: usize) -> Result<(), RoutineRefusal> {
        if let Some(r) = self.refuse {
            return Err(r);
        }
        self.started.push(clutch);
        self.routine = RoutineState::Running;
        Ok(())
    }
    fn stop_kiss_routine(&mut self) {
        self.stops += 1;
        self.routine = RoutineState::Aborted { reason: 1 };
    }
    fn kiss_routine(&self) -> RoutineState {
        self.routine
    }
    fn seed(&mut self) -> u32 {
        if self.seeds.is_empty() {
            7
        } else {
            self.seeds.remove(0)
        }
    }
}

fn snap(t_s: f64) -> Snapshot {
    crate::diag::values::test_snapshot(t_s)
}

struct Rig {
    server: UdsServer,
    ecu: FakeEcu,
    memory: FaultMemory,
    now: Duration,
}

impl Rig {
    fn new() -> Rig {
        Rig {
            server: UdsServer::new(),
            ecu: FakeEcu::new(),
            memory: FaultMemory::new(),
            now: Duration::ZERO,
        }
    }
    fn at_ms(&mut self, ms: u64) -> &mut Rig {
        self.now = Duration::from_millis(ms);
        self
    }
    fn req(&mut self, request: &[u8]) -> Option<Vec<u8>> {
        let (now, s, e, m) = (self.now, &mut self.server, &mut self.ecu, &mut self.memory);
        s.handle(now, request, false, e, m)
    }
    fn func(&mut self, request: &[u8]) -> Option<Vec<u8>> {
        let (now, s, e, m) = (self.now, &mut self.server, &mut self.ecu, &mut self.memory);
        s.handle(now, request, true, e, m)
    }
    fn extended(&mut self) {
        assert_eq!(
            self.req(&[0x10, 0x03]),
            Some(vec![0x50, 0x03, 0x00, 0x32, 0x01, 0xF4])
        );
    }
    /// Extended session and level 1 unlocked with the first seed 0x12345678:
    /// 0x12345678 ^ 0x44445443 = 0x5670023B, rotated left by 7 = 0x38011DAB.
    fn unlock(&mut self) {
        self.extended();
        assert_eq!(
            self.req(&[0x27, 0x01]),
            Some(vec![0x67, 0x01, 0x12, 0x34, 0x56, 0x78])
        );
        assert_eq!(
            self.req(&[0x27, 0x02, 0x38, 0x01, 0x1D, 0xAB]),
            Some(vec![0x67, 0x02])
        );
    }
}

fn nrc(sid: u8, code: u8) -> Option<Vec<u8>> {
    Some(vec![0x7F, sid, code])
}

mod nrcs;
mod positive;
mod sessions;

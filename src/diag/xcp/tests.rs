//! Tests of the XCP slave against hand-written packets: the requests as pyxcp 0.29 builds
//! them (`Master.*` in pyxcp/master/master.py, `DaqProcessor.setup` in
//! pyxcp/daq_stim/__init__.py) and the responses as the ASAM XCP 1.x layouts and pyxcp's parsers
//! (pyxcp/types.py) read them.

use std::time::Duration;

use proptest::prelude::*;

use super::fake_ecu::{idx, FakeEcu};
use super::*;
use crate::can::messages::{FaultCode, TcuState};
use crate::diag::values::{Calibration, Measurement, Snapshot, CALIBRATION_BASE, MEASUREMENT_BASE};
use crate::model::gear::Gear;

pub fn snapshot() -> Snapshot {
    Snapshot {
        t_s: 1.0,
        state: TcuState::Neutral,
        fault: FaultCode::None,
        gear_active: Gear::G1,
        theta_est_c: [85.25, 90.5],
        t_ref_nm: [12.0, -3.5],
        x_ref_mm: [5.0, 6.0],
        x_mm: [5.5, 6.5],
        kiss_mm: [7.0, 7.25],
        engine_rpm: 1500.0,
        shaft_rpm: [1200.0, 800.0],
        out_rpm: 300.0,
        pedal_pct: 42.0,
        housing_c: 40.0,
    }
}

const T: Duration = Duration::from_millis(5);

fn f32le(v: f32) -> [u8; 4] {
    v.to_le_bytes()
}

/// A connected slave.
fn connected(ecu: &mut FakeEcu) -> XcpSlave {
    let mut s = XcpSlave::new();
    assert!(s.handle_cro(T, &[0xFF, 0x00], ecu).is_some());
    s
}

#[test]
fn connect_response_is_the_documented_one() {
    let mut ecu = FakeEcu::new();
    let mut s = XcpSlave::new();
    // pyxcp: request(CONNECT, mode) → FF 00. ConnectResponse: resource (CAL/PAG | DAQ),
    // commModeBasic (OPTIONAL, BYTE, INTEL), maxCto 8, maxDto 8 (Int16 Intel), protocol 1,
    // transport 1.
    let r = s.handle_cro(T, &[0xFF, 0x00], &mut ecu);
    assert_eq!(
        r,
        Some(vec![0xFF, 0x05, 0x80, 0x08, 0x08, 0x00, 0x01, 0x01])
    );
    assert!(s.connected());
}

#[test]
fn before_connect_only_connect_is_answered() {
    let mut ecu = FakeEcu::new();
    let mut s = XcpSlave::new();
    assert_eq!(s.handle_cro(T, &[0xFD], &mut ecu), None);
    assert_eq!(s.handle_cro(T, &[0xFC], &mut ecu), None);
    assert_eq!(s.handle_cro(T, &[0x12, 0x34], &mut ecu), None);
    assert_eq!(s.handle_cro(T, &[0xFF], &mut ecu), None); // CONNECT without mode: no session
    assert!(s
        .handle_cro(T, &[0xFF, 0x00, 0xCC, 0xCC], &mut ecu)
        .is_some());
    // DISCONNECT ends the session.
    assert_eq!(s.handle_cro(T, &[0xFE], &mut ecu), Some(vec![0xFF]));
    assert_eq!(s.handle_cro(T, &[0xFD], &mut ecu), None);
}

#[test]
fn status_comm_mode_synch_and_id() {
    let mut ecu = FakeEcu::new();
    let mut s = connected(&mut ecu);
    // GET_STATUS: session status, protection, state number, session configuration id (2).
    assert_eq!(
        s.handle_cro(T, &[0xFD], &mut ecu),
        Some(vec![0xFF, 0, 0, 0, 0, 0])
    );
    // GET_COMM_MODE_INFO: reserved, optional modes, reserved, MAX_BS, MIN_ST, QUEUE, version.
    assert_eq!(
        s.handle_cro(T, &[0xFB], &mut ecu),
        Some(vec![0xFF, 0, 0, 0, 0, 0, 0, 0x10])
    );
    assert_eq!(s.handle_cro(T, &[0xFC], &mut ecu), Some(vec![0xFE, 0x00]));
    // GET_ID type 1 (A2L name), mode 0: upload the length from the MTA (pyxcp `identifier`).
    assert_eq!(
        s.handle_cro(T, &[0xFA, 0x01], &mut ecu),
        Some(vec![0xFF, 0, 0, 0, 4, 0, 0, 0])
    );
    assert_eq!(
        s.handle_cro(T, &[0xF5, 0x04], &mut ecu),
        Some(b"\xFFddct".to_vec())
    );
    // An unknown type: length 0.
    assert_eq!(
        s.handle_cro(T, &[0xFA, 0x07], &mut ecu),
        Some(vec![0xFF, 0, 0, 0, 0, 0, 0, 0])
    );
}

#[test]
fn set_mta_upload_and_short_upload_read_measurements() {
    let mut ecu = FakeEcu::new();
    ecu.snap = Some(snapshot());
    let mut s = connected(&mut ecu);
    // SET_MTA to Clutch2TempEst (0x00010004): F6 00 00 ext addr (Intel).
    assert_eq!(
        s.handle_cro(T, &[0xF6, 0, 0, 0, 0x04, 0x00, 0x01, 0x00], &mut ecu),
        Some(vec![0xFF])
    );
    let mut want = vec![0xFF];
    want.extend_from_slice(&f32le(90.5));
    assert_eq!(s.handle_cro(T, &[0xF5, 0x04], &mut ecu), Some(want));
    // The MTA advanced: next is Clutch1TorqueRef.
    let mut want = vec![0xFF];
    want.extend_from_slice(&f32le(12.0)[..2]);
    assert_eq!(s.handle_cro(T, &[0xF5, 0x02], &mut ecu), Some(want));
    // SHORT_UPLOAD of EngineSpeed (0x00010028), bytes 1..4 then the whole.
    let a = Measurement::EngineSpeed.address().to_le_bytes();
    let mut want = vec![0xFF];
    want.extend_from_slice(&f32le(1500.0));
    assert_eq!(
        s.handle_cro(T, &[0xF4, 4, 0, 0, a[0], a[1], a[2], a[3]], &mut ecu),
        Some(want)
    );
    let mut want = vec![0xFF];
    want.extend_from_slice(&f32le(1500.0)[1..]);
    assert_eq!(
        s.handle_cro(T, &[0xF4, 3, 0, 0, a[0] + 1, a[1], a[2], a[3]], &mut ecu),
        Some(want)
    );
    // Unmapped, too long, zero, other extension.
    assert_eq!(
        s.handle_cro(T, &[0xF4, 4, 0, 0, 0, 0, 0, 0], &mut ecu),
        Some(vec![0xFE, 0x24])
    );
    assert_eq!(
        s.handle_cro(T, &[0xF5, 8], &mut ecu),
        Some(vec![0xFE, 0x22])
    );
    assert_eq!(
        s.handle_cro(T, &[0xF5, 0], &mut ecu),
        Some(vec![0xFE, 0x22])
    );
    assert_eq!(
        s.handle_cro(T, &[0xF6, 0, 0, 1, 0, 0, 1, 0], &mut ecu),
        Some(vec![0xFE, 0x22])
    );
}

#[test]
fn download_writes_calibrations_through_the_ecu() {
    let mut ecu = FakeEcu::new();
    let mut s = connected(&mut ecu);
    // LaunchLockupTime (0x00020010) := 1.5 (limits 0.2 ..= 10).
    let a = Calibration::LaunchLockupTime.address();
    assert_eq!(a, CALIBRATION_BASE + 0x10);
    let set_mta = [0xF6, 0, 0, 0, 0x10, 0x00, 0x02, 0x00];
    assert_eq!(s.handle_cro(T, &set_mta, &mut ecu), Some(vec![0xFF]));
    let v = f32le(1.5);
    let dl = [0xF0, 4, v[0], v[1], v[2], v[3], 0, 0];
    assert_eq!(s.handle_cro(T, &dl, &mut ecu), Some(vec![0xFF]));
    assert_eq!(ecu.calibration(Calibration::LaunchLockupTime), 1.5);
    // Read back.
    assert_eq!(s.handle_cro(T, &set_mta, &mut ecu), Some(vec![0xFF]));
    assert_eq!(
        s.handle_cro(T, &[0xF5, 4], &mut ecu),
        Some(vec![0xFF, v[0], v[1], v[2], v[3]])
    );
    // 50 s: out of range, memory unchanged.
    assert_eq!(s.handle_cro(T, &set_mta, &mut ecu), Some(vec![0xFF]));
    let v = f32le(50.0);
    let dl = [0xF0, 4, v[0], v[1], v[2], v[3]];
    assert_eq!(s.handle_cro(T, &dl, &mut ecu), Some(vec![0xFE, 0x22]));
    assert_eq!(ecu.calibration(Calibration::LaunchLockupTime), 1.5);
    // NaN: out of range.
    let v = f32le(f32::NAN);
    let dl = [0xF0, 4, v[0], v[1], v[2], v[3]];
    assert_eq!(s.handle_cro(T, &dl, &mut ecu), Some(vec![0xFE, 0x22]));
    // A measurement: write protected; unmapped: access denied.
    let m = [0xF6, 0, 0, 0, 0x00, 0x00, 0x01, 0x00];
    assert_eq!(s.handle_cro(T, &m, &mut ecu), Some(vec![0xFF]));
    assert_eq!(
        s.handle_cro(T, &[0xF0, 4, 0, 0, 0, 0], &mut ecu),
        Some(vec![0xFE, 0x23])
    );
    assert_eq!(
        s.handle_cro(T, &[0xF6, 0, 0, 0, 0, 0, 0, 0], &mut ecu),
        Some(vec![0xFF])
    );
    assert_eq!(
        s.handle_cro(T, &[0xF0, 4, 0, 0, 0, 0], &mut ecu),
        Some(vec![0xFE, 0x24])
    );
    // n beyond MAX_CTO − 2, and a packet shorter than n.
    assert_eq!(
        s.handle_cro(T, &[0xF0, 7, 0, 0, 0, 0, 0, 0], &mut ecu),
        Some(vec![0xFE, 0x22])
    );
    assert_eq!(
        s.handle_cro(T, &[0xF0, 4, 0, 0], &mut ecu),
        Some(vec![0xFE, 0x21])
    );
}

#[test]
fn daq_info_responses_parse_as_pyxcp_reads_them() {
    let mut ecu = FakeEcu::new();
    let mut s = connected(&mut ecu);
    // GET_DAQ_PROCESSOR_INFO: properties (DYNAMIC | prescaler | timestamp), MAX_DAQ 4,
    // MAX_EVENT_CHANNEL 1, MIN_DAQ 0, key byte 0 (IDF_ABS_ODT_NUMBER).
    assert_eq!(
        s.handle_cro(T, &[0xDA], &mut ecu),
        Some(vec![0xFF, 0x13, 4, 0, 1, 0, 0, 0])
    );
    // GET_DAQ_RESOLUTION_INFO: 1, 7, 1, 0, mode (unit 1 µs << 4 | S4), ticks 1.
    assert_eq!(
        s.handle_cro(T, &[0xD9], &mut ecu),
        Some(vec![0xFF, 1, 7, 1, 0, 0x34, 1, 0])
    );
    // GET_DAQ_EVENT_INFO 0: D7 00 ecn(2) → properties, MAX_DAQ_LIST, name length, cycle, unit,
    // priority; then pyxcp fetches the name with UPLOAD.
    assert_eq!(
        s.handle_cro(T, &[0xD7, 0, 0, 0], &mut ecu),
        Some(vec![0xFF, 0x84, 4, 4, 10, 6, 0])
    );
    assert_eq!(
        s.handle_cro(T, &[0xF5, 4], &mut ecu),
        Some(b"\xFF10ms".to_vec())
    );
    assert_eq!(
        s.handle_cro(T, &[0xD7, 0, 1, 0], &mut ecu),
        Some(vec![0xFE, 0x22])
    );
    // GET_DAQ_CLOCK: reserved ×3, then the µs ticks (5 ms = 5000 = 0x1388).
    assert_eq!(
        s.handle_cro(T, &[0xDC], &mut ecu),
        Some(vec![0xFF, 0, 0, 0, 0x88, 0x13, 0, 0])
    );
}

/// Sends `cro` and expects a plain `FF`.
fn expect_ok(s: &mut XcpSlave, ecu: &mut FakeEcu, cro: &[u8]) {
    assert_eq!(s.handle_cro(T, cro, ecu), Some(vec![0xFF]), "{cro:02X?}");
}

/// DaqProcessor.setup for two lists on event 0, as pyxcp sends it for:
/// list 0 (timestamps): Clutch1TempEst, EngineSpeed — the first ODT keeps only its timestamp
/// (3 bytes left < 4), ODT 1 = Clutch1TempEst, ODT 2 = EngineSpeed (first-fit decreasing);
/// list 1 (no timestamps, prescaler 2): Clutch1KissPoint + ClutchKp in one ODT.
fn setup_two_lists(s: &mut XcpSlave, ecu: &mut FakeEcu) {
    expect_ok(s, ecu, &[0xD6]); // FREE_DAQ
    expect_ok(s, ecu, &[0xD5, 0, 2, 0]); // ALLOC_DAQ 2
    expect_ok(s, ecu, &[0xD4, 0, 0, 0, 3]); // ALLOC_ODT list 0: 3
    expect_ok(s, ecu, &[0xD4, 0, 1, 0, 1]); // ALLOC_ODT list 1: 1
    expect_ok(s, ecu, &[0xD3, 0, 0, 0, 0, 0]); // ALLOC_ODT_ENTRY 0/0: 0
    expect_ok(s, ecu, &[0xD3, 0, 0, 0, 1, 1]); // 0/1: 1
    expect_ok(s, ecu, &[0xD3, 0, 0, 0, 2, 1]); // 0/2: 1
    expect_ok(s, ecu, &[0xD3, 0, 1, 0, 0, 2]); // 1/0: 2
                                               // SET_DAQ_PTR list odt entry, WRITE_DAQ FF size ext addr.
    expect_ok(s, ecu, &[0xE2, 0, 0, 0, 1, 0]);
    expect_ok(s, ecu, &[0xE1, 0xFF, 4, 0, 0x00, 0x00, 0x01, 0x00]); // Clutch1TempEst
    expect_ok(s, ecu, &[0xE2, 0, 0, 0, 2, 0]);
    expect_ok(s, ecu, &[0xE1, 0xFF, 4, 0, 0x28, 0x00, 0x01, 0x00]); // EngineSpeed
    expect_ok(s, ecu, &[0xE2, 0, 1, 0, 0, 0]);
    expect_ok(s, ecu, &[0xE1, 0xFF, 4, 0, 0x20, 0x00, 0x01, 0x00]); // Clutch1KissPoint
    expect_ok(s, ecu, &[0xE1, 0xFF, 3, 0, 0x00, 0x00, 0x02, 0x00]); // ClutchKp, 3 low bytes
                                                                    // SET_DAQ_LIST_MODE mode list event prescaler priority; START_STOP_DAQ_LIST select.
    expect_ok(s, ecu, &[0xE0, 0x10, 0, 0, 0, 0, 1, 0]);
    assert_eq!(s.handle_cro(T, &[0xDE, 2, 0, 0], ecu), Some(vec![0xFF, 0]));
    expect_ok(s, ecu, &[0xE0, 0x00, 1, 0, 0, 0, 2, 0]);
    assert_eq!(s.handle_cro(T, &[0xDE, 2, 1, 0], ecu), Some(vec![0xFF, 3]));
}

#[test]
fn a_pyxcp_daq_setup_then_packets_at_each_event() {
    let mut ecu = FakeEcu::new();
    ecu.cals[idx(Calibration::ClutchKp)] = 20.0;
    let mut s = connected(&mut ecu);
    setup_two_lists(&mut s, &mut ecu);
    let snap = snapshot();
    // Selected, not started: nothing yet.
    assert!(s.on_event(T, 0, &snap, &ecu).is_empty());
    expect_ok(&mut s, &mut ecu, &[0xDD, 1]); // START_STOP_SYNCH start selected
    assert_eq!(
        s.handle_cro(T, &[0xFD], &mut ecu),
        Some(vec![0xFF, 0x40, 0, 0, 0, 0])
    );
    // GET_DAQ_LIST_MODE 0: running | timestamp, event 0, prescaler 1, priority 0.
    assert_eq!(
        s.handle_cro(T, &[0xDF, 0, 0, 0], &mut ecu),
        Some(vec![0xFF, 0x50, 0, 0, 0, 0, 1, 0])
    );
    // t = 0x01020304 µs.
    let now = Duration::from_micros(0x0102_0304);
    let t = [0x04, 0x03, 0x02, 0x01];
    let p = s.on_event(now, 0, &snap, &ecu);
    let v1 = f32le(85.25);
    let v2 = f32le(1500.0);
    assert_eq!(
        p,
        vec![
            vec![0x00, t[0], t[1], t[2], t[3]],
            vec![0x01, v1[0], v1[1], v1[2], v1[3]],
            vec![0x02, v2[0], v2[1], v2[2], v2[3]],
        ]
    );
    // Another event channel: nothing.
    assert!(s.on_event(now, 1, &snap, &ecu).is_empty());
    // Second event: list 1 (prescaler 2) comes too.
    let p = s.on_event(now, 0, &snap, &ecu);
    let k = f32le(7.0);
    let kp = f32le(20.0);
    assert_eq!(p.len(), 4);
    assert_eq!(
        p[3],
        vec![0x03, k[0], k[1], k[2], k[3], kp[0], kp[1], kp[2]]
    );
    // START_STOP_SYNCH stop all: no more packets.
    expect_ok(&mut s, &mut ecu, &[0xDD, 0]);
    assert!(s.on_event(now, 0, &snap, &ecu).is_empty());
    assert_eq!(
        s.handle_cro(T, &[0xFD], &mut ecu),
        Some(vec![0xFF, 0, 0, 0, 0, 0])
    );
}

#[test]
fn daq_errors() {
    let mut ecu = FakeEcu::new();
    let mut s = connected(&mut ecu);
    let e = |code: u8| Some(vec![0xFE, code]);
    // Allocation order and bounds.
    assert_eq!(s.handle_cro(T, &[0xD4, 0, 0, 0, 1], &mut ecu), e(0x29));
    assert_eq!(s.handle_cro(T, &[0xD5, 0, 5, 0], &mut ecu), e(0x30));
    expect_ok(&mut s, &mut ecu, &[0xD5, 0, 1, 0]);
    assert_eq!(s.handle_cro(T, &[0xD5, 0, 1, 0], &mut ecu), e(0x29));
    assert_eq!(s.handle_cro(T, &[0xD4, 0, 1, 0, 1], &mut ecu), e(0x22));
    assert_eq!(s.handle_cro(T, &[0xD4, 0, 0, 0, 33], &mut ecu), e(0x30));
    expect_ok(&mut s, &mut ecu, &[0xD4, 0, 0, 0, 1]);
    assert_eq!(s.handle_cro(T, &[0xD3, 0, 0, 0, 0, 8], &mut ecu), e(0x30));
    assert_eq!(s.handle_cro(T, &[0xD3, 0, 0, 0, 1, 1], &mut ecu), e(0x22));
    expect_ok(&mut s, &mut ecu, &[0xD3, 0, 0, 0, 0, 2]);
    assert_eq!(s.handle_cro(T, &[0xD4, 0, 0, 0, 1], &mut ecu), e(0x29));
    // DAQ pointer out of range; WRITE_DAQ without a pointer, past the ODT, bad sizes.
    assert_eq!(
        s.handle_cro(T, &[0xE1, 0xFF, 4, 0, 0, 0, 1, 0], &mut ecu),
        e(0x29)
    );
    assert_eq!(s.handle_cro(T, &[0xE2, 0, 0, 0, 0, 2], &mut ecu), e(0x22));
    assert_eq!(s.handle_cro(T, &[0xE2, 0, 0, 0, 1, 0], &mut ecu), e(0x22));
    assert_eq!(s.handle_cro(T, &[0xE2, 0, 1, 0, 0, 0], &mut ecu), e(0x22));
    expect_ok(&mut s, &mut ecu, &[0xE2, 0, 0, 0, 0, 1]);
    assert_eq!(
        s.handle_cro(T, &[0xE1, 0xFF, 8, 0, 0, 0, 1, 0], &mut ecu),
        e(0x22)
    );
    assert_eq!(
        s.handle_cro(T, &[0xE1, 0x03, 4, 0, 0, 0, 1, 0], &mut ecu),
        e(0x22)
    );
    assert_eq!(
        s.handle_cro(T, &[0xE1, 0xFF, 4, 0, 0, 0, 0, 0], &mut ecu),
        e(0x24)
    );
    expect_ok(&mut s, &mut ecu, &[0xE1, 0xFF, 4, 0, 0, 0, 1, 0]);
    assert_eq!(
        s.handle_cro(T, &[0xE1, 0xFF, 4, 0, 0, 0, 1, 0], &mut ecu),
        e(0x22)
    );
    // READ_DAQ reads the entry back.
    expect_ok(&mut s, &mut ecu, &[0xE2, 0, 0, 0, 0, 1]);
    assert_eq!(
        s.handle_cro(T, &[0xDB], &mut ecu),
        Some(vec![0xFF, 0xFF, 4, 0, 0, 0, 1, 0])
    );
    // Entry 0 unwritten + entry 1 (4 bytes) + timestamp = 9 > 8: ERR_DAQ_CONFIG at select.
    expect_ok(&mut s, &mut ecu, &[0xE2, 0, 0, 0, 0, 0]);
    expect_ok(&mut s, &mut ecu, &[0xE1, 0xFF, 4, 0, 4, 0, 1, 0]);
    expect_ok(&mut s, &mut ecu, &[0xE0, 0x10, 0, 0, 0, 0, 1, 0]);
    assert_eq!(s.handle_cro(T, &[0xDE, 2, 0, 0], &mut ecu), e(0x2A));
    // Mode: STIM, PID_OFF and other event channels are refused.
    assert_eq!(
        s.handle_cro(T, &[0xE0, 0x02, 0, 0, 0, 0, 1, 0], &mut ecu),
        e(0x22)
    );
    assert_eq!(
        s.handle_cro(T, &[0xE0, 0x20, 0, 0, 0, 0, 1, 0], &mut ecu),
        e(0x22)
    );
    assert_eq!(
        s.handle_cro(T, &[0xE0, 0x00, 0, 0, 1, 0, 1, 0], &mut ecu),
        e(0x22)
    );
    assert_eq!(s.handle_cro(T, &[0xDE, 3, 0, 0], &mut ecu), e(0x22));
    assert_eq!(s.handle_cro(T, &[0xDD, 3], &mut ecu), e(0x22));
    // Unknown and short commands.
    assert_eq!(s.handle_cro(T, &[0xF8, 0, 0], &mut ecu), e(0x20));
    assert_eq!(s.handle_cro(T, &[0xE2, 0, 0], &mut ecu), e(0x21));
}

#[test]
fn running_lists_refuse_changes_and_free_daq_stops_them() {
    let mut ecu = FakeEcu::new();
    let mut s = connected(&mut ecu);
    setup_two_lists(&mut s, &mut ecu);
    assert_eq!(
        s.handle_cro(T, &[0xDE, 1, 0, 0], &mut ecu),
        Some(vec![0xFF, 0])
    );
    assert_eq!(
        s.handle_cro(T, &[0xE2, 0, 0, 0, 1, 0], &mut ecu),
        Some(vec![0xFE, 0x11])
    );
    assert!(!s.on_event(T, 0, &snapshot(), &ecu).is_empty());
    expect_ok(&mut s, &mut ecu, &[0xD6]);
    assert!(s.on_event(T, 0, &snapshot(), &ecu).is_empty());
    assert!(!s.daq_running());
}

#[test]
fn upload_of_measurements_before_the_first_step_is_nan() {
    let mut ecu = FakeEcu::new();
    let mut s = connected(&mut ecu);
    let a = MEASUREMENT_BASE.to_le_bytes();
    let n = f32le(f32::NAN);
    assert_eq!(
        s.handle_cro(T, &[0xF4, 4, 0, 0, a[0], a[1], a[2], a[3]], &mut ecu),
        Some(vec![0xFF, n[0], n[1], n[2], n[3]])
    );
}

/// Seeded CROs: every answer is a response, an error packet or nothing; the slave never panics
/// and a response fits one CTO.
fn check_any(cros: &[Vec<u8>]) {
    let mut ecu = FakeEcu::new();
    ecu.snap = Some(snapshot());
    let mut s = XcpSlave::new();
    let snap = snapshot();
    for (i, cro) in cros.iter().enumerate() {
        let now = Duration::from_millis(10 * i as u64);
        if let Some(r) = s.handle_cro(now, cro, &mut ecu) {
            assert!(r.len() <= 8 && (r[0] == 0xFF || (r[0] == 0xFE && r.len() == 2)));
        }
        for p in s.on_event(now, 0, &snap, &ecu) {
            assert!(p.len() <= 8 && p[0] < 0xFC);
        }
    }
}

fn cro_strategy() -> impl Strategy<Value = Vec<u8>> {
    // Mostly implemented command codes with small parameters, so that sequences get deep.
    let code = prop_oneof![
        prop::sample::select(Command::ALL.map(|c| c as u8).to_vec()),
        any::<u8>()
    ];
    (
        code,
        prop::collection::vec(0u8..8, 0..8),
        prop::collection::vec(any::<u8>(), 0..3),
    )
        .prop_map(|(c, mut rest, tail)| {
            rest.extend(tail);
            rest.insert(0, c);
            rest
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]
    #[test]
    fn arbitrary_cros_never_panic(cros in prop::collection::vec(cro_strategy(), 0..64)) {
        let mut all = vec![vec![0xFF, 0x00]];
        all.extend(cros);
        check_any(&all);
    }
}

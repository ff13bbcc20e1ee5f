use super::memory::FaultMemory;
use super::*;

fn snap(t_s: f64) -> Snapshot {
    crate::diag::values::test_snapshot(t_s)
}

fn ms(n: u64) -> Duration {
    Duration::from_millis(n)
}

const F: FaultCode = FaultCode::EngStatusTimeout;

#[test]
fn table_bytes_by_hand() {
    assert_eq!(dtc_of(FaultCode::None), None);
    assert_eq!(dtc_of(F).map(|d| d.bytes()), Some([0xC1, 0x00, 0x87]));
    assert_eq!(dtc_of(F).map(|d| d.to_string()), Some("U0100-87".into()));
    let p = dtc_of(FaultCode::ClutchOverTempLimit);
    assert_eq!(p.map(|d| d.bytes()), Some([0x02, 0x18, 0x98]));
    assert_eq!(p.map(|d| d.to_string()), Some("P0218-98".into()));
    assert_eq!(
        dtc_of(FaultCode::PedalCrc).map(|d| d.to_string()),
        Some("U1403-83".into())
    );
    // Every fault code but None, each once, each DTC distinct.
    for f in FaultCode::ALL.iter().skip(1) {
        assert_eq!(TABLE.iter().filter(|(g, _)| g == f).count(), 1, "{f:?}");
    }
    for (i, (_, d)) in TABLE.iter().enumerate() {
        assert!(TABLE.iter().skip(i + 1).all(|(_, e)| e != d), "{d}");
    }
}

#[test]
fn status_sequence_over_operation_cycles() {
    let mut m = FaultMemory::new();
    m.start_operation_cycle();
    assert_eq!(m.status_of(F), Some(0x50));
    m.update(ms(0), FaultCode::None, true, &snap(0.0));
    assert_eq!(m.status_of(F), Some(0x00));
    // Failed from t = 10 ms: testFailed, thisCycle, pending, sinceLastClear = 0x27.
    for k in 1..=9 {
        m.update(ms(10 * k), F, true, &snap(0.01 * k as f64));
        assert_eq!(m.status_of(F), Some(0x27), "step {k}");
    }
    // The 10th failed step: 100 ms since the last step without failure: confirmed.
    m.update(ms(100), F, true, &snap(0.1));
    assert_eq!(m.status_of(F), Some(0x2F));
    // Another fault's DTC is untouched but tested.
    assert_eq!(m.status_of(FaultCode::PedalCrc), Some(0x00));
    // Heal.
    m.update(ms(110), FaultCode::None, true, &snap(0.11));
    assert_eq!(m.status_of(F), Some(0x2E));
    // New cycle: pending stays (failed in the last cycle).
    m.start_operation_cycle();
    assert_eq!(m.status_of(F), Some(0x6C));
    // Inputs not fresh: the test does not run.
    m.update(ms(0), FaultCode::None, false, &snap(0.0));
    assert_eq!(m.status_of(F), Some(0x6C));
    m.update(ms(10), FaultCode::None, true, &snap(0.0));
    assert_eq!(m.status_of(F), Some(0x2C));
    let rec = m.record(Dtc::sae(0xC100, 0x87)).copied();
    assert_eq!(rec.map(|r| (r.occurrences, r.aging)), Some((1, 0)));
    // Aging: 40 completed cycles without failure.
    for cycle in 1..=40u8 {
        m.start_operation_cycle();
        let expected = if cycle < 40 { 0x68 } else { 0x60 };
        assert_eq!(m.status_of(F), Some(expected), "cycle {cycle}");
        m.update(ms(0), FaultCode::None, true, &snap(0.0));
        let aging = m.record(Dtc::sae(0xC100, 0x87)).map(|r| r.aging);
        assert_eq!(aging, Some(if cycle < 40 { cycle } else { 0 }));
    }
    assert_eq!(m.status_of(F), Some(0x20));
}

#[test]
fn short_failures_stay_pending_and_count_cycles() {
    let mut m = FaultMemory::new();
    m.update(ms(0), FaultCode::None, true, &snap(0.0));
    for k in 1..=9 {
        m.update(ms(10 * k), F, true, &snap(0.0));
    }
    m.update(ms(100), FaultCode::None, true, &snap(0.0));
    m.update(ms(110), F, true, &snap(0.0));
    assert_eq!(m.status_of(F), Some(0x27));
    m.start_operation_cycle();
    // A cycle without failure ends: pending cleared (never confirmed).
    m.update(ms(0), FaultCode::None, true, &snap(0.0));
    m.start_operation_cycle();
    assert_eq!(m.status_of(F), Some(0x60));
    m.update(ms(0), F, true, &snap(0.0));
    let rec = m.record(Dtc::sae(0xC100, 0x87)).copied();
    assert_eq!(rec.map(|r| r.occurrences), Some(2));
    // The snapshot is the first failure's.
    assert_eq!(rec.and_then(|r| r.freeze).map(|f| f.t_s), Some(0.0));
}

#[test]
fn freeze_frame_and_clear() {
    let mut m = FaultMemory::new();
    assert!(!m.is_dirty());
    m.update(ms(0), FaultCode::ImplausibleSpeed, false, &snap(12.5));
    assert!(m.is_dirty());
    let d = Dtc::sae(0x0715, 0x64);
    let f = m.record(d).and_then(|r| r.freeze);
    assert_eq!(
        f.map(|f| (f.t_s, f.engine_rpm, f.gear, f.state)),
        Some((12.5, 2000.0, 2, 4))
    );
    m.mark_saved();
    assert!(m.clear(0x0007_1565).is_err());
    assert!(!m.is_dirty());
    assert!(m.clear(0x0007_1564).is_ok());
    assert_eq!(
        m.record(d).map(|r| (r.status, r.freeze)),
        Some((0x50, None))
    );
    assert!(m.is_dirty());
    m.update(ms(10), FaultCode::PedalCrc, true, &snap(1.0));
    assert!(m.clear(GROUP_ALL).is_ok());
    assert!(m.records().all(|(_, _, r)| *r == DtcRecord::default()));
}

#[test]
fn serialization_round_trip_keeps_nan_and_checks_version() {
    let mut m = FaultMemory::new();
    let mut s = snap(3.0);
    s.pedal_pct = f64::NAN;
    m.update(ms(0), F, true, &s);
    m.mark_saved();
    // Failing on in the same cycle with a NaN in the snapshot changes nothing stored.
    m.update(ms(10), F, true, &s);
    m.update(ms(20), FaultCode::None, true, &s);
    assert!(!m.is_dirty());
    let bytes = m.to_bytes().unwrap();
    let back = FaultMemory::from_bytes(&bytes).unwrap();
    assert!(!back.is_dirty());
    for ((_, _, a), (_, _, b)) in m.records().zip(back.records()) {
        assert_eq!(
            (a.status, a.occurrences, a.aging),
            (b.status, b.occurrences, b.aging)
        );
        assert_eq!(a.freeze.map(|f| f.t_s), b.freeze.map(|f| f.t_s));
    }
    let pedal = back
        .record(Dtc::sae(0xC100, 0x87))
        .and_then(|r| r.freeze)
        .map(|f| f.pedal_pct);
    assert!(pedal.is_some_and(f64::is_nan));
    let text = String::from_utf8(bytes).unwrap();
    assert!(text.contains("\"version\": 1"), "{text}");
    assert!(matches!(
        FaultMemory::from_bytes(text.replace("\"version\": 1", "\"version\": 2").as_bytes()),
        Err(DtcError::UnsupportedVersion { found: 2 })
    ));
    assert!(matches!(
        FaultMemory::from_bytes(br#"{"version":1,"dtcs":[{"dtc":1,"status":0,"occurrences":0,"aging":0,"freeze":null}]}"#),
        Err(DtcError::UnknownInFile(1))
    ));
    assert!(FaultMemory::from_bytes(b"{\"version\":1,").is_err());
    // A file listing no DTC is an untested memory.
    let empty = FaultMemory::from_bytes(br#"{"version":1,"dtcs":[]}"#).unwrap();
    assert_eq!(empty, FaultMemory::new());
}

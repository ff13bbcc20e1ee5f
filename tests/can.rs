//! Bus layer: encode/decode round trips of every message and signal, setter range checks, E2E,
//! candump I/O and robustness against random frames and garbage log lines.

use ddct::can::candump::{format_record, parse_line, LogReader, LogRecord, LogWriter};
use ddct::can::codec::CodecError;
use ddct::can::decode::LogDecoder;
use ddct::can::e2e::{e2e_crc, sample_frames, E2eChecker, E2eConfig, E2eError, E2eSender};
use ddct::can::messages::*;
use ddct::can::{Bus, CanFrame, EndpointConfig, InProcessBus, ManualClock};

mod common;
use std::sync::Arc;
use std::time::Duration;

/// A small deterministic generator (SplitMix64) so failures reproduce.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

#[test]
fn contract_has_thirteen_signal_messages_and_five_transport_ids() {
    let want = [
        (0x100, "ENG_Status", true),
        (0x110, "DRV_Pedal", true),
        (0x120, "TCU_ClutchCmd", true),
        (0x121, "TCU_EngineReq", true),
        (0x122, "TCU_GearCmd", true),
        (0x123, "TCU_Status", true),
        (0x124, "TCU_Estimates", false),
        (0x130, "DCT_Sensors", true),
        (0x131, "DCT_Actuators", true),
        (0x140, "BENCH_Torque", false),
        (0x141, "BENCH_Temps", false),
        (0x142, "BENCH_Vehicle", false),
        (0x1F0, "SIM_Truth", false),
    ];
    // The diagnostic transport ids (ISO 15765-2 for UDS, XCP on CAN): event frames, no signals.
    let transport = [
        (0x7DF, "DIAG_FunctionalReq", "BENCH"),
        (0x7E1, "TCU_DiagReq", "BENCH"),
        (0x7E9, "TCU_DiagResp", "TCU"),
        (0x7F0, "TCU_XcpCro", "BENCH"),
        (0x7F1, "TCU_XcpDto", "TCU"),
    ];
    assert_eq!(MESSAGES.len(), want.len() + transport.len());
    let (signal_messages, transport_messages) = MESSAGES.split_at(want.len());
    for (m, (id, name, sender)) in transport_messages.iter().zip(transport) {
        assert_eq!(
            (
                m.id,
                m.name,
                m.sender,
                m.e2e,
                m.cycle_ms,
                m.dlc,
                m.signals.len()
            ),
            (id, name, sender, false, 0, 8, 0)
        );
    }
    for (m, (id, name, e2e)) in signal_messages.iter().zip(want) {
        assert_eq!(
            (m.id, m.name, m.e2e, m.cycle_ms, m.dlc),
            (id, name, e2e, 10, 8)
        );
        if e2e {
            // Counter in the high nibble of byte 6, CRC in byte 7, payload signals in bits 0..52.
            let ac = &m.signals[m.signal_index("AliveCounter").unwrap()];
            let crc = &m.signals[m.signal_index("Crc").unwrap()];
            assert_eq!(
                (ac.start_bit, ac.length, crc.start_bit, crc.length),
                (52, 4, 56, 8)
            );
            for s in m
                .signals
                .iter()
                .filter(|s| s.name != "AliveCounter" && s.name != "Crc")
            {
                assert!(
                    s.start_bit + s.length <= 52,
                    "{}.{} overlaps the E2E bytes",
                    m.name,
                    s.name
                );
            }
        }
    }
}

#[test]
fn resolutions_keep_the_physics_visible() {
    for m in MESSAGES {
        for s in m.signals {
            let limit = match s.unit {
                "rpm" => 0.5,
                "mm" => 0.001,
                "Nm" => 0.1,
                "degC" if s.name == "HousingTemp" => 1.0,
                "degC" => 0.1,
                _ => continue,
            };
            assert!(
                s.factor <= limit + 1e-12,
                "{}.{} resolution {}",
                m.name,
                s.name,
                s.factor
            );
        }
    }
}

#[test]
fn every_signal_round_trips_at_min_mid_max() {
    let frames = sample_frames();
    assert_eq!(
        frames.len(),
        MESSAGES.iter().filter(|m| !m.signals.is_empty()).count() * 3,
        "a sample for every message and case"
    );
    for f in &frames {
        let decoded = f.def.decode_lenient(&f.data).unwrap();
        for (d, want) in decoded.iter().zip(&f.values) {
            assert!(
                (d.value - want).abs() <= d.signal.half_lsb(),
                "{} {} {}: {} != {}",
                f.def.name,
                f.case.as_str(),
                d.signal.name,
                d.value,
                want
            );
            assert!(d.in_range);
        }
        // The typed decoder accepts it and encodes back to the same bytes.
        let typed = Message::decode(u32::from(f.def.id), &f.data).unwrap();
        assert_eq!(
            typed.encode().unwrap(),
            f.data,
            "{} {}",
            f.def.name,
            f.case.as_str()
        );
        assert_eq!(typed.id(), f.def.id);
    }
}

#[test]
fn typed_messages_round_trip_with_quantisation() {
    let s = DctSensors {
        in_shaft1_speed: 2345.25,
        in_shaft2_speed: -120.5,
        out_shaft_speed: 612.74,
        housing_temp: 63.4,
        alive_counter: 9,
        crc: 0,
    };
    let d = DctSensors::decode(&s.encode().unwrap()).unwrap();
    assert_eq!(
        d.in_shaft1_speed, 2345.5,
        "0.5 rpm steps, round half away from zero"
    );
    assert_eq!(d.in_shaft2_speed, -120.5);
    assert_eq!(d.out_shaft_speed, 612.5);
    assert_eq!(d.housing_temp, 63.0);
    assert_eq!(d.alive_counter, 9);
    let st = TcuStatus {
        gear_active: GearActive::G3,
        tcu_state: TcuState::Launch,
        fault_code: FaultCode::SensorsTimeout,
        ..Default::default()
    };
    let back = TcuStatus::decode(&st.encode().unwrap()).unwrap();
    assert_eq!(back, st);
    assert_eq!(FaultCode::SensorsTimeout.label(), "SensorsTimeout");
}

#[test]
fn setters_reject_out_of_range_naming_the_signal() {
    let mut m = TcuClutchCmd::default();
    m.set_clutch1_pos_req(7.5).unwrap();
    let e = m.set_clutch1_pos_req(8.2).unwrap_err();
    assert_eq!(
        e,
        CodecError::OutOfRange {
            message: "TCU_ClutchCmd",
            signal: "Clutch1PosReq",
            value: 8.2,
            min: 0.0,
            max: 8.0
        }
    );
    assert!(e.to_string().contains("TCU_ClutchCmd.Clutch1PosReq"), "{e}");
    assert_eq!(m.clutch1_pos_req, 7.5, "a rejected value is not stored");
    assert!(matches!(
        m.set_clutch2_pos_req(f64::NAN),
        Err(CodecError::NotFinite {
            signal: "Clutch2PosReq",
            ..
        })
    ));
    let mut e = EngStatus::default();
    assert!(matches!(
        e.set_eng_speed(-1.0),
        Err(CodecError::OutOfRange {
            signal: "EngSpeed",
            ..
        })
    ));
    let mut p = DrvPedal::default();
    assert!(matches!(
        p.set_accel_pedal(100.1),
        Err(CodecError::OutOfRange {
            signal: "AccelPedal",
            ..
        })
    ));
    assert!(matches!(
        p.set_alive_counter(16),
        Err(CodecError::OutOfRange {
            signal: "AliveCounter",
            ..
        })
    ));
    // encode() checks too.
    let bad = BenchVehicle {
        vehicle_accel: 40.0,
        ..Default::default()
    };
    assert!(matches!(
        bad.encode(),
        Err(CodecError::OutOfRange {
            signal: "VehicleAccel",
            ..
        })
    ));
    // Every signal of every message rejects a value above its maximum by a whole step.
    for def in MESSAGES {
        for (si, s) in def.signals.iter().enumerate() {
            let too_big = s.max + s.factor.max(1e-3) * 2.0;
            match def.check(si, too_big) {
                Err(CodecError::OutOfRange { signal, .. }) => assert_eq!(signal, s.name),
                other => panic!("{}.{}: {other:?}", def.name, s.name),
            }
        }
    }
}

#[test]
fn decode_rejects_bad_payloads_with_typed_errors() {
    assert!(matches!(
        EngStatus::decode(&[0; 7]),
        Err(CodecError::WrongDlc {
            expected: 8,
            found: 7,
            ..
        })
    ));
    // GearLever raw 7 is not in the value table.
    let mut d = [0u8; 8];
    d[1] = 7 << 3;
    assert!(matches!(
        DrvPedal::decode(&d),
        Err(CodecError::UnknownValue {
            signal: "GearLever",
            raw: 7,
            ..
        })
    ));
    // Pedal raw 1023 = 102.3 % is outside 0..100.
    let mut d = [0u8; 8];
    d[0] = 0xFF;
    d[1] = 0x03;
    assert!(matches!(
        DrvPedal::decode(&d),
        Err(CodecError::OutOfRange {
            signal: "AccelPedal",
            ..
        })
    ));
    assert!(matches!(
        Message::decode(0x7FF, &[0; 8]),
        Err(CodecError::UnknownId { id: 0x7FF })
    ));
}

#[test]
fn crc_golden_vectors() {
    assert_eq!(ddct::can::e2e::crc8_sae_j1850(b"123456789"), 0x4B);
    // One frame per protected message: recomputing over id bytes + bytes 0-6 matches byte 7,
    // and any single-bit flip in the covered bytes is detected.
    for f in sample_frames().iter().filter(|f| f.def.e2e) {
        assert_eq!(f.data[7], e2e_crc(f.def.id, &f.data));
        for byte in 0..7 {
            for bit in 0..8 {
                let mut g = f.data;
                g[byte] ^= 1 << bit;
                assert_ne!(
                    g[7],
                    e2e_crc(f.def.id, &g),
                    "{} byte {byte} bit {bit}",
                    f.def.name
                );
            }
        }
        // The id is covered too: the same payload under another protected id fails.
        let other = MESSAGES.iter().find(|m| m.e2e && m.id != f.def.id).unwrap();
        assert_ne!(f.data[7], e2e_crc(other.id, &f.data));
    }
}

#[test]
fn random_frames_never_panic_and_are_rejected_typed() {
    let mut rng = Rng(0xDDC7);
    let contract_ids: Vec<u16> = MESSAGES.iter().map(|m| m.id).collect();
    let mut checker = E2eChecker::all(E2eConfig::default(), Duration::ZERO);
    let (mut rejected, mut accepted_protected) = (0usize, 0usize);
    let n = 100_000;
    for i in 0..n {
        let id: u32 = match rng.below(3) {
            0 => u32::from(contract_ids[rng.below(contract_ids.len() as u64) as usize]),
            1 => rng.below(0x800) as u32,
            _ => rng.below(1 << 29) as u32,
        };
        let len = rng.below(9) as usize;
        let mut data = [0u8; 8];
        for b in data.iter_mut().take(len) {
            *b = rng.next() as u8;
        }
        let data = &data[..len];
        let now = Duration::from_micros(i as u64 * 100);
        let decoded = Message::decode(id, data);
        let e2e = checker.check(now, id, data);
        match (&decoded, &e2e) {
            (Err(_), _) => rejected += 1,
            (Ok(m), Ok(())) => {
                assert!(m.encode().is_ok());
                accepted_protected += 1;
            }
            (Ok(_), Err(E2eError::NotProtected { .. })) => {}
            (Ok(_), Err(_)) => rejected += 1,
        }
        // Extended and random ids decode only if they are contract ids.
        if decoded.is_ok() {
            assert!(message_def(id).is_some() && len == 8);
        }
        let _ = checker.timeouts(now).count();
    }
    assert!(
        rejected > n / 2,
        "most random frames must be rejected, got {rejected}"
    );
    // A random CRC matches 1/256 of the time and a counter must also be the next one.
    assert!(
        accepted_protected < n / 500,
        "{accepted_protected} random frames passed E2E"
    );
}

#[test]
fn garbage_log_lines_are_rejected_with_line_numbers() {
    let mut rng = Rng(42);
    let alphabet = b"()0123456789.#ABCDEFabcdefRTvcan xyz\t-";
    let mut text = String::new();
    for _ in 0..20_000 {
        let len = rng.below(40) as usize;
        let line: String = (0..len)
            .map(|_| alphabet[rng.below(alphabet.len() as u64) as usize] as char)
            .collect();
        text.push_str(&line);
        text.push('\n');
        // Mutations of a valid line exercise the deeper branches.
        let mut valid = b"(1436509052.249713) vcan0 044#2A366C2BBA".to_vec();
        let pos = rng.below(valid.len() as u64) as usize;
        valid[pos] = alphabet[rng.below(alphabet.len() as u64) as usize];
        text.push_str(&String::from_utf8(valid).unwrap());
        text.push('\n');
    }
    let mut errors = 0;
    let mut last_line = 0;
    for item in LogReader::new(text.as_bytes()) {
        match item {
            Ok(r) => {
                // Whatever parsed must print back to a line that parses to the same record.
                assert_eq!(parse_line(&format_record(&r)).unwrap(), r);
            }
            Err(ddct::can::candump::LogError::Line { line, .. }) => {
                assert!(line > last_line);
                last_line = line;
                errors += 1;
            }
            Err(e) => panic!("{e}"),
        }
    }
    assert!(errors > 20_000, "{errors}");
    // Random bytes (not UTF-8) are an error too, not a panic.
    let bytes: Vec<u8> = (0..10_000).map(|_| rng.next() as u8).collect();
    for item in LogReader::new(&bytes[..]) {
        let _ = item;
    }
}

#[test]
fn log_writer_reader_round_trip_through_the_decoder() {
    let mut tx = E2eSender::new();
    let mut buf = Vec::new();
    {
        let mut w = LogWriter::new(&mut buf);
        for k in 0..40u64 {
            let mut d = EngStatus {
                eng_speed: 800.0 + k as f64,
                eng_torque_act: 10.0,
                ..Default::default()
            }
            .encode()
            .unwrap();
            tx.protect(ids::ENG_STATUS, &mut d);
            w.write(&LogRecord {
                timestamp: Duration::from_micros(1_700_000_000_000_000 + k * 10_000),
                iface: "vcan0".into(),
                frame: CanFrame::standard(ids::ENG_STATUS, &d).unwrap(),
                direction: None,
            })
            .unwrap();
        }
        w.flush().unwrap();
    }
    let text = String::from_utf8(buf).unwrap();
    assert!(text.starts_with("(1700000000.000000) vcan0 100#"));
    let mut dec = LogDecoder::default();
    let frames: Vec<_> = LogReader::new(text.as_bytes())
        .map(|r| dec.decode(&r.unwrap()))
        .collect();
    assert_eq!(frames.len(), 40);
    assert!(frames
        .iter()
        .all(|f| f.e2e.as_str() == "ok" && f.error.is_none()));
    assert_eq!(frames[39].signals[0].value, 839.0);
    assert!(dec.gaps().is_empty());
}

#[tokio::test]
async fn in_process_bus_carries_protected_frames_between_nodes() {
    let clock = Arc::new(ManualClock::new(Duration::ZERO));
    let bus = InProcessBus::with_clock("sim", clock.clone());
    let mut plant = bus.endpoint(EndpointConfig::default());
    let mut tcu = bus.endpoint(EndpointConfig::default());
    let mut tx = E2eSender::new();
    let mut checker = E2eChecker::all(E2eConfig::default(), Duration::ZERO);
    for k in 0..100u64 {
        clock.set(Duration::from_millis(10 * k));
        let mut d = DctSensors {
            in_shaft1_speed: k as f64,
            ..Default::default()
        }
        .encode()
        .unwrap();
        tx.protect(ids::DCT_SENSORS, &mut d);
        plant
            .send(CanFrame::standard(ids::DCT_SENSORS, &d).unwrap())
            .await
            .unwrap();
        let rx = tcu.recv().await.unwrap();
        assert_eq!(rx.timestamp, Duration::from_millis(10 * k));
        checker
            .check(rx.timestamp, rx.frame.raw_id(), rx.frame.bytes())
            .unwrap();
        assert_eq!(
            DctSensors::decode(rx.frame.bytes())
                .unwrap()
                .in_shaft1_speed,
            k as f64
        );
        assert!(
            plant.try_recv().unwrap().is_none(),
            "no own echo by default"
        );
    }
    // Silence: the timeout shows exactly at 3 cycles after the last valid frame.
    assert!(checker
        .timeout(Duration::from_millis(1019), ids::DCT_SENSORS)
        .is_none());
    assert!(checker
        .timeout(Duration::from_millis(1020), ids::DCT_SENSORS)
        .is_some());
}

/// Library sources outside the generated contract, each without its unit-test module and with
/// comments removed: what the DBC-is-the-only-source check reads.
fn library_code() -> Vec<(std::path::PathBuf, String)> {
    common::rust_files(&common::src(""))
        .into_iter()
        .filter(|p| {
            // The generated contract, and the gear type with its conversion to the DBC's codes.
            !["can/messages.rs", "can/gear.rs", "model/gear.rs"]
                .iter()
                .any(|g| p.ends_with(g))
        })
        .map(|p| {
            let text = std::fs::read_to_string(&p).unwrap();
            let code = text.split("#[cfg(test)]").next().unwrap_or("");
            let code: Vec<&str> = code
                .lines()
                .map(|l| l.split("//").next().unwrap_or(""))
                .collect();
            (p, code.join("\n"))
        })
        .collect()
}

/// Issue 15: the DBC is the single source of truth. Outside the generated contract no code
/// addresses a signal by its position (`signals[2]`, `def(), 0, …`), writes a contract id as a
/// literal (hex or decimal), copies the E2E byte positions or a cycle time, or handles a gear as
/// a number; the checker is shown to catch each pattern on a line written for the purpose.
#[test]
fn no_positional_signal_access_literal_id_cycle_or_gear_number_outside_the_contract() {
    let ids: Vec<u16> = MESSAGES.iter().map(|m| m.id).collect();
    let offences = |code: &str| -> Vec<String> {
        let mut found = Vec::new();
        for (n, line) in code.lines().enumerate() {
            let compact: String = line.split_whitespace().collect();
            let positional = compact.contains("signals[")
                && compact
                    .split("signals[")
                    .skip(1)
                    .any(|rest| rest.starts_with(|c: char| c.is_ascii_digit()))
                || compact.contains("def(),") && {
                    let rest = compact.split("def(),").nth(1).unwrap_or("");
                    rest.starts_with(|c: char| c.is_ascii_digit())
                };
            let id_literal = ids.iter().any(|id| {
                let hex = format!("0x{id:x}");
                let dec = id.to_string();
                let words: Vec<&str> = line
                    .split(|c: char| !c.is_ascii_alphanumeric() && c != '_')
                    .collect();
                words
                    .iter()
                    .any(|w| w.eq_ignore_ascii_case(&hex) || (*w == dec && line.contains("id")))
            });
            let e2e_bytes = compact.contains("data[6]") || compact.contains("data[7]");
            // A cycle time written out (the DBC's GenMsgCycleTime is the only source).
            let cycle_literal =
                compact.contains("from_millis(10)") || compact.contains("from_secs_f64(0.01)");
            // A gear compared with or written as a number (the `Gear` type and the DBC's
            // value tables are the only sources of gear codes).
            let gearish = |left: &str| {
                let token: String = left
                    .chars()
                    .rev()
                    .take_while(|c| c.is_ascii_alphanumeric() || "_.[]()".contains(*c))
                    .collect::<String>()
                    .to_lowercase();
                token.contains("raeg") && !token.contains("revel")
            };
            let gear_number = ["==", "!=", "<=", ">=", "<", ">"].iter().any(|op| {
                let parts: Vec<&str> = compact.split(op).collect();
                parts
                    .windows(2)
                    .any(|w| gearish(w[0]) && w[1].starts_with(|c: char| c.is_ascii_digit()))
            }) || compact.contains("(1..=6).contains(&g")
                || {
                    let parts: Vec<&str> = compact.split("asu8").collect();
                    parts[..parts.len() - 1].iter().any(|l| gearish(l))
                };
            if positional || id_literal || e2e_bytes || cycle_literal || gear_number {
                found.push(format!("{}: {}", n + 1, line.trim()));
            }
        }
        found
    };
    // The checker catches what it is meant to.
    for bad in [
        "let s = &def.signals[2];",
        "fit(TcuClutchCmd::def(), 0, x)",
        "let id = 0x130;",
        "if frame.id == 304 {",
        "data[7] ^= 1;",
        "let period = Duration::from_millis(10);",
        "if r.gear_active == 7 {",
        "if !(1..=6).contains(&gear) {",
        "let up = gear < 6;",
        "r.gear_req = [m.gear_odd_req as u8, m.gear_even_req as u8];",
    ] {
        assert!(!offences(bad).is_empty(), "the check misses `{bad}`");
    }
    let mut all = Vec::new();
    let files = library_code();
    assert!(files.len() > 50, "{} files", files.len());
    for (p, code) in &files {
        for o in offences(code) {
            all.push(format!("{}:{o}", p.display()));
        }
    }
    assert!(
        all.is_empty(),
        "outside the generated contract:\n{}",
        all.join("\n")
    );
}

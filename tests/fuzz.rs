//! Property tests (proptest) over everything that reads bytes from outside (issue 12): the TCU's
//! input path (frame decode, E2E, plausibility, timeouts, the state machine), the plant's input
//! path, the candump line parser and log decoder, and the rig CSV loader. Inputs are random frames
//! and random text, and — to get past the checks — mutations of real traffic (the frames of an
//! in-process launch) and of real files: bit flips, wrong ids and lengths, duplicates, reordering,
//! time jumps.
//!
//! Every property asserts what must hold for any input: no panic (a panic fails the case), every
//! frame put on the bus decodes to finite values inside the DBC's ranges, the TCU's trace stays
//! finite, a parsed candump line formats back to itself, a rejected file names itself.
//!
//! Cases per property: `DDCT_FUZZ_CASES` (default 2 000 in the test suite; `scripts/fuzz`
//! runs the million-case campaign and reports the counts).

use ddct::can::candump::{format_record, parse_line};
use ddct::can::decode::LogDecoder;
use ddct::can::messages::message_def;
use ddct::can::{CanFrame, Received};
use ddct::plant::{Plant, PlantConfig};
use ddct::records::dataset::Dataset;
use ddct::sim::{self, SimOptions, SimScenario};
use ddct::tcu::config::TcuConfig;
use ddct::tcu::{Tcu, TcuInputs, TimedFrame};
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;
use std::time::Duration;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn cases() -> u32 {
    std::env::var("DDCT_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(2_000)
}

fn runner() -> TestRunner {
    TestRunner::new(Config {
        cases: cases(),
        failure_persistence: None,
        // Shrinking a failure of a sequence of 64 frames is slow and the seed is printed.
        max_shrink_iters: 200,
        ..Config::default()
    })
}

fn tcu_config() -> &'static TcuConfig {
    static C: OnceLock<TcuConfig> = OnceLock::new();
    C.get_or_init(|| TcuConfig::load(root().join("config/tcu.toml")).expect("config/tcu.toml"))
}

/// The frames of a real in-process launch (plant and TCU), with their times.
fn traffic() -> &'static [(Duration, CanFrame)] {
    static T: OnceLock<Vec<(Duration, CanFrame)>> = OnceLock::new();
    T.get_or_init(|| {
        let sc = SimScenario::load(&root().join("config/scenarios/launch_50.toml")).unwrap();
        sim::run_scenario(&sc, tcu_config(), &SimOptions::default()).frames
    })
}

/// Every frame decodes (when its id is in the DBC) to finite values inside the DBC's ranges.
fn assert_frame_sane(f: &CanFrame, who: &str) -> Result<(), TestCaseError> {
    let Some(def) = message_def(f.raw_id()) else {
        return Err(TestCaseError::fail(format!(
            "{who} sent {:#x}, not in the DBC",
            f.raw_id()
        )));
    };
    let sigs = def
        .decode_lenient(f.bytes())
        .map_err(|e| TestCaseError::fail(format!("{who}: {e}")))?;
    for s in sigs {
        prop_assert!(
            s.value.is_finite(),
            "{who}: {}.{} = {}",
            def.name,
            s.signal.name,
            s.value
        );
        prop_assert!(
            s.in_range,
            "{who}: {}.{} = {} outside the DBC range",
            def.name,
            s.signal.name,
            s.value
        );
    }
    Ok(())
}

/// A frame: an id of the contract or any 11-bit id, any length, any bytes.
fn any_frame() -> impl Strategy<Value = CanFrame> {
    let ids: Vec<u16> = ddct::can::messages::MESSAGES.iter().map(|m| m.id).collect();
    (
        prop_oneof![3 => proptest::sample::select(ids), 1 => 0u16..0x800],
        proptest::collection::vec(any::<u8>(), 0..=8),
    )
        .prop_map(|(id, data)| CanFrame::standard(id, &data).expect("11-bit id, ≤ 8 bytes"))
}

/// One change to a window of real traffic.
#[derive(Debug, Clone)]
enum Mutation {
    FlipBit { at: usize, bit: u8 },
    SetByte { at: usize, byte: usize, value: u8 },
    Truncate { at: usize, len: usize },
    Duplicate { at: usize },
    Drop { at: usize },
    Swap { at: usize },
    Replace { at: usize, frame: CanFrame },
    Delay { at: usize, ms: u64 },
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), 0u8..64).prop_map(|(at, bit)| Mutation::FlipBit { at, bit }),
        (any::<usize>(), 0usize..8, any::<u8>()).prop_map(|(at, byte, value)| Mutation::SetByte {
            at,
            byte,
            value
        }),
        (any::<usize>(), 0usize..8).prop_map(|(at, len)| Mutation::Truncate { at, len }),
        any::<usize>().prop_map(|at| Mutation::Duplicate { at }),
        any::<usize>().prop_map(|at| Mutation::Drop { at }),
        any::<usize>().prop_map(|at| Mutation::Swap { at }),
        (any::<usize>(), any_frame()).prop_map(|(at, frame)| Mutation::Replace { at, frame }),
        (any::<usize>(), 0u64..5_000).prop_map(|(at, ms)| Mutation::Delay { at, ms }),
    ]
}

fn apply(frames: &mut Vec<(Duration, CanFrame)>, m: &Mutation) {
    if frames.is_empty() {
        return;
    }
    let n = frames.len();
    let rebuild = |f: &CanFrame, data: &[u8]| {
        CanFrame::standard(f.standard_id().unwrap_or(0), data).unwrap_or(*f)
    };
    match *m {
        Mutation::FlipBit { at, bit } => {
            let (_, f) = &mut frames[at % n];
            let mut d = f.bytes().to_vec();
            if !d.is_empty() {
                let k = usize::from(bit / 8) % d.len();
                d[k] ^= 1 << (bit % 8);
                *f = rebuild(f, &d);
            }
        }
        Mutation::SetByte { at, byte, value } => {
            let (_, f) = &mut frames[at % n];
            let mut d = f.bytes().to_vec();
            if !d.is_empty() {
                let k = byte % d.len();
                d[k] = value;
                *f = rebuild(f, &d);
            }
        }
        Mutation::Truncate { at, len } => {
            let (_, f) = &mut frames[at % n];
            let d = f.bytes().to_vec();
            *f = rebuild(f, &d[..len.min(d.len())]);
        }
        Mutation::Duplicate { at } => {
            let x = frames[at % n];
            frames.insert(at % n, x);
        }
        Mutation::Drop { at } => {
            frames.remove(at % n);
        }
        Mutation::Swap { at } => {
            let j = (at % n + 1) % n;
            let (a, b) = (frames[at % n].1, frames[j].1);
            frames[at % n].1 = b;
            frames[j].1 = a;
        }
        Mutation::Replace { at, frame } => frames[at % n].1 = frame,
        Mutation::Delay { at, ms } => {
            // Everything from `at` on arrives later (a silent sender, a stalled bus).
            for x in frames[at % n..].iter_mut() {
                x.0 += Duration::from_millis(ms);
            }
        }
    }
}

/// A window of real traffic, mutated.
fn mutated_traffic() -> impl Strategy<Value = Vec<(Duration, CanFrame)>> {
    let n = traffic().len();
    (
        0..n.saturating_sub(400),
        20usize..400,
        proptest::collection::vec(mutation(), 0..24),
    )
        .prop_map(|(start, len, muts)| {
            let mut w: Vec<(Duration, CanFrame)> =
                traffic()[start..(start + len).min(traffic().len())].to_vec();
            for m in &muts {
                apply(&mut w, m);
            }
            w
        })
}

/// Random frames at random times, or mutated real traffic.
fn input_stream() -> impl Strategy<Value = Vec<(Duration, CanFrame)>> {
    prop_oneof![
        1 => proptest::collection::vec((0u64..3_000, any_frame()), 0..64).prop_map(|v| {
            let mut t = Duration::ZERO;
            v.into_iter()
                .map(|(dt_us, f)| {
                    t += Duration::from_micros(dt_us);
                    (t, f)
                })
                .collect()
        }),
        3 => mutated_traffic(),
    ]
}

/// Frames (or lines, or CSV files) fed per property, for the campaign's report.
static FED: [AtomicU64; 7] = [const { AtomicU64::new(0) }; 7];

fn fed(k: usize, n: usize) {
    FED[k].fetch_add(n as u64, Ordering::Relaxed);
}

fn report(k: usize, what: &str) {
    println!(
        "{} cases, {} {what} fed",
        cases(),
        FED[k].load(Ordering::Relaxed)
    );
}

/// Runs the TCU core over a stream, one step per 10 ms, and checks every output.
fn tcu_over(stream: &[(Duration, CanFrame)]) -> Result<(), TestCaseError> {
    fed(0, stream.len());
    let t0 = stream.first().map_or(Duration::ZERO, |x| x.0);
    let mut tcu = Tcu::new(tcu_config().clone(), Duration::ZERO);
    let end = stream.last().map_or(Duration::ZERO, |x| x.0 - t0) + Duration::from_millis(50);
    let mut k = 0;
    let mut now = Duration::from_millis(10);
    while now <= end {
        let mut inbox = Vec::new();
        while k < stream.len() && stream[k].0 - t0 <= now {
            inbox.push(TimedFrame {
                at: stream[k].0 - t0,
                frame: stream[k].1,
            });
            k += 1;
        }
        let out = tcu.step(now, &TcuInputs { frames: &inbox });
        prop_assert_eq!(
            out.frames.len(),
            5,
            "the TCU emits its five messages every step"
        );
        for f in &out.frames {
            assert_frame_sane(f, "TCU")?;
        }
        let tr = out.trace;
        for v in tr
            .x_ref_mm
            .iter()
            .chain(&tr.t_ref_nm)
            .chain(&tr.theta_est_c)
            .chain(&tr.power_est_w)
        {
            prop_assert!(v.is_finite(), "TCU trace not finite: {tr:?}");
        }
        now += Duration::from_millis(10);
    }
    Ok(())
}

#[test]
fn the_tcu_input_path_takes_any_frames() {
    runner()
        .run(&input_stream(), |s| tcu_over(&s))
        .unwrap_or_else(|e| panic!("{e}"));
    report(0, "frames");
}

#[test]
fn the_plant_input_path_takes_any_frames() {
    let cfg = PlantConfig::load(&root().join("config/plant.toml")).expect("config/plant.toml");
    runner()
        .run(&input_stream(), |stream| {
            fed(1, stream.len());
            let mut plant = Plant::new(cfg.clone());
            let t0 = stream.first().map_or(Duration::ZERO, |x| x.0);
            let rx: Vec<Received> = stream
                .iter()
                .map(|(t, f)| Received {
                    frame: *f,
                    timestamp: *t - t0,
                })
                .collect();
            let end = rx.last().map_or(Duration::ZERO, |r| r.timestamp) + Duration::from_millis(30);
            let mut now = Duration::ZERO;
            let mut k = 0;
            while now <= end {
                let j = rx[k..].partition_point(|r| r.timestamp <= now) + k;
                let out = plant.step(now, &rx[k..j]);
                k = j;
                for f in &out.frames {
                    assert_frame_sane(&f.frame, "plant")?;
                }
                now += Duration::from_millis(10);
            }
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{e}"));
    report(1, "frames");
}

/// A candump `-l` line: real ones mutated character by character, or random text.
fn candump_line() -> impl Strategy<Value = String> {
    let real: Vec<String> = traffic()
        .iter()
        .take(2_000)
        .map(|(t, f)| {
            format_record(&ddct::can::candump::LogRecord {
                timestamp: *t + Duration::from_secs(1_700_000_000),
                iface: "vcan0".into(),
                frame: *f,
                direction: None,
            })
        })
        .collect();
    let chars = "0123456789abcdefABCDEF#.() -Rrx\t\u{e9}\u{0}";
    prop_oneof![
        1 => "\\PC{0,80}",
        3 => (
            proptest::sample::select(real),
            proptest::collection::vec((any::<usize>(), proptest::sample::select(chars.chars().collect::<Vec<_>>()), 0u8..3), 0..6),
        )
            .prop_map(|(line, edits)| {
                let mut c: Vec<char> = line.chars().collect();
                for (at, ch, op) in edits {
                    let n = c.len().max(1);
                    match op {
                        0 if !c.is_empty() => c[at % n] = ch,
                        1 => c.insert(at % (c.len() + 1), ch),
                        _ if !c.is_empty() => {
                            c.remove(at % n);
                        }
                        _ => {}
                    }
                }
                c.into_iter().collect()
            }),
    ]
}

#[test]
fn candump_lines_parse_or_are_refused_and_round_trip() {
    runner()
        .run(&proptest::collection::vec(candump_line(), 1..20), |lines| {
            fed(2, lines.len());
            let mut dec = LogDecoder::default();
            for line in &lines {
                match parse_line(line) {
                    Ok(r) => {
                        let again = parse_line(&format_record(&r))
                            .map_err(|e| TestCaseError::fail(format!("{e}")))?;
                        prop_assert_eq!(&again, &r);
                        let d = dec.decode(&r);
                        for s in d.signals.iter() {
                            prop_assert!(s.value.is_finite() || !s.in_range);
                        }
                    }
                    Err(e) => prop_assert!(!e.to_string().is_empty()),
                }
            }
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{e}"));
    report(2, "lines");
}

/// A rig record in the documented columns (the first 300 rows of a truth generator's training
/// record: enough to reach every check).
fn rig_csv() -> &'static str {
    static C: OnceLock<String> = OnceLock::new();
    C.get_or_init(|| {
        let nominal = ddct::model::params::Params::default();
        let t = ddct::truth::draw(1, 0, &nominal);
        let recs = ddct::truth::records(&t, 1);
        let text = &recs.train[0].1;
        text.lines().take(301).collect::<Vec<_>>().join("\n")
    })
}

#[test]
fn rig_csv_files_load_or_are_refused_naming_the_file() {
    let base = rig_csv();
    let lines: Vec<&str> = base.lines().collect();
    let edits = proptest::collection::vec(
        (
            any::<usize>(),
            prop_oneof![
                Just("nan".to_string()),
                Just("inf".to_string()),
                Just("-1e300".to_string()),
                Just("".to_string()),
                Just("x".to_string()),
                Just("1e-9".to_string()),
                Just("-61".to_string()),
                Just("601".to_string()),
                "[-0-9.e]{1,8}",
            ],
            any::<usize>(),
            0u8..4,
        ),
        0..8,
    );
    runner()
        .run(&edits, |edits| {
            let mut rows: Vec<String> = lines.iter().map(|s| s.to_string()).collect();
            for (row, value, col, op) in edits {
                let r = row % rows.len();
                let mut cells: Vec<String> = rows[r].split(',').map(str::to_string).collect();
                let c = col % cells.len().max(1);
                match op {
                    0 | 1 => cells[c] = value,
                    2 => {
                        cells.remove(c);
                    }
                    _ => {
                        rows.remove(r.max(1).min(rows.len() - 1));
                        continue;
                    }
                }
                rows[r] = cells.join(",");
            }
            let text = rows.join("\n");
            fed(3, 1);
            if let Err(e) = Dataset::from_csv("fuzz.csv", &text) {
                prop_assert!(
                    e.to_string().contains("fuzz.csv"),
                    "error without the file name: {e}"
                );
            }
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{e}"));
    report(3, "files");
}

/// Every numeric key of every shipped configuration (TCU calibration, plant and rig, physical
/// parameters, the `ddct sim` scenarios, the fault file), set to NaN, ±infinity, 1e300 or a
/// string: each is refused, and the error names the file, the key and its line. Copies of `config/` in a
/// temporary directory, so that the files' references to each other still resolve.
#[test]
fn every_config_key_with_nan_inf_huge_or_a_string_is_refused_naming_file_line_and_key() {
    let tmp = std::env::temp_dir().join(format!("ddct-config-fuzz-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    copy_dir(&root().join("config"), &tmp.join("config"));
    let plant = PlantConfig::load(&root().join("config/plant.toml")).unwrap();
    type Loader = Box<dyn Fn(&std::path::Path) -> Result<(), String>>;
    let loaders: Vec<(&str, Loader)> = vec![
        (
            "tcu.toml",
            Box::new(|p| {
                TcuConfig::load(p)
                    .map(drop)
                    .map_err(|e| ddct::error_chain::chain(&e))
            }),
        ),
        (
            "plant.toml",
            Box::new(|p| {
                PlantConfig::load(p)
                    .map(drop)
                    .map_err(|e| ddct::error_chain::chain(&e))
            }),
        ),
        (
            "plant_rig.toml",
            Box::new(|p| {
                PlantConfig::load(p)
                    .map(drop)
                    .map_err(|e| ddct::error_chain::chain(&e))
            }),
        ),
        // A parameter error names the key; every caller (plant, TCU, CLI) adds the file.
        (
            "params.toml",
            Box::new(|p| {
                ddct::model::params::Params::load(p)
                    .map(drop)
                    .map_err(|e| format!("{}: {}", p.display(), ddct::error_chain::chain(&e)))
            }),
        ),
        (
            "plant_faults.toml",
            Box::new(move |p| {
                plant
                    .load_faults(p)
                    .map(drop)
                    .map_err(|e| ddct::error_chain::chain(&e))
            }),
        ),
    ];
    let mut files: Vec<(PathBuf, usize)> = loaders
        .iter()
        .enumerate()
        .map(|(k, (name, _))| (tmp.join("config").join(name), k))
        .collect();
    let scenarios = tmp.join("config/scenarios");
    let mut tried = 0;
    let mut failures = Vec::new();
    let scenario_loader: Loader = Box::new(|p| {
        SimScenario::load(p)
            .map(drop)
            .map_err(|e| ddct::error_chain::chain(&e))
    });
    for e in std::fs::read_dir(&scenarios).unwrap() {
        let p = e.unwrap().path();
        if SimScenario::load(&p).is_ok() {
            files.push((p, usize::MAX));
        }
    }
    let number = |v: &str| v.trim().parse::<f64>().is_ok();
    for (path, k) in &files {
        let load = if *k == usize::MAX {
            &scenario_loader
        } else {
            &loaders[*k].1
        };
        let original = std::fs::read_to_string(path).unwrap();
        assert!(
            load(path).is_ok(),
            "{} does not load as shipped",
            path.display()
        );
        let lines: Vec<&str> = original.lines().collect();
        for (n, line) in lines.iter().enumerate() {
            let code = line.split('#').next().unwrap_or("");
            let Some((key, value)) = code.split_once('=') else {
                continue;
            };
            let key = key.trim();
            if key.is_empty() || key.starts_with('[') || !number(value) {
                continue;
            }
            for bad in ["nan", "inf", "-inf", "1e300", "\"x\""] {
                let mut text = lines.clone();
                let changed = format!("{key} = {bad}");
                text[n] = &changed;
                std::fs::write(path, text.join("\n")).unwrap();
                tried += 1;
                let file = path.file_name().unwrap().to_string_lossy().to_string();
                match load(path) {
                    Ok(()) => failures.push(format!("{file}:{} `{key} = {bad}` accepted", n + 1)),
                    Err(e)
                        if !(e.contains(&file)
                            && e.contains(key)
                            && e.contains(&format!("line {}", n + 1))) =>
                    {
                        failures.push(format!("{file}:{} `{key} = {bad}`: {e}", n + 1))
                    }
                    Err(_) => {}
                }
            }
            std::fs::write(path, &original).unwrap();
        }
    }
    let _ = std::fs::remove_dir_all(&tmp);
    println!(
        "{tried} bad values in {} files, {} not refused by name",
        files.len(),
        failures.len()
    );
    assert!(
        failures.is_empty(),
        "{} of {tried}:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

fn copy_dir(from: &std::path::Path, to: &std::path::Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let p = e.unwrap().path();
        let dest = to.join(p.file_name().unwrap());
        if p.is_dir() {
            copy_dir(&p, &dest);
        } else {
            std::fs::copy(&p, &dest).unwrap();
        }
    }
}

/// Frames an ISO-TP endpoint may see, with the time before each (µs): every PCI nibble (0–3 and
/// two invalid ones), any low nibble and 0–7 more bytes, so that single, first, consecutive and
/// flow-control frames of every length — valid, truncated, out of sequence — all occur.
fn isotp_stream() -> impl Strategy<Value = Vec<(u64, Vec<u8>)>> {
    let frame = (0u8..6, 0u8..16, prop::collection::vec(any::<u8>(), 0..=7)).prop_map(
        |(pci, low, rest)| {
            let mut f = vec![pci << 4 | low];
            f.extend(rest);
            f
        },
    );
    prop::collection::vec((0u64..1_500_000, frame), 0..120)
}

/// Feeds a stream to a receiver and to a sender in the middle of a 100-byte message: nothing
/// panics, a received message is 1–4 095 bytes, and the sender's consecutive frames carry
/// sequence numbers 1, 2, … and are never more than the message needs.
fn isotp_over(stream: &[(u64, Vec<u8>)]) -> Result<(), TestCaseError> {
    use ddct::diag::isotp::{IsoTp, IsoTpConfig, MAX_PAYLOAD};
    let cfg = IsoTpConfig {
        block_size: 2,
        st_min: 1,
        ..IsoTpConfig::default()
    };
    let (mut rx, mut tx) = (IsoTp::new(cfg), IsoTp::new(cfg));
    let mut now = Duration::ZERO;
    tx.send(now, &[0x5A; 100])
        .map_err(|e| TestCaseError::fail(e.to_string()))?;
    let (mut sn, mut cfs) = (1u8, 0usize);
    for (gap, f) in stream {
        now += Duration::from_micros(*gap);
        rx.handle_timeout(now);
        tx.handle_timeout(now);
        if let Some(m) = rx.handle_frame(now, f).or_else(|| rx.handle_functional(f)) {
            prop_assert!((1..=MAX_PAYLOAD).contains(&m.len()), "{} bytes", m.len());
        }
        tx.handle_frame(now, f);
        while rx.poll_transmit(now).is_some() {}
        while let Some(out) = tx.poll_transmit(now) {
            let b = out.bytes();
            if b[0] >> 4 == 2 {
                prop_assert_eq!(b[0] & 0x0F, sn);
                sn = (sn + 1) & 0x0F;
                cfs += 1;
            }
        }
        // 100 − 6 bytes after the first frame: 14 consecutive frames at most.
        prop_assert!(cfs <= 14, "{cfs} consecutive frames");
    }
    fed(4, stream.len());
    Ok(())
}

#[test]
fn the_isotp_transport_takes_any_frames() {
    runner()
        .run(&isotp_stream(), |s| isotp_over(&s))
        .unwrap_or_else(|e| panic!("{e}"));
    report(4, "ISO-TP frames");
}

/// One event at the TCU's diagnostic side: a frame on one of its three request ids, or a TCU step
/// (kind 3). UDS frames are mostly single frames of the known services (so requests get past the
/// transport into the server's checks), XCP frames mostly start with a command code (0xC0–0xFF).
fn diag_stream() -> impl Strategy<Value = Vec<(u64, u8, Vec<u8>)>> {
    const SIDS: [u8; 11] = [
        0x10, 0x11, 0x14, 0x19, 0x22, 0x27, 0x2E, 0x31, 0x3E, 0xBA, 0x85,
    ];
    let uds = (
        prop::sample::select(SIDS.to_vec()),
        prop::collection::vec(any::<u8>(), 0..=6),
        any::<bool>(),
    )
        .prop_map(|(sid, rest, raw)| {
            if raw {
                let mut f = vec![sid];
                f.extend(rest);
                f
            } else {
                let mut f = vec![1 + rest.len() as u8, sid];
                f.extend(rest);
                f
            }
        });
    let xcp = (0xC0u8..=0xFF, prop::collection::vec(any::<u8>(), 0..=7)).prop_map(|(c, rest)| {
        let mut f = vec![c];
        f.extend(rest);
        f
    });
    let event = prop_oneof![
        (Just(0u8), uds.clone()),
        (Just(1u8), uds),
        (Just(2u8), xcp),
        (Just(3u8), Just(Vec::new())),
    ];
    prop::collection::vec((0u64..200_000, event), 0..150)
        .prop_map(|v| v.into_iter().map(|(g, (k, f))| (g, k, f)).collect())
}

/// Feeds a stream to the whole diagnostic side (ISO-TP, UDS server, XCP slave, fault memory)
/// around a real TCU core: nothing panics, and every frame it sends is a UDS response or an XCP
/// packet of at most 8 bytes; an ECUReset restarts the core.
fn diag_over(stream: &[(u64, u8, Vec<u8>)]) -> Result<(), TestCaseError> {
    use ddct::can::messages::ids;
    use ddct::diag::dtc::memory::FaultMemory;
    use ddct::diag::stack::{DiagConfig, DiagStack};
    let mut tcu = Tcu::new(tcu_config().clone(), Duration::ZERO);
    let mut stack = DiagStack::new(DiagConfig::default(), FaultMemory::default());
    let mut now = Duration::ZERO;
    for (gap, kind, bytes) in stream {
        now += Duration::from_micros(*gap);
        stack.handle_timeout(now, &mut tcu);
        let id = [
            ids::TCU_DIAG_REQ,
            ids::DIAG_FUNCTIONAL_REQ,
            ids::TCU_XCP_CRO,
        ]
        .get(*kind as usize);
        match id.and_then(|id| CanFrame::standard(*id, bytes).ok()) {
            Some(f) => stack.handle_frame(now, &f, &mut tcu),
            None => {
                let out = tcu.step(now, &TcuInputs { frames: &[] });
                stack.after_step(now, now, &out, &mut tcu);
            }
        }
        while let Some(f) = stack.poll_transmit(now) {
            let id = f.standard_id();
            prop_assert!(
                id == Some(ids::TCU_DIAG_RESP) || id == Some(ids::TCU_XCP_DTO),
                "{f:?}"
            );
            prop_assert!(f.bytes().len() <= 8);
        }
        if stack.take_reset().is_some() {
            tcu = Tcu::new(tcu_config().clone(), now);
            stack.restarted();
        }
    }
    fed(5, stream.len());
    Ok(())
}

#[test]
fn the_diagnostic_side_takes_any_requests() {
    runner()
        .run(&diag_stream(), |s| diag_over(&s))
        .unwrap_or_else(|e| panic!("{e}"));
    report(5, "diagnostic frames and steps");
}

/// A valid MF4 of a few frames (standard, extended, remote, on two interfaces), as bytes.
fn mf4_bytes() -> &'static [u8] {
    static BYTES: OnceLock<Vec<u8>> = OnceLock::new();
    BYTES.get_or_init(|| {
        let mut w = ddct::can::mf4::Mf4Writer::new();
        for line in [
            "(1700000000.000100) vcan0 100#0102030405060708",
            "(1700000000.001000) vcan0 1ABCDEF0#DEAD",
            "(1700000000.002000) can1 7E1#R T",
            "(1700000000.003000) vcan0 123#",
        ] {
            w.push(&ddct::can::candump::parse_line(line).unwrap());
        }
        let mut out = Vec::new();
        w.finish(&mut out).unwrap();
        out
    })
}

/// Byte edits of the valid file: overwrite a run, cut it, or graft random bytes.
fn mf4_mutations() -> impl Strategy<Value = Vec<u8>> {
    let n = mf4_bytes().len();
    prop_oneof![
        (0..n, proptest::collection::vec(any::<u8>(), 1..16)).prop_map(|(at, bytes)| {
            let mut v = mf4_bytes().to_vec();
            for (i, b) in bytes.into_iter().enumerate() {
                if at + i < v.len() {
                    v[at + i] = b;
                }
            }
            v
        }),
        (0..n).prop_map(|cut| mf4_bytes()[..cut].to_vec()),
        proptest::collection::vec(any::<u8>(), 0..512).prop_map(|tail| {
            let mut v = ddct::can::mf4::MAGIC.to_vec();
            v.extend(tail);
            v
        }),
    ]
}

#[test]
fn the_mf4_reader_takes_any_bytes() {
    runner()
        .run(&mf4_mutations(), |bytes| {
            // Ok or a typed error, never a panic; every frame read is a valid classic frame.
            if let Ok(frames) = ddct::can::mf4::read(&bytes) {
                for f in frames.flatten() {
                    prop_assert!(f.frame.bytes().len() <= 8);
                }
            }
            fed(6, 1);
            Ok(())
        })
        .unwrap_or_else(|e| panic!("{e}"));
    report(6, "MF4 files");
}

//! The TCU in closed loop with the plant core (`ddct sim`'s lockstep runner, simulated time):
//! issue 6's acceptance — launches, shifts, the paper's Sect. 6 compensation table, the thermal
//! estimator against SIM_Truth, and the safety cases asserted exactly in simulated time.
//!
//! The expectations are independent of the controller's internals: everything is measured from
//! the frames on the (simulated) bus — the plant's sensor, bench and truth messages and the TCU's
//! TCU_Status/TCU_ClutchCmd/TCU_EngineReq/TCU_Estimates.

#[path = "tcu/kiss_point.rs"]
mod kiss_point;

use ddct::can::e2e::{E2eChecker, E2eConfig};
use ddct::can::messages::{ids, FaultCode, TcuClutchCmd, TcuEngineReq, TcuState, TcuStatus};
use ddct::can::CanFrame;
use ddct::model::gear::Gear;
use ddct::sim::metrics::{self, LaunchMetrics, Metrics};
use ddct::sim::{self, Injection, InjectionKind, SimOptions, SimRun, SimScenario};
use ddct::tcu::TcuConfig;
use std::path::PathBuf;
use std::time::Duration;

fn scenario(name: &str) -> SimScenario {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("config/scenarios")
        .join(format!("{name}.toml"));
    SimScenario::load(&p).unwrap_or_else(|e| panic!("{e}"))
}

fn tcu_config() -> TcuConfig {
    TcuConfig::load(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("config/tcu.toml")).unwrap()
}

fn run(name: &str, opts: &SimOptions) -> (SimRun, Metrics) {
    let cfg = tcu_config();
    let r = sim::run_scenario(&scenario(name), &cfg, opts);
    let m = metrics::compute(&r.rows, &cfg);
    (r, m)
}

fn only_launch(m: &Metrics, name: &str) -> LaunchMetrics {
    assert_eq!(m.launches.len(), 1, "{name}: one launch expected");
    m.launches[0].clone()
}

#[test]
fn flat_launches_lock_up_in_time_without_stall_flare_or_spike() {
    for (name, pedal) in [
        ("launch_20", 20.0),
        ("launch_50", 50.0),
        ("launch_100", 100.0),
    ] {
        let (r, m) = run(name, &SimOptions::default());
        let l = only_launch(&m, name);
        assert_eq!(l.pedal_pct, pedal);
        let lock = l.lockup_s.unwrap_or_else(|| panic!("{name}: no lock-up"));
        assert!(
            (0.8..=2.5).contains(&lock),
            "{name}: lock-up after {lock} s"
        );
        assert!(!l.stall, "{name}: engine fell to {} rpm", l.min_engine_rpm);
        assert!(l.flare_rpm <= 300.0, "{name}: flare {} rpm", l.flare_rpm);
        let spike = l.lockup_spike_mps2.unwrap();
        assert!(spike <= 0.5, "{name}: lock-up spike {spike} m/s²");
        // The TCU says Drive once locked, and nothing on the bus is NaN.
        assert!(r.rows.iter().any(|x| x.state == TcuState::Drive), "{name}");
        assert!(!m.nonfinite, "{name}");
        assert!(r.rows.iter().all(|x| x.fault == FaultCode::None), "{name}");
    }
}

#[test]
fn upshifts_at_half_pedal_keep_the_vehicle_accelerating_and_downshifts_complete() {
    let (_, m) = run("shifts_50", &SimOptions::default());
    let ups: Vec<_> = m
        .shifts
        .iter()
        .filter(|s| s.up && Gear::G3.above(s.from))
        .collect();
    assert_eq!(
        ups.iter().map(|s| (s.from, s.to)).collect::<Vec<_>>(),
        vec![(Gear::G1, Gear::G2), (Gear::G2, Gear::G3)]
    );
    for s in &ups {
        assert!(s.completed, "{s:?}");
        assert!(s.min_accel_mps2 > 0.0, "acceleration not positive: {s:?}");
        assert!(s.duration_s < 1.5, "{s:?}");
    }
    let downs: Vec<_> = m.shifts.iter().filter(|s| !s.up).collect();
    assert!(
        downs.iter().any(|s| (s.from, s.to) == (Gear::G2, Gear::G1)),
        "{downs:?}"
    );
    assert!(downs.iter().all(|s| s.completed), "{downs:?}");
    // Back to a standstill in creep/hold, engine alive.
    assert!(
        m.min_engine_rpm_driving > 600.0,
        "{}",
        m.min_engine_rpm_driving
    );
}

/// The paper's Sect. 6 (Figs. 15, 17, 18): preheated launches, temperature compensation off/on.
#[test]
fn temperature_compensation_table() {
    let mut err = std::collections::BTreeMap::new();
    let mut peak = std::collections::BTreeMap::new();
    for t in [40, 140, 240] {
        for c in ["on", "off"] {
            let name = format!("preheat_{t}_temp_{c}");
            let (_, m) = run(&name, &SimOptions::default());
            let l = only_launch(&m, &name);
            assert!(l.lockup_s.is_some(), "{name}");
            err.insert((c, t), l.peak_torque_error_300ms_nm);
            peak.insert((c, t), l.peak_accel_600ms_mps2);
        }
    }
    // Off: both grow with the temperature.
    assert!(err[&("off", 40)] < err[&("off", 140)] && err[&("off", 140)] < err[&("off", 240)]);
    assert!(err[&("off", 240)] > 3.0 * err[&("off", 40)], "{err:?}");
    assert!(peak[&("off", 40)] < peak[&("off", 140)] && peak[&("off", 140)] < peak[&("off", 240)]);
    // On: within 20 % of the 40 °C values.
    for t in [140, 240] {
        let (e0, e) = (err[&("on", 40)], err[&("on", t)]);
        assert!((e - e0).abs() <= 0.2 * e0, "{t} °C: {e} vs {e0}");
        let (a0, a) = (peak[&("on", 40)], peak[&("on", t)]);
        assert!((a - a0).abs() <= 0.2 * a0, "{t} °C: {a} vs {a0}");
    }
}

/// Fig. 14: without slip compensation the torque error grows as the slip falls toward lock-up.
#[test]
fn slip_compensation_removes_the_low_slip_torque_error() {
    for pedal in [30, 100] {
        let rel = |c: &str| {
            let name = format!("slip_{c}_{pedal}");
            let (_, m) = run(&name, &SimOptions::default());
            let l = only_launch(&m, &name);
            // Relative mean error T_ref − T_actual per slip bin, from 10–20 rad/s down to 0.3–1.
            l.torque_error_by_slip
                .iter()
                .filter(|b| b.slip_hi_radps <= 20.0)
                .map(|b| {
                    b.mean_rel_error
                        .unwrap_or_else(|| panic!("{name}: empty bin {b:?}"))
                })
                .collect::<Vec<f64>>()
        };
        let (on, off) = (rel("on"), rel("off"));
        // Off: grows monotonically as the slip falls, to more than 5 % of the torque.
        for w in off.windows(2) {
            assert!(w[1] > w[0], "{pedal} %: off {off:?}");
        }
        assert!(*off.last().unwrap() > 0.05, "{pedal} %: off {off:?}");
        // On: stays small (actuator lag and sampling only).
        assert!(on.iter().all(|e| e.abs() < 0.03), "{pedal} %: on {on:?}");
        assert!(
            on.last().unwrap().abs() < 0.3 * off.last().unwrap(),
            "{on:?} {off:?}"
        );
    }
}

#[test]
fn estimator_tracks_the_truth_over_twenty_repeated_launches() {
    let (_, m) = run("repeated_launches", &SimOptions::default());
    assert_eq!(m.launches.len(), 20);
    let e = m.estimator;
    assert!(e.max_true_c[0] > 70.0, "the clutch heats: {e:?}");
    assert!(e.rmse_c[0] < 15.0 && e.rmse_c[1] < 15.0, "{e:?}");
    eprintln!(
        "estimator over 20 launches: RMSE {:.2} / {:.2} °C, max {:.2} / {:.2} °C, truth up to {:.1} °C",
        e.rmse_c[0], e.rmse_c[1], e.max_abs_c[0], e.max_abs_c[1], e.max_true_c[0]
    );
}

#[test]
fn uphill_launch_and_creep_in_traffic() {
    let (_, m) = run("uphill_launch", &SimOptions::default());
    let l = only_launch(&m, "uphill");
    assert!(l.lockup_s.is_some_and(|t| t < 2.5) && !l.stall, "{l:?}");
    let (r, m) = run("creep_traffic", &SimOptions::default());
    assert!(m.min_engine_rpm_driving > 600.0);
    // Creeping with the brake off settles at a walking pace and the engine at idle.
    let creep: Vec<_> = r
        .rows
        .iter()
        .filter(|x| x.t_s > 6.0 && x.t_s < 8.0)
        .collect();
    assert!(creep.iter().all(|x| x.state == TcuState::Creep));
    let v = creep.last().unwrap().v_kmh;
    assert!((3.0..9.0).contains(&v), "creep speed {v} km/h");
    // Brake on: the clutch lets go and the car stops.
    let held: Vec<_> = r
        .rows
        .iter()
        .filter(|x| x.t_s > 10.5 && x.t_s < 12.0)
        .collect();
    assert!(held
        .iter()
        .all(|x| x.v_kmh.abs() < 0.1 && x.t_act_nm[0].abs() < 2.0));
}

#[test]
fn runs_are_deterministic() {
    let (a, _) = run("launch_50", &SimOptions::default());
    let (b, _) = run("launch_50", &SimOptions::default());
    assert_eq!(a.frames, b.frames);
    assert_eq!(a.frame_count, a.frames.len() as u64);
    // Counting instead of keeping the frames changes nothing else.
    let dropped = SimOptions {
        drop_frames: true,
        ..SimOptions::default()
    };
    let (c, _) = run("launch_50", &dropped);
    assert!(c.frames.is_empty());
    assert_eq!(c.frame_count, a.frame_count);
    assert_eq!(c.rows, a.rows);
}

// ---------------------------------------------------------------------------------------------
// Safety, exactly, in simulated time.

const FAULT_FROM_S: f64 = 5.0;
const FAULT_TO_S: f64 = 5.5;

struct SafetyTimes {
    last_valid: Duration,
    detected: Duration,
    fault: FaultCode,
    safe_cmd: Duration,
    first_back: Duration,
    recovered: Duration,
}

/// Replays the TCU's frames of a run with a fault on `id` and measures detection and recovery.
fn safety_case(id: u16, kind: InjectionKind) -> SafetyTimes {
    let opts = SimOptions {
        injections: vec![Injection {
            id,
            kind,
            from_s: FAULT_FROM_S,
            to_s: FAULT_TO_S,
        }],
        ..SimOptions::default()
    };
    let (r, m) = run("launch_50", &opts);
    assert!(!m.nonfinite);
    // The faulted message's frames as the TCU received them, judged by an independent checker.
    let mut checker = E2eChecker::all(E2eConfig::default(), Duration::ZERO);
    let mut last_valid = Duration::ZERO;
    let mut first_back = None;
    for (t, f) in &r.frames {
        if f.standard_id() == Some(id) {
            let ok = checker.check(*t, f.raw_id(), f.bytes()).is_ok();
            if ok && t.as_secs_f64() < FAULT_TO_S {
                last_valid = *t;
            }
            // After a gap the alive counter jumps: the first frame back counts as returned.
            if t.as_secs_f64() >= FAULT_TO_S && first_back.is_none() {
                first_back = Some(*t);
            }
        }
    }
    let status: Vec<(Duration, TcuStatus)> = tcu_frames(&r, ids::TCU_STATUS)
        .map(|(t, f)| (t, TcuStatus::decode(f.bytes()).unwrap()))
        .collect();
    let (detected, st) = *status
        .iter()
        .find(|(t, s)| *t > last_valid && s.fault_code != FaultCode::None)
        .expect("a fault code in TCU_Status");
    let safe_cmd = status
        .iter()
        .find(|(t, s)| *t >= detected && s.tcu_state == TcuState::SafeState)
        .expect("safe state")
        .0;
    let first_back = first_back.expect("the message came back");
    let recovered = status
        .iter()
        .find(|(t, s)| {
            *t >= first_back
                && s.fault_code == FaultCode::None
                && !matches!(s.tcu_state, TcuState::SafeState | TcuState::Init)
        })
        .expect("recovery")
        .0;
    // In the safe state: clutches opened at a controlled rate, the engine request released.
    let cmds: Vec<(Duration, TcuClutchCmd)> = tcu_frames(&r, ids::TCU_CLUTCH_CMD)
        .filter(|(t, _)| *t >= safe_cmd && *t < first_back)
        .map(|(t, f)| (t, TcuClutchCmd::decode(f.bytes()).unwrap()))
        .collect();
    let rate = tcu_config().safety.open_rate_mm_per_s;
    let pos = |c: &TcuClutchCmd| [c.clutch1_pos_req, c.clutch2_pos_req];
    for w in cmds.windows(2) {
        let dt = (w[1].0 - w[0].0).as_secs_f64();
        for i in 0..2 {
            let dx = pos(&w[1].1)[i] - pos(&w[0].1)[i];
            assert!(
                dx <= 1e-9,
                "clutch {}: opening only, {dx} mm at {:?}",
                i + 1,
                w[1].0
            );
            assert!(
                -dx <= rate * dt + 2e-3,
                "controlled rate: {dx} mm in {dt} s"
            );
        }
    }
    assert!(
        pos(&cmds.last().unwrap().1).iter().all(|&x| x < 1.0),
        "both open by the end"
    );
    for (t, f) in tcu_frames(&r, ids::TCU_ENGINE_REQ) {
        if t >= safe_cmd && t < first_back {
            assert!(
                !TcuEngineReq::decode(f.bytes())
                    .unwrap()
                    .eng_torque_req_active
            );
        }
    }
    SafetyTimes {
        last_valid,
        detected,
        fault: st.fault_code,
        safe_cmd,
        first_back,
        recovered,
    }
}

fn tcu_frames(r: &SimRun, id: u16) -> impl Iterator<Item = (Duration, &CanFrame)> + '_ {
    r.frames
        .iter()
        .filter(move |(_, f)| f.standard_id() == Some(id))
        .map(|(t, f)| (*t, f))
}

fn check_safety(id: u16, kind: InjectionKind, expected: FaultCode) {
    let s = safety_case(id, kind);
    let cycle = Duration::from_millis(10);
    let detect = s.detected - s.last_valid;
    // Detected within 3 cycles of the last valid frame (and not before: 3 cycles is the timeout).
    assert!(
        detect <= 3 * cycle && detect > 2 * cycle,
        "{kind:?}: detected {detect:?} after the last valid frame"
    );
    assert_eq!(s.fault, expected, "{kind:?}");
    // Safe state commanded in the same or the next TCU cycle.
    assert!(s.safe_cmd - s.detected <= cycle, "{kind:?}");
    // Normal operation within 100 ms of valid inputs coming back.
    let rec = s.recovered - s.first_back;
    assert!(
        rec <= Duration::from_millis(100),
        "{kind:?}: recovery {rec:?}"
    );
    eprintln!(
        "{kind:?} on {id:#x}: detected {:.0} ms after the last valid frame, safe state {:.0} ms \
         later, recovered {:.0} ms after valid frames returned",
        detect.as_secs_f64() * 1e3,
        (s.safe_cmd - s.detected).as_secs_f64() * 1e3,
        rec.as_secs_f64() * 1e3
    );
}

#[test]
fn eng_status_stopped_gives_a_timeout_safe_state_and_recovery() {
    check_safety(
        ids::ENG_STATUS,
        InjectionKind::Stop,
        FaultCode::EngStatusTimeout,
    );
}

#[test]
fn eng_status_crc_corrupted_gives_a_crc_fault() {
    check_safety(
        ids::ENG_STATUS,
        InjectionKind::CorruptCrc,
        FaultCode::EngStatusCrc,
    );
}

#[test]
fn eng_status_counter_frozen_gives_a_counter_fault() {
    check_safety(
        ids::ENG_STATUS,
        InjectionKind::FreezeCounter,
        FaultCode::EngStatusCounter,
    );
}

/// A corrupted DCT_Sensors frame triggers no computation (a garbage flood on that id must not
/// drive the TCU), so the core runs on its own deadline and still flags it within 3 cycles.
#[test]
fn sensors_crc_corrupted_gives_a_crc_fault_on_the_fallback_deadline() {
    check_safety(
        ids::DCT_SENSORS,
        InjectionKind::CorruptCrc,
        FaultCode::SensorsCrc,
    );
}

#[test]
fn sensors_stopped_still_run_the_tcu_on_its_fallback_deadline() {
    check_safety(
        ids::DCT_SENSORS,
        InjectionKind::Stop,
        FaultCode::SensorsTimeout,
    );
}

// ---------------------------------------------------------------------------------------------
// The daemon, in real time on the in-process bus.

/// The TCU daemon with the plant daemon on the in-process bus: it computes on each DCT_Sensors
/// frame, launches, and when the plant stops its fallback deadline keeps it running and it goes
/// to the safe state with a timeout fault.
#[tokio::test]
async fn daemon_launches_with_the_plant_and_detects_its_silence() {
    use ddct::can::{EndpointConfig, InProcessBus};
    use ddct::daemon::plant::{run as run_plant, Pacing, PlantDaemonConfig};
    use ddct::daemon::tcu::{run as run_tcu, TcuDaemonConfig};
    let sc = scenario("launch_50");
    let bus = InProcessBus::new("sim");
    let plant_ep = bus.endpoint(EndpointConfig::default());
    let tcu_ep = bus.endpoint(EndpointConfig::default());
    let plant_cfg = PlantDaemonConfig {
        plant: sc.plant.clone(),
        pacing: Pacing::RealTime { speed: 1.0 },
        duration: Some(Duration::from_millis(3000)),
        log: None,
        lockstep: None,
    };
    let tcu_cfg = TcuDaemonConfig {
        tcu: tcu_config(),
        duration: Some(Duration::from_millis(3300)),
        log: None,
        clock: Default::default(),
        diag: None,
    };
    let (p, t) = tokio::join!(
        run_plant(plant_ep, std::future::pending::<()>(), plant_cfg),
        run_tcu(tcu_ep, std::future::pending::<()>(), tcu_cfg)
    );
    let (p, t) = (p.unwrap(), t.unwrap());
    eprintln!("{}{}", p.summary(), t.summary());
    assert_eq!(t.stopped_by, "duration");
    // Every plant cycle's DCT_Sensors was handled: it triggered a computation, or it came within
    // half a cycle of one (a late fallback step on a loaded machine) and was coalesced into it.
    // None is lost; most trigger their own (generous bound: a loaded CI host coalesced 54).
    assert!(
        t.sync_computations + t.syncs_coalesced >= 290,
        "a sensors frame neither computed on nor coalesced: {t:?}"
    );
    assert!(t.sync_computations >= 150, "{t:?}");
    assert!(
        t.fallback_computations >= 20,
        "the 300 ms after the plant stopped: {t:?}"
    );
    assert_eq!(t.send_errors, 0);
    // The plant stopped first: the TCU ends in the safe state with a timeout fault.
    assert_eq!(t.final_state, TcuState::SafeState);
    assert!(
        matches!(
            t.final_fault,
            FaultCode::EngStatusTimeout | FaultCode::SensorsTimeout | FaultCode::ActuatorsTimeout
        ),
        "{:?}",
        t.final_fault
    );
    // It launched: the plant accepted its commands throughout.
    assert!(
        p.plant
            .rx_accepted
            .get("TCU_ClutchCmd")
            .copied()
            .unwrap_or(0)
            >= 250
    );
}

// ---------------------------------------------------------------------------------------------
// Plausibility, over-temperature and garbage, through the plant's own fault injection.

fn inline(text: &str) -> (SimRun, Metrics) {
    let sc = SimScenario::from_toml_str(std::path::Path::new("inline.toml"), text)
        .unwrap_or_else(|e| panic!("{e}"));
    let cfg = tcu_config();
    let r = sim::run_scenario(&sc, &cfg, &SimOptions::default());
    let m = metrics::compute(&r.rows, &cfg);
    (r, m)
}

const LAUNCH_DRIVER: &str = r#"
duration_s = 6.0
[driver]
t_s       = [0.0, 0.5, 1.0, 1.0, 6.0]
pedal_pct = [0.0, 0.0, 0.0, 40.0, 40.0]
brake     = [1.0, 1.0, 1.0, 0.0, 0.0]
lever     = ["N", "D", "D", "D", "D"]
"#;

fn first_fault(r: &SimRun, after_s: f64) -> Option<(f64, FaultCode, TcuState)> {
    r.rows
        .iter()
        .find(|x| x.t_s >= after_s && x.fault != FaultCode::None)
        .map(|x| (x.t_s, x.fault, x.state))
}

#[test]
fn implausible_values_give_their_fault_codes_and_the_safe_state() {
    for (signal, message, value, expected) in [
        (
            "HousingTemp",
            "DCT_Sensors",
            200.0,
            FaultCode::ImplausibleTemp,
        ),
        (
            "EngSpeed",
            "ENG_Status",
            9500.0,
            FaultCode::ImplausibleSpeed,
        ),
        (
            "Clutch1Pos",
            "DCT_Actuators",
            12.0,
            FaultCode::ImplausiblePosition,
        ),
    ] {
        let text = format!(
            "{LAUNCH_DRIVER}\n[[faults]]\nmessage = \"{message}\"\nkind = \"implausible\"\n\
             signal = \"{signal}\"\nvalue = {value}\nfrom_s = 4.0\nto_s = 4.5\n"
        );
        let (r, m) = inline(&text);
        assert!(!m.nonfinite);
        let (t, code, state) = first_fault(&r, 3.9).unwrap_or_else(|| panic!("{signal}: no fault"));
        assert_eq!(code, expected, "{signal}");
        assert_eq!(state, TcuState::SafeState, "{signal}");
        // The first implausible frame is at 4.0 s; the last valid one 10 ms before: detected
        // within 3 cycles of it.
        assert!(t <= 3.99 + 0.031, "{signal}: detected at {t}");
        // Back to normal once the values are plausible again.
        let back = r
            .rows
            .iter()
            .find(|x| x.t_s >= 4.5 && x.fault == FaultCode::None && x.state != TcuState::SafeState)
            .map(|x| x.t_s);
        assert!(
            back.is_some_and(|b| b <= 4.6),
            "{signal}: recovered at {back:?}"
        );
    }
}

#[test]
fn over_temperature_warns_then_limits_the_torque() {
    let cfg = tcu_config();
    let (warn, limit) = (cfg.safety.over_temp_warn_c, cfg.safety.over_temp_limit_c);
    // Between the thresholds: a warning, nothing else changes.
    let t_warn = 0.5 * (warn + limit);
    let text = format!(
        "{LAUNCH_DRIVER}\n[initial]\ntemperature_c = {t_warn}\n[tcu]\ninitial_temp_c = {t_warn}\n"
    );
    let (r, m) = inline(&text);
    assert!(r
        .rows
        .iter()
        .any(|x| x.fault == FaultCode::ClutchOverTempWarning));
    assert!(m.launches[0].lockup_s.is_some());
    // Above the limit: the engine torque request is capped and the fault code says so.
    let t_lim = limit + 10.0;
    let text = format!(
        "{LAUNCH_DRIVER}\n[initial]\ntemperature_c = {t_lim}\n[tcu]\ninitial_temp_c = {t_lim}\n"
    );
    let (r, m) = inline(&text);
    let launching: Vec<_> = r
        .rows
        .iter()
        .filter(|x| x.state == TcuState::Launch)
        .collect();
    assert!(!launching.is_empty());
    assert!(launching
        .iter()
        .all(|x| x.fault == FaultCode::ClutchOverTempLimit));
    let cap = cfg.safety.over_temp_engine_torque_nm;
    assert!(
        launching
            .iter()
            .all(|x| x.eng_req_nm.is_none_or(|t| t <= cap + 0.05)),
        "engine request above {cap} N·m"
    );
    assert!(
        m.launches[0].lockup_s.is_some(),
        "it still launches: {:?}",
        m.launches[0]
    );
}

/// Garbage on every input id (random payloads, wrong lengths) never panics the core and never
/// puts a non-finite or out-of-range value on the bus.
#[test]
fn garbage_frames_never_panic_or_leak_nan() {
    use ddct::can::messages::{TcuEstimates, TcuGearCmd};
    use ddct::tcu::{Tcu, TcuInputs, TimedFrame};
    let mut tcu = Tcu::new(tcu_config(), Duration::ZERO);
    let mut seed: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut rnd = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    let inputs = [
        ids::ENG_STATUS,
        ids::DRV_PEDAL,
        ids::DCT_SENSORS,
        ids::DCT_ACTUATORS,
    ];
    for k in 0..2000u32 {
        let now = Duration::from_millis(10) * k;
        let mut frames = Vec::new();
        for &id in &inputs {
            let len = (rnd() % 9) as usize;
            let bytes = rnd().to_le_bytes();
            frames.push(TimedFrame {
                at: now,
                frame: CanFrame::standard(id, &bytes[..len]).unwrap(),
            });
        }
        let out = tcu.step(now, &TcuInputs { frames: &frames });
        assert_eq!(out.frames.len(), 5);
        for f in &out.frames {
            match f.standard_id().unwrap() {
                ids::TCU_CLUTCH_CMD => {
                    let c = TcuClutchCmd::decode(f.bytes()).unwrap();
                    assert!(c.clutch1_pos_req.is_finite() && c.clutch2_pos_req.is_finite());
                }
                ids::TCU_ENGINE_REQ => {
                    assert!(TcuEngineReq::decode(f.bytes())
                        .unwrap()
                        .eng_torque_req
                        .is_finite())
                }
                ids::TCU_GEAR_CMD => {
                    TcuGearCmd::decode(f.bytes()).unwrap();
                }
                ids::TCU_STATUS => {
                    let s = TcuStatus::decode(f.bytes()).unwrap();
                    if k > 3 {
                        assert!(matches!(s.tcu_state, TcuState::Init | TcuState::SafeState));
                    }
                }
                ids::TCU_ESTIMATES => {
                    TcuEstimates::decode(f.bytes()).unwrap();
                }
                other => panic!("unexpected id {other:#x}"),
            }
        }
    }
}

/// The InternalNonFinite path end to end. A configuration file cannot carry a non-finite value
/// any more (the config fuzz shows every key refused), so the corruption is made where nothing
/// checks it — a heating coefficient of the TCU's thermal model set to NaN in memory after
/// loading, as a corrupted RAM cell or a model singularity would. Expected (docs/tcu.md): the
/// TCU_Status frames on the bus carry FaultCode InternalNonFinite, the clutch commands stay
/// finite (the last finite one held) and no non-finite value reaches the bus.
#[test]
fn a_non_finite_internal_value_gives_internal_non_finite_on_the_bus() {
    use ddct::can::messages::TcuEstimates;
    let sc = SimScenario::from_toml_str(std::path::Path::new("inline.toml"), LAUNCH_DRIVER)
        .unwrap_or_else(|e| panic!("{e}"));
    let mut cfg = tcu_config();
    cfg.physics.thermal3.alpha3_k_per_j = f64::NAN;
    let r = sim::run_scenario(&sc, &cfg, &SimOptions::default());
    let mut codes = std::collections::BTreeMap::new();
    for (_, f) in tcu_frames(&r, ids::TCU_STATUS) {
        *codes
            .entry(format!(
                "{:?}",
                TcuStatus::decode(f.bytes()).unwrap().fault_code
            ))
            .or_insert(0usize) += 1;
    }
    // From the third cycle on (the first frames precede the first estimator update and the
    // inputs' arrival) every status frame says so, in the safe state.
    let late: Vec<TcuStatus> = tcu_frames(&r, ids::TCU_STATUS)
        .filter(|(t, _)| *t >= Duration::from_millis(30))
        .map(|(_, f)| TcuStatus::decode(f.bytes()).unwrap())
        .collect();
    assert!(late.len() > 500, "{} status frames", late.len());
    assert!(
        late.iter()
            .all(|s| s.fault_code == FaultCode::InternalNonFinite
                && s.tcu_state == TcuState::SafeState),
        "status codes on the bus: {codes:?}"
    );
    for (t, f) in tcu_frames(&r, ids::TCU_CLUTCH_CMD) {
        let c = TcuClutchCmd::decode(f.bytes()).unwrap();
        assert!(
            c.clutch1_pos_req.is_finite() && c.clutch2_pos_req.is_finite(),
            "{t:?}: {c:?}"
        );
    }
    for (t, f) in tcu_frames(&r, ids::TCU_ESTIMATES) {
        let e = TcuEstimates::decode(f.bytes()).unwrap();
        assert!(format!("{e:?}").find("NaN").is_none(), "{t:?}: {e:?}");
    }
    println!("status codes on the bus: {codes:?}");
}

/// The plant's multi-rate integration (a quiet cycle in one RK4 step of 10 ms, `plant::core`'s
/// `quiet`) in closed loop against the fixed 1 ms RK4 reference, on the bench's default run and
/// the 60 s drive cycle: the same launches and shifts (gears, completed), lock-up times within one
/// cycle, shift durations within three, the scenario's verdict the same, and most cycles taken in
/// one step. The loop's own sensitivity sets these bounds: the TCU decides on thresholds once per
/// cycle, so a difference far below a sensor's resolution moves a decision by a cycle — the fixed
/// reference itself, with the vehicle 10 ppm (15 g) heavier or lighter, moves the shift durations
/// of drive_60s by 20 ms and a clutch torque on the same row by a quarter of its peak
/// (`a_10_ppm_heavier_vehicle_moves_the_closed_loop_by_a_cycle`). The integrator's accuracy on the
/// same commands (lock-ups and shifts within one cycle, peak torques within 0.5 %) is asserted
/// open loop by `multirate_plant_follows_the_fixed_1ms_reference_on_the_same_commands`.
#[test]
fn multirate_integration_keeps_the_closed_loop_of_the_fixed_1ms_reference() {
    use ddct::plant::{Plant, StepPolicy};
    use ddct::sim::verdict;
    use ddct::tcu::Tcu;
    const CYCLE_S: f64 = 0.010 + 1e-9;
    for name in ["launch_shift_20s", "drive_60s"] {
        let sc = scenario(name);
        let run = |step: StepPolicy| {
            let mut cfg = tcu_config();
            sc.tcu.apply(&mut cfg);
            let mut plant = Plant::new(ddct::plant::PlantConfig {
                step,
                ..sc.plant.clone()
            });
            let mut tcu = Tcu::new(cfg, Duration::ZERO);
            let d = Duration::from_secs_f64(sc.duration_s);
            let t = sim::run_with(&mut plant, &mut tcu, d, &SimOptions::default());
            (t.metrics, plant.stats().clone())
        };
        let (rm, fixed_stats) = run(StepPolicy::Fixed);
        let (mm, multi_stats) = run(StepPolicy::Multirate);
        assert!(
            !rm.launches.is_empty() && rm.launches.len() == mm.launches.len(),
            "{name}"
        );
        for (r, m) in rm.launches.iter().zip(&mm.launches) {
            let (lr, lm) = (r.lockup_s.unwrap(), m.lockup_s.unwrap());
            assert!(
                (lr - lm).abs() <= CYCLE_S,
                "{name}: lock-up {lm} s against {lr} s"
            );
        }
        assert!(
            !rm.shifts.is_empty() && rm.shifts.len() == mm.shifts.len(),
            "{name}"
        );
        for (r, m) in rm.shifts.iter().zip(&mm.shifts) {
            assert_eq!(
                (r.from, r.to, r.completed),
                (m.from, m.to, m.completed),
                "{name}"
            );
            let dd = (r.duration_s - m.duration_s).abs();
            assert!(
                dd <= 3.0 * CYCLE_S,
                "{name}: shift at {} s lasts {} against {} s",
                r.t_start_s,
                m.duration_s,
                r.duration_s
            );
        }
        let verdict = |m| verdict::passed(&verdict::judge(sc.limits.as_ref(), m, None));
        assert!(
            verdict(&rm) && verdict(&mm),
            "{name}: the scenario's limits"
        );
        assert_eq!(fixed_stats.quiet_cycles, 0);
        assert_eq!(
            fixed_stats.steps, multi_stats.steps,
            "{name}: the same simulated time"
        );
        let cycles = multi_stats.cycles as f64;
        assert!(
            multi_stats.quiet_cycles as f64 >= 0.5 * cycles,
            "{name}: {} of {cycles} cycles in one step",
            multi_stats.quiet_cycles
        );
    }
}

/// What the plant did, sampled at its cycles: lock and gear-engagement events (time, clutch or
/// shaft, new value) and the clutch torques.
#[derive(Default)]
struct PlantPath {
    locks: Vec<(f64, usize, bool)>,
    gears: Vec<(f64, usize, Gear)>,
    torque: Vec<(f64, [f64; 2])>,
}

/// Plays the TCU's frames of a recorded run (`frames`, each at the time the TCU sent it) into a
/// plant with `cfg`, delivered as the lockstep runner delivers them, and records its path.
fn open_loop(
    cfg: ddct::plant::PlantConfig,
    frames: &[(Duration, CanFrame)],
    duration: Duration,
) -> (PlantPath, ddct::plant::PlantStats) {
    use ddct::can::Received;
    let mut plant = ddct::plant::Plant::new(cfg);
    let own: Vec<u16> = plant.sent_ids().to_vec();
    let tcu: Vec<(Duration, CanFrame)> = frames
        .iter()
        .filter(|(_, f)| f.standard_id().is_some_and(|id| !own.contains(&id)))
        .copied()
        .collect();
    let cycle = Duration::from_millis(10);
    let (mut path, mut k, mut t) = (PlantPath::default(), 0, Duration::ZERO);
    let mut last: Option<ddct::plant::Truth> = None;
    while t <= duration {
        // The frames the TCU sent before this cycle (the runner hands them over at its next
        // plant call).
        let mut rx = Vec::new();
        while k < tcu.len() && tcu[k].0 < t {
            rx.push(Received {
                frame: tcu[k].1,
                timestamp: tcu[k].0,
            });
            k += 1;
        }
        let tr = plant.step(t, &rx).truth;
        let s = &tr.state;
        if let Some(p) = last {
            for (i, (a, b)) in [(p.state.lock1, s.lock1), (p.state.lock2, s.lock2)]
                .into_iter()
                .enumerate()
            {
                if a != b {
                    path.locks.push((tr.t_s, i, b));
                }
            }
            let g = [
                (p.state.gear_odd.engaged, s.gear_odd.engaged),
                (p.state.gear_even.engaged, s.gear_even.engaged),
            ];
            for (i, (a, b)) in g.into_iter().enumerate() {
                if a != b {
                    path.gears.push((tr.t_s, i, b));
                }
            }
        }
        path.torque
            .push((tr.t_s, [tr.outputs.t_fc1_nm, tr.outputs.t_fc2_nm]));
        last = Some(tr);
        t += cycle;
    }
    (path, plant.stats().clone())
}

/// The integrator's accuracy without the loop: the TCU's commands of a fixed-step closed-loop
/// run played into a fixed-step plant and a multi-rate one. Every lock-up, break-away and gear
/// engagement the same and within one 10 ms cycle, the peak clutch torque of every slipping phase
/// within 0.5 % (issue 14); and most cycles taken in one step.
#[test]
fn multirate_plant_follows_the_fixed_1ms_reference_on_the_same_commands() {
    use ddct::plant::StepPolicy;
    for name in ["launch_shift_20s", "drive_60s"] {
        let sc = scenario(name);
        let mut fixed_sc = sc.clone();
        fixed_sc.plant.step = StepPolicy::Fixed;
        let rec = sim::run_scenario(&fixed_sc, &tcu_config(), &SimOptions::default());
        let d = Duration::from_secs_f64(sc.duration_s);
        let cfg = |step| ddct::plant::PlantConfig {
            step,
            ..sc.plant.clone()
        };
        let (reference, _) = open_loop(cfg(StepPolicy::Fixed), &rec.frames, d);
        let (multi, stats) = open_loop(cfg(StepPolicy::Multirate), &rec.frames, d);
        const CYCLE_S: f64 = 0.010 + 1e-9;
        assert!(reference.locks.len() >= 6, "{name}: {:?}", reference.locks);
        assert_eq!(
            reference.locks.len(),
            multi.locks.len(),
            "{name}: {:?}\n{:?}",
            reference.locks,
            multi.locks
        );
        for (r, m) in reference.locks.iter().zip(&multi.locks) {
            assert!(
                r.1 == m.1 && r.2 == m.2 && (r.0 - m.0).abs() <= CYCLE_S,
                "{name}: lock {m:?} against {r:?}"
            );
        }
        assert!(reference.gears.len() >= 4, "{name}: {:?}", reference.gears);
        assert_eq!(reference.gears.len(), multi.gears.len(), "{name}");
        for (r, m) in reference.gears.iter().zip(&multi.gears) {
            assert!(
                r.1 == m.1 && r.2 == m.2 && (r.0 - m.0).abs() <= CYCLE_S,
                "{name}: gear {m:?} against {r:?}"
            );
        }
        // Slipping phases of the reference: from a break-away (or the start) to the lock-up.
        let mut worst: f64 = 0.0;
        for i in 0..2 {
            let mut from = 0.0;
            for &(t, c, locked) in &reference.locks {
                if c != i {
                    continue;
                }
                if !locked {
                    from = t;
                    continue;
                }
                let peak = |p: &PlantPath| {
                    p.torque
                        .iter()
                        .filter(|(ts, _)| *ts >= from - CYCLE_S && *ts <= t + CYCLE_S)
                        .map(|(_, tq)| tq[i].abs())
                        .fold(0.0, f64::max)
                };
                let (pr, pm) = (peak(&reference), peak(&multi));
                let rel = (pm - pr).abs() / pr.max(1.0);
                worst = worst.max(rel);
                assert!(
                    rel <= 0.005,
                    "{name}: clutch {} slipping {from}..{t} s: peak {pm} against {pr} N·m",
                    i + 1
                );
            }
        }
        let cycles = stats.cycles as f64;
        assert!(
            stats.quiet_cycles as f64 >= 0.5 * cycles,
            "{name}: {} of {cycles}",
            stats.quiet_cycles
        );
        eprintln!(
            "{name}: {} lock events, {} gear engagements, worst peak torque {:.3} %, {} of {cycles} cycles in one step",
            reference.locks.len(),
            reference.gears.len(),
            100.0 * worst,
            stats.quiet_cycles
        );
    }
}

/// The premise of the closed-loop bounds above: the fixed-step reference itself, with the
/// vehicle 10 ppm heavier and 10 ppm lighter, moves a shift of drive_60s by more than one cycle
/// or a peak clutch torque by more than 0.5 % — the loop's decisions on thresholds, not the
/// integrator, set how closely two closed-loop runs can agree.
#[test]
fn a_10_ppm_heavier_vehicle_moves_the_closed_loop_by_a_cycle() {
    use ddct::plant::StepPolicy;
    let sc = scenario("drive_60s");
    let run = |scale: f64| {
        let mut s = sc.clone();
        s.plant.step = StepPolicy::Fixed;
        s.plant.params.driveline.vehicle_mass_kg *= scale;
        sim::run_scenario(&s, &tcu_config(), &SimOptions::default())
    };
    let nominal = run(1.0);
    let mut moved = Vec::new();
    for scale in [1.0 + 1e-5, 1.0 - 1e-5] {
        let other = run(scale);
        let (a, b) = (&nominal.metrics.shifts, &other.metrics.shifts);
        assert_eq!(a.len(), b.len());
        let dd = a
            .iter()
            .zip(b)
            .map(|(x, y)| (x.duration_s - y.duration_s).abs())
            .fold(0.0, f64::max);
        let peak = |r: &SimRun, i: usize| {
            r.rows
                .iter()
                .map(|w| w.t_act_nm[i].abs())
                .collect::<Vec<_>>()
        };
        // Largest change of the clutch torque on the same row, relative to its peak.
        let dt = (0..2)
            .map(|i| {
                let (p, q) = (peak(&nominal, i), peak(&other, i));
                let top = p.iter().copied().fold(1.0, f64::max);
                p.iter()
                    .zip(&q)
                    .map(|(x, y)| (x - y).abs())
                    .fold(0.0, f64::max)
                    / top
            })
            .fold(0.0, f64::max);
        eprintln!("vehicle mass x{scale}: shift durations moved up to {dd:.3} s, torque by {:.1} % of its peak", 100.0 * dt);
        moved.push(dd > 0.010 + 1e-9 || dt > 0.005);
    }
    assert!(
        moved.iter().any(|&m| m),
        "a 10 ppm change left the closed loop within the bounds"
    );
}

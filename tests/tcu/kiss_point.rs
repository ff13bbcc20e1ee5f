//! (in the `tcu` test binary) The kiss-point adaptation routine (issue 16, UDS RoutineControl 0x0201) in closed loop with
//! the plant core (`ddct sim`'s lockstep runner, simulated time).
//!
//! The expectation is the plant's own kiss point x_ISP(θ_c) of (9), from the plant's parameters
//! and its true clutch temperature at the end of the run — never the TCU's model: with the plant's
//! λ0 shifted the learned value must follow the plant, away from the TCU model's x_ISP(θ̂).

use ddct::model::clutch;
use ddct::model::gear::Gear;
use ddct::plant::Plant;
use ddct::sim::{self, Row, SimOptions, SimScenario};
use ddct::tcu::routine::{AbortReason, Condition, RoutineRefusal, RoutineState};
use ddct::tcu::{Tcu, TcuConfig};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The error allowed against the plant's kiss point (mm).
const TOLERANCE_MM: f64 = 0.05;

fn tcu_config() -> TcuConfig {
    TcuConfig::load(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("config/tcu.toml")).unwrap()
}

/// A standstill scenario of `duration_s` with the lever held at `lever`, the brake on, engine at
/// idle (the plant's default sensor noise and quantisation).
fn standstill(lever: &str, duration_s: f64) -> SimScenario {
    scenario(lever, 1.0, duration_s)
}

/// The driver holds `lever` and the brake at `brake` (0..1), pedal released.
fn scenario(lever: &str, brake: f64, duration_s: f64) -> SimScenario {
    let text = format!(
        r#"
description = "standstill, lever {lever}"
duration_s = {duration_s}
[driver]
t_s       = [0.0, {duration_s}]
pedal_pct = [0.0, 0.0]
brake     = [{brake}, {brake}]
lever     = ["{lever}", "{lever}"]
"#
    );
    SimScenario::from_toml_str(Path::new("kiss.toml"), &text).unwrap_or_else(|e| panic!("{e}"))
}

/// What a run gives: the routine's state, the learned kiss points, the plant's true kiss point
/// per clutch at the end (x_ISP(θ_c) of (9) with the plant's parameters), the model's, the rows.
struct Outcome {
    state: RoutineState,
    learned: [Option<f64>; 2],
    plant_kiss: [f64; 2],
    model_kiss: [f64; 2],
    start: Started,
    rows: Vec<Row>,
}

/// A start's result, when the tester started the routine in that step.
type Started = Option<Result<(), RoutineRefusal>>;

/// Runs `sc` with the plant's λ0 shifted by `shift_mm`; `act(t, tcu)` is called before each
/// TCU step (`Some(result)` of a start is kept).
fn run(sc: &SimScenario, shift_mm: f64, act: &mut dyn FnMut(f64, &mut Tcu) -> Started) -> Outcome {
    let mut plant_cfg = sc.plant.clone();
    plant_cfg.params.clutch.x_isp0_mm += shift_mm;
    let mut plant = Plant::new(plant_cfg.clone());
    let mut tcu = Tcu::new(tcu_config(), Duration::ZERO);
    let mut start = None;
    let trace = sim::run_with_hook(
        &mut plant,
        &mut tcu,
        Duration::from_secs_f64(sc.duration_s),
        &SimOptions::default(),
        &mut |t, tcu| {
            if let Some(r) = act(t.as_secs_f64(), tcu) {
                start = Some(r);
            }
        },
    );
    // The plant's true clutch temperatures (SIM_Truth, 0.1 °C) in the routine's last cycle (a
    // hot clutch cools while the routine runs), else at the end.
    let th = plant.state().thermal;
    let theta = trace
        .rows
        .iter()
        .rev()
        .find(|r| r.phase.starts_with("kiss"))
        .map_or([th.c1, th.c2], |r| r.theta_true_c);
    let p = &plant_cfg.params.clutch;
    Outcome {
        state: tcu.kiss_point_routine(),
        learned: tcu.learned_kiss_points(),
        plant_kiss: theta.map(|t| clutch::x_isp(p, t)),
        model_kiss: tcu.kiss_points(),
        start,
        rows: trace.rows,
    }
}

/// Starts the routine for `clutch` once, at `at_s`.
fn start_at(
    clutch: usize,
    at_s: f64,
) -> impl FnMut(f64, &mut Tcu) -> Option<Result<(), RoutineRefusal>> {
    let mut done = false;
    move |t, tcu| {
        if !done && t >= at_s {
            done = true;
            Some(tcu.start_kiss_point_routine(clutch))
        } else {
            None
        }
    }
}

/// Learns `clutch`'s kiss point with the plant's λ0 shifted by `shift_mm`; returns the error
/// against the plant (mm) and the learned value's distance to the TCU model's kiss point.
fn learn(clutch: usize, shift_mm: f64, lever: &str) -> (f64, f64) {
    learn_in(&standstill(lever, 35.0), clutch, shift_mm, lever)
}

/// [`learn`] in the scenario `sc` (lever `lever`).
fn learn_in(sc: &SimScenario, clutch: usize, shift_mm: f64, lever: &str) -> (f64, f64) {
    let out = run(sc, shift_mm, &mut start_at(clutch, 2.0));
    assert_eq!(out.start, Some(Ok(())), "start refused");
    let RoutineState::Done { clutch: c, kiss_mm } = out.state else {
        panic!("clutch {clutch}, shift {shift_mm}: {:?}", out.state);
    };
    assert_eq!(c, clutch);
    assert_eq!(out.learned[clutch], Some(kiss_mm));
    assert_eq!(out.learned[1 - clutch], None);
    let err = kiss_mm - out.plant_kiss[clutch];
    let busy: Vec<f64> = out
        .rows
        .iter()
        .filter(|r| r.phase.starts_with("kiss"))
        .map(|r| r.t_s)
        .collect();
    let took = busy.last().unwrap() - busy.first().unwrap();
    // For comparison: the measured position at the detection, without the onset fit.
    let at_detection = out
        .rows
        .iter()
        .rev()
        .find(|r| r.phase.starts_with("kiss"))
        .map_or(f64::NAN, |r| r.x_mm[clutch] - out.plant_kiss[clutch]);
    eprintln!(
        "clutch {clutch} lever {lever} λ0 shift {shift_mm:+.2} mm: learned {kiss_mm:.4} mm, \
         plant {:.4} mm, model {:.4} mm, error {err:+.4} mm (uncorrected position at the \
         detection {at_detection:+.4} mm), routine {took:.1} s",
        out.plant_kiss[clutch], out.model_kiss[clutch]
    );
    assert!(took <= out_cfg_timeout(), "took {took} s");
    // Afterwards the strategy is back in Neutral with both gears preselected again and both
    // clutches open.
    let last = out.rows.last().unwrap();
    assert_eq!(last.phase, "neutral");
    assert_eq!(last.gear_act, [Gear::G1, Gear::G2], "gears re-engaged");
    assert!(
        last.x_mm
            .iter()
            .all(|&x| x < out.plant_kiss[0].min(out.plant_kiss[1])),
        "clutches open: {:?}",
        last.x_mm
    );
    (err, kiss_mm - out.model_kiss[clutch])
}

/// The routine's timeout of the calibration (s).
fn out_cfg_timeout() -> f64 {
    tcu_config().kiss_routine.timeout_s
}

#[test]
fn learns_both_kiss_points_of_the_nominal_plant() {
    for (clutch, lever) in [(0, "N"), (1, "P")] {
        let (err, _) = learn(clutch, 0.0, lever);
        assert!(err.abs() <= TOLERANCE_MM, "clutch {clutch}: error {err} mm");
    }
}

/// The plant's λ0 of (9) shifted, which the TCU's model does not know: the learned value follows
/// the plant, not the model.
#[test]
fn learns_a_kiss_point_the_model_does_not_have() {
    for (clutch, shift) in [(0, 0.3), (1, -0.2)] {
        let (err, off_model) = learn(clutch, shift, "N");
        assert!(err.abs() <= TOLERANCE_MM, "clutch {clutch}: error {err} mm");
        assert!(
            (off_model - shift).abs() <= TOLERANCE_MM,
            "clutch {clutch}: {off_model} mm from the model, the plant is {shift} mm away"
        );
    }
}

/// A hot plant (120 °C clutches, x_ISP of (9) about 0.27 mm before its room-temperature value)
/// with the TCU's estimator starting from its own initial temperature: the learned value follows
/// the plant's temperature-dependent kiss point.
#[test]
fn learns_a_hot_clutch_kiss_point() {
    let mut sc = standstill("N", 35.0);
    sc.plant.initial.temperature_c = 120.0;
    let (err, _) = learn_in(&sc, 0, 0.0, "N");
    assert!(err.abs() <= TOLERANCE_MM, "error {err} mm");
}

#[test]
fn refuses_a_moving_vehicle_the_lever_in_d_and_a_stopped_engine() {
    // Lever in D, at standstill.
    let out = run(&standstill("D", 3.0), 0.0, &mut start_at(0, 2.0));
    assert_eq!(
        out.start,
        Some(Err(RoutineRefusal::Condition(
            Condition::LeverNotParkOrNeutral
        )))
    );
    // Rolling at 20 km/h in N, brake released.
    let mut sc = scenario("N", 0.0, 3.0);
    sc.plant.initial.vehicle_kmh = 20.0;
    sc.plant.initial.gear_odd = Gear::G1;
    let out = run(&sc, 0.0, &mut start_at(0, 1.0));
    assert_eq!(
        out.start,
        Some(Err(RoutineRefusal::Condition(Condition::NotAtStandstill)))
    );
    // Engine off.
    let mut sc = standstill("N", 3.0);
    sc.plant.initial.engine_rpm = 0.0;
    let out = run(&sc, 0.0, &mut start_at(1, 2.0));
    assert_eq!(
        out.start,
        Some(Err(RoutineRefusal::Condition(Condition::EngineNotRunning)))
    );
    assert_eq!(out.state, RoutineState::Idle);
}

/// Stopped by the tester in the middle of the ramp: aborted with that reason, nothing learned,
/// the clutch reopened and the gear re-engaged by the strategy.
#[test]
fn a_stop_aborts_and_reopens() {
    let mut start = start_at(0, 2.0);
    let mut act = |t: f64, tcu: &mut Tcu| {
        if t >= 8.0 && matches!(tcu.kiss_point_routine(), RoutineState::Running { .. }) {
            tcu.stop_kiss_point_routine();
        }
        start(t, tcu)
    };
    let out = run(&standstill("N", 11.0), 0.0, &mut act);
    assert_eq!(out.start, Some(Ok(())));
    assert_eq!(
        out.state,
        RoutineState::Aborted {
            clutch: 0,
            reason: AbortReason::StoppedByTester
        }
    );
    assert_eq!(out.learned, [None, None]);
    let at_stop = out.rows.iter().rev().find(|r| r.t_s < 8.0).unwrap();
    assert_eq!(at_stop.phase, "kiss_ramp", "stopped in the ramp");
    let last = out.rows.last().unwrap();
    assert_eq!(last.phase, "neutral");
    assert!(last.x_mm[0] < out.plant_kiss[0] - 0.1, "{:?}", last.x_mm);
    assert_eq!(last.gear_act[0], Gear::G1);
}

//! A run's verdict: the pass/fail limits of a scenario (`[limits]`) checked against the metrics
//! of the run (`super::metrics`, the same definitions for `ddct sim` and a bench's bus log), and
//! on a bench the TCU's reaction latency over the bare frame echo. `ddct sim` and `ddct bench`
//! print the checks as a PASS/FAIL table, exit with status 1 when one fails and write them as
//! JUnit XML with `--junit`.
//!
//! ```toml
//! [limits]
//! launches_min = 1                 # launches seen at least
//! lockup_s_max = 2.5               # every launch locks up within (s from its start)
//! flare_rpm_max = 400              # engine speed over the launch target n(p) before lock-up
//! spike_mps2_max = 1.0             # lock-up acceleration spike
//! torque_error_300ms_nm_max = 60   # peak |T_ref − T_actual| in a launch's first 300 ms
//! shifts_complete = true           # every shift ends in Drive (default true)
//! no_stall = true                  # no launch stalls the engine (default true)
//! estimator_rmse_c_max = 5.0       # estimated clutch temperatures vs SIM_Truth
//! faults_allowed = ["PedalTimeout"]  # fault codes that may appear (default: none)
//! latency_ratio_max = 20.0         # bench: TCU reaction p99 over the echo's p99
//! ```
//!
//! Without a `[limits]` table only the invariant holds: no non-finite value on the bus. On a
//! bench, fault codes after the plant's last frame (the TCU's ENG_Status timeout when the plant
//! stops first) end the run and are not judged.

use super::metrics::{EstimatorMetrics, LaunchMetrics, Metrics, ShiftMetrics, StatusEvent};
use crate::can::messages::FaultCode;
use serde::{Deserialize, Serialize};

/// Pass/fail limits of a scenario.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    pub launches_min: Option<usize>,
    pub lockup_s_max: Option<f64>,
    pub flare_rpm_max: Option<f64>,
    pub spike_mps2_max: Option<f64>,
    pub torque_error_300ms_nm_max: Option<f64>,
    pub shifts_complete: Option<bool>,
    pub no_stall: Option<bool>,
    pub estimator_rmse_c_max: Option<f64>,
    #[serde(default)]
    pub faults_allowed: Vec<FaultCode>,
    pub latency_ratio_max: Option<f64>,
}

// Every numeric limit is positive (`f64::MIN_POSITIVE`: 0 excluded) and at most the largest
// value that still means something (`crate::ranges`).
crate::ranges!(Limits as _l, "limits" {
    launches_min: [1.0, 1e6],
    lockup_s_max: [f64::MIN_POSITIVE, 3600.0],
    flare_rpm_max: [f64::MIN_POSITIVE, 10_000.0],
    spike_mps2_max: [f64::MIN_POSITIVE, 100.0],
    torque_error_300ms_nm_max: [f64::MIN_POSITIVE, 10_000.0],
    estimator_rmse_c_max: [f64::MIN_POSITIVE, 1000.0],
    latency_ratio_max: [f64::MIN_POSITIVE, 1e6],
});

/// One check of a verdict.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Check {
    /// The limit's key (`finite` for the invariant).
    pub name: &'static str,
    /// What was required, in words.
    pub limit: String,
    /// What the run showed.
    pub measured: String,
    pub pass: bool,
}

/// Whether every check passed.
pub fn passed(checks: &[Check]) -> bool {
    checks.iter().all(|c| c.pass)
}

fn check(name: &'static str, limit: String, measured: String, pass: bool) -> Check {
    Check {
        name,
        limit,
        measured,
        pass,
    }
}

/// The largest of `values` (`None` for none) against `max`.
fn at_most(name: &'static str, unit: &str, max: f64, values: &[Option<f64>]) -> Check {
    let missing = values.iter().filter(|v| v.is_none()).count();
    let worst = values.iter().flatten().copied().fold(f64::NAN, f64::max);
    let measured = match (values.is_empty(), missing) {
        (true, _) => "no launch".to_string(),
        (false, 0) => format!("max {worst:.2} {unit}"),
        (false, m) => format!("{m} of {} never reached", values.len()),
    };
    let pass = !values.is_empty() && missing == 0 && worst <= max;
    check(name, format!("≤ {max} {unit}"), measured, pass)
}

/// The checks of `limits` (or the invariant alone) against a run's metrics; `latency_ratio` is
/// the bench's TCU reaction p99 over the echo's p99 (`None` in simulation: the limit is then
/// not checked).
pub fn judge(limits: Option<&Limits>, m: &Metrics, latency_ratio: Option<f64>) -> Vec<Check> {
    let mut out = vec![check(
        "finite",
        "no NaN or infinity on the bus".into(),
        if m.nonfinite { "found" } else { "none" }.into(),
        !m.nonfinite,
    )];
    let Some(l) = limits else { return out };
    out.extend(launch_checks(l, &m.launches));
    if l.shifts_complete.unwrap_or(true) {
        out.push(shifts_complete(&m.shifts));
    }
    if let Some(max) = l.estimator_rmse_c_max {
        out.push(estimator_rmse(max, &m.estimator));
    }
    out.push(faults(&l.faults_allowed, &m.status_events));
    if let (Some(max), Some(r)) = (l.latency_ratio_max, latency_ratio) {
        out.push(check(
            "latency_ratio_max",
            format!("≤ {max}× the echo"),
            format!("{r:.1}×"),
            r <= max,
        ));
    }
    out
}

/// The checks of the launches' limits that are set (how many, lock-up, flare, spike, torque
/// error), and that no launch stalled (unless `no_stall = false`).
fn launch_checks(l: &Limits, launches: &[LaunchMetrics]) -> Vec<Check> {
    let mut out = Vec::new();
    let n = launches.len();
    if let Some(min) = l.launches_min {
        out.push(check(
            "launches_min",
            format!("≥ {min}"),
            n.to_string(),
            n >= min,
        ));
    }
    let launch = |f: fn(&LaunchMetrics) -> Option<f64>| -> Vec<Option<f64>> {
        launches.iter().map(f).collect()
    };
    if let Some(max) = l.lockup_s_max {
        out.push(at_most("lockup_s_max", "s", max, &launch(|x| x.lockup_s)));
    }
    if let Some(max) = l.flare_rpm_max {
        out.push(at_most(
            "flare_rpm_max",
            "rpm",
            max,
            &launch(|x| Some(x.flare_rpm)),
        ));
    }
    if let Some(max) = l.spike_mps2_max {
        let v = launch(|x| x.lockup_spike_mps2.map(f64::abs));
        out.push(at_most("spike_mps2_max", "m/s²", max, &v));
    }
    if let Some(max) = l.torque_error_300ms_nm_max {
        let v = launch(|x| Some(x.peak_torque_error_300ms_nm));
        out.push(at_most("torque_error_300ms_nm_max", "N·m", max, &v));
    }
    if l.no_stall.unwrap_or(true) {
        let stalls = launches.iter().filter(|x| x.stall).count();
        out.push(check(
            "no_stall",
            "no launch stalls".into(),
            format!("{stalls} of {n} stalled"),
            stalls == 0,
        ));
    }
    out
}

/// Every shift ends in Drive (the ones that did not are listed).
fn shifts_complete(shifts: &[ShiftMetrics]) -> Check {
    let open: Vec<String> = shifts
        .iter()
        .filter(|s| !s.completed)
        .map(|s| format!("{}->{} at {:.2} s", s.from, s.to, s.t_start_s))
        .collect();
    check(
        "shifts_complete",
        "every shift ends in Drive".into(),
        if open.is_empty() {
            format!("{} of {} completed", shifts.len(), shifts.len())
        } else {
            format!("not completed: {}", open.join(", "))
        },
        open.is_empty(),
    )
}

/// The worse clutch's estimated temperature RMSE against SIM_Truth, at most `max` (fails
/// without SIM_Truth).
fn estimator_rmse(max: f64, e: &EstimatorMetrics) -> Check {
    let worst = e.rmse_c[0].max(e.rmse_c[1]);
    check(
        "estimator_rmse_c_max",
        format!("≤ {max} °C"),
        if e.samples == 0 {
            "no SIM_Truth".into()
        } else {
            format!("{worst:.2} °C")
        },
        e.samples > 0 && worst <= max,
    )
}

/// No fault code in the TCU's status but the `allowed` ones.
fn faults(allowed: &[FaultCode], events: &[StatusEvent]) -> Check {
    let mut faults: Vec<FaultCode> = events
        .iter()
        .map(|e| e.fault)
        .filter(|f| *f != FaultCode::None && !allowed.contains(f))
        .collect();
    faults.dedup();
    check(
        "faults",
        if allowed.is_empty() {
            "no fault code".into()
        } else {
            let a: Vec<_> = allowed.iter().map(|f| f.label()).collect();
            format!("only {}", a.join(", "))
        },
        if faults.is_empty() {
            "none other".into()
        } else {
            let f: Vec<_> = faults.iter().map(|f| f.label()).collect();
            f.join(", ")
        },
        faults.is_empty(),
    )
}

/// The checks of several runs as one table for a terminal or a pipe (no colour).
pub fn table(runs: &[(String, Vec<Check>)]) -> String {
    let mut s = format!(
        "{:<22} {:<26} {:<6} {:<30} {}\n",
        "scenario", "check", "result", "limit", "measured"
    );
    for (scenario, checks) in runs {
        for c in checks {
            s.push_str(&format!(
                "{:<22} {:<26} {:<6} {:<30} {}\n",
                scenario,
                c.name,
                if c.pass { "PASS" } else { "FAIL" },
                c.limit,
                c.measured
            ));
        }
    }
    s
}

/// JUnit XML of the verdicts of several scenarios: one test suite per scenario, one test case
/// per check, a failure (with the limit and the measured value) per failed check.
pub fn junit(name: &str, runs: &[(String, Vec<Check>)]) -> String {
    use quick_junit::{NonSuccessKind, Report, TestCase, TestCaseStatus, TestSuite};
    let mut report = Report::new(name);
    for (scenario, checks) in runs {
        let mut suite = TestSuite::new(scenario.as_str());
        for c in checks {
            let status = if c.pass {
                TestCaseStatus::success()
            } else {
                let mut s = TestCaseStatus::non_success(NonSuccessKind::Failure);
                s.set_message(format!(
                    "{}: limit {}, measured {}",
                    c.name, c.limit, c.measured
                ));
                s
            };
            let mut case = TestCase::new(c.name, status);
            case.set_classname(format!("ddct.{scenario}"));
            suite.add_test_case(case);
        }
        report.add_test_suite(suite);
    }
    report
        .to_string()
        .unwrap_or_else(|e| format!("<!-- JUnit XML could not be written: {e} -->"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::messages::TcuState;
    use crate::sim::metrics::{EstimatorMetrics, LaunchMetrics, ShiftMetrics, StatusEvent};

    fn launch(lockup: Option<f64>, flare: f64, stall: bool) -> LaunchMetrics {
        LaunchMetrics {
            t_start_s: 1.0,
            pedal_pct: 50.0,
            target_rpm: 2000.0,
            lockup_s: lockup,
            stall,
            min_engine_rpm: 900.0,
            max_engine_rpm: 2400.0,
            flare_rpm: flare,
            accel_before_lockup_mps2: None,
            lockup_spike_mps2: Some(-0.4),
            peak_torque_error_300ms_nm: 20.0,
            peak_accel_600ms_mps2: 2.0,
            torque_error_by_slip: vec![],
            friction_energy_kj: 10.0,
        }
    }

    fn metrics(launches: Vec<LaunchMetrics>, shift_done: bool, fault: FaultCode) -> Metrics {
        Metrics {
            launches,
            shifts: vec![ShiftMetrics {
                t_start_s: 4.0,
                up: true,
                from: crate::model::gear::Gear::G1,
                to: crate::model::gear::Gear::G2,
                duration_s: 0.8,
                completed: shift_done,
                min_accel_mps2: 0.5,
                accel_before_mps2: 1.0,
                max_engine_rpm: 3000.0,
            }],
            estimator: EstimatorMetrics {
                samples: 100,
                rmse_c: [0.4, 0.3],
                max_abs_c: [1.0, 1.0],
                max_true_c: [60.0, 60.0],
            },
            status_events: vec![StatusEvent {
                t_s: 2.0,
                state: TcuState::Drive,
                fault,
            }],
            max_speed_kmh: 40.0,
            min_engine_rpm_driving: 900.0,
            nonfinite: false,
        }
    }

    fn limits() -> Limits {
        Limits {
            launches_min: Some(1),
            lockup_s_max: Some(2.0),
            flare_rpm_max: Some(300.0),
            spike_mps2_max: Some(1.0),
            estimator_rmse_c_max: Some(1.0),
            ..Limits::default()
        }
    }

    fn failed(c: &[Check]) -> Vec<&'static str> {
        c.iter().filter(|c| !c.pass).map(|c| c.name).collect()
    }

    #[test]
    fn a_run_inside_its_limits_passes_every_check() {
        let m = metrics(vec![launch(Some(1.5), 120.0, false)], true, FaultCode::None);
        let c = judge(Some(&limits()), &m, None);
        assert!(passed(&c), "{c:?}");
        let names: Vec<_> = c.iter().map(|c| c.name).collect();
        assert_eq!(
            names,
            [
                "finite",
                "launches_min",
                "lockup_s_max",
                "flare_rpm_max",
                "spike_mps2_max",
                "no_stall",
                "shifts_complete",
                "estimator_rmse_c_max",
                "faults"
            ]
        );
    }

    #[test]
    fn each_violation_fails_its_own_check() {
        // No lock-up, a 762 rpm flare, an open shift and a timeout (the run issue 13 saw).
        let m = metrics(
            vec![launch(None, 762.0, false)],
            false,
            FaultCode::SensorsTimeout,
        );
        let c = judge(Some(&limits()), &m, None);
        assert_eq!(
            failed(&c),
            ["lockup_s_max", "flare_rpm_max", "shifts_complete", "faults"]
        );
        let allowed = Limits {
            faults_allowed: vec![FaultCode::SensorsTimeout],
            ..limits()
        };
        assert!(!failed(&judge(Some(&allowed), &m, None)).contains(&"faults"));
        // No launch at all cannot pass a launch limit.
        let m = metrics(vec![], true, FaultCode::None);
        assert_eq!(
            failed(&judge(Some(&limits()), &m, None)),
            [
                "launches_min",
                "lockup_s_max",
                "flare_rpm_max",
                "spike_mps2_max"
            ]
        );
    }

    #[test]
    fn without_limits_only_the_invariant_is_checked() {
        let mut m = metrics(vec![launch(None, 900.0, true)], false, FaultCode::PedalCrc);
        assert!(passed(&judge(None, &m, None)));
        m.nonfinite = true;
        assert_eq!(failed(&judge(None, &m, None)), ["finite"]);
    }

    #[test]
    fn the_latency_ratio_is_checked_only_where_measured() {
        let l = Limits {
            latency_ratio_max: Some(5.0),
            ..Limits::default()
        };
        let m = metrics(vec![], true, FaultCode::None);
        assert!(!judge(Some(&l), &m, None)
            .iter()
            .any(|c| c.name == "latency_ratio_max"));
        assert_eq!(
            failed(&judge(Some(&l), &m, Some(7.5))),
            ["latency_ratio_max"]
        );
    }

    #[test]
    fn numeric_limits_must_be_finite_and_positive() {
        use crate::ranges::Ranged;
        let key = |l: &Limits| l.check_ranges().err().map(|e| e.key);
        assert_eq!(key(&limits()), None);
        let bad = Limits {
            spike_mps2_max: Some(f64::NAN),
            ..limits()
        };
        assert_eq!(key(&bad).as_deref(), Some("limits.spike_mps2_max"));
        let bad = Limits {
            lockup_s_max: Some(-1.0),
            ..limits()
        };
        let e = bad.check_ranges().unwrap_err();
        assert_eq!(
            (e.key.as_str(), e.value, e.max),
            ("limits.lockup_s_max", -1.0, 3600.0)
        );
        let bad = Limits {
            flare_rpm_max: Some(0.0),
            ..limits()
        };
        assert_eq!(key(&bad).as_deref(), Some("limits.flare_rpm_max"));
        let bad = Limits {
            launches_min: Some(0),
            ..limits()
        };
        assert_eq!(key(&bad).as_deref(), Some("limits.launches_min"));
    }
}

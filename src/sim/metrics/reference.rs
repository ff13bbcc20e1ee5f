//! The slice-based computation the metrics had before [`super::Stream`] (test only): the oracle
//! the stream must match bit for bit. Kept verbatim so that a change of the stream that alters
//! a figure fails the tests instead of silently redefining it.

use super::figures::{
    launch_clutch, EstimatorMetrics, LaunchMetrics, Metrics, ShiftMetrics, SlipBin, StatusEvent,
    RPM, SLIP_BINS_RADPS,
};
use crate::can::messages::TcuState;
use crate::sim::row::Row;
use crate::tcu::TcuConfig;

/// Bit for bit: `Debug` prints every `f64` in its shortest round-trip form (−0.0 and NaN
/// included), where `PartialEq` would take −0.0 for 0.0.
pub(crate) fn assert_same(a: &Metrics, b: &Metrics, what: &str) {
    assert_eq!(format!("{a:#?}"), format!("{b:#?}"), "{what}");
}

/// Metrics of a run's rows.
pub fn compute(rows: &[Row], cfg: &TcuConfig) -> Metrics {
    let mut launches = Vec::new();
    let mut shifts = Vec::new();
    let idle = cfg.physics.engine.idle_speed_rpm;
    for k in 1..rows.len() {
        let (prev, r) = (&rows[k - 1], &rows[k]);
        if r.state == TcuState::Launch
            && matches!(
                prev.state,
                TcuState::Creep | TcuState::Neutral | TcuState::Init
            )
        {
            launches.push(launch(rows, k, cfg, idle));
        }
        if matches!(r.state, TcuState::Upshift | TcuState::Downshift) && prev.state != r.state {
            shifts.push(shift(rows, k));
        }
    }
    let mut n = 0usize;
    let mut se = [0.0; 2];
    let mut mx = [0.0f64; 2];
    let mut mt = [f64::MIN; 2];
    for r in rows {
        // Rows before the first SIM_Truth or the first TCU_Estimates frame (both decode to
        // exactly 0 °C until seen): nothing to compare. On a bus the plant's first cycle can
        // precede the TCU's first estimate now that it starts as soon as the TCU listens.
        let unseen = |t: [f64; 2]| t[0] == 0.0 && t[1] == 0.0;
        if unseen(r.theta_true_c) || unseen(r.theta_est_c) {
            continue;
        }
        n += 1;
        for i in 0..2 {
            let e = r.theta_est_c[i] - r.theta_true_c[i];
            se[i] += e * e;
            mx[i] = mx[i].max(e.abs());
            mt[i] = mt[i].max(r.theta_true_c[i]);
        }
    }
    let estimator = EstimatorMetrics {
        samples: n,
        rmse_c: se.map(|s| if n > 0 { (s / n as f64).sqrt() } else { 0.0 }),
        max_abs_c: mx,
        max_true_c: mt,
    };
    let mut status_events = Vec::new();
    for (k, r) in rows.iter().enumerate() {
        if k == 0 || r.state != rows[k - 1].state || r.fault != rows[k - 1].fault {
            status_events.push(StatusEvent {
                t_s: r.t_s,
                state: r.state,
                fault: r.fault,
            });
        }
    }
    let nonfinite = rows.iter().any(|r| {
        [
            r.n_e_rpm,
            r.t_e_nm,
            r.x_ref_mm[0],
            r.x_ref_mm[1],
            r.t_ref_nm[0],
            r.t_ref_nm[1],
            r.theta_est_c[0],
            r.theta_est_c[1],
            r.accel_mps2,
        ]
        .iter()
        .any(|v| !v.is_finite())
            || r.eng_req_nm.is_some_and(|v| !v.is_finite())
    });
    Metrics {
        launches,
        shifts,
        estimator,
        status_events,
        max_speed_kmh: rows.iter().map(|r| r.v_kmh).fold(0.0, f64::max),
        min_engine_rpm_driving: rows
            .iter()
            .filter(|r| {
                matches!(
                    r.state,
                    TcuState::Launch | TcuState::Drive | TcuState::Upshift | TcuState::Downshift
                )
            })
            .map(|r| r.n_e_rpm)
            .fold(f64::INFINITY, f64::min),
        nonfinite,
    }
}

fn launch(rows: &[Row], k0: usize, cfg: &TcuConfig, idle: f64) -> LaunchMetrics {
    let r0 = &rows[k0];
    let t0 = r0.t_s;
    let c = launch_clutch(r0);
    let l = &cfg.launch;
    let p = r0.pedal_pct / 100.0;
    let target = l.engine_rpm_0 + (l.engine_rpm_100 - l.engine_rpm_0) * p;
    // Lock-up: |slip| < 5 rpm, while still launching or just after.
    let mut lock: Option<usize> = None;
    let mut end = rows.len();
    for (k, r) in rows.iter().enumerate().skip(k0) {
        if !matches!(r.state, TcuState::Launch | TcuState::Drive) {
            end = k;
            break;
        }
        if r.slip_rpm(c).abs() < 5.0 {
            lock = Some(k);
            break;
        }
    }
    let t_lock = lock.map(|k| rows[k].t_s);
    let upto = lock
        .unwrap_or(end.min(rows.len()))
        .max(k0 + 1)
        .min(rows.len());
    let window = |a: f64, b: f64| rows.iter().filter(move |r| r.t_s >= a && r.t_s < b);
    let seg = &rows[k0..upto];
    let min_e = rows[k0..(upto + 50).min(rows.len())]
        .iter()
        .map(|r| r.n_e_rpm)
        .fold(f64::INFINITY, f64::min);
    let max_e = seg.iter().map(|r| r.n_e_rpm).fold(0.0, f64::max);
    let (pre, spike) = match t_lock {
        Some(tl) => {
            let pre: Vec<f64> = window(tl - 0.1, tl).map(|r| r.accel_mps2).collect();
            let pre_m = if pre.is_empty() {
                None
            } else {
                Some(pre.iter().sum::<f64>() / pre.len() as f64)
            };
            let post = window(tl, tl + 0.3)
                .map(|r| r.accel_mps2)
                .fold(f64::MIN, f64::max);
            (pre_m, pre_m.map(|a| post - a))
        }
        None => (None, None),
    };
    let peak_err = window(t0, t0 + 0.3)
        .map(|r| (r.t_ref_nm[c] - r.t_act_nm[c]).abs())
        .fold(0.0, f64::max);
    let peak_acc = window(t0, t0 + 0.6)
        .map(|r| r.accel_mps2)
        .fold(f64::MIN, f64::max);
    let mut bins = Vec::new();
    for w in SLIP_BINS_RADPS.windows(2) {
        let (hi, lo) = (w[0], w[1]);
        let sel: Vec<&Row> = seg
            .iter()
            .filter(|r| {
                let s = r.slip_rpm(c).abs() * RPM;
                s < hi && s >= lo && r.t_ref_nm[c] > 1.0
            })
            .collect();
        let n = sel.len();
        let mean = |f: &dyn Fn(&Row) -> f64| {
            if n == 0 {
                None
            } else {
                Some(sel.iter().map(|r| f(r)).sum::<f64>() / n as f64)
            }
        };
        bins.push(SlipBin {
            slip_hi_radps: hi,
            slip_lo_radps: lo,
            mean_error_nm: mean(&|r| r.t_ref_nm[c] - r.t_act_nm[c]),
            mean_rel_error: mean(&|r| (r.t_ref_nm[c] - r.t_act_nm[c]) / r.t_ref_nm[c]),
            n,
        });
    }
    let mut energy = 0.0;
    for w in seg.windows(2) {
        let dt = w[1].t_s - w[0].t_s;
        energy += w[0].t_act_nm[c] * w[0].slip_rpm(c) * RPM * dt;
    }
    let _ = idle;
    LaunchMetrics {
        t_start_s: t0,
        pedal_pct: r0.pedal_pct,
        target_rpm: target,
        lockup_s: t_lock.map(|t| t - t0),
        stall: min_e < 0.6 * idle,
        min_engine_rpm: min_e,
        max_engine_rpm: max_e,
        flare_rpm: max_e - target,
        accel_before_lockup_mps2: pre,
        lockup_spike_mps2: spike,
        peak_torque_error_300ms_nm: peak_err,
        peak_accel_600ms_mps2: peak_acc,
        torque_error_by_slip: bins,
        friction_energy_kj: energy / 1e3,
    }
}

fn shift(rows: &[Row], k0: usize) -> ShiftMetrics {
    let r0 = &rows[k0];
    let state = r0.state;
    let from = rows[k0 - 1].gear_active;
    let mut end = rows.len() - 1;
    let mut completed = false;
    for (k, r) in rows.iter().enumerate().skip(k0) {
        if r.state != state {
            end = k;
            completed = r.state == TcuState::Drive;
            break;
        }
    }
    let t_end = rows[end].t_s;
    let before: Vec<f64> = rows
        .iter()
        .filter(|r| r.t_s >= r0.t_s - 0.1 && r.t_s < r0.t_s)
        .map(|r| r.accel_mps2)
        .collect();
    let min_acc = rows
        .iter()
        .filter(|r| r.t_s >= r0.t_s && r.t_s <= t_end + 0.2)
        .map(|r| r.accel_mps2)
        .fold(f64::INFINITY, f64::min);
    let max_e = rows[k0..=end].iter().map(|r| r.n_e_rpm).fold(0.0, f64::max);
    ShiftMetrics {
        t_start_s: r0.t_s,
        up: state == TcuState::Upshift,
        from,
        to: rows[end].gear_active,
        duration_s: t_end - r0.t_s,
        completed,
        min_accel_mps2: min_acc,
        accel_before_mps2: if before.is_empty() {
            0.0
        } else {
            before.iter().sum::<f64>() / before.len() as f64
        },
        max_engine_rpm: max_e,
    }
}

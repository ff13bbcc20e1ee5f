//! Engine: full-load curve, pedal → torque demand, motoring drag, idle governor (PI with
//! anti-windup), external torque request, first-order torque lag. The engine torque T_e is the
//! input of (18a).
//!
//! - Full load T_full(n): quadratic below the peak (215 N·m at 2500 rpm by default) through the
//!   idle point and above it through the cut-off point; it falls linearly to zero below the stall
//!   speed and over `cutoff_band_rpm` above the cut-off speed (fuel cut).
//! - Driver demand: p·T_full(n) − (1 − p)·T_drag(n), pedal p ∈ [0, 1], T_drag = d0 + d1·n/1000
//!   (faded to zero at standstill so a stopped engine is not driven backwards).
//! - Idle governor: T_gov = kp·(ω_idle − ω) + I, İ = ki·(ω_idle − ω) with I ∈ [0, I_max]; the
//!   command is max(demand, T_gov) limited to T_full.
//! - External request (TCU_EngineReq): when active the command is the request limited to
//!   [−T_drag, T_full]; the governor is bypassed (the TCU has authority, as in (23)–(24)).
//! - Torque lag: Ṫ_e = (T_cmd − T_e)/τ.

use super::params::EngineParams;

/// rad/s per rpm.
pub const RPM: f64 = std::f64::consts::PI / 30.0;

/// Engine inputs.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EngineInputs {
    /// Accelerator pedal, fraction 0..1.
    pub pedal: f64,
    /// External torque request (N·m) when active.
    pub torque_request_nm: Option<f64>,
}

/// Full-load (wide-open throttle) torque at engine speed `w` (rad/s), N·m.
pub(crate) fn full_load(p: &EngineParams, w_radps: f64) -> f64 {
    let n = w_radps / RPM;
    let t = if n <= p.peak_speed_rpm {
        let k = (1.0 - p.torque_at_idle_nm / p.peak_torque_nm)
            / ((p.idle_speed_rpm - p.peak_speed_rpm) / p.peak_speed_rpm).powi(2);
        let d = (n - p.peak_speed_rpm) / p.peak_speed_rpm;
        p.peak_torque_nm * (1.0 - k * d * d)
    } else {
        let k = (1.0 - p.torque_at_cutoff_nm / p.peak_torque_nm)
            / ((p.cutoff_speed_rpm - p.peak_speed_rpm) / p.peak_speed_rpm).powi(2);
        let d = (n - p.peak_speed_rpm) / p.peak_speed_rpm;
        p.peak_torque_nm * (1.0 - k * d * d)
    };
    let stall = (n / p.stall_speed_rpm).clamp(0.0, 1.0);
    let cut = (1.0 - (n - p.cutoff_speed_rpm) / p.cutoff_band_rpm).clamp(0.0, 1.0);
    t.max(0.0) * stall * cut
}

/// Motoring drag torque (N·m, ≥ 0) at engine speed `w` (rad/s).
pub(crate) fn drag(p: &EngineParams, w_radps: f64) -> f64 {
    let n = w_radps / RPM;
    let fade = (n / 100.0).clamp(0.0, 1.0);
    (p.drag0_nm + p.drag1_nm_per_krpm * n.max(0.0) / 1000.0) * fade
}

/// Commanded torque (before the lag) and the governor integral rate.
/// Returns `(t_cmd_nm, d_idle_int_nm_per_s)`.
pub fn command(p: &EngineParams, w_radps: f64, idle_int_nm: f64, u: &EngineInputs) -> (f64, f64) {
    let full = full_load(p, w_radps);
    let dr = drag(p, w_radps);
    let e = p.idle_speed_rpm * RPM - w_radps;
    let mut di = p.idle_ki_nm_per_rad * e;
    if (idle_int_nm >= p.idle_int_max_nm && di > 0.0) || (idle_int_nm <= 0.0 && di < 0.0) {
        di = 0.0;
    }
    if let Some(req) = u.torque_request_nm.filter(|r| r.is_finite()) {
        return (req.clamp(-dr, full), di);
    }
    let pedal = if u.pedal.is_finite() {
        u.pedal.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let demand = pedal * full - (1.0 - pedal) * dr;
    let gov = p.idle_kp_nm_per_radps * e + idle_int_nm;
    (demand.max(gov).min(full), di)
}

/// Lagged torque rate (N·m/s).
#[inline]
pub(crate) fn torque_rate(p: &EngineParams, t_e_nm: f64, t_cmd_nm: f64) -> f64 {
    (t_cmd_nm - t_e_nm) / p.torque_lag_s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::params::Params;

    #[test]
    fn full_load_curve_points() {
        let p = Params::default().engine;
        assert!((full_load(&p, 2500.0 * RPM) - 215.0).abs() < 1e-9);
        assert!((full_load(&p, 800.0 * RPM) - 155.0).abs() < 1e-9);
        assert!((full_load(&p, 6500.0 * RPM) - 150.0).abs() < 1e-9);
        assert_eq!(full_load(&p, 6600.0 * RPM), 0.0);
        // Peak is the maximum.
        for n in (0..7000).step_by(50) {
            assert!(full_load(&p, n as f64 * RPM) <= 215.0 + 1e-9);
        }
    }

    #[test]
    fn request_is_honoured_within_limits() {
        let p = Params::default().engine;
        let w = 2000.0 * RPM;
        let u = EngineInputs {
            pedal: 1.0,
            torque_request_nm: Some(42.0),
        };
        assert_eq!(command(&p, w, 0.0, &u).0, 42.0);
        let u = EngineInputs {
            pedal: 0.0,
            torque_request_nm: Some(1e4),
        };
        assert_eq!(command(&p, w, 0.0, &u).0, full_load(&p, w));
    }

    #[test]
    fn governor_acts_below_idle_only() {
        let p = Params::default().engine;
        let u = EngineInputs::default();
        let (t_low, di) = command(&p, 700.0 * RPM, 0.0, &u);
        assert!(t_low > 0.0 && di > 0.0);
        let (t_high, _) = command(&p, 2000.0 * RPM, 0.0, &u);
        assert!((t_high + drag(&p, 2000.0 * RPM)).abs() < 1e-9);
    }
}

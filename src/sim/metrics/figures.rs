//! What the metrics of a run are ([`Metrics`]: launches, shifts, the estimator's accuracy, the
//! status changes), as [`super::Stream`] fills them and the reports read them.

use crate::can::messages::{FaultCode, TcuState};
use crate::model::gear::Gear;
use crate::sim::row::Row;
use serde::Serialize;

/// Slip bin edges (rad/s), from high to low, for the torque error over slip.
pub const SLIP_BINS_RADPS: [f64; 8] = [100.0, 50.0, 20.0, 10.0, 5.0, 2.0, 1.0, 0.3];

/// rad/s per rpm.
pub(super) const RPM: f64 = std::f64::consts::PI / 30.0;

/// One launch.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct LaunchMetrics {
    pub t_start_s: f64,
    pub pedal_pct: f64,
    /// Calibration target n(p) (rpm).
    pub target_rpm: f64,
    pub lockup_s: Option<f64>,
    pub stall: bool,
    pub min_engine_rpm: f64,
    pub max_engine_rpm: f64,
    pub flare_rpm: f64,
    pub accel_before_lockup_mps2: Option<f64>,
    pub lockup_spike_mps2: Option<f64>,
    pub peak_torque_error_300ms_nm: f64,
    pub peak_accel_600ms_mps2: f64,
    /// Mean T_ref − T_actual (N·m) and sample count per slip bin [edge_i, edge_{i+1}).
    pub torque_error_by_slip: Vec<SlipBin>,
    /// Friction energy estimate ∑T_actual·slip·dt over the engagement (kJ).
    pub friction_energy_kj: f64,
}

#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct SlipBin {
    pub slip_hi_radps: f64,
    pub slip_lo_radps: f64,
    pub mean_error_nm: Option<f64>,
    pub mean_rel_error: Option<f64>,
    pub n: usize,
}

/// One shift.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ShiftMetrics {
    pub t_start_s: f64,
    pub up: bool,
    pub from: Gear,
    pub to: Gear,
    pub duration_s: f64,
    pub completed: bool,
    pub min_accel_mps2: f64,
    pub accel_before_mps2: f64,
    pub max_engine_rpm: f64,
}

/// Estimator accuracy against SIM_Truth.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct EstimatorMetrics {
    pub samples: usize,
    pub rmse_c: [f64; 2],
    pub max_abs_c: [f64; 2],
    pub max_true_c: [f64; 2],
}

/// A change of TcuState or FaultCode.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct StatusEvent {
    pub t_s: f64,
    pub state: TcuState,
    pub fault: FaultCode,
}

/// Everything of one run.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Metrics {
    pub launches: Vec<LaunchMetrics>,
    pub shifts: Vec<ShiftMetrics>,
    pub estimator: EstimatorMetrics,
    pub status_events: Vec<StatusEvent>,
    pub max_speed_kmh: f64,
    pub min_engine_rpm_driving: f64,
    /// Any non-finite value among the decoded signals (never expected).
    pub nonfinite: bool,
}

/// The clutch a row's launch engages.
pub(super) fn launch_clutch(r: &Row) -> usize {
    // Reverse launches on the even shaft's clutch, forward on the odd one's.
    usize::from(r.gear_active.is_reverse())
}

//! One TCU cycle of a run as the bus carried it ([`Row`]): what the runner records and the
//! metrics, plots and logs read.

use crate::can::messages::{FaultCode, TcuState};
use crate::model::gear::Gear;
use serde::Serialize;

/// One TCU cycle as seen on the bus (SI-ish units as named).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Default)]
pub struct Row {
    pub t_s: f64,
    pub pedal_pct: f64,
    pub brake: bool,
    pub n_e_rpm: f64,
    pub t_e_nm: f64,
    pub n_c_rpm: [f64; 2],
    pub n_out_rpm: f64,
    pub housing_c: f64,
    pub x_mm: [f64; 2],
    pub gear_act: [Gear; 2],
    pub x_ref_mm: [f64; 2],
    pub eng_req_nm: Option<f64>,
    pub gear_req: [Gear; 2],
    pub state: TcuState,
    pub fault: FaultCode,
    pub gear_active: Gear,
    pub theta_est_c: [f64; 2],
    pub t_ref_nm: [f64; 2],
    pub t_act_nm: [f64; 2],
    pub theta_pp_c: [f64; 2],
    pub theta_cd_c: f64,
    pub theta_true_c: [f64; 2],
    pub v_kmh: f64,
    pub accel_mps2: f64,
    pub grade_pct: f64,
    /// TCU internals.
    pub n_e_ref_rpm: f64,
    pub n_c_ref_rpm: f64,
    pub phase: &'static str,
}

impl Row {
    /// Measured slip of clutch `i` from the bus (rpm).
    pub fn slip_rpm(&self, i: usize) -> f64 {
        self.n_e_rpm - self.n_c_rpm[i]
    }
}

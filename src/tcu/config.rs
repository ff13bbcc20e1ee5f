//! The TCU's calibration (`config/tcu.toml`): compensation switches of the torque inverse (paper
//! Sect. 6), estimator, input checks, safety thresholds, the gains of the decoupling controller
//! (23)–(27), creep, launch and shift strategy, the kiss-point adaptation routine (x_ISP of (9)
//! learned where the torque of (13) starts, [`super::routine`]). The physical parameters the TCU's models use
//! (clutch (13), thermal (17), driveline (22), engine map) come from the parameter file the
//! calibration names (`params = "params.toml"`, relative to the calibration file).
//!
//! Loading checks TOML syntax, unknown and missing keys (serde) and then every value's range;
//! each failure is a [`TcuConfigError`] naming the key.

use crate::model::effects::EffectSet;
use crate::model::params::{Params, ParamsError};
use crate::ranges::{RangeError, Ranged};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The calibration compiled into the binary; [`TcuConfig::default`] is this file.
pub const DEFAULT_TOML: &str = include_str!("../../config/tcu.toml");

/// Errors of loading a calibration.
#[derive(Debug, thiserror::Error)]
pub enum TcuConfigError {
    #[error("cannot read TCU calibration {path}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("TCU calibration {path}: not valid TOML")]
    Syntax {
        path: PathBuf,
        #[source]
        source: Box<toml::de::Error>,
    },
    #[error(transparent)]
    OutOfRange(#[from] RangeError),
    #[error("TCU calibration: inconsistent `{key}`: {reason}")]
    Inconsistent { key: String, reason: String },
    #[error("TCU calibration: effects file {path}")]
    Effects {
        path: PathBuf,
        #[source]
        source: crate::model::effects::EffectError,
    },
    #[error("TCU calibration {location}")]
    InFile {
        /// The file, and the line of the key when it is found.
        location: String,
        #[source]
        source: Box<TcuConfigError>,
    },
    #[error("TCU calibration: parameter file {path}")]
    Params {
        path: PathBuf,
        #[source]
        source: ParamsError,
    },
}

impl TcuConfigError {
    /// The dotted key (`table.key`) a range or consistency error is about.
    pub fn key(&self) -> Option<&str> {
        match self {
            TcuConfigError::OutOfRange(RangeError { key, .. })
            | TcuConfigError::Inconsistent { key, .. } => Some(key),
            _ => None,
        }
    }
}

/// Compensation switches of the inverse of (13).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Compensation {
    pub temperature: bool,
    pub slip: bool,
    pub calibration_temp_c: f64,
    pub calibration_slip_radps: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EstimatorCfg {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub initial_temp_c: Option<f64>,
    pub slip_deadband_radps: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InputsCfg {
    pub timeout_cycles: u32,
    pub max_counter_skip: u8,
    pub recovery_frames: u32,
    pub max_engine_rpm: f64,
    pub max_engine_rate_rpm_per_s: f64,
    pub max_out_rate_rpm_per_s: f64,
    pub max_shaft_mismatch_radps: f64,
    /// Output-shaft speed above which a lever move into D or R is refused (FaultCode
    /// ImplausibleLever; the previous lever stays in force).
    #[serde(default = "default_max_lever_engage_out_rpm")]
    pub max_lever_engage_out_rpm: f64,
    pub housing_temp_min_c: f64,
    pub housing_temp_max_c: f64,
    pub max_position_mm: f64,
}

/// About 6 km/h (walking pace) with the default wheel radius (0.31 m) and final drive (3.6).
fn default_max_lever_engage_out_rpm() -> f64 {
    185.0
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SafetyCfg {
    pub open_rate_mm_per_s: f64,
    pub over_temp_warn_c: f64,
    pub over_temp_limit_c: f64,
    pub over_temp_engine_torque_nm: f64,
    pub over_temp_hysteresis_c: f64,
    /// Anti-stall: a slipping clutch's torque is unlimited while the engine turns at least this
    /// fraction of idle ...
    pub antistall_free_idle_fraction: f64,
    /// ... and falls to zero at this fraction of idle ...
    pub antistall_zero_idle_fraction: f64,
    /// ... from this share of the engine's full-load torque.
    pub antistall_max_share: f64,
    /// Below this fraction of idle an engine torque request asking less than the driver's demand
    /// is dropped, so the engine's own idle governor brings the engine back (every mode).
    pub antistall_release_idle_fraction: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControlCfg {
    pub clutch_kp_per_s: f64,
    pub clutch_ki_per_s2: f64,
    pub engine_kp_per_s: f64,
    pub engine_ki_per_s2: f64,
    pub max_torque_nm: f64,
    pub standby_gap_mm: f64,
    pub open_position_mm: f64,
    pub lock_slip_radps: f64,
    pub lock_cycles: u32,
    pub lock_undershoot_radps: f64,
    pub lock_hold_slip_radps: f64,
    pub clamp_margin: f64,
    pub clamp_offset_nm: f64,
    pub clamp_rate_nm_per_s: f64,
    pub blend_rate_nm_per_s: f64,
    pub slip_alarm_radps: f64,
    pub command_delay_s: f64,
    /// Integral limit of the clutch-speed PI (N·m).
    pub clutch_integral_limit_nm: f64,
    /// Integral limit of the engine-speed PI (N·m).
    pub engine_integral_limit_nm: f64,
    /// Time constant of the output-shaft acceleration filter (s).
    pub accel_filter_s: f64,
    /// The lead terms (actuator and engine lag) differentiate over the time between two steps;
    /// steps closer than this (a burst of late frames) get no lead rather than a huge one (s).
    pub min_lead_dt_s: f64,
    /// Drive: cycles in a row above `slip_alarm_radps` before the clamp capacity is boosted.
    pub slip_alarm_cycles: u32,
    /// Drive: factor on `clamp_margin` and `clamp_offset_nm` while the slip alarm holds.
    pub slip_alarm_boost: f64,
    /// Drive: the engine request blending to the driver's demand is released within this of it
    /// (N·m).
    pub blend_release_nm: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CreepCfg {
    pub pedal_on_pct: f64,
    pub slip_radps: f64,
    pub accel_mps2: f64,
    pub max_torque_nm: f64,
    pub standstill_kmh: f64,
    pub stop_engine_rpm: f64,
    /// Rate at which a held creep torque is released (N·m/s).
    pub release_rate_nm_per_s: f64,
    /// The clutch-speed reference stays within this of the measured clutch speed (rad/s).
    pub reference_window_radps: f64,
    /// Largest rise of the creep torque, so the engine's idle governor keeps up (N·m/s).
    pub torque_rise_nm_per_s: f64,
    /// Share of the launch's PI_c gains creep uses (the creep torque sits near the kiss point,
    /// where the actuator lag matters most).
    pub gain_share: f64,
    /// A creep torque being released (brake on) is still applied above this; below it the clutch
    /// goes to standby (N·m).
    pub min_hold_torque_nm: f64,
    /// Drive, any gear: the engine below this fraction of idle (about to stall) opens the clutch
    /// and goes to creep.
    pub stall_idle_fraction: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaunchCfg {
    pub engine_rpm_0: f64,
    pub engine_rpm_100: f64,
    pub lockup_time_s: f64,
    pub engine_rate_rpm_per_s: f64,
    pub jerk_time_s: f64,
    pub sync_slip_radps: f64,
    pub min_sync_time_s: f64,
    /// The clutch-speed reference stays within this of the measured clutch speed (rad/s).
    pub reference_window_radps: f64,
    /// Pedal released this long in the start gear: back to creep (s).
    pub pedal_off_s: f64,
    /// Time constant of the engine-speed profile toward its target (s).
    pub engine_profile_s: f64,
    /// Share of the engine's full-load torque the clutch may draw on in a launch.
    pub engine_torque_share: f64,
    /// After the synchronisation profile a slip still above zero is pulled down further at this
    /// rate (rad/s²) ...
    pub sync_tail_rate_radps2: f64,
    /// ... up to this far below zero, so that the slip crosses and the clutch locks (rad/s).
    pub sync_tail_max_radps: f64,
    /// The clutch acceleration target is cut to what the engine has left, but not below this
    /// share of it.
    pub min_accel_share: f64,
    /// The engine-speed target lies at least this many `sync_slip_radps` above the clutch speed at
    /// the launch's start.
    pub target_min_sync_slips: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShiftCfg {
    pub torque_phase_s: f64,
    pub min_inertia_phase_s: f64,
    pub max_inertia_phase_s: f64,
    pub engine_authority: f64,
    pub downshift_offgoing_fraction: f64,
    pub min_interval_s: f64,
    /// Drive: time in the gear (after lock-up) before a scheduled shift may start (s).
    pub settle_s: f64,
    /// Drive: a scheduled downshift with the engine below this fraction of idle (lugging) starts
    /// at once, without waiting for `settle_s`, `min_interval_s` or the request's blend.
    pub lugging_idle_fraction: f64,
    /// A shift is abandoned (both clutches open, creep in the start gear) when the on-coming
    /// clutch shaft falls below this fraction of idle (hard braking toward a stop) ...
    pub abort_clutch_idle_fraction: f64,
    /// ... or the engine below this fraction of idle.
    pub abort_engine_idle_fraction: f64,
    /// Upshift, inertia phase: the on-coming clutch's least torque, which pulls the engine down
    /// with the pedal off (N·m).
    pub min_oncoming_nm: f64,
    /// Inertia-phase duration: the engine torque available for the speed change is taken as at
    /// least this (N·m).
    pub min_authority_nm: f64,
    /// Upshift, inertia phase: the engine torque counts as recovered within the larger of this
    /// share of the on-coming clutch's torque ...
    pub release_torque_share: f64,
    /// ... and this (N·m); then the held slip is released toward lock-up ...
    pub release_torque_nm: f64,
    /// ... or at the latest this long after the smoothstep's end (s) ...
    pub release_timeout_s: f64,
    /// ... along a ramp of this duration (s).
    pub release_ramp_s: f64,
    /// Downshift: the inertia phase hands over to the torque phase once the on-coming slip is
    /// within this of its end value (rad/s) ...
    pub downshift_sync_radps: f64,
    /// ... or at the latest this long after the smoothstep's end (s).
    pub downshift_sync_timeout_s: f64,
    /// A shift running longer than this (s) ...
    pub fallback_lock_s: f64,
    /// ... with the on-coming slip below this counts as locked: drive in the new gear (rad/s).
    pub fallback_lock_slip_radps: f64,
    /// A shift not completed in this time is abandoned: a fresh start from the measurements (s).
    pub abort_s: f64,
    pub up_kmh_0: [f64; 5],
    pub up_kmh_100: [f64; 5],
    pub down_kmh_0: [f64; 5],
    pub down_kmh_100: [f64; 5],
}

/// `[kiss_routine]`: the kiss-point adaptation routine ([`super::routine`], UDS RoutineControl
/// 0x0201). Optional in a calibration file: a missing table or key takes the default below.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct KissRoutineCfg {
    /// Standstill: the vehicle below this speed (km/h) to start and to keep running.
    pub max_vehicle_kmh: f64,
    /// Engine running: its speed above this fraction of idle.
    pub engine_running_idle_fraction: f64,
    /// Settling with the clutch open and the shaft in neutral: the mean input-shaft speed of one
    /// window of this length (s) ...
    pub settle_window_s: f64,
    /// ... within this of the previous window's (rpm) counts as settled (spun down or steady).
    pub steady_rpm: f64,
    /// Approach from open to the ramp's start at this rate (mm/s) ...
    pub approach_rate_mm_per_s: f64,
    /// ... the start lying this far before the model's kiss point x_ISP(θ̂) of (9) (mm) ...
    pub start_before_kiss_mm: f64,
    /// ... held this long there while the speed baseline is measured (s).
    pub hold_s: f64,
    /// The slow ramp's rate (mm/s).
    pub ramp_rate_mm_per_s: f64,
    /// The ramp ends this far beyond the model's kiss point: the shaft did not move (mm).
    pub end_beyond_kiss_mm: f64,
    /// The shaft counts as turning once its speed left the baseline by this (rpm); the onset fit
    /// uses the samples between `fit_floor_rpm` and this.
    pub detect_rpm: f64,
    /// Lower bound of the onset fit's samples (rpm above the baseline).
    pub fit_floor_rpm: f64,
    /// The measured position is fitted over this window before the onset (s).
    pub position_fit_s: f64,
    /// The whole routine is aborted after this (s).
    pub timeout_s: f64,
}

impl Default for KissRoutineCfg {
    fn default() -> Self {
        Self {
            max_vehicle_kmh: 0.5,
            engine_running_idle_fraction: 0.7,
            settle_window_s: 0.5,
            steady_rpm: 2.0,
            approach_rate_mm_per_s: 10.0,
            start_before_kiss_mm: 0.8,
            hold_s: 0.5,
            ramp_rate_mm_per_s: 0.1,
            end_beyond_kiss_mm: 1.0,
            detect_rpm: 40.0,
            fit_floor_rpm: 4.0,
            position_fit_s: 1.0,
            timeout_s: 30.0,
        }
    }
}

/// The whole calibration plus the physical parameters it names.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TcuConfig {
    /// Path of the parameter file, relative to the calibration file.
    pub params: PathBuf,
    /// Optional effects file (`model::effects`, `[effects.<id>]` tables) calibrating the TCU's
    /// torque characteristic, relative to the calibration file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effects: Option<PathBuf>,
    pub compensation: Compensation,
    pub estimator: EstimatorCfg,
    pub inputs: InputsCfg,
    pub safety: SafetyCfg,
    pub control: ControlCfg,
    pub creep: CreepCfg,
    pub launch: LaunchCfg,
    pub shift: ShiftCfg,
    /// The kiss-point adaptation routine (optional table: defaults without it).
    #[serde(default)]
    pub kiss_routine: KissRoutineCfg,
    /// The physical parameters (loaded from `params`).
    #[serde(skip)]
    pub physics: Params,
    /// The calibrated effects (loaded from `effects`; nominal without).
    #[serde(skip)]
    pub effect_set: EffectSet,
}

// The allowed range of every key, table by table (`crate::ranges`).
crate::ranges!(Compensation as _c, "compensation" {
    calibration_temp_c: [-40.0, 400.0],
    calibration_slip_radps: [0.0, 1e6],
});
crate::ranges!(EstimatorCfg as _e, "estimator" {
    initial_temp_c: [-40.0, 400.0],
    slip_deadband_radps: [0.0, 10.0],
});
crate::ranges!(InputsCfg as _i, "inputs" {
    timeout_cycles: [1.0, 100.0],
    max_counter_skip: [0.0, 14.0],
    recovery_frames: [1.0, 100.0],
    max_engine_rpm: [1000.0, 20000.0],
    max_engine_rate_rpm_per_s: [100.0, 1e6],
    max_out_rate_rpm_per_s: [10.0, 1e6],
    max_shaft_mismatch_radps: [1.0, 1e4],
    max_lever_engage_out_rpm: [0.0, 2000.0],
    housing_temp_min_c: [-60.0, 100.0],
    housing_temp_max_c: [0.0, 250.0],
    max_position_mm: [0.1, 50.0],
});
crate::ranges!(SafetyCfg as s, "safety" {
    open_rate_mm_per_s: [0.1, 1000.0],
    over_temp_warn_c: [50.0, 400.0],
    over_temp_limit_c: [s.over_temp_warn_c, 400.0],
    over_temp_engine_torque_nm: [0.0, 2000.0],
    over_temp_hysteresis_c: [0.0, 100.0],
    antistall_free_idle_fraction: [0.1, 2.0],
    antistall_zero_idle_fraction: [0.0, s.antistall_free_idle_fraction - 0.01],
    antistall_max_share: [0.0, 1.0],
    antistall_release_idle_fraction: [0.5, 2.0],
});
crate::ranges!(ControlCfg as _k, "control" {
    clutch_kp_per_s: [0.0, 200.0],
    clutch_ki_per_s2: [0.0, 5000.0],
    engine_kp_per_s: [0.0, 200.0],
    engine_ki_per_s2: [0.0, 5000.0],
    max_torque_nm: [1.0, 5000.0],
    standby_gap_mm: [0.0, 5.0],
    open_position_mm: [0.0, 10.0],
    lock_slip_radps: [0.01, 20.0],
    lock_cycles: [1.0, 100.0],
    lock_undershoot_radps: [0.0, 20.0],
    lock_hold_slip_radps: [0.0, 50.0],
    clamp_margin: [0.0, 5.0],
    clamp_offset_nm: [0.0, 500.0],
    clamp_rate_nm_per_s: [1.0, 1e5],
    blend_rate_nm_per_s: [1.0, 1e5],
    slip_alarm_radps: [0.1, 100.0],
    command_delay_s: [0.0, 0.1],
    clutch_integral_limit_nm: [0.0, 5000.0],
    engine_integral_limit_nm: [0.0, 5000.0],
    accel_filter_s: [0.0, 1.0],
    min_lead_dt_s: [0.0, 0.01],
    slip_alarm_cycles: [1.0, 100.0],
    slip_alarm_boost: [1.0, 5.0],
    blend_release_nm: [0.01, 50.0],
});
crate::ranges!(CreepCfg as _c, "creep" {
    pedal_on_pct: [0.0, 50.0],
    slip_radps: [0.0, 100.0],
    accel_mps2: [0.01, 10.0],
    max_torque_nm: [0.0, 500.0],
    standstill_kmh: [0.0, 20.0],
    stop_engine_rpm: [0.0, 5000.0],
    release_rate_nm_per_s: [1.0, 1e4],
    reference_window_radps: [0.1, 200.0],
    torque_rise_nm_per_s: [1.0, 1e4],
    gain_share: [0.05, 1.0],
    min_hold_torque_nm: [0.0, 10.0],
    stall_idle_fraction: [0.3, 1.0],
});
crate::ranges!(LaunchCfg as l, "launch" {
    engine_rpm_0: [500.0, 8000.0],
    engine_rpm_100: [l.engine_rpm_0, 8000.0],
    lockup_time_s: [0.2, 10.0],
    engine_rate_rpm_per_s: [10.0, 1e5],
    jerk_time_s: [0.0, 5.0],
    sync_slip_radps: [0.5, 200.0],
    min_sync_time_s: [0.0, 5.0],
    reference_window_radps: [0.1, 200.0],
    pedal_off_s: [0.0, 10.0],
    engine_profile_s: [0.01, 2.0],
    engine_torque_share: [0.1, 1.0],
    sync_tail_rate_radps2: [0.5, 100.0],
    sync_tail_max_radps: [0.5, 50.0],
    min_accel_share: [0.0, 1.0],
    target_min_sync_slips: [1.0, 10.0],
});
crate::ranges!(ShiftCfg as h, "shift" {
    torque_phase_s: [0.01, 5.0],
    min_inertia_phase_s: [0.01, 5.0],
    max_inertia_phase_s: [h.min_inertia_phase_s, 10.0],
    engine_authority: [0.05, 1.0],
    downshift_offgoing_fraction: [0.0, 1.0],
    min_interval_s: [0.0, 60.0],
    settle_s: [0.0, 5.0],
    lugging_idle_fraction: [0.5, 3.0],
    abort_clutch_idle_fraction: [0.3, 0.99],
    abort_engine_idle_fraction: [0.3, 0.99],
    min_oncoming_nm: [0.0, 200.0],
    min_authority_nm: [0.5, 100.0],
    release_torque_share: [0.0, 1.0],
    release_torque_nm: [0.0, 100.0],
    release_timeout_s: [0.0, 5.0],
    release_ramp_s: [0.01, 1.0],
    downshift_sync_radps: [0.1, 50.0],
    downshift_sync_timeout_s: [0.0, 5.0],
    fallback_lock_s: [0.5, 20.0],
    fallback_lock_slip_radps: [0.1, 20.0],
    abort_s: [0.5, 30.0],
    up_kmh_0: [0.0, 400.0],
    up_kmh_100: [0.0, 400.0],
    down_kmh_0: [0.0, 400.0],
    down_kmh_100: [0.0, 400.0],
});
crate::ranges!(KissRoutineCfg as r, "kiss_routine" {
    max_vehicle_kmh: [0.0, 5.0],
    engine_running_idle_fraction: [0.1, 1.0],
    settle_window_s: [0.05, 5.0],
    steady_rpm: [0.1, 100.0],
    approach_rate_mm_per_s: [0.1, 100.0],
    start_before_kiss_mm: [0.05, 5.0],
    hold_s: [0.0, 5.0],
    ramp_rate_mm_per_s: [0.005, 2.0],
    end_beyond_kiss_mm: [0.05, 5.0],
    detect_rpm: [1.0, 1000.0],
    fit_floor_rpm: [0.5, 500.0],
    position_fit_s: [0.05, 10.0],
    timeout_s: [1.0, 600.0],
});

impl Default for TcuConfig {
    fn default() -> Self {
        // The embedded file is checked by the unit test `default_file_is_valid`.
        let mut c = TcuConfig::from_toml_str(DEFAULT_TOML, Path::new("config/tcu.toml"))
            .expect("config/tcu.toml is valid");
        c.physics = Params::default();
        c
    }
}

/// A validation error placed in its file, at the line of its key when the key is found.
fn in_file(e: TcuConfigError, path: &Path, text: &str) -> TcuConfigError {
    let line = e.key().and_then(|k| crate::toml_key::line_of(text, k));
    TcuConfigError::InFile {
        location: match line {
            Some(l) => format!("{} line {l}", path.display()),
            None => path.display().to_string(),
        },
        source: Box::new(e),
    }
}

impl TcuConfig {
    /// Parses and validates a calibration's text (the parameter file is not loaded: `physics`
    /// holds the defaults). `path` only names the file in errors.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<TcuConfig, TcuConfigError> {
        let mut c: TcuConfig = toml::from_str(text).map_err(|e| TcuConfigError::Syntax {
            path: path.to_path_buf(),
            source: Box::new(e),
        })?;
        c.physics = Params::default();
        c.validate().map_err(|e| in_file(e, path, text))?;
        Ok(c)
    }

    /// Loads a calibration file and the parameter file it names.
    pub fn load(path: impl AsRef<Path>) -> Result<TcuConfig, TcuConfigError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| TcuConfigError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut c = Self::from_toml_str(&text, path)?;
        let pp = path
            .parent()
            .unwrap_or_else(|| Path::new("."))
            .join(&c.params);
        c.physics = Params::load(&pp).map_err(|source| TcuConfigError::Params {
            path: pp.clone(),
            source,
        })?;
        if let Some(e) = &c.effects {
            let ep = path.parent().unwrap_or_else(|| Path::new(".")).join(e);
            c.effect_set = EffectSet::load(&ep).map_err(|source| TcuConfigError::Effects {
                path: ep.clone(),
                source,
            })?;
        }
        Ok(c)
    }

    /// The declared range of every key ([`crate::ranges!`] beside each table), then the rules
    /// between keys that are not ranges.
    pub fn validate(&self) -> Result<(), TcuConfigError> {
        self.compensation.check_ranges()?;
        self.estimator.check_ranges()?;
        self.inputs.check_ranges()?;
        self.safety.check_ranges()?;
        self.control.check_ranges()?;
        self.creep.check_ranges()?;
        self.launch.check_ranges()?;
        self.shift.check_ranges()?;
        self.kiss_routine.check_ranges()?;
        self.consistency()
    }

    /// Rules between keys: the housing's plausible band is not empty, a drive stall opens the
    /// clutch below the engine speed of a lugging downshift, a shift's fallback lock comes before
    /// its abort, and every downshift speed lies below its upshift speed (hysteresis).
    fn consistency(&self) -> Result<(), TcuConfigError> {
        let i = &self.inputs;
        let h = &self.shift;
        for (below, above, key, reason) in [
            (
                i.housing_temp_min_c,
                i.housing_temp_max_c,
                "inputs.housing_temp_min_c",
                "must be below inputs.housing_temp_max_c",
            ),
            (
                self.creep.stall_idle_fraction,
                h.lugging_idle_fraction,
                "creep.stall_idle_fraction",
                "must be below shift.lugging_idle_fraction (a lugging engine downshifts before it stalls)",
            ),
            (
                self.kiss_routine.fit_floor_rpm + 1.0,
                self.kiss_routine.detect_rpm,
                "kiss_routine.detect_rpm",
                "must exceed kiss_routine.fit_floor_rpm by at least 1 rpm",
            ),
            (
                h.fallback_lock_s,
                h.abort_s,
                "shift.fallback_lock_s",
                "must be below shift.abort_s (a nearly locked shift completes before it is abandoned)",
            ),
        ] {
            if below >= above {
                return Err(TcuConfigError::Inconsistent {
                    key: key.into(),
                    reason: reason.into(),
                });
            }
        }
        for g in 0..h.up_kmh_0.len() {
            for (down, up, name) in [
                (h.down_kmh_0[g], h.up_kmh_0[g], "down_kmh_0"),
                (h.down_kmh_100[g], h.up_kmh_100[g], "down_kmh_100"),
            ] {
                if down >= up {
                    return Err(TcuConfigError::Inconsistent {
                        key: format!("shift.{name}[{g}]"),
                        reason: format!(
                            "downshift speed {down} km/h must be below the upshift speed {up} km/h"
                        ),
                    });
                }
            }
        }
        Ok(())
    }

    /// The calibration as TOML (without the physical parameters).
    pub fn to_toml_string(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_file_is_valid() {
        let c = TcuConfig::from_toml_str(DEFAULT_TOML, Path::new("tcu.toml")).unwrap();
        assert!(c.compensation.temperature && c.compensation.slip);
        assert_eq!(c.inputs.timeout_cycles, 3);
    }

    #[test]
    fn a_missing_file_keeps_its_io_error_as_the_source() {
        use std::error::Error as _;
        let e = TcuConfig::load("/nonexistent/tcu.toml").unwrap_err();
        let io = e.source().and_then(|s| s.downcast_ref::<std::io::Error>());
        assert_eq!(
            io.map(|e| e.kind()),
            Some(std::io::ErrorKind::NotFound),
            "{e:?}"
        );
        let e = crate::plant::PlantConfig::load(std::path::Path::new("/nonexistent/plant.toml"))
            .unwrap_err();
        assert!(
            e.source().is_some_and(|s| s.is::<std::io::Error>()),
            "{e:?}"
        );
        assert!(crate::error_chain::chain(&e).starts_with("cannot read /nonexistent/plant.toml: "));
    }

    #[test]
    fn errors_name_the_key() {
        let bad = DEFAULT_TOML.replace("clamp_margin = 0.25", "clamp_margin = -1.0");
        let e = TcuConfig::from_toml_str(&bad, Path::new("x.toml")).unwrap_err();
        let msg = format!("{e}: {}", std::error::Error::source(&e).unwrap());
        assert!(msg.contains("control.clamp_margin"), "{msg}");
        // The file and the key's line.
        let line = 1 + DEFAULT_TOML
            .lines()
            .position(|l| l.trim_start().starts_with("clamp_margin ="))
            .unwrap();
        assert!(msg.contains(&format!("x.toml line {line}")), "{msg}");
        let nan = DEFAULT_TOML.replace("clamp_margin = 0.25", "clamp_margin = nan");
        let e = TcuConfig::from_toml_str(&nan, Path::new("x.toml")).unwrap_err();
        assert!(
            crate::error_chain::chain(&e).contains(&format!("x.toml line {line}")),
            "{e}"
        );
        let bad = DEFAULT_TOML.replace("clamp_margin = 0.25", "clamp_margn = 0.25");
        let e = TcuConfig::from_toml_str(&bad, Path::new("x.toml")).unwrap_err();
        assert!(crate::error_chain::chain(&e).contains("clamp_margn"), "{e}");
        let bad = DEFAULT_TOML.replace("down_kmh_0 = [13.0", "down_kmh_0 = [15.0");
        let e = TcuConfig::from_toml_str(&bad, Path::new("x.toml")).unwrap_err();
        assert!(
            crate::error_chain::chain(&e).contains("shift.down_kmh_0[0]"),
            "{e}"
        );
    }

    /// The default calibration with the value of `key` (a key whose name is unique in the file)
    /// replaced by `value`.
    fn with_value(key: &str, value: &str) -> String {
        let lines: Vec<&str> = DEFAULT_TOML
            .lines()
            .filter(|l| l.trim_start().starts_with(&format!("{key} =")))
            .collect();
        assert_eq!(lines.len(), 1, "{key} once in config/tcu.toml");
        let line = lines[0];
        let comment = line.find('#').map_or("", |i| &line[i..]);
        DEFAULT_TOML.replace(line, &format!("{key} = {value} {comment}"))
    }

    /// The chain of a calibration's error (`from_toml_str`), or `None` when it loads.
    fn load_error(text: &str) -> Option<String> {
        TcuConfig::from_toml_str(text, Path::new("x.toml"))
            .err()
            .map(|e| crate::error_chain::chain(&e))
    }

    #[test]
    fn strategy_tunables_out_of_range_are_refused_naming_the_key() {
        // Each key of issue 15's second part with a value just outside its range.
        for (key, bad) in [
            ("safety.antistall_release_idle_fraction", "2.5"),
            ("control.min_lead_dt_s", "0.05"),
            ("control.slip_alarm_cycles", "0"),
            ("control.slip_alarm_boost", "0.5"),
            ("control.blend_release_nm", "0.0"),
            ("creep.torque_rise_nm_per_s", "0.0"),
            ("creep.gain_share", "1.5"),
            ("creep.min_hold_torque_nm", "-0.5"),
            ("creep.stall_idle_fraction", "1.1"),
            ("launch.sync_tail_rate_radps2", "0.0"),
            ("launch.sync_tail_max_radps", "100.0"),
            ("launch.min_accel_share", "1.1"),
            ("launch.target_min_sync_slips", "0.5"),
            ("shift.settle_s", "-0.1"),
            ("shift.lugging_idle_fraction", "12.0"),
            ("shift.abort_clutch_idle_fraction", "1.0"),
            ("shift.abort_engine_idle_fraction", "1.0"),
            ("shift.min_oncoming_nm", "-1.0"),
            ("shift.min_authority_nm", "0.0"),
            ("shift.release_torque_share", "1.5"),
            ("shift.release_torque_nm", "800.0"),
            ("shift.release_timeout_s", "30.0"),
            ("shift.release_ramp_s", "0.0"),
            ("shift.downshift_sync_radps", "0.0"),
            ("shift.downshift_sync_timeout_s", "-0.5"),
            ("shift.fallback_lock_s", "0.0"),
            ("shift.fallback_lock_slip_radps", "0.0"),
            ("shift.abort_s", "40.0"),
        ] {
            let name = key.split_once('.').unwrap().1;
            let e = load_error(&with_value(name, bad)).unwrap_or_else(|| panic!("{key} = {bad}"));
            assert!(e.contains(&format!("`{key}` = ")), "{key}: {e}");
            // NaN fails every range (an integer key refuses it as a type error).
            let nan = load_error(&with_value(name, "nan"));
            assert!(
                nan.is_some_and(|e| e.contains(key) || key == "control.slip_alarm_cycles"),
                "{key} = nan"
            );
        }
    }

    #[test]
    fn a_stall_opens_below_the_lugging_downshift() {
        let ok = with_value("stall_idle_fraction", "0.95");
        assert_eq!(load_error(&ok), None);
        let bad = with_value("stall_idle_fraction", "0.95")
            .replace("lugging_idle_fraction = 1.2", "lugging_idle_fraction = 0.9");
        let e = load_error(&bad).expect("stall above lugging");
        assert!(
            e.contains("inconsistent `creep.stall_idle_fraction`")
                && e.contains("shift.lugging_idle_fraction"),
            "{e}"
        );
        let equal = with_value("lugging_idle_fraction", "0.85");
        assert!(load_error(&equal).is_some_and(|e| e.contains("creep.stall_idle_fraction")));
    }

    #[test]
    fn the_fallback_lock_comes_before_the_shift_abort() {
        assert_eq!(load_error(&with_value("abort_s", "3.5")), None);
        for abort in ["3.0", "2.0"] {
            let e = load_error(&with_value("abort_s", abort)).expect("abort before fallback");
            assert!(
                e.contains("inconsistent `shift.fallback_lock_s`") && e.contains("shift.abort_s"),
                "{e}"
            );
        }
    }

    /// `[kiss_routine]` is optional (a calibration without it loads with the defaults, which are
    /// the file's), and each of its keys is range-checked naming the key.
    #[test]
    fn the_kiss_routine_table_is_optional_and_range_checked() {
        let start = DEFAULT_TOML
            .find("\n[kiss_routine]")
            .expect("table in config/tcu.toml");
        let end = DEFAULT_TOML[start + 1..]
            .find("\n[")
            .map_or(DEFAULT_TOML.len(), |e| start + 1 + e);
        let without = format!("{}{}", &DEFAULT_TOML[..start], &DEFAULT_TOML[end..]);
        let c = TcuConfig::from_toml_str(&without, Path::new("x.toml")).unwrap();
        assert_eq!(c.kiss_routine, KissRoutineCfg::default());
        assert_eq!(TcuConfig::default().kiss_routine, KissRoutineCfg::default());
        for (key, bad) in [
            ("kiss_routine.ramp_rate_mm_per_s", "0.0"),
            ("kiss_routine.detect_rpm", "0.5"),
            ("kiss_routine.timeout_s", "nan"),
            ("kiss_routine.start_before_kiss_mm", "-1.0"),
        ] {
            let name = key.split_once('.').unwrap().1;
            let e = load_error(&with_value(name, bad)).unwrap_or_else(|| panic!("{key} = {bad}"));
            assert!(e.contains(&format!("`{key}` = ")), "{key}: {e}");
        }
        // Within its range but not above the fit floor (4 rpm) by 1 rpm: the rule between keys.
        let e = load_error(&with_value("detect_rpm", "4.5")).expect("detect_rpm = 4.5");
        assert!(
            e.contains("kiss_routine.detect_rpm") && e.contains("fit_floor_rpm"),
            "{e}"
        );
    }

    #[test]
    fn loads_with_its_parameter_file() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/tcu.toml");
        let c = TcuConfig::load(dir).unwrap();
        assert_eq!(c.physics, Params::default());
    }
}

//! The TCU's calibration (`config/tcu.toml`): compensation switches of the torque inverse (paper
//! Sect. 6), estimator, input checks, safety thresholds, the gains of the decoupling controller
//! (23)–(27), creep, launch and shift strategy. The physical parameters the TCU's models use
//! (clutch (13), thermal (17), driveline (22), engine map) come from the parameter file the
//! calibration names (`params = "params.toml"`, relative to the calibration file).
//!
//! Loading checks TOML syntax, unknown and missing keys (serde) and then every value's range;
//! each failure is a [`TcuConfigError`] naming the key.

use crate::model::effects::EffectSet;
use crate::model::params::{Params, ParamsError};
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
    #[error("TCU calibration {path}: {message}")]
    Syntax { path: PathBuf, message: String },
    #[error("TCU calibration: `{key}` = {value} is out of its allowed range {min} ..= {max}")]
    OutOfRange {
        key: String,
        value: f64,
        min: f64,
        max: f64,
    },
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
    pub up_kmh_0: [f64; 5],
    pub up_kmh_100: [f64; 5],
    pub down_kmh_0: [f64; 5],
    pub down_kmh_100: [f64; 5],
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
    /// The physical parameters (loaded from `params`).
    #[serde(skip)]
    pub physics: Params,
    /// The calibrated effects (loaded from `effects`; nominal without).
    #[serde(skip)]
    pub effect_set: EffectSet,
}

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
    let key = match &e {
        TcuConfigError::OutOfRange { key, .. } | TcuConfigError::Inconsistent { key, .. } => {
            Some(key.as_str())
        }
        _ => None,
    };
    let line = key.and_then(|k| key_line(text, k));
    TcuConfigError::InFile {
        location: match line {
            Some(l) => format!("{} line {l}", path.display()),
            None => path.display().to_string(),
        },
        source: Box::new(e),
    }
}

/// The 1-based line of a dotted key (`table.key`) in TOML text: the `key =` line after the
/// `[table]` header.
fn key_line(text: &str, dotted: &str) -> Option<usize> {
    let (table, key) = dotted.rsplit_once('.').unwrap_or(("", dotted));
    let mut current = String::new();
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if let Some(h) = t.strip_prefix('[').and_then(|h| h.split(']').next()) {
            current = h.trim().to_string();
        } else if current == table
            && t.split('=').next().map(str::trim) == Some(key)
            && t.contains('=')
        {
            return Some(i + 1);
        }
    }
    None
}

fn range(key: &str, value: f64, min: f64, max: f64) -> Result<(), TcuConfigError> {
    if value.is_finite() && value >= min && value <= max {
        Ok(())
    } else {
        Err(TcuConfigError::OutOfRange {
            key: key.to_string(),
            value,
            min,
            max,
        })
    }
}

impl TcuConfig {
    /// Parses and validates a calibration's text (the parameter file is not loaded: `physics`
    /// holds the defaults). `path` only names the file in errors.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<TcuConfig, TcuConfigError> {
        let mut c: TcuConfig = toml::from_str(text).map_err(|e| TcuConfigError::Syntax {
            path: path.to_path_buf(),
            message: e.to_string().trim().replace('\n', " "),
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

    /// Range and consistency checks of every key.
    pub fn validate(&self) -> Result<(), TcuConfigError> {
        let c = &self.compensation;
        range(
            "compensation.calibration_temp_c",
            c.calibration_temp_c,
            -40.0,
            400.0,
        )?;
        range(
            "compensation.calibration_slip_radps",
            c.calibration_slip_radps,
            0.0,
            1e6,
        )?;
        let e = &self.estimator;
        if let Some(t) = e.initial_temp_c {
            range("estimator.initial_temp_c", t, -40.0, 400.0)?;
        }
        range(
            "estimator.slip_deadband_radps",
            e.slip_deadband_radps,
            0.0,
            10.0,
        )?;
        let i = &self.inputs;
        range(
            "inputs.timeout_cycles",
            f64::from(i.timeout_cycles),
            1.0,
            100.0,
        )?;
        range(
            "inputs.max_counter_skip",
            f64::from(i.max_counter_skip),
            0.0,
            14.0,
        )?;
        range(
            "inputs.recovery_frames",
            f64::from(i.recovery_frames),
            1.0,
            100.0,
        )?;
        range("inputs.max_engine_rpm", i.max_engine_rpm, 1000.0, 20000.0)?;
        range(
            "inputs.max_engine_rate_rpm_per_s",
            i.max_engine_rate_rpm_per_s,
            100.0,
            1e6,
        )?;
        range(
            "inputs.max_out_rate_rpm_per_s",
            i.max_out_rate_rpm_per_s,
            10.0,
            1e6,
        )?;
        range(
            "inputs.max_shaft_mismatch_radps",
            i.max_shaft_mismatch_radps,
            1.0,
            1e4,
        )?;
        range(
            "inputs.max_lever_engage_out_rpm",
            i.max_lever_engage_out_rpm,
            0.0,
            2000.0,
        )?;
        range(
            "inputs.housing_temp_min_c",
            i.housing_temp_min_c,
            -60.0,
            100.0,
        )?;
        range(
            "inputs.housing_temp_max_c",
            i.housing_temp_max_c,
            0.0,
            250.0,
        )?;
        if i.housing_temp_min_c >= i.housing_temp_max_c {
            return Err(TcuConfigError::Inconsistent {
                key: "inputs.housing_temp_min_c".into(),
                reason: "must be below inputs.housing_temp_max_c".into(),
            });
        }
        range("inputs.max_position_mm", i.max_position_mm, 0.1, 50.0)?;
        let s = &self.safety;
        range(
            "safety.open_rate_mm_per_s",
            s.open_rate_mm_per_s,
            0.1,
            1000.0,
        )?;
        range("safety.over_temp_warn_c", s.over_temp_warn_c, 50.0, 400.0)?;
        range(
            "safety.over_temp_limit_c",
            s.over_temp_limit_c,
            s.over_temp_warn_c,
            400.0,
        )?;
        range(
            "safety.over_temp_engine_torque_nm",
            s.over_temp_engine_torque_nm,
            0.0,
            2000.0,
        )?;
        range(
            "safety.over_temp_hysteresis_c",
            s.over_temp_hysteresis_c,
            0.0,
            100.0,
        )?;
        let k = &self.control;
        range("control.clutch_kp_per_s", k.clutch_kp_per_s, 0.0, 200.0)?;
        range("control.clutch_ki_per_s2", k.clutch_ki_per_s2, 0.0, 5000.0)?;
        range("control.engine_kp_per_s", k.engine_kp_per_s, 0.0, 200.0)?;
        range("control.engine_ki_per_s2", k.engine_ki_per_s2, 0.0, 5000.0)?;
        range("control.max_torque_nm", k.max_torque_nm, 1.0, 5000.0)?;
        range("control.standby_gap_mm", k.standby_gap_mm, 0.0, 5.0)?;
        range("control.open_position_mm", k.open_position_mm, 0.0, 10.0)?;
        range("control.lock_slip_radps", k.lock_slip_radps, 0.01, 20.0)?;
        range("control.lock_cycles", f64::from(k.lock_cycles), 1.0, 100.0)?;
        range(
            "control.lock_undershoot_radps",
            k.lock_undershoot_radps,
            0.0,
            20.0,
        )?;
        range(
            "control.lock_hold_slip_radps",
            k.lock_hold_slip_radps,
            0.0,
            50.0,
        )?;
        range("control.clamp_margin", k.clamp_margin, 0.0, 5.0)?;
        range("control.clamp_offset_nm", k.clamp_offset_nm, 0.0, 500.0)?;
        range(
            "control.clamp_rate_nm_per_s",
            k.clamp_rate_nm_per_s,
            1.0,
            1e5,
        )?;
        range(
            "control.blend_rate_nm_per_s",
            k.blend_rate_nm_per_s,
            1.0,
            1e5,
        )?;
        range("control.slip_alarm_radps", k.slip_alarm_radps, 0.1, 100.0)?;
        range("control.command_delay_s", k.command_delay_s, 0.0, 0.1)?;
        let c = &self.creep;
        range("creep.pedal_on_pct", c.pedal_on_pct, 0.0, 50.0)?;
        range("creep.slip_radps", c.slip_radps, 0.0, 100.0)?;
        range("creep.accel_mps2", c.accel_mps2, 0.01, 10.0)?;
        range("creep.max_torque_nm", c.max_torque_nm, 0.0, 500.0)?;
        range("creep.standstill_kmh", c.standstill_kmh, 0.0, 20.0)?;
        range("creep.stop_engine_rpm", c.stop_engine_rpm, 0.0, 5000.0)?;
        let l = &self.launch;
        range("launch.engine_rpm_0", l.engine_rpm_0, 500.0, 8000.0)?;
        range(
            "launch.engine_rpm_100",
            l.engine_rpm_100,
            l.engine_rpm_0,
            8000.0,
        )?;
        range("launch.lockup_time_s", l.lockup_time_s, 0.2, 10.0)?;
        range(
            "launch.engine_rate_rpm_per_s",
            l.engine_rate_rpm_per_s,
            10.0,
            1e5,
        )?;
        range("launch.jerk_time_s", l.jerk_time_s, 0.0, 5.0)?;
        range("launch.sync_slip_radps", l.sync_slip_radps, 0.5, 200.0)?;
        range("launch.min_sync_time_s", l.min_sync_time_s, 0.0, 5.0)?;
        // The strategy's tunables (issue 15): key, value, smallest, largest.
        for (key, v, lo, hi) in [
            (
                "safety.antistall_free_idle_fraction",
                s.antistall_free_idle_fraction,
                0.1,
                2.0,
            ),
            (
                "safety.antistall_zero_idle_fraction",
                s.antistall_zero_idle_fraction,
                0.0,
                s.antistall_free_idle_fraction - 0.01,
            ),
            (
                "safety.antistall_max_share",
                s.antistall_max_share,
                0.0,
                1.0,
            ),
            (
                "control.clutch_integral_limit_nm",
                k.clutch_integral_limit_nm,
                0.0,
                5000.0,
            ),
            (
                "control.engine_integral_limit_nm",
                k.engine_integral_limit_nm,
                0.0,
                5000.0,
            ),
            ("control.accel_filter_s", k.accel_filter_s, 0.0, 1.0),
            (
                "creep.release_rate_nm_per_s",
                c.release_rate_nm_per_s,
                1.0,
                1e4,
            ),
            (
                "creep.reference_window_radps",
                c.reference_window_radps,
                0.1,
                200.0,
            ),
            (
                "launch.reference_window_radps",
                l.reference_window_radps,
                0.1,
                200.0,
            ),
            ("launch.pedal_off_s", l.pedal_off_s, 0.0, 10.0),
            ("launch.engine_profile_s", l.engine_profile_s, 0.01, 2.0),
            (
                "launch.engine_torque_share",
                l.engine_torque_share,
                0.1,
                1.0,
            ),
        ] {
            range(key, v, lo, hi)?;
        }
        let h = &self.shift;
        range("shift.torque_phase_s", h.torque_phase_s, 0.01, 5.0)?;
        range(
            "shift.min_inertia_phase_s",
            h.min_inertia_phase_s,
            0.01,
            5.0,
        )?;
        range(
            "shift.max_inertia_phase_s",
            h.max_inertia_phase_s,
            h.min_inertia_phase_s,
            10.0,
        )?;
        range("shift.engine_authority", h.engine_authority, 0.05, 1.0)?;
        range(
            "shift.downshift_offgoing_fraction",
            h.downshift_offgoing_fraction,
            0.0,
            1.0,
        )?;
        range("shift.min_interval_s", h.min_interval_s, 0.0, 60.0)?;
        for g in 0..5 {
            for (name, table) in [
                ("up_kmh_0", &h.up_kmh_0),
                ("up_kmh_100", &h.up_kmh_100),
                ("down_kmh_0", &h.down_kmh_0),
                ("down_kmh_100", &h.down_kmh_100),
            ] {
                range(&format!("shift.{name}[{g}]"), table[g], 0.0, 400.0)?;
            }
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

    #[test]
    fn loads_with_its_parameter_file() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/tcu.toml");
        let c = TcuConfig::load(dir).unwrap();
        assert_eq!(c.physics, Params::default());
    }
}

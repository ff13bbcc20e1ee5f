//! The TCU's run-time calibrations: the keys of the calibration file ([`TcuConfig`]) that may
//! change while the core runs ([`super::Tcu::set_calibration`]), how each is read from and
//! written into a calibration, and which are 0/1 switches. The diagnostic adapters reach them on
//! the bus through `crate::diag::values`, which maps each to its unit, limits and XCP address.

use super::config::TcuConfig;

/// One calibration the TCU takes while it runs: a key of the TCU calibration file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Calibration {
    /// `control.clutch_kp_per_s`: clutch speed controller proportional gain (23)–(27).
    ClutchKp,
    /// `control.clutch_ki_per_s2`: clutch speed controller integral gain.
    ClutchKi,
    /// `control.engine_kp_per_s`: engine speed controller proportional gain.
    EngineKp,
    /// `control.engine_ki_per_s2`: engine speed controller integral gain.
    EngineKi,
    /// `launch.lockup_time_s`: launch lock-up time.
    LaunchLockupTime,
    /// `safety.over_temp_warn_c`: over-temperature warning threshold.
    OverTempWarn,
    /// `compensation.temperature`: temperature compensation of the inverse (0/1).
    CompTemperature,
    /// `compensation.slip`: slip compensation of the inverse (0/1).
    CompSlip,
}

impl Calibration {
    /// Every calibration (in the order of their DIDs and XCP addresses).
    pub const ALL: [Calibration; 8] = [
        Calibration::ClutchKp,
        Calibration::ClutchKi,
        Calibration::EngineKp,
        Calibration::EngineKi,
        Calibration::LaunchLockupTime,
        Calibration::OverTempWarn,
        Calibration::CompTemperature,
        Calibration::CompSlip,
    ];

    /// Its key in the calibration file (`table.key`).
    pub fn key(self) -> &'static str {
        use Calibration::*;
        match self {
            ClutchKp => "control.clutch_kp_per_s",
            ClutchKi => "control.clutch_ki_per_s2",
            EngineKp => "control.engine_kp_per_s",
            EngineKi => "control.engine_ki_per_s2",
            LaunchLockupTime => "launch.lockup_time_s",
            OverTempWarn => "safety.over_temp_warn_c",
            CompTemperature => "compensation.temperature",
            CompSlip => "compensation.slip",
        }
    }

    /// Its value in `c`.
    pub fn get(self, c: &TcuConfig) -> f64 {
        use Calibration::*;
        match self {
            ClutchKp => c.control.clutch_kp_per_s,
            ClutchKi => c.control.clutch_ki_per_s2,
            EngineKp => c.control.engine_kp_per_s,
            EngineKi => c.control.engine_ki_per_s2,
            LaunchLockupTime => c.launch.lockup_time_s,
            OverTempWarn => c.safety.over_temp_warn_c,
            CompTemperature => f64::from(u8::from(c.compensation.temperature)),
            CompSlip => f64::from(u8::from(c.compensation.slip)),
        }
    }

    /// `c` with this calibration set to `v`, without any check (see
    /// [`super::Tcu::set_calibration`] for the checked write). A switch is on for any
    /// value ≥ 0.5.
    pub fn put(self, c: &mut TcuConfig, v: f64) {
        use Calibration::*;
        match self {
            ClutchKp => c.control.clutch_kp_per_s = v,
            ClutchKi => c.control.clutch_ki_per_s2 = v,
            EngineKp => c.control.engine_kp_per_s = v,
            EngineKi => c.control.engine_ki_per_s2 = v,
            LaunchLockupTime => c.launch.lockup_time_s = v,
            OverTempWarn => c.safety.over_temp_warn_c = v,
            CompTemperature => c.compensation.temperature = v >= 0.5,
            CompSlip => c.compensation.slip = v >= 0.5,
        }
    }

    /// Whether the value is a 0/1 switch.
    pub fn is_switch(self) -> bool {
        matches!(self, Calibration::CompTemperature | Calibration::CompSlip)
    }
}

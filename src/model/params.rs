//! Physical parameters of the dry dual-clutch driveline, loaded from one TOML file
//! (`config/params.toml`) that the plant, the TCU and the tools all read.
//!
//! Groups: [`ClutchParams`] (friction (4)–(6), flat spring (7)–(10), everything the torque
//! characteristic (13) needs), [`ThermalParams5`] ((16a)–(16e)), [`ThermalParams3`] ((17a)–(17c)),
//! [`DrivelineParams`] ((18)–(20) plus grade, brake, gears and synchronisers), [`EngineParams`],
//! [`ActuatorParams`] and [`IntegratorParams`]. Every key is a plain number whose unit is in its
//! name; every key is required and has an allowed range, declared once beside it
//! (`param_table!`, which declares it through [`crate::ranges!`]). Loading checks, in order: TOML
//! syntax, the tables and keys (serde: present, none unknown, numbers), the ranges, then
//! cross-field consistency (e.g. the kiss point stays below `x_to_max_mm`, the spring force (10)
//! is strictly increasing). Each failure is a [`ParamsError`] naming the key and its line.

use crate::ranges::Ranged;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The parameter file compiled into the binary; [`Params::default`] is this file.
pub const DEFAULT_TOML: &str = include_str!("../../config/params.toml");

/// Temperature range (°C) over which the torque characteristic must be well defined.
pub(crate) const THETA_VALID_C: (f64, f64) = (-40.0, 400.0);

/// Allowed range of one key.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spec {
    /// Key name inside its table.
    pub key: &'static str,
    /// Smallest allowed value (inclusive).
    pub min: f64,
    /// Largest allowed value (inclusive).
    pub max: f64,
}

/// Errors of loading and validating parameters. `key` is always `table.key`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamsError {
    #[error("cannot read parameter file {path}")]
    Io {
        path: PathBuf,
        #[source]
        source: crate::io_error::IoError,
    },
    #[error("parameter file is not valid TOML")]
    Syntax {
        #[source]
        source: Box<toml::de::Error>,
    },
    /// A table or key missing or unknown, or a value of the wrong type (serde's message, with
    /// the line, the key and the text around it).
    #[error("parameter file does not have the expected tables and keys")]
    Structure {
        #[source]
        source: Box<toml::de::Error>,
    },
    #[error(transparent)]
    OutOfRange(#[from] crate::ranges::RangeError),
    #[error("inconsistent parameter `{key}`: {reason}")]
    Inconsistent { key: String, reason: String },
    /// An error of a key placed at the key's line of the file ([`Params::load`]).
    #[error("line {line}")]
    AtLine {
        line: usize,
        #[source]
        source: Box<ParamsError>,
    },
}

impl ParamsError {
    /// The `table.key` the error is about, if any.
    pub fn key(&self) -> Option<&str> {
        match self {
            ParamsError::OutOfRange(crate::ranges::RangeError { key, .. })
            | ParamsError::Inconsistent { key, .. } => Some(key),
            ParamsError::AtLine { source, .. } => source.key(),
            _ => None,
        }
    }
}

macro_rules! param_table {
    (
        $(#[$m:meta])*
        $name:ident, $table:literal {
            $( $(#[$fm:meta])* $field:ident : [$min:expr, $max:expr] ),* $(,)?
        }
    ) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
        #[serde(deny_unknown_fields)]
        pub struct $name {
            $( $(#[$fm])* pub $field: f64, )*
        }

        impl $name {
            /// Allowed range of each key, in declaration order.
            pub const SPECS: &'static [Spec] = &[
                $( Spec { key: stringify!($field), min: $min, max: $max }, )*
            ];

            /// Values in the order of [`Self::SPECS`].
            pub fn values(&self) -> Vec<f64> {
                vec![ $( self.$field, )* ]
            }
        }

        $crate::ranges!($name as _p, $table { $( $field: [$min, $max] ),* });
    };
}

param_table! {
    /// Clutch friction, geometry and flat spring: everything (13) needs.
    ClutchParams, "clutch" {
        /// Inner facing radius R1 (m).
        r1_m: [0.01, 0.5],
        /// Outer facing radius R2 (m).
        r2_m: [0.01, 0.5],
        /// Static (low sliding speed) friction coefficient μ_s.
        mu_s: [0.01, 1.0],
        /// Friction shape parameter γ of (4) (s/m).
        gamma_s_per_m: [0.001, 1000.0],
        /// c1 of (5).
        c1: [-1.0, 1.0],
        /// c2 of (5) (rad/°C).
        c2_rad_per_c: [-1.0, 1.0],
        /// c3 of (5) (rad).
        c3_rad: [-10.0, 10.0],
        /// c4 of (5).
        c4: [0.0, 1.0],
        /// Slope λ of (7) (mm of compression per mm of bearing travel).
        lambda: [1e-3, 10.0],
        /// λ0 of (9): kiss point at θ_a (mm).
        x_isp0_mm: [0.0, 50.0],
        /// λ1 of (9) (mm/°C).
        x_isp1_mm_per_c: [-0.1, 0.1],
        /// λ2 of (9) (mm/°C²).
        x_isp2_mm_per_c2: [-1e-3, 1e-3],
        /// Room temperature θ_a of (9) (°C).
        theta_a_c: [-40.0, 60.0],
        /// Bearing position of full flat-spring compression x_to,max (mm).
        x_to_max_mm: [0.1, 50.0],
        /// p1 of (10) (N/m).
        p1_n_per_m: [0.0, 1e9],
        /// p2 of (10) (N/m²).
        p2_n_per_m2: [-1e13, 1e13],
        /// p3 of (10) (N/m³).
        p3_n_per_m3: [-1e17, 1e17],
    }
}

param_table! {
    /// 5-state thermal model (16): rates in 1/s, heating gains in K/J.
    ThermalParams5, "thermal5" {
        alpha1_per_s: [0.0, 10.0],
        alpha2_per_s: [0.0, 10.0],
        alpha3_k_per_j: [0.0, 1.0],
        alpha4_per_s: [0.0, 10.0],
        alpha5_per_s: [0.0, 10.0],
        alpha6_per_s: [0.0, 10.0],
        alpha7_k_per_j: [0.0, 1.0],
        alpha8_per_s: [0.0, 10.0],
        alpha9_k_per_j: [0.0, 1.0],
    }
}

param_table! {
    /// 3-state thermal model (17): α̃1, α̃2, α̃4 in 1/s, α̃3 in K/J.
    ThermalParams3, "thermal3" {
        alpha1_per_s: [0.0, 10.0],
        alpha2_per_s: [0.0, 10.0],
        alpha3_k_per_j: [0.0, 1.0],
        alpha4_per_s: [0.0, 10.0],
    }
}

param_table! {
    /// Driveline (18)–(20), road load (19), grade, brake, gears and synchronisers.
    DrivelineParams, "driveline" {
        /// Engine + flywheel inertia J_eq (kg·m²).
        j_eq_kgm2: [1e-3, 10.0],
        /// Odd clutch disk + input shaft inertia J_c1 (kg·m²).
        j_c1_kgm2: [1e-4, 1.0],
        /// Even clutch disk + input shaft inertia J_c2 (kg·m²).
        j_c2_kgm2: [1e-4, 1.0],
        /// Wheels, output shaft and final drive inertia, added to m·R_w² in J_d (kg·m²).
        j_wheels_kgm2: [0.0, 100.0],
        /// Vehicle mass (kg).
        vehicle_mass_kg: [100.0, 40000.0],
        /// Wheel radius R_w (m).
        wheel_radius_m: [0.1, 1.0],
        /// Final drive ratio i_f.
        final_drive: [1.0, 10.0],
        ratio_g1: [0.2, 10.0],
        ratio_g2: [0.2, 10.0],
        ratio_g3: [0.2, 10.0],
        ratio_g4: [0.2, 10.0],
        ratio_g5: [0.2, 10.0],
        ratio_g6: [0.2, 10.0],
        /// Reverse ratio magnitude (even shaft; the output turns backwards).
        ratio_reverse: [0.2, 10.0],
        /// f0 of (19) (N·m).
        f0_nm: [0.0, 2000.0],
        /// f1 of (19) (N·m·s/m).
        f1_nm_s_per_m: [0.0, 100.0],
        /// f2 of (19) (N·m·s²/m²).
        f2_nm_s2_per_m2: [0.0, 10.0],
        gravity_m_per_s2: [9.0, 10.0],
        /// Speed over which the constant load and the brake are regularised (m/s).
        load_smoothing_m_per_s: [1e-4, 1.0],
        /// Wheel brake torque at full brake (N·m).
        brake_max_nm: [0.0, 50000.0],
        /// Time a gear fork needs to select a gear (s).
        gear_select_time_s: [0.0, 5.0],
        /// Synchroniser torque capacity on the input shaft (N·m).
        sync_torque_nm: [0.1, 1000.0],
        /// Synchroniser friction regularisation speed (rad/s).
        sync_smoothing_radps: [1e-3, 100.0],
        /// The dog engages once the shaft is within this speed of the gear's speed (rad/s).
        sync_tolerance_radps: [1e-3, 100.0],
    }
}

param_table! {
    /// Engine: full-load curve, motoring drag, torque lag and idle governor.
    EngineParams, "engine" {
        peak_torque_nm: [10.0, 2000.0],
        peak_speed_rpm: [500.0, 10000.0],
        idle_speed_rpm: [300.0, 3000.0],
        cutoff_speed_rpm: [1000.0, 20000.0],
        torque_at_idle_nm: [0.0, 2000.0],
        torque_at_cutoff_nm: [0.0, 2000.0],
        cutoff_band_rpm: [1.0, 2000.0],
        stall_speed_rpm: [1.0, 3000.0],
        drag0_nm: [0.0, 500.0],
        drag1_nm_per_krpm: [0.0, 500.0],
        torque_lag_s: [1e-3, 2.0],
        idle_kp_nm_per_radps: [0.0, 100.0],
        idle_ki_nm_per_rad: [0.0, 1000.0],
        idle_int_max_nm: [0.0, 2000.0],
    }
}

param_table! {
    /// Clutch actuators: rate-limited first-order lags on the bearing position.
    ActuatorParams, "actuator" {
        tau_s: [1e-4, 1.0],
        rate_mm_per_s: [0.1, 10000.0],
        x_min_mm: [0.0, 50.0],
        x_max_mm: [0.1, 50.0],
    }
}

param_table! {
    /// Fixed-step integrator.
    IntegratorParams, "integrator" {
        /// RK4 step (s).
        dt_s: [1e-6, 0.1],
        /// Stick/slip events located inside one step at most (integer).
        max_events_per_step: [1.0, 16.0],
    }
}

/// All parameters; [`Params::default`] equals `config/params.toml`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    pub clutch: ClutchParams,
    pub thermal5: ThermalParams5,
    pub thermal3: ThermalParams3,
    pub driveline: DrivelineParams,
    pub engine: EngineParams,
    pub actuator: ActuatorParams,
    pub integrator: IntegratorParams,
}

/// The embedded file parsed once (checked by the unit test `default_file_is_valid`).
static DEFAULT: std::sync::LazyLock<Params> = std::sync::LazyLock::new(|| {
    Params::from_toml_str(DEFAULT_TOML).expect("config/params.toml is valid")
});

impl Default for Params {
    fn default() -> Self {
        *DEFAULT
    }
}

impl Params {
    /// Parses and validates a parameter file's text: TOML syntax, then the tables and keys
    /// (serde: every key required, none unknown, numbers only), then every key's declared range
    /// and the rules between keys.
    pub fn from_toml_str(text: &str) -> Result<Params, ParamsError> {
        // One parse when the file is well-formed; a failure is told apart (syntax or structure)
        // by parsing the text as a plain table.
        let p: Params =
            toml::from_str(text).map_err(|source| match text.parse::<toml::Table>() {
                Err(syntax) => ParamsError::Syntax {
                    source: Box::new(syntax),
                },
                Ok(_) => ParamsError::Structure {
                    source: Box::new(source),
                },
            })?;
        p.validate()?;
        Ok(p)
    }

    /// Reads, parses and validates a parameter file.
    pub fn load(path: impl AsRef<Path>) -> Result<Params, ParamsError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| ParamsError::Io {
            path: path.to_path_buf(),
            source: e.into(),
        })?;
        Params::from_toml_str(&text).map_err(|e| {
            match e.key().and_then(|k| crate::toml_key::line_of(&text, k)) {
                Some(line) => ParamsError::AtLine {
                    line,
                    source: Box::new(e),
                },
                None => e,
            }
        })
    }

    /// Serialises to TOML (without the comments of the original file).
    pub fn to_toml_string(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }

    /// Checks every range and the cross-field consistency.
    pub fn validate(&self) -> Result<(), ParamsError> {
        self.clutch.validate()?;
        self.thermal5.check_ranges()?;
        self.thermal3.check_ranges()?;
        self.driveline.check_ranges()?;
        self.engine.validate()?;
        self.actuator.validate()?;
        self.integrator.check_ranges()?;
        if self.integrator.max_events_per_step.fract() != 0.0 {
            return Err(inconsistent(
                "integrator.max_events_per_step",
                "must be an integer",
            ));
        }
        Ok(())
    }
}

fn inconsistent(key: &str, reason: impl Into<String>) -> ParamsError {
    ParamsError::Inconsistent {
        key: key.to_string(),
        reason: reason.into(),
    }
}

impl ClutchParams {
    /// Range and consistency checks of the torque characteristic.
    pub fn validate(&self) -> Result<(), ParamsError> {
        self.check_ranges()?;
        if self.r2_m <= self.r1_m {
            return Err(inconsistent(
                "clutch.r2_m",
                "must be larger than clutch.r1_m",
            ));
        }
        // Kiss point (9) inside (0, x_to_max) over the whole valid temperature range: check the
        // ends and the vertex of the parabola.
        let (lo, hi) = THETA_VALID_C;
        let mut thetas = vec![lo, hi];
        if self.x_isp2_mm_per_c2 != 0.0 {
            let v = self.theta_a_c - self.x_isp1_mm_per_c / (2.0 * self.x_isp2_mm_per_c2);
            if v > lo && v < hi {
                thetas.push(v);
            }
        }
        let mut u_max_mm: f64 = 0.0;
        for th in thetas {
            let d = th - self.theta_a_c;
            let x = self.x_isp2_mm_per_c2 * d * d + self.x_isp1_mm_per_c * d + self.x_isp0_mm;
            if !(x > 0.0 && x < self.x_to_max_mm) {
                return Err(inconsistent(
                    "clutch.x_isp0_mm",
                    format!(
                        "kiss point x_ISP({th:.0} °C) = {x:.3} mm must lie in (0, x_to_max_mm = {}) for {lo}..{hi} °C",
                        self.x_to_max_mm
                    ),
                ));
            }
            u_max_mm = u_max_mm.max(self.lambda * (self.x_to_max_mm - x));
        }
        // Spring (10) strictly increasing on [0, u_max]: F'(u) = 3 p3 u² + 2 p2 u + p1 > 0.
        let u_max = u_max_mm * 1e-3;
        let dfdu =
            |u: f64| 3.0 * self.p3_n_per_m3 * u * u + 2.0 * self.p2_n_per_m2 * u + self.p1_n_per_m;
        let mut us = vec![0.0, u_max];
        if self.p3_n_per_m3 != 0.0 {
            let v = -self.p2_n_per_m2 / (3.0 * self.p3_n_per_m3);
            if v > 0.0 && v < u_max {
                us.push(v);
            }
        }
        for u in us {
            if dfdu(u) <= 0.0 {
                return Err(inconsistent(
                    "clutch.p2_n_per_m2",
                    format!(
                        "flat-spring force (10) must increase strictly with compression on 0..{u_max_mm:.3} mm (dF/du = {:.4e} N/m at u = {:.4} mm)",
                        dfdu(u),
                        u * 1e3
                    ),
                ));
            }
        }
        Ok(())
    }
}

impl EngineParams {
    fn validate(&self) -> Result<(), ParamsError> {
        self.check_ranges()?;
        if !(self.idle_speed_rpm < self.peak_speed_rpm
            && self.peak_speed_rpm < self.cutoff_speed_rpm)
        {
            return Err(inconsistent(
                "engine.peak_speed_rpm",
                "must lie strictly between engine.idle_speed_rpm and engine.cutoff_speed_rpm",
            ));
        }
        if self.torque_at_idle_nm > self.peak_torque_nm
            || self.torque_at_cutoff_nm > self.peak_torque_nm
        {
            return Err(inconsistent(
                "engine.peak_torque_nm",
                "must be at least engine.torque_at_idle_nm and engine.torque_at_cutoff_nm",
            ));
        }
        if self.stall_speed_rpm >= self.idle_speed_rpm {
            return Err(inconsistent(
                "engine.stall_speed_rpm",
                "must be below engine.idle_speed_rpm",
            ));
        }
        Ok(())
    }
}

impl ActuatorParams {
    fn validate(&self) -> Result<(), ParamsError> {
        self.check_ranges()?;
        if self.x_max_mm <= self.x_min_mm {
            return Err(inconsistent(
                "actuator.x_max_mm",
                "must exceed actuator.x_min_mm",
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_file_is_valid() {
        let p = Params::from_toml_str(DEFAULT_TOML).unwrap();
        assert_eq!(p.clutch.r1_m, 0.075);
        assert_eq!(p.clutch.p3_n_per_m3, 9.44e12);
        assert_eq!(p.thermal5.alpha9_k_per_j, 1.8e-4);
        assert_eq!(p.driveline.ratio_g1, 4.15);
        assert_eq!(p.engine.peak_torque_nm, 215.0);
        assert_eq!(p.actuator.rate_mm_per_s, 100.0);
        assert_eq!(p.integrator.dt_s, 1e-3);
        assert_eq!(p, Params::default());
    }

    /// The chain of an error: the key and the line are in it.
    fn chain(e: &ParamsError) -> String {
        crate::error_chain::chain(e)
    }

    #[test]
    fn a_missing_key_is_named_with_its_line() {
        let text = DEFAULT_TOML.replace("mu_s = 0.27", "");
        let e = Params::from_toml_str(&text).unwrap_err();
        assert!(matches!(e, ParamsError::Structure { .. }), "{e:?}");
        assert!(chain(&e).contains("missing field `mu_s`"), "{}", chain(&e));
        let clutch = 1 + DEFAULT_TOML.lines().position(|l| l == "[clutch]").unwrap();
        assert!(
            chain(&e).contains(&format!("line {clutch}")),
            "{}",
            chain(&e)
        );
    }

    #[test]
    fn out_of_range_is_named() {
        let text = DEFAULT_TOML.replace("tau_s = 0.02", "tau_s = 5.0");
        let e = Params::from_toml_str(&text).unwrap_err();
        assert!(
            matches!(&e, ParamsError::OutOfRange(r) if r.key == "actuator.tau_s" && r.value == 5.0),
            "{e:?}"
        );
        assert!(e.to_string().contains("actuator.tau_s"));
        assert_eq!(e.key(), Some("actuator.tau_s"));
        let text = DEFAULT_TOML.replace("tau_s = 0.02", "tau_s = nan");
        assert!(matches!(
            Params::from_toml_str(&text).unwrap_err(),
            ParamsError::OutOfRange(r) if r.key == "actuator.tau_s" && r.value.is_nan()
        ));
    }

    #[test]
    fn unknown_and_wrong_type_rejected() {
        let text = DEFAULT_TOML.replace("tau_s = 0.02", "tau_s = 0.02\ntau_ms = 20");
        let e = Params::from_toml_str(&text).unwrap_err();
        assert!(
            chain(&e).contains("unknown field `tau_ms`"),
            "{}",
            chain(&e)
        );
        let text = DEFAULT_TOML.replace("tau_s = 0.02", "tau_s = \"fast\"");
        let e = Params::from_toml_str(&text).unwrap_err();
        let line = 1 + text
            .lines()
            .position(|l| l.starts_with("tau_s = \"fast"))
            .unwrap();
        assert!(chain(&e).contains(&format!("line {line}")), "{}", chain(&e));
        assert!(chain(&e).contains("tau_s"), "{}", chain(&e));
        assert!(matches!(
            Params::from_toml_str("[clutch\n").unwrap_err(),
            ParamsError::Syntax { .. }
        ));
    }

    /// A file that cannot be read or parsed keeps the I/O or TOML error as its cause.
    #[test]
    fn read_and_syntax_errors_keep_their_cause() {
        use std::error::Error as _;
        let e = Params::load("/nonexistent/p.toml").unwrap_err();
        let io = e
            .source()
            .and_then(|s| s.downcast_ref::<crate::io_error::IoError>());
        assert_eq!(io.map(|i| i.kind()), Some(std::io::ErrorKind::NotFound));
        assert!(crate::error_chain::chain(&e)
            .starts_with("cannot read parameter file /nonexistent/p.toml: "));
        let e = Params::from_toml_str("[clutch\n").unwrap_err();
        let chain = crate::error_chain::chain(&e);
        assert!(
            chain.starts_with("parameter file is not valid TOML: "),
            "{chain}"
        );
        assert!(chain.contains("line 1"), "{chain}");
    }

    #[test]
    fn inconsistent_spring_rejected() {
        let mut p = Params::default();
        p.clutch.p2_n_per_m2 = -1e10;
        assert!(
            matches!(p.validate().unwrap_err(), ParamsError::Inconsistent { key, .. } if key == "clutch.p2_n_per_m2")
        );
        let mut p = Params::default();
        p.clutch.x_isp0_mm = 7.5;
        assert!(
            matches!(p.validate().unwrap_err(), ParamsError::Inconsistent { key, .. } if key == "clutch.x_isp0_mm")
        );
    }

    #[test]
    fn round_trip_through_toml() {
        let p = Params::default();
        assert_eq!(Params::from_toml_str(&p.to_toml_string()).unwrap(), p);
    }
}

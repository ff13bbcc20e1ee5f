//! `ddct sim` scenario files: a driver (the plant's driver-scenario columns `t_s`, `pedal_pct`,
//! `brake`, `lever`, `grade_pct`, inline in `[driver]` or in a file named by `driver = "..."`),
//! the plant's initial conditions (`[initial]`, as in the plant configuration), overrides of the
//! TCU calibration (`[tcu]`) and the simulated duration.
//!
//! ```toml
//! description = "launch at 50 % pedal on the flat"
//! duration_s = 6.0
//! [driver]
//! t_s       = [0.0, 1.0, 1.0, 6.0]
//! pedal_pct = [0.0, 0.0, 50.0, 50.0]
//! brake     = [1.0, 1.0, 0.0, 0.0]
//! lever     = ["D", "D", "D", "D"]
//! [initial]
//! temperature_c = 40.0     # every thermal mass of the plant
//! housing_c = 40.0
//! [tcu]
//! temperature_compensation = true
//! slip_compensation = true
//! initial_temp_c = 40.0    # the TCU's estimate at start (a TCU that kept it across a restart)
//! ```

use crate::can::messages::GearLever;
use crate::tcu::TcuConfig;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Errors of scenario files; `key` names the offending key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScenarioError {
    #[error("cannot read scenario {path}: {message}")]
    Io { path: PathBuf, message: String },
    #[error("scenario {path}: not valid TOML: {message}")]
    Syntax { path: PathBuf, message: String },
    #[error("scenario {path}: `{key}`: {reason}")]
    Key {
        path: PathBuf,
        key: String,
        reason: String,
    },
}

fn key_err(path: &Path, key: impl Into<String>, reason: impl Into<String>) -> ScenarioError {
    ScenarioError::Key {
        path: path.to_path_buf(),
        key: key.into(),
        reason: reason.into(),
    }
}

/// What the driver does at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriverSample {
    /// Pedal fraction 0..1.
    pub pedal: f64,
    /// Brake fraction 0..1.
    pub brake: f64,
    pub lever: GearLever,
    /// Grade, rise over run.
    pub grade: f64,
}

/// Driver points over time (pedal and grade linear, brake and lever held).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DriverTable {
    pub t_s: Vec<f64>,
    pub pedal_pct: Vec<f64>,
    pub brake: Vec<f64>,
    pub lever: Vec<GearLever>,
    pub grade_pct: Vec<f64>,
}

fn index_before(t: &[f64], x: f64) -> usize {
    // Last index with t[i] <= x (0 before the first point).
    match t.iter().rposition(|&ti| ti <= x) {
        Some(i) => i,
        None => 0,
    }
}

fn linear(t: &[f64], v: &[f64], x: f64) -> f64 {
    if t.is_empty() {
        return 0.0;
    }
    if x <= t[0] {
        return v[0];
    }
    let i = index_before(t, x);
    if i + 1 >= t.len() {
        return v[t.len() - 1];
    }
    let (t0, t1) = (t[i], t[i + 1]);
    if t1 <= t0 {
        return v[i + 1];
    }
    v[i] + (v[i + 1] - v[i]) * (x - t0) / (t1 - t0)
}

impl DriverTable {
    pub fn sample(&self, t_s: f64) -> DriverSample {
        if self.t_s.is_empty() {
            return DriverSample {
                pedal: 0.0,
                brake: 0.0,
                lever: GearLever::P,
                grade: 0.0,
            };
        }
        let i = index_before(&self.t_s, t_s);
        DriverSample {
            pedal: linear(&self.t_s, &self.pedal_pct, t_s) / 100.0,
            brake: self.brake[i],
            lever: self.lever[i],
            grade: linear(&self.t_s, &self.grade_pct, t_s) / 100.0,
        }
    }

    pub fn last_time(&self) -> f64 {
        self.t_s.last().copied().unwrap_or(0.0)
    }

    fn from_table(path: &Path, doc: &toml::Table) -> Result<Self, ScenarioError> {
        for k in doc.keys() {
            if ![
                "description",
                "t_s",
                "pedal_pct",
                "brake",
                "lever",
                "grade_pct",
            ]
            .contains(&k.as_str())
            {
                return Err(key_err(path, format!("driver.{k}"), "unknown key"));
            }
        }
        let nums = |key: &str| -> Result<Option<Vec<f64>>, ScenarioError> {
            match doc.get(key) {
                None => Ok(None),
                Some(toml::Value::Array(a)) => a
                    .iter()
                    .enumerate()
                    .map(|(i, v)| match v {
                        toml::Value::Float(f) if f.is_finite() => Ok(*f),
                        toml::Value::Integer(n) => Ok(*n as f64),
                        _ => Err(key_err(
                            path,
                            format!("driver.{key}[{i}]"),
                            "must be a number",
                        )),
                    })
                    .collect::<Result<Vec<_>, _>>()
                    .map(Some),
                Some(_) => Err(key_err(path, format!("driver.{key}"), "must be an array")),
            }
        };
        let t = nums("t_s")?.ok_or_else(|| key_err(path, "driver.t_s", "missing"))?;
        if t.is_empty() {
            return Err(key_err(path, "driver.t_s", "needs at least one point"));
        }
        if t.windows(2).any(|w| w[1] < w[0]) || t[0] < 0.0 {
            return Err(key_err(
                path,
                "driver.t_s",
                "times must be >= 0 and non-decreasing",
            ));
        }
        let n = t.len();
        let col = |key: &str, default: f64, lo: f64, hi: f64| -> Result<Vec<f64>, ScenarioError> {
            let v = nums(key)?.unwrap_or_else(|| vec![default; n]);
            if v.len() != n {
                return Err(key_err(
                    path,
                    format!("driver.{key}"),
                    format!("has {} values, t_s has {n}", v.len()),
                ));
            }
            if let Some((i, x)) = v.iter().enumerate().find(|(_, x)| !(lo..=hi).contains(*x)) {
                return Err(key_err(
                    path,
                    format!("driver.{key}[{i}]"),
                    format!("{x} is outside {lo} ..= {hi}"),
                ));
            }
            Ok(v)
        };
        let pedal_pct = col("pedal_pct", 0.0, 0.0, 100.0)?;
        let brake = col("brake", 0.0, 0.0, 1.0)?;
        let grade_pct = col("grade_pct", 0.0, -50.0, 50.0)?;
        let lever = match doc.get("lever") {
            None => vec![GearLever::D; n],
            Some(toml::Value::Array(a)) if a.len() == n => a
                .iter()
                .enumerate()
                .map(|(i, v)| {
                    v.as_str()
                        .and_then(|s| GearLever::ALL.iter().find(|g| g.label() == s).copied())
                        .ok_or_else(|| {
                            key_err(path, format!("driver.lever[{i}]"), "must be P, R, N or D")
                        })
                })
                .collect::<Result<Vec<_>, _>>()?,
            Some(_) => {
                return Err(key_err(
                    path,
                    "driver.lever",
                    format!("must be an array of {n} lever positions"),
                ))
            }
        };
        Ok(DriverTable {
            t_s: t,
            pedal_pct,
            brake,
            lever,
            grade_pct,
        })
    }
}

/// Initial conditions of the plant (a subset of the plant configuration's `[initial]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Initial {
    pub engine_rpm: f64,
    pub vehicle_kmh: f64,
    pub gear_odd: u8,
    pub gear_even: u8,
    pub temperature_c: f64,
    pub housing_c: f64,
}

impl Default for Initial {
    fn default() -> Self {
        Self {
            engine_rpm: 800.0,
            vehicle_kmh: 0.0,
            gear_odd: 0,
            gear_even: 0,
            temperature_c: 25.0,
            housing_c: 25.0,
        }
    }
}

/// Overrides of the TCU calibration.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TcuOverrides {
    pub temperature_compensation: Option<bool>,
    pub slip_compensation: Option<bool>,
    pub initial_temp_c: Option<f64>,
}

impl TcuOverrides {
    /// Applies the overrides to a calibration.
    pub fn apply(&self, cfg: &mut TcuConfig) {
        if let Some(v) = self.temperature_compensation {
            cfg.compensation.temperature = v;
        }
        if let Some(v) = self.slip_compensation {
            cfg.compensation.slip = v;
        }
        if let Some(v) = self.initial_temp_c {
            cfg.estimator.initial_temp_c = Some(v);
        }
    }
}

/// A `ddct sim` scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct SimScenario {
    pub name: String,
    pub description: String,
    pub duration_s: f64,
    pub driver: DriverTable,
    pub initial: Initial,
    pub tcu: TcuOverrides,
}

impl SimScenario {
    pub fn load(path: &Path) -> Result<Self, ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(|e| ScenarioError::Io {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        Self::from_toml_str(path, &text)
    }

    pub fn from_toml_str(path: &Path, text: &str) -> Result<Self, ScenarioError> {
        let doc: toml::Table =
            text.parse()
                .map_err(|e: toml::de::Error| ScenarioError::Syntax {
                    path: path.to_path_buf(),
                    message: e.to_string().trim().replace('\n', " "),
                })?;
        for k in doc.keys() {
            if !["description", "duration_s", "driver", "initial", "tcu"].contains(&k.as_str()) {
                return Err(key_err(path, k.clone(), "unknown key"));
            }
        }
        let driver = match doc.get("driver") {
            Some(toml::Value::Table(t)) => DriverTable::from_table(path, t)?,
            Some(toml::Value::String(f)) => {
                let p = path.parent().unwrap_or(Path::new(".")).join(f);
                let text = std::fs::read_to_string(&p).map_err(|e| ScenarioError::Io {
                    path: p.clone(),
                    message: e.to_string(),
                })?;
                let t: toml::Table =
                    text.parse()
                        .map_err(|e: toml::de::Error| ScenarioError::Syntax {
                            path: p.clone(),
                            message: e.to_string(),
                        })?;
                DriverTable::from_table(&p, &t)?
            }
            _ => return Err(key_err(path, "driver", "missing (a table or a file name)")),
        };
        let initial: Initial = match doc.get("initial") {
            None => Initial::default(),
            Some(v) => v
                .clone()
                .try_into()
                .map_err(|e: toml::de::Error| key_err(path, "initial", e.message().to_string()))?,
        };
        let tcu: TcuOverrides = match doc.get("tcu") {
            None => TcuOverrides::default(),
            Some(v) => v
                .clone()
                .try_into()
                .map_err(|e: toml::de::Error| key_err(path, "tcu", e.message().to_string()))?,
        };
        let duration_s = match doc.get("duration_s") {
            None => driver.last_time(),
            Some(toml::Value::Float(f)) => *f,
            Some(toml::Value::Integer(n)) => *n as f64,
            Some(_) => return Err(key_err(path, "duration_s", "must be a number")),
        };
        if !(duration_s.is_finite() && duration_s > 0.0 && duration_s <= 3600.0) {
            return Err(key_err(
                path,
                "duration_s",
                format!("{duration_s} is outside 0 < d <= 3600"),
            ));
        }
        let description = doc
            .get("description")
            .and_then(|v| v.as_str())
            .unwrap_or("")
            .to_string();
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scenario".into());
        Ok(SimScenario {
            name,
            description,
            duration_s,
            driver,
            initial,
            tcu,
        })
    }
}

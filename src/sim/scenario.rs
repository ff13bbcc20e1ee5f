//! `ddct sim` scenario files. A scenario is a plant configuration (the plant daemon's format,
//! `config/plant.toml`) with a built-in driver (the plant's driver-scenario format,
//! `config/scenarios/driver_*.toml`: `t_s`, `pedal_pct`, `brake`, `lever`, `grade_pct`), plus
//! overrides of the TCU calibration and the simulated duration:
//!
//! ```toml
//! description = "launch at 50 % pedal on the flat"
//! duration_s = 6.0
//! # plant = "../plant.toml"   # base plant configuration (default: the built-in config/plant.toml)
//! driver = "driver_launch_50.toml"   # a driver-scenario file, or an inline [driver] table
//! [initial]                # merged key by key into the plant configuration's [initial]
//! temperature_c = 40.0
//! [tcu]
//! temperature_compensation = true
//! slip_compensation = true
//! initial_temp_c = 40.0    # the TCU's estimate at its start (a TCU that kept it across a restart)
//! ```
//!
//! An optional `[limits]` table holds the run's pass/fail limits ([`super::verdict`]).
//!
//! One format for every command: a driver scenario alone (`t_s`, `pedal_pct`, … at the top) is
//! read as a sim scenario with the built-in plant, and `ddct plant --scenario` takes a sim
//! scenario too (its plant configuration and driver).
//!
//! The plant tables `[initial]`, `[housing]`, `[sensors]` and `[inputs]` merge key by key into the
//! base configuration; `[effects]` and `[[faults]]` replace the base's. Relative file names are
//! relative to the scenario file.

use super::verdict::Limits;
use crate::plant::config::{sent_ids, PlantConfig, DEFAULT_TOML};
use crate::plant::faults::parse_faults;
use crate::plant::{Mode, PlantError, Scenario};
use crate::ranges::Ranged;
use crate::tcu::TcuConfig;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Errors of scenario files; `key` names the offending key.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    #[error("cannot read scenario {path}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("scenario {path}: not valid TOML")]
    Syntax {
        path: PathBuf,
        #[source]
        source: Box<toml::de::Error>,
    },
    #[error("scenario {path}{}: `{key}`: {reason}", crate::toml_key::at_line(*.line))]
    Key {
        path: PathBuf,
        /// The line of the key in the file, when the file holds it.
        line: Option<usize>,
        key: String,
        reason: String,
    },
    #[error("scenario {path}")]
    Plant {
        path: PathBuf,
        #[source]
        source: PlantError,
    },
}

impl ScenarioError {
    /// Places a key error of the file `path` — the scenario's own or one of its plant's — at its
    /// key's line in that file's `text`.
    fn located(self, path: &Path, text: &str) -> Self {
        match self {
            ScenarioError::Key {
                path: p,
                line: None,
                key,
                reason,
            } if p == path => ScenarioError::Key {
                line: crate::toml_key::line_in_text(text, &key),
                path: p,
                key,
                reason,
            },
            ScenarioError::Plant { path: p, source } => ScenarioError::Plant {
                path: p,
                source: source.located(path, text),
            },
            e => e,
        }
    }
}

fn key_err(path: &Path, key: impl Into<String>, reason: impl Into<String>) -> ScenarioError {
    let key = key.into();
    ScenarioError::Key {
        path: path.to_path_buf(),
        line: None,
        key,
        reason: reason.into(),
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
    /// The overrides applied to the default calibration must validate (a NaN, an infinity or an
    /// out-of-range temperature is refused here, not found later in a running TCU).
    pub fn validate(&self, path: &Path) -> Result<(), ScenarioError> {
        let mut cfg = TcuConfig::default();
        self.apply(&mut cfg);
        cfg.validate().map_err(|e| match e.key() {
            Some(key) => {
                let key = key.rsplit('.').next().unwrap_or(key);
                key_err(path, format!("tcu.{key}"), e.to_string())
            }
            None => key_err(path, "tcu", crate::error_chain::chain(&e)),
        })
    }

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
    /// The plant configuration, with the driver as its built-in scenario.
    pub plant: PlantConfig,
    pub tcu: TcuOverrides,
    /// Pass/fail limits (`[limits]`), if the scenario sets any.
    pub limits: Option<Limits>,
}

const SCENARIO_KEYS: [&str; 12] = [
    "limits",
    "description",
    "duration_s",
    "plant",
    "driver",
    "tcu",
    "initial",
    "housing",
    "sensors",
    "inputs",
    "effects",
    "faults",
];

/// Whether a parsed scenario is a driver scenario (`t_s` at the top, no `driver`).
fn is_driver_file(doc: &toml::Table) -> bool {
    doc.contains_key("t_s") && !doc.contains_key("driver")
}

/// Whether the scenario file at `path` is a sim scenario (it has a `driver`), as opposed to a
/// driver scenario; `Ok(false)` for a file that does not parse (its loader then says why).
pub fn is_sim_scenario(path: &Path) -> Result<bool, ScenarioError> {
    let text = std::fs::read_to_string(path).map_err(|e| ScenarioError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    Ok(text
        .parse::<toml::Table>()
        .is_ok_and(|doc| doc.contains_key("driver")))
}

impl SimScenario {
    pub fn load(path: &Path) -> Result<Self, ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(|e| ScenarioError::Io {
            path: path.to_path_buf(),
            source: e,
        })?;
        Self::from_toml_str(path, &text)
    }

    /// Parses a scenario's text; `path` names it in errors (with the key's line).
    pub fn from_toml_str(path: &Path, text: &str) -> Result<Self, ScenarioError> {
        Self::from_text(path, text).map_err(|e| e.located(path, text))
    }

    fn from_text(path: &Path, text: &str) -> Result<Self, ScenarioError> {
        let plant_err = |source| ScenarioError::Plant {
            path: path.to_path_buf(),
            source,
        };
        let doc = scenario_doc(path, text)?;
        let dir = path.parent().unwrap_or(Path::new("."));
        let (base_path, base, faults_doc) = plant_doc(path, dir, &doc)?;
        let mut plant = PlantConfig::from_doc(path, &base, Some(&base_path)).map_err(plant_err)?;
        if plant.mode != Mode::Vehicle {
            return Err(key_err(
                path,
                "plant.mode",
                "a sim scenario needs vehicle mode",
            ));
        }
        let driver = match doc.get("driver") {
            Some(toml::Value::Table(t)) => Scenario::from_table(path, t).map_err(plant_err)?,
            Some(toml::Value::String(f)) => Scenario::load(&dir.join(f)).map_err(plant_err)?,
            _ => {
                return Err(key_err(
                    path,
                    "driver",
                    "missing (a driver-scenario file name or an inline [driver] table)",
                ))
            }
        };
        plant.scenario = Some(driver);
        if let Some(fd) = faults_doc {
            plant.faults =
                parse_faults(path, &fd, &sent_ids(Mode::Vehicle, true)).map_err(plant_err)?;
        }
        let tcu: TcuOverrides = typed_section(path, &doc, "tcu")?.unwrap_or_default();
        tcu.validate(path)?;
        let limits: Option<Limits> = typed_section(path, &doc, "limits")?;
        if let Some(e) = limits.as_ref().and_then(|l| l.check_ranges().err()) {
            let reason = format!("{} is outside 0 < limit <= {}", e.value, e.max);
            return Err(key_err(path, e.key, reason));
        }
        let duration_s = match doc.get("duration_s") {
            None => plant.scenario.as_ref().map_or(0.0, |s| s.duration_s),
            Some(toml::Value::Float(f)) => *f,
            Some(toml::Value::Integer(n)) => *n as f64,
            Some(_) => return Err(key_err(path, "duration_s", "must be a number")),
        };
        // A scenario runs at least one 10 ms cycle and at most an hour.
        crate::ranges::check("", "duration_s", &duration_s, 0.01, 3600.0)
            .map_err(|e| key_err(path, e.key.clone(), e.reason()))?;
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
            plant,
            tcu,
            limits,
        })
    }
}

/// A scenario's document: its TOML, a driver scenario (`t_s`, `pedal_pct`, … at the top: the
/// format `ddct plant --scenario` reads too) wrapped as the `driver` of a sim scenario with the
/// built-in plant; every top-level key checked against [`SCENARIO_KEYS`].
fn scenario_doc(path: &Path, text: &str) -> Result<toml::Table, ScenarioError> {
    let doc: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| ScenarioError::Syntax {
            path: path.to_path_buf(),
            source: Box::new(e),
        })?;
    let doc = if is_driver_file(&doc) {
        let mut wrapped = toml::Table::new();
        if let Some(d) = doc.get("description") {
            wrapped.insert("description".into(), d.clone());
        }
        wrapped.insert("driver".into(), toml::Value::Table(doc));
        wrapped
    } else {
        doc
    };
    for k in doc.keys() {
        if !SCENARIO_KEYS.contains(&k.as_str()) {
            return Err(key_err(
                path,
                k.clone(),
                format!("unknown key (allowed: {})", SCENARIO_KEYS.join(", ")),
            ));
        }
    }
    Ok(doc)
}

/// The plant configuration document of a scenario: the base plant file (`plant`, relative to
/// `dir`; the built-in one by default) with the scenario's `initial`, `housing`, `sensors` and
/// `inputs` keys laid over it and its `effects` in place of the base's; and the faults (the
/// scenario's, else the base file's), parsed once the driver is known (DRV_Pedal is then one of
/// the plant's). Returns the base file's path, the document and the faults.
#[allow(clippy::type_complexity)]
fn plant_doc(
    path: &Path,
    dir: &Path,
    doc: &toml::Table,
) -> Result<(PathBuf, toml::Table, Option<toml::Table>), ScenarioError> {
    let (base_path, base_text) = match doc.get("plant") {
        None => (PathBuf::from("config/plant.toml"), DEFAULT_TOML.to_string()),
        Some(toml::Value::String(f)) => {
            let p = dir.join(f);
            let t = std::fs::read_to_string(&p).map_err(|e| ScenarioError::Io {
                path: p.clone(),
                source: e,
            })?;
            (p, t)
        }
        Some(_) => return Err(key_err(path, "plant", "must be a file name")),
    };
    let mut base: toml::Table =
        base_text
            .parse()
            .map_err(|e: toml::de::Error| ScenarioError::Syntax {
                path: base_path.clone(),
                source: Box::new(e),
            })?;
    for t in ["initial", "housing", "sensors", "inputs"] {
        match doc.get(t) {
            None => {}
            Some(toml::Value::Table(over)) => {
                let entry = base
                    .entry(t.to_string())
                    .or_insert_with(|| toml::Value::Table(toml::Table::new()));
                if let toml::Value::Table(bt) = entry {
                    for (k, v) in over {
                        bt.insert(k.clone(), v.clone());
                    }
                }
            }
            Some(_) => return Err(key_err(path, t, "must be a table")),
        }
    }
    if let Some(e) = doc.get("effects") {
        base.insert("effects".into(), e.clone());
    }
    let faults = doc
        .get("faults")
        .cloned()
        .or_else(|| base.remove("faults"))
        .map(|f| {
            let mut t = toml::Table::new();
            t.insert("faults".into(), f);
            t
        });
    base.remove("faults");
    if let Some(toml::Value::Table(p)) = base.get_mut("plant") {
        p.remove("scenario");
    }
    Ok((base_path, base, faults))
}

/// The scenario's `key` section as `T` (`None` when absent); a refused key is named by its
/// dotted path.
fn typed_section<T: serde::de::DeserializeOwned>(
    path: &Path,
    doc: &toml::Table,
    key: &str,
) -> Result<Option<T>, ScenarioError> {
    let Some(v) = doc.get(key) else {
        return Ok(None);
    };
    v.clone()
        .try_into()
        .map(Some)
        .map_err(|e: toml::de::Error| {
            let at = match v {
                toml::Value::Table(t) => crate::toml_key::refused_path::<T>(key, t),
                _ => key.to_string(),
            };
            key_err(path, at, e.message().to_string())
        })
}

#[cfg(test)]
mod tests {

    #[test]
    fn a_driver_scenario_is_a_sim_scenario_with_the_built_in_plant() {
        let text = "description = \"d\"\nt_s = [0.0, 2.0]\npedal_pct = [0.0, 30.0]\n\
                    brake = [1.0, 0.0]\nlever = [\"N\", \"D\"]\n";
        let s = SimScenario::from_toml_str(Path::new("x/driver_d.toml"), text).unwrap();
        assert_eq!(s.description, "d");
        assert_eq!(s.duration_s, 2.0);
        assert_eq!(s.plant.scenario.as_ref().map(|d| d.duration_s), Some(2.0));
        assert_eq!(s.plant.initial, PlantConfig::default().initial);
        // A bad value still names the file's own line and key.
        let bad = text.replace("[0.0, 30.0]", "[0.0, 300.0]");
        let e = SimScenario::from_toml_str(Path::new("x/driver_d.toml"), &bad).unwrap_err();
        let msg = crate::error_chain::chain(&e);
        assert!(
            msg.contains("x/driver_d.toml") && msg.contains("pedal_pct"),
            "{msg}"
        );
    }
    use super::*;

    const TEXT: &str = r#"
description = "t"
duration_s = 2.0
[driver]
t_s = [0.0, 1.0]
pedal_pct = [0.0, 50.0]
lever = ["D", "D"]
[initial]
temperature_c = 140.0
[sensors]
speed_rpm = 0.0
[tcu]
temperature_compensation = false
initial_temp_c = 140.0
"#;

    #[test]
    fn a_non_finite_or_out_of_range_tcu_override_names_the_file_and_key() {
        for bad in ["nan", "inf", "-inf", "1e12", "-41.0"] {
            let text = TEXT.replace("initial_temp_c = 140.0", &format!("initial_temp_c = {bad}"));
            let e = SimScenario::from_toml_str(Path::new("x/sc.toml"), &text).unwrap_err();
            let msg = e.to_string();
            assert!(
                msg.contains("x/sc.toml") && msg.contains("tcu.initial_temp_c"),
                "{bad}: {msg}"
            );
        }
    }

    #[test]
    fn merges_into_the_plant_configuration() {
        let s = SimScenario::from_toml_str(Path::new("x.toml"), TEXT).unwrap();
        assert_eq!(s.plant.initial.temperature_c, 140.0);
        // Keys not overridden keep the base configuration's value.
        let base = PlantConfig::default();
        assert_eq!(s.plant.initial.housing_c, base.initial.housing_c);
        assert_eq!(s.plant.sensors.speed_rpm, 0.0);
        assert_eq!(s.plant.sensors.position_mm, base.sensors.position_mm);
        assert!(s.plant.scenario.is_some());
        let mut c = TcuConfig::default();
        s.tcu.apply(&mut c);
        assert!(!c.compensation.temperature && c.compensation.slip);
        assert_eq!(c.estimator.initial_temp_c, Some(140.0));
    }

    #[test]
    fn errors_name_the_key() {
        let bad = TEXT.replace("duration_s = 2.0", "duration_s = 2.0\nfoo = 1");
        let e = SimScenario::from_toml_str(Path::new("x.toml"), &bad).unwrap_err();
        assert!(crate::error_chain::chain(&e).contains("`foo`"), "{e}");
        let bad = TEXT.replace("pedal_pct = [0.0, 50.0]", "pedal_pct = [0.0, 150.0]");
        let e = SimScenario::from_toml_str(Path::new("x.toml"), &bad).unwrap_err();
        assert!(crate::error_chain::chain(&e).contains("pedal_pct"), "{e}");
        let bad = TEXT.replace("initial_temp_c = 140.0", "initial_tmp_c = 140.0");
        let e = SimScenario::from_toml_str(Path::new("x.toml"), &bad).unwrap_err();
        assert!(crate::error_chain::chain(&e).contains("tcu"), "{e}");
    }
}

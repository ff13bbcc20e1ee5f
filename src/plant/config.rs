//! The plant's configuration file (`config/plant.toml`, `config/plant_rig.toml`): mode, physical
//! parameters (a `params.toml`), initial conditions, housing air, sensor noise, input handling,
//! rig settings, reality effects (`[effects.<id>]`, see `model::effects`) and faults
//! (`[[faults]]`, see [`super::faults`]). Every table and key is optional (defaults below);
//! unknown keys are rejected with an error naming them.

use super::error::{parse_toml, read_text, PlantError};
use super::faults::{parse_faults, Fault};
use super::profile::{RigProfile, Scenario};
use crate::can::messages::{ids, DctSensors};
use crate::model::effects::EffectSet;
use crate::model::gear::Gear;
use crate::model::Params;
use crate::ranges::Ranged;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The plant's cycle: DCT_Sensors' cycle time in the DBC (every plant message has it).
pub const CYCLE: Duration = Duration::from_millis(DctSensors::CYCLE_MS as u64);

/// The configuration compiled into the binary (`config/plant.toml`).
pub const DEFAULT_TOML: &str = include_str!("../../config/plant.toml");

/// Operating mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// The vehicle: engine, transmission, wheels and road.
    #[default]
    Vehicle,
    /// The test rig of the paper's Sect. 3.3.
    Rig,
}

/// How the plant integrates (`[plant] step`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum StepPolicy {
    /// One RK4 step per bus cycle while the cycle is quiet (`plant::core::quiet`: inputs
    /// constant, each clutch locked or open, no gear moving), the 1 ms step otherwise.
    #[default]
    Multirate,
    /// The 1 ms step (`params.integrator.dt_s`) throughout: the reference.
    Fixed,
}

impl Mode {
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Vehicle => "vehicle",
            Mode::Rig => "rig",
        }
    }
}

/// `[plant]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct PlantTable {
    mode: Mode,
    params: Option<String>,
    seed: u64,
    scenario: Option<String>,
    rig_profile: Option<String>,
    step: StepPolicy,
}

impl Default for PlantTable {
    fn default() -> Self {
        Self {
            mode: Mode::Vehicle,
            params: None,
            seed: 1,
            scenario: None,
            rig_profile: None,
            step: StepPolicy::Multirate,
        }
    }
}

/// `[initial]`: initial conditions.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Initial {
    /// Engine speed (rpm); in rig mode the dyno speed comes from `[rig]` or the profile.
    pub engine_rpm: f64,
    /// Vehicle speed (km/h).
    pub vehicle_kmh: f64,
    /// Engaged odd / even gear, as its bus code (0 neutral, 1–6, 7 reverse on the even shaft) or
    /// label (`"N"`, `"G3"`, `"R"`).
    pub gear_odd: Gear,
    pub gear_even: Gear,
    /// All five thermal masses (°C), unless overridden below.
    pub temperature_c: f64,
    pub pp1_c: Option<f64>,
    pub pp2_c: Option<f64>,
    pub c1_c: Option<f64>,
    pub c2_c: Option<f64>,
    pub cd_c: Option<f64>,
    /// Housing air θ_h at the start (°C).
    pub housing_c: f64,
}

impl Default for Initial {
    fn default() -> Self {
        Self {
            engine_rpm: 800.0,
            vehicle_kmh: 0.0,
            gear_odd: Gear::N,
            gear_even: Gear::N,
            temperature_c: 25.0,
            pp1_c: None,
            pp2_c: None,
            c1_c: None,
            c2_c: None,
            cd_c: None,
            housing_c: 25.0,
        }
    }
}

/// `[housing]`: the housing air relaxes to `target_c` with time constant `tau_s`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Housing {
    /// Ambient / under-hood air temperature (°C).
    pub target_c: f64,
    pub tau_s: f64,
}

impl Default for Housing {
    fn default() -> Self {
        Self {
            target_c: 25.0,
            tau_s: 900.0,
        }
    }
}

/// `[sensors]`: standard deviations of the Gaussian sensor noise (0: none). Quantisation is the
/// contract's (DBC resolution), applied when encoding.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct SensorNoise {
    pub speed_rpm: f64,
    pub engine_torque_nm: f64,
    pub position_mm: f64,
    pub torque_nm: f64,
    pub temperature_c: f64,
    pub housing_c: f64,
    pub vehicle_accel_mps2: f64,
}

/// `[inputs]`: handling of the frames the plant reads.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InputOptions {
    /// An input is stale after this many 10 ms cycles without a valid frame; then clutch requests
    /// fall to 0 mm (open), the engine request becomes inactive, the pedal 0 and the brake off;
    /// gear requests are held.
    pub timeout_cycles: u32,
    /// Brake fraction applied while DRV_Pedal.BrakeSwitch is set.
    pub brake_switch_fraction: f64,
}

impl Default for InputOptions {
    fn default() -> Self {
        Self {
            timeout_cycles: 3,
            brake_switch_fraction: 0.4,
        }
    }
}

/// `[rig]`: the test rig of the paper's Sect. 3.3.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RigOptions {
    /// Dyno speed holding the input side (rpm) when no profile gives one.
    pub input_speed_rpm: f64,
    /// Gears engaged on the output side (the output is braked), as in `[initial]`.
    pub gear_odd: Gear,
    pub gear_even: Gear,
    /// Wheel-brake fraction holding the output.
    pub brake: f64,
}

impl Default for RigOptions {
    fn default() -> Self {
        Self {
            input_speed_rpm: 2000.0,
            gear_odd: Gear::G5,
            gear_even: Gear::G6,
            brake: 1.0,
        }
    }
}

/// The validated plant configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct PlantConfig {
    pub mode: Mode,
    pub params: Params,
    /// Sensor-noise seed.
    pub seed: u64,
    pub initial: Initial,
    pub housing: Housing,
    pub sensors: SensorNoise,
    pub inputs: InputOptions,
    pub rig: RigOptions,
    pub effects: EffectSet,
    pub faults: Vec<Fault>,
    /// Vehicle mode: the built-in driver (plays DRV_Pedal); `None`: DRV_Pedal from the bus.
    pub scenario: Option<Scenario>,
    /// Rig mode: the built-in x_to profile; `None`: TCU_ClutchCmd from the bus.
    pub rig_profile: Option<RigProfile>,
    /// The file it came from.
    pub source: Option<PathBuf>,
    /// Multi-rate or fixed-step integration.
    pub step: StepPolicy,
}

impl Default for PlantConfig {
    fn default() -> Self {
        Self::from_toml_str(Path::new("config/plant.toml"), DEFAULT_TOML, None)
            .expect("config/plant.toml is valid (checked by a unit test)")
    }
}

/// Messages the plant sends in a mode (DRV_Pedal only when it plays the driver).
pub fn sent_ids(mode: Mode, plays_driver: bool) -> Vec<u16> {
    let mut v = vec![
        ids::ENG_STATUS,
        ids::DCT_SENSORS,
        ids::DCT_ACTUATORS,
        ids::BENCH_TORQUE,
        ids::BENCH_TEMPS,
        ids::BENCH_VEHICLE,
        ids::SIM_TRUTH,
    ];
    if mode == Mode::Vehicle && plays_driver {
        v.insert(0, ids::DRV_PEDAL);
    }
    v
}

fn table<T: for<'de> Deserialize<'de> + Default>(
    path: &Path,
    doc: &toml::Table,
    name: &str,
) -> Result<T, PlantError> {
    match doc.get(name) {
        None => Ok(T::default()),
        Some(v @ toml::Value::Table(t)) => v.clone().try_into().map_err(|e: toml::de::Error| {
            let key = crate::toml_key::refused_path::<T>(name, t);
            PlantError::key(path, key, e.message().to_string())
        }),
        Some(_) => Err(PlantError::key(path, name, "must be a table")),
    }
}

fn resolve(base: Option<&Path>, rel: &str) -> PathBuf {
    let p = PathBuf::from(rel);
    match base.and_then(Path::parent) {
        Some(dir) if p.is_relative() => dir.join(p),
        _ => p,
    }
}

// The allowed range of every number, table by table (`crate::ranges`).
crate::ranges!(Initial as _i, "initial" {
    engine_rpm: [0.0, 7000.0],
    vehicle_kmh: [-60.0, 250.0],
    temperature_c: [-40.0, 350.0],
    pp1_c: [-40.0, 350.0],
    pp2_c: [-40.0, 350.0],
    c1_c: [-40.0, 350.0],
    c2_c: [-40.0, 350.0],
    cd_c: [-40.0, 350.0],
    housing_c: [-40.0, 200.0],
});
crate::ranges!(Housing as _h, "housing" {
    target_c: [-40.0, 200.0],
    tau_s: [1.0, 1e6],
});
crate::ranges!(SensorNoise as _s, "sensors" {
    speed_rpm: [0.0, 100.0],
    engine_torque_nm: [0.0, 50.0],
    position_mm: [0.0, 1.0],
    torque_nm: [0.0, 50.0],
    temperature_c: [0.0, 20.0],
    housing_c: [0.0, 20.0],
    vehicle_accel_mps2: [0.0, 5.0],
});
crate::ranges!(InputOptions as _i, "inputs" {
    timeout_cycles: [1.0, 1000.0],
    brake_switch_fraction: [0.0, 1.0],
});
crate::ranges!(RigOptions as _r, "rig" {
    input_speed_rpm: [0.0, 6000.0],
    brake: [0.0, 1.0],
});

impl PlantConfig {
    /// Reads and validates a plant configuration; relative file names inside it are relative to
    /// its folder.
    pub fn load(path: &Path) -> Result<Self, PlantError> {
        Self::from_toml_str(path, &read_text(path)?, Some(path))
    }

    /// Parses a configuration's text; `path` names it in errors (with the key's line), `base`
    /// (the file) resolves relative file names (`None`: relative to the working directory).
    pub fn from_toml_str(path: &Path, text: &str, base: Option<&Path>) -> Result<Self, PlantError> {
        Self::from_doc(path, &parse_toml(path, text)?, base).map_err(|e| e.located(path, text))
    }

    /// [`PlantConfig::from_toml_str`] of a parsed table (errors name keys, not lines: a caller
    /// holding the text places them with [`PlantError::located`]).
    pub(crate) fn from_doc(
        path: &Path,
        doc: &toml::Table,
        base: Option<&Path>,
    ) -> Result<Self, PlantError> {
        for k in doc.keys() {
            if !matches!(
                k.as_str(),
                "plant"
                    | "initial"
                    | "housing"
                    | "sensors"
                    | "inputs"
                    | "rig"
                    | "effects"
                    | "faults"
            ) {
                return Err(PlantError::key(
                    path,
                    k,
                    "unknown table (plant, initial, housing, sensors, inputs, rig, effects, faults)",
                ));
            }
        }
        let plant: PlantTable = table(path, doc, "plant")?;
        let params = match &plant.params {
            None => Params::default(),
            Some(p) => {
                let pp = resolve(base, p);
                Params::load(&pp).map_err(|source| PlantError::Params { path: pp, source })?
            }
        };
        let initial: Initial = table(path, doc, "initial")?;
        let housing: Housing = table(path, doc, "housing")?;
        let sensors: SensorNoise = table(path, doc, "sensors")?;
        let inputs: InputOptions = table(path, doc, "inputs")?;
        let rig: RigOptions = table(path, doc, "rig")?;
        let effects = match doc.get("effects") {
            None => EffectSet::nominal(),
            Some(toml::Value::Table(t)) => {
                EffectSet::from_table(t).map_err(|source| PlantError::Effects {
                    path: path.to_path_buf(),
                    source,
                })?
            }
            Some(_) => return Err(PlantError::key(path, "effects", "must be a table")),
        };
        let scenario = match &plant.scenario {
            Some(s) => Some(Scenario::load(&resolve(base, s))?),
            None => None,
        };
        let rig_profile = match &plant.rig_profile {
            Some(s) => Some(RigProfile::load(&resolve(base, s))?),
            None => None,
        };
        let sent = sent_ids(plant.mode, scenario.is_some());
        let faults = parse_faults(path, doc, &sent)?;
        let cfg = PlantConfig {
            mode: plant.mode,
            params,
            seed: plant.seed,
            initial,
            housing,
            sensors,
            inputs,
            rig,
            effects,
            faults,
            scenario,
            rig_profile,
            source: base.map(Path::to_path_buf),
            step: plant.step,
        };
        cfg.validate(path)?;
        Ok(cfg)
    }

    /// The declared range of every number ([`crate::ranges!`] above), the shafts' gears, and
    /// a time step that divides the cycle.
    pub fn validate(&self, path: &Path) -> Result<(), PlantError> {
        let range = |e| PlantError::range(path, e);
        self.initial.check_ranges().map_err(range)?;
        self.housing.check_ranges().map_err(range)?;
        self.sensors.check_ranges().map_err(range)?;
        self.inputs.check_ranges().map_err(range)?;
        self.rig.check_ranges().map_err(range)?;
        check_shafts(
            path,
            "initial",
            self.initial.gear_odd,
            self.initial.gear_even,
        )?;
        check_shafts(path, "rig", self.rig.gear_odd, self.rig.gear_even)?;
        let dt = self.params.integrator.dt_s;
        let per_cycle = CYCLE.as_secs_f64() / dt;
        if (per_cycle - per_cycle.round()).abs() > 1e-9 {
            return Err(PlantError::key(
                path,
                "integrator.dt_s",
                format!("{dt} s does not divide the 10 ms cycle"),
            ));
        }
        Ok(())
    }

    /// Loads a faults file (`[[faults]]` tables) for this configuration.
    pub fn load_faults(&self, path: &Path) -> Result<Vec<Fault>, PlantError> {
        let text = read_text(path)?;
        let doc = parse_toml(path, &text)?;
        let faults = match doc.keys().find(|k| *k != "faults") {
            Some(k) => Err(PlantError::key(
                path,
                k,
                "a faults file holds only [[faults]] tables",
            )),
            None => parse_faults(path, &doc, &sent_ids(self.mode, self.scenario.is_some())),
        };
        faults.map_err(|e| e.located(path, &text))
    }

    /// Re-checks the faults against the messages sent after mode or driver changed.
    pub fn check_faults(&self) -> Result<(), PlantError> {
        let sent = sent_ids(self.mode, self.scenario.is_some());
        for (i, f) in self.faults.iter().enumerate() {
            if !sent.contains(&f.message.id) {
                return Err(PlantError::key(
                    self.source.as_deref().unwrap_or(Path::new("faults")),
                    format!("faults[{i}].message"),
                    format!("the plant does not send {} in this mode", f.message.name),
                ));
            }
        }
        Ok(())
    }

    /// Messages this configuration sends.
    pub fn sent_ids(&self) -> Vec<u16> {
        sent_ids(self.mode, self.scenario.is_some())
    }
}

/// `TABLE.gear_odd` must be neutral or an odd gear, `TABLE.gear_even` neutral, an even gear or
/// reverse (the DBC's `GearOddAct` and `GearEvenAct` tables).
fn check_shafts(path: &Path, table: &str, odd: Gear, even: Gear) -> Result<(), PlantError> {
    use crate::can::messages::{GearEvenAct, GearOddAct};
    if GearOddAct::try_from(odd).is_err() {
        return Err(PlantError::key(
            path,
            format!("{table}.gear_odd"),
            format!("gear {odd} is not on the odd shaft (N, 1, 3 or 5)"),
        ));
    }
    if GearEvenAct::try_from(even).is_err() {
        return Err(PlantError::key(
            path,
            format!("{table}.gear_even"),
            format!("gear {even} is not on the even shaft (N, 2, 4, 6 or R)"),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_file_is_valid() {
        let c = PlantConfig::default();
        assert_eq!(c.mode, Mode::Vehicle);
        assert!(c.effects.is_nominal());
        assert!(c.faults.is_empty());
    }

    #[test]
    fn errors_name_the_key() {
        let p = Path::new("p.toml");
        let e = PlantConfig::from_toml_str(p, "[initial]\nengine_rpm = 9000\n", None).unwrap_err();
        assert!(
            matches!(&e, PlantError::Key { key, .. } if key == "initial.engine_rpm"),
            "{e}"
        );
        let e = PlantConfig::from_toml_str(p, "[initial]\nrpm = 900\n", None).unwrap_err();
        assert!(
            matches!(&e, PlantError::Key { key, .. } if key == "initial.rpm"),
            "{e}"
        );
        assert!(crate::error_chain::chain(&e).contains("rpm"), "{e}");
        let e = PlantConfig::from_toml_str(p, "[plant]\nmode = \"boat\"\n", None).unwrap_err();
        assert!(
            matches!(&e, PlantError::Key { key, .. } if key == "plant.mode"),
            "{e}"
        );
        let e = PlantConfig::from_toml_str(p, "[effects.actuator_backlash]\nwidth_mm = 5\n", None)
            .unwrap_err();
        assert!(matches!(&e, PlantError::Effects { .. }), "{e}");
        assert!(crate::error_chain::chain(&e).contains("effects.actuator_backlash.width_mm"));
        let e = PlantConfig::from_toml_str(p, "[gearbox]\n", None).unwrap_err();
        assert!(
            matches!(&e, PlantError::Key { key, .. } if key == "gearbox"),
            "{e}"
        );
        let e = PlantConfig::from_toml_str(p, "[plant]\nparams = \"/nonexistent.toml\"\n", None)
            .unwrap_err();
        assert!(matches!(&e, PlantError::Params { .. }), "{e}");
    }

    /// Gears are read as bus codes or labels; a code outside the DBC's table and a gear on the
    /// wrong shaft are errors naming the key, never neutral.
    #[test]
    fn gears_are_checked_at_the_boundary() {
        let p = Path::new("p.toml");
        let ok =
            PlantConfig::from_toml_str(p, "[initial]\ngear_odd = 3\ngear_even = \"R\"\n", None)
                .unwrap();
        assert_eq!(
            (ok.initial.gear_odd, ok.initial.gear_even),
            (Gear::G3, Gear::R)
        );
        for (text, key) in [
            ("[initial]\ngear_odd = 8\n", "initial.gear_odd"),
            ("[initial]\ngear_odd = 2\n", "initial.gear_odd"),
            ("[initial]\ngear_even = \"G5\"\n", "initial.gear_even"),
            ("[rig]\ngear_even = 1.5\n", "rig.gear_even"),
        ] {
            let e = PlantConfig::from_toml_str(p, text, None).unwrap_err();
            assert!(
                matches!(&e, PlantError::Key { key: k, .. } if k == key),
                "{text}: {e}"
            );
        }
    }
}

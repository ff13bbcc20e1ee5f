//! The plant: a simulated dry dual-clutch transmission as the bus sees it (issue 5, DESIGN.md §2,
//! §3, §5).
//!
//! [`Plant`] is a pure core (no clock, no socket, no tokio): [`Plant::step`] takes the time since
//! the start and the frames received since the last call, integrates the powertrain of
//! `model::powertrain` (engine, actuators, clutches with the torque characteristic (13), driveline
//! (18)–(20) with stick/slip, 5-state thermal model (16)) at its 1 ms step up to `now`, and returns
//! the frames due at their 10 ms cycle — ENG_Status, DCT_Sensors, DCT_Actuators, BENCH_Torque,
//! BENCH_Temps, BENCH_Vehicle, SIM_Truth (and DRV_Pedal when it plays the driver) — as typed
//! messages with E2E applied and as CAN frames, plus the simulation truth for tests.
//!
//! Around the powertrain:
//! - engine ECU honouring TCU_EngineReq, clutch actuators following TCU_ClutchCmd, gear actuators
//!   following TCU_GearCmd; inputs checked (DLC, CRC, alive counter, ranges), errors counted, a
//!   silent input times out to a safe default ([`core`]);
//! - housing air θ_h relaxing slowly to an ambient / under-hood value;
//! - sensors with the contract's quantisation and seeded Gaussian noise ([`noise`]);
//! - modes ([`config::Mode`]): vehicle (driver on the bus or a built-in scenario, [`profile`]) and
//!   test rig (paper Sect. 3.3: input held at a set speed by a dyno, output braked, clutch
//!   positions from the bus or a built-in x_to profile, [`profile::RigProfile`]);
//! - reality effects of `model::effects`, each acting only through its physics ([`hooks`]);
//! - fault injection on the plant's own frames per message and time window ([`faults`]).

pub mod config;
pub mod core;
pub mod faults;
pub mod hooks;
pub mod noise;
pub mod profile;

pub use self::config::{Mode, PlantConfig, StepPolicy};
pub use self::core::{CycleMessages, OutFrame, Output, Plant, PlantStats, Truth};
pub use self::faults::{Fault, FaultKind};
pub use self::profile::{RigProfile, Scenario};

use std::path::PathBuf;

/// Errors of the plant's configuration files (plant config, scenario, rig profile, faults,
/// effects). `key` names the TOML key (`table.key`, with an index for arrays).
#[derive(Debug, thiserror::Error)]
pub enum PlantError {
    #[error("cannot read {path}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}: not valid TOML")]
    Syntax {
        path: PathBuf,
        #[source]
        source: Box<toml::de::Error>,
    },
    #[error("{path}{}: `{key}`: {reason}", crate::toml_key::at_line(*.line))]
    Key {
        path: PathBuf,
        /// The line of the key in the file, when the file holds it.
        line: Option<usize>,
        key: String,
        reason: String,
    },
    #[error("{path}")]
    Params {
        path: PathBuf,
        #[source]
        source: crate::model::ParamsError,
    },
    #[error("{path}")]
    Effects {
        path: PathBuf,
        #[source]
        source: crate::model::effects::EffectError,
    },
}

impl PlantError {
    pub(crate) fn key(
        path: &std::path::Path,
        key: impl Into<String>,
        reason: impl Into<String>,
    ) -> Self {
        let key = key.into();
        PlantError::Key {
            path: path.to_path_buf(),
            line: None,
            key,
            reason: reason.into(),
        }
    }

    /// A number of the file `path` outside its declared range.
    pub(crate) fn range(path: &std::path::Path, e: crate::ranges::RangeError) -> Self {
        let reason = e.reason();
        Self::key(path, e.key, reason)
    }

    /// Places a key error of the file `path` at its key's line in that file's `text` (the
    /// loaders call it where they hold the text; other errors pass unchanged).
    pub(crate) fn located(self, path: &std::path::Path, text: &str) -> Self {
        match self {
            PlantError::Key {
                path: p,
                line: None,
                key,
                reason,
            } if p == path => PlantError::Key {
                line: crate::toml_key::line_in_text(text, &key),
                path: p,
                key,
                reason,
            },
            e => e,
        }
    }
}

pub(crate) fn read_text(path: &std::path::Path) -> Result<String, PlantError> {
    std::fs::read_to_string(path).map_err(|e| PlantError::Io {
        path: path.to_path_buf(),
        source: e,
    })
}

pub(crate) fn parse_toml(path: &std::path::Path, text: &str) -> Result<toml::Table, PlantError> {
    text.parse()
        .map_err(|source: toml::de::Error| PlantError::Syntax {
            path: path.to_path_buf(),
            source: Box::new(source),
        })
}

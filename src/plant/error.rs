//! The errors of the plant's configuration files ([`PlantError`]) and the reading and TOML
//! parsing that the loaders of [`super::config`], [`super::profile`] and [`super::faults`] share.

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

//! The data-quality stage's findings: what a logger did to a channel of a record, with what to
//! fix on the logger.

use crate::records::dataset::Col;

/// What a logger did to a channel.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum DataKind {
    /// Every sample holds the same value (exact zeros: a channel logged but not connected).
    Constant { value: f64 },
    /// New values only every `every` samples, held in between: the channel's true rate.
    Held { every: usize, rate_hz: f64 },
    /// Isolated samples far from their neighbours: their number, share of the samples and the
    /// largest departure from the local median (the channel's unit).
    Spikes {
        count: usize,
        share: f64,
        largest: f64,
    },
    /// Readings on a grid of `step` (the channel's unit) so coarse that `repeated` of the
    /// consecutive readings are equal: the noise is hidden below the step.
    Quantised { step: f64, repeated: f64 },
    /// A slow wander of the reading unrelated to the physics ([`drift`]: found against the
    /// model): the range of its 10 s means (the channel's unit) and the share of its steps the
    /// physics explains.
    Drift { wander: f64, r2: f64 },
    /// Short runs of exact zeros inside a live reading: their number, the samples they hold and
    /// the longest (s).
    Dropouts {
        runs: usize,
        samples: usize,
        longest_s: f64,
    },
}

impl DataKind {
    /// What to fix on the logger.
    pub fn fix(&self) -> &'static str {
        match self {
            DataKind::Constant { .. } => {
                "the channel carries no signal: connect or configure it, or leave it out of the log"
            }
            DataKind::Held { .. } => {
                "log the channel at the record's rate (or from its own message at its own rate), \
                 not a held copy of a slower source"
            }
            DataKind::Spikes { .. } => {
                "look for interference on the sensor line (shielding, ground) or a corrupted \
                 transfer; the spikes are not the transmission"
            }
            DataKind::Quantised { .. } => {
                "log the channel at its full resolution (the DBC's factor), not rounded to a \
                 coarser step"
            }
            DataKind::Drift { .. } => {
                "the sensor drifts (cold junction, ageing, a loose contact): check its reference \
                 and calibrate it against a reference at rest"
            }
            DataKind::Dropouts { .. } => {
                "the logger filled lost messages with zeros: log them as missing (empty) or \
                 check the message's cycle and the bus load"
            }
        }
    }
}

/// One channel of one record with a logger artefact.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DataFinding {
    /// The record (its source).
    pub file: String,
    #[serde(serialize_with = "column_name")]
    pub channel: Col,
    #[serde(flatten)]
    pub kind: DataKind,
    pub fix: &'static str,
}

fn column_name<S: serde::Serializer>(c: &Col, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(c.name())
}

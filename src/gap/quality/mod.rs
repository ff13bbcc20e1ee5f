//! The data-quality stage (issue 45, item 1): before the model is compared with a record, each
//! measured channel is checked for what a logger does to it — a channel that never changes
//! (exact zeros of an unused clutch), one that updates slower than the record's rate and is held
//! in between (sample-and-hold, with its true rate), isolated spikes (EMI). Each is a typed
//! [`DataFinding`] naming the record, the channel and what to fix on the logger: a fact about the
//! logger, not about the transmission.
//!
//! Checked: the outputs the diagnosis compares (clutch torques of (13), the thermocouples of
//! (16), the positions, the engine torque of (18a)) and the speeds it takes as inputs.

mod constant;
mod held;
mod spikes;

use crate::records::dataset::{Col, Dataset};

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

/// Whether every finite sample of `v` holds one value (a channel logged but not connected).
pub fn is_constant(v: &[f64]) -> bool {
    constant::value(v).is_some()
}

/// Whether `v` is held: a new value only every few samples ([`held`]).
pub fn is_held(v: &[f64]) -> bool {
    held::every(v).is_some()
}

/// The samples of `v` that are spikes ([`spikes`]): not compared with the model.
pub fn spike_samples(v: &[f64]) -> Vec<usize> {
    spikes::samples(v)
}

/// The channels checked.
pub const CHECKED: [Col; 11] = [
    Col::T1,
    Col::T2,
    Col::Pp1,
    Col::Pp2,
    Col::Cd,
    Col::X1,
    Col::X2,
    Col::Te,
    Col::Wf,
    Col::Wc1,
    Col::Wc2,
];

/// Every artefact of every checked channel of `records`, record by record.
pub fn check<'a>(records: impl IntoIterator<Item = &'a Dataset>) -> Vec<DataFinding> {
    let mut out = Vec::new();
    for d in records {
        for c in CHECKED {
            let Some(v) = d.get(c) else { continue };
            let found = match constant::value(v) {
                Some(value) => vec![DataKind::Constant { value }],
                None => held::every(v)
                    .map(|every| DataKind::Held {
                        every,
                        rate_hz: 1.0 / (every as f64 * d.dt),
                    })
                    .into_iter()
                    .chain(spikes::find(v).map(|s| DataKind::Spikes {
                        count: s.count,
                        share: s.share,
                        largest: s.largest,
                    }))
                    .collect(),
            };
            out.extend(found.into_iter().map(|kind| DataFinding {
                file: d.source.clone(),
                channel: c,
                fix: kind.fix(),
                kind,
            }));
        }
    }
    out
}

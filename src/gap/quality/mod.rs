//! The data-quality stage (issue 45, item 1): before the model is compared with a record, each
//! measured channel is checked for what a logger does to it — a channel that never changes
//! (exact zeros of an unused clutch), one that updates slower than the record's rate and is held
//! in between (sample-and-hold, with its true rate), a grid so coarse that the reading sits
//! still, isolated spikes (EMI), short runs of zeros (lost messages filled with zeros). Each is a
//! typed [`DataFinding`] naming the record, the channel and what to fix on the logger: a fact
//! about the logger, not about the transmission. A thermocouple's slow drift is found later,
//! against the model ([`drift`], phase 5). [`repair`] says what the diagnosis does with
//! them: spike and dropout samples are bridged in the model's inputs and never compared.
//!
//! Checked: the outputs the diagnosis compares (clutch torques of (13), the thermocouples of
//! (16), the positions, the engine torque of (18a)) and the speeds it takes as inputs.

mod checked;
mod constant;
pub mod drift;
mod dropouts;
mod held;
mod quantised;
mod repair;
mod spikes;

pub use checked::CHECKED;
pub use repair::{repaired, Bridged, Repaired};

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

/// Whether every finite sample of `v` holds one value (a channel logged but not connected).
pub fn is_constant(v: &[f64]) -> bool {
    constant::value(v).is_some()
}

/// The number of samples each value of `v` is held for, when `v` is held ([`held`]).
pub fn held_every(v: &[f64]) -> Option<usize> {
    held::every(v)
}

/// The grid step of `v`'s readings, if they lie on one ([`quantised`]): a floor of the
/// channel's noise is at least step/√12.
pub fn grid_step(v: &[f64]) -> Option<f64> {
    quantised::grid_step(v)
}

/// Every artefact of every checked channel of `records`, record by record.
pub fn check<'a>(records: impl IntoIterator<Item = &'a Dataset>) -> Vec<DataFinding> {
    let mut out = Vec::new();
    for d in records {
        for c in CHECKED {
            let Some(v) = d.get(c) else { continue };
            let found = match constant::value(v) {
                Some(value) => vec![DataKind::Constant { value }],
                None => artefacts(v, d.dt, c.resolution()),
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

/// The artefacts of a channel that is not constant, at a record step of `dt` s, carried by the
/// bus at `resolution`.
fn artefacts(v: &[f64], dt: f64, resolution: f64) -> Vec<DataKind> {
    let held = held::every(v).map(|every| DataKind::Held {
        every,
        rate_hz: 1.0 / (every as f64 * dt),
    });
    // A held channel repeats its readings by the hold, not by a coarse grid.
    let coarse = held
        .is_none()
        .then(|| quantised::coarse(v, resolution))
        .flatten()
        .map(|(step, repeated)| DataKind::Quantised { step, repeated });
    let spikes = spikes::find(v).map(|s| DataKind::Spikes {
        count: s.count,
        share: s.share,
        largest: s.largest,
    });
    let runs = dropouts::runs(v, dropouts::max_len(dt));
    let dropouts = (!runs.is_empty()).then(|| DataKind::Dropouts {
        runs: runs.len(),
        samples: runs.iter().map(|r| r.1).sum(),
        longest_s: runs.iter().map(|r| r.1).max().unwrap_or(0) as f64 * dt,
    });
    [held, coarse, spikes, dropouts]
        .into_iter()
        .flatten()
        .collect()
}

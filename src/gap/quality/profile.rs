//! One analysis of each checked channel of a record, made once: whether it is constant, held,
//! on a grid (and a coarse one), where its spikes and dropouts are. The findings, the repair of
//! the model's inputs, which samples are compared and each channel's noise-floor bounds are all
//! read from it, so no detector runs twice on a record.

use super::checked::CHECKED;
use super::finding::{DataFinding, DataKind};
use super::{constant, dropouts, held, quantised, spikes};
use crate::records::dataset::{Col, Dataset};

/// What the stage found on one channel.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Facts {
    /// Every finite sample holds this value.
    pub constant: Option<f64>,
    /// Each reading is held for this many samples.
    pub held: Option<usize>,
    /// The step of the grid the readings lie on.
    pub grid: Option<f64>,
    /// The spike and dropout samples (ascending): not readings.
    pub bad: Vec<usize>,
    /// The artefacts, as reported.
    kinds: Vec<DataKind>,
}

/// The facts of every checked channel of one record.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    /// The record (its source).
    pub source: String,
    facts: Vec<(Col, Facts)>,
}

impl Profile {
    /// Analyses every checked channel of `d`.
    pub fn of(d: &Dataset) -> Profile {
        let facts = CHECKED
            .iter()
            .filter_map(|&c| d.get(c).map(|v| (c, facts(v, d.dt, c.resolution()))))
            .collect();
        Profile {
            source: d.source.clone(),
            facts,
        }
    }

    /// The facts of column `c` (`None`: not logged or not checked).
    pub fn get(&self, c: Col) -> Option<&Facts> {
        self.facts.iter().find(|(k, _)| *k == c).map(|(_, f)| f)
    }

    /// The channels with spike or dropout samples.
    pub fn bad(&self) -> impl Iterator<Item = (Col, &[usize])> {
        self.facts
            .iter()
            .filter(|(_, f)| !f.bad.is_empty())
            .map(|(c, f)| (*c, f.bad.as_slice()))
    }

    /// Every artefact found, channel by channel.
    pub fn findings(&self) -> Vec<DataFinding> {
        self.facts
            .iter()
            .flat_map(|(c, f)| {
                f.kinds.iter().map(|kind| DataFinding {
                    file: self.source.clone(),
                    channel: *c,
                    fix: kind.fix(),
                    kind: kind.clone(),
                })
            })
            .collect()
    }
}

/// The facts of channel `v`, at a record step of `dt` s, carried by the bus at `resolution`.
fn facts(v: &[f64], dt: f64, resolution: f64) -> Facts {
    if let Some(value) = constant::value(v) {
        return Facts {
            constant: Some(value),
            kinds: vec![DataKind::Constant { value }],
            ..Facts::default()
        };
    }
    let every = held::every(v);
    let grid = quantised::grid_step(v);
    let held = every.map(|every| DataKind::Held {
        every,
        rate_hz: 1.0 / (every as f64 * dt),
    });
    // A held channel repeats its readings by the hold, not by a coarse grid.
    let coarse = every
        .is_none()
        .then(|| quantised::coarse(v, grid, resolution))
        .flatten()
        .map(|(step, repeated)| DataKind::Quantised { step, repeated });
    let (mut bad, spikes) = spikes::detect(v, grid).map_or((Vec::new(), None), |(at, s)| {
        let kind = DataKind::Spikes {
            count: s.count,
            share: s.share,
            largest: s.largest,
        };
        (at, Some(kind))
    });
    let runs = dropouts::runs(v, dropouts::max_len(dt));
    let dropouts = (!runs.is_empty()).then(|| DataKind::Dropouts {
        runs: runs.len(),
        samples: runs.iter().map(|r| r.1).sum(),
        longest_s: runs.iter().map(|r| r.1).max().unwrap_or(0) as f64 * dt,
    });
    for (start, len) in runs {
        bad.extend(start..start + len);
    }
    bad.sort_unstable();
    bad.dedup();
    Facts {
        constant: None,
        held: every,
        grid,
        bad,
        kinds: [held, coarse, spikes, dropouts]
            .into_iter()
            .flatten()
            .collect(),
    }
}

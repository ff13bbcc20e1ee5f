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
mod finding;
mod held;
mod profile;
mod quantised;
mod repair;
mod spikes;

pub use checked::CHECKED;
pub use finding::{DataFinding, DataKind};
pub use profile::{Facts, Profile};
pub use repair::repaired;

use crate::records::dataset::Dataset;

/// Every artefact of every checked channel of `records`, record by record.
pub fn check<'a>(records: impl IntoIterator<Item = &'a Dataset>) -> Vec<DataFinding> {
    records
        .into_iter()
        .flat_map(|d| Profile::of(d).findings())
        .collect()
}

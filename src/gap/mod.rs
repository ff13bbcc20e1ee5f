//! Sim-to-real gap diagnosis (DESIGN.md §6, issues 7, 17 and 43). It reads bench records as
//! [`crate::records`] holds them (schema, CSV, candump/MF4, resampling, events) and is given
//! them by its callers; bench experiments that produce records are [`crate::experiment`]. The
//! folders are the method's stages, each importing only the ones above it in this list:
//!
//! - [`fit`]: least squares and statistics, knowing nothing of clutches;
//! - [`model`]: what is fitted — a candidate model, its class terms and shapes, the effect
//!   classes (one `EffectClass` impl per family in [`model::classes`]), the typed parameters;
//! - [`quality`]: the data-quality stage — what the logger did to each channel (held,
//!   constant, spiked), before any model is compared;
//! - [`record`]: a record as the diagnosis reads it, with its model-free series and events;
//! - [`eval`]: the model replayed on a record (the thermal replay of (16), the disk estimate);
//! - [`method`]: the paper's identification, then the diagnosis — noise floors, where the gap
//!   lies, recalibration, class selection, black box, typed findings and verdict;
//! - [`report`]: rendering a diagnosis (Markdown, JSON, figures, table rows);
//!
//! Pure: nothing here reads a clock, a file or the machine's state, touches a socket or uses
//! tokio; files are opened and written by the CLI and the fleet shell.

pub mod eval;
pub mod fit;
pub mod method;
pub mod model;
pub mod quality;
pub mod record;
pub mod report;

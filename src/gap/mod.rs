//! Sim-to-real gap diagnosis (DESIGN.md §6, issues 7, 17 and 43). The folders are the method's
//! stages, each importing only the ones above it in this list:
//!
//! - [`data`]: bench records as read (schema, CSV, candump/MF4, resampling and cutting);
//! - [`fit`]: least squares and statistics, knowing nothing of clutches;
//! - [`model`]: what is fitted — a candidate model, its class terms and shapes, the effect
//!   classes (one `EffectClass` impl per family in [`model::classes`]), the typed parameters;
//! - [`record`]: a record as the diagnosis reads it, with its model-free series and events;
//! - [`eval`]: the model replayed on a record (the thermal replay of (16), the disk estimate);
//! - [`method`]: the paper's identification, then the diagnosis — noise floors, where the gap
//!   lies, recalibration, class selection, black box, typed findings and verdict;
//! - [`report`]: rendering a diagnosis (Markdown, JSON, figures, table rows);
//! - [`experiment`]: bench experiments that produce records (the plant core in process, the
//!   synthetic rig).
//!
//! Pure: nothing here reads a clock, touches a socket or uses tokio.

pub mod data;
pub mod eval;
pub mod experiment;
pub mod fit;
pub mod method;
pub mod model;
pub mod record;
pub mod report;

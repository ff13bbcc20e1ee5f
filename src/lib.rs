//! ddct: a virtual transmission control unit (TCU) for a dry dual-clutch transmission on CAN, the
//! plant that simulates it, and a sim-to-real gap diagnosis.
//!
//! Layout: `can` (bus contract, buses, logs), `model` (pure physics), `plant` and `tcu` (pure
//! cores stepped with `now` as an argument), `records` (bench records: schema, readers,
//! events), `experiment` (bench experiments on the plant that produce records), `identify` (the
//! paper's parameter identification, `ddct identify`), `gap` (diagnosis), `truth` (an
//! independent truth generator) and `blind` (the diagnosis's blind test against it).

pub mod bench;
pub mod blind;
pub mod can;
pub mod daemon;
pub mod diag;
pub mod error_chain;
pub mod experiment;
pub mod gap;
pub mod identify;
pub mod io_error;
pub mod model;
pub mod num_text;
pub mod par;
pub mod parquet_file;
pub mod plant;
pub mod plot;
pub mod ranges;
pub mod records;
pub mod sim;
pub mod tcu;
pub mod toml_key;
pub mod truth;

//! Sim-to-real gap diagnosis (DESIGN.md §6, issue 7): bench datasets ([`dataset`]), event
//! segmentation ([`events`]), a record as the diagnosis reads it ([`measured`]: its series, and
//! the model-free series derived from them kept by value in [`memo`]s: [`slip_shapes`],
//! [`windows`], [`power_sites`]; [`series`] the operations on them), the model replayed on
//! measured data per subsystem ([`replay`]; the disk temperature estimate in [`disk`], the
//! thermal replay from per-record windows in [`fast_replay`], the hooks in [`set_hooks`]), the paper's identification procedure ([`identify`]), the effect library as fit
//! candidates ([`candidates`]), where the gap lies ([`where_`]), the black-box discrepancy
//! ([`blackbox`]), the diagnosis itself ([`diagnose`]), in-process bench experiments on the plant
//! core ([`experiment`]), least squares ([`lsq`]) and statistics ([`stats`]), synthetic rig data
//! with known parameters ([`synth`]).
//!
//! Pure: nothing here reads a clock, touches a socket or uses tokio.

pub mod blackbox;
pub mod candidates;
pub mod class;
pub mod classes;
pub mod context;
pub mod dataset;
pub mod diagnose;
pub mod disk;
pub mod events;
pub mod experiment;
pub mod fast_replay;
pub mod finding;
pub mod findings_table;
pub mod form_error;
pub mod identify;
pub mod keys;
pub mod lsq;
pub mod measured;
pub mod memo;
pub mod power_sites;
pub mod record_frames;
pub mod replay;
pub mod report;
pub mod select;
pub mod series;
pub mod set_hooks;
pub mod shape;
pub mod slip_shapes;
pub mod stats;
pub mod synth;
pub mod terms;
pub mod where_;
pub mod windows;

//! Sim-to-real gap diagnosis (DESIGN.md §6, issue 7): bench datasets ([`dataset`]), event
//! segmentation ([`events`]), least squares ([`lsq`]) and statistics ([`stats`]), synthetic rig
//! data with known parameters ([`synth`]).
//!
//! Pure: nothing here reads a clock, touches a socket or uses tokio.

pub mod dataset;
pub mod events;
pub mod identify;
pub mod keys;
pub mod lsq;
pub mod replay;
pub mod stats;
pub mod synth;

//! Bench experiments that produce records: on the plant core in process ([`experiment`]) and the synthetic rig with known parameters ([`synth`]).

pub mod experiment;
pub mod synth;

//! Bench experiments that produce records: on the plant core in process ([`plant`]) and the synthetic rig with known parameters ([`synth`]).

pub mod plant;
pub mod synth;

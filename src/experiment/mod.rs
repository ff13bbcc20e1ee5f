//! Bench experiments that produce records with a known truth (the diagnosis's CLI experiments
//! and the tests): on the plant core in process ([`plant`]) and the synthetic rig with known parameters ([`synth`]).

pub mod plant;
pub mod synth;

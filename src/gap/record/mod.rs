//! A record as the diagnosis reads it ([`measured`]): plain data, with the model-free series derived from it kept by value in [`memo`]s ([`slip_shapes`], [`windows`], [`power_sites`]; [`series`] the operations on them).

pub mod measured;
pub mod memo;
pub mod power_sites;
pub mod series;
pub mod slip_shapes;
pub mod windows;

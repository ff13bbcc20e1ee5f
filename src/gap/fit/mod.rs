//! Least squares ([`lsq`]: the problem separate from its Levenberg–Marquardt solver) and the statistics the method reads ([`stats`]: seeded RNG, bootstrap, quantiles).

pub mod lsq;
pub mod stats;

//! The slip dependence Q(ω) of the equivalent friction radius (6) at every sample of a record,
//! for the torque predictions (`gap::eval::predict`).
//!
//! Q depends on the clutch's γ, R1 and R2 and on the measured slip alone. No recalibration and
//! no effect class moves γ, R1 or R2, so the thousands of models a diagnosis evaluates on one
//! record share one Q per sample: it is computed once per record and geometry (two cube roots and
//! two table lookups of [`crate::model::slip_integral`] a sample) and kept by the record
//! ([`crate::gap::record::measured::Measured::slip_shapes`], keyed by the three parameters' bits); the
//! numbers are the ones [`clutch::slip_shape`] gives.

use crate::model::clutch;
use crate::model::params::ClutchParams;

/// Q(ω) of (6) at every sample of one record, for one clutch geometry.
#[derive(Debug)]
pub struct SlipShapes {
    q: [Vec<f64>; 2],
}

impl SlipShapes {
    /// The key of a geometry: γ, R1, R2 (bits).
    pub fn key(p: &ClutchParams) -> [u64; 3] {
        [p.gamma_s_per_m, p.r1_m, p.r2_m].map(f64::to_bits)
    }

    /// Q of each clutch's slip `slip` for the geometry of `p`.
    pub fn new(p: &ClutchParams, slip: [&[f64]; 2]) -> Self {
        SlipShapes {
            q: [0, 1].map(|i| slip[i].iter().map(|&w| clutch::slip_shape(p, w)).collect()),
        }
    }

    /// Q(ω) of clutch `i` at sample `k` (m).
    #[inline]
    pub fn at(&self, i: usize, k: usize) -> f64 {
        self.q[i][k]
    }
}

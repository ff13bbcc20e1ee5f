//! The slip dependence Q(ω) of the equivalent friction radius (6) at every sample of a record,
//! for the torque predictions of [`super::candidates`].
//!
//! Q depends on the clutch's γ, R1 and R2 and on the measured slip alone. No recalibration and
//! no effect class moves γ, R1 or R2, so the thousands of models a diagnosis evaluates on one
//! record share one Q per sample: it is computed once per record (two cube roots and two table
//! lookups of [`crate::model::slip_integral`] a sample) and kept in the record's
//! [`SlipShapeCache`], keyed by the three parameters' bits and the slip series it was made from.
//! A model with other values computes Q itself: the cache only saves work, the numbers are the
//! ones [`clutch::slip_shape`] gives.
//!
//! The sliding acceleration d|ω|/dt a friction term of that variable reads
//! ([`super::candidates::slide_acceleration`]) is a function of the measured slip alone too: it
//! is kept the same way ([`SlideCache`]), keyed by the slip series and the sample time.

use std::sync::Arc;

use super::record_cache::RecordCache;

use super::replay::{Measured, Shared};
use crate::model::clutch;
use crate::model::params::ClutchParams;

/// A record's [`SlipShapes`], one per set of (γ, R1, R2) asked for; clones of a [`Measured`]
/// share it.
#[derive(Debug, Clone, Default)]
pub struct SlipShapeCache(RecordCache<SlipShapes>);

/// Q(ω) of (6) at every sample of one record, for one clutch geometry.
#[derive(Debug)]
pub struct SlipShapes {
    /// γ, R1, R2 (bits).
    key: [u64; 3],
    /// The slip series Q was computed from (a clone of the record with other slips must not take
    /// it).
    slip: [Shared; 2],
    q: [Vec<f64>; 2],
}

fn key(p: &ClutchParams) -> [u64; 3] {
    [p.gamma_s_per_m, p.r1_m, p.r2_m].map(f64::to_bits)
}

impl SlipShapes {
    fn new(p: &ClutchParams, m: &Measured) -> Self {
        SlipShapes {
            key: key(p),
            slip: m.slip.clone(),
            q: [0, 1].map(|i| {
                m.slip[i]
                    .iter()
                    .map(|&w| clutch::slip_shape(p, w))
                    .collect()
            }),
        }
    }

    fn of(&self, p: &ClutchParams, m: &Measured) -> bool {
        self.key == key(p) && (0..2).all(|i| Arc::ptr_eq(&self.slip[i], &m.slip[i]))
    }

    /// Q(ω) of clutch `i` at sample `k` (m).
    #[inline]
    pub fn at(&self, i: usize, k: usize) -> f64 {
        self.q[i][k]
    }
}

impl SlipShapeCache {
    /// The slip shapes of `m` for the clutch `p`, made on first use.
    pub fn get(&self, p: &ClutchParams, m: &Measured) -> Arc<SlipShapes> {
        self.0.get(|s| s.of(p, m), || SlipShapes::new(p, m))
    }
}

/// A record's sliding accelerations ([`Slides`]); clones of a [`Measured`] share it.
#[derive(Debug, Clone, Default)]
pub struct SlideCache(RecordCache<Slides>);

/// [`super::candidates::slide_acceleration`] of each clutch's measured slip.
#[derive(Debug)]
pub struct Slides {
    /// The slip series and sample time (bits) they were computed from.
    slip: [Shared; 2],
    dt: u64,
    pub acc: [Vec<f64>; 2],
}

impl SlideCache {
    /// The sliding accelerations of `m`, made on first use.
    pub fn get(&self, m: &Measured) -> Arc<Slides> {
        self.0.get(
            |s| s.dt == m.dt.to_bits() && (0..2).all(|i| Arc::ptr_eq(&s.slip[i], &m.slip[i])),
            || Slides {
                slip: m.slip.clone(),
                dt: m.dt.to_bits(),
                acc: [0, 1].map(|i| super::candidates::slide_acceleration(&m.slip[i], m.dt)),
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::replay::test_record;
    use crate::model::params::Params;

    /// Every sample's Q is the one `clutch::slip_shape` computes, bit for bit; a clutch with
    /// another γ gets its own entry, the same clutch the same entry.
    #[test]
    fn the_cache_holds_what_slip_shape_computes() {
        let p = Params::default();
        let m = test_record(&p);
        let a = m.slip_shapes.get(&p.clutch, &m);
        let mut moving = 0;
        for i in 0..2 {
            for k in 0..m.n {
                let q = clutch::slip_shape(&p.clutch, m.slip[i][k]);
                assert_eq!(a.at(i, k).to_bits(), q.to_bits());
                moving += usize::from(m.slip[i][k] != 0.0);
            }
        }
        assert!(moving > 100, "the record slips at {moving} samples only");
        assert!(Arc::ptr_eq(&a, &m.slip_shapes.get(&p.clutch, &m)));
        let mut other = p.clutch;
        other.gamma_s_per_m *= 2.0;
        let b = m.slip_shapes.get(&other, &m);
        assert!(!Arc::ptr_eq(&a, &b));
        let k = (0..m.n).find(|&k| m.slip[0][k].abs() > 0.1).unwrap();
        assert_eq!(
            b.at(0, k).to_bits(),
            clutch::slip_shape(&other, m.slip[0][k]).to_bits()
        );
    }

    /// The kept sliding accelerations are the centred differences of |ω| over ±2 samples,
    /// computed here by hand; a clone with another slip series gets its own entry.
    #[test]
    fn the_slide_cache_holds_the_sliding_acceleration() {
        let p = Params::default();
        let m = test_record(&p);
        let a = m.slides.get(&m);
        let n = m.n;
        for i in 0..2 {
            let w = |k: usize| m.slip[i][k].abs();
            for k in 0..n {
                let (lo, hi) = (k.saturating_sub(2), (k + 2).min(n - 1));
                let want = (w(hi) - w(lo)) / ((hi - lo) as f64 * m.dt);
                assert_eq!(
                    a.acc[i][k].to_bits(),
                    want.to_bits(),
                    "clutch {i} sample {k}"
                );
            }
        }
        assert!(
            a.acc[0].iter().any(|v| v.abs() > 1.0),
            "the record never slides"
        );
        assert!(Arc::ptr_eq(&a, &m.slides.get(&m)));
        let mut other = m.clone();
        other.slip[0] = m.slip[0].iter().map(|w| 2.0 * w).collect();
        let b = other.slides.get(&other);
        assert!(!Arc::ptr_eq(&a, &b));
        assert_eq!(b.acc[0][10].to_bits(), (2.0 * a.acc[0][10]).to_bits());
    }
}

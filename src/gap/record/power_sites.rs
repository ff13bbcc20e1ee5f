//! The measured friction power P = T_c·ω_fc of every sample located among the knots of the
//! facing-surface rise ([`crate::gap::model::terms::Surface`], the hidden surface temperature of the
//! friction's temperature dependence (4)): the segment each sample's power falls in and how far
//! along it.
//!
//! A surface fit moves the rise's values and its time constant, never its knots (a class's knots
//! are fixed for the diagnosis; the library member's are fixed numbers), and the power is
//! measured. So the hundreds of surface replays a fit makes on a record share one location per
//! sample: it is computed once per record and set of knots
//! ([`crate::gap::record::measured::Measured::power_sites`], keyed by the knots' bits), and each replay reads
//! the value at it ([`Shape::at`]), the same number [`Shape::eval`] gives.

use crate::gap::model::shape::{Shape, Site};

/// Each clutch's friction power (floored at zero) located on one set of knots.
#[derive(Debug)]
pub struct PowerSites {
    sites: [Vec<Site>; 2],
}

impl PowerSites {
    /// Each clutch's power `power` located on the knots of `rise`.
    pub fn locate(rise: &Shape, power: [&[f64]; 2]) -> Self {
        PowerSites {
            sites: [0, 1].map(|i| power[i].iter().map(|p| rise.locate(p.max(0.0))).collect()),
        }
    }

    /// The site of clutch `i`'s power at sample `k`.
    #[inline]
    pub fn at(&self, i: usize, k: usize) -> Site {
        self.sites[i][k]
    }
}

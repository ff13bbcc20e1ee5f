//! The measured friction power P = T_c·ω_fc of every sample located among the knots of the
//! facing-surface rise ([`super::terms::Surface`], the hidden surface temperature of the
//! friction's temperature dependence (4)): the segment each sample's power falls in and how far
//! along it.
//!
//! A surface fit moves the rise's values and its time constant, never its knots (a class's knots
//! are fixed for the diagnosis; the library member's are fixed numbers), and the power is
//! measured. So the hundreds of surface replays a fit makes on a record share one location per
//! sample: it is computed once ([`PowerSiteCache`], keyed by the knots' bits and the power series
//! it was made from), and each replay reads the value at it ([`Shape::at`]), the same number
//! [`Shape::eval`] gives.

use std::sync::Arc;

use super::record_cache::RecordCache;
use super::replay::{Measured, Shared};
use super::shape::{Shape, Site, KNOTS};

/// A record's [`PowerSites`], one per set of knots asked for; clones of a [`Measured`] share it.
#[derive(Debug, Clone, Default)]
pub struct PowerSiteCache(RecordCache<PowerSites>);

/// Each clutch's friction power (floored at zero) located on one set of knots.
#[derive(Debug)]
pub struct PowerSites {
    /// The knots (bits).
    z: [u64; KNOTS],
    /// The power series they were located from.
    power: [Shared; 2],
    sites: [Vec<Site>; 2],
}

impl PowerSites {
    /// The site of clutch `i`'s power at sample `k`.
    #[inline]
    pub fn at(&self, i: usize, k: usize) -> Site {
        self.sites[i][k]
    }
}

impl PowerSiteCache {
    /// The friction powers of `m` located on the knots of `rise`, made on first use.
    pub fn get(&self, rise: &Shape, m: &Measured) -> Arc<PowerSites> {
        let z = rise.z.map(f64::to_bits);
        self.0.get(
            |s| s.z == z && (0..2).all(|i| Arc::ptr_eq(&s.power[i], &m.power[i])),
            || PowerSites {
                z,
                power: m.power.clone(),
                sites: [0, 1].map(|i| m.power[i].iter().map(|p| rise.locate(p.max(0.0))).collect()),
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::replay::test_record;
    use crate::model::params::Params;

    /// Every sample's value at its kept site is the curve's value at the sample's power, bit for
    /// bit, for curves of other values on the same knots; other knots get their own entry.
    #[test]
    fn a_kept_site_gives_the_curves_value_at_the_power() {
        let p = Params::default();
        let m = test_record(&p);
        let z = [0.0, 500.0, 1e3, 2e3, 4e3, 8e3, 16e3];
        let curves = [
            Shape {
                z,
                v: [0.0, 1.0, 3.0, 4.0, 9.0, 10.0, 30.0],
            },
            Shape {
                z,
                v: [0.0, -2.0, 0.5, 7.0, 7.5, 20.0, 21.0],
            },
        ];
        let sites = m.power_sites.get(&curves[0], &m);
        let mut segments = std::collections::BTreeSet::new();
        for c in &curves {
            for i in 0..2 {
                for k in 0..m.n {
                    let x = m.power[i][k].max(0.0);
                    assert_eq!(c.at(sites.at(i, k)).to_bits(), c.eval(x).to_bits());
                    segments.insert(sites.at(i, k).seg);
                }
            }
        }
        assert!(
            segments.len() >= 3,
            "the record's powers fall in segments {segments:?} only"
        );
        assert!(Arc::ptr_eq(&sites, &m.power_sites.get(&curves[1], &m)));
        let mut other = curves[0];
        other.z[1] = 600.0;
        assert!(!Arc::ptr_eq(&sites, &m.power_sites.get(&other, &m)));
    }
}

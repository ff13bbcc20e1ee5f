//! The 95 % interval of a class's magnitude by the delta method ([`magnitude_ci95`];
//! the noise it holds: `gap::method::form_error`).

use super::effect_class::EffectClass;
use super::knots::Knots;
use crate::gap::fit::lsq::{Fit, Z95};
use crate::gap::model::candidate::Model;

/// The 95 % interval of a fitted class's magnitude by the delta method: the magnitude's
/// gradient in the class's parameters (central differences of half a standard error) with the
/// fit's covariance of those parameters (the recalibration's left out: the magnitude does not
/// read them). `None` when a parameter the magnitude moves with is not identifiable.
pub fn magnitude_ci95(
    class: &dyn EffectClass,
    knots: &Knots,
    m: &Model,
    fit: &Fit,
) -> Option<(f64, f64)> {
    let (mag, _) = class.magnitude(m);
    let k = fit.p.len();
    let nc = class.params(m).len().min(k);
    let at = |j: usize, h: f64| {
        let mut v = fit.p[..nc].to_vec();
        v[j] += h;
        let mut q = *m;
        class.remove(&mut q, m);
        class.apply(knots, &mut q, &v);
        class.magnitude(&q).0
    };
    let mut grad = vec![0.0; nc];
    for (j, g) in grad.iter_mut().enumerate() {
        let se = fit.std_err[j];
        if se == 0.0 {
            continue;
        }
        if !se.is_finite() {
            return None;
        }
        let h = 0.5 * se;
        *g = (at(j, h) - at(j, -h)) / (2.0 * h);
    }
    let mut var = 0.0;
    for i in 0..nc {
        for j in 0..nc {
            let r = if i == j {
                1.0
            } else {
                fit.correlation[i * k + j]
            };
            let c = grad[i] * grad[j] * fit.std_err[i] * fit.std_err[j];
            if c != 0.0 {
                if !r.is_finite() {
                    return None;
                }
                var += r * c;
            }
        }
    }
    let half = Z95 * var.max(0.0).sqrt();
    Some((mag - half, mag + half))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::model::candidate::Model;
    use crate::gap::model::class::{ClassId, Variable};

    /// The surface temperature's rise at 30 kW, a knot here, is the sum of the first five
    /// increments: its interval is ±1.96·√(gᵀΣg) with g = (1, 1, 1, 1, 1, 0, 0), whatever
    /// τ_s's error — 2 K per increment, two of them correlated 0.5: √(5·4 + 2·0.5·4) = √24.
    #[test]
    fn a_magnitude_interval_is_the_delta_method_of_the_parameters() {
        let mut knots = Knots::default();
        knots
            .0
            .insert(Variable::Power, [500.0, 4e3, 8e3, 15e3, 22e3, 30e3, 45e3]);
        let c = ClassId::FrictionSurfaceTemperature.fit();
        let base = Model::nominal(crate::model::params::Params::default());
        let p = vec![20.0, 15.0, 10.0, 8.0, 5.0, 3.0, 0.4];
        let mut m = base;
        c.apply(&knots, &mut m, &p);
        let (mag, _) = c.magnitude(&m);
        assert!((mag - 58.0).abs() < 1e-9, "{mag}");
        let k = p.len();
        let mut correlation = vec![0.0; k * k];
        for i in 0..k {
            correlation[i * k + i] = 1.0;
        }
        correlation[1] = 0.5;
        correlation[k] = 0.5;
        let fit = Fit {
            names: c.params(&base).into_iter().map(|s| s.name).collect(),
            std_err: vec![2.0, 2.0, 2.0, 2.0, 2.0, 2.0, 0.3],
            ci95: vec![(0.0, 0.0); k],
            at_bound: vec![false; k],
            p,
            sse: 1.0,
            n: 1000,
            n_eff: 1000.0,
            iterations: 5,
            converged: true,
            correlation,
        };
        let (lo, hi) = magnitude_ci95(c, &knots, &m, &fit).unwrap();
        let half = Z95 * 24f64.sqrt();
        assert!((lo - (mag - half)).abs() < 1e-6 && (hi - (mag + half)).abs() < 1e-6);
        // A parameter the magnitude moves with that is not identifiable: no interval.
        let mut loose = fit.clone();
        loose.std_err[2] = f64::INFINITY;
        assert_eq!(magnitude_ci95(c, &knots, &m, &loose), None);
    }
}

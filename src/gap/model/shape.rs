//! The flexible, shape-constrained representation of an effect class's term (issue 17 item 1):
//! a piecewise-linear curve s(z) over [`KNOTS`] knots placed in the driving variable's range in
//! the training records (quantiles mixed with an even spacing, see [`Shape::knots`]), anchored
//! at s(z₀) = 0 at the first knot, each increment bounded by physics (the class's bounds in
//! `classes`), and extrapolated linearly beyond the end knots (so a validation record hotter
//! than the training ones still sees the trend).
//!
//! The increments may change sign once (a peak, or a first segment that jumps where the
//! variable's low end is invisible: a clamp load of zero transmits no torque, so the curve's
//! anchor there is free and its first segment acts as a level); a curve that turns more than
//! once is refitted monotone (`select::fit`, `classes::zigzag_sign`). The truths are monotone,
//! but the term carries the effect as the recalibrated (possibly detuned) model sees it: bounded
//! to one sign everywhere (each direction fitted from no effect, the better kept), a friction
//! falling with clamp load on a detuned baseline (`scripts/gap-cases`,
//! clamp_load_power_detuned_2) fitted ΔBIC −1 206 instead of −3 561 and lost to
//! `actuator_transfer` (−2 386); left free, seven knots zigzagged on a static-friction change
//! over the temperature (static_friction: validation gain 4.5 %, not significant, against 22 %
//! as a monotone curve). Measured in session 16.
//!
//! A parametric member of the class (a linear spring-stiffness law, a power law in the clamp
//! load, …) is a special case up to the piecewise-linear approximation; any monotone form in
//! other families (exponential, saturating, power, splines) is represented to within the
//! interpolation error between knots.

/// Number of knots.
pub const KNOTS: usize = 7;

/// A piecewise-linear curve anchored at zero at its first knot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shape {
    /// Knot positions (increasing).
    pub z: [f64; KNOTS],
    /// Values at the knots (v[0] = 0).
    pub v: [f64; KNOTS],
}

/// A point located among a [`Shape`]'s knots ([`Shape::locate`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Site {
    /// The segment (0 … KNOTS − 2).
    pub seg: usize,
    /// The fraction of the way along it (below 0 or above 1 on the extended end segments).
    pub f: f64,
}

impl Shape {
    /// Knots between the 2 and 98 % quantiles of `values` (finite ones), evenly spaced in the
    /// quantiles of an equal mixture of the data and the uniform distribution over that range:
    /// dense where the data are, but no segment wider than twice an even spacing, so a change
    /// near the end of a long-tailed variable (a step in the friction energy that only the end
    /// of one record reaches) still falls between close knots. Spread apart when the data are
    /// concentrated. `None` when the variable does not vary.
    pub fn knots(values: impl Iterator<Item = f64>) -> Option<[f64; KNOTS]> {
        let mut v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
        if v.len() < 2 * KNOTS {
            return None;
        }
        v.sort_by(f64::total_cmp);
        let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
        let (lo, hi) = (q(0.02), q(0.98));
        let tol = 1e-9 * (lo.abs() + hi.abs()).max(1e-12);
        // Not wider than the tolerance, or not a number.
        if (hi - lo).partial_cmp(&tol) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        // The mixture's distribution function on [lo, hi], from 0 at lo to 1 at hi.
        let (n_lo, n_hi) = (
            v.partition_point(|x| *x < lo) as f64,
            v.partition_point(|x| *x <= hi) as f64,
        );
        let cdf = |x: f64| {
            let emp = (v.partition_point(|y| *y <= x) as f64 - n_lo) / (n_hi - n_lo).max(1.0);
            0.5 * emp.clamp(0.0, 1.0) + 0.5 * (x - lo) / (hi - lo)
        };
        let mut z = [lo; KNOTS];
        z[KNOTS - 1] = hi;
        for (i, zi) in z.iter_mut().enumerate().take(KNOTS - 1).skip(1) {
            let p = i as f64 / (KNOTS - 1) as f64;
            let (mut a, mut b) = (lo, hi);
            for _ in 0..60 {
                let m = 0.5 * (a + b);
                if cdf(m) < p {
                    a = m;
                } else {
                    b = m;
                }
            }
            *zi = 0.5 * (a + b);
        }
        // At least 5 % of the range between knots (concentrated data, e.g. one rig speed).
        let min_gap = 0.05 * (hi - lo);
        for i in 1..KNOTS {
            if z[i] < z[i - 1] + min_gap {
                z[i] = z[i - 1] + min_gap;
            }
        }
        Some(z)
    }

    /// A curve from knots and the increments between them (`d.len() == KNOTS − 1`).
    pub fn from_increments(z: [f64; KNOTS], d: &[f64]) -> Shape {
        let mut v = [0.0; KNOTS];
        for i in 1..KNOTS {
            v[i] = v[i - 1] + d.get(i - 1).copied().unwrap_or(0.0);
        }
        Shape { z, v }
    }

    /// The flat curve (no effect).
    pub fn zero(z: [f64; KNOTS]) -> Shape {
        Shape { z, v: [0.0; KNOTS] }
    }

    /// Value at `x`: linear between knots, linear extrapolation of the end segments.
    #[inline]
    pub fn eval(&self, x: f64) -> f64 {
        self.at(self.locate(x))
    }

    /// Where `x` lies among the knots: its segment and the fraction of the way along it (outside
    /// the knots, of the end segment extended). It reads the knots alone, so a series located
    /// once serves every curve on the same knots: [`Self::at`] of it is [`Self::eval`].
    #[inline]
    pub fn locate(&self, x: f64) -> Site {
        let seg = self.segment(x);
        let z = &self.z;
        let w = (z[seg + 1] - z[seg]).max(1e-300);
        Site {
            seg,
            f: (x - z[seg]) / w,
        }
    }

    /// The value at a [`Site`] located on this curve's knots.
    #[inline]
    pub fn at(&self, s: Site) -> f64 {
        self.v[s.seg] + s.f * (self.v[s.seg + 1] - self.v[s.seg])
    }

    /// Slope ds/dx at `x` (of the segment `x` falls in).
    #[inline]
    pub fn slope(&self, x: f64) -> f64 {
        let seg = self.segment(x);
        (self.v[seg + 1] - self.v[seg]) / (self.z[seg + 1] - self.z[seg]).max(1e-300)
    }

    /// The segment whose line gives the value at `x` (the end ones extrapolated).
    #[inline]
    fn segment(&self, x: f64) -> usize {
        let z = &self.z;
        if x <= z[1] {
            0
        } else if x >= z[KNOTS - 2] {
            KNOTS - 2
        } else {
            let mut i = 1;
            while i < KNOTS - 2 && x > z[i + 1] {
                i += 1;
            }
            i
        }
    }

    /// Largest |s| over the knots (the magnitude of the term over the training range).
    pub fn magnitude(&self) -> f64 {
        self.v.iter().fold(0.0, |a, b| a.max(b.abs()))
    }

    /// Signed change over the training range, s(z_last) − s(z₀).
    pub fn span(&self) -> f64 {
        self.v[KNOTS - 1] - self.v[0]
    }

    /// (z, s(z)) at the knots.
    pub fn points(&self) -> Vec<(f64, f64)> {
        self.z.iter().copied().zip(self.v.iter().copied()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The slope is the difference quotient of `eval` inside every segment and beyond the ends.
    #[test]
    fn slope_is_the_segment_difference_quotient() {
        let z = std::array::from_fn(|i| i as f64);
        let d: Vec<f64> = (1..KNOTS).map(|i| [1.0, 2.0, 0.5, -0.5][i % 4]).collect();
        let s = Shape::from_increments(z, &d);
        for x in [-2.0, 0.3, 1.5, 2.2, 3.7, 5.4, 9.0] {
            let h = 1e-6;
            let q = (s.eval(x + h) - s.eval(x - h)) / (2.0 * h);
            assert!((s.slope(x) - q).abs() < 1e-6, "{x}: {} vs {q}", s.slope(x));
        }
    }

    #[test]
    fn interpolates_and_extrapolates_linearly() {
        // Knots 0, 1, …; increments 1, 2, 0.5, 0.5, … (values 0, 1, 3, 3.5, 4, …).
        let z: [f64; KNOTS] = std::array::from_fn(|i| i as f64);
        let d: Vec<f64> = (1..KNOTS)
            .map(|i| [1.0, 2.0, 0.5][(i - 1).min(2)])
            .collect();
        let s = Shape::from_increments(z, &d);
        assert_eq!(&s.v[..4], &[0.0, 1.0, 3.0, 3.5]);
        assert!((s.eval(0.5) - 0.5).abs() < 1e-12);
        assert!((s.eval(1.5) - 2.0).abs() < 1e-12);
        assert!((s.eval(2.5) - 3.25).abs() < 1e-12);
        // Extrapolation continues the end slopes.
        let last = (KNOTS - 1) as f64;
        assert!((s.eval(-1.0) + 1.0).abs() < 1e-12);
        assert!((s.eval(last + 2.0) - (s.v[KNOTS - 1] + 1.0)).abs() < 1e-12);
        assert_eq!(s.magnitude(), s.v[KNOTS - 1]);
        assert_eq!(s.span(), s.v[KNOTS - 1]);
    }

    /// A long-tailed variable (most samples low, a few far out, as the friction energy of a
    /// short hot record beside a long sweep): the quantiles alone put the last segment over the
    /// upper half of the range; the mixed knots keep every segment within twice an even spacing
    /// and still place more knots where the samples are.
    #[test]
    fn knots_of_a_long_tailed_variable_cover_its_end() {
        let x = (0..10_000).map(|i| {
            let u = i as f64 / 9_999.0;
            if i % 2 == 0 {
                0.07 * u
            } else {
                0.8 * u
            }
        });
        let z = Shape::knots(x).unwrap();
        let (lo, hi) = (z[0], z[KNOTS - 1]);
        let even = (hi - lo) / (KNOTS - 1) as f64;
        for w in z.windows(2) {
            assert!(w[1] - w[0] <= 2.0 * even + 1e-12, "{z:?}");
            assert!(w[1] > w[0]);
        }
        // Denser than even where half the samples lie (below 0.07).
        assert!(z[1] - z[0] < even, "{z:?}");
        // The quantiles (2/98 %) bound the range.
        assert!(lo < 0.01 && (0.75..0.8).contains(&hi), "{z:?}");
    }

    #[test]
    fn approximates_a_smooth_monotone_form() {
        // An exponential form, unknown to the shape: the knot fit is within the
        // interpolation bound h²/8·max|f''| between knots.
        let f = |x: f64| (-x / 80.0).exp() - 1.0;
        let z = Shape::knots((0..1000).map(|i| 25.0 + 0.25 * i as f64)).unwrap();
        let d: Vec<f64> = (1..KNOTS).map(|i| f(z[i]) - f(z[i - 1])).collect();
        let s = Shape::from_increments(z, &d);
        let h = z.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
        let bound = h * h / 8.0 / (80.0f64 * 80.0) + 1e-12;
        for i in 0..100 {
            let x = z[0] + (z[KNOTS - 1] - z[0]) * i as f64 / 99.0;
            assert!((s.eval(x) - (f(x) - f(z[0]))).abs() <= bound, "{x}");
        }
    }

    #[test]
    fn knots_need_variation() {
        assert!(Shape::knots(std::iter::repeat_n(3.0, 100)).is_none());
        assert!(Shape::knots([1.0, 2.0].into_iter()).is_none());
        let z = Shape::knots((0..100).map(|i| if i < 95 { 10.0 } else { 20.0 })).unwrap();
        assert!(z.windows(2).all(|w| w[1] > w[0]));
    }
}

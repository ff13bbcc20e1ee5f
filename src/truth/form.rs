//! Functional forms of the truth's effects: monotone maps f: [0, 1] → [0, 1] with f(0) = 0 and
//! f(1) = 1, drawn from broad families. An effect scales or shifts a term of the model by
//! `a·f(z)` (or `a·(f(z) − 1)`), z being its driving variable normalised to [0, 1]; the family is
//! recorded in the truth so that accuracy can be reported per family.

use super::rng::Xoshiro;
use std::fmt;

/// Families of functional forms.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum Family {
    /// Monotone cubic Hermite spline (Fritsch–Carlson slopes) through 3–6 random knots.
    Spline,
    /// z^p, p log-uniform in [0.3, 3.5].
    Power,
    /// (e^{kz} − 1)/(e^k − 1), |k| in [0.7, 6].
    Exponential,
    /// 1 − e^{−z/z0} or tanh((z − z_c)/w), normalised: a rise that levels off.
    Saturating,
    /// Monotone piecewise-linear through 2–4 random interior knots.
    PiecewiseLinear,
    /// A constant parameter (dead time, gain, offset, backlash width, …): no driving variable.
    Scalar,
}

impl Family {
    /// The families a variable-driven effect draws from.
    pub const SHAPES: [Family; 5] = [
        Family::Spline,
        Family::Power,
        Family::Exponential,
        Family::Saturating,
        Family::PiecewiseLinear,
    ];
    pub const ALL: [Family; 6] = [
        Family::Spline,
        Family::Power,
        Family::Exponential,
        Family::Saturating,
        Family::PiecewiseLinear,
        Family::Scalar,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            Family::Spline => "spline",
            Family::Power => "power",
            Family::Exponential => "exponential",
            Family::Saturating => "saturating",
            Family::PiecewiseLinear => "piecewise_linear",
            Family::Scalar => "scalar",
        }
    }

    pub fn parse(s: &str) -> Option<Family> {
        Family::ALL.iter().copied().find(|f| f.as_str() == s)
    }
}

impl fmt::Display for Family {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A drawn monotone form.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(tag = "family", rename_all = "snake_case")]
pub enum Form {
    Spline {
        xs: Vec<f64>,
        ys: Vec<f64>,
        #[serde(skip)]
        slopes: Vec<f64>,
    },
    Power {
        p: f64,
    },
    Exponential {
        k: f64,
    },
    Saturating {
        /// `exp`: 1 − e^{−z/scale}; `tanh`: tanh((z − centre)/scale).
        kind: &'static str,
        scale: f64,
        centre: f64,
    },
    PiecewiseLinear {
        xs: Vec<f64>,
        ys: Vec<f64>,
    },
    /// f ≡ 1 (a constant effect).
    Scalar,
}

/// Random monotone knots: 0 = x0 < … < xn = 1, 0 = y0 ≤ … ≤ yn = 1 with random increments.
fn random_knots(rng: &mut Xoshiro, interior: usize) -> (Vec<f64>, Vec<f64>) {
    let mut xs: Vec<f64> = (0..interior).map(|_| rng.range(0.05, 0.95)).collect();
    xs.sort_by(f64::total_cmp);
    xs.dedup_by(|a, b| (*a - *b).abs() < 0.03);
    xs.insert(0, 0.0);
    xs.push(1.0);
    // Increments with a heavy spread (some segments nearly flat, some steep).
    let inc: Vec<f64> = (1..xs.len()).map(|_| rng.log_uniform(0.02, 1.0)).collect();
    let total: f64 = inc.iter().sum();
    let mut ys = vec![0.0];
    let mut acc = 0.0;
    for d in inc {
        acc += d / total;
        ys.push(acc);
    }
    *ys.last_mut().unwrap() = 1.0;
    (xs, ys)
}

/// Fritsch–Carlson monotone slopes of a cubic Hermite interpolant.
fn monotone_slopes(xs: &[f64], ys: &[f64]) -> Vec<f64> {
    let n = xs.len();
    let d: Vec<f64> = (0..n - 1)
        .map(|i| (ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i]))
        .collect();
    let mut m = vec![0.0; n];
    m[0] = d[0];
    m[n - 1] = d[n - 2];
    for i in 1..n - 1 {
        m[i] = if d[i - 1] * d[i] <= 0.0 {
            0.0
        } else {
            // Weighted harmonic mean (Fritsch–Butland), monotone by construction.
            let (h0, h1) = (xs[i] - xs[i - 1], xs[i + 1] - xs[i]);
            let w1 = 2.0 * h1 + h0;
            let w2 = h1 + 2.0 * h0;
            (w1 + w2) / (w1 / d[i - 1] + w2 / d[i])
        };
    }
    for i in 0..n - 1 {
        if d[i] == 0.0 {
            m[i] = 0.0;
            m[i + 1] = 0.0;
            continue;
        }
        let (a, b) = (m[i] / d[i], m[i + 1] / d[i]);
        let s = a * a + b * b;
        if s > 9.0 {
            let t = 3.0 / s.sqrt();
            m[i] = t * a * d[i];
            m[i + 1] = t * b * d[i];
        }
    }
    m
}

impl Form {
    /// Draws a form of `family`.
    pub fn draw(family: Family, rng: &mut Xoshiro) -> Form {
        match family {
            Family::Spline => {
                let k = 1 + rng.below(4);
                let (xs, ys) = random_knots(rng, k);
                let slopes = monotone_slopes(&xs, &ys);
                Form::Spline { xs, ys, slopes }
            }
            Family::Power => Form::Power {
                p: rng.log_uniform(0.3, 3.5),
            },
            Family::Exponential => Form::Exponential {
                k: rng.sign() * rng.range(0.7, 6.0),
            },
            Family::Saturating => {
                if rng.uniform() < 0.5 {
                    Form::Saturating {
                        kind: "exp",
                        scale: rng.log_uniform(0.04, 0.6),
                        centre: 0.0,
                    }
                } else {
                    Form::Saturating {
                        kind: "tanh",
                        scale: rng.log_uniform(0.05, 0.4),
                        centre: rng.range(0.1, 0.8),
                    }
                }
            }
            Family::PiecewiseLinear => {
                let k = 2 + rng.below(3);
                let (xs, ys) = random_knots(rng, k);
                Form::PiecewiseLinear { xs, ys }
            }
            Family::Scalar => Form::Scalar,
        }
    }

    pub fn family(&self) -> Family {
        match self {
            Form::Spline { .. } => Family::Spline,
            Form::Power { .. } => Family::Power,
            Form::Exponential { .. } => Family::Exponential,
            Form::Saturating { .. } => Family::Saturating,
            Form::PiecewiseLinear { .. } => Family::PiecewiseLinear,
            Form::Scalar => Family::Scalar,
        }
    }

    /// f(z), z clamped to [0, 1]; f(0) = 0, f(1) = 1, non-decreasing.
    pub fn eval(&self, z: f64) -> f64 {
        let z = if z.is_nan() { 0.0 } else { z.clamp(0.0, 1.0) };
        match self {
            Form::Spline { xs, ys, slopes } => {
                let i = segment(xs, z);
                let h = xs[i + 1] - xs[i];
                let t = (z - xs[i]) / h;
                let (t2, t3) = (t * t, t * t * t);
                (2.0 * t3 - 3.0 * t2 + 1.0) * ys[i]
                    + (t3 - 2.0 * t2 + t) * h * slopes[i]
                    + (-2.0 * t3 + 3.0 * t2) * ys[i + 1]
                    + (t3 - t2) * h * slopes[i + 1]
            }
            Form::Power { p } => z.powf(*p),
            Form::Exponential { k } => ((k * z).exp() - 1.0) / (k.exp() - 1.0),
            Form::Saturating {
                kind,
                scale,
                centre,
            } => {
                if *kind == "exp" {
                    (1.0 - (-z / scale).exp()) / (1.0 - (-1.0 / scale).exp())
                } else {
                    let g = |x: f64| ((x - centre) / scale).tanh();
                    (g(z) - g(0.0)) / (g(1.0) - g(0.0))
                }
            }
            Form::PiecewiseLinear { xs, ys } => {
                let i = segment(xs, z);
                let t = (z - xs[i]) / (xs[i + 1] - xs[i]);
                ys[i] + t * (ys[i + 1] - ys[i])
            }
            Form::Scalar => 1.0,
        }
    }

    /// Short text for reports.
    pub fn describe(&self) -> String {
        match self {
            Form::Spline { xs, .. } => format!("monotone spline, {} knots", xs.len()),
            Form::Power { p } => format!("z^{p:.2}"),
            Form::Exponential { k } => format!("(e^({k:.2}z)−1)/(e^{k:.2}−1)"),
            Form::Saturating {
                kind,
                scale,
                centre,
            } => {
                if *kind == "exp" {
                    format!("1−e^(−z/{scale:.2}) normalised")
                } else {
                    format!("tanh((z−{centre:.2})/{scale:.2}) normalised")
                }
            }
            Form::PiecewiseLinear { xs, .. } => {
                format!("piecewise linear, {} segments", xs.len() - 1)
            }
            Form::Scalar => "constant".into(),
        }
    }
}

fn segment(xs: &[f64], z: f64) -> usize {
    let n = xs.len();
    let mut i = 0;
    while i + 2 < n && z > xs[i + 1] {
        i += 1;
    }
    i
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_family_is_monotone_and_normalised() {
        let mut rng = Xoshiro::new(3);
        for fam in Family::SHAPES {
            for _ in 0..200 {
                let f = Form::draw(fam, &mut rng);
                assert_eq!(f.family(), fam);
                assert!(f.eval(0.0).abs() < 1e-9, "{f:?}");
                assert!((f.eval(1.0) - 1.0).abs() < 1e-9, "{f:?}");
                let mut prev = f.eval(0.0);
                for k in 1..=400 {
                    let v = f.eval(k as f64 / 400.0);
                    assert!(v >= prev - 1e-12, "{f:?} not monotone at {k}");
                    assert!(v.is_finite());
                    prev = v;
                }
            }
        }
        assert_eq!(Form::Scalar.eval(0.3), 1.0);
    }
}

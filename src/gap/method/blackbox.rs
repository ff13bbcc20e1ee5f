//! Black-box discrepancy of the torque characteristic (Kennedy–O'Hagan style model discrepancy,
//! SINDy-like basis regression): the recalibrated model's torque residual is regressed on a
//! polynomial basis of operating variables — clutch temperature θ_c, slip, x_to past the kiss
//! point, friction power, its 0.5 s low-pass, dθ_c/dt and slip acceleration — as a relative
//! correction T_model·g(z) by ridge least squares on the training files, and evaluated on the
//! validation files. If it explains far more of the validation gap than the best library effect,
//! the gap lies outside the library; the variables it needs (by the validation loss when a
//! variable's terms are dropped) say what the missing physics depends on.

use crate::gap::model::candidate::Channel;
use crate::gap::record::measured::Measured;
use crate::gap::record::series;
use crate::model::clutch;
use crate::model::params::Params;
use nalgebra::{DMatrix, DVector};

/// The operating variables of the basis.
pub const VARIABLES: [&str; 6] = [
    "temperature",
    "slip",
    "x_to",
    "power",
    "temperature_rate",
    "slip_acceleration",
];

/// Per-sample operating variables of a torque sample (scaled to O(1)).
fn variables(
    p: &Params,
    m: &Measured,
    disk: &[Vec<f64>; 2],
    extra: &Extra,
    i: usize,
    k: usize,
    t_model: f64,
) -> [f64; 6] {
    let th = disk[i][k];
    let w = m.slip[i][k].abs();
    let x = m.x[i][k] - clutch::x_isp(&p.clutch, th);
    let pw = (t_model * w).abs() / 2e4;
    [
        (th - 100.0) / 100.0,
        (1.0 + w).ln() / 5.0 - 0.5,
        x,
        pw + extra.p_filt[i][k] / 2e4,
        extra.dth[i][k] / 5.0,
        extra.acc[i][k] / 100.0,
    ]
}

/// Per-file derived signals.
struct Extra {
    p_filt: [Vec<f64>; 2],
    dth: [Vec<f64>; 2],
    acc: [Vec<f64>; 2],
}

fn extra(m: &Measured, disk: &[Vec<f64>; 2]) -> Extra {
    let tau = 0.5;
    let a = (-m.dt / tau).exp();
    let p_filt = [0, 1].map(|i| {
        let mut f = 0.0;
        m.power[i]
            .iter()
            .map(|p| {
                f = a * f + (1.0 - a) * p.abs();
                f
            })
            .collect::<Vec<f64>>()
    });
    let dth = [0, 1].map(|i| series::derivative(&disk[i], m.dt, 10));
    let acc = [0, 1].map(|i| {
        let mag: Vec<f64> = m.slip[i].iter().map(|w| w.abs()).collect();
        series::derivative(&mag, m.dt, 3)
    });
    Extra { p_filt, dth, acc }
}

/// Basis features of one sample: T_model·[1, v, v², v·v'] over the variables kept.
fn features(v: &[f64; 6], keep: &[bool; 6], t_model: f64, out: &mut Vec<f64>) {
    out.clear();
    out.push(t_model);
    for a in 0..6 {
        if !keep[a] {
            continue;
        }
        out.push(t_model * v[a]);
        out.push(t_model * v[a] * v[a]);
        for b in a + 1..6 {
            if keep[b] {
                out.push(t_model * v[a] * v[b]);
            }
        }
    }
}

/// One file's torque samples for [`Design::collect`]: (file, samples of clutch 1, samples of
/// clutch 2, model torques, disk temperatures, first bootstrap unit, torque noise floor per
/// clutch).
pub type DesignItem<'a> = (
    &'a Measured,
    &'a [usize],
    &'a [usize],
    &'a [Vec<f64>; 2],
    &'a [Vec<f64>; 2],
    usize,
    [f64; 2],
);

/// Training or validation design for the torque channels of a set of files: per sample the
/// variables, the model torque and the residual, with the block (event) index.
#[derive(Debug, Clone, Default)]
pub struct Design {
    pub z: Vec<[f64; 6]>,
    pub t_model: Vec<f64>,
    pub resid: Vec<f64>,
    /// Weight 1/σ² of the sample (its file's torque noise floor).
    pub w: Vec<f64>,
    pub unit: Vec<usize>,
}

impl Design {
    /// Collects the samples of `chans` (torque channels) with the recalibrated predictions.
    pub fn collect(p: &Params, items: &[DesignItem<'_>]) -> Design {
        let mut d = Design::default();
        for (m, s0, s1, tq, disk, off, sg) in items {
            let ex = extra(m, disk);
            for (i, s) in [(0usize, *s0), (1usize, *s1)] {
                if tq[i].len() != m.n {
                    continue;
                }
                for &k in s {
                    let t = tq[i][k];
                    if !t.is_finite() {
                        continue;
                    }
                    d.z.push(variables(p, m, disk, &ex, i, k, t));
                    d.t_model.push(t);
                    d.resid.push(m.torque[i][k] - t);
                    d.w.push(1.0 / (sg[i] * sg[i]).max(1e-12));
                    d.unit.push(off + m.seg.block_of(k));
                }
            }
        }
        d
    }

    pub fn len(&self) -> usize {
        self.resid.len()
    }

    pub fn is_empty(&self) -> bool {
        self.resid.is_empty()
    }
}

/// A fitted discrepancy.
#[derive(Debug, Clone, PartialEq)]
pub struct Discrepancy {
    pub keep: [bool; 6],
    pub beta: Vec<f64>,
}

impl Discrepancy {
    /// Ridge fit of the residual on the basis (variables not in `keep` dropped).
    pub fn fit(d: &Design, keep: [bool; 6], ridge: f64) -> Option<Discrepancy> {
        let mut f = Vec::new();
        features(&[0.0; 6], &keep, 1.0, &mut f);
        let q = f.len();
        if d.len() < 4 * q {
            return None;
        }
        let mut a = DMatrix::<f64>::zeros(q, q);
        let mut b = DVector::<f64>::zeros(q);
        for j in 0..d.len() {
            features(&d.z[j], &keep, d.t_model[j], &mut f);
            let w = d.w[j];
            for r in 0..q {
                b[r] += w * f[r] * d.resid[j];
                for c in r..q {
                    a[(r, c)] += w * f[r] * f[c];
                }
            }
        }
        for r in 0..q {
            for c in 0..r {
                a[(r, c)] = a[(c, r)];
            }
        }
        let tr = (0..q).map(|r| a[(r, r)]).sum::<f64>() / q as f64;
        for r in 0..q {
            a[(r, r)] += ridge * tr;
        }
        let beta = a.cholesky()?.solve(&b);
        Some(Discrepancy {
            keep,
            beta: beta.iter().copied().collect(),
        })
    }

    /// Predicted residual of sample j of a design.
    pub fn predict(&self, d: &Design, j: usize, buf: &mut Vec<f64>) -> f64 {
        features(&d.z[j], &self.keep, d.t_model[j], buf);
        buf.iter().zip(&self.beta).map(|(a, b)| a * b).sum()
    }

    /// Per-unit sums of squared standardized residuals after the correction (for the
    /// bootstrap).
    pub fn unit_sse(&self, d: &Design, units: usize) -> Vec<f64> {
        let mut out = vec![0.0; units];
        let mut buf = Vec::new();
        for j in 0..d.len() {
            let e = d.resid[j] - self.predict(d, j, &mut buf);
            out[d.unit[j].min(units - 1)] += d.w[j] * e * e;
        }
        out
    }
}

/// Result of the black-box check.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BlackBoxResult {
    /// Validation SSE of the torque channels (standardized by each file's noise floor) before
    /// (recalibrated) and after the correction.
    pub sse_before: f64,
    pub sse_after: f64,
    /// Variables whose removal costs more than 15 % of the explained validation SSE, by
    /// importance, with that share.
    pub depends_on: Vec<(String, f64)>,
    /// Share of the explained SSE lost when each variable is dropped.
    pub importance: Vec<(String, f64)>,
    /// Per validation unit SSE after the correction.
    #[serde(skip)]
    pub unit_sse_after: Vec<f64>,
}

/// Fits the discrepancy on `train` and evaluates it on `val`.
pub fn check(
    train: &Design,
    val: &Design,
    units: usize,
    channels: &[Channel],
) -> Option<BlackBoxResult> {
    let _ = channels;
    let ridge = 1e-4;
    let full = Discrepancy::fit(train, [true; 6], ridge)?;
    let before: f64 = val.resid.iter().zip(&val.w).map(|(r, w)| w * r * r).sum();
    let unit_after = full.unit_sse(val, units.max(1));
    let after: f64 = unit_after.iter().sum();
    let gain = before - after;
    let mut importance = Vec::new();
    for (a, name) in VARIABLES.iter().enumerate() {
        let mut keep = [true; 6];
        keep[a] = false;
        let share = match Discrepancy::fit(train, keep, ridge) {
            Some(dd) => {
                let s: f64 = dd.unit_sse(val, units.max(1)).iter().sum();
                if gain > 0.0 {
                    ((s - after) / gain).max(0.0)
                } else {
                    0.0
                }
            }
            None => 0.0,
        };
        importance.push((name.to_string(), share));
    }
    let mut depends_on: Vec<(String, f64)> = importance
        .iter()
        .filter(|(_, s)| *s > 0.15)
        .cloned()
        .collect();
    depends_on.sort_by(|a, b| b.1.total_cmp(&a.1));
    Some(BlackBoxResult {
        sse_before: before,
        sse_after: after,
        depends_on,
        importance,
        unit_sse_after: unit_after,
    })
}

//! Least squares for the identification: a bounded Levenberg–Marquardt solver for nonlinear
//! problems (the paper tuned λ1, λ2 and the non-convective thermal terms with a genetic
//! algorithm; a gradient method with bounds finds the same minimum far faster on these smooth
//! problems) and linear least squares by SVD (the convective thermal terms of Sect. 4.2), both
//! with parameter covariances and 95 % confidence intervals.
//!
//! Covariance: σ̂²·(JᵀJ)⁻¹ with σ̂² = SSE/(n − k), inflated by n/n_eff where n_eff is the
//! effective number of independent residuals (from the lag-1 autocorrelation ρ of the residuals,
//! n_eff = n(1 − ρ)/(1 + ρ)), so that slowly varying model errors do not give falsely narrow
//! intervals. Directions of JᵀJ below a relative singular value of 1e-10 are reported as not
//! identifiable (infinite interval).

use nalgebra::{DMatrix, DVector};

/// z of the two-sided 95 % normal interval.
pub const Z95: f64 = 1.959_963_985;

/// One free parameter.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ParamSpec {
    pub name: String,
    /// Starting value.
    pub init: f64,
    pub lo: f64,
    pub hi: f64,
    /// Typical magnitude: the solver works on p/scale (or ln(p/scale) with `log`).
    pub scale: f64,
    /// Solve for ln(p) (positive parameters whose magnitude, not offset, matters).
    pub log: bool,
}

impl ParamSpec {
    pub fn new(name: impl Into<String>, init: f64, lo: f64, hi: f64, scale: f64) -> Self {
        ParamSpec {
            name: name.into(),
            init: init.clamp(lo, hi),
            lo,
            hi,
            scale: if scale > 0.0 && scale.is_finite() {
                scale
            } else {
                1.0
            },
            log: false,
        }
    }

    /// The same parameter solved for in log space (needs `lo > 0`; ignored otherwise).
    pub fn log(mut self) -> Self {
        self.log = self.lo > 0.0;
        self
    }

    fn to_z(&self, p: f64) -> f64 {
        if self.log {
            (p.max(self.lo) / self.scale).ln()
        } else {
            p / self.scale
        }
    }

    fn to_p(&self, z: f64) -> f64 {
        let p = if self.log {
            self.scale * z.exp()
        } else {
            self.scale * z
        };
        p.clamp(self.lo, self.hi)
    }

    /// dp/dz at p.
    fn dp_dz(&self, p: f64) -> f64 {
        if self.log {
            p
        } else {
            self.scale
        }
    }

    fn z_bounds(&self) -> (f64, f64) {
        (self.to_z(self.lo), self.to_z(self.hi))
    }
}

/// Solver options.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LmOptions {
    pub max_iter: usize,
    /// Stop when the relative SSE decrease of an accepted step is below this.
    pub tol_sse: f64,
    /// Stop when the scaled step is below this.
    pub tol_step: f64,
    /// Central (true) or forward differences for the Jacobian.
    pub central: bool,
}

impl Default for LmOptions {
    fn default() -> Self {
        LmOptions {
            max_iter: 100,
            tol_sse: 1e-10,
            tol_step: 1e-9,
            central: false,
        }
    }
}

/// Result of a fit.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Fit {
    pub names: Vec<String>,
    pub p: Vec<f64>,
    pub sse: f64,
    /// Number of residuals.
    pub n: usize,
    /// Effective number of independent residuals (autocorrelation-corrected).
    pub n_eff: f64,
    /// Standard errors (∞ when not identifiable).
    pub std_err: Vec<f64>,
    /// 95 % intervals.
    pub ci95: Vec<(f64, f64)>,
    /// Parameter at (or within 1e-9 of) a bound.
    pub at_bound: Vec<bool>,
    pub iterations: usize,
    pub converged: bool,
    /// Parameter correlation matrix (row-major, k×k), NaN where not identifiable.
    pub correlation: Vec<f64>,
}

impl Fit {
    /// Residual RMS.
    pub fn rms(&self) -> f64 {
        (self.sse / self.n.max(1) as f64).sqrt()
    }

    /// Value of a named parameter.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.names.iter().position(|n| n == name).map(|i| self.p[i])
    }

    /// Largest absolute correlation between two different parameters.
    pub fn max_abs_correlation(&self) -> f64 {
        let k = self.p.len();
        let mut m: f64 = 0.0;
        for i in 0..k {
            for j in 0..k {
                if i != j {
                    let c = self.correlation[i * k + j];
                    if c.is_finite() {
                        m = m.max(c.abs());
                    }
                }
            }
        }
        m
    }
}

/// Lag-1 autocorrelation of a residual vector (0 for fewer than 3 values).
pub fn lag1_autocorrelation(r: &[f64]) -> f64 {
    if r.len() < 3 {
        return 0.0;
    }
    let m = r.iter().sum::<f64>() / r.len() as f64;
    let mut num = 0.0;
    let mut den = 0.0;
    for k in 0..r.len() {
        let a = r[k] - m;
        den += a * a;
        if k + 1 < r.len() {
            num += a * (r[k + 1] - m);
        }
    }
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

/// Effective sample size n(1 − ρ)/(1 + ρ) with ρ the lag-1 autocorrelation clamped to [0, 0.999].
pub fn effective_n(r: &[f64]) -> f64 {
    let rho = lag1_autocorrelation(r).clamp(0.0, 0.999);
    (r.len() as f64 * (1.0 - rho) / (1.0 + rho)).max(1.0)
}

fn sse_of(r: &[f64]) -> f64 {
    let s: f64 = r.iter().map(|v| v * v).sum();
    if s.is_finite() {
        s
    } else {
        f64::INFINITY
    }
}

/// The residuals of a problem. [`Residuals::eval_many`] evaluates the points of a
/// finite-difference Jacobian together, so that a problem can spread them over threads; the
/// solver's results do not depend on how (each point's residuals are a function of the point).
pub trait Residuals {
    /// Fills `r` with the residuals at `p`.
    fn eval(&mut self, p: &[f64], r: &mut [f64]);

    /// [`Residuals::eval`] at every point of `ps` into the matching `rs`; by default one after
    /// another.
    fn eval_many(&mut self, ps: &[Vec<f64>], rs: &mut [Vec<f64>]) {
        for (p, r) in ps.iter().zip(rs.iter_mut()) {
            self.eval(p, r);
        }
    }
}

/// A closure `f(p, r)` as [`Residuals`], evaluated one point at a time.
struct Sequential<'a>(&'a mut dyn FnMut(&[f64], &mut [f64]));

impl Residuals for Sequential<'_> {
    fn eval(&mut self, p: &[f64], r: &mut [f64]) {
        (self.0)(p, r)
    }
}

/// Minimises Σ r(p)² over the box of `specs` by projected Levenberg–Marquardt (Nielsen's damping
/// update) with a finite-difference Jacobian. `f(p, r)` fills the `n` residuals; non-finite
/// residuals count as a failed step. Returns the fit with covariance-based intervals.
pub fn levenberg_marquardt(
    f: &mut dyn FnMut(&[f64], &mut [f64]),
    n: usize,
    specs: &[ParamSpec],
    opts: LmOptions,
) -> Fit {
    levenberg_marquardt_clustered(f, n, specs, opts, None)
}

/// [`levenberg_marquardt`] with residual clusters (one id per residual, e.g. the engagement
/// block it belongs to) for cluster-robust intervals.
pub fn levenberg_marquardt_clustered(
    f: &mut dyn FnMut(&[f64], &mut [f64]),
    n: usize,
    specs: &[ParamSpec],
    opts: LmOptions,
    clusters: Option<&[usize]>,
) -> Fit {
    solve(&mut Sequential(f), n, specs, opts, clusters)
}

/// [`levenberg_marquardt_clustered`] of a problem given as [`Residuals`].
pub fn solve(
    f: &mut dyn Residuals,
    n: usize,
    specs: &[ParamSpec],
    opts: LmOptions,
    clusters: Option<&[usize]>,
) -> Fit {
    let k = specs.len();
    let to_p = |z: &[f64]| -> Vec<f64> { z.iter().zip(specs).map(|(z, s)| s.to_p(*z)).collect() };
    let zb: Vec<(f64, f64)> = specs.iter().map(|s| s.z_bounds()).collect();
    let mut z: Vec<f64> = specs.iter().map(|s| s.to_z(s.init)).collect();
    let mut r = vec![0.0; n];
    f.eval(&to_p(&z), &mut r);
    let mut sse = sse_of(&r);
    let mut jac = DMatrix::<f64>::zeros(n, k);
    let mut rn = vec![0.0; n];
    let mut iterations = 0;
    let mut converged = false;
    let jacobian = |f: &mut dyn Residuals, z: &[f64], r: &[f64], jac: &mut DMatrix<f64>| {
        difference_jacobian(f, specs, &zb, opts.central, z, r, jac)
    };
    if k > 0 && sse.is_finite() {
        jacobian(f, &z, &r, &mut jac);
        // Whether `jac` is the Jacobian at `z` (only a converged accepted step leaves it behind).
        let mut fresh = true;
        let mut mu: f64 = -1.0;
        let mut nu = 2.0;
        let mut small = 0;
        while iterations < opts.max_iter {
            iterations += 1;
            let a = gram(&jac);
            let g = jac.tr_mul(&DVector::from_column_slice(&r));
            if mu < 0.0 {
                mu = 1e-3;
            }
            let Some(znew) = damped_step(&a, &g, mu, &z, &zb) else {
                mu *= nu;
                nu *= 2.0;
                continue;
            };
            let dz: Vec<f64> = (0..k).map(|j| znew[j] - z[j]).collect();
            let moved = dz
                .iter()
                .zip(&z)
                .map(|(d, z)| d.abs() / z.abs().max(1.0))
                .fold(0.0, f64::max);
            f.eval(&to_p(&znew), &mut rn);
            let sn = sse_of(&rn);
            // Predicted decrease of ½SSE for the (projected) step: −gᵀδ − ½δᵀAδ.
            let dzv = DVector::from_column_slice(&dz);
            let pred = -(g.dot(&dzv)) - 0.5 * dzv.dot(&(&a * &dzv));
            let actual = 0.5 * (sse - sn);
            if sn < sse {
                let rho = if pred > 0.0 { actual / pred } else { 1.0 };
                let rel = (sse - sn) / sse.max(1e-300);
                z = znew;
                std::mem::swap(&mut r, &mut rn);
                sse = sn;
                mu *= (1.0f64 / 3.0).max(1.0 - (2.0 * rho - 1.0).powi(3));
                nu = 2.0;
                if rel < opts.tol_sse || moved < opts.tol_step {
                    small += 1;
                    if small >= 3 {
                        converged = true;
                        fresh = false;
                        break;
                    }
                } else {
                    small = 0;
                }
                jacobian(f, &z, &r, &mut jac);
            } else {
                if moved < opts.tol_step {
                    converged = true;
                    break;
                }
                mu *= nu;
                nu *= 2.0;
                if !mu.is_finite() || mu > 1e300 {
                    converged = true;
                    break;
                }
            }
        }
        // Jacobian at the solution for the covariance (the same evaluations again when the last
        // one is at the solution: `f` is deterministic).
        if !fresh {
            jacobian(f, &z, &r, &mut jac);
        }
    }
    summary(
        specs,
        to_p(&z),
        &r,
        sse,
        &jac,
        clusters,
        iterations,
        converged,
    )
}

/// The Levenberg–Marquardt point from `z`: the step solving (JᵀJ + μ·D)δ = −Jᵀr with JᵀJ = `a`,
/// Jᵀr = `g` and Marquardt's scaling D, the diagonal of JᵀJ (floored so that a parameter the data
/// do not see still gets a finite step), clamped to the bounds `zb`; `None` when the damped
/// matrix is not positive definite.
fn damped_step(
    a: &DMatrix<f64>,
    g: &DVector<f64>,
    mu: f64,
    z: &[f64],
    zb: &[(f64, f64)],
) -> Option<Vec<f64>> {
    let k = z.len();
    let dmax = (0..k).map(|j| a[(j, j)]).fold(0.0, f64::max).max(1e-300);
    let mut m = a.clone();
    for j in 0..k {
        m[(j, j)] += mu * a[(j, j)].max(1e-12 * dmax);
    }
    let step = m.cholesky().map(|c| c.solve(&(-g)))?;
    Some(
        (0..k)
            .map(|j| (z[j] + step[j]).clamp(zb[j].0, zb[j].1))
            .collect(),
    )
}

/// The Jacobian of the residuals at `z` (residuals `r` there) by differences in the solver's
/// coordinates, forward (backward at an upper bound) or central where `central` asks and the
/// bounds allow; every column's points are evaluated together ([`Residuals::eval_many`]).
fn difference_jacobian(
    f: &mut dyn Residuals,
    specs: &[ParamSpec],
    zb: &[(f64, f64)],
    central: bool,
    z: &[f64],
    r: &[f64],
    jac: &mut DMatrix<f64>,
) {
    let (n, k) = (r.len(), z.len());
    let to_p = |z: &[f64]| -> Vec<f64> { z.iter().zip(specs).map(|(z, s)| s.to_p(*z)).collect() };
    let mut points = Vec::with_capacity(2 * k);
    let mut cols = Vec::with_capacity(k);
    for j in 0..k {
        let h = 1e-6 * z[j].abs().max(1.0);
        let up_ok = z[j] + h <= zb[j].1;
        let hs = if up_ok { h } else { -h };
        let mut zp = z.to_vec();
        zp[j] += hs;
        points.push(to_p(&zp));
        let central = central && z[j] - hs >= zb[j].0 && z[j] - hs <= zb[j].1;
        if central {
            let mut zm = z.to_vec();
            zm[j] -= hs;
            points.push(to_p(&zm));
        }
        cols.push((hs, central));
    }
    let mut res = vec![vec![0.0; n]; points.len()];
    f.eval_many(&points, &mut res);
    let mut at = 0;
    for (j, (hs, central)) in cols.into_iter().enumerate() {
        let rp = &res[at];
        if central {
            let rm = &res[at + 1];
            for i in 0..n {
                jac[(i, j)] = (rp[i] - rm[i]) / (2.0 * hs);
            }
            at += 2;
        } else {
            for i in 0..n {
                jac[(i, j)] = (rp[i] - r[i]) / hs;
            }
            at += 1;
        }
    }
}

/// The fit at the solution `p` (residuals `r`, Jacobian `jac` there): standard errors from the
/// covariance inflated by the residuals' autocorrelation, 95 % intervals, the parameters at a
/// bound.
#[allow(clippy::too_many_arguments)]
fn summary(
    specs: &[ParamSpec],
    p: Vec<f64>,
    r: &[f64],
    sse: f64,
    jac: &DMatrix<f64>,
    clusters: Option<&[usize]>,
    iterations: usize,
    converged: bool,
) -> Fit {
    let (n, k) = (r.len(), specs.len());
    let n_eff = effective_n(r);
    let dof = (n as f64 - k as f64).max(1.0);
    let sigma2 = sse / dof * (n as f64 / n_eff).max(1.0);
    let (std_z, corr) = covariance(jac, sigma2, r, clusters);
    let std_err: Vec<f64> = std_z
        .iter()
        .zip(specs)
        .zip(&p)
        .map(|((s, sp), p)| s * sp.dp_dz(*p))
        .collect();
    let ci95 = p
        .iter()
        .zip(&std_err)
        .map(|(p, s)| (p - Z95 * s, p + Z95 * s))
        .collect();
    let at_bound = p
        .iter()
        .zip(specs)
        .map(|(p, s)| {
            let tol = 1e-9 * s.scale.max(p.abs());
            (p - s.lo).abs() <= tol || (s.hi - p).abs() <= tol
        })
        .collect();
    Fit {
        names: specs.iter().map(|s| s.name.clone()).collect(),
        p,
        sse,
        n,
        n_eff,
        std_err,
        ci95,
        at_bound,
        iterations,
        converged,
        correlation: corr,
    }
}

/// JᵀJ, each entry below the diagonal the mirror of the one above it: nalgebra's `tr_mul`
/// makes entry (i, j) as column i · column j, and a dot product sums the same products in the
/// same order either way round, so this is `tr_mul`'s matrix, bit for bit, for half the work.
fn gram(jac: &DMatrix<f64>) -> DMatrix<f64> {
    let k = jac.ncols();
    let mut a = DMatrix::<f64>::zeros(k, k);
    for i in 0..k {
        for j in i..k {
            let v = jac.column(i).dot(&jac.column(j));
            a[(i, j)] = v;
            a[(j, i)] = v;
        }
    }
    a
}

/// Pseudo-inverse of JᵀJ by SVD of the equilibrated matrix, and the parameters that load on a
/// direction with a singular value below 1e-10 of the largest (not identifiable).
fn pinv_normal(jac: &DMatrix<f64>) -> (DMatrix<f64>, Vec<bool>) {
    let k = jac.ncols();
    let a = jac.tr_mul(jac);
    let d: Vec<f64> = (0..k)
        .map(|j| {
            let v = a[(j, j)];
            if v > 0.0 {
                1.0 / v.sqrt()
            } else {
                1.0
            }
        })
        .collect();
    let mut b = a.clone();
    for i in 0..k {
        for j in 0..k {
            b[(i, j)] *= d[i] * d[j];
        }
    }
    let svd = b.svd(true, true);
    let smax = svd.singular_values.iter().cloned().fold(0.0, f64::max);
    let mut inv = DMatrix::<f64>::zeros(k, k);
    let mut bad = vec![false; k];
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return (inv, vec![true; k]);
    };
    for (m, &sv) in svd.singular_values.iter().enumerate() {
        if sv > 1e-10 * smax && sv > 0.0 {
            for i in 0..k {
                for j in 0..k {
                    inv[(i, j)] += vt[(m, i)] * u[(j, m)] / sv * d[i] * d[j];
                }
            }
        } else {
            for i in 0..k {
                if vt[(m, i)].abs() > 1e-3 {
                    bad[i] = true;
                }
            }
        }
    }
    for i in 0..k {
        if a[(i, i)] <= 0.0 {
            bad[i] = true;
        }
    }
    (inv, bad)
}

/// Standard errors and correlations: σ²(JᵀJ)⁺, and when residual clusters are given (events:
/// residuals inside one engagement are correlated) also the cluster-robust sandwich
/// (JᵀJ)⁺ [Σ_g (J_gᵀr_g)(J_gᵀr_g)ᵀ · G/(G−1)] (JᵀJ)⁺; each variance is the larger of the two.
fn covariance(
    jac: &DMatrix<f64>,
    sigma2: f64,
    r: &[f64],
    clusters: Option<&[usize]>,
) -> (Vec<f64>, Vec<f64>) {
    let k = jac.ncols();
    if k == 0 {
        return (vec![], vec![]);
    }
    let (inv, bad) = pinv_normal(jac);
    let mut cov = &inv * sigma2;
    if let Some(cl) = clusters.filter(|c| c.len() == jac.nrows()) {
        let g_max = cl.iter().copied().max().unwrap_or(0) + 1;
        let mut scores = DMatrix::<f64>::zeros(g_max, k);
        for (i, &g) in cl.iter().enumerate() {
            for j in 0..k {
                scores[(g, j)] += jac[(i, j)] * r[i];
            }
        }
        let used: Vec<usize> = (0..g_max)
            .filter(|&g| (0..k).any(|j| scores[(g, j)] != 0.0))
            .collect();
        let gn = used.len();
        if gn >= 5 {
            let mut meat = DMatrix::<f64>::zeros(k, k);
            for &g in &used {
                for a in 0..k {
                    for b in 0..k {
                        meat[(a, b)] += scores[(g, a)] * scores[(g, b)];
                    }
                }
            }
            meat *= gn as f64 / (gn as f64 - 1.0);
            let sand = &inv * meat * &inv;
            // Elementwise: keep the larger variance; rescale the covariances accordingly.
            let mut out = cov.clone();
            let scale: Vec<f64> = (0..k)
                .map(|i| {
                    if cov[(i, i)] > 0.0 && sand[(i, i)] > cov[(i, i)] {
                        (sand[(i, i)] / cov[(i, i)]).sqrt()
                    } else {
                        1.0
                    }
                })
                .collect();
            for i in 0..k {
                for j in 0..k {
                    out[(i, j)] = cov[(i, j)] * scale[i] * scale[j];
                }
            }
            // Correlations from the sandwich when it dominates everywhere.
            if (0..k).all(|i| sand[(i, i)] >= cov[(i, i)]) {
                out = sand;
            }
            cov = out;
        }
    }
    let mut std = vec![0.0; k];
    for i in 0..k {
        std[i] = if bad[i] || cov[(i, i)] <= 0.0 {
            f64::INFINITY
        } else {
            cov[(i, i)].sqrt()
        };
    }
    let mut corr = vec![f64::NAN; k * k];
    for i in 0..k {
        for j in 0..k {
            if !bad[i] && !bad[j] && cov[(i, i)] > 0.0 && cov[(j, j)] > 0.0 {
                corr[i * k + j] = cov[(i, j)] / (cov[(i, i)] * cov[(j, j)]).sqrt();
            }
        }
    }
    (std, corr)
}

/// Result of a linear least-squares fit y ≈ Xβ.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LinearFit {
    pub beta: Vec<f64>,
    pub std_err: Vec<f64>,
    pub ci95: Vec<(f64, f64)>,
    pub sse: f64,
    pub n: usize,
    pub n_eff: f64,
}

/// Linear least squares by SVD with covariance-based 95 % intervals (autocorrelation-corrected).
/// `x` is row-major with `k` columns. Returns `None` for an empty or non-finite problem.
pub fn linear_lsq(x: &[f64], y: &[f64], k: usize) -> Option<LinearFit> {
    let n = y.len();
    if k == 0 || n < k || x.len() != n * k || x.iter().chain(y).any(|v| !v.is_finite()) {
        return None;
    }
    let xm = DMatrix::from_row_slice(n, k, x);
    let yv = DVector::from_column_slice(y);
    let svd = xm.clone().svd(true, true);
    let beta = svd.solve(&yv, 1e-12).ok()?;
    let r = &yv - &xm * &beta;
    let rv: Vec<f64> = r.iter().copied().collect();
    let sse = rv.iter().map(|v| v * v).sum::<f64>();
    let n_eff = effective_n(&rv);
    let sigma2 = sse / (n as f64 - k as f64).max(1.0) * (n as f64 / n_eff).max(1.0);
    let (std, _) = covariance(&xm, sigma2, &rv, None);
    let b: Vec<f64> = beta.iter().copied().collect();
    let ci95 = b
        .iter()
        .zip(&std)
        .map(|(b, s)| (b - Z95 * s, b + Z95 * s))
        .collect();
    Some(LinearFit {
        beta: b,
        std_err: std,
        ci95,
        sse,
        n,
        n_eff,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::fit::stats::Rng;

    /// [`gram`] is nalgebra's JᵀJ bit for bit, on a matrix whose columns differ in scale and
    /// sign (rounding differs between the entries).
    #[test]
    fn the_mirrored_gram_matrix_is_tr_mul() {
        let (n, k) = (1001, 6);
        let jac = DMatrix::<f64>::from_fn(n, k, |r, c| {
            ((r * 7 + c * 13) as f64 * 0.37).sin() * 10f64.powi(c as i32 - 3)
        });
        let want = jac.tr_mul(&jac);
        let got = gram(&jac);
        for i in 0..k {
            for j in 0..k {
                assert_eq!(got[(i, j)].to_bits(), want[(i, j)].to_bits(), "({i}, {j})");
            }
        }
    }

    #[test]
    fn lm_recovers_exponential_within_interval() {
        // y = a·exp(−b t) + c with Gaussian noise.
        let (a, b, c) = (3.0, 0.7, 0.5);
        let mut rng = Rng::new(7);
        let t: Vec<f64> = (0..400).map(|i| i as f64 * 0.02).collect();
        let y: Vec<f64> = t
            .iter()
            .map(|t| a * (-b * t).exp() + c + 0.02 * rng.normal())
            .collect();
        let specs = [
            ParamSpec::new("a", 1.0, 0.0, 10.0, 1.0),
            ParamSpec::new("b", 0.2, 0.0, 5.0, 1.0),
            ParamSpec::new("c", 0.0, -5.0, 5.0, 1.0),
        ];
        let mut f = |p: &[f64], r: &mut [f64]| {
            for i in 0..t.len() {
                r[i] = y[i] - (p[0] * (-p[1] * t[i]).exp() + p[2]);
            }
        };
        let fit = levenberg_marquardt(&mut f, t.len(), &specs, LmOptions::default());
        assert!(fit.converged);
        for (truth, (lo, hi)) in [a, b, c].iter().zip(&fit.ci95) {
            assert!(lo <= truth && truth <= hi, "{truth} not in [{lo}, {hi}]");
            assert!(hi - lo < 0.1 * truth.abs().max(0.5));
        }
        assert!((fit.rms() - 0.02).abs() < 0.003);
    }

    #[test]
    fn lm_respects_bounds_and_flags_unidentifiable() {
        // Only p0 + p1 matters: the pair is not identifiable; p0 is bounded above by 0.5.
        let mut f = |p: &[f64], r: &mut [f64]| {
            for (i, ri) in r.iter_mut().enumerate() {
                *ri = (p[0] + p[1]) - 2.0 + 1e-3 * (i as f64 - 1.5);
            }
        };
        let specs = [
            ParamSpec::new("p0", 0.0, -1.0, 0.5, 1.0),
            ParamSpec::new("p1", 0.0, -10.0, 10.0, 1.0),
        ];
        let fit = levenberg_marquardt(&mut f, 4, &specs, LmOptions::default());
        assert!(fit.p[0] <= 0.5);
        assert!((fit.p[0] + fit.p[1] - 2.0).abs() < 1e-6);
        assert!(fit.std_err.iter().all(|s| s.is_infinite()));
    }

    #[test]
    fn linear_lsq_matches_closed_form() {
        // y = 2 + 3x exactly, plus a symmetric perturbation that does not change the slope.
        let xs: Vec<f64> = (0..5).map(f64::from).collect();
        let y: Vec<f64> = xs.iter().map(|x| 2.0 + 3.0 * x).collect();
        let design: Vec<f64> = xs.iter().flat_map(|x| [1.0, *x]).collect();
        let fit = linear_lsq(&design, &y, 2).unwrap();
        assert!((fit.beta[0] - 2.0).abs() < 1e-12 && (fit.beta[1] - 3.0).abs() < 1e-12);
        assert!(fit.sse < 1e-20);
        assert!(linear_lsq(&design, &y[..4], 2).is_none());
    }

    #[test]
    fn autocorrelation_of_white_and_smooth_signals() {
        let mut rng = Rng::new(3);
        let w: Vec<f64> = (0..5000).map(|_| rng.normal()).collect();
        assert!(lag1_autocorrelation(&w).abs() < 0.05);
        let s: Vec<f64> = (0..5000).map(|i| (i as f64 * 0.01).sin()).collect();
        assert!(lag1_autocorrelation(&s) > 0.99);
        assert!(effective_n(&s) < 50.0);
    }
}

//! Dry-clutch torque characteristic of the paper, Sect. 3, and its inverse.
//!
//! - Friction (4) with the temperature-dependent dynamic coefficient (5):
//!   μ(ρω, θ) = μ_s + (μ_d(θ) − μ_s)·tanh(γρ|ω|)^{1/3}, μ_d(θ) = c1·sin(c2θ + c3) + c4.
//! - Equivalent friction radius (6): R_μ(ω, θ) = 1/(R2−R1)·∫_{R1}^{R2} μ(ρω, θ)ρ dρ, computed as
//!   μ_s(R1+R2)/2 + (μ_d(θ) − μ_s)·Q(|ω|), Q in closed form over one tabulated universal
//!   integral ([`super::slip_integral`]; relative error below 1e-9, checked in the tests against
//!   the 8-node Gauss–Legendre rule, itself within 1e-12 of a 512-node composite rule).
//! - Flat-spring compression (7)–(9) in mm, spring load (10) with u in m.
//! - Single-clutch torque (13) T = 2·R_μ(ω, θ_c)·F(u_fs(x_to, θ_c)) and the two-facing form (11).
//! - Signed slip: the torque has the sign of the slip ω_fc = ω_f − ω_c (it acts on the clutch disk
//!   in the direction of the slip and on the flywheel against it), so it is odd in the slip; at
//!   exactly zero slip (13) gives 0 and the static capacity [`capacity`] = 2·R_μ(0, θ)·F applies.
//! - Inverse [`invert`]: the bearing position giving a torque magnitude at a slip and temperature;
//!   monotone between x_ISP(θ) and x_to,max, solved as a monotone cubic with bounded safeguarded
//!   Newton iterations, no allocation.
//!
//! Units: positions in mm, slip in rad/s, temperatures in °C, forces in N, torques in N·m.
//! All functions are pure and take the parameters as their first argument.

use super::gauss_legendre::{GL_W, GL_X};
use super::params::ClutchParams;
use super::slip_integral;

/// Errors of the torque inverse.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum ClutchError {
    #[error("non-finite input to the torque inverse: {name} = {value}")]
    NonFinite { name: &'static str, value: f64 },
}

/// Result of [`invert`].
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Inversion {
    /// Throwout-bearing position (mm).
    pub x_to_mm: f64,
    /// True when the requested torque exceeds what x_to,max gives (x_to_mm = x_to,max then).
    pub saturated: bool,
}

/// Dynamic friction coefficient μ_d(θ) of (5).
#[inline]
pub(crate) fn mu_d(p: &ClutchParams, theta_c: f64) -> f64 {
    p.c1 * (p.c2_rad_per_c * theta_c + p.c3_rad).sin() + p.c4
}

/// Friction coefficient (4) at the sliding speed `v_mps` = ρ·ω (m/s) and facing temperature.
/// Even in the sliding speed (the direction is carried by the torque sign).
#[inline]
pub fn mu(p: &ClutchParams, v_mps: f64, theta_fp: f64) -> f64 {
    p.mu_s + (mu_d(p, theta_fp) - p.mu_s) * (p.gamma_s_per_m * v_mps.abs()).tanh().cbrt()
}

/// Q(ω) = 1/(R2−R1)·∫ tanh(γρ|ω|)^{1/3} ρ dρ (m), the slip-dependent part of (6): the exact
/// closed form over the tabulated universal integral of [`slip_integral`], or for a very narrow
/// facing the 8-node rule.
#[inline]
pub fn slip_shape(p: &ClutchParams, slip_radps: f64) -> f64 {
    let w = slip_radps.abs();
    if w == 0.0 {
        return 0.0;
    }
    match slip_integral::q(p.r1_m, p.r2_m, p.gamma_s_per_m * w) {
        Some(q) => q,
        None => slip_shape_quadrature(p, w),
    }
}

/// Q(ω) by 8-node Gauss–Legendre over the facing (ω ≥ 0).
#[inline]
fn slip_shape_quadrature(p: &ClutchParams, w: f64) -> f64 {
    if w == 0.0 {
        return 0.0;
    }
    let half = 0.5 * (p.r2_m - p.r1_m);
    let mid = 0.5 * (p.r2_m + p.r1_m);
    let gw = p.gamma_s_per_m * w;
    let mut s = 0.0;
    for i in 0..4 {
        let ra = mid + half * GL_X[i];
        let rb = mid - half * GL_X[i];
        s += GL_W[i] * ((gw * ra).tanh().cbrt() * ra + (gw * rb).tanh().cbrt() * rb);
    }
    // ∫ = half·Σ wᵢ f(ρᵢ); divided by (R2 − R1) = 2·half.
    0.5 * s
}

/// Equivalent friction radius (6) R_μ(ω, θ) (m). Even in the slip.
#[inline]
pub fn r_mu(p: &ClutchParams, slip_radps: f64, theta_fp: f64) -> f64 {
    r_mu_shaped(p, slip_shape(p, slip_radps), theta_fp)
}

/// [`r_mu`] with the slip's [`slip_shape`] Q(ω) given: the two facings of a clutch slip alike, so
/// Q is taken once for both.
#[inline]
pub(crate) fn r_mu_shaped(p: &ClutchParams, q: f64, theta_fp: f64) -> f64 {
    p.mu_s * 0.5 * (p.r1_m + p.r2_m) + (mu_d(p, theta_fp) - p.mu_s) * q
}

/// R_μ by composite Gauss–Legendre with `panels` panels of 8 nodes: an independent,
/// high-accuracy reference for (6) used by tests and figures.
pub fn r_mu_reference(p: &ClutchParams, slip_radps: f64, theta_fp: f64, panels: usize) -> f64 {
    let panels = panels.max(1);
    let h = (p.r2_m - p.r1_m) / panels as f64;
    let mut s = 0.0;
    for k in 0..panels {
        let a = p.r1_m + k as f64 * h;
        let mid = a + 0.5 * h;
        for i in 0..4 {
            for sign in [1.0, -1.0] {
                let rho = mid + sign * 0.5 * h * GL_X[i];
                s += GL_W[i] * 0.5 * h * mu(p, rho * slip_radps, theta_fp) * rho;
            }
        }
    }
    s / (p.r2_m - p.r1_m)
}

/// Kiss point (incipient sliding point) x_to,ISP(θ) of (9) (mm).
#[inline]
pub fn x_isp(p: &ClutchParams, theta_fs: f64) -> f64 {
    let d = theta_fs - p.theta_a_c;
    p.x_isp2_mm_per_c2 * d * d + p.x_isp1_mm_per_c * d + p.x_isp0_mm
}

/// Every parameter [`u_fs`] reads ((7)–(9): λ, the kiss point's λ0, λ1, λ2 and θ_a, x_to,max):
/// whether the clutch is engaged (β of (16)) depends on the clutch parameters only through these.
pub(crate) fn engagement_params(p: &ClutchParams) -> [f64; 6] {
    [
        p.lambda,
        p.x_isp0_mm,
        p.x_isp1_mm_per_c,
        p.x_isp2_mm_per_c2,
        p.theta_a_c,
        p.x_to_max_mm,
    ]
}

/// Maximum flat-spring compression u_fs,max(θ) of (8) (mm).
#[inline]
pub(crate) fn u_fs_max(p: &ClutchParams, theta_fs: f64) -> f64 {
    p.lambda * (p.x_to_max_mm - x_isp(p, theta_fs))
}

/// Flat-spring compression u_fs(x_to, θ) of (7) (mm), saturated to [0, u_fs,max(θ)].
#[inline]
pub(crate) fn u_fs(p: &ClutchParams, x_to_mm: f64, theta_fs: f64) -> f64 {
    let u = p.lambda * (x_to_mm - x_isp(p, theta_fs));
    u.max(0.0).min(u_fs_max(p, theta_fs).max(0.0))
}

/// Flat-spring load (10) F(u) (N) for a compression in mm (the p's take u in m).
#[inline]
pub(crate) fn spring_force(p: &ClutchParams, u_fs_mm: f64) -> f64 {
    let u = u_fs_mm * 1e-3;
    ((p.p3_n_per_m3 * u + p.p2_n_per_m2) * u + p.p1_n_per_m) * u
}

/// Clamp force F(u_fs(x_to, θ)) of (7)–(10) (N).
#[inline]
pub fn normal_force(p: &ClutchParams, x_to_mm: f64, theta_fs: f64) -> f64 {
    spring_force(p, u_fs(p, x_to_mm, theta_fs))
}

/// Single-clutch torque (13) (N·m), with the sign of the slip ω_fc = ω_f − ω_c.
#[inline]
pub fn torque(p: &ClutchParams, x_to_mm: f64, slip_radps: f64, theta_c: f64) -> f64 {
    torque_shaped(p, x_to_mm, slip_radps, theta_c, None)
}

/// [`torque`] with the slip's Q(ω) ([`slip_shape`]) given when `q` is.
#[inline]
pub(crate) fn torque_shaped(
    p: &ClutchParams,
    x_to_mm: f64,
    slip_radps: f64,
    theta_c: f64,
    q: Option<f64>,
) -> f64 {
    let f = normal_force(p, x_to_mm, theta_c);
    if f == 0.0 || slip_radps == 0.0 {
        return 0.0;
    }
    let q = q.unwrap_or_else(|| slip_shape(p, slip_radps));
    slip_radps.signum() * 2.0 * r_mu_shaped(p, q, theta_c) * f
}

/// Two-facing torque (11) (N·m): facing temperatures θ_fp1, θ_fp2 and flat-spring temperature
/// θ_fs. Equals (13) when θ_fp1 = θ_fp2 = θ_fs = θ_c.
#[inline]
pub fn torque_two_facing(
    p: &ClutchParams,
    x_to_mm: f64,
    slip_radps: f64,
    theta_fp1: f64,
    theta_fp2: f64,
    theta_fs: f64,
) -> f64 {
    let f = normal_force(p, x_to_mm, theta_fs);
    if f == 0.0 || slip_radps == 0.0 {
        return 0.0;
    }
    slip_radps.signum() * (r_mu(p, slip_radps, theta_fp1) + r_mu(p, slip_radps, theta_fp2)) * f
}

/// Static capacity 2·R_μ(0, θ)·F (N·m): the largest torque a locked clutch transmits.
#[inline]
pub fn capacity(p: &ClutchParams, x_to_mm: f64, theta_c: f64) -> f64 {
    2.0 * r_mu(p, 0.0, theta_c) * normal_force(p, x_to_mm, theta_c)
}

/// Largest torque magnitude (13) gives at this slip and temperature (at x_to,max).
#[inline]
pub fn max_torque(p: &ClutchParams, slip_radps: f64, theta_c: f64) -> f64 {
    2.0 * r_mu(p, slip_radps, theta_c) * spring_force(p, u_fs_max(p, theta_c))
}

/// Compression u (mm) with F(u) = `force_n`, for 0 ≤ F ≤ F(u_hi_mm). Safeguarded Newton on the
/// cubic (10) (strictly increasing, checked by `ClutchParams::validate`), at most 60 iterations.
fn spring_inverse(p: &ClutchParams, force_n: f64, u_hi_mm: f64) -> f64 {
    let (p1, p2, p3) = (p.p1_n_per_m, p.p2_n_per_m2, p.p3_n_per_m3);
    let g = |u: f64| ((p3 * u + p2) * u + p1) * u - force_n;
    let dg = |u: f64| (3.0 * p3 * u + 2.0 * p2) * u + p1;
    let (mut lo, mut hi) = (0.0, u_hi_mm * 1e-3);
    // Start from the linear solution, kept inside the bracket.
    let mut u = if p1 > 0.0 { force_n / p1 } else { 0.5 * hi };
    if !(u > lo && u < hi) {
        u = 0.5 * (lo + hi);
    }
    for _ in 0..60 {
        let gu = g(u);
        if gu == 0.0 {
            return u * 1e3;
        }
        if gu > 0.0 {
            hi = u;
        } else {
            lo = u;
        }
        let d = dg(u);
        let mut next = if d > 0.0 { u - gu / d } else { f64::NAN };
        if !(next > lo && next < hi) {
            next = 0.5 * (lo + hi);
        }
        if (next - u).abs() <= 1e-15 * hi.max(1e-12) {
            return next * 1e3;
        }
        u = next;
    }
    u * 1e3
}

/// Inverse of (13): the bearing position x_to (mm) whose torque magnitude at `slip_radps` and
/// `theta_c` equals |`torque_nm`|. Zero torque gives the kiss point x_ISP(θ); a torque beyond
/// [`max_torque`] gives x_to,max with `saturated = true`. At zero slip the static radius R_μ(0, θ)
/// is used (the position that makes the static capacity equal the request).
pub fn invert(
    p: &ClutchParams,
    torque_nm: f64,
    slip_radps: f64,
    theta_c: f64,
) -> Result<Inversion, ClutchError> {
    for (name, value) in [
        ("torque_nm", torque_nm),
        ("slip_radps", slip_radps),
        ("theta_c", theta_c),
    ] {
        if !value.is_finite() {
            return Err(ClutchError::NonFinite { name, value });
        }
    }
    let t = torque_nm.abs();
    let x0 = x_isp(p, theta_c);
    if t == 0.0 {
        return Ok(Inversion {
            x_to_mm: x0,
            saturated: false,
        });
    }
    let force = t / (2.0 * r_mu(p, slip_radps, theta_c));
    let u_max = u_fs_max(p, theta_c);
    let f_max = spring_force(p, u_max);
    if force >= f_max {
        return Ok(Inversion {
            x_to_mm: p.x_to_max_mm,
            saturated: force > f_max,
        });
    }
    let u = spring_inverse(p, force, u_max);
    Ok(Inversion {
        x_to_mm: (x0 + u / p.lambda).min(p.x_to_max_mm),
        saturated: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::params::Params;

    fn cp() -> ClutchParams {
        Params::default().clutch
    }

    /// Each clutch parameter moved by 10 % (and 0.01 where zero): u_fs moves somewhere on a grid
    /// exactly when the parameter is one of [`engagement_params`].
    #[test]
    fn the_engagement_parameters_are_those_u_fs_reads() {
        let p = cp();
        let table = toml::Table::try_from(p).unwrap();
        for key in table.keys() {
            let mut t = table.clone();
            let v = t[key].as_float().unwrap();
            t[key] = toml::Value::Float(if v == 0.0 { 0.01 } else { v * 1.1 });
            let q: ClutchParams = t.try_into().unwrap();
            let mut moved = false;
            for x in 0..=100 {
                for th in [-20.0, 25.0, 140.0, 300.0] {
                    moved |= u_fs(&p, x as f64 * 0.1, th) != u_fs(&q, x as f64 * 0.1, th);
                }
            }
            let listed = engagement_params(&p) != engagement_params(&q);
            assert_eq!(moved, listed, "{key}: u_fs moved {moved}, listed {listed}");
        }
    }

    #[test]
    fn gauss_legendre_integrates_degree_15_exactly() {
        // ∫_{-1}^{1} x^k dx for even k = 2/(k+1).
        for k in (0..=14i32).step_by(2) {
            let s: f64 = (0..4).map(|i| 2.0 * GL_W[i] * GL_X[i].powi(k)).sum();
            assert!((s - 2.0 / (k as f64 + 1.0)).abs() < 1e-14, "k={k}");
        }
    }

    #[test]
    fn r_mu_matches_reference() {
        let p = cp();
        for &w in &[1e-6, 1e-3, 0.1, 1.0, 5.0, 20.0, 50.0, 200.0, 1e3, 1e4] {
            for &th in &[-20.0, 25.0, 140.0, 240.0, 350.0] {
                let a = r_mu(&p, w, th);
                let b = r_mu_reference(&p, w, th, 64);
                assert!(((a - b) / b).abs() < 1e-10, "w={w} th={th} {a} {b}");
            }
        }
    }

    /// Q by a 256-panel composite 8-node rule (independent of the table).
    fn slip_shape_reference(p: &ClutchParams, w: f64) -> f64 {
        let panels = 256;
        let h = (p.r2_m - p.r1_m) / panels as f64;
        let f = |rho: f64| (p.gamma_s_per_m * w * rho).tanh().cbrt() * rho;
        let mut s = 0.0;
        for k in 0..panels {
            let mid = p.r1_m + (k as f64 + 0.5) * h;
            for i in 0..4 {
                s += GL_W[i] * 0.5 * h * (f(mid + 0.5 * h * GL_X[i]) + f(mid - 0.5 * h * GL_X[i]));
            }
        }
        s / (p.r2_m - p.r1_m)
    }

    /// The closed form of Q agrees with a fine composite rule over slips from 1e-6 to 1e4 rad/s,
    /// for the nominal facing and wide/narrow facings and friction shapes across the parameter
    /// ranges; on the nominal facing the 8-node rule the model used before agrees as well.
    #[test]
    fn slip_shape_closed_form_matches_quadrature() {
        let nominal = cp();
        for i in 0..=400 {
            let w = 10f64.powf(-6.0 + 10.0 * i as f64 / 400.0);
            let (a, b) = (slip_shape(&nominal, w), slip_shape_quadrature(&nominal, w));
            assert!(((a - b) / b).abs() < 1e-9, "{w}: {a} vs 8-node {b}");
        }
        let mut worst: f64 = 0.0;
        for (r1, r2, gamma) in [
            (0.075, 0.115, 2.0),
            (0.01, 0.5, 0.001),
            (0.2, 0.25, 1000.0),
            (0.1, 0.105, 37.0),
        ] {
            let p = ClutchParams {
                r1_m: r1,
                r2_m: r2,
                gamma_s_per_m: gamma,
                ..cp()
            };
            for i in 0..=400 {
                let w = 10f64.powf(-6.0 + 10.0 * i as f64 / 400.0);
                let (a, b) = (slip_shape(&p, w), slip_shape_reference(&p, w));
                worst = worst.max(((a - b) / b).abs());
            }
        }
        assert!(worst < 1e-9, "worst relative error {worst:e}");
    }

    #[test]
    fn r_mu_at_zero_slip_is_static() {
        let p = cp();
        let r = r_mu(&p, 0.0, 100.0);
        assert!((r - 0.27 * 0.095).abs() < 1e-15);
    }

    #[test]
    fn spring_inverse_round_trip() {
        let p = cp();
        let umax = u_fs_max(&p, 25.0);
        for i in 0..=100 {
            let u = umax * i as f64 / 100.0;
            let f = spring_force(&p, u);
            let back = spring_inverse(&p, f, umax);
            assert!((back - u).abs() < 1e-9, "u={u} back={back}");
        }
    }

    /// A slip far below any physical one still gives the sign of the slip times the static
    /// capacity (the slip integral underflowed to 0/0 = NaN below about 1e-160 rad/s before), and
    /// one far above any physical one the fully sliding torque.
    #[test]
    fn torque_at_extreme_slips_is_finite() {
        let p = cp();
        let cap = capacity(&p, 5.5, 100.0);
        for w in [5e-324, 1e-300, 1e-170, 1e-100] {
            for sign in [1.0, -1.0] {
                let t = torque(&p, 5.5, sign * w, 100.0);
                assert!((t - sign * cap).abs() <= 1e-15 * cap, "{w:e}: {t} vs {cap}");
            }
        }
        let full = 2.0 * (mu_d(&p, 100.0) * 0.5 * (p.r1_m + p.r2_m)) * normal_force(&p, 5.5, 100.0);
        for w in [1e100, 1e300, f64::MAX] {
            let t = torque(&p, 5.5, -w, 100.0);
            assert!((t + full).abs() <= 1e-14 * full, "{w:e}: {t} vs {full}");
        }
    }

    #[test]
    fn invert_rejects_nan() {
        let p = cp();
        assert!(matches!(
            invert(&p, f64::NAN, 1.0, 20.0),
            Err(ClutchError::NonFinite {
                name: "torque_nm",
                ..
            })
        ));
    }
}

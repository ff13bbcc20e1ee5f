//! The nominal physics of the truth's rig, written from the paper's equations without the
//! project's model code (only parameter values are taken from `Params`):
//!
//! - friction (4) μ(ρω, θ) = μ_s + (μ_d(θ) − μ_s)·tanh(γρ|ω|)^{1/3}, μ_d(θ) = c1·sin(c2θ + c3) + c4 (5);
//! - equivalent radius (6) R_μ = 1/(R2 − R1)·∫ μ ρ dρ, here split exactly as
//!   μ_s·(R1 + R2)/2 + (μ_d − μ_s)·Q(ω) with Q(ω) = 1/(R2 − R1)·∫ tanh(γρ|ω|)^{1/3} ρ dρ by
//!   composite Simpson over the radius ([`SIMPSON_PANELS`] panels);
//! - kiss point (9), flat-spring compression (7)–(8) and load (10) (u in m);
//! - torque (13) T = sign(ω)·2·R_μ(ω, θ_c)·F(u_fs(x_to, θ_c)) and the two-facing form (11);
//! - the 5-state thermal model (16a)–(16e) in its physical form: heat capacities C, conductances G,
//!   convective conductances h and the shares φ of the friction power each mass receives, chosen so
//!   that C·θ̇ reproduces (16) term by term (α1 = G_pc/C_pp, α4 = G_pc/C_c, α5 = G_ccd/C_c =
//!   G_ccd/C_cd, α2 = h_pp/C_pp, α6 = h_c/C_c, α8 = h_cd/C_cd, α3 = φ_pp/C_pp, α7 = φ_c/C_c,
//!   α9 = φ_cd/C_cd) and the shares add up to one — the heat that leaves a clutch disk by
//!   conduction enters the central disk (the project's sign of (16e), see the
//!   documentation of its thermal model);
//! - the actuator: first-order lag with rate limit on the clamped request.

use crate::model::params::Params;

/// Simpson panels over the radius for Q(ω) (even).
pub const SIMPSON_PANELS: usize = 64;

/// Nominal parameters of the rig in the truth's own form.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Physics {
    pub r1: f64,
    pub r2: f64,
    pub mu_s: f64,
    pub gamma: f64,
    pub c1: f64,
    pub c2: f64,
    pub c3: f64,
    pub c4: f64,
    pub lambda: f64,
    pub l0: f64,
    pub l1: f64,
    pub l2: f64,
    pub theta_a: f64,
    pub x_max: f64,
    pub p1: f64,
    pub p2: f64,
    pub p3: f64,
    /// Heat capacities (J/K): pressure plate, clutch disk, central disk.
    pub c_pp: f64,
    pub c_c: f64,
    pub c_cd: f64,
    /// Conductances (W/K): plate–disk, disk–central disk (when the clutch is not open).
    pub g_pc: f64,
    pub g_ccd: f64,
    /// Convective conductances to the housing air (W/K) (plate and disk when open; central disk
    /// per open clutch).
    pub h_pp: f64,
    pub h_c: f64,
    pub h_cd: f64,
    /// Shares of a clutch's friction power entering its plate, its disk and the central disk.
    pub phi_pp: f64,
    pub phi_c: f64,
    pub phi_cd: f64,
    /// Actuator.
    pub tau: f64,
    pub rate: f64,
    pub x_lo: f64,
    pub x_hi: f64,
}

impl Physics {
    pub fn new(p: &Params) -> Physics {
        let c = &p.clutch;
        let t = &p.thermal5;
        // Capacities: C_c = C_cd from α5 appearing in (16c)–(16e) alike, C_pp/C_c = α4/α1 from the
        // plate–disk conduction, scale from the friction power shares adding up to one.
        let c_c = 1.0
            / (t.alpha3_k_per_j * t.alpha4_per_s / t.alpha1_per_s
                + t.alpha7_k_per_j
                + t.alpha9_k_per_j);
        let c_pp = c_c * t.alpha4_per_s / t.alpha1_per_s;
        let c_cd = c_c;
        Physics {
            r1: c.r1_m,
            r2: c.r2_m,
            mu_s: c.mu_s,
            gamma: c.gamma_s_per_m,
            c1: c.c1,
            c2: c.c2_rad_per_c,
            c3: c.c3_rad,
            c4: c.c4,
            lambda: c.lambda,
            l0: c.x_isp0_mm,
            l1: c.x_isp1_mm_per_c,
            l2: c.x_isp2_mm_per_c2,
            theta_a: c.theta_a_c,
            x_max: c.x_to_max_mm,
            p1: c.p1_n_per_m,
            p2: c.p2_n_per_m2,
            p3: c.p3_n_per_m3,
            c_pp,
            c_c,
            c_cd,
            g_pc: t.alpha1_per_s * c_pp,
            g_ccd: t.alpha5_per_s * c_c,
            h_pp: t.alpha2_per_s * c_pp,
            h_c: t.alpha6_per_s * c_c,
            h_cd: t.alpha8_per_s * c_cd,
            phi_pp: t.alpha3_k_per_j * c_pp,
            phi_c: t.alpha7_k_per_j * c_c,
            phi_cd: t.alpha9_k_per_j * c_cd,
            tau: p.actuator.tau_s,
            rate: p.actuator.rate_mm_per_s,
            x_lo: p.actuator.x_min_mm,
            x_hi: p.actuator.x_max_mm,
        }
    }

    /// μ_d(θ) of (5).
    #[inline]
    pub fn mu_dyn(&self, theta: f64) -> f64 {
        self.c1 * (self.c2 * theta + self.c3).sin() + self.c4
    }

    /// Q(ω) = 1/(R2 − R1)·∫_{R1}^{R2} tanh(γρ|ω|)^{1/3} ρ dρ (m), composite Simpson.
    pub fn q_slip(&self, w: f64) -> f64 {
        let w = w.abs();
        if w == 0.0 {
            return 0.0;
        }
        let n = SIMPSON_PANELS;
        let h = (self.r2 - self.r1) / n as f64;
        let f = |rho: f64| (self.gamma * rho * w).tanh().cbrt() * rho;
        let mut s = f(self.r1) + f(self.r2);
        for k in 1..n {
            let rho = self.r1 + k as f64 * h;
            s += if k % 2 == 1 { 4.0 } else { 2.0 } * f(rho);
        }
        s * h / 3.0 / (self.r2 - self.r1)
    }

    /// Mean radius 1/(R2 − R1)·∫ ρ dρ = (R1 + R2)/2 (m).
    #[inline]
    pub fn r_mean(&self) -> f64 {
        0.5 * (self.r1 + self.r2)
    }

    /// R_μ of (6) for one facing with static and dynamic coefficients, Q(ω) given (m).
    #[inline]
    pub fn r_mu_q(&self, q: f64, mu_s: f64, mu_dyn: f64) -> f64 {
        mu_s * self.r_mean() + (mu_dyn - mu_s) * q
    }

    /// Kiss point (9) (mm).
    #[inline]
    pub fn kiss(&self, theta: f64) -> f64 {
        let d = theta - self.theta_a;
        self.l2 * d * d + self.l1 * d + self.l0
    }

    /// Flat-spring compression (7)–(8) (mm) for a bearing position, kiss point and x_to,max.
    #[inline]
    pub fn compression(&self, x: f64, kiss: f64, x_max: f64) -> f64 {
        let u_max = (self.lambda * (x_max - kiss)).max(0.0);
        (self.lambda * (x - kiss)).clamp(0.0, u_max)
    }

    /// Flat-spring load (10) (N), u in mm.
    #[inline]
    pub fn spring(&self, u_mm: f64) -> f64 {
        let u = 1e-3 * u_mm;
        self.p1 * u + self.p2 * u * u + self.p3 * u * u * u
    }

    /// Nominal torque (13) (N·m): T = sign(ω)·2·R_μ(ω, θ_c)·F(u_fs(x, θ_c)).
    pub fn torque_nominal(&self, x: f64, w: f64, theta_c: f64) -> f64 {
        let f = self.spring(self.compression(x, self.kiss(theta_c), self.x_max));
        if f == 0.0 || w == 0.0 {
            return 0.0;
        }
        let r = self.r_mu_q(self.q_slip(w), self.mu_s, self.mu_dyn(theta_c));
        w.signum() * 2.0 * r * f
    }

    /// Actuator rate (mm/s) for position x and request r: lag τ (possibly changed), rate limit.
    #[inline]
    pub fn actuator_rate(&self, x: f64, r: f64, tau: f64) -> f64 {
        let r = r.clamp(self.x_lo, self.x_hi);
        ((r - x) / tau).clamp(-self.rate, self.rate)
    }

    /// Total heat capacity of the pack (J/K).
    pub fn pack_capacity(&self) -> f64 {
        2.0 * self.c_pp + 2.0 * self.c_c + self.c_cd
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thermal_form_reproduces_the_alphas() {
        let p = Params::default();
        let ph = Physics::new(&p);
        let t = &p.thermal5;
        let close = |a: f64, b: f64| ((a - b) / b).abs() < 1e-12;
        assert!(close(ph.g_pc / ph.c_pp, t.alpha1_per_s));
        assert!(close(ph.h_pp / ph.c_pp, t.alpha2_per_s));
        assert!(close(ph.phi_pp / ph.c_pp, t.alpha3_k_per_j));
        assert!(close(ph.g_pc / ph.c_c, t.alpha4_per_s));
        assert!(close(ph.g_ccd / ph.c_c, t.alpha5_per_s));
        assert!(close(ph.g_ccd / ph.c_cd, t.alpha5_per_s));
        assert!(close(ph.h_c / ph.c_c, t.alpha6_per_s));
        assert!(close(ph.phi_c / ph.c_c, t.alpha7_k_per_j));
        assert!(close(ph.h_cd / ph.c_cd, t.alpha8_per_s));
        assert!(close(ph.phi_cd / ph.c_cd, t.alpha9_k_per_j));
        assert!((ph.phi_pp + ph.phi_c + ph.phi_cd - 1.0).abs() < 1e-12);
    }

    #[test]
    fn simpson_q_converges() {
        let ph = Physics::new(&Params::default());
        for w in [0.5, 1.0, 5.0, 50.0, 230.0] {
            // Against a 20 000-panel midpoint rule.
            let n = 20_000;
            let h = (ph.r2 - ph.r1) / n as f64;
            let mut s = 0.0;
            for k in 0..n {
                let rho = ph.r1 + (k as f64 + 0.5) * h;
                s += (ph.gamma * rho * w).tanh().cbrt() * rho * h;
            }
            let q_ref = s / (ph.r2 - ph.r1);
            assert!(((ph.q_slip(w) - q_ref) / q_ref).abs() < 1e-7, "w={w}");
        }
    }

    /// (13) at a state worked out by hand: x_to = 6 mm, θ_c = θ_a = 25 °C (kiss point λ0 = 4 mm),
    /// slip 100 rad/s.
    #[test]
    fn torque_at_a_hand_computed_state() {
        let ph = Physics::new(&Params::default());
        // u = 0.25·(6 − 4) = 0.5 mm = 5e-4 m.
        let u: f64 = 5e-4;
        let f = 3.01e6 * u - 1.94e9 * u * u + 9.44e12 * u * u * u;
        assert!((f - 2200.0).abs() < 1e-9);
        // μ_d(25) = 0.07·sin(0.013·25 − 0.379) + 0.33.
        let mu_d = 0.07 * (0.013f64 * 25.0 - 0.379).sin() + 0.33;
        // At 100 rad/s γρω ≥ 15: tanh^{1/3} = 1 to 1e-12, so R_μ = μ_d·(R1+R2)/2.
        let r = mu_d * 0.095;
        let t = 2.0 * r * f;
        assert!((ph.torque_nominal(6.0, 100.0, 25.0) - t).abs() < 1e-8 * t);
        assert!((t - 2.0 * 0.095 * 2200.0 * mu_d).abs() < 1e-9);
        // Odd in the slip, zero below the kiss point.
        assert_eq!(
            ph.torque_nominal(6.0, -100.0, 25.0),
            -ph.torque_nominal(6.0, 100.0, 25.0)
        );
        assert_eq!(ph.torque_nominal(3.9, 100.0, 25.0), 0.0);
    }
}

//! Thermal models of the dry dual clutch, paper Sect. 4, as derivative functions.
//!
//! - [`Thermal5`]: the 5-state model (16a)–(16e) — pressure plates θ_pp1, θ_pp2, clutch disks
//!   θ_c1, θ_c2, central disk θ_cd; used by the plant (the "truth" family).
//! - [`Thermal3`]: the 3-state model (17a)–(17c) — θ_c1, θ_c2 and one body θ_b (pressure plates +
//!   central disk); used by the TCU estimator.
//!
//! Inputs: friction powers P_i = T_fci·ω_fci (W, ≥ 0 for a physical clutch), the housing air
//! temperature θ_h (°C) and the contact flags β_i = 1 when clutch i is not open (u_fs > 0),
//! see [`beta`].
//!
//! Sign convention: the conduction terms of (16e) and (17c) are the counterparts of those in
//! (16c)/(16d) and (17a)/(17b) — heat that leaves a clutch disk enters the central disk (body).
//! The paper prints them as −α5β1(θ_c1 − θ_cd); read literally that would cool the central disk
//! when the clutch is hotter (an unbounded drift of both), so they are implemented as
//! +α5β1(θ_c1 − θ_cd), which is what the paper's sentence "the first two terms ... correspond to
//! the conductive heat terms in (16c) and (16d)" describes.

use super::clutch;
use super::integrator::{rk4_step, OdeState, OdeSystem};
use super::params::{ClutchParams, ThermalParams3, ThermalParams5};
use serde::{Deserialize, Serialize};

/// Inputs of a thermal derivative.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ThermalInputs {
    /// Friction power of clutch 1, T_fc1·ω_fc1 (W).
    pub p_fric1_w: f64,
    /// Friction power of clutch 2 (W).
    pub p_fric2_w: f64,
    /// β1: 1.0 when clutch 1 is not open, else 0.0.
    pub beta1: f64,
    /// β2.
    pub beta2: f64,
    /// Housing air temperature θ_h (°C).
    pub theta_h_c: f64,
    /// Flywheel speed ω_f (rad/s): the pressure plates and the central disk turn with it (the
    /// nominal model's convection does not depend on it; a speed-dependent convection does).
    pub w_f_radps: f64,
}

/// β of a clutch: 1.0 when the flat spring is compressed (u_fs > 0), i.e. the clutch is not open.
#[inline]
pub fn beta(p: &ClutchParams, x_to_mm: f64, theta_c: f64) -> f64 {
    if clutch::u_fs(p, x_to_mm, theta_c) > 0.0 {
        1.0
    } else {
        0.0
    }
}

/// State of the 5-state model (°C).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Thermal5State {
    pub pp1: f64,
    pub pp2: f64,
    pub c1: f64,
    pub c2: f64,
    pub cd: f64,
}

impl Thermal5State {
    /// All five temperatures equal to `theta_c`.
    pub fn uniform(theta_c: f64) -> Self {
        Self {
            pp1: theta_c,
            pp2: theta_c,
            c1: theta_c,
            c2: theta_c,
            cd: theta_c,
        }
    }
    /// `self + k·d` (RK4 stages).
    pub fn axpy(&self, k: f64, d: &Self) -> Self {
        Self {
            pp1: self.pp1 + k * d.pp1,
            pp2: self.pp2 + k * d.pp2,
            c1: self.c1 + k * d.c1,
            c2: self.c2 + k * d.c2,
            cd: self.cd + k * d.cd,
        }
    }
    /// Body temperature as the paper defines it for (17): mean of pressure plates and central disk.
    pub fn body(&self) -> f64 {
        (self.pp1 + self.pp2 + self.cd) / 3.0
    }
    pub fn as_array(&self) -> [f64; 5] {
        [self.pp1, self.pp2, self.c1, self.c2, self.cd]
    }
}

/// The 5-state thermal model (16).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Thermal5 {
    pub p: ThermalParams5,
}

impl Thermal5 {
    pub fn new(p: ThermalParams5) -> Self {
        Self { p }
    }

    /// Time derivative (°C/s) of (16a)–(16e).
    #[inline]
    pub fn derivative(&self, s: &Thermal5State, u: &ThermalInputs) -> Thermal5State {
        let a = &self.p;
        let (b1, b2, th) = (u.beta1, u.beta2, u.theta_h_c);
        Thermal5State {
            pp1: a.alpha1_per_s * b1 * (s.c1 - s.pp1)
                + a.alpha2_per_s * (1.0 - b1) * (th - s.pp1)
                + a.alpha3_k_per_j * u.p_fric1_w,
            pp2: a.alpha1_per_s * b2 * (s.c2 - s.pp2)
                + a.alpha2_per_s * (1.0 - b2) * (th - s.pp2)
                + a.alpha3_k_per_j * u.p_fric2_w,
            c1: a.alpha4_per_s * b1 * (s.pp1 - s.c1)
                + a.alpha5_per_s * b1 * (s.cd - s.c1)
                + a.alpha6_per_s * (1.0 - b1) * (th - s.c1)
                + a.alpha7_k_per_j * u.p_fric1_w,
            c2: a.alpha4_per_s * b2 * (s.pp2 - s.c2)
                + a.alpha5_per_s * b2 * (s.cd - s.c2)
                + a.alpha6_per_s * (1.0 - b2) * (th - s.c2)
                + a.alpha7_k_per_j * u.p_fric2_w,
            cd: a.alpha5_per_s * b1 * (s.c1 - s.cd)
                + a.alpha5_per_s * b2 * (s.c2 - s.cd)
                + a.alpha8_per_s * (2.0 - b1 - b2) * (th - s.cd)
                + a.alpha9_k_per_j * (u.p_fric1_w + u.p_fric2_w),
        }
    }
}

/// A clutch disk's equation (16c)/(16d) with the plate, central-disk and housing temperatures
/// and the friction power given (as a replay of measured records takes them), written
/// θ̇_c = −λ·θ_c + g(θ_pp, θ_cd, θ_h, P): λ and the coefficients of g for contact flag β.
/// The disk replays of the diagnosis integrate it exactly over a step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiskRate {
    /// λ = α4·β + α5·β + α6·(1 − β) (1/s).
    pub lam: f64,
    /// g's coefficients of θ_pp (α4·β), θ_cd (α5·β), θ_h (α6·(1 − β)) and P (α7).
    pub k_pp: f64,
    pub k_cd: f64,
    pub k_th: f64,
    pub k_p: f64,
}

impl DiskRate {
    /// The disk equation of parameters `a` at contact flag `b`.
    #[inline(always)]
    pub fn new(a: &ThermalParams5, b: f64) -> Self {
        let (k_pp, k_cd, k_th) = (
            a.alpha4_per_s * b,
            a.alpha5_per_s * b,
            a.alpha6_per_s * (1.0 - b),
        );
        DiskRate {
            lam: k_pp + k_cd + k_th,
            k_pp,
            k_cd,
            k_th,
            k_p: a.alpha7_k_per_j,
        }
    }

    /// g for plate `pp`, central disk `cd`, housing `th` (°C) and friction power `pw` (W).
    #[inline(always)]
    pub fn g(&self, pp: f64, cd: f64, th: f64, pw: f64) -> f64 {
        self.k_pp * pp + self.k_cd * cd + self.k_th * th + self.k_p * pw
    }
}

/// State of the 3-state model (°C).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Thermal3State {
    pub c1: f64,
    pub c2: f64,
    /// Body: both pressure plates and the central disk.
    pub body: f64,
}

impl Thermal3State {
    pub fn uniform(theta_c: f64) -> Self {
        Self {
            c1: theta_c,
            c2: theta_c,
            body: theta_c,
        }
    }
    pub fn axpy(&self, k: f64, d: &Self) -> Self {
        Self {
            c1: self.c1 + k * d.c1,
            c2: self.c2 + k * d.c2,
            body: self.body + k * d.body,
        }
    }
}

/// The 3-state thermal model (17).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Thermal3 {
    pub p: ThermalParams3,
}

impl Thermal3 {
    pub fn new(p: ThermalParams3) -> Self {
        Self { p }
    }

    /// Time derivative (°C/s) of (17a)–(17c).
    #[inline]
    pub fn derivative(&self, s: &Thermal3State, u: &ThermalInputs) -> Thermal3State {
        let a = &self.p;
        let (b1, b2, th) = (u.beta1, u.beta2, u.theta_h_c);
        Thermal3State {
            c1: a.alpha1_per_s * b1 * (s.body - s.c1)
                + a.alpha2_per_s * (1.0 - b1) * (th - s.c1)
                + a.alpha3_k_per_j * u.p_fric1_w,
            c2: a.alpha1_per_s * b2 * (s.body - s.c2)
                + a.alpha2_per_s * (1.0 - b2) * (th - s.c2)
                + a.alpha3_k_per_j * u.p_fric2_w,
            body: a.alpha1_per_s * b1 * (s.c1 - s.body)
                + a.alpha1_per_s * b2 * (s.c2 - s.body)
                + a.alpha4_per_s * (2.0 - b1 - b2) * (th - s.body)
                + a.alpha3_k_per_j * (u.p_fric1_w + u.p_fric2_w),
        }
    }

    /// One RK4 step of length `dt` with inputs held constant (the estimator's update).
    pub fn step(&self, s: &Thermal3State, u: &ThermalInputs, dt: f64) -> Thermal3State {
        rk4_step(self, s, u, dt)
    }
}

impl Thermal5 {
    /// One RK4 step of length `dt` with inputs held constant.
    pub fn step(&self, s: &Thermal5State, u: &ThermalInputs, dt: f64) -> Thermal5State {
        rk4_step(self, s, u, dt)
    }
}

impl OdeState for Thermal5State {
    fn axpy(&self, k: f64, d: &Self) -> Self {
        Thermal5State::axpy(self, k, d)
    }
}

impl OdeState for Thermal3State {
    fn axpy(&self, k: f64, d: &Self) -> Self {
        Thermal3State::axpy(self, k, d)
    }
}

impl OdeSystem for Thermal5 {
    type State = Thermal5State;
    type Input = ThermalInputs;
    fn derivative(&self, x: &Thermal5State, u: &ThermalInputs) -> Thermal5State {
        Thermal5::derivative(self, x, u)
    }
}

impl OdeSystem for Thermal3 {
    type State = Thermal3State;
    type Input = ThermalInputs;
    fn derivative(&self, x: &Thermal3State, u: &ThermalInputs) -> Thermal3State {
        Thermal3::derivative(self, x, u)
    }
}

/// Inputs of the reference duty cycle used to derive the 3-state parameters from the 5-state
/// model at time `t_s`: 20 cycles of 60 s (a 2 s launch on clutch 1 with 20 kW falling to zero,
/// locked driving, a 1 s shift to clutch 2 with 8 kW falling to zero, driving on clutch 2, 10 s
/// stop with both clutches open), then 1800 s of cooling with both clutches open; housing 40 °C.
pub(crate) fn reference_duty_cycle(t_s: f64) -> ThermalInputs {
    let mut u = ThermalInputs {
        theta_h_c: 40.0,
        ..Default::default()
    };
    if t_s >= 1200.0 {
        return u;
    }
    let t = t_s % 60.0;
    if t < 2.0 {
        u.beta1 = 1.0;
        u.p_fric1_w = 20_000.0 * (1.0 - t / 2.0);
    } else if t < 25.0 {
        u.beta1 = 1.0;
    } else if t < 26.0 {
        u.beta1 = 1.0;
        u.beta2 = 1.0;
        u.p_fric2_w = 8_000.0 * (1.0 - (t - 25.0));
    } else if t < 50.0 {
        u.beta2 = 1.0;
    }
    u
}

/// Sum of squared differences (°C²) between the 3-state model with `p3` and the 5-state model
/// with `p5` over the reference duty cycle (3000 s, RK4 at `dt`, sampled every second): clutch
/// temperatures against θ_c1, θ_c2 and the body against the mean of θ_pp1, θ_pp2, θ_cd (the
/// paper's definition of the measured body temperature). Returns (cost, samples).
pub fn lumping_cost(p5: &ThermalParams5, p3: &ThermalParams3, dt: f64) -> (f64, usize) {
    let (m5, m3) = (Thermal5::new(*p5), Thermal3::new(*p3));
    let mut s5 = Thermal5State::uniform(40.0);
    let mut s3 = Thermal3State::uniform(40.0);
    let per_s = (1.0 / dt).round() as usize;
    let mut cost = 0.0;
    let mut n = 0;
    for k in 0..3000 * per_s {
        let u = reference_duty_cycle(k as f64 * dt);
        s5 = m5.step(&s5, &u, dt);
        s3 = m3.step(&s3, &u, dt);
        if (k + 1) % per_s == 0 {
            cost +=
                (s3.c1 - s5.c1).powi(2) + (s3.c2 - s5.c2).powi(2) + (s3.body - s5.body()).powi(2);
            n += 3;
        }
    }
    (cost, n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (16c)/(16d) as −λ·θ_c + g is the derivative's disk row, engaged or open.
    #[test]
    fn the_disk_rate_is_the_derivatives_disk_row() {
        let a = Params::default().thermal5;
        let m = Thermal5::new(a);
        for b in [0.0, 1.0] {
            let s = Thermal5State {
                pp1: 140.0,
                pp2: 90.0,
                c1: 170.0,
                c2: 60.0,
                cd: 110.0,
            };
            let u = ThermalInputs {
                p_fric1_w: 9000.0,
                p_fric2_w: 0.0,
                beta1: b,
                beta2: b,
                theta_h_c: 45.0,
                w_f_radps: 200.0,
            };
            let d = m.derivative(&s, &u);
            let r = DiskRate::new(&a, b);
            let g = r.g(s.pp1, s.cd, u.theta_h_c, u.p_fric1_w);
            assert!((g - r.lam * s.c1 - d.c1).abs() < 1e-9 * d.c1.abs().max(1.0));
        }
    }
    use crate::model::params::Params;

    #[test]
    fn equilibrium_at_housing_temperature() {
        let p = Params::default();
        let t5 = Thermal5::new(p.thermal5);
        let t3 = Thermal3::new(p.thermal3);
        for (b1, b2) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0)] {
            let u = ThermalInputs {
                beta1: b1,
                beta2: b2,
                theta_h_c: 60.0,
                ..Default::default()
            };
            let d = t5.derivative(&Thermal5State::uniform(60.0), &u);
            assert!(d.as_array().iter().all(|v| v.abs() < 1e-15));
            let d = t3.derivative(&Thermal3State::uniform(60.0), &u);
            assert!(d.c1.abs() + d.c2.abs() + d.body.abs() < 1e-15);
        }
    }

    #[test]
    fn heat_flows_from_hot_clutch_into_central_disk() {
        let t5 = Thermal5::new(Params::default().thermal5);
        let mut s = Thermal5State::uniform(50.0);
        s.c1 = 150.0;
        let u = ThermalInputs {
            beta1: 1.0,
            theta_h_c: 50.0,
            ..Default::default()
        };
        let d = t5.derivative(&s, &u);
        assert!(d.c1 < 0.0 && d.cd > 0.0 && d.pp1 > 0.0);
    }
}

//! Clutch temperature estimator: the 3-state thermal model (17a)–(17c) of the paper's Sect. 4,
//! driven by
//! - the estimated friction power P̂_i = T̂_fci·ω_fci, with T̂_fci the torque characteristic (13) at
//!   the measured bearing position, the measured slip and the *estimated* clutch temperature
//!   (slips below a dead band of two speed LSBs count as a locked clutch: no power);
//! - the measured housing air temperature θ_h;
//! - β_i = 1 when the flat spring of clutch i is compressed at the measured position and the
//!   estimated temperature (u_fs(x_meas, θ̂) > 0), else 0.
//!
//! One RK4 step of (17) per TCU cycle with the inputs held (`model::thermal::Thermal3::step`).

use super::control::ClutchModel;
use crate::model::clutch;
use crate::model::params::ThermalParams3;
use crate::model::thermal::{Thermal3, Thermal3State, ThermalInputs};

/// Inputs of one estimator update (measured values).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct EstimatorInputs {
    /// Measured bearing positions (mm).
    pub x_mm: [f64; 2],
    /// Measured slips ω_e − ω_ci (rad/s).
    pub slip_radps: [f64; 2],
    /// Measured housing temperature θ_h (°C).
    pub theta_h_c: f64,
}

/// The estimator's state and its last inputs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ThermalEstimator {
    model: Thermal3,
    state: Option<Thermal3State>,
    /// Friction power estimates of the last update (W).
    pub power_w: [f64; 2],
    /// Friction torque estimates of the last update (N·m).
    pub torque_nm: [f64; 2],
    /// β of the last update.
    pub beta: [f64; 2],
    deadband: f64,
    /// The last update computed a non-finite state (it was not taken).
    failed: bool,
}

impl ThermalEstimator {
    /// A new estimator; `initial` sets every temperature, otherwise the first housing temperature
    /// initialises it.
    pub fn new(p: ThermalParams3, initial: Option<f64>, slip_deadband_radps: f64) -> Self {
        Self {
            model: Thermal3::new(p),
            state: initial.map(Thermal3State::uniform),
            power_w: [0.0; 2],
            torque_nm: [0.0; 2],
            beta: [0.0; 2],
            deadband: slip_deadband_radps,
            failed: false,
        }
    }

    /// True when the last update computed a non-finite temperature or power: the estimate is
    /// frozen at its last finite value and must not be trusted (FaultCode InternalNonFinite).
    pub fn failed(&self) -> bool {
        self.failed
    }

    /// Current estimate, if initialised.
    pub fn state(&self) -> Option<Thermal3State> {
        self.state
    }

    /// Estimated clutch temperatures (°C); `fallback` before the first update.
    pub fn clutch_temps(&self, fallback: f64) -> [f64; 2] {
        self.state.map_or([fallback; 2], |s| [s.c1, s.c2])
    }

    /// Advances the estimate by `dt` seconds.
    pub fn update(&mut self, model: &ClutchModel, u: &EstimatorInputs, dt: f64) {
        if !u.theta_h_c.is_finite() {
            return;
        }
        let s = *self
            .state
            .get_or_insert_with(|| Thermal3State::uniform(u.theta_h_c));
        let th = [s.c1, s.c2];
        #[allow(clippy::needless_range_loop)] // four parallel per-clutch arrays
        for i in 0..2 {
            let (x, w) = (u.x_mm[i], u.slip_radps[i]);
            if !(x.is_finite() && w.is_finite()) {
                self.power_w[i] = 0.0;
                self.torque_nm[i] = 0.0;
                continue;
            }
            self.beta[i] = if clutch::u_fs(&model.p, x, th[i]) > 0.0 {
                1.0
            } else {
                0.0
            };
            let w_eff = if w.abs() < self.deadband { 0.0 } else { w };
            let t = model.torque(x, w_eff, th[i]);
            self.torque_nm[i] = t;
            self.power_w[i] = (t * w_eff).max(0.0);
        }
        if !(dt.is_finite() && dt > 0.0) {
            return;
        }
        let tin = ThermalInputs {
            p_fric1_w: self.power_w[0],
            p_fric2_w: self.power_w[1],
            beta1: self.beta[0],
            beta2: self.beta[1],
            theta_h_c: u.theta_h_c,
            // The TCU's model (16') has no speed-dependent convection.
            ..ThermalInputs::default()
        };
        let next = self.model.step(&s, &tin, dt);
        self.failed = !(next.c1.is_finite()
            && next.c2.is_finite()
            && next.body.is_finite()
            && self.power_w.iter().all(|p| p.is_finite()));
        if !self.failed {
            self.state = Some(next);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::params::Params;
    use crate::tcu::config::TcuConfig;

    fn model() -> ClutchModel {
        let c = TcuConfig::default();
        ClutchModel::new(c.physics.clutch, c.compensation)
    }

    #[test]
    fn a_non_finite_update_is_refused_and_reported() {
        let mut p = Params::default().thermal3;
        p.alpha3_k_per_j = f64::NAN;
        let mut e = ThermalEstimator::new(p, Some(60.0), 0.1);
        let u = EstimatorInputs {
            x_mm: [0.0, 0.0],
            slip_radps: [100.0, 100.0],
            theta_h_c: 40.0,
        };
        e.update(&model(), &u, 0.01);
        assert!(e.failed());
        assert_eq!(e.clutch_temps(0.0), [60.0, 60.0]);
    }

    #[test]
    fn open_clutches_relax_to_the_housing_temperature() {
        let p = Params::default().thermal3;
        let mut e = ThermalEstimator::new(p, Some(200.0), 0.1);
        let u = EstimatorInputs {
            x_mm: [0.0, 0.0],
            slip_radps: [100.0, 100.0],
            theta_h_c: 40.0,
        };
        let m = model();
        for _ in 0..100 {
            e.update(&m, &u, 0.01);
        }
        let s = e.state().unwrap();
        // Open clutch: θ̇_c = α̃2 (θ_h − θ_c), exponential decay with rate α̃2.
        let expected = 40.0 + 160.0 * (-p.alpha2_per_s * 1.0).exp();
        assert!((s.c1 - expected).abs() < 1e-6, "{} vs {expected}", s.c1);
        assert_eq!(e.power_w, [0.0, 0.0]);
    }

    #[test]
    fn slipping_clutch_heats_with_the_model_power() {
        let p = Params::default().thermal3;
        let mut e = ThermalEstimator::new(p, Some(50.0), 0.1);
        let m = model();
        let u = EstimatorInputs {
            x_mm: [5.5, 0.0],
            slip_radps: [80.0, 0.0],
            theta_h_c: 50.0,
        };
        e.update(&m, &u, 0.01);
        let t = m.torque(5.5, 80.0, 50.0);
        assert!((e.power_w[0] - t * 80.0).abs() < 1e-9);
        // First step from equilibrium: Δθ_c1 ≈ α̃3·P·dt.
        let d = e.state().unwrap().c1 - 50.0;
        assert!((d - p.alpha3_k_per_j * t * 80.0 * 0.01).abs() < 1e-3 * d.abs());
        assert_eq!(e.beta, [1.0, 0.0]);
    }
}

//! The decoupling engagement controller of the paper's Sect. 5.2 (Fig. 13), with the equations the
//! paper leaves blank written out as in DESIGN.md §4. With k_odd = i_godd·i_f, k_even = i_geven·i_f
//! and the reduced driveline (22):
//!
//! - (23) ω̇_f = v_e / J_eq, (24) v_e = T_e − T_fc1 − T_fc2, so T_e,ref = v_e + T_fc1,ref + T_fc2,ref;
//! - (25) ω̇_c1 = (k_odd / J_eq2)·v_c1, (26) v_c1 = k_odd T_fc1 + k_even T_fc2 − T_Load,
//!   (27) T_fc1,ref = (v_c1 − k_even T_fc2,ref + T̂_Load) / k_odd (and symmetrically for clutch 2);
//! - PI_e and PI_c produce v_e and v_c from the speed errors of the single-integrator models (23)
//!   and (25); both are written normalised by the model gain, v = J·(ω̇_ref + kp·e + ki·∫e), with
//!   conditional-integration anti-windup when the torque they command saturates;
//! - x_to,ref = the inverse of (13) at T_fc,ref, the measured slip and the estimated temperature
//!   ([`ClutchModel::position_for`]); temperature and slip compensation are each switchable off
//!   (the inverse then assumes the calibration temperature, or a constant friction coefficient
//!   μ_d, paper Sect. 6), everything else unchanged.
//!
//! [`ClutchModel`] is the one place the TCU evaluates the torque characteristic, both forward (the
//! thermal estimator's friction power) and inverse (the controller); a calibration with effects of
//! `model::effects` (`effects = "FILE"` in the TCU calibration) replaces it in that one spot.

use super::config::Compensation;
use crate::model::clutch;
use crate::model::driveline;
use crate::model::effects::{self, EffectSet, TorqueContext};
use crate::model::gear::Gear;
use crate::model::params::{ClutchParams, DrivelineParams, EngineParams};

/// The TCU's model of one dry clutch: the torque characteristic (13) and its inverse, optionally
/// calibrated with effects of `model::effects` (e.g. the ones `ddct gap` identified; the nominal
/// set gives (13) exactly).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClutchModel {
    pub p: ClutchParams,
    pub comp: Compensation,
    pub effects: EffectSet,
}

impl ClutchModel {
    pub fn new(p: ClutchParams, comp: Compensation) -> Self {
        Self::with_effects(p, comp, EffectSet::nominal())
    }

    pub fn with_effects(p: ClutchParams, comp: Compensation, effects: EffectSet) -> Self {
        Self { p, comp, effects }
    }

    /// Torque (N·m, sign of the slip) the model predicts at a bearing position, slip and clutch
    /// temperature: (13) (with the calibration's effects). Used by the estimator with the
    /// measured position and slip.
    pub fn torque(&self, x_to_mm: f64, slip_radps: f64, theta_c: f64) -> f64 {
        effects::torque(
            &self.p,
            &self.effects,
            &TorqueContext::new(x_to_mm, slip_radps, theta_c),
        )
    }

    /// The temperature and slip the inverse uses, after the compensation switches.
    pub fn inverse_arguments(&self, slip_radps: f64, theta_est_c: f64) -> (f64, f64) {
        let th = if self.comp.temperature {
            theta_est_c
        } else {
            self.comp.calibration_temp_c
        };
        let s = if self.comp.slip {
            slip_radps.abs()
        } else {
            self.comp.calibration_slip_radps
        };
        (s, th)
    }

    /// Bearing position (mm) for a torque magnitude at the measured slip and the estimated
    /// temperature: the inverse of (13) with the compensation switches applied. `None` torque or a
    /// non-finite argument gives the kiss point of the temperature the inverse uses.
    pub fn position_for(&self, torque_nm: f64, slip_radps: f64, theta_est_c: f64) -> f64 {
        let (s, th) = self.inverse_arguments(slip_radps, theta_est_c);
        let t = if torque_nm.is_finite() {
            torque_nm.abs()
        } else {
            0.0
        };
        match effects::invert(&self.p, &self.effects, t, &TorqueContext::new(0.0, s, th)) {
            Ok(inv) => inv.x_to_mm,
            Err(_) => clutch::x_isp(&self.p, self.comp.calibration_temp_c),
        }
    }

    /// Static capacity position: the bearing position whose static capacity 2·R_μ(0,θ)·F equals
    /// `torque_nm` (slip compensation on) — used to clamp a locked clutch.
    pub fn clamp_position_for(&self, torque_nm: f64, theta_est_c: f64) -> f64 {
        self.position_for(torque_nm, 0.0, theta_est_c)
    }

    /// Kiss point x_ISP at the estimated temperature (mm). Used for the standby position of an
    /// open clutch and to decide whether a clutch is open; it is not part of the torque inverse, so
    /// the compensation switches leave it alone (switching the inverse's temperature off must not
    /// also make a hot clutch drag at standstill).
    pub fn kiss_point(&self, theta_est_c: f64) -> f64 {
        let th = if theta_est_c.is_finite() {
            theta_est_c
        } else {
            self.comp.calibration_temp_c
        };
        // The inverse of zero torque is the kiss point (shifted by any calibrated wear).
        match effects::invert(
            &self.p,
            &self.effects,
            0.0,
            &TorqueContext::new(0.0, 0.0, th),
        ) {
            Ok(inv) => inv.x_to_mm,
            Err(_) => clutch::x_isp(&self.p, th),
        }
    }

    /// Largest torque the model gives at this slip and temperature.
    pub fn max_torque(&self, slip_radps: f64, theta_est_c: f64) -> f64 {
        let (s, th) = self.inverse_arguments(slip_radps, theta_est_c);
        if self.effects.is_nominal() {
            clutch::max_torque(&self.p, s, th)
        } else {
            effects::torque(
                &self.p,
                &self.effects,
                &TorqueContext::new(self.p.x_to_max_mm, s.max(1e-9), th),
            )
            .abs()
        }
    }
}

/// A PI controller normalised by its model gain: u = ff + kp·e + ∫ki·e, with conditional
/// integration (the integral is frozen while the output it produces is saturated in the direction
/// the error pushes) and an integral clamp.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct Pi {
    pub kp: f64,
    pub ki: f64,
    pub integral: f64,
    /// Bound of |integral| (same unit as the output).
    pub integral_max: f64,
}

impl Pi {
    pub fn new(kp: f64, ki: f64, integral_max: f64) -> Self {
        Self {
            kp,
            ki,
            integral: 0.0,
            integral_max,
        }
    }

    pub fn reset(&mut self, integral: f64) {
        self.integral = integral.clamp(-self.integral_max, self.integral_max);
    }

    /// Unsaturated output for error `e` with feed-forward `ff`.
    pub fn output(&self, ff: f64, e: f64) -> f64 {
        ff + self.kp * e + self.integral
    }

    /// Integrates the error over `dt` unless `saturated_high` (and e > 0) or `saturated_low`
    /// (and e < 0): anti-windup by conditional integration.
    pub fn integrate(&mut self, e: f64, dt: f64, saturated_high: bool, saturated_low: bool) {
        if !(e.is_finite() && dt.is_finite()) {
            return;
        }
        if (saturated_high && e > 0.0) || (saturated_low && e < 0.0) {
            return;
        }
        self.integral =
            (self.integral + self.ki * e * dt).clamp(-self.integral_max, self.integral_max);
    }
}

/// Driveline quantities of the reduced model (22) for the current gears.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reduced {
    /// J_eq (engine + flywheel) (kg·m²).
    pub j_eq: f64,
    /// J_eq2 = k_odd² J_c1 + k_even² J_c2 + J_d (only shafts with a gear engaged) (kg·m²).
    pub j_eq2: f64,
    /// Overall ratios k = i_g·i_f per shaft (0 when neutral).
    pub k: [f64; 2],
}

impl Reduced {
    pub fn new(d: &DrivelineParams, gear_odd: Gear, gear_even: Gear) -> Self {
        let k_odd = driveline::overall_ratio(d, gear_odd).unwrap_or(0.0);
        let k_even = driveline::overall_ratio(d, gear_even).unwrap_or(0.0);
        let j = driveline::inertias(d);
        Reduced {
            j_eq: d.j_eq_kgm2,
            j_eq2: k_odd * k_odd * d.j_c1_kgm2 + k_even * k_even * d.j_c2_kgm2 + j[3],
            k: [k_odd, k_even],
        }
    }

    /// The model gain of (25) for clutch `a`: ω̇_ca = b·v_c with b = k_a / J_eq2 (rad/s² per N·m).
    pub fn clutch_gain(&self, a: usize) -> f64 {
        self.k[a] / self.j_eq2
    }

    /// Decoupling law (27) for the active clutch `a`: T_a,ref = (v_c − k_o T_o,ref + T̂_L) / k_a.
    pub fn decouple(&self, a: usize, v_c: f64, t_other_ref: f64, t_load_hat: f64) -> f64 {
        let o = 1 - a;
        if self.k[a] == 0.0 {
            return 0.0;
        }
        (v_c - self.k[o] * t_other_ref + t_load_hat) / self.k[a]
    }

    /// v_c of (26) that makes clutch `a` follow an acceleration: J_eq2/k_a·ω̇.
    pub fn v_c_for(&self, a: usize, w_dot: f64) -> f64 {
        if self.k[a] == 0.0 {
            0.0
        } else {
            self.j_eq2 / self.k[a] * w_dot
        }
    }
}

/// The TCU's road-load estimate T̂_Load (19) at the wheels from the measured output speed (no
/// grade: the clutch-speed integral absorbs it).
pub(crate) fn load_estimate(d: &DrivelineParams, w_out_radps: f64) -> f64 {
    driveline::load_torque(d, w_out_radps, 0.0, 0.0)
}

/// Engine torque range the engine ECU honours at speed `w`: [−drag, full load] (N·m).
pub(crate) fn engine_range(e: &EngineParams, w_radps: f64) -> (f64, f64) {
    use crate::model::engine;
    (-engine::drag(e, w_radps), engine::full_load(e, w_radps))
}

/// The driver's torque demand the engine delivers without a TCU request (the engine ECU's pedal
/// map): p·T_full − (1 − p)·T_drag, p in 0..1.
pub(crate) fn driver_demand(e: &EngineParams, pedal: f64, w_radps: f64) -> f64 {
    use crate::model::engine;
    let p = if pedal.is_finite() {
        pedal.clamp(0.0, 1.0)
    } else {
        0.0
    };
    p * engine::full_load(e, w_radps) - (1.0 - p) * engine::drag(e, w_radps)
}

/// Moves `x` toward `target` by at most `rate·dt`.
pub(crate) fn approach(x: f64, target: f64, rate: f64, dt: f64) -> f64 {
    let step = (rate * dt).abs();
    if !x.is_finite() {
        return target;
    }
    x + (target - x).clamp(-step, step)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::params::Params;

    fn comp(t: bool, s: bool) -> Compensation {
        Compensation {
            temperature: t,
            slip: s,
            calibration_temp_c: 25.0,
            calibration_slip_radps: 1000.0,
        }
    }

    #[test]
    fn inverse_round_trips_through_the_forward_model() {
        let m = ClutchModel::new(Params::default().clutch, comp(true, true));
        for &(t, s, th) in &[(40.0, 50.0, 25.0), (120.0, 1.0, 140.0), (10.0, 0.3, 240.0)] {
            let x = m.position_for(t, s, th);
            assert!((m.torque(x, s, th) - t).abs() < 1e-6, "{t} {s} {th}");
        }
    }

    #[test]
    fn switches_change_only_their_argument() {
        let p = Params::default().clutch;
        let on = ClutchModel::new(p, comp(true, true));
        let no_temp = ClutchModel::new(p, comp(false, true));
        let no_slip = ClutchModel::new(p, comp(true, false));
        // Temperature off: the inverse at 240 °C equals the compensated inverse at 25 °C.
        assert_eq!(
            no_temp.position_for(60.0, 20.0, 240.0),
            on.position_for(60.0, 20.0, 25.0)
        );
        // Slip off: constant friction μ_d — at low slip the same torque needs a smaller position
        // than the compensated inverse (μ(0.2 rad/s) < μ_d), at high slip the two agree.
        assert!(no_slip.position_for(60.0, 0.2, 100.0) < on.position_for(60.0, 0.2, 100.0) - 0.01);
        assert!(
            (no_slip.position_for(60.0, 500.0, 100.0) - on.position_for(60.0, 500.0, 100.0)).abs()
                < 1e-6
        );
        // The forward model (the estimator's) ignores the switches.
        assert_eq!(
            no_temp.torque(5.0, 10.0, 200.0),
            on.torque(5.0, 10.0, 200.0)
        );
    }

    #[test]
    fn a_calibration_with_effects_inverts_its_own_forward_model() {
        use crate::model::effects::EffectId;
        let p = Params::default().clutch;
        for id in [EffectId::SpringStiffnessTemp, EffectId::FrictionPressure] {
            let set = EffectSet::single(id, &id.typical()[..id.params().len()]).unwrap();
            let m = ClutchModel::with_effects(p, comp(true, true), set);
            let nominal = ClutchModel::new(p, comp(true, true));
            let x = m.position_for(80.0, 20.0, 200.0);
            assert!((m.torque(x, 20.0, 200.0) - 80.0).abs() < 1e-4, "{id:?}");
            assert!(
                (x - nominal.position_for(80.0, 20.0, 200.0)).abs() > 1e-3,
                "{id:?} changes the calibration"
            );
        }
    }

    #[test]
    fn decoupling_law_inverts_the_reduced_model() {
        let d = Params::default().driveline;
        let r = Reduced::new(&d, Gear::G1, Gear::G2);
        // (26) with T_fc1 from (27) must give back v_c1.
        let (v_c, t2, tl) = (120.0, 30.0, 50.0);
        let t1 = r.decouple(0, v_c, t2, tl);
        assert!((r.k[0] * t1 + r.k[1] * t2 - tl - v_c).abs() < 1e-9);
        // A neutral even shaft leaves J_eq2 = k_odd² J_c1 + J_d.
        let r1 = Reduced::new(&d, Gear::G1, Gear::N);
        assert!(r1.j_eq2 < r.j_eq2 && r1.k[1] == 0.0);
    }

    #[test]
    fn pi_does_not_wind_up_while_saturated() {
        let mut pi = Pi::new(1.0, 10.0, 100.0);
        for _ in 0..100 {
            pi.integrate(5.0, 0.01, true, false);
        }
        assert_eq!(pi.integral, 0.0);
        pi.integrate(-5.0, 0.01, true, false);
        assert!(pi.integral < 0.0, "unwinds");
        for _ in 0..10000 {
            pi.integrate(5.0, 0.01, false, false);
        }
        assert_eq!(pi.integral, 100.0, "clamped");
    }
}

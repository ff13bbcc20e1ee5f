//! The plant's reality effects as `model::powertrain::Hooks`: the pure evaluation functions of
//! `model::effects` plus the few discrete states some effects need, advanced between the 1 ms
//! steps by [`EffectHooks::advance`]:
//! - `actuator_backlash`: the bearing position behind the play (the powertrain's `x1_mm`/`x2_mm`
//!   are the actuator positions the sensor measures; the clutch sees the bearing);
//! - `surface_temperature_friction`: the facing surface temperature per clutch;
//! - `sliding_acceleration_friction`: the slip acceleration of the previous step.
//!
//! `actuator_dead_time` acts on the requests before the powertrain (in `core`), and
//! `engine_torque_error`'s report (the ECU's map estimate) is formed in `core` from
//! [`effects::engine_map_estimate`].

use crate::model::driveline::{C1, C2, F};
use crate::model::effects::{self, EffectSet, TorqueContext};
use crate::model::params::ClutchParams;
use crate::model::powertrain::{ClutchContext, Hooks, Outputs, State};
use crate::model::thermal::{Thermal5State, ThermalInputs};

/// Effect hooks with their discrete states.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffectHooks {
    pub set: EffectSet,
    /// Throwout-bearing positions behind the backlash (mm).
    pub bearing_mm: [f64; 2],
    /// Facing surface temperatures (°C).
    pub theta_surface_c: [f64; 2],
    /// Slip accelerations dω_fc/dt of the previous step (rad/s²).
    pub slip_accel_radps2: [f64; 2],
}

impl EffectHooks {
    /// Hooks for `set` starting at state `s` (bearings at the actuators, surfaces at θ_c).
    pub fn new(set: EffectSet, s: &State) -> Self {
        Self {
            set,
            bearing_mm: [s.x1_mm, s.x2_mm],
            theta_surface_c: [s.thermal.c1, s.thermal.c2],
            slip_accel_radps2: [0.0; 2],
        }
    }

    /// The torque context of a clutch: bearing behind the backlash, effect states.
    pub fn context(&self, c: &ClutchContext) -> TorqueContext {
        let i = c.clutch.min(1);
        TorqueContext {
            x_to_mm: effects::bearing_position(&self.set, self.bearing_mm[i], c.x_to_mm),
            slip_radps: c.slip_radps,
            theta_c: c.theta_c,
            theta_pp: c.theta_pp,
            theta_cd: c.theta_cd,
            e_fric_j: c.e_fric_j,
            theta_surface_c: if self
                .set
                .is_active(effects::EffectId::SurfaceTemperatureFriction)
            {
                self.theta_surface_c[i]
            } else {
                c.theta_c
            },
            slip_accel_radps2: self.slip_accel_radps2[i],
            slip_shape: None,
        }
    }

    /// Bearing position (mm) the clutch sees for actuator position `x_actuator_mm`.
    pub fn bearing(&self, i: usize, x_actuator_mm: f64) -> f64 {
        effects::bearing_position(&self.set, self.bearing_mm[i.min(1)], x_actuator_mm)
    }

    /// True when the effect states need the powertrain's outputs at the end of every step
    /// (the surface temperature its friction power, the sliding acceleration the body
    /// accelerations); otherwise the plant computes outputs only when a frame is due.
    pub fn needs_outputs(&self) -> bool {
        self.set
            .is_active(effects::EffectId::SurfaceTemperatureFriction)
            || self
                .set
                .is_active(effects::EffectId::SlidingAccelerationFriction)
    }

    /// Advances the discrete effect states over a step of `dt` seconds that ended at `s` with
    /// outputs `out` (`None` when [`Self::needs_outputs`] is false: only the bearings move).
    pub fn advance(&mut self, s: &State, out: Option<&Outputs>, dt: f64) {
        let x = [s.x1_mm, s.x2_mm];
        for (b, x) in self.bearing_mm.iter_mut().zip(x) {
            *b = effects::bearing_position(&self.set, *b, x);
        }
        let Some(out) = out else {
            return;
        };
        let th = [s.thermal.c1, s.thermal.c2];
        let p = [out.p_fric1_w, out.p_fric2_w];
        let acc_c = [out.acc[C1], out.acc[C2]];
        for i in 0..2 {
            self.theta_surface_c[i] = effects::surface_temperature_step(
                &self.set,
                self.theta_surface_c[i],
                th[i],
                p[i],
                dt,
            );
            let a = out.acc[F] - acc_c[i];
            self.slip_accel_radps2[i] = if a.is_finite() { a } else { 0.0 };
        }
    }
}

impl Hooks for EffectHooks {
    fn clutch_torque(&self, p: &ClutchParams, c: &ClutchContext) -> f64 {
        effects::torque(p, &self.set, &self.context(c))
    }

    fn clutch_capacity(&self, p: &ClutchParams, c: &ClutchContext) -> f64 {
        effects::capacity(p, &self.set, &self.context(c))
    }

    fn clutch_beta(&self, p: &ClutchParams, c: &ClutchContext) -> f64 {
        effects::beta(p, &self.set, &self.context(c))
    }

    fn engine_command(&self, nominal_nm: f64, _w_f_radps: f64) -> f64 {
        effects::engine_real_torque(&self.set, nominal_nm)
    }

    fn extra_heat(&self, s: &Thermal5State, u: &ThermalInputs) -> Thermal5State {
        effects::thermal5_extra(&self.set, s, u)
    }
}

//! The actuator classes: the position request acting a dead time later, a lag τ far from the
//! model's (both seen in position vs request), and a gain and offset between the measured
//! position and the bearing (seen through the torque). The backlash is its library member alone
//! ([`super::MemberOnly`]).

use super::basis::Basis;
use super::common::{
    gain_offset, go, largest_gain_error, member_magnitude, member_params, POSITION_READING_RANGE,
};
use super::effect_class::EffectClass;
use super::knots::{Has, Knots, Needs};
use crate::gap::fit::lsq::ParamSpec;
use crate::gap::model::candidate::Model;
use crate::gap::model::class::ClassId;
use crate::gap::model::terms::X_REF_MM;
use crate::model::effects::{EffectId, Subsystem};

fn no_requests(has: Has) -> Option<String> {
    (!has(Needs::Requests))
        .then(|| "no position request logged (x_to1_req_mm / x_to2_req_mm, TCU_ClutchCmd)".into())
}

pub struct DeadTime;

impl EffectClass for DeadTime {
    fn id(&self) -> ClassId {
        ClassId::ActuatorDeadTime
    }
    fn group(&self) -> Subsystem {
        Subsystem::Actuator
    }
    fn not_checkable(&self, _knots: &Knots, has: Has) -> Option<String> {
        no_requests(has)
    }
    fn params(&self, _base: &Model) -> Vec<ParamSpec> {
        member_params(EffectId::ActuatorDeadTime)
    }
    fn apply(&self, _knots: &Knots, m: &mut Model, v: &[f64]) {
        m.set.set_clamped(EffectId::ActuatorDeadTime, v);
    }
    fn clear(&self, _m: &mut Model, _reference: &Model) {}
    fn magnitude(&self, m: &Model) -> (f64, &'static str) {
        member_magnitude(self.id(), m)
    }
    fn basis(&self, _m: &Model) -> Basis {
        Basis::Parameter
    }
}

/// The model's lag τ itself, refitted: the class is the actuator's recalibration.
pub struct Lag;

impl EffectClass for Lag {
    fn id(&self) -> ClassId {
        ClassId::ActuatorLag
    }
    fn group(&self) -> Subsystem {
        Subsystem::Actuator
    }
    fn not_checkable(&self, _knots: &Knots, has: Has) -> Option<String> {
        no_requests(has)
    }
    fn replaces_recalibration(&self) -> bool {
        true
    }
    fn params(&self, base: &Model) -> Vec<ParamSpec> {
        let tau = base.p.actuator.tau_s;
        vec![ParamSpec::new("actuator_lag.tau_s", tau, tau / 20.0, tau * 20.0, tau).log()]
    }
    fn apply(&self, _knots: &Knots, m: &mut Model, v: &[f64]) {
        m.p.actuator.tau_s = v[0];
    }
    fn clear(&self, m: &mut Model, reference: &Model) {
        m.p.actuator.tau_s = reference.p.actuator.tau_s;
    }
    fn magnitude(&self, m: &Model) -> (f64, &'static str) {
        (m.p.actuator.tau_s, "s")
    }
    fn basis(&self, _m: &Model) -> Basis {
        Basis::Parameter
    }
}

/// Bearing = gain·(measured − x_ref) + x_ref + offset: fitted on the torque, which the bearing
/// sets.
pub struct Transfer;

impl EffectClass for Transfer {
    fn id(&self) -> ClassId {
        ClassId::ActuatorTransfer
    }
    fn group(&self) -> Subsystem {
        Subsystem::TorqueCharacteristic
    }
    fn params(&self, _base: &Model) -> Vec<ParamSpec> {
        gain_offset(self.id(), 0.3, "offset_mm", 1.0, 0.05)
    }
    fn apply(&self, _knots: &Knots, m: &mut Model, v: &[f64]) {
        m.terms.transfer = Some(go(v));
    }
    fn clear(&self, m: &mut Model, _reference: &Model) {
        m.terms.transfer = None;
    }
    fn magnitude(&self, m: &Model) -> (f64, &'static str) {
        (
            largest_gain_error(m.terms.transfer, X_REF_MM, POSITION_READING_RANGE),
            "mm, bearing minus measured position, largest over 0…6 mm",
        )
    }
    fn basis(&self, _m: &Model) -> Basis {
        let (from, to) = POSITION_READING_RANGE;
        Basis::Largest { from, to }
    }
}

//! The engine torque (18a) differing from the ECU's map by a relative error: its library member.

use super::basis::Basis;
use super::common::{member_magnitude, member_params};
use super::effect_class::EffectClass;
use super::knots::{Has, Knots, Needs};
use crate::gap::fit::lsq::ParamSpec;
use crate::gap::model::candidate::Model;
use crate::gap::model::class::ClassId;
use crate::model::effects::{EffectId, Subsystem};

pub struct TorqueError;

impl EffectClass for TorqueError {
    fn id(&self) -> ClassId {
        ClassId::EngineTorqueError
    }
    fn group(&self) -> Subsystem {
        Subsystem::Engine
    }
    fn not_checkable(&self, _knots: &Knots, has: Has) -> Option<String> {
        (!has(Needs::Engine)).then(|| {
            "needs vehicle records with T_e_Nm (on the rig the dyno replaces the engine)".into()
        })
    }
    fn params(&self, _base: &Model) -> Vec<ParamSpec> {
        member_params(EffectId::EngineTorqueError)
    }
    fn apply(&self, _knots: &Knots, m: &mut Model, v: &[f64]) {
        m.set.set_clamped(EffectId::EngineTorqueError, v);
    }
    fn clear(&self, _m: &mut Model, _reference: &Model) {}
    fn magnitude(&self, m: &Model) -> (f64, &'static str) {
        member_magnitude(self.id(), m)
    }
    fn basis(&self, _m: &Model) -> Basis {
        Basis::Parameter
    }
}

//! A class whose flexible form is its library member's parametric form (the facings following
//! their plates (11), the actuator's backlash).

use super::basis::Basis;
use super::common::{member_magnitude, member_params};
use super::effect_class::EffectClass;
use super::knots::Knots;
use crate::gap::fit::lsq::ParamSpec;
use crate::gap::model::candidate::Model;
use crate::gap::model::class::ClassId;
use crate::model::effects::Subsystem;

/// A class whose flexible form is its library member's parametric form.
pub struct MemberOnly(pub ClassId, pub Subsystem);

impl EffectClass for MemberOnly {
    fn id(&self) -> ClassId {
        self.0
    }
    fn group(&self) -> Subsystem {
        self.1
    }
    fn params(&self, _base: &Model) -> Vec<ParamSpec> {
        self.0.member().map(member_params).unwrap_or_default()
    }
    fn apply(&self, _knots: &Knots, m: &mut Model, v: &[f64]) {
        if let Some(id) = self.0.member() {
            m.set.set_clamped(id, v);
        }
    }
    fn clear(&self, _m: &mut Model, _reference: &Model) {}
    fn magnitude(&self, m: &Model) -> (f64, &'static str) {
        member_magnitude(self.0, m)
    }
    fn basis(&self, _m: &Model) -> Basis {
        Basis::Parameter
    }
}

//! A factor 1 + s(θ_c) on one term of the model in the clutch temperature — the static friction
//! coefficient μ_s of (4), the flat-spring load of (10) — whose library member is a linear law in
//! θ read from the fitted curve's slope.

use super::basis::{Basis, RELATIVE};
use super::common::{points_of, shape_change, shape_on, shape_params, slope};
use super::effect_class::EffectClass;
use super::knots::Knots;
use crate::gap::fit::lsq::ParamSpec;
use crate::gap::model::candidate::Model;
use crate::gap::model::class::{ClassId, Variable};
use crate::gap::model::shape::Shape;
use crate::gap::model::terms::Terms;
use crate::model::effects::{EffectId, Subsystem};

/// The class, its member, and the term it reads and writes.
pub struct TemperatureFactor {
    pub id: ClassId,
    pub member: EffectId,
    pub term: fn(&Terms) -> Option<Shape>,
    pub set: fn(&mut Terms, Option<Shape>),
}

impl EffectClass for TemperatureFactor {
    fn id(&self) -> ClassId {
        self.id
    }
    fn group(&self) -> Subsystem {
        Subsystem::TorqueCharacteristic
    }
    fn shape_variable(&self) -> Option<Variable> {
        Some(Variable::Temperature)
    }
    fn params(&self, _base: &Model) -> Vec<ParamSpec> {
        shape_params(self.id.as_str(), 0.4, 0.02)
    }
    fn apply(&self, knots: &Knots, m: &mut Model, v: &[f64]) {
        (self.set)(&mut m.terms, shape_on(knots, Variable::Temperature, v));
    }
    fn clear(&self, m: &mut Model, _reference: &Model) {
        (self.set)(&mut m.terms, None);
    }
    fn magnitude(&self, m: &Model) -> (f64, &'static str) {
        (
            shape_change((self.term)(&m.terms).as_ref(), true).0,
            RELATIVE,
        )
    }
    fn basis(&self, m: &Model) -> Basis {
        shape_change((self.term)(&m.terms).as_ref(), true).1
    }
    fn shape_points(&self, m: &Model) -> Vec<(f64, f64)> {
        points_of((self.term)(&m.terms))
    }
    fn member_from_shape(&self, m: &Model) -> Option<(EffectId, Vec<f64>)> {
        let pts = self.shape_points(m);
        (pts.len() >= 2).then(|| (self.member, vec![slope(&pts)]))
    }
}

//! The flat-spring load (10) scaled by g(θ_c); its member a linear law in θ.

use super::{
    points_of, shape_change, shape_on, shape_params, slope, torque_shape_checkable, Basis,
    EffectClass, Has, Knots, RELATIVE,
};
use crate::gap::candidates::Model;
use crate::gap::class::{ClassId, Variable};
use crate::gap::lsq::ParamSpec;
use crate::model::effects::{EffectId, Subsystem};

pub struct SpringTemperature;

impl EffectClass for SpringTemperature {
    fn id(&self) -> ClassId {
        ClassId::SpringTemperature
    }
    fn group(&self) -> Subsystem {
        Subsystem::TorqueCharacteristic
    }
    fn shape_variable(&self) -> Option<Variable> {
        Some(Variable::Temperature)
    }
    fn not_checkable(&self, knots: &Knots, has: Has) -> Option<String> {
        torque_shape_checkable(Variable::Temperature, knots, has)
    }
    fn params(&self, _base: &Model) -> Vec<ParamSpec> {
        shape_params(self.id().as_str(), 0.4, 0.02)
    }
    fn apply(&self, knots: &Knots, m: &mut Model, v: &[f64]) {
        m.terms.spring = shape_on(knots, Variable::Temperature, v);
    }
    fn clear(&self, m: &mut Model, _reference: &Model) {
        m.terms.spring = None;
    }
    fn magnitude(&self, m: &Model) -> (f64, &'static str) {
        (shape_change(m.terms.spring.as_ref(), true).0, RELATIVE)
    }
    fn basis(&self, m: &Model) -> Basis {
        shape_change(m.terms.spring.as_ref(), true).1
    }
    fn shape_points(&self, m: &Model) -> Vec<(f64, f64)> {
        points_of(m.terms.spring)
    }
    fn member_from_shape(&self, m: &Model) -> Option<(EffectId, Vec<f64>)> {
        let pts = self.shape_points(m);
        (pts.len() >= 2).then(|| (EffectId::SpringStiffnessTemp, vec![slope(&pts)]))
    }
}

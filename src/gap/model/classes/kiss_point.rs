//! The kiss point (9) shifted by s(z) (mm): beyond its quadratic in θ with the temperature, or
//! with the friction energy (wear, bedding-in: x_to,max moves too); the wear member a linear law
//! in the energy.

use super::basis::Basis;
use super::common::{points_of, shape_change, shape_on, shape_params, slope};
use super::effect_class::EffectClass;
use super::knots::Knots;
use crate::gap::fit::lsq::ParamSpec;
use crate::gap::model::candidate::Model;
use crate::gap::model::class::{ClassId, Variable};
use crate::model::effects::{EffectId, Subsystem};

/// The shift in a variable, and the member read from its slope (if any).
pub struct KissPoint(pub ClassId, pub Variable, pub Option<EffectId>);

impl EffectClass for KissPoint {
    fn id(&self) -> ClassId {
        self.0
    }
    fn group(&self) -> Subsystem {
        Subsystem::TorqueCharacteristic
    }
    fn shape_variable(&self) -> Option<Variable> {
        Some(self.1)
    }
    fn writes(&self) -> Option<&'static str> {
        Some("kiss_point")
    }
    fn params(&self, _base: &Model) -> Vec<ParamSpec> {
        shape_params(self.0.as_str(), 1.0, 0.05)
    }
    fn apply(&self, knots: &Knots, m: &mut Model, v: &[f64]) {
        m.terms.kiss = shape_on(knots, self.1, v).map(|s| (self.1, s));
    }
    fn clear(&self, m: &mut Model, _reference: &Model) {
        m.terms.kiss = None;
    }
    fn magnitude(&self, m: &Model) -> (f64, &'static str) {
        (
            shape_change(m.terms.kiss.as_ref().map(|k| &k.1), false).0,
            "mm",
        )
    }
    fn basis(&self, m: &Model) -> Basis {
        shape_change(m.terms.kiss.as_ref().map(|k| &k.1), false).1
    }
    fn shape_points(&self, m: &Model) -> Vec<(f64, f64)> {
        points_of(m.terms.kiss.map(|s| s.1))
    }
    fn member_from_shape(&self, m: &Model) -> Option<(EffectId, Vec<f64>)> {
        let member = self.2?;
        let pts = self.shape_points(m);
        (pts.len() >= 2).then(|| (member, vec![slope(&pts)]))
    }
}

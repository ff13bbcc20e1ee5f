//! The thermal paths of (16) the model lacks: conduction from the disks to supports at the
//! housing temperature, convection changing with the flywheel speed, and the friction heat's
//! partition between plate and disk changing with the friction power.

use super::basis::Basis;
use super::common::{no_temperatures, points_of, shape_change, shape_on, shape_params, slope};
use super::effect_class::EffectClass;
use super::knots::{Has, Knots, Needs};
use crate::gap::fit::lsq::ParamSpec;
use crate::gap::model::candidate::Model;
use crate::gap::model::class::{ClassId, Variable};
use crate::gap::model::shape::KNOTS;
use crate::gap::model::terms::{Convection, Partition, Support};
use crate::model::effects::{EffectId, Subsystem};
use std::ops::Range;

/// A thermal shape class: it needs the temperatures and its variable varying.
fn checkable(var: Variable, knots: &Knots, has: Has) -> Option<String> {
    if !has(Needs::Temperatures) {
        return Some(no_temperatures());
    }
    (!knots.0.contains_key(&var)).then(|| match var {
        Variable::TemperatureDifference => {
            "the records do not vary the temperature above the housing".into()
        }
        Variable::Speed => "the records do not vary the flywheel speed".into(),
        _ => "the records have no slipping clutch whose friction power varies".into(),
    })
}

pub struct SupportConduction;

impl EffectClass for SupportConduction {
    fn id(&self) -> ClassId {
        ClassId::SupportConduction
    }
    fn group(&self) -> Subsystem {
        Subsystem::Thermal
    }
    fn shape_variable(&self) -> Option<Variable> {
        Some(Variable::TemperatureDifference)
    }
    /// None: its heat flows are bounded to be non-negative already.
    fn increments(&self) -> Option<Range<usize>> {
        None
    }
    fn not_checkable(&self, knots: &Knots, has: Has) -> Option<String> {
        checkable(Variable::TemperatureDifference, knots, has)
    }
    /// Heat loss rising with θ − θ_h (K/s per knot interval), weights of the plates and the
    /// central disk relative to the clutch disks.
    fn params(&self, _base: &Model) -> Vec<ParamSpec> {
        let name = self.id().as_str();
        let mut v: Vec<ParamSpec> = (1..KNOTS)
            .map(|j| ParamSpec::new(format!("{name}.d{j}_k_per_s"), 0.0, 0.0, 2.0, 0.02))
            .collect();
        v.push(ParamSpec::new(format!("{name}.w_pp"), 0.3, 0.0, 3.0, 0.1));
        v.push(ParamSpec::new(format!("{name}.w_cd"), 1.0, 0.0, 3.0, 0.1));
        v
    }
    fn apply(&self, knots: &Knots, m: &mut Model, v: &[f64]) {
        m.terms.support =
            shape_on(knots, Variable::TemperatureDifference, v).map(|shape| Support {
                shape,
                w_pp: v.get(KNOTS - 1).copied().unwrap_or(0.0),
                w_cd: v.get(KNOTS).copied().unwrap_or(1.0),
            });
    }
    fn clear(&self, m: &mut Model, _reference: &Model) {
        m.terms.support = None;
    }
    fn magnitude(&self, m: &Model) -> (f64, &'static str) {
        (
            shape_change(m.terms.support.as_ref().map(|s| &s.shape), false).0,
            "K/s from a clutch disk at the top of θ − θ_h",
        )
    }
    fn basis(&self, m: &Model) -> Basis {
        shape_change(m.terms.support.as_ref().map(|s| &s.shape), false).1
    }
    fn shape_points(&self, m: &Model) -> Vec<(f64, f64)> {
        points_of(m.terms.support.map(|s| s.shape))
    }
    fn member_from_shape(&self, m: &Model) -> Option<(EffectId, Vec<f64>)> {
        let pts = self.shape_points(m);
        (pts.len() >= 2).then(|| (EffectId::SupportConduction, vec![slope(&pts)]))
    }
}

/// Relative change of the convective rates over the flywheel-speed range.
pub struct ConvectionSpeed;

impl EffectClass for ConvectionSpeed {
    fn id(&self) -> ClassId {
        ClassId::ConvectionSpeed
    }
    fn group(&self) -> Subsystem {
        Subsystem::Thermal
    }
    fn shape_variable(&self) -> Option<Variable> {
        Some(Variable::Speed)
    }
    fn not_checkable(&self, knots: &Knots, has: Has) -> Option<String> {
        checkable(Variable::Speed, knots, has)
    }
    fn params(&self, _base: &Model) -> Vec<ParamSpec> {
        shape_params(self.id().as_str(), 2.0, 0.05)
    }
    fn apply(&self, knots: &Knots, m: &mut Model, v: &[f64]) {
        m.terms.convection = shape_on(knots, Variable::Speed, v).map(|shape| Convection { shape });
    }
    fn clear(&self, m: &mut Model, _reference: &Model) {
        m.terms.convection = None;
    }
    fn magnitude(&self, m: &Model) -> (f64, &'static str) {
        (
            shape_change(m.terms.convection.as_ref().map(|c| &c.shape), false).0,
            "relative convection change over the flywheel-speed range",
        )
    }
    fn basis(&self, m: &Model) -> Basis {
        shape_change(m.terms.convection.as_ref().map(|c| &c.shape), false).1
    }
    fn shape_points(&self, m: &Model) -> Vec<(f64, f64)> {
        points_of(m.terms.convection.map(|c| c.shape))
    }
}

/// Share of the plate's heat moved to the disk over the friction-power range, and the disk's
/// rate per unit of the plate's: C_pp/C_c = α4/α1 in (16).
pub struct HeatPartition;

impl EffectClass for HeatPartition {
    fn id(&self) -> ClassId {
        ClassId::HeatPartition
    }
    fn group(&self) -> Subsystem {
        Subsystem::Thermal
    }
    fn shape_variable(&self) -> Option<Variable> {
        Some(Variable::Power)
    }
    fn not_checkable(&self, knots: &Knots, has: Has) -> Option<String> {
        checkable(Variable::Power, knots, has)
    }
    fn params(&self, base: &Model) -> Vec<ParamSpec> {
        let a = &base.p.thermal5;
        let w = a.alpha4_per_s / a.alpha1_per_s.max(1e-12);
        let mut v = shape_params(self.id().as_str(), 0.5, 0.01);
        v.push(ParamSpec::new(
            format!("{}.w_c", self.id()),
            w,
            0.0,
            3.0 * w,
            0.1 * w,
        ));
        v
    }
    fn apply(&self, knots: &Knots, m: &mut Model, v: &[f64]) {
        m.terms.partition = shape_on(knots, Variable::Power, v).map(|shape| Partition {
            shape,
            w_c: v.get(KNOTS - 1).copied().unwrap_or(0.0),
        });
    }
    fn clear(&self, m: &mut Model, _reference: &Model) {
        m.terms.partition = None;
    }
    fn magnitude(&self, m: &Model) -> (f64, &'static str) {
        (
            shape_change(m.terms.partition.as_ref().map(|p| &p.shape), false).0,
            "share of the plate's friction heat moved to the disk over the power range",
        )
    }
    fn basis(&self, m: &Model) -> Basis {
        shape_change(m.terms.partition.as_ref().map(|p| &p.shape), false).1
    }
    fn shape_points(&self, m: &Model) -> Vec<(f64, f64)> {
        points_of(m.terms.partition.map(|p| p.shape))
    }
}

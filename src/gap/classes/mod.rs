//! How each effect class is fitted (issue 17 item 1; issue 43): one [`EffectClass`] impl per
//! family of classes, registered in [`ClassId::fit`]. An impl says which channels the class is
//! fitted on, its free parameters with bounds (the increments of a bounded [`Shape`] in the
//! class's variable, or the few physical parameters of a library member), how a parameter vector
//! sets a [`Model`] and how it is removed again, and what its magnitude is measured over
//! ([`Basis`]). Bounds are physical limits, not plausible ranges: a fitted magnitude outside the
//! documented range is reported, not rejected (item 8).
//!
//! Where the classes enter the paper's model is in [`super::class`] (equations (4)–(6), (9),
//! (10), (11), (16), (18a)); the families:
//! [`friction`] (μ multipliers, static friction, the facing-surface temperature, the facings),
//! [`spring`], [`kiss_point`], [`actuator`], [`thermal`] (the paths of (16)), [`engine`],
//! and [`sensors`] (torque, thermocouples, position).
//!
//! Adding a class: a variant in [`super::class`]'s table, one impl (a new file, or a struct in
//! its family's file), one line in [`ClassId::fit`]; the trait's required methods are what the
//! compiler asks for.

pub mod actuator;
pub mod basis;
pub mod engine;
pub mod friction;
pub mod kiss_point;
pub mod sensors;
pub mod spring;
pub mod thermal;

pub use basis::{magnitude_ci95, Basis, RELATIVE};

use super::candidates::{Channel, Model};
use super::class::{ClassId, Variable};
use super::lsq::ParamSpec;
use super::shape::{Shape, KNOTS};
use crate::model::effects::{EffectId, Subsystem};
use std::collections::BTreeMap;
use std::ops::Range;

/// Knot positions of the class variables over the training records (variables that do not
/// vary have none: their classes cannot be checked).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Knots(pub BTreeMap<Variable, [f64; KNOTS]>);

/// What a class needs from the records.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Needs {
    Torque,
    Temperatures,
    Requests,
    Engine,
}

/// Which representation of a class is fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Form {
    /// The flexible term (diagnosis).
    Flexible,
    /// The library member's parametric form (the calibration the TCU and the plant read).
    Member,
}

/// What the records can show of a class: `has` answers which channels they log.
pub type Has<'a> = &'a dyn Fn(Needs) -> bool;

/// How an effect class is fitted, reported and taken out again. The required methods are a
/// class's own; the provided ones are the rules most classes share, overridden where a class
/// differs (each override says why).
pub trait EffectClass: Sync {
    /// The class this impl fits.
    fn id(&self) -> ClassId;

    /// The channel group the class is fitted on (the actuator's backlash and transfer are seen
    /// through the torque: they are fitted on the torque characteristic's channels, while their
    /// [`ClassId::subsystem`] is the actuator).
    fn group(&self) -> Subsystem;

    /// Free parameters of the flexible form.
    fn params(&self, base: &Model) -> Vec<ParamSpec>;

    /// Sets the class's term in `m` from the parameter vector `v` (as [`EffectClass::params`]
    /// lists them).
    fn apply(&self, knots: &Knots, m: &mut Model, v: &[f64]);

    /// Clears the class's own term (the member is removed by [`EffectClass::remove`]); a class
    /// that moves a model parameter gets `reference`'s value back.
    fn clear(&self, m: &mut Model, reference: &Model);

    /// Magnitude of the fitted term with its unit, by its [`EffectClass::basis`].
    fn magnitude(&self, m: &Model) -> (f64, &'static str);

    /// What [`EffectClass::magnitude`] is measured over.
    fn basis(&self, m: &Model) -> Basis;

    /// The channels the class is fitted on.
    fn channels(&self) -> Vec<Channel> {
        group_channels(self.group())
    }

    /// The variable of a shape class's term.
    fn shape_variable(&self) -> Option<Variable> {
        None
    }

    /// Where the shape's increments sit in the flexible parameter vector.
    fn increments(&self) -> Option<Range<usize>> {
        self.shape_variable().map(|_| 0..KNOTS - 1)
    }

    /// True for a class fitted as a flexible term, whose calibration for the TCU and the plant
    /// is its library member refitted in the member's own form.
    fn is_flexible(&self) -> bool {
        self.shape_variable().is_some()
    }

    /// Why the class cannot be fitted on these records, or `None` when it can.
    fn not_checkable(&self, _knots: &Knots, has: Has) -> Option<String> {
        (self.group() == Subsystem::TorqueCharacteristic && !has(Needs::Torque)).then(no_torque)
    }

    /// Starting points besides the parameters' `init`, for least squares with several basins.
    fn other_starts(&self) -> Vec<Vec<f64>> {
        Vec::new()
    }

    /// The term two classes must not both write (they cannot be selected together).
    fn writes(&self) -> Option<&'static str> {
        None
    }

    /// The fitted shape (variable value, term value) at the knots.
    fn shape_points(&self, _m: &Model) -> Vec<(f64, f64)> {
        Vec::new()
    }

    /// The library member's parameters that best represent the fitted flexible term.
    fn member_from_shape(&self, _m: &Model) -> Option<(EffectId, Vec<f64>)> {
        None
    }

    /// Further groups recalibrated with the class (besides its own).
    fn recalibrates_also(&self) -> &'static [Subsystem] {
        &[]
    }

    /// Further channel groups the class is fitted on (besides [`EffectClass::channels`]).
    fn also_fitted_on(&self) -> &'static [Subsystem] {
        &[]
    }

    /// True when the class is its group's recalibration itself (the others of the group are
    /// then not recalibrated beside it).
    fn replaces_recalibration(&self) -> bool {
        false
    }

    /// Whether the fit can read the base model's cached disk-temperature estimate: a class of
    /// the torque characteristic leaves the disk replay as it is.
    fn reads_cached_disk(&self) -> bool {
        self.group() == Subsystem::TorqueCharacteristic
    }

    /// Rank of the fit's time, for the queue order only (higher first).
    fn fit_cost(&self) -> u8 {
        u8::from(!self.reads_cached_disk())
    }

    /// A sensor's largest reading error over its channel's working range, with that channel's
    /// practical tolerance and unit.
    fn reading_error(&self, _m: &Model) -> Option<(f64, f64, &'static str)> {
        None
    }

    /// True when the class is credited only if its own readings carry a third of its gain.
    fn own_readings_carry_the_gain(&self) -> bool {
        false
    }

    /// Free parameters of a class in a form.
    fn params_in(&self, base: &Model, form: Form) -> Vec<ParamSpec> {
        match (form, self.id().member()) {
            (Form::Member, Some(id)) => member_params(id),
            _ => self.params(base),
        }
    }

    /// Sets the class's term in a form.
    fn apply_in(&self, knots: &Knots, m: &mut Model, v: &[f64], form: Form) {
        match (form, self.id().member()) {
            (Form::Member, Some(id)) => m.set.set_clamped(id, v),
            _ => self.apply(knots, m, v),
        }
    }

    /// Removes the class's term from a model (flexible term and member).
    fn remove(&self, m: &mut Model, reference: &Model) {
        self.clear(m, reference);
        if let Some(id) = self.id().member() {
            m.set.remove(id);
        }
    }
}

impl ClassId {
    /// How the class is fitted: the registry of the impls, one line a class.
    pub fn fit(self) -> &'static dyn EffectClass {
        use friction::{Multiplier, StaticTemperature, SurfaceTemperature};
        use ClassId::*;
        match self {
            FrictionTemperature => &Multiplier(FrictionTemperature, Variable::Temperature, None),
            FrictionStaticTemperature => &StaticTemperature,
            FrictionSlip => &Multiplier(FrictionSlip, Variable::Slip, None),
            FrictionClampLoad => &Multiplier(
                FrictionClampLoad,
                Variable::ClampLoad,
                Some(EffectId::FrictionPressure),
            ),
            FrictionSlidingAcceleration => &Multiplier(
                FrictionSlidingAcceleration,
                Variable::SlidingAcceleration,
                None,
            ),
            FrictionEnergy => &Multiplier(FrictionEnergy, Variable::FrictionEnergy, None),
            FrictionSurfaceTemperature => &SurfaceTemperature,
            FacingTemperature => &MemberOnly(FacingTemperature, Subsystem::TorqueCharacteristic),
            SpringTemperature => &spring::SpringTemperature,
            KissPointTemperature => {
                &kiss_point::KissPoint(KissPointTemperature, Variable::Temperature, None)
            }
            KissPointEnergy => &kiss_point::KissPoint(
                KissPointEnergy,
                Variable::FrictionEnergy,
                Some(EffectId::KissPointWear),
            ),
            ActuatorDeadTime => &actuator::DeadTime,
            ActuatorLag => &actuator::Lag,
            ActuatorBacklash => &MemberOnly(ActuatorBacklash, Subsystem::TorqueCharacteristic),
            ActuatorTransfer => &actuator::Transfer,
            SupportConduction => &thermal::SupportConduction,
            ConvectionSpeed => &thermal::ConvectionSpeed,
            HeatPartition => &thermal::HeatPartition,
            EngineTorqueError => &engine::TorqueError,
            SensorTorque => &sensors::Torque,
            SensorTorqueSkew => &sensors::TorqueSkew,
            SensorTemperatureLag => &sensors::TemperatureLag,
            SensorTemperature => &sensors::Temperature,
            SensorPosition => &sensors::Position,
        }
    }
}

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

/// A member's first parameter as the magnitude, in its unit.
pub fn member_magnitude(class: ClassId, m: &Model) -> (f64, &'static str) {
    match class.member().and_then(|id| Some((id, m.set.get(id)?))) {
        Some((id, v)) => (v[0], id.params()[0].unit),
        None => (0.0, ""),
    }
}

/// The channels of a subsystem's equation.
pub fn group_channels(s: Subsystem) -> Vec<Channel> {
    match s {
        Subsystem::TorqueCharacteristic => vec![Channel::Torque(0), Channel::Torque(1)],
        Subsystem::Thermal => vec![Channel::Temp(0), Channel::Temp(1), Channel::Temp(2)],
        Subsystem::Actuator => vec![Channel::Pos(0), Channel::Pos(1)],
        Subsystem::Engine => vec![Channel::Engine],
        Subsystem::Driveline => vec![],
    }
}

/// The increments of a shape, each within ±`bound` (solver scale `scale`).
pub fn shape_params(prefix: &str, bound: f64, scale: f64) -> Vec<ParamSpec> {
    (1..KNOTS)
        .map(|j| ParamSpec::new(format!("{prefix}.d{j}"), 0.0, -bound, bound, scale))
        .collect()
}

/// A library member's parameters, from its typical value within its bounds.
pub fn member_params(id: EffectId) -> Vec<ParamSpec> {
    id.params()
        .iter()
        .map(|ps| {
            let scale = (ps.plausible.1 - ps.plausible.0).abs().max(1e-12);
            ParamSpec::new(
                format!("{}.{}", id.as_str(), ps.name),
                ps.typical,
                ps.bounds.0,
                ps.bounds.1,
                scale,
            )
        })
        .collect()
}

/// A gain (1 ± `gain_span`) and an offset (± `offset_bound`, solver scale `offset_scale`).
pub fn gain_offset(
    class: ClassId,
    gain_span: f64,
    offset: &str,
    offset_bound: f64,
    offset_scale: f64,
) -> Vec<ParamSpec> {
    vec![
        ParamSpec::new(
            format!("{class}.gain"),
            1.0,
            1.0 - gain_span,
            1.0 + gain_span,
            gain_span / 15.0,
        ),
        ParamSpec::new(
            format!("{class}.{offset}"),
            0.0,
            -offset_bound,
            offset_bound,
            offset_scale,
        ),
    ]
}

/// The shape in `var` with increments `v` on the records' knots (none where `var` does not vary).
pub fn shape_on(knots: &Knots, var: Variable, v: &[f64]) -> Option<Shape> {
    knots.0.get(&var).map(|z| Shape::from_increments(*z, v))
}

/// Why a torque class cannot be fitted: no torque.
pub fn no_torque() -> String {
    "no slipping clutch torque in the records".into()
}

/// Why a thermal class cannot be fitted: no temperatures.
pub fn no_temperatures() -> String {
    "no plate / central-disk temperatures".into()
}

/// A shape class of the torque characteristic: it needs the torque and its variable varying.
pub fn torque_shape_checkable(var: Variable, knots: &Knots, has: Has) -> Option<String> {
    if !has(Needs::Torque) {
        return Some(no_torque());
    }
    (!knots.0.contains_key(&var)).then(|| format!("the records do not vary the {var}"))
}

/// A shape's change over its knots: the relative change of a multiplier 1 + s, the span of
/// the others; with its [`Basis`] over the knots' range.
pub fn shape_change(shape: Option<&Shape>, multiplier: bool) -> (f64, Basis) {
    let Some(s) = shape else {
        return (0.0, Basis::Parameter);
    };
    let (from, to) = (s.z[0], s.z[KNOTS - 1]);
    if multiplier {
        let m = (1.0 + s.v[KNOTS - 1]) / (1.0 + s.v[0]) - 1.0;
        (m, Basis::Ratio { from, to })
    } else {
        (s.span(), Basis::Change { from, to })
    }
}

/// Least-squares slope of the term through the knots.
pub fn slope(pts: &[(f64, f64)]) -> f64 {
    let n = pts.len() as f64;
    let mz = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let mv = pts.iter().map(|p| p.1).sum::<f64>() / n;
    let sxy: f64 = pts.iter().map(|p| (p.0 - mz) * (p.1 - mv)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mz).powi(2)).sum();
    if sxx > 0.0 {
        sxy / sxx
    } else {
        0.0
    }
}

/// A shape's points, when at least two: what a member's slope is read from.
pub fn points_of(shape: Option<Shape>) -> Vec<(f64, f64)> {
    shape.map(|s| s.points()).unwrap_or_default()
}

/// Increments smaller than this share of the curve's total variation are rounding, not a turn.
const TURN_SHARE: f64 = 0.02;

/// When a fitted shape turns more than once (its increments, leaving out those below
/// [`TURN_SHARE`] of the total variation, change sign twice or more), the sign of its total
/// change: the direction of the monotone curve it is refitted as. `None` for a curve that is
/// monotone or turns once (a peak, or the first segment's jump where the variable's low end
/// is invisible to the torque — a clamp load of zero transmits nothing).
pub fn zigzag_sign(d: &[f64]) -> Option<f64> {
    let tv: f64 = d.iter().map(|x| x.abs()).sum();
    let signs: Vec<bool> = d
        .iter()
        .filter(|x| x.abs() > TURN_SHARE * tv)
        .map(|x| *x > 0.0)
        .collect();
    let turns = signs.windows(2).filter(|w| w[0] != w[1]).count();
    (turns > 1).then(|| {
        if d.iter().sum::<f64>() >= 0.0 {
            1.0
        } else {
            -1.0
        }
    })
}

/// True when two classes write the same term (they cannot be selected together).
pub fn conflicts(a: ClassId, b: ClassId) -> bool {
    a == b || matches!((a.fit().writes(), b.fit().writes()), (Some(x), Some(y)) if x == y)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_class_is_registered_under_its_own_id() {
        for c in ClassId::ALL {
            assert_eq!(c.fit().id(), *c);
        }
    }

    /// Fits seen on the cases of `scripts/gap-cases`: a friction change over the clamp load
    /// whose first segment jumps (one turn: kept), a static-friction change fitted as a zigzag
    /// in the temperature (four turns: refitted rising), kiss-point wear whose small early
    /// increments are rounding beside the step at the end (two turns among the rest).
    #[test]
    fn zigzag_sign_counts_only_the_turns_that_matter() {
        let clamp = [0.0382, -0.0055, -0.0052, -0.0080, -0.0073, -0.0064];
        assert_eq!(zigzag_sign(&clamp), None);
        let static_friction = [0.0089, 0.0134, -0.0357, 0.0547, -0.0150, 0.0461];
        assert_eq!(zigzag_sign(&static_friction), Some(1.0));
        let wear = [-9e-5, 3.0e-4, -8.1e-4, 3.8e-3, -9.6e-3, 0.0899];
        assert_eq!(zigzag_sign(&wear), Some(1.0));
        assert_eq!(zigzag_sign(&[-0.1, -0.2, 0.001, -0.3]), None);
        assert_eq!(zigzag_sign(&[0.0; 6]), None);
    }

    #[test]
    fn every_shape_class_has_its_increments_in_its_parameters() {
        let base = Model::nominal(crate::model::params::Params::default());
        for c in ClassId::ALL {
            if let Some(r) = c.fit().increments() {
                let p = c.fit().params(&base);
                assert!(r.end <= p.len(), "{c:?}");
                for s in &p[r] {
                    assert!(s.name.contains(".d"), "{c:?}: {}", s.name);
                }
            }
        }
    }

    /// Only the two kiss-point classes share a term.
    #[test]
    fn the_kiss_point_classes_conflict_and_no_others() {
        use ClassId::*;
        assert!(conflicts(KissPointTemperature, KissPointEnergy));
        assert!(conflicts(SpringTemperature, SpringTemperature));
        assert!(!conflicts(FrictionTemperature, FrictionSlip));
    }
}

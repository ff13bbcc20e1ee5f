//! The trait every effect class implements ([`EffectClass`]): its required methods are what a
//! class must say, its provided ones the rules most classes share.

use super::basis::Basis;
use super::common::{group_channels, member_params, no_torque, torque_shape_checkable};
use super::knots::{Form, Has, Knots, Needs};
use crate::gap::fit::lsq::ParamSpec;
use crate::gap::model::candidate::{Channel, Model};
use crate::gap::model::class::{ClassId, Variable};
use crate::gap::model::shape::KNOTS;
use crate::model::effects::{EffectId, Subsystem};
use std::ops::Range;

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

    /// Why the class cannot be fitted on these records, or `None` when it can: a class of the
    /// torque characteristic needs the torque, and a shape class of it its variable varying.
    fn not_checkable(&self, knots: &Knots, has: Has) -> Option<String> {
        if self.group() != Subsystem::TorqueCharacteristic {
            return None;
        }
        match self.shape_variable() {
            Some(var) => torque_shape_checkable(var, knots, has),
            None => (!has(Needs::Torque)).then(no_torque),
        }
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

//! An effect set and a model's thermal class terms as the powertrain's [`Hooks`]
//! ([`crate::model::powertrain`]), for the replays of the diagnosis on measured data (no
//! backlash state: the replays see the measured position). [`SetHooks::of`] (in
//! [`crate::gap::model::candidates`]) makes them from a model.

use crate::gap::model::terms;
use crate::model::effects::{self, EffectSet};

/// Whether a replay asks the hooks for their extra heat of (16) at every step, or the caller
/// knows it to be exactly zero in every state (no heat effect, no thermal term): the replay then
/// adds zero without the call — the same numbers, and a step's dependency chain without a call
/// on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Heat {
    Hooks,
    Zero,
}

/// An effect set as powertrain hooks (no backlash state: the replays see the measured position).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SetHooks(pub EffectSet, pub Option<terms::ThermalTerms>);

impl SetHooks {
    /// [`Heat::Zero`] when the hooks' extra heat is zero in every state: no heat effect
    /// ([`effects::HEAT_EFFECTS`]) and no thermal term.
    pub fn heat(&self) -> Heat {
        if self.0.only(&effects::HEAT_EFFECTS).is_nominal() && self.1.is_none() {
            Heat::Zero
        } else {
            Heat::Hooks
        }
    }
}

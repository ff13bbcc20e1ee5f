//! The flat-spring load (10) scaled by g(θ_c); its member a linear law in θ.

use super::factor::TemperatureFactor;
use crate::gap::model::class::ClassId;
use crate::model::effects::EffectId;

pub static SPRING_TEMPERATURE: TemperatureFactor = TemperatureFactor {
    id: ClassId::SpringTemperature,
    member: EffectId::SpringStiffnessTemp,
    term: |t| t.spring,
    set: |t, s| t.spring = s,
};

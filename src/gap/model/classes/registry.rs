//! The registry of the class impls ([`ClassId::fit`], one line a class) and what follows from
//! it for a pair of classes ([`conflicts`]).

use super::effect_class::EffectClass;
use super::member_only::MemberOnly;
use super::{actuator, engine, friction, kiss_point, sensors, speed_sensor, spring, thermal};
use crate::gap::model::class::{ClassId, Variable};
use crate::model::effects::{EffectId, Subsystem};

impl ClassId {
    /// How the class is fitted: the registry of the impls, one line a class.
    pub fn fit(self) -> &'static dyn EffectClass {
        use friction::{Multiplier, SurfaceTemperature};
        use ClassId::*;
        match self {
            FrictionTemperature => &Multiplier(FrictionTemperature, Variable::Temperature, None),
            FrictionStaticTemperature => &friction::STATIC_TEMPERATURE,
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
            SpringTemperature => &spring::SPRING_TEMPERATURE,
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
            SensorSpeed => &speed_sensor::Speed,
        }
    }
}

/// True when two classes write the same term (they cannot be selected together).
pub fn conflicts(a: ClassId, b: ClassId) -> bool {
    a == b || matches!((a.fit().writes(), b.fit().writes()), (Some(x), Some(y)) if x == y)
}

//! Effect classes of the diagnosis (issue 17): an unmodelled effect is named by **where it enters
//! the model** — the term it modifies — and **the variable that term depends on**, not by one
//! parametric formula. Each class is fitted with a flexible, shape-constrained representation
//! (a bounded piecewise-linear curve in its variable, see [`crate::gap::model::shape`]) jointly with the
//! recalibration, so that a reality written in another functional form is still recognised.
//!
//! Where the classes enter the paper's model:
//! - friction coefficient of (4)–(6): a multiplier m(z) on μ with z = clutch temperature θ_c,
//!   slip |ω_fc|, clamp load F of (10), sliding acceleration, or friction energy; a multiplier
//!   on the static coefficient μ_s alone; a hidden fast surface (flash) temperature driving μ_d;
//!   facing temperatures following their plates (11);
//! - flat-spring load (10): a multiplier g(θ_c);
//! - kiss point (9): a shift s(θ_c) beyond the quadratic of (9), or s(E) with the friction energy
//!   (wear, bedding-in);
//! - actuator: dead time and lag between request and measured position, backlash and a
//!   gain/offset between the measured position and the bearing (the sensor reads the actuator);
//! - thermal paths of (16): conduction to supports, convection depending on speed, heat
//!   partition between plate and disk;
//! - engine torque (18a): a relative map error;
//! - sensors: gain/offset of the torque channel, lag and gain/offset of the thermocouples,
//!   gain/offset of the position sensor, time skew of the torque channel, gain and time skew
//!   of the speed channels (the slip of (4)–(6) and the friction power of (16)).
//!
//! The library's named effects (`model::effects`) are members or special cases of these classes
//! ([`ClassId::member`]), so calibration files and `ddct plant --effects` keep working.
//!
//! This module is vocabulary only: names, subsystems, variables, documentation.

use crate::model::effects::{EffectId, Subsystem};
use std::fmt;

/// The variable a class's term depends on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Variable {
    /// Clutch-disk temperature θ_c (°C).
    Temperature,
    /// Slip speed |ω_fc| (rad/s).
    Slip,
    /// Clamp load F of (10) (N).
    ClampLoad,
    /// Sliding acceleration d|ω_fc|/dt (rad/s²).
    SlidingAcceleration,
    /// Friction energy dissipated by the clutch since the start of the record (MJ).
    FrictionEnergy,
    /// Time (a state with its own dynamics, a delay or a lag) (s).
    Time,
    /// Bearing / actuator position (mm).
    Position,
    /// Temperature difference to the housing (K).
    TemperatureDifference,
    /// Flywheel speed ω_f (rad/s): the plates and the central disk turn with it.
    Speed,
    /// Friction power of the clutch T·ω_fc (W).
    Power,
    /// Engine torque (N·m).
    EngineTorque,
    /// The measured value of a channel itself (sensor gain/offset).
    Measurement,
}

impl Variable {
    pub fn as_str(self) -> &'static str {
        match self {
            Variable::Temperature => "temperature",
            Variable::Slip => "slip",
            Variable::ClampLoad => "clamp_load",
            Variable::SlidingAcceleration => "sliding_acceleration",
            Variable::FrictionEnergy => "friction_energy",
            Variable::Time => "time",
            Variable::Position => "position",
            Variable::TemperatureDifference => "temperature_difference",
            Variable::Speed => "speed",
            Variable::Power => "power",
            Variable::EngineTorque => "engine_torque",
            Variable::Measurement => "measurement",
        }
    }
}

impl fmt::Display for Variable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Whether a class belongs to the physics or to the instrumentation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// The transmission behaves differently from the model.
    Physics,
    /// The transmission is as modelled; a sensor reports it wrongly.
    Sensor,
}

macro_rules! classes {
    ($( $id:ident = $name:literal, $sub:ident, $var:ident, $kind:ident, $member:expr, $doc:literal; )*) => {
        /// An effect class: the term of the model it modifies and the variable it depends on.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
        #[serde(rename_all = "snake_case")]
        pub enum ClassId { $( #[doc = $doc] $id, )* }

        impl ClassId {
            /// Every class, in declaration order.
            pub const ALL: &'static [ClassId] = &[ $( ClassId::$id, )* ];

            /// Identifier (snake case) used in reports, JSON and TOML.
            pub fn as_str(self) -> &'static str {
                match self { $( ClassId::$id => $name, )* }
            }

            /// The subsystem whose equation the class modifies (sensors: the subsystem whose
            /// channel they corrupt).
            pub fn subsystem(self) -> Subsystem {
                match self { $( ClassId::$id => Subsystem::$sub, )* }
            }

            /// The variable the class's term depends on.
            pub fn variable(self) -> Variable {
                match self { $( ClassId::$id => Variable::$var, )* }
            }

            /// Physics or instrumentation.
            pub fn kind(self) -> Kind {
                match self { $( ClassId::$id => Kind::$kind, )* }
            }

            /// The library effect that is a member (special case) of this class, if any.
            pub fn member(self) -> Option<EffectId> {
                match self { $( ClassId::$id => $member, )* }
            }

            /// One-line description.
            pub fn doc(self) -> &'static str {
                match self { $( ClassId::$id => $doc, )* }
            }
        }
    };
}

classes! {
    FrictionTemperature = "friction_temperature", TorqueCharacteristic, Temperature, Physics, None,
        "friction coefficient μ scaled by m(θ_c) beyond the model's μ_d(θ) of (5)";
    FrictionStaticTemperature = "friction_static_temperature", TorqueCharacteristic, Temperature,
        Physics, Some(EffectId::MuStaticTemp),
        "static (low sliding speed) friction coefficient μ_s of (4) scaled by m(θ_c)";
    FrictionSlip = "friction_slip", TorqueCharacteristic, Slip, Physics, None,
        "friction coefficient μ scaled by m(|ω_fc|) beyond the tanh law of (4)";
    FrictionClampLoad = "friction_clamp_load", TorqueCharacteristic, ClampLoad, Physics,
        Some(EffectId::FrictionPressure),
        "friction coefficient μ scaled by m(F): the torque is not proportional to the clamp load";
    FrictionSlidingAcceleration = "friction_sliding_acceleration", TorqueCharacteristic,
        SlidingAcceleration, Physics, Some(EffectId::SlidingAccelerationFriction),
        "friction coefficient μ scaled by m(d|ω_fc|/dt)";
    FrictionEnergy = "friction_energy", TorqueCharacteristic, FrictionEnergy, Physics, None,
        "friction coefficient μ scaled by m(E): fade or bedding-in with dissipated energy";
    FrictionSurfaceTemperature = "friction_surface_temperature", TorqueCharacteristic, Power,
        Physics, Some(EffectId::SurfaceTemperatureFriction),
        "μ_d driven by a hidden fast facing-surface (flash) temperature heated by the friction power";
    FacingTemperature = "facing_temperature", TorqueCharacteristic, Temperature, Physics,
        Some(EffectId::FacingAsymmetry),
        "facing temperatures of (11) following their adjacent plates instead of θ_c";
    SpringTemperature = "spring_temperature", TorqueCharacteristic, Temperature, Physics,
        Some(EffectId::SpringStiffnessTemp),
        "flat-spring load (10) scaled by g(θ_c)";
    KissPointTemperature = "kiss_point_temperature", TorqueCharacteristic, Temperature, Physics,
        None, "kiss point (9) shifted by s(θ_c) beyond its quadratic in θ";
    KissPointEnergy = "kiss_point_energy", TorqueCharacteristic, FrictionEnergy, Physics,
        Some(EffectId::KissPointWear),
        "kiss point (9) and x_to,max shifted by s(E) with the dissipated friction energy (wear)";
    ActuatorDeadTime = "actuator_dead_time", Actuator, Time, Physics,
        Some(EffectId::ActuatorDeadTime),
        "position request acting a dead time later (seen in position vs request)";
    ActuatorLag = "actuator_lag", Actuator, Time, Physics, None,
        "actuator lag τ far from the model's (seen in position vs request)";
    ActuatorBacklash = "actuator_backlash", Actuator, Position, Physics,
        Some(EffectId::ActuatorBacklash),
        "play (hysteresis) between the measured actuator position and the bearing";
    ActuatorTransfer = "actuator_transfer", Actuator, Position, Physics, None,
        "gain and offset between the measured actuator position and the bearing";
    SupportConduction = "support_conduction", Thermal, TemperatureDifference, Physics,
        Some(EffectId::SupportConduction),
        "heat flow from the disks to supports at the housing temperature, q(θ − θ_h)";
    ConvectionSpeed = "convection_speed", Thermal, Speed, Physics, None,
        "convection of (16) changing with the flywheel speed";
    HeatPartition = "heat_partition", Thermal, Power, Physics, None,
        "share of the friction heat entering the plates vs the disks differing from (16)";
    EngineTorqueError = "engine_torque_error", Engine, EngineTorque, Physics,
        Some(EffectId::EngineTorqueError),
        "engine torque differing from the ECU's map by a relative error";
    SensorTorque = "sensor_torque", TorqueCharacteristic, Measurement, Sensor, None,
        "torque sensor gain and offset";
    SensorTorqueSkew = "sensor_torque_skew", TorqueCharacteristic, Time, Sensor, None,
        "torque channel shifted in time against the others";
    SensorTemperatureLag = "sensor_temperature_lag", Thermal, Time, Sensor, None,
        "thermocouples lagging the surface they measure (first order)";
    SensorTemperature = "sensor_temperature", Thermal, Measurement, Sensor, None,
        "thermocouple gain and offset";
    SensorPosition = "sensor_position", Actuator, Measurement, Sensor, None,
        "position sensor gain and offset (seen in position vs request and in the torque)";
    SensorSpeed = "sensor_speed", Thermal, Measurement, Sensor, None,
        "speed sensors' gain and time skew: the slip and friction power the model is given";
}

impl ClassId {
    /// Parses an identifier (as printed by [`ClassId::as_str`]).
    pub fn parse(s: &str) -> Option<ClassId> {
        ClassId::ALL.iter().copied().find(|c| c.as_str() == s)
    }

    /// The class a library effect belongs to.
    pub fn of_effect(id: EffectId) -> Option<ClassId> {
        ClassId::ALL
            .iter()
            .copied()
            .find(|c| c.member() == Some(id))
    }
}

impl fmt::Display for ClassId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_are_unique() {
        for c in ClassId::ALL {
            assert_eq!(ClassId::parse(c.as_str()), Some(*c));
        }
        let mut names: Vec<_> = ClassId::ALL.iter().map(|c| c.as_str()).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), ClassId::ALL.len());
    }

    #[test]
    fn every_library_effect_is_a_member_of_one_class() {
        for id in EffectId::ALL {
            let owners: Vec<_> = ClassId::ALL
                .iter()
                .filter(|c| c.member() == Some(id))
                .collect();
            assert_eq!(owners.len(), 1, "{id}");
            assert_eq!(ClassId::of_effect(id).map(|c| c.member()), Some(Some(id)));
        }
    }
}

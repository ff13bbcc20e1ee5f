//! A candidate of the diagnosis: a [`Model`] is the nominal physics with a parameter set, an
//! effect set from the effect library (`model::effects`, the same functions the plant uses as
//! truth) and the fitted class terms; a [`Channel`] is an output the diagnosis compares with a
//! measurement, with its subsystem (the torque of (4)–(10), the temperatures of (16), the
//! bearing positions, the engine report of (18a)) and its practical tolerance.

use crate::gap::model::terms::Terms;
use crate::model::effects::{EffectSet, Subsystem};
use crate::model::params::Params;
use crate::records::dataset::Col;

/// A candidate model: parameters and effects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Model {
    pub p: Params,
    pub set: EffectSet,
    /// Fitted class terms (flexible forms, sensors).
    pub terms: Terms,
}

impl Model {
    pub fn nominal(p: Params) -> Self {
        Model {
            p,
            set: EffectSet::nominal(),
            terms: Terms::default(),
        }
    }
}

/// An output the diagnosis compares with a measurement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
pub enum Channel {
    /// Clutch torque of clutch 0/1 (equation error, slipping samples).
    Torque(usize),
    /// Temperatures: 0 = θ_pp1, 1 = θ_pp2, 2 = θ_cd (thermal replay).
    Temp(usize),
    /// Bearing position of clutch 0/1 (actuator replay from the requests).
    Pos(usize),
    /// ENG_Status torque report against the flywheel balance (18a), as means over windows of
    /// [`ENGINE_WINDOW`] samples (integral form: no differentiation of the speed).
    Engine,
}

impl Channel {
    pub const ALL: [Channel; 8] = [
        Channel::Torque(0),
        Channel::Torque(1),
        Channel::Temp(0),
        Channel::Temp(1),
        Channel::Temp(2),
        Channel::Pos(0),
        Channel::Pos(1),
        Channel::Engine,
    ];

    /// Output name (the CSV column).
    pub fn name(self) -> &'static str {
        match self {
            Channel::Torque(0) => "T_c1_Nm",
            Channel::Torque(_) => "T_c2_Nm",
            Channel::Temp(0) => "th_pp1_C",
            Channel::Temp(1) => "th_pp2_C",
            Channel::Temp(_) => "th_cd_C",
            Channel::Pos(0) => "x_to1_mm",
            Channel::Pos(_) => "x_to2_mm",
            Channel::Engine => "T_e_Nm",
        }
    }

    /// The record's column this channel compares with.
    pub fn column(self) -> Col {
        match self {
            Channel::Torque(0) => Col::T1,
            Channel::Torque(_) => Col::T2,
            Channel::Temp(0) => Col::Pp1,
            Channel::Temp(1) => Col::Pp2,
            Channel::Temp(_) => Col::Cd,
            Channel::Pos(0) => Col::X1,
            Channel::Pos(_) => Col::X2,
            Channel::Engine => Col::Te,
        }
    }

    /// The subsystem whose equation this channel's residual checks.
    pub fn subsystem(self) -> Subsystem {
        match self {
            Channel::Torque(_) => Subsystem::TorqueCharacteristic,
            Channel::Temp(_) => Subsystem::Thermal,
            Channel::Pos(_) => Subsystem::Actuator,
            Channel::Engine => Subsystem::Engine,
        }
    }

    /// Practical tolerance of a channel (RMS, the channel's unit): a model that is right but
    /// implemented differently (another integrator, step or input convention) may leave this much
    /// above the noise floor without the gap being significant. Stated in physical terms a bench
    /// engineer would accept as agreement: 0.25 N·m of clutch torque, 0.3 °C of a thermocouple,
    /// 0.005 mm of bearing position (the actuator replay from the requests is exact but for the
    /// sensor noise: 0.2–0.3 % excess on nominal blind records; 0.02 mm, ten times a 2 µm sensor's
    /// noise, hid position-sensor errors of 4σ), 1 N·m of engine torque.
    pub fn tolerance(self) -> f64 {
        match self {
            Channel::Torque(_) => 0.25,
            Channel::Temp(_) => 0.3,
            Channel::Pos(_) => 0.005,
            Channel::Engine => 1.0,
        }
    }

    pub fn index(self) -> usize {
        Channel::ALL.iter().position(|c| *c == self).unwrap_or(0)
    }
}

/// Samples per window of the engine balance (0.1 s at 10 ms).
pub const ENGINE_WINDOW: usize = 10;

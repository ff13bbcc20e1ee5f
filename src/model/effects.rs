//! Reality effects: physics the nominal model of the paper does not have (DESIGN.md §5), as one
//! library used three ways — by the plant as truth, by the gap diagnosis as fit candidates, and by
//! the TCU as an optional calibrated extension of its model.
//!
//! Every effect has an identifier ([`EffectId`], used in configs, reports and JSON), a subsystem
//! ([`Subsystem`]), an equation, and a small parameter vector (at most [`MAX_PARAMS`] numbers) whose
//! names, units, plausible ranges and hard bounds are in its [`EffectSpec`]. A parameter vector
//! equal to [`ParamSpec::nominal`] makes the effect vanish. Evaluation is pure, cheap and
//! allocation-free; an [`EffectSet`] is a `Copy` array of optional parameter vectors.
//!
//! The effects and where they act (each only through its physics):
//!
//! | id | subsystem | equation |
//! |---|---|---|
//! | `spring_stiffness_temp` | torque_characteristic | F(u, θ) = F₍₁₀₎(u)·(1 + k_s·max(θ_c − θ_a, 0)) |
//! | `friction_pressure` | torque_characteristic | μ·(p/p_ref)^(a−1), p = F/(π(R2²−R1²)), p_ref = 0.24 MPa |
//! | `mu_static_temp` | torque_characteristic | μ_s(θ) = μ_s·(1 + k_μ·(θ_fp − θ_a)) in (4) |
//! | `facing_asymmetry` | torque_characteristic | (11) with θ_fp1 = θ_c + w(θ_pp − θ_c), θ_fp2 = θ_c + w(θ_cd − θ_c) |
//! | `support_conduction` | thermal | (16c)–(16e) += −α_s(θ − θ_h) for θ_c1, θ_c2, θ_cd |
//! | `actuator_backlash` | actuator | play of width b between measured actuator and bearing |
//! | `actuator_dead_time` | actuator | x_ref,act(t) = x_ref(t − τ_d) |
//! | `engine_torque_error` | engine | T_e,real = (1 + e)·T_e,map; ENG_Status reports T_e,map |
//! | `kiss_point_wear` | torque_characteristic | x_ISP(θ, E) = x_ISP(θ) + k_w·E (the whole (7)–(8) shifts) |
//! | `surface_temperature_friction` (outside the library) | torque_characteristic | μ_d at θ_s, θ̇_s = h·P − (θ_s − θ_c)/τ_s |
//! | `sliding_acceleration_friction` (outside the library) | torque_characteristic | μ·(1 + g·tanh(−a_s/a_ref)), a_s = R_m·d\|ω_fc\|/dt |
//!
//! The last two are not candidates of the diagnosis ([`EffectSpec::in_library`] is false): the
//! blind test uses them as truths "outside the library".
//!
//! Equation numbers "(11)" are the paper's. Units as in `clutch`: mm, rad/s, °C, N, N·m, J, s.

use super::clutch::{self, Inversion};
use super::params::ClutchParams;
use super::thermal::{Thermal3State, Thermal5State, ThermalInputs};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt;

/// Largest number of parameters of one effect.
pub const MAX_PARAMS: usize = 2;

/// Reference pressure of `friction_pressure` (Pa): the pressure at which the paper's friction
/// curve (Fig. 2) was measured.
pub(crate) const FRICTION_P_REF_PA: f64 = 0.24e6;

/// Longest dead time the plant's delay line holds (s); the upper bound of `delay_s`.
pub(crate) const MAX_DEAD_TIME_S: f64 = 0.1;

/// Effect identifiers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EffectId {
    SpringStiffnessTemp,
    FrictionPressure,
    MuStaticTemp,
    FacingAsymmetry,
    SupportConduction,
    ActuatorBacklash,
    ActuatorDeadTime,
    EngineTorqueError,
    KissPointWear,
    SurfaceTemperatureFriction,
    SlidingAccelerationFriction,
}

/// Subsystem identifiers (the equations the diagnosis computes residuals of).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Subsystem {
    TorqueCharacteristic,
    Thermal,
    Driveline,
    Actuator,
    Engine,
}

impl Subsystem {
    pub const ALL: [Subsystem; 5] = [
        Subsystem::TorqueCharacteristic,
        Subsystem::Thermal,
        Subsystem::Driveline,
        Subsystem::Actuator,
        Subsystem::Engine,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            Subsystem::TorqueCharacteristic => "torque_characteristic",
            Subsystem::Thermal => "thermal",
            Subsystem::Driveline => "driveline",
            Subsystem::Actuator => "actuator",
            Subsystem::Engine => "engine",
        }
    }

    pub fn parse(s: &str) -> Option<Subsystem> {
        Subsystem::ALL.into_iter().find(|x| x.as_str() == s)
    }
}

impl fmt::Display for Subsystem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// One parameter of an effect.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamSpec {
    /// Key in `[effects.<id>]`.
    pub name: &'static str,
    /// Unit (text).
    pub unit: &'static str,
    /// The value at which the effect vanishes (a fit starts here).
    pub nominal: f64,
    /// Value used when a config omits the key (a mid-range magnitude).
    pub typical: f64,
    /// Documented plausible range (literature magnitudes, DESIGN.md §5).
    pub plausible: (f64, f64),
    /// Draws for "effect present" keep |value − nominal| at least this large (0: any).
    pub min_effect: f64,
    /// Hard limits: configs outside are rejected; fits are bounded by them.
    pub bounds: (f64, f64),
    /// One line of documentation.
    pub doc: &'static str,
}

impl ParamSpec {
    /// Maps a uniform number `u` in [0, 1) to a plausible value with |v − nominal| ≥
    /// `min_effect` (for blind tests drawing a hidden truth).
    pub fn draw(&self, u: f64) -> f64 {
        let u = if u.is_finite() {
            u.clamp(0.0, 1.0)
        } else {
            0.5
        };
        let (lo, hi) = self.plausible;
        if self.min_effect <= 0.0 {
            return lo + u * (hi - lo);
        }
        // Two intervals [lo, nominal − m] and [nominal + m, hi] (the empty ones dropped).
        let a = ((self.nominal - self.min_effect) - lo).max(0.0);
        let b = (hi - (self.nominal + self.min_effect)).max(0.0);
        if a + b <= 0.0 {
            return lo + u * (hi - lo);
        }
        let s = u * (a + b);
        if s < a {
            lo + s
        } else {
            self.nominal + self.min_effect + (s - a)
        }
    }
}

/// Documentation and metadata of an effect.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EffectSpec {
    pub id: EffectId,
    pub subsystem: Subsystem,
    /// False for the plant-only effects the diagnosis does not know ("outside the library").
    pub in_library: bool,
    /// The equation (plain text, paper equation numbers).
    pub equation: &'static str,
    /// What it models and where it acts.
    pub description: &'static str,
    pub params: &'static [ParamSpec],
}

const SPECS: [EffectSpec; EffectId::COUNT] = [
    EffectSpec {
        id: EffectId::SpringStiffnessTemp,
        subsystem: Subsystem::TorqueCharacteristic,
        in_library: true,
        equation: "F_fc(u, θ_c) = F_(10)(u) · (1 + k_s · max(θ_c − θ_a, 0))",
        description: "Temperature-dependent flat-spring stiffness (the paper's own suspicion above \
                      140 °C): the spring load (10) softens above room temperature; the kiss point \
                      (9) and the friction are unchanged, so the torque changes only when the \
                      clutch is warmer than θ_a.",
        params: &[ParamSpec {
            name: "k_per_c",
            unit: "1/°C",
            nominal: 0.0,
            typical: -2.4e-4,
            plausible: (-3.6e-4, -1.3e-4),
            min_effect: 0.0,
            bounds: (-2.0e-3, 1.0e-3),
            doc: "relative stiffness change per °C above θ_a (−3 … −8 % at 250 °C)",
        }],
    },
    EffectSpec {
        id: EffectId::FrictionPressure,
        subsystem: Subsystem::TorqueCharacteristic,
        in_library: true,
        equation: "μ_eff = μ · (p / p_ref)^(a − 1), p = F_fc / (π (R2² − R1²)), p_ref = 0.24 MPa",
        description: "Pressure-dependent friction coefficient: the torque becomes 2 R_μ F (F/F_ref)^(a−1), \
                      i.e. it grows as F^a instead of F. Equal to the nominal torque at the \
                      reference pressure of the paper's friction curve.",
        params: &[ParamSpec {
            name: "exponent",
            unit: "-",
            nominal: 1.0,
            typical: 0.88,
            plausible: (0.8, 1.25),
            min_effect: 0.08,
            bounds: (0.5, 1.5),
            doc: "pressure exponent a of the friction law",
        }],
    },
    EffectSpec {
        id: EffectId::MuStaticTemp,
        subsystem: Subsystem::TorqueCharacteristic,
        in_library: true,
        equation: "μ_s(θ_fp) = μ_s · (1 + k_μ (θ_fp − θ_a)) in (4)",
        description: "Temperature dependence of the static (low sliding speed) friction coefficient; \
                      it changes the torque at low slip and the static capacity, not the torque at \
                      high slip where μ → μ_d(θ).",
        params: &[ParamSpec {
            name: "k_per_c",
            unit: "1/°C",
            nominal: 0.0,
            typical: -5.0e-4,
            plausible: (-8.0e-4, -2.0e-4),
            min_effect: 0.0,
            bounds: (-3.0e-3, 3.0e-3),
            doc: "relative change of μ_s per °C (−4.5 … −18 % at 250 °C)",
        }],
    },
    EffectSpec {
        id: EffectId::FacingAsymmetry,
        subsystem: Subsystem::TorqueCharacteristic,
        in_library: true,
        equation: "T = [R_μ(ω, θ_fp1) + R_μ(ω, θ_fp2)] F(u(x, θ_c)) (11), θ_fp1 = θ_c + w (θ_pp − θ_c), \
                   θ_fp2 = θ_c + w (θ_cd − θ_c)",
        description: "Asymmetric facing temperatures: the facing on the pressure-plate side follows \
                      the plate, the one on the central-disk side follows the central disk, with \
                      coupling weight w; the flat spring stays at θ_c.",
        params: &[ParamSpec {
            name: "weight",
            unit: "-",
            nominal: 0.0,
            typical: 0.7,
            plausible: (0.4, 1.0),
            min_effect: 0.0,
            bounds: (0.0, 1.0),
            doc: "coupling of each facing's temperature to its adjacent plate",
        }],
    },
    EffectSpec {
        id: EffectId::SupportConduction,
        subsystem: Subsystem::Thermal,
        in_library: true,
        equation: "θ̇_ci += −α_s (θ_ci − θ_h), θ̇_cd += −α_s (θ_cd − θ_h) in (16c)–(16e)",
        description: "Conduction from the clutch disks (through their hubs) and the central disk \
                      (through its bearing) to supports at the housing temperature: an extra heat \
                      sink active whether the clutch is open or not. Changes temperatures only; \
                      the torque at a given temperature is unchanged.",
        params: &[ParamSpec {
            name: "alpha_per_s",
            unit: "1/s",
            nominal: 0.0,
            typical: 2.0e-3,
            plausible: (1.0e-3, 4.0e-3),
            min_effect: 0.0,
            bounds: (0.0, 0.05),
            doc: "conduction rate to the supports",
        }],
    },
    EffectSpec {
        id: EffectId::ActuatorBacklash,
        subsystem: Subsystem::Actuator,
        in_library: true,
        equation: "x_to = play_b(x_act): x_to ← x_act − b/2 when x_act > x_to + b/2, \
                   x_to ← x_act + b/2 when x_act < x_to − b/2, else held",
        description: "Backlash (direction-dependent play) between the measured actuator position \
                      and the throwout bearing: the sensor reads the actuator, the clutch sees the \
                      bearing, which lags by b/2 in the direction of motion.",
        params: &[ParamSpec {
            name: "width_mm",
            unit: "mm",
            nominal: 0.0,
            typical: 0.15,
            plausible: (0.1, 0.2),
            min_effect: 0.0,
            bounds: (0.0, 1.0),
            doc: "total play b",
        }],
    },
    EffectSpec {
        id: EffectId::ActuatorDeadTime,
        subsystem: Subsystem::Actuator,
        in_library: true,
        equation: "x_ref,act(t) = x_ref(t − τ_d) before the first-order rate-limited actuator",
        description: "Dead time of the actuator electronics and hydraulics: the position command \
                      acts τ_d later; the position sensor measures the (delayed) actuator. Shifts \
                      the torque in time, not its steady value.",
        params: &[ParamSpec {
            name: "delay_s",
            unit: "s",
            nominal: 0.0,
            typical: 0.02,
            plausible: (0.010, 0.030),
            min_effect: 0.0,
            bounds: (0.0, MAX_DEAD_TIME_S),
            doc: "dead time τ_d (the plant resolves it to its 1 ms step)",
        }],
    },
    EffectSpec {
        id: EffectId::EngineTorqueError,
        subsystem: Subsystem::Engine,
        in_library: true,
        equation: "T_e,real = (1 + e) T_e,map; ENG_Status.EngTorqueAct = T_e,map",
        description: "Engine torque map error: the torque the engine delivers differs from what \
                      the ECU's map says (and reports) by a relative error e, also when it honours \
                      a torque request.",
        params: &[ParamSpec {
            name: "rel_error",
            unit: "-",
            nominal: 0.0,
            typical: 0.07,
            plausible: (-0.10, 0.10),
            min_effect: 0.05,
            bounds: (-0.5, 0.5),
            doc: "relative error e (±5 … ±10 %)",
        }],
    },
    EffectSpec {
        id: EffectId::KissPointWear,
        subsystem: Subsystem::TorqueCharacteristic,
        in_library: true,
        equation: "x_ISP(θ, E) = x_ISP(θ) + k_w E, x_to,max + k_w E (E: friction energy of this \
                   clutch since the start, MJ)",
        description: "Kiss-point drift with dissipated energy (facing wear and bedding-in): the \
                      whole characteristic (7)–(8) moves to larger bearing positions by k_w per MJ \
                      dissipated. Long-term wear is ~1e-3 mm/MJ; the plausible range is that of a \
                      new clutch bedding in, the only drift a bench run can see.",
        params: &[ParamSpec {
            name: "mm_per_mj",
            unit: "mm/MJ",
            nominal: 0.0,
            typical: 0.15,
            plausible: (0.05, 0.3),
            min_effect: 0.0,
            bounds: (-1.0, 2.0),
            doc: "kiss-point shift per MJ of friction energy",
        }],
    },
    EffectSpec {
        id: EffectId::SurfaceTemperatureFriction,
        subsystem: Subsystem::TorqueCharacteristic,
        in_library: false,
        equation: "μ_d evaluated at θ_s; θ̇_s = h P_fric − (θ_s − θ_c)/τ_s (per clutch)",
        description: "Friction driven by a fast facing-surface (flash) temperature that heats with \
                      the friction power and relaxes quickly to θ_c. Outside the diagnosis library.",
        params: &[
            ParamSpec {
                name: "heat_k_per_j",
                unit: "K/J",
                nominal: 0.0,
                typical: 8.0e-3,
                plausible: (5.0e-3, 1.5e-2),
                min_effect: 0.0,
                bounds: (0.0, 0.1),
                doc: "surface heating per joule of friction work h",
            },
            ParamSpec {
                name: "tau_s",
                unit: "s",
                nominal: 0.5,
                typical: 0.5,
                plausible: (0.3, 1.0),
                min_effect: 0.0,
                bounds: (0.01, 10.0),
                doc: "relaxation time of the surface temperature τ_s",
            },
        ],
    },
    EffectSpec {
        id: EffectId::SlidingAccelerationFriction,
        subsystem: Subsystem::TorqueCharacteristic,
        in_library: false,
        equation: "μ_eff = μ (1 + g tanh(−a_s / a_ref)), a_s = R_m d|ω_fc|/dt, R_m = (R1 + R2)/2",
        description: "Friction depending on the sliding acceleration (the paper's Fig. 2 was taken \
                      at a fixed sliding acceleration): higher friction while the slip decelerates. \
                      Outside the diagnosis library.",
        params: &[
            ParamSpec {
                name: "gain",
                unit: "-",
                nominal: 0.0,
                typical: 0.12,
                plausible: (0.08, 0.2),
                min_effect: 0.0,
                bounds: (-0.5, 0.5),
                doc: "relative friction change at large deceleration g",
            },
            ParamSpec {
                name: "a_ref_mps2",
                unit: "m/s²",
                nominal: 1.0,
                typical: 1.0,
                plausible: (0.5, 2.0),
                min_effect: 0.0,
                bounds: (0.01, 100.0),
                doc: "sliding acceleration scale a_ref",
            },
        ],
    },
];

impl EffectId {
    pub const COUNT: usize = 11;
    /// Every effect the plant knows, in declaration order.
    pub const ALL: [EffectId; EffectId::COUNT] = [
        EffectId::SpringStiffnessTemp,
        EffectId::FrictionPressure,
        EffectId::MuStaticTemp,
        EffectId::FacingAsymmetry,
        EffectId::SupportConduction,
        EffectId::ActuatorBacklash,
        EffectId::ActuatorDeadTime,
        EffectId::EngineTorqueError,
        EffectId::KissPointWear,
        EffectId::SurfaceTemperatureFriction,
        EffectId::SlidingAccelerationFriction,
    ];
    /// The diagnosis library (candidates of `ddct gap`).
    pub const LIBRARY: [EffectId; 9] = [
        EffectId::SpringStiffnessTemp,
        EffectId::FrictionPressure,
        EffectId::MuStaticTemp,
        EffectId::FacingAsymmetry,
        EffectId::SupportConduction,
        EffectId::ActuatorBacklash,
        EffectId::ActuatorDeadTime,
        EffectId::EngineTorqueError,
        EffectId::KissPointWear,
    ];
    /// Plant-only effects ("outside the library").
    pub const OUTSIDE_LIBRARY: [EffectId; 2] = [
        EffectId::SurfaceTemperatureFriction,
        EffectId::SlidingAccelerationFriction,
    ];

    fn index(self) -> usize {
        self as usize
    }

    pub fn spec(self) -> &'static EffectSpec {
        &SPECS[self.index()]
    }

    pub fn subsystem(self) -> Subsystem {
        self.spec().subsystem
    }

    pub fn in_library(self) -> bool {
        self.spec().in_library
    }

    pub fn params(self) -> &'static [ParamSpec] {
        self.spec().params
    }

    /// The identifier as written in configs, reports and JSON.
    pub fn as_str(self) -> &'static str {
        match self {
            EffectId::SpringStiffnessTemp => "spring_stiffness_temp",
            EffectId::FrictionPressure => "friction_pressure",
            EffectId::MuStaticTemp => "mu_static_temp",
            EffectId::FacingAsymmetry => "facing_asymmetry",
            EffectId::SupportConduction => "support_conduction",
            EffectId::ActuatorBacklash => "actuator_backlash",
            EffectId::ActuatorDeadTime => "actuator_dead_time",
            EffectId::EngineTorqueError => "engine_torque_error",
            EffectId::KissPointWear => "kiss_point_wear",
            EffectId::SurfaceTemperatureFriction => "surface_temperature_friction",
            EffectId::SlidingAccelerationFriction => "sliding_acceleration_friction",
        }
    }

    pub fn parse(s: &str) -> Option<EffectId> {
        EffectId::ALL.into_iter().find(|e| e.as_str() == s)
    }

    /// Nominal parameter vector (the effect vanishes).
    pub fn nominal(self) -> [f64; MAX_PARAMS] {
        let mut v = [0.0; MAX_PARAMS];
        for (i, s) in self.params().iter().enumerate() {
            v[i] = s.nominal;
        }
        v
    }

    /// Typical parameter vector (a mid-range magnitude).
    pub fn typical(self) -> [f64; MAX_PARAMS] {
        let mut v = [0.0; MAX_PARAMS];
        for (i, s) in self.params().iter().enumerate() {
            v[i] = s.typical;
        }
        v
    }
}

impl fmt::Display for EffectId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Errors of building or loading an effect set; `key` is `effects.<id>[.<param>]`.
#[derive(Debug, thiserror::Error)]
pub enum EffectError {
    #[error("unknown effect `{key}` (known: {known})")]
    UnknownEffect { key: String, known: String },
    #[error("unknown parameter `{key}` (parameters: {known})")]
    UnknownParam { key: String, known: String },
    #[error("parameter `{key}` must be a number")]
    NotANumber { key: String },
    /// A parameter outside [`ParamSpec::bounds`] (or not finite).
    #[error(transparent)]
    OutOfBounds(#[from] crate::ranges::RangeError),
    #[error("effect `{id}` takes {expected} parameter(s), got {found}")]
    WrongLength {
        id: &'static str,
        expected: usize,
        found: usize,
    },
    #[error("`{key}` must be a table of parameters")]
    NotATable { key: String },
    #[error("effects file is not valid TOML")]
    Syntax {
        #[source]
        source: Box<toml::de::Error>,
    },
    #[error("cannot read effects file {path}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
}

/// A set of active effects with their parameters. `Copy`, allocation-free; the default is the
/// nominal model (no effect).
///
/// An inactive effect's parameters are zeros, not undefined: the optimiser computes an effect's
/// term from its parameter before it selects on whether the effect is active, and an `Option`'s
/// undefined payload once held a subnormal number there, a floating-point microcode assist on
/// every sample of the disk replay (the 30-minute diagnosis took 1.34× as long).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EffectSet {
    params: [[f64; MAX_PARAMS]; EffectId::COUNT],
    active: [bool; EffectId::COUNT],
}

impl EffectSet {
    /// No effect.
    pub fn nominal() -> Self {
        Self::default()
    }

    /// One effect with the given parameters (checked against the bounds).
    pub fn single(id: EffectId, params: &[f64]) -> Result<Self, EffectError> {
        let mut s = Self::default();
        s.set(id, params)?;
        Ok(s)
    }

    /// Activates `id` with `params` (length and bounds checked).
    pub fn set(&mut self, id: EffectId, params: &[f64]) -> Result<(), EffectError> {
        let specs = id.params();
        if params.len() != specs.len() {
            return Err(EffectError::WrongLength {
                id: id.as_str(),
                expected: specs.len(),
                found: params.len(),
            });
        }
        let mut v = [0.0; MAX_PARAMS];
        for (i, (spec, &x)) in specs.iter().zip(params).enumerate() {
            let (min, max) = spec.bounds;
            crate::ranges::check(&format!("effects.{id}"), spec.name, &x, min, max)?;
            v[i] = x;
        }
        self.put(id, v);
        Ok(())
    }

    /// Activates `id` with `params` clamped into the bounds (non-finite values become nominal);
    /// for optimisers that may step outside. Extra values are ignored, missing ones are nominal.
    pub fn set_clamped(&mut self, id: EffectId, params: &[f64]) {
        let mut v = id.nominal();
        for (i, spec) in id.params().iter().enumerate() {
            if let Some(&x) = params.get(i) {
                v[i] = if x.is_finite() {
                    x.clamp(spec.bounds.0, spec.bounds.1)
                } else {
                    spec.nominal
                };
            }
        }
        self.put(id, v);
    }

    fn put(&mut self, id: EffectId, v: [f64; MAX_PARAMS]) {
        self.params[id.index()] = v;
        self.active[id.index()] = true;
    }

    /// Deactivates `id`.
    pub fn remove(&mut self, id: EffectId) {
        self.params[id.index()] = [0.0; MAX_PARAMS];
        self.active[id.index()] = false;
    }

    /// The parameters of `id` if active (length = number of parameters of `id`).
    pub fn get(&self, id: EffectId) -> Option<&[f64]> {
        self.is_active(id)
            .then(|| &self.params[id.index()][..id.params().len()])
    }

    /// First parameter of `id` if active.
    #[inline]
    fn p0(&self, id: EffectId) -> Option<f64> {
        let v = &self.params[id.index()];
        self.is_active(id).then_some(v[0])
    }

    #[inline]
    fn p01(&self, id: EffectId) -> Option<(f64, f64)> {
        let v = &self.params[id.index()];
        self.is_active(id).then_some((v[0], v[1]))
    }

    #[inline]
    pub fn is_active(&self, id: EffectId) -> bool {
        self.active[id.index()]
    }

    /// The set with only the effects of `ids` kept (the others off).
    pub fn only(&self, ids: &[EffectId]) -> EffectSet {
        let mut s = EffectSet::default();
        for &id in ids {
            s.params[id.index()] = self.params[id.index()];
            s.active[id.index()] = self.active[id.index()];
        }
        s
    }

    /// True when no effect is active.
    pub fn is_nominal(&self) -> bool {
        !self.active.contains(&true)
    }

    /// Active effects with their parameters.
    pub fn iter(&self) -> impl Iterator<Item = (EffectId, &[f64])> + '_ {
        EffectId::ALL
            .into_iter()
            .filter_map(move |id| self.get(id).map(|p| (id, p)))
    }

    /// True when some active effect acts on the torque characteristic (13).
    pub fn touches_torque(&self) -> bool {
        self.iter()
            .any(|(id, _)| id.subsystem() == Subsystem::TorqueCharacteristic)
    }

    /// Parses an effects file: tables `[effects.<id>]` with `param = value` (a missing parameter
    /// takes its typical value; `enabled = false` switches the effect off).
    pub fn from_toml_str(text: &str) -> Result<Self, EffectError> {
        let doc: toml::Table =
            text.parse()
                .map_err(|source: toml::de::Error| EffectError::Syntax {
                    source: Box::new(source),
                })?;
        for key in doc.keys() {
            if key != "effects" {
                return Err(EffectError::UnknownEffect {
                    key: key.clone(),
                    known: "a file of [effects.<id>] tables".into(),
                });
            }
        }
        match doc.get("effects") {
            None => Ok(Self::default()),
            Some(toml::Value::Table(t)) => Self::from_table(t),
            Some(_) => Err(EffectError::NotATable {
                key: "effects".into(),
            }),
        }
    }

    /// Reads an effects file.
    pub fn load(path: impl AsRef<std::path::Path>) -> Result<Self, EffectError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| EffectError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_toml_str(&text)
    }

    /// Parses the content of an `effects` table: `<id> = { param = value, ... }`.
    pub fn from_table(t: &toml::Table) -> Result<Self, EffectError> {
        let mut set = Self::default();
        for (name, v) in t {
            let id = EffectId::parse(name).ok_or_else(|| EffectError::UnknownEffect {
                key: format!("effects.{name}"),
                known: EffectId::ALL.map(|e| e.as_str()).join(", "),
            })?;
            let toml::Value::Table(pt) = v else {
                return Err(EffectError::NotATable {
                    key: format!("effects.{name}"),
                });
            };
            let specs = id.params();
            let mut values = id.typical();
            let mut enabled = true;
            for (k, val) in pt {
                if k == "enabled" {
                    match val {
                        toml::Value::Boolean(b) => enabled = *b,
                        _ => {
                            return Err(EffectError::NotANumber {
                                key: format!("effects.{name}.enabled (a boolean)"),
                            })
                        }
                    }
                    continue;
                }
                let Some(i) = specs.iter().position(|s| s.name == k) else {
                    return Err(EffectError::UnknownParam {
                        key: format!("effects.{name}.{k}"),
                        known: specs.iter().map(|s| s.name).collect::<Vec<_>>().join(", "),
                    });
                };
                values[i] = match val {
                    toml::Value::Float(f) => *f,
                    toml::Value::Integer(n) => *n as f64,
                    _ => {
                        return Err(EffectError::NotANumber {
                            key: format!("effects.{name}.{k}"),
                        })
                    }
                };
            }
            if enabled {
                set.set(id, &values[..specs.len()])?;
            }
        }
        Ok(set)
    }

    /// The `[effects.<id>]` TOML form (empty string for the nominal set).
    pub fn to_toml_string(&self) -> String {
        let mut out = String::new();
        for (id, p) in self.iter() {
            out.push_str(&format!("[effects.{id}]\n"));
            for (spec, v) in id.params().iter().zip(p) {
                out.push_str(&format!("{} = {:e}    # {}\n", spec.name, v, spec.unit));
            }
        }
        out
    }

    /// `{id: {param: value}}` (the JSON form).
    pub fn to_map(&self) -> BTreeMap<String, BTreeMap<String, f64>> {
        self.iter()
            .map(|(id, p)| {
                (
                    id.as_str().to_string(),
                    id.params()
                        .iter()
                        .zip(p)
                        .map(|(s, v)| (s.name.to_string(), *v))
                        .collect(),
                )
            })
            .collect()
    }
}

impl Serialize for EffectSet {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.to_map().serialize(s)
    }
}

impl<'de> Deserialize<'de> for EffectSet {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let m: BTreeMap<String, BTreeMap<String, f64>> = BTreeMap::deserialize(d)?;
        let mut t = toml::Table::new();
        for (id, params) in m {
            let mut pt = toml::Table::new();
            for (k, v) in params {
                pt.insert(k, toml::Value::Float(v));
            }
            t.insert(id, toml::Value::Table(pt));
        }
        EffectSet::from_table(&t).map_err(serde::de::Error::custom)
    }
}

// ------------------------------------------------------------------------ torque characteristic

/// Everything the torque characteristic with effects may depend on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueContext {
    /// Throwout-bearing position (mm) — the bearing, after any actuator backlash.
    pub x_to_mm: f64,
    /// Slip ω_f − ω_c (rad/s).
    pub slip_radps: f64,
    /// Clutch disk temperature θ_c (°C).
    pub theta_c: f64,
    /// Pressure-plate temperature of this clutch (°C) (`facing_asymmetry`).
    pub theta_pp: f64,
    /// Central-disk temperature (°C) (`facing_asymmetry`).
    pub theta_cd: f64,
    /// Friction energy of this clutch since the start (J) (`kiss_point_wear`).
    pub e_fric_j: f64,
    /// Facing surface temperature (°C) (`surface_temperature_friction`); θ_c when unknown.
    pub theta_surface_c: f64,
    /// Slip acceleration dω_fc/dt (rad/s²) (`sliding_acceleration_friction`); 0 when unknown.
    pub slip_accel_radps2: f64,
    /// Q(ω) of (6) at this slip for the clutch's γ, R1 and R2 ([`clutch::slip_shape`]) when the
    /// caller has it (a replay evaluating one record's samples under many models); `None`:
    /// computed here.
    pub slip_shape: Option<f64>,
}

impl TorqueContext {
    /// A context with uniform temperature θ_c, no energy, no surface heating, no acceleration.
    pub fn new(x_to_mm: f64, slip_radps: f64, theta_c: f64) -> Self {
        Self {
            x_to_mm,
            slip_radps,
            theta_c,
            theta_pp: theta_c,
            theta_cd: theta_c,
            e_fric_j: 0.0,
            theta_surface_c: theta_c,
            slip_accel_radps2: 0.0,
            slip_shape: None,
        }
    }
}

/// Kiss-point shift of `kiss_point_wear` (mm) after `e_fric_j` joules.
#[inline]
pub(crate) fn wear_shift_mm(set: &EffectSet, e_fric_j: f64) -> f64 {
    match set.p0(EffectId::KissPointWear) {
        Some(k) if e_fric_j.is_finite() => k * e_fric_j * 1e-6,
        _ => 0.0,
    }
}

/// Stiffness factor of `spring_stiffness_temp` at θ_c (≥ 0.05).
#[inline]
pub(crate) fn spring_factor(p: &ClutchParams, set: &EffectSet, theta_c: f64) -> f64 {
    match set.p0(EffectId::SpringStiffnessTemp) {
        Some(k) => (1.0 + k * (theta_c - p.theta_a_c).max(0.0)).max(0.05),
        None => 1.0,
    }
}

/// Flat-spring load with effects (N): (7)–(10), wear shift, stiffness factor.
#[inline]
pub fn normal_force(p: &ClutchParams, set: &EffectSet, c: &TorqueContext) -> f64 {
    let x = c.x_to_mm - wear_shift_mm(set, c.e_fric_j);
    let u = clutch::u_fs(p, x, c.theta_c);
    if u <= 0.0 {
        return 0.0;
    }
    clutch::spring_force(p, u) * spring_factor(p, set, c.theta_c)
}

/// Pressure factor (p/p_ref)^(a−1) of `friction_pressure` at clamp force `f` (N).
#[inline]
pub(crate) fn pressure_factor(p: &ClutchParams, set: &EffectSet, f: f64) -> f64 {
    match set.p0(EffectId::FrictionPressure) {
        Some(a) if a != 1.0 && f > 0.0 => {
            let area = std::f64::consts::PI * (p.r2_m * p.r2_m - p.r1_m * p.r1_m);
            (f / (FRICTION_P_REF_PA * area)).powf(a - 1.0)
        }
        _ => 1.0,
    }
}

/// Sliding-acceleration factor of `sliding_acceleration_friction`.
#[inline]
pub(crate) fn acceleration_factor(p: &ClutchParams, set: &EffectSet, c: &TorqueContext) -> f64 {
    match set.p01(EffectId::SlidingAccelerationFriction) {
        Some((g, a_ref)) if c.slip_accel_radps2.is_finite() => {
            let r_m = 0.5 * (p.r1_m + p.r2_m);
            let a_s = r_m * c.slip_radps.signum() * c.slip_accel_radps2;
            1.0 + g * (-a_s / a_ref).tanh()
        }
        _ => 1.0,
    }
}

/// The two facing temperatures (plate side, central-disk side) that the friction sees.
#[inline]
pub(crate) fn facing_temperatures(set: &EffectSet, c: &TorqueContext) -> (f64, f64) {
    let (mut t1, mut t2) = (c.theta_c, c.theta_c);
    if let Some(w) = set.p0(EffectId::FacingAsymmetry) {
        t1 += w * (c.theta_pp - c.theta_c);
        t2 += w * (c.theta_cd - c.theta_c);
    }
    if set.is_active(EffectId::SurfaceTemperatureFriction) && c.theta_surface_c.is_finite() {
        let d = c.theta_surface_c - c.theta_c;
        t1 += d;
        t2 += d;
    }
    (t1, t2)
}

/// Equivalent friction radius (6) of one facing at its temperature, with `mu_static_temp`, the
/// slip's Q(ω) ([`clutch::slip_shape`]) given: μ_s(θ) moves only the static part, so Q does not
/// depend on the set.
#[inline]
fn r_mu_shaped(p: &ClutchParams, set: &EffectSet, q: f64, theta_fp: f64) -> f64 {
    match set.p0(EffectId::MuStaticTemp) {
        Some(k) => {
            let mut c = *p;
            c.mu_s = (p.mu_s * (1.0 + k * (theta_fp - p.theta_a_c))).max(0.01 * p.mu_s);
            clutch::r_mu_shaped(&c, q, theta_fp)
        }
        None => clutch::r_mu_shaped(p, q, theta_fp),
    }
}

/// R_μ of both facings: Q(ω) once (`q` when given), and one facing doubled when both are at one
/// temperature.
#[inline]
fn r_mu_both(
    p: &ClutchParams,
    set: &EffectSet,
    slip_radps: f64,
    q: Option<f64>,
    t1: f64,
    t2: f64,
) -> f64 {
    let q = q.unwrap_or_else(|| clutch::slip_shape(p, slip_radps));
    let a = r_mu_shaped(p, set, q, t1);
    if t1 == t2 {
        a + a
    } else {
        a + r_mu_shaped(p, set, q, t2)
    }
}

/// Torque magnitude at the context's position and `slip` (N·m, ≥ 0); `q`: Q(ω) of that slip
/// when known.
#[inline]
fn magnitude(
    p: &ClutchParams,
    set: &EffectSet,
    c: &TorqueContext,
    slip: f64,
    q: Option<f64>,
) -> f64 {
    let f = normal_force(p, set, c);
    if f <= 0.0 {
        return 0.0;
    }
    let (t1, t2) = facing_temperatures(set, c);
    let r = r_mu_both(p, set, slip, q, t1, t2);
    let accel = if slip == 0.0 {
        1.0
    } else {
        acceleration_factor(p, set, c)
    };
    r * f * pressure_factor(p, set, f) * accel
}

/// Torque (13) of a slipping clutch with every torque-characteristic effect of `set` (N·m, with
/// the sign of the slip). Equals `clutch::torque` for the nominal set.
#[inline]
pub fn torque(p: &ClutchParams, set: &EffectSet, c: &TorqueContext) -> f64 {
    if set.is_nominal() {
        return clutch::torque_shaped(p, c.x_to_mm, c.slip_radps, c.theta_c, c.slip_shape);
    }
    if c.slip_radps == 0.0 {
        return 0.0;
    }
    c.slip_radps.signum() * magnitude(p, set, c, c.slip_radps, c.slip_shape)
}

/// Static capacity 2·R_μ(0, θ)·F with effects (N·m).
#[inline]
pub fn capacity(p: &ClutchParams, set: &EffectSet, c: &TorqueContext) -> f64 {
    if set.is_nominal() {
        return clutch::capacity(p, c.x_to_mm, c.theta_c);
    }
    magnitude(p, set, c, 0.0, None)
}

/// The effects [`beta`] reads (whether a clutch is engaged).
pub const ENGAGEMENT_EFFECTS: [EffectId; 1] = [EffectId::KissPointWear];

/// The effects [`thermal5_extra`] reads (extra heat flows). A replay of the thermal model (16)
/// under a set depends on the set only through these and [`ENGAGEMENT_EFFECTS`] (the others act
/// on the torque, the actuator, the engine or the driveline).
pub const HEAT_EFFECTS: [EffectId; 1] = [EffectId::SupportConduction];

/// β of the thermal model with effects: 1 when the flat spring is compressed.
#[inline]
pub fn beta(p: &ClutchParams, set: &EffectSet, c: &TorqueContext) -> f64 {
    let x = c.x_to_mm - wear_shift_mm(set, c.e_fric_j);
    if clutch::u_fs(p, x, c.theta_c) > 0.0 {
        1.0
    } else {
        0.0
    }
}

/// Inverse of [`torque`] in the bearing position: the x_to (mm) whose torque magnitude at the
/// context's slip, temperatures and energy equals |`torque_nm`| (the context's `x_to_mm` is
/// ignored). Zero torque gives the (shifted) kiss point; a torque beyond reach gives the (shifted)
/// x_to,max with `saturated`. Exact to 1e-7 mm; at most 100 bracketed iterations.
pub fn invert(
    p: &ClutchParams,
    set: &EffectSet,
    torque_nm: f64,
    c: &TorqueContext,
) -> Result<Inversion, clutch::ClutchError> {
    if set.is_nominal() || !set.touches_torque() {
        return clutch::invert(p, torque_nm, c.slip_radps, c.theta_c);
    }
    for (name, value) in [
        ("torque_nm", torque_nm),
        ("slip_radps", c.slip_radps),
        ("theta_c", c.theta_c),
    ] {
        if !value.is_finite() {
            return Err(clutch::ClutchError::NonFinite { name, value });
        }
    }
    let target = torque_nm.abs();
    let shift = wear_shift_mm(set, c.e_fric_j);
    let lo0 = clutch::x_isp(p, c.theta_c) + shift;
    let hi0 = p.x_to_max_mm + shift;
    if target == 0.0 {
        return Ok(Inversion {
            x_to_mm: lo0,
            saturated: false,
        });
    }
    let slip = c.slip_radps;
    let g = |x: f64| {
        let mut cc = *c;
        cc.x_to_mm = x;
        magnitude(p, set, &cc, slip, c.slip_shape) - target
    };
    let (a, b) = (lo0, hi0);
    let (fa, fb) = (g(a), g(b));
    if fb < 0.0 {
        return Ok(Inversion {
            x_to_mm: hi0,
            saturated: true,
        });
    }
    if fb == 0.0 {
        return Ok(Inversion {
            x_to_mm: hi0,
            saturated: false,
        });
    }
    Ok(Inversion {
        x_to_mm: illinois_root(g, (a, fa), (b, fb)),
        saturated: false,
    })
}

/// The root of `g` in the bracket `a` < `b` (`g(a)` < 0 < `g(b)`, given): Illinois regula falsi
/// with a bisection guard (a midpoint step after each, so the bracket shrinks geometrically even
/// when regula falsi stalls), to a bracket of 1e-9 or 100 iterations; an exact zero ends it.
fn illinois_root(
    g: impl Fn(f64) -> f64,
    (mut a, mut fa): (f64, f64),
    (mut b, mut fb): (f64, f64),
) -> f64 {
    let mut side = 0i8;
    for _ in 0..100 {
        if (b - a) <= 1e-9 {
            break;
        }
        let mut x = (a * fb - b * fa) / (fb - fa);
        if !(x > a && x < b) {
            x = 0.5 * (a + b);
        }
        let fx = g(x);
        if fx == 0.0 {
            return x;
        }
        if fx < 0.0 {
            a = x;
            fa = fx;
            if side == -1 {
                fb *= 0.5;
            }
            side = -1;
        } else {
            b = x;
            fb = fx;
            if side == 1 {
                fa *= 0.5;
            }
            side = 1;
        }
        let m = 0.5 * (a + b);
        let fm = g(m);
        if fm < 0.0 {
            a = m;
            fa = fm;
        } else {
            b = m;
            fb = fm;
        }
    }
    0.5 * (a + b)
}

// ------------------------------------------------------------------------------------- thermal

/// Extra temperature rates (°C/s) of thermal effects added to (16): `support_conduction`.
#[inline]
pub fn thermal5_extra(set: &EffectSet, s: &Thermal5State, u: &ThermalInputs) -> Thermal5State {
    match set.p0(EffectId::SupportConduction) {
        Some(k) if k != 0.0 => Thermal5State {
            pp1: 0.0,
            pp2: 0.0,
            c1: -k * (s.c1 - u.theta_h_c),
            c2: -k * (s.c2 - u.theta_h_c),
            cd: -k * (s.cd - u.theta_h_c),
        },
        _ => Thermal5State::default(),
    }
}

/// Extra temperature rates (°C/s) of thermal effects added to the TCU's 3-state model (17):
/// `support_conduction` on both clutch disks, and on the body with a third of the rate (the body
/// lumps two pressure plates and the central disk, of which only the central disk conducts).
#[inline]
pub fn thermal3_extra(set: &EffectSet, s: &Thermal3State, theta_h_c: f64) -> Thermal3State {
    match set.p0(EffectId::SupportConduction) {
        Some(k) if k != 0.0 => Thermal3State {
            c1: -k * (s.c1 - theta_h_c),
            c2: -k * (s.c2 - theta_h_c),
            body: -k / 3.0 * (s.body - theta_h_c),
        },
        _ => Thermal3State::default(),
    }
}

/// Surface temperature after `dt` seconds of `surface_temperature_friction` (exact solution with
/// the friction power and θ_c held): θ_s → θ_c + h P τ with time constant τ. Returns θ_c when
/// the effect is off.
#[inline]
pub(crate) fn surface_temperature_step(
    set: &EffectSet,
    theta_s: f64,
    theta_c: f64,
    p_fric_w: f64,
    dt: f64,
) -> f64 {
    match set.p01(EffectId::SurfaceTemperatureFriction) {
        Some((h, tau)) => {
            let eq = theta_c + h * p_fric_w.max(0.0) * tau;
            eq + (theta_s - eq) * (-dt / tau).exp()
        }
        None => theta_c,
    }
}

// ------------------------------------------------------------------------------------ actuator

/// Backlash (play operator) of total width `width_mm`: the bearing position after the actuator
/// moved to `x_actuator_mm`, given the bearing position before.
#[inline]
pub fn backlash(width_mm: f64, x_bearing_mm: f64, x_actuator_mm: f64) -> f64 {
    let h = 0.5 * width_mm.max(0.0);
    if x_actuator_mm > x_bearing_mm + h {
        x_actuator_mm - h
    } else if x_actuator_mm < x_bearing_mm - h {
        x_actuator_mm + h
    } else {
        x_bearing_mm
    }
}

/// Bearing position with the set's `actuator_backlash` (identity when off).
#[inline]
pub(crate) fn bearing_position(set: &EffectSet, x_bearing_mm: f64, x_actuator_mm: f64) -> f64 {
    match set.p0(EffectId::ActuatorBacklash) {
        Some(b) if b > 0.0 => backlash(b, x_bearing_mm, x_actuator_mm),
        _ => x_actuator_mm,
    }
}

/// Actuator command that puts the bearing at `x_bearing_target_mm` when the actuator last moved
/// in direction `dir` (+1 closing, −1 opening): the inverse of the play, for a TCU compensating a
/// calibrated backlash.
#[inline]
pub fn backlash_compensation(set: &EffectSet, x_bearing_target_mm: f64, dir: f64) -> f64 {
    match set.p0(EffectId::ActuatorBacklash) {
        Some(b) if b > 0.0 => x_bearing_target_mm + 0.5 * b * dir.signum(),
        _ => x_bearing_target_mm,
    }
}

/// Dead time of `actuator_dead_time` (s; 0 when off).
#[inline]
pub(crate) fn dead_time_s(set: &EffectSet) -> f64 {
    set.p0(EffectId::ActuatorDeadTime).unwrap_or(0.0)
}

/// Capacity of [`DelayLine`] in samples.
pub(crate) const DELAY_CAPACITY: usize = 256;

/// A fixed-capacity delay line of samples at a fixed step: `push` a sample, get the one `n`
/// steps old (the oldest available while fewer have been pushed). No allocation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct DelayLine {
    buf: [f64; DELAY_CAPACITY],
    head: usize,
    filled: usize,
}

impl DelayLine {
    /// A line whose history is `initial` everywhere.
    pub fn new(initial: f64) -> Self {
        Self {
            buf: [initial; DELAY_CAPACITY],
            head: 0,
            filled: DELAY_CAPACITY,
        }
    }

    /// Pushes the newest sample and returns the sample `delay_steps` steps older (0: the newest).
    pub fn push(&mut self, x: f64, delay_steps: usize) -> f64 {
        self.head = (self.head + 1) % DELAY_CAPACITY;
        self.buf[self.head] = x;
        self.filled = (self.filled + 1).min(DELAY_CAPACITY);
        let d = delay_steps.min(DELAY_CAPACITY - 1).min(self.filled - 1);
        self.buf[(self.head + DELAY_CAPACITY - d) % DELAY_CAPACITY]
    }
}

/// Delay in whole steps of `dt_s` for the set's dead time.
#[inline]
pub(crate) fn dead_time_steps(set: &EffectSet, dt_s: f64) -> usize {
    let d = dead_time_s(set);
    if d > 0.0 && dt_s > 0.0 {
        (d / dt_s).round() as usize
    } else {
        0
    }
}

/// A sampled signal delayed by `delay_s` at sample `i` (linear interpolation between samples of
/// step `dt_s`; before the first sample, the first sample). For fitting the dead time on logs.
pub(crate) fn delayed_sample(samples: &[f64], i: usize, dt_s: f64, delay_s: f64) -> f64 {
    if samples.is_empty() {
        return f64::NAN;
    }
    let i = i.min(samples.len() - 1);
    let pos = i as f64 - delay_s / dt_s;
    if pos <= 0.0 {
        return samples[0];
    }
    let k = pos.floor() as usize;
    let frac = pos - k as f64;
    if k + 1 >= samples.len() {
        return samples[samples.len() - 1];
    }
    samples[k] * (1.0 - frac) + samples[k + 1] * frac
}

// -------------------------------------------------------------------------------------- engine

/// Torque the engine really delivers when its map gives `map_nm` (`engine_torque_error`).
#[inline]
pub(crate) fn engine_real_torque(set: &EffectSet, map_nm: f64) -> f64 {
    match set.p0(EffectId::EngineTorqueError) {
        Some(e) => (1.0 + e) * map_nm,
        None => map_nm,
    }
}

/// The ECU's map estimate of a real torque (what ENG_Status reports).
#[inline]
pub fn engine_map_estimate(set: &EffectSet, real_nm: f64) -> f64 {
    match set.p0(EffectId::EngineTorqueError) {
        Some(e) => real_nm / (1.0 + e),
        None => real_nm,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::params::Params;

    fn cp() -> ClutchParams {
        Params::default().clutch
    }

    #[test]
    fn a_removed_effect_leaves_the_set_it_was_added_to() {
        // Equal sets are equal whatever was active before: an inactive effect's parameters are
        // zeros (not left over), and a wear shift computed from them is zero.
        for id in EffectId::ALL {
            let mut s = EffectSet::single(EffectId::KissPointWear, &[2.0]).unwrap();
            let before = s;
            s.set_clamped(id, &[1e-310, 1e-310, 1e-310, 1e-310]);
            s.remove(id);
            if id == EffectId::KissPointWear {
                assert_eq!(s, EffectSet::nominal(), "{id}");
                assert_eq!(wear_shift_mm(&s, 1e6), 0.0);
            } else {
                assert_eq!(s, before, "{id}");
                assert_eq!(wear_shift_mm(&s, 1e6), 2.0);
            }
        }
    }

    #[test]
    fn specs_are_consistent() {
        for (i, id) in EffectId::ALL.iter().enumerate() {
            let s = id.spec();
            assert_eq!(s.id, *id, "SPECS order");
            assert_eq!(id.index(), i);
            assert!(!s.params.is_empty() && s.params.len() <= MAX_PARAMS);
            assert_eq!(EffectId::parse(id.as_str()), Some(*id));
            for p in s.params {
                assert!(
                    p.bounds.0 <= p.nominal && p.nominal <= p.bounds.1,
                    "{id}.{}",
                    p.name
                );
                assert!(p.bounds.0 <= p.plausible.0 && p.plausible.1 <= p.bounds.1);
                assert!(p.plausible.0 <= p.typical && p.typical <= p.plausible.1);
                for k in 0..=20 {
                    let v = p.draw(k as f64 / 20.0);
                    assert!(v >= p.plausible.0 - 1e-15 && v <= p.plausible.1 + 1e-15);
                    assert!((v - p.nominal).abs() >= p.min_effect - 1e-12);
                }
            }
            assert_eq!(s.in_library, EffectId::LIBRARY.contains(id));
        }
        assert_eq!(
            serde_json::to_string(&EffectId::KissPointWear).unwrap(),
            "\"kiss_point_wear\""
        );
        assert_eq!(
            serde_json::to_string(&Subsystem::TorqueCharacteristic).unwrap(),
            "\"torque_characteristic\""
        );
    }

    /// Of every effect at its typical and at its extreme parameters, exactly those of
    /// [`ENGAGEMENT_EFFECTS`] move β and exactly those of [`HEAT_EFFECTS`] the extra heat of (16).
    #[test]
    fn only_the_engagement_and_heat_effects_move_beta_and_heat() {
        let p = cp();
        let s = Thermal5State {
            pp1: 90.0,
            pp2: 70.0,
            c1: 130.0,
            c2: 60.0,
            cd: 100.0,
        };
        let u = ThermalInputs {
            p_fric1_w: 4000.0,
            p_fric2_w: 0.0,
            beta1: 1.0,
            beta2: 0.0,
            theta_h_c: 45.0,
            w_f_radps: 200.0,
        };
        let (mut moves_beta, mut moves_heat) = (Vec::new(), Vec::new());
        for id in EffectId::ALL {
            let specs = id.params();
            for pick in [0, 1, 2] {
                let v: Vec<f64> = specs
                    .iter()
                    .map(|q| [q.typical, q.bounds.0, q.bounds.1][pick])
                    .collect();
                let set = EffectSet::single(id, &v).unwrap();
                if thermal5_extra(&set, &s, &u) != Thermal5State::default()
                    && !moves_heat.contains(&id)
                {
                    moves_heat.push(id);
                }
                for x in [2.0, 4.5, 5.2, 6.0, 8.0] {
                    for th in [20.0, 140.0, 300.0] {
                        let mut c = TorqueContext::new(x, 30.0, th);
                        c.e_fric_j = 5e7;
                        if beta(&p, &set, &c) != beta(&p, &EffectSet::nominal(), &c)
                            && !moves_beta.contains(&id)
                        {
                            moves_beta.push(id);
                        }
                    }
                }
            }
        }
        assert_eq!(moves_beta, ENGAGEMENT_EFFECTS.to_vec());
        assert_eq!(moves_heat, HEAT_EFFECTS.to_vec());
        let typical = EffectId::FrictionPressure.params()[0].typical;
        let other = EffectSet::single(EffectId::FrictionPressure, &[typical]).unwrap();
        assert!(other.only(&ENGAGEMENT_EFFECTS).is_nominal());
        let wear = EffectSet::single(EffectId::KissPointWear, &[0.01]).unwrap();
        assert_eq!(wear.only(&ENGAGEMENT_EFFECTS), wear);
        assert!(wear.only(&HEAT_EFFECTS).is_nominal());
    }

    #[test]
    fn nominal_parameters_make_every_effect_vanish() {
        let p = cp();
        for id in EffectId::ALL {
            let set = EffectSet::single(id, &id.nominal()[..id.params().len()]).unwrap();
            for &(x, w, th) in &[(4.8, 50.0, 25.0), (5.5, 1.0, 140.0), (6.0, -200.0, 240.0)] {
                let mut c = TorqueContext::new(x, w, th);
                c.theta_pp = th + 30.0;
                c.theta_cd = th + 10.0;
                c.e_fric_j = 2e6;
                c.slip_accel_radps2 = -50.0;
                let t = torque(&p, &set, &c);
                let t0 = clutch::torque(&p, x, w, th);
                assert!(
                    (t - t0).abs() < 1e-12 * t0.abs().max(1.0),
                    "{id}: {t} vs {t0}"
                );
            }
            assert_eq!(engine_real_torque(&set, 100.0), 100.0);
            assert_eq!(bearing_position(&set, 3.0, 3.1), 3.1);
        }
    }

    #[test]
    fn toml_round_trip_and_errors() {
        let text = "[effects.spring_stiffness_temp]\nk_per_c = -3e-4\n\
                    [effects.surface_temperature_friction]\nheat_k_per_j = 0.01\n\
                    [effects.actuator_backlash]\nenabled = false\nwidth_mm = 0.2\n";
        let set = EffectSet::from_toml_str(text).unwrap();
        assert_eq!(set.get(EffectId::SpringStiffnessTemp), Some(&[-3e-4][..]));
        // Missing parameter takes its typical value.
        assert_eq!(
            set.get(EffectId::SurfaceTemperatureFriction),
            Some(&[0.01, 0.5][..])
        );
        assert!(!set.is_active(EffectId::ActuatorBacklash));
        let back = EffectSet::from_toml_str(&set.to_toml_string()).unwrap();
        assert_eq!(back, set);
        let json = serde_json::to_string(&set).unwrap();
        assert_eq!(serde_json::from_str::<EffectSet>(&json).unwrap(), set);
        assert!(matches!(
            EffectSet::from_toml_str("[effects.warp_drive]\nx = 1\n"),
            Err(EffectError::UnknownEffect { key, .. }) if key == "effects.warp_drive"
        ));
        assert!(matches!(
            EffectSet::from_toml_str("[effects.actuator_backlash]\nwidth = 1\n"),
            Err(EffectError::UnknownParam { key, .. }) if key == "effects.actuator_backlash.width"
        ));
        assert!(matches!(
            EffectSet::from_toml_str("[effects.actuator_dead_time]\ndelay_s = 3.0\n"),
            Err(EffectError::OutOfBounds(r)) if r.key == "effects.actuator_dead_time.delay_s"
        ));
        assert!(matches!(
            EffectSet::from_toml_str("[effects.actuator_dead_time]\ndelay_s = \"x\"\n"),
            Err(EffectError::NotANumber { .. })
        ));
        assert!(matches!(
            EffectSet::single(EffectId::FrictionPressure, &[1.0, 2.0]),
            Err(EffectError::WrongLength { .. })
        ));
    }

    #[test]
    fn spring_softening_only_above_room_temperature() {
        let p = cp();
        let set = EffectSet::single(EffectId::SpringStiffnessTemp, &[-3e-4]).unwrap();
        let at = |th: f64| torque(&p, &set, &TorqueContext::new(5.5, 50.0, th));
        assert_eq!(at(20.0), clutch::torque(&p, 5.5, 50.0, 20.0));
        assert_eq!(at(25.0), clutch::torque(&p, 5.5, 50.0, 25.0));
        let ratio = at(225.0) / clutch::torque(&p, 5.5, 50.0, 225.0);
        assert!((ratio - (1.0 - 3e-4 * 200.0)).abs() < 1e-12);
    }

    #[test]
    fn pressure_law_scales_as_force_to_the_a() {
        let p = cp();
        let a = 0.85;
        let set = EffectSet::single(EffectId::FrictionPressure, &[a]).unwrap();
        let area = std::f64::consts::PI * (p.r2_m.powi(2) - p.r1_m.powi(2));
        for x in [4.3, 5.0, 6.5] {
            let f = clutch::normal_force(&p, x, 60.0);
            let t = torque(&p, &set, &TorqueContext::new(x, 80.0, 60.0));
            let t0 = clutch::torque(&p, x, 80.0, 60.0);
            let expect = t0 * (f / (0.24e6 * area)).powf(a - 1.0);
            assert!((t - expect).abs() < 1e-10 * expect);
        }
    }

    #[test]
    fn mu_static_acts_at_low_slip_not_high() {
        let p = cp();
        let set = EffectSet::single(EffectId::MuStaticTemp, &[-6e-4]).unwrap();
        let c = |w: f64| TorqueContext::new(5.5, w, 200.0);
        let cap = capacity(&p, &set, &c(0.0));
        let cap0 = clutch::capacity(&p, 5.5, 200.0);
        assert!((cap / cap0 - (1.0 - 6e-4 * 175.0)).abs() < 1e-12);
        // At 1e5 rad/s tanh(γρω)^(1/3) = 1 to machine precision: μ = μ_d, no μ_s left.
        let hi = torque(&p, &set, &c(1e5));
        assert!((hi - clutch::torque(&p, 5.5, 1e5, 200.0)).abs() < 1e-9 * hi);
    }

    #[test]
    fn facing_asymmetry_is_the_two_facing_form() {
        let p = cp();
        let set = EffectSet::single(EffectId::FacingAsymmetry, &[1.0]).unwrap();
        let mut c = TorqueContext::new(5.2, 40.0, 120.0);
        c.theta_pp = 160.0;
        c.theta_cd = 140.0;
        let t = torque(&p, &set, &c);
        let expect = clutch::torque_two_facing(&p, 5.2, 40.0, 160.0, 140.0, 120.0);
        assert!((t - expect).abs() < 1e-12 * expect);
        assert!(t > clutch::torque(&p, 5.2, 40.0, 120.0));
    }

    #[test]
    fn wear_shifts_the_characteristic() {
        let p = cp();
        let set = EffectSet::single(EffectId::KissPointWear, &[0.2]).unwrap();
        let mut c = TorqueContext::new(5.2, 40.0, 80.0);
        c.e_fric_j = 1.5e6; // 0.3 mm
        let t = torque(&p, &set, &c);
        assert!((t - clutch::torque(&p, 4.9, 40.0, 80.0)).abs() < 1e-9);
        c.x_to_mm = clutch::x_isp(&p, 80.0) + 0.29;
        assert_eq!(beta(&p, &set, &c), 0.0);
    }

    #[test]
    fn inverse_with_effects_round_trips() {
        let p = cp();
        let mut set = EffectSet::nominal();
        set.set(EffectId::SpringStiffnessTemp, &[-3e-4]).unwrap();
        set.set(EffectId::FrictionPressure, &[0.9]).unwrap();
        set.set(EffectId::KissPointWear, &[0.1]).unwrap();
        let mut c = TorqueContext::new(0.0, 60.0, 180.0);
        c.e_fric_j = 1e6;
        for x in [4.0, 4.5, 5.0, 6.0, 7.0] {
            c.x_to_mm = x;
            let t = torque(&p, &set, &c);
            if t <= 0.0 {
                continue;
            }
            let inv = invert(&p, &set, t, &c).unwrap();
            assert!(!inv.saturated);
            assert!((inv.x_to_mm - x).abs() < 1e-6, "{x} -> {}", inv.x_to_mm);
        }
        assert!(invert(&p, &set, 1e5, &c).unwrap().saturated);
    }

    #[test]
    fn backlash_play_and_compensation() {
        let b = 0.2;
        let mut bearing = 0.0;
        let mut trace = vec![];
        for x in [0.0, 0.05, 0.1, 0.3, 0.5, 0.45, 0.4, 0.2, 0.25] {
            bearing = backlash(b, bearing, x);
            trace.push(bearing);
        }
        let expect = [0.0, 0.0, 0.0, 0.2, 0.4, 0.4, 0.4, 0.3, 0.3];
        for (a, e) in trace.iter().zip(expect) {
            assert!((a - e).abs() < 1e-12, "{trace:?}");
        }
        let set = EffectSet::single(EffectId::ActuatorBacklash, &[b]).unwrap();
        // Closing: command target + b/2 puts the bearing on target.
        let cmd = backlash_compensation(&set, 3.0, 1.0);
        assert!((backlash(b, 2.0, cmd) - 3.0).abs() < 1e-12);
    }

    #[test]
    fn delay_line_and_delayed_sample() {
        let mut d = DelayLine::new(0.0);
        let out: Vec<f64> = (1..=6).map(|k| d.push(k as f64, 2)).collect();
        assert_eq!(out, vec![0.0, 0.0, 1.0, 2.0, 3.0, 4.0]);
        let s = [0.0, 1.0, 2.0, 3.0];
        assert!((delayed_sample(&s, 3, 0.01, 0.015) - 1.5).abs() < 1e-12);
        assert_eq!(delayed_sample(&s, 0, 0.01, 0.015), 0.0);
    }

    #[test]
    fn surface_temperature_relaxes_exactly() {
        let set = EffectSet::single(EffectId::SurfaceTemperatureFriction, &[0.01, 0.5]).unwrap();
        // Constant 2 kW: equilibrium θ_c + 0.01·2000·0.5 = θ_c + 10.
        let mut th = 50.0;
        for _ in 0..5000 {
            th = surface_temperature_step(&set, th, 50.0, 2000.0, 1e-3);
        }
        assert!((th - 60.0).abs() < 1e-3);
        let after = surface_temperature_step(&set, 60.0, 50.0, 0.0, 0.5);
        assert!((after - (50.0 + 10.0 * (-1f64).exp())).abs() < 1e-12);
    }

    #[test]
    fn support_conduction_is_a_sink_to_the_housing() {
        let set = EffectSet::single(EffectId::SupportConduction, &[2e-3]).unwrap();
        let mut s = Thermal5State::uniform(100.0);
        s.c1 = 150.0;
        let u = ThermalInputs {
            theta_h_c: 40.0,
            ..Default::default()
        };
        let d = thermal5_extra(&set, &s, &u);
        assert_eq!(d.pp1, 0.0);
        assert!((d.c1 + 2e-3 * 110.0).abs() < 1e-15);
        assert!((d.cd + 2e-3 * 60.0).abs() < 1e-15);
        let d3 = thermal3_extra(&set, &Thermal3State::uniform(100.0), 40.0);
        assert!((d3.body + 2e-3 / 3.0 * 60.0).abs() < 1e-15);
    }

    #[test]
    fn engine_error_and_estimate_are_inverse() {
        let set = EffectSet::single(EffectId::EngineTorqueError, &[-0.08]).unwrap();
        let real = engine_real_torque(&set, 150.0);
        assert!((real - 138.0).abs() < 1e-12);
        assert!((engine_map_estimate(&set, real) - 150.0).abs() < 1e-12);
    }

    #[test]
    fn sliding_acceleration_raises_friction_while_decelerating() {
        let p = cp();
        let set = EffectSet::single(EffectId::SlidingAccelerationFriction, &[0.1, 1.0]).unwrap();
        let mut c = TorqueContext::new(5.5, 30.0, 60.0);
        let t0 = clutch::torque(&p, 5.5, 30.0, 60.0);
        c.slip_accel_radps2 = -200.0; // a_s = −19 m/s²: tanh(19) ≈ 1
        assert!((torque(&p, &set, &c) / t0 - 1.1).abs() < 1e-9);
        c.slip_accel_radps2 = 0.0;
        assert_eq!(torque(&p, &set, &c), t0);
    }
}

//! Pure physics of the dry dual-clutch driveline (paper Sects. 3–5): friction and equivalent
//! radius (4)–(6), flat spring (7)–(10), clutch torque (11)/(13) and its inverse ([`clutch`]),
//! (13) over many points at once ([`clutch_batch`]), thermal models (16)/(17) ([`thermal`]),
//! driveline (18)–(20) with stick/slip ([`driveline`]), engine and actuators, a fixed-step RK4
//! integrator ([`integrator`]) and the assembled powertrain ([`powertrain`]). All parameters come
//! from one TOML file ([`params`]). No I/O, no clock.

pub mod actuator;
pub mod clutch;
pub mod clutch_batch;
pub mod driveline;
pub mod effects;
pub mod engine;
mod gauss_legendre;
pub mod gear;
pub mod integrator;
pub mod params;
pub mod powertrain;
pub mod slip_integral;
pub mod thermal;

pub use params::{
    ActuatorParams, ClutchParams, DrivelineParams, EngineParams, IntegratorParams, Params,
    ParamsError, ThermalParams3, ThermalParams5,
};

//! The plant: a simulated dry dual-clutch transmission as the bus sees it (issue 5, DESIGN.md §2,
//! §3, §5).
//!
//! [`Plant`] is a pure core (no clock, no socket, no tokio): [`Plant::step`] takes the time since
//! the start and the frames received since the last call, integrates the powertrain of
//! `model::powertrain` (engine, actuators, clutches with the torque characteristic (13), driveline
//! (18)–(20) with stick/slip, 5-state thermal model (16)) at its 1 ms step up to `now`, and returns
//! the frames due at their 10 ms cycle — ENG_Status, DCT_Sensors, DCT_Actuators, BENCH_Torque,
//! BENCH_Temps, BENCH_Vehicle, SIM_Truth (and DRV_Pedal when it plays the driver) — as typed
//! messages with E2E applied and as CAN frames, plus the simulation truth for tests.
//!
//! Around the powertrain:
//! - engine ECU honouring TCU_EngineReq, clutch actuators following TCU_ClutchCmd, gear actuators
//!   following TCU_GearCmd; inputs checked (DLC, CRC, alive counter, ranges), errors counted, a
//!   silent input times out to a safe default ([`core`]);
//! - housing air θ_h relaxing slowly to an ambient / under-hood value;
//! - sensors with the contract's quantisation and seeded Gaussian noise ([`noise`]);
//! - modes ([`config::Mode`]): vehicle (driver on the bus or a built-in scenario, [`profile`]) and
//!   test rig (paper Sect. 3.3: input held at a set speed by a dyno, output braked, clutch
//!   positions from the bus or a built-in x_to profile, [`profile::RigProfile`]);
//! - reality effects of `model::effects`, each acting only through its physics ([`hooks`]);
//! - fault injection on the plant's own frames per message and time window ([`faults`]).

pub mod config;
pub mod core;
mod error;
pub mod faults;
pub mod hooks;
pub mod noise;
pub mod profile;

pub use self::config::{Mode, PlantConfig, StepPolicy};
pub use self::core::{CycleMessages, OutFrame, Output, Plant, PlantStats, Truth};
pub use self::error::PlantError;
pub use self::faults::{Fault, FaultKind};
pub use self::profile::{RigProfile, Scenario};

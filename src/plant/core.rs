//! The plant core: [`Plant::step`] integrates the powertrain at its 1 ms step up to `now` and
//! returns the frames due, with the received frames applied at their timestamps.
//!
//! Received frames are read like an ECU reads its mailboxes at the start of its 10 ms task: at
//! each cycle boundary t, the frames with a timestamp up to t are checked (DLC, CRC, alive
//! counter — a skipped counter is accepted, a repeated one is not — and the DBC ranges) and
//! latched, then the cycle's frames are sampled and sent. So a command sent in answer to the
//! plant's cycle-n frames acts from cycle n+1 on, whatever its latency within the cycle.
//!
//! Per 1 ms step, in order: the commands of this instant are formed (vehicle: TCU_ClutchCmd,
//! TCU_EngineReq, TCU_GearCmd and the driver from DRV_Pedal or the built-in scenario; rig: the
//! x_to profile or TCU_ClutchCmd, the dyno speed, fixed gears and the brake); an input silent for
//! `inputs.timeout_cycles` cycles falls to its safe default (clutch requests 0 mm, engine request
//! inactive, pedal 0, brake off; gear requests held); the clutch requests pass the dead-time line
//! (`actuator_dead_time`); one `Powertrain::step` with the effect hooks; the effect states and the
//! housing air advance. Every 10 ms the sensors are sampled (seeded noise, then the contract's
//! saturation and quantisation by the generated encoders), the messages are encoded, E2E applied
//! and the configured faults applied.
//!
//! With `[plant] step = "multirate"` (the default) a quiet cycle — inputs constant, each clutch
//! locked or open, no gear moving, in vehicle mode — is integrated in one RK4 step of 10 ms
//! instead of ten of 1 ms (`quiet`).
//!
//! Rig mode (paper Sect. 3.3): the dyno is an ideal speed source — the flywheel speed is set to
//! the dyno speed at the start of each step and the engine torque state to the torque the
//! clutches take (ENG_Status then reports the dyno torque); the output is held by the wheel
//! brake with both rig gears engaged. A built-in x_to profile is sampled at the 10 ms cycle,
//! quantised to TCU_ClutchCmd's resolution and held, as a controller commanding over the bus
//! would.

pub use super::config::CYCLE;
use super::config::{Mode, PlantConfig};
use super::faults::{Fault, FaultKind};
use super::hooks::EffectHooks;
use super::noise::gauss;
use super::profile::{CycleSampler, DriverSample};
use crate::can::codec::MessageDef;
use crate::can::e2e::{protect, E2eChecker, E2eConfig, E2eError, CRC_BYTE};
use crate::can::messages::{
    ids, message_def, BenchTemps, BenchTorque, BenchVehicle, DctActuators, DctSensors, DrvPedal,
    EngStatus, GearEvenAct, GearLever, GearOddAct, SimTruth, TcuClutchCmd, TcuEngineReq,
    TcuGearCmd,
};
use crate::can::{CanFrame, Received};
use crate::model::driveline::{self, GearShaft};
use crate::model::effects::{self, DelayLine};
use crate::model::engine::RPM;
use crate::model::powertrain::{Inputs, Outputs, Powertrain, State};
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Duration;

mod quiet;

/// A frame to send at `due` (time since the start).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutFrame {
    pub due: Duration,
    pub frame: CanFrame,
    pub message: &'static str,
    /// The fault applied to this frame, if any (the last one when several).
    pub fault: Option<FaultKind>,
}

/// The typed messages of one cycle as the sensors produced them (before faults), with the alive
/// counter and CRC the clean frame carries.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CycleMessages {
    pub t: Duration,
    pub eng_status: EngStatus,
    pub dct_sensors: DctSensors,
    pub dct_actuators: DctActuators,
    pub bench_torque: BenchTorque,
    pub bench_temps: BenchTemps,
    pub bench_vehicle: BenchVehicle,
    pub sim_truth: SimTruth,
    /// Only when the plant plays the driver.
    pub drv_pedal: Option<DrvPedal>,
}

impl CycleMessages {
    /// The payload of message `id` (`None`: not one of the cycle's, or no driver played).
    fn encode(&self, id: u16) -> Option<Result<[u8; 8], crate::can::codec::CodecError>> {
        match id {
            ids::DRV_PEDAL => self.drv_pedal.map(|m| m.encode()),
            ids::ENG_STATUS => Some(self.eng_status.encode()),
            ids::DCT_SENSORS => Some(self.dct_sensors.encode()),
            ids::DCT_ACTUATORS => Some(self.dct_actuators.encode()),
            ids::BENCH_TORQUE => Some(self.bench_torque.encode()),
            ids::BENCH_TEMPS => Some(self.bench_temps.encode()),
            ids::BENCH_VEHICLE => Some(self.bench_vehicle.encode()),
            ids::SIM_TRUTH => Some(self.sim_truth.encode()),
            _ => None,
        }
    }

    /// Records the alive counter and CRC that message `id` went out with (the E2E-protected
    /// messages).
    fn stamp(&mut self, id: u16, counter: u8, crc: u8) {
        match id {
            ids::DRV_PEDAL => {
                if let Some(m) = self.drv_pedal.as_mut() {
                    (m.alive_counter, m.crc) = (counter, crc);
                }
            }
            ids::ENG_STATUS => {
                (self.eng_status.alive_counter, self.eng_status.crc) = (counter, crc)
            }
            ids::DCT_SENSORS => {
                (self.dct_sensors.alive_counter, self.dct_sensors.crc) = (counter, crc)
            }
            ids::DCT_ACTUATORS => {
                (self.dct_actuators.alive_counter, self.dct_actuators.crc) = (counter, crc)
            }
            _ => {}
        }
    }
}

/// The simulation truth at the end of a [`Plant::step`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Truth {
    pub t_s: f64,
    pub state: State,
    pub outputs: Outputs,
    pub theta_h_c: f64,
    /// Clutch position requests before the dead time (mm).
    pub x_ref_mm: [f64; 2],
    /// Requests after the dead time, what the actuators follow (mm).
    pub x_ref_applied_mm: [f64; 2],
    /// Throwout-bearing positions behind the backlash (mm).
    pub x_bearing_mm: [f64; 2],
    pub theta_surface_c: [f64; 2],
    /// Engine torque the ECU reports (its map estimate; the dyno torque in rig mode) (N·m).
    pub engine_torque_reported_nm: f64,
    pub pedal: f64,
    pub brake: f64,
    pub grade: f64,
}

/// What one [`Plant::step`] produced.
#[derive(Debug, Clone, PartialEq)]
pub struct Output {
    /// Frames due before the next cycle, sorted by `due`; send each at its `due`.
    pub frames: Vec<OutFrame>,
    /// Typed messages of the cycles sampled during this step.
    pub cycles: Vec<CycleMessages>,
    pub truth: Truth,
}

/// Counters of the plant core.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct PlantStats {
    /// Integration steps (of 1 ms; a quiet cycle counts its ten).
    pub steps: u64,
    /// Cycles integrated in one step (`quiet`: `[plant] step = "multirate"`).
    pub quiet_cycles: u64,
    /// 10 ms cycles sampled.
    pub cycles: u64,
    /// Frames handed out for sending.
    pub frames_out: u64,
    /// Frames received (all ids).
    pub rx_frames: u64,
    /// Accepted frames per message.
    pub rx_accepted: BTreeMap<String, u64>,
    /// Rejected or suspicious frames per `message.kind` (bad_crc, counter_repeated,
    /// counter_skipped (accepted), wrong_dlc, decode, second_driver).
    pub rx_errors: BTreeMap<String, u64>,
    /// Frames of ids the plant does not read.
    pub rx_ignored: u64,
    /// Onsets of input timeouts per message.
    pub input_timeouts: BTreeMap<String, u64>,
    /// Frames affected per `message.kind` of fault.
    pub faults_applied: BTreeMap<String, u64>,
    /// Messages that could not be encoded (never expected: values are saturated first).
    pub encode_errors: u64,
    /// Non-finite states met (the state is then reset to the last finite one).
    pub nonfinite_states: u64,
}

#[derive(Debug, Clone, Copy, Default)]
struct Latched<T> {
    msg: Option<T>,
    at: Duration,
    fresh: bool,
}

#[derive(Debug, Clone, Copy, Default)]
struct Latch {
    clutch: Latched<TcuClutchCmd>,
    engine: Latched<TcuEngineReq>,
    gear: Latched<TcuGearCmd>,
    pedal: Latched<DrvPedal>,
}

impl<T> Latched<T> {
    /// A message just received at `at`.
    fn new(msg: T, at: Duration) -> Self {
        Latched {
            msg: Some(msg),
            at,
            fresh: true,
        }
    }
}

impl Latch {
    /// Decodes the data of message `id` received at `at` into its latch; false when it does not
    /// decode (or is not a message the plant latches).
    fn set(&mut self, id: u16, data: &[u8], at: Duration) -> bool {
        match id {
            ids::TCU_CLUTCH_CMD => TcuClutchCmd::decode(data)
                .map(|m| self.clutch = Latched::new(m, at))
                .is_ok(),
            ids::TCU_ENGINE_REQ => TcuEngineReq::decode(data)
                .map(|m| self.engine = Latched::new(m, at))
                .is_ok(),
            ids::TCU_GEAR_CMD => TcuGearCmd::decode(data)
                .map(|m| self.gear = Latched::new(m, at))
                .is_ok(),
            ids::DRV_PEDAL => DrvPedal::decode(data)
                .map(|m| self.pedal = Latched::new(m, at))
                .is_ok(),
            _ => false,
        }
    }
}

/// Noise channels (fixed numbering: the noise of a channel does not depend on the others).
mod ch {
    pub const ENG_SPEED: u32 = 0;
    pub const ENG_TORQUE: u32 = 1;
    pub const SHAFT1: u32 = 2;
    pub const SHAFT2: u32 = 3;
    pub const OUT: u32 = 4;
    pub const HOUSING: u32 = 5;
    pub const POS1: u32 = 6;
    pub const POS2: u32 = 7;
    pub const TORQUE1: u32 = 8;
    pub const TORQUE2: u32 = 9;
    pub const PP1: u32 = 10;
    pub const PP2: u32 = 11;
    pub const CD: u32 = 12;
    pub const ACCEL: u32 = 13;
}

/// The simulated transmission (see the module documentation).
#[derive(Debug, Clone)]
pub struct Plant {
    cfg: PlantConfig,
    pt: Powertrain<EffectHooks>,
    s: State,
    last_finite: State,
    dt: f64,
    steps: u64,
    steps_per_cycle: u64,
    next_cycle: u64,
    theta_h: f64,
    /// exp(−h/τ) of the housing air over one step and over one cycle in one step.
    housing_decay: [f64; 2],
    delay: [DelayLine; 2],
    delay_steps: usize,
    x_ref: [f64; 2],
    x_ref_applied: [f64; 2],
    driver: DriverSample,
    /// The built-in driver sampled once per cycle where it holds still.
    sampler: CycleSampler,
    latch: Latch,
    checker: E2eChecker,
    sent: Vec<u16>,
    counters: Vec<u8>,
    last_counter: Vec<Option<u8>>,
    fault_hits: Vec<u64>,
    queue: Vec<OutFrame>,
    pending_rx: Vec<Received>,
    last_out: Outputs,
    /// `last_out` belongs to the current state (outputs are computed only when a frame is due,
    /// in rig mode, or for effects whose states need them).
    out_fresh: bool,
    /// Inputs of the last step (for outputs computed after it).
    u_last: Inputs,
    rig_speed_radps: f64,
    stats: PlantStats,
}

fn finite(s: &State) -> bool {
    [
        s.w_f,
        s.w_c1,
        s.w_c2,
        s.w_out,
        s.x1_mm,
        s.x2_mm,
        s.engine_torque_nm,
    ]
    .iter()
    .chain(s.thermal.as_array().iter())
    .all(|v| v.is_finite())
}

/// The E2E-protected messages the plant receives and checks.
const RECEIVED_E2E: [u16; 4] = [
    ids::TCU_CLUTCH_CMD,
    ids::TCU_ENGINE_REQ,
    ids::TCU_GEAR_CMD,
    ids::DRV_PEDAL,
];

/// The state at the configuration's initial conditions: at rest at the initial engine speed (a
/// rig: its input speed `rig_rpm`) and temperatures (each part's own where given), the gears of
/// the mode engaged; a vehicle rolls at its initial speed with the input shafts of engaged gears
/// turning with the output.
fn initial_state(cfg: &PlantConfig, rig_rpm: f64) -> State {
    let p = cfg.params;
    let i = cfg.initial;
    let rpm = if cfg.mode == Mode::Rig {
        rig_rpm
    } else {
        i.engine_rpm
    };
    let mut s = State::at_rest(rpm, i.temperature_c);
    s.thermal.pp1 = i.pp1_c.unwrap_or(i.temperature_c);
    s.thermal.pp2 = i.pp2_c.unwrap_or(i.temperature_c);
    s.thermal.c1 = i.c1_c.unwrap_or(i.temperature_c);
    s.thermal.c2 = i.c2_c.unwrap_or(i.temperature_c);
    s.thermal.cd = i.cd_c.unwrap_or(i.temperature_c);
    let (g_odd, g_even) = match cfg.mode {
        Mode::Vehicle => (i.gear_odd, i.gear_even),
        Mode::Rig => (cfg.rig.gear_odd, cfg.rig.gear_even),
    };
    s.gear_odd = GearShaft::engaged(g_odd);
    s.gear_even = GearShaft::engaged(g_even);
    if cfg.mode == Mode::Vehicle {
        s.w_out = i.vehicle_kmh / 3.6 / p.driveline.wheel_radius_m;
        s.w_c1 = driveline::overall_ratio(&p.driveline, g_odd).map_or(0.0, |k| k * s.w_out);
        s.w_c2 = driveline::overall_ratio(&p.driveline, g_even).map_or(0.0, |k| k * s.w_out);
    }
    s
}

impl Plant {
    /// A plant at its initial conditions.
    pub fn new(cfg: PlantConfig) -> Self {
        let p = cfg.params;
        let i = cfg.initial;
        let rig_rpm = cfg
            .rig_profile
            .as_ref()
            .map_or(cfg.rig.input_speed_rpm, |r| r.input_speed_rpm);
        let s = initial_state(&cfg, rig_rpm);
        let hooks = EffectHooks::new(cfg.effects, &s);
        let pt = Powertrain::with_hooks(p, hooks);
        let dt = p.integrator.dt_s;
        let steps_per_cycle = (CYCLE.as_secs_f64() / dt).round().max(1.0) as u64;
        let delay_steps = effects::dead_time_steps(&cfg.effects, dt);
        let sent = cfg.sent_ids();
        let n = sent.len();
        let checker = E2eChecker::for_ids(
            E2eConfig {
                timeout_cycles: cfg.inputs.timeout_cycles,
            },
            Duration::ZERO,
            RECEIVED_E2E,
        );
        let last_out = pt.outputs(&s, &Inputs::default());
        let nf = cfg.faults.len();
        Plant {
            theta_h: i.housing_c,
            housing_decay: [1.0, steps_per_cycle as f64]
                .map(|steps| (-steps * dt / cfg.housing.tau_s).exp()),
            rig_speed_radps: rig_rpm * RPM,
            pt,
            s,
            last_finite: s,
            dt,
            steps: 0,
            steps_per_cycle,
            next_cycle: 0,
            delay: [DelayLine::new(0.0), DelayLine::new(0.0)],
            delay_steps,
            x_ref: [0.0; 2],
            x_ref_applied: [0.0; 2],
            driver: DriverSample {
                pedal: 0.0,
                brake: 0.0,
                lever: GearLever::P,
                grade: 0.0,
            },
            sampler: CycleSampler::default(),
            latch: Latch::default(),
            checker,
            counters: vec![0; n],
            last_counter: vec![None; n],
            sent,
            fault_hits: vec![0; nf],
            queue: Vec::new(),
            pending_rx: Vec::new(),
            last_out,
            out_fresh: true,
            u_last: Inputs::default(),
            stats: PlantStats::default(),
            cfg,
        }
    }

    pub fn config(&self) -> &PlantConfig {
        &self.cfg
    }

    pub fn state(&self) -> &State {
        &self.s
    }

    pub fn stats(&self) -> &PlantStats {
        &self.stats
    }

    /// When the plant next needs to run: its next 10 ms cycle (received frames take effect and
    /// sensor frames are produced only at cycles; a call in between only integrates).
    pub fn poll_timeout(&self) -> Duration {
        CYCLE.saturating_mul(u32::try_from(self.next_cycle).unwrap_or(u32::MAX))
    }

    /// Simulated time integrated so far.
    pub fn time(&self) -> Duration {
        Duration::from_secs_f64(self.steps as f64 * self.dt)
    }

    /// Messages this plant sends, in sending order within a cycle.
    pub fn sent_ids(&self) -> &[u16] {
        &self.sent
    }

    /// The effect hooks (effect set and its states).
    pub fn hooks(&self) -> &EffectHooks {
        &self.pt.hooks
    }

    /// Integrates up to `now` (time since the start; not before the current time) and returns the
    /// frames due before the next cycle. The frames `rx` (timestamps are times since the start,
    /// like `now`) are applied at the first cycle boundary at or after their timestamp.
    pub fn step(&mut self, now: Duration, rx: &[Received]) -> Output {
        if !rx.is_empty() {
            self.pending_rx.extend_from_slice(rx);
            self.pending_rx.sort_by_key(|r| r.timestamp);
        }
        let target = (now.as_secs_f64() / self.dt + 1e-6).floor() as u64;
        let mut cycles = Vec::new();
        loop {
            if self.steps == self.next_cycle * self.steps_per_cycle {
                let t = self.time();
                self.apply_rx_until(t);
                self.outputs_for_frames();
                cycles.push(self.emit_cycle(t));
                self.next_cycle += 1;
            }
            if self.steps >= target {
                break;
            }
            let at_boundary = self.steps % self.steps_per_cycle == 0;
            if at_boundary && self.steps + self.steps_per_cycle <= target && self.quiet_cycle() {
                continue;
            }
            self.substep();
        }
        self.outputs_for_frames();
        let horizon = now + CYCLE;
        self.queue.sort_by_key(|f| f.due);
        let n_due = self.queue.partition_point(|f| f.due < horizon);
        let frames: Vec<OutFrame> = self.queue.drain(..n_due).collect();
        self.stats.frames_out += frames.len() as u64;
        Output {
            frames,
            cycles,
            truth: self.truth(),
        }
    }

    /// The truth at the current time.
    pub fn truth(&self) -> Truth {
        Truth {
            t_s: self.steps as f64 * self.dt,
            state: self.s,
            outputs: self.last_out,
            theta_h_c: self.theta_h,
            x_ref_mm: self.x_ref,
            x_ref_applied_mm: self.x_ref_applied,
            x_bearing_mm: [
                self.pt.hooks.bearing(0, self.s.x1_mm),
                self.pt.hooks.bearing(1, self.s.x2_mm),
            ],
            theta_surface_c: if self
                .cfg
                .effects
                .is_active(effects::EffectId::SurfaceTemperatureFriction)
            {
                self.pt.hooks.theta_surface_c
            } else {
                [self.s.thermal.c1, self.s.thermal.c2]
            },
            engine_torque_reported_nm: self.engine_reported(),
            pedal: self.driver.pedal,
            brake: self.driver.brake,
            grade: self.driver.grade,
        }
    }

    fn engine_reported(&self) -> f64 {
        match self.cfg.mode {
            Mode::Rig => self.s.engine_torque_nm,
            Mode::Vehicle => {
                effects::engine_map_estimate(&self.cfg.effects, self.s.engine_torque_nm)
            }
        }
    }

    fn apply_rx_until(&mut self, t: Duration) {
        let n = self.pending_rx.partition_point(|r| r.timestamp <= t);
        if n == 0 {
            return;
        }
        let frames: Vec<Received> = self.pending_rx.drain(..n).collect();
        for r in &frames {
            self.receive(r);
        }
    }

    fn count(map: &mut BTreeMap<String, u64>, key: String) {
        *map.entry(key).or_default() += 1;
    }

    /// Checks and latches one received frame.
    fn receive(&mut self, r: &Received) {
        self.stats.rx_frames += 1;
        let Some(id) = r.frame.standard_id() else {
            self.stats.rx_ignored += 1;
            return;
        };
        let name = message_def(u32::from(id)).map_or("?", |d| d.name);
        if !self.reads(id) {
            // A pedal frame while the plant plays the driver's scenario is a second driver.
            if id == ids::DRV_PEDAL && self.cfg.scenario.is_some() && self.cfg.mode == Mode::Vehicle
            {
                Self::count(&mut self.stats.rx_errors, format!("{name}.second_driver"));
            } else {
                self.stats.rx_ignored += 1;
            }
            return;
        }
        let data = r.frame.bytes();
        match self.checker.check(r.timestamp, u32::from(id), data) {
            Ok(()) => {}
            Err(e @ E2eError::CounterSkipped { .. }) => {
                Self::count(&mut self.stats.rx_errors, format!("{name}.{}", e.kind()));
            }
            Err(e) => {
                Self::count(&mut self.stats.rx_errors, format!("{name}.{}", e.kind()));
                return;
            }
        }
        if self.latch.set(id, data, r.timestamp) {
            Self::count(&mut self.stats.rx_accepted, name.to_string());
        } else {
            Self::count(&mut self.stats.rx_errors, format!("{name}.decode"));
        }
    }

    /// Whether the plant reads message `id` in its mode: a vehicle the TCU's commands and, unless
    /// it plays the driver's scenario itself, the pedal; a rig only the clutch command, unless it
    /// follows its own profile.
    fn reads(&self, id: u16) -> bool {
        match self.cfg.mode {
            Mode::Vehicle => {
                matches!(
                    id,
                    ids::TCU_CLUTCH_CMD | ids::TCU_ENGINE_REQ | ids::TCU_GEAR_CMD
                ) || (id == ids::DRV_PEDAL && self.cfg.scenario.is_none())
            }
            Mode::Rig => id == ids::TCU_CLUTCH_CMD && self.cfg.rig_profile.is_none(),
        }
    }

    /// Freshness of a latched input at `t` (counting the onset of a timeout).
    fn fresh<T: Copy>(
        l: &mut Latched<T>,
        t: Duration,
        limit: Duration,
        name: &str,
        stats: &mut PlantStats,
    ) -> Option<T> {
        let m = l.msg?;
        let fresh = t.saturating_sub(l.at) < limit;
        if l.fresh && !fresh {
            Self::count(&mut stats.input_timeouts, name.to_string());
        }
        l.fresh = fresh;
        fresh.then_some(m)
    }

    /// Powertrain inputs at time `t` (before the dead time) and the requested positions.
    fn commands(&mut self, t: Duration) -> Inputs {
        let limit = CYCLE * self.cfg.inputs.timeout_cycles;
        let (cycle, first, last) = self.cycle_span();
        let stats = &mut self.stats;
        let mut u = Inputs {
            theta_h_c: self.theta_h,
            ..Inputs::default()
        };
        match self.cfg.mode {
            Mode::Rig => {
                self.x_ref = match &self.cfg.rig_profile {
                    Some(prof) => {
                        let tc = (t.as_nanos() / CYCLE.as_nanos()) as f64 * CYCLE.as_secs_f64();
                        let x = prof.x_ref(tc);
                        // At the contract's resolution, as a controller commanding over the bus.
                        let q = TcuClutchCmd {
                            clutch1_pos_req: x[0],
                            clutch2_pos_req: x[1],
                            ..Default::default()
                        };
                        match q.encode().and_then(|d| TcuClutchCmd::decode(&d)) {
                            Ok(m) => [m.clutch1_pos_req, m.clutch2_pos_req],
                            Err(_) => x,
                        }
                    }
                    None => Self::fresh(&mut self.latch.clutch, t, limit, "TCU_ClutchCmd", stats)
                        .map_or([0.0; 2], |m| [m.clutch1_pos_req, m.clutch2_pos_req]),
                };
                u.gear_odd_req = self.cfg.rig.gear_odd;
                u.gear_even_req = self.cfg.rig.gear_even;
                u.brake = self.cfg.rig.brake;
                self.driver = DriverSample {
                    pedal: 0.0,
                    brake: self.cfg.rig.brake,
                    lever: GearLever::N,
                    grade: 0.0,
                };
            }
            Mode::Vehicle => {
                self.x_ref = Self::fresh(&mut self.latch.clutch, t, limit, "TCU_ClutchCmd", stats)
                    .map_or([0.0; 2], |m| [m.clutch1_pos_req, m.clutch2_pos_req]);
                u.engine_torque_request_nm =
                    Self::fresh(&mut self.latch.engine, t, limit, "TCU_EngineReq", stats)
                        .filter(|m| m.eng_torque_req_active)
                        .map(|m| m.eng_torque_req);
                // Gear requests are held after a timeout (a gear actuator keeps its position).
                Self::fresh(&mut self.latch.gear, t, limit, "TCU_GearCmd", stats);
                let (go, ge) = match self.latch.gear.msg {
                    Some(m) => (m.gear_odd_req.into(), m.gear_even_req.into()),
                    None => (self.cfg.initial.gear_odd, self.cfg.initial.gear_even),
                };
                u.gear_odd_req = go;
                u.gear_even_req = ge;
                self.driver = match &self.cfg.scenario {
                    Some(sc) => self.sampler.sample(sc, t.as_secs_f64(), cycle, first, last),
                    None => {
                        let brake_frac = self.cfg.inputs.brake_switch_fraction;
                        match Self::fresh(&mut self.latch.pedal, t, limit, "DRV_Pedal", stats) {
                            Some(m) => DriverSample {
                                pedal: m.accel_pedal / 100.0,
                                brake: if m.brake_switch { brake_frac } else { 0.0 },
                                lever: m.gear_lever,
                                grade: 0.0,
                            },
                            None => DriverSample {
                                pedal: 0.0,
                                brake: 0.0,
                                lever: self.driver.lever,
                                grade: 0.0,
                            },
                        }
                    }
                };
                u.pedal = self.driver.pedal;
                u.brake = self.driver.brake;
                u.grade = self.driver.grade;
            }
        }
        u
    }

    /// The current bus cycle (index) and the times of its first and last step (s), as
    /// [`Self::time`] gives them.
    fn cycle_span(&self) -> (u64, f64, f64) {
        let n = self.steps_per_cycle;
        let cycle = self.steps / n;
        let at = |k: u64| Duration::from_secs_f64(k as f64 * self.dt).as_secs_f64();
        (cycle, at(cycle * n), at(cycle * n + n - 1))
    }

    /// One integration step.
    fn substep(&mut self) {
        let t = self.time();
        let mut u = self.commands(t);
        let d = self.delay_steps;
        self.x_ref_applied = [
            self.delay[0].push(self.x_ref[0], d),
            self.delay[1].push(self.x_ref[1], d),
        ];
        u.x1_ref_mm = self.x_ref_applied[0];
        u.x2_ref_mm = self.x_ref_applied[1];
        if self.cfg.mode == Mode::Rig {
            // Ideal dyno: holds the input speed and supplies what the clutches take.
            self.s.w_f = self.rig_speed_radps;
            self.s.engine_torque_nm = self.last_out.t_fc1_nm + self.last_out.t_fc2_nm;
            self.s.idle_int_nm = 0.0;
        }
        let (prev_out, prev_fresh) = (self.last_out, self.out_fresh);
        self.pt.advance(&mut self.s, &u, self.dt);
        self.u_last = u;
        self.out_fresh = false;
        // Rig mode feeds the clutch torques back to the dyno every step.
        let every_step = self.cfg.mode == Mode::Rig || self.pt.hooks.needs_outputs();
        let outputs_ok = !every_step || self.refresh_outputs();
        if finite(&self.s) && outputs_ok {
            self.last_finite = self.s;
            let out = every_step.then_some(&self.last_out);
            self.pt.hooks.advance(&self.s, out, self.dt);
        } else {
            self.stats.nonfinite_states += 1;
            self.s = self.last_finite;
            self.s.t_s += self.dt;
            // The outputs of the state restored (computed again if they never were).
            self.last_out = prev_out;
            self.out_fresh = prev_fresh;
        }
        self.relax_housing(self.housing_decay[0]);
        self.steps += 1;
        self.stats.steps += 1;
    }

    /// The housing air relaxed towards its target by the factor `decay` (one of `housing_decay`).
    fn relax_housing(&mut self, decay: f64) {
        let h = &self.cfg.housing;
        self.theta_h = h.target_c + (self.theta_h - h.target_c) * decay;
    }

    /// Computes the outputs of the current state once after a step (see `out_fresh`). False
    /// when its clutch torques are not finite: the last finite outputs are kept.
    fn refresh_outputs(&mut self) -> bool {
        if self.out_fresh {
            return true;
        }
        self.out_fresh = true;
        let out = self.pt.outputs(&self.s, &self.u_last);
        let ok = out.t_fc1_nm.is_finite() && out.t_fc2_nm.is_finite();
        if ok {
            self.last_out = out;
        }
        ok
    }

    /// The outputs the frames of a cycle (and the truth) are made from.
    fn outputs_for_frames(&mut self) {
        if !self.refresh_outputs() {
            self.stats.nonfinite_states += 1;
        }
    }

    fn noise(&self, cycle: u64, channel: u32, sigma: f64) -> f64 {
        if sigma > 0.0 {
            sigma * gauss(self.cfg.seed, cycle, channel)
        } else {
            0.0
        }
    }

    /// Samples the sensors at cycle time `t`, encodes, protects, applies faults, queues.
    fn emit_cycle(&mut self, t: Duration) -> CycleMessages {
        self.stats.cycles += 1;
        let mut msgs = self.sample_cycle(t);
        self.send_cycle(t, &mut msgs);
        msgs
    }

    /// The cycle's messages as the sensors read them at `t` (noise, then the contract's
    /// saturation), before the alive counter and CRC.
    fn sample_cycle(&mut self, t: Duration) -> CycleMessages {
        let k = self.next_cycle;
        let (eng_status, dct_sensors, dct_actuators) = self.drive_messages(k);
        let (bench_torque, bench_temps) = self.bench_messages(k);
        let s = self.s;
        let o = self.last_out;
        let n = self.cfg.sensors;
        // The driver at this instant (the last step used the one of its start).
        let (cycle, first, last) = self.cycle_span();
        let driver = match (&self.cfg.mode, &self.cfg.scenario) {
            (Mode::Vehicle, Some(sc)) => {
                self.sampler.sample(sc, t.as_secs_f64(), cycle, first, last)
            }
            _ => self.driver,
        };
        let bench_vehicle = BenchVehicle {
            vehicle_speed: BenchVehicle::saturate_vehicle_speed(o.vehicle_speed_mps * 3.6),
            vehicle_accel: BenchVehicle::saturate_vehicle_accel(
                o.vehicle_accel_mps2 + self.noise(k, ch::ACCEL, n.vehicle_accel_mps2),
            ),
            road_grade: BenchVehicle::saturate_road_grade(driver.grade * 100.0),
        };
        let sim_truth = SimTruth {
            clutch1_temp_true: SimTruth::saturate_clutch1_temp_true(s.thermal.c1),
            clutch2_temp_true: SimTruth::saturate_clutch2_temp_true(s.thermal.c2),
        };
        let drv_pedal =
            (self.cfg.mode == Mode::Vehicle && self.cfg.scenario.is_some()).then(|| DrvPedal {
                accel_pedal: DrvPedal::saturate_accel_pedal(driver.pedal * 100.0),
                brake_switch: driver.brake > 0.0,
                gear_lever: driver.lever,
                ..Default::default()
            });
        CycleMessages {
            t,
            eng_status,
            dct_sensors,
            dct_actuators,
            bench_torque,
            bench_temps,
            bench_vehicle,
            sim_truth,
            drv_pedal,
        }
    }

    /// ENG_Status, DCT_Sensors and DCT_Actuators of cycle `k`: what the TCU reads.
    fn drive_messages(&self, k: u64) -> (EngStatus, DctSensors, DctActuators) {
        let s = self.s;
        let n = self.cfg.sensors;
        let rpm = |w: f64| w / RPM;
        let eng = EngStatus {
            eng_speed: EngStatus::saturate_eng_speed(
                rpm(s.w_f) + self.noise(k, ch::ENG_SPEED, n.speed_rpm),
            ),
            eng_torque_act: EngStatus::saturate_eng_torque_act(
                self.engine_reported() + self.noise(k, ch::ENG_TORQUE, n.engine_torque_nm),
            ),
            ..Default::default()
        };
        let sensors = DctSensors {
            in_shaft1_speed: DctSensors::saturate_in_shaft1_speed(
                rpm(s.w_c1) + self.noise(k, ch::SHAFT1, n.speed_rpm),
            ),
            in_shaft2_speed: DctSensors::saturate_in_shaft2_speed(
                rpm(s.w_c2) + self.noise(k, ch::SHAFT2, n.speed_rpm),
            ),
            out_shaft_speed: DctSensors::saturate_out_shaft_speed(
                rpm(s.w_out) + self.noise(k, ch::OUT, n.speed_rpm),
            ),
            housing_temp: DctSensors::saturate_housing_temp(
                self.theta_h + self.noise(k, ch::HOUSING, n.housing_c),
            ),
            ..Default::default()
        };
        let actuators = DctActuators {
            clutch1_pos: DctActuators::saturate_clutch1_pos(
                s.x1_mm + self.noise(k, ch::POS1, n.position_mm),
            ),
            clutch2_pos: DctActuators::saturate_clutch2_pos(
                s.x2_mm + self.noise(k, ch::POS2, n.position_mm),
            ),
            // A selector engages only gears of its own shaft (`Powertrain::update_gears`, the
            // config's `check_shafts`): the conversions cannot fail.
            gear_odd_act: GearOddAct::try_from(s.gear_odd.engaged).unwrap_or_default(),
            gear_even_act: GearEvenAct::try_from(s.gear_even.engaged).unwrap_or_default(),
            ..Default::default()
        };
        (eng, sensors, actuators)
    }

    /// BENCH_Torque and BENCH_Temps of cycle `k`: the rig's torque and temperature sensors.
    fn bench_messages(&self, k: u64) -> (BenchTorque, BenchTemps) {
        let s = self.s;
        let o = self.last_out;
        let n = self.cfg.sensors;
        let torque = BenchTorque {
            clutch1_torque: BenchTorque::saturate_clutch1_torque(
                o.t_fc1_nm + self.noise(k, ch::TORQUE1, n.torque_nm),
            ),
            clutch2_torque: BenchTorque::saturate_clutch2_torque(
                o.t_fc2_nm + self.noise(k, ch::TORQUE2, n.torque_nm),
            ),
        };
        let temps = BenchTemps {
            pressure_plate1_temp: BenchTemps::saturate_pressure_plate1_temp(
                s.thermal.pp1 + self.noise(k, ch::PP1, n.temperature_c),
            ),
            pressure_plate2_temp: BenchTemps::saturate_pressure_plate2_temp(
                s.thermal.pp2 + self.noise(k, ch::PP2, n.temperature_c),
            ),
            central_disk_temp: BenchTemps::saturate_central_disk_temp(
                s.thermal.cd + self.noise(k, ch::CD, n.temperature_c),
            ),
        };
        (torque, temps)
    }

    /// Encodes and queues every message the plant sends, each with its alive counter and CRC
    /// (written back into `msgs`, as the clean frame carries them).
    fn send_cycle(&mut self, t: Duration, msgs: &mut CycleMessages) {
        for slot in 0..self.sent.len() {
            let id = self.sent[slot];
            let data = match msgs.encode(id) {
                Some(Ok(d)) => d,
                Some(Err(_)) => {
                    self.stats.encode_errors += 1;
                    continue;
                }
                None => continue,
            };
            if let Some((counter, crc)) = self.send(slot, t, data) {
                msgs.stamp(id, counter, crc);
            }
        }
    }

    /// Protects, faults and queues one message; returns the clean frame's (counter, CRC) for
    /// protected messages.
    fn send(&mut self, slot: usize, t: Duration, mut data: [u8; 8]) -> Option<(u8, u8)> {
        let id = self.sent[slot];
        let def = message_def(u32::from(id))?;
        let active = ActiveFaults::of(&self.cfg.faults, id, t);
        let mut applied: Option<FaultKind> = None;
        if active.get(FaultKind::Stop).is_some() {
            self.hit(def, FaultKind::Stop, &mut applied);
            return None;
        }
        let clean = if def.e2e {
            Some(self.protect_faulted(slot, def, &active, &mut data, &mut applied))
        } else {
            self.implant(def, &active, &mut data, &mut applied);
            None
        };
        if let Some(&(i, f)) = active.get(FaultKind::Drop) {
            let n = self.fault_hits[i];
            self.fault_hits[i] += 1;
            if n % u64::from(f.every) == 0 {
                self.hit(def, FaultKind::Drop, &mut applied);
                return clean;
            }
        }
        let mut due = t;
        if let Some((_, f)) = active.get(FaultKind::Delay) {
            due = t + f.delay;
            self.hit(def, FaultKind::Delay, &mut applied);
        }
        let Ok(frame) = CanFrame::standard(id, &data) else {
            self.stats.encode_errors += 1;
            return clean;
        };
        self.queue.push(OutFrame {
            due,
            frame,
            message: def.name,
            fault: applied,
        });
        clean
    }

    /// Counts fault `k` applied to a frame of `def` and notes it as the frame's fault.
    fn hit(&mut self, def: &MessageDef, k: FaultKind, applied: &mut Option<FaultKind>) {
        Self::count(
            &mut self.stats.faults_applied,
            format!("{}.{}", def.name, k.as_str()),
        );
        *applied = Some(k);
    }

    /// An `implausible` fault's value written into `data`.
    fn implant(
        &mut self,
        def: &MessageDef,
        active: &ActiveFaults,
        data: &mut [u8; 8],
        applied: &mut Option<FaultKind>,
    ) {
        if let Some((si, raw)) = active
            .get(FaultKind::Implausible)
            .and_then(|(_, f)| f.implausible_raw())
        {
            let mut payload = u64::from_le_bytes(*data);
            def.signals[si].insert(&mut payload, raw);
            *data = payload.to_le_bytes();
            self.hit(def, FaultKind::Implausible, applied);
        }
    }

    /// The E2E protection of an outgoing frame of slot `slot`, with its faults: the alive counter
    /// (frozen by `freeze_counter` once one was sent), an `implausible` value protected as if
    /// valid, a `corrupt_crc` CRC. Returns the counter and CRC the frame would carry without
    /// faults (the bench's record of what was meant).
    fn protect_faulted(
        &mut self,
        slot: usize,
        def: &MessageDef,
        active: &ActiveFaults,
        data: &mut [u8; 8],
        applied: &mut Option<FaultKind>,
    ) -> (u8, u8) {
        let id = self.sent[slot];
        let counter = match self.last_counter[slot] {
            Some(last) if active.get(FaultKind::FreezeCounter).is_some() => {
                self.hit(def, FaultKind::FreezeCounter, applied);
                last
            }
            _ => {
                let c = self.counters[slot];
                self.counters[slot] = (c + 1) % 16;
                c
            }
        };
        let mut clean_data = *data;
        protect(id, &mut clean_data, counter);
        let clean = (counter, clean_data[CRC_BYTE]);
        self.implant(def, active, data, applied);
        protect(id, data, counter);
        self.last_counter[slot] = Some(counter);
        if active.get(FaultKind::CorruptCrc).is_some() {
            data[CRC_BYTE] ^= 0x5A;
            self.hit(def, FaultKind::CorruptCrc, applied);
        }
        clean
    }
}

/// The faults active on one message at one time, with their index in the configuration.
struct ActiveFaults(Vec<(usize, Fault)>);

impl ActiveFaults {
    /// The faults of `faults` on message `id` whose window holds `t`.
    fn of(faults: &[Fault], id: u16, t: Duration) -> Self {
        ActiveFaults(
            faults
                .iter()
                .enumerate()
                .filter(|(_, f)| f.message.id == id && f.active(t))
                .map(|(i, f)| (i, *f))
                .collect(),
        )
    }

    /// The first active fault of kind `k`.
    fn get(&self, k: FaultKind) -> Option<&(usize, Fault)> {
        self.0.iter().find(|(_, f)| f.kind == k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    /// The default plant (vehicle mode with its built-in driver), no frame received.
    fn plant() -> Plant {
        Plant::new(PlantConfig::default())
    }

    /// One step to 100 ms: the cycles at 0, 10, …, 100 ms (the DBC's cycle), each sending every
    /// message the plant sends once, due at its cycle.
    #[test]
    fn each_cycle_sends_each_message_once_at_its_cycle() {
        let mut p = plant();
        let out = p.step(ms(100), &[]);
        assert_eq!(out.cycles.len(), 11);
        for &id in p.sent_ids() {
            let dues: Vec<_> = out
                .frames
                .iter()
                .filter(|f| f.frame.standard_id() == Some(id))
                .map(|f| f.due)
                .collect();
            let expected: Vec<_> = (0..=10).map(|k| CYCLE * k).collect();
            assert_eq!(dues, expected, "{:#x}", id);
        }
        assert!(out.frames.windows(2).all(|w| w[0].due <= w[1].due));
    }

    /// Time is integrated up to `now` in whole steps, and the plant asks to run again at its
    /// next cycle.
    #[test]
    fn time_reaches_now_and_the_next_run_is_the_next_cycle() {
        let mut p = plant();
        p.step(ms(25), &[]);
        assert_eq!(p.time(), ms(25));
        assert_eq!(p.poll_timeout(), ms(30));
        p.step(ms(30), &[]);
        assert_eq!(p.poll_timeout(), ms(40));
    }

    /// Every protected frame passes an independent E2E check: its CRC right and its alive
    /// counter advancing by one per cycle, message by message.
    #[test]
    fn every_protected_frame_has_its_crc_and_a_running_counter() {
        let mut p = plant();
        let out = p.step(ms(500), &[]);
        let mut checker = E2eChecker::all(E2eConfig::default(), Duration::ZERO);
        let mut checked = 0;
        for f in &out.frames {
            let id = f.frame.raw_id();
            if message_def(id).is_some_and(|m| m.e2e) {
                checker.check(f.due, id, f.frame.bytes()).unwrap();
                checked += 1;
            }
        }
        assert!(checked >= 51 * 3, "{checked}");
    }

    /// The truth follows the integration: at rest with the clutches open, the vehicle stays put
    /// and the engine idles near its idle speed.
    #[test]
    fn a_plant_left_alone_idles_at_rest() {
        let mut p = plant();
        let out = p.step(ms(2000), &[]);
        let s = &out.truth.state;
        assert_eq!(s.w_out, 0.0);
        let idle = p.config().params.engine.idle_speed_rpm * RPM;
        assert!((s.w_f - idle).abs() < 0.05 * idle, "{} vs {idle}", s.w_f);
    }
}

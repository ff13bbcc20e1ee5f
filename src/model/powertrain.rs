//! The assembled dual-clutch powertrain: engine, two clutch actuators, two dry clutches with the
//! torque characteristic (13), the driveline (18)–(20) with stick/slip, gear selectors with
//! synchronisers, and the 5-state thermal model (16) — one [`State`] with named fields, one
//! [`Powertrain::derivative`] and an event-handling [`Powertrain::step`] on top of the RK4
//! integrator.
//!
//! Stick/slip per clutch (Karnopp-style, as events, without chattering):
//! - a slipping clutch locks when its slip crosses zero inside a step (the crossing is located by
//!   linear interpolation and the step is split there) and the torque needed to stay locked is at
//!   most the static capacity 2·R_μ(0, θ)·F; the speeds are then projected onto the lock
//!   conserving momentum (the tiny kinetic energy lost is booked as friction heat);
//! - a locked clutch breaks away at the start of a step when the torque it has to carry exceeds
//!   that capacity.
//!
//! Because μ_d(θ) > μ_s over the whole range, the slipping torque grows with the slip, so a clutch
//! that broke away settles at a small slip instead of re-locking at once: no chattering.
//!
//! Energy book-keeping: the state integrates the engine work, the friction work of each clutch,
//! the synchroniser work and the load work, so that
//! E_engine − E_fric1 − E_fric2 − E_sync − E_load = ΔKE (checked by the tests to 1e-6), and the
//! thermal model receives exactly the friction power that the driveline dissipates.
//!
//! Hooks for the plant's "reality effects": every clutch torque, static capacity and contact flag β
//! goes through [`Hooks`], as does the engine torque command and an extra heat-flow term, so an
//! effect wraps the nominal function instead of copying the model.

use super::actuator;
use super::clutch;
use super::driveline::{self, GearShaft, Groups, Links, C1, C2, F, OUT};
use super::engine::{self, EngineInputs};
use super::gear::Gear;
use super::integrator::{rk4_step_from, OdeState, OdeSystem};
use super::params::{ClutchParams, Params};
use super::thermal::{self, Thermal5, Thermal5State, ThermalInputs};
use serde::{Deserialize, Serialize};

/// Everything a clutch-level hook may depend on.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ClutchContext {
    /// 0 for clutch 1 (odd), 1 for clutch 2 (even).
    pub clutch: usize,
    /// Throwout-bearing position (mm).
    pub x_to_mm: f64,
    /// Slip ω_f − ω_c (rad/s).
    pub slip_radps: f64,
    /// Clutch disk temperature θ_c (°C).
    pub theta_c: f64,
    /// Pressure-plate temperature of this clutch (°C) (facing on the plate side).
    pub theta_pp: f64,
    /// Central-disk temperature (°C) (facing on the central-disk side).
    pub theta_cd: f64,
    /// Friction energy dissipated by this clutch so far (J) (e.g. for wear).
    pub e_fric_j: f64,
}

/// Extension points for effects the nominal model does not have. Every method defaults to the
/// nominal physics.
pub trait Hooks {
    /// Torque of a slipping clutch (N·m, sign of the slip). Nominal: (13).
    fn clutch_torque(&self, p: &ClutchParams, c: &ClutchContext) -> f64 {
        clutch::torque(p, c.x_to_mm, c.slip_radps, c.theta_c)
    }
    /// Static capacity of a locked clutch (N·m). Nominal: 2·R_μ(0, θ)·F.
    fn clutch_capacity(&self, p: &ClutchParams, c: &ClutchContext) -> f64 {
        clutch::capacity(p, c.x_to_mm, c.theta_c)
    }
    /// β of the thermal model (1 when not open). Nominal: u_fs > 0.
    fn clutch_beta(&self, p: &ClutchParams, c: &ClutchContext) -> f64 {
        thermal::beta(p, c.x_to_mm, c.theta_c)
    }
    /// Engine torque command after the nominal map (N·m), e.g. a map error.
    fn engine_command(&self, nominal_nm: f64, _w_f_radps: f64) -> f64 {
        nominal_nm
    }
    /// Extra temperature rates (°C/s) added to (16), e.g. conduction to the supports.
    fn extra_heat(&self, _s: &Thermal5State, _u: &ThermalInputs) -> Thermal5State {
        Thermal5State::default()
    }
}

/// The nominal model: no effects.
#[derive(Debug, Clone, Copy, Default)]
pub struct Nominal;
impl Hooks for Nominal {}

/// Event counters (cumulative).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct EventCounts {
    /// Lock events per clutch.
    pub locks: [u32; 2],
    /// Break-away events per clutch.
    pub unlocks: [u32; 2],
    /// Dog engagements per shaft (odd, even).
    pub gear_engagements: [u32; 2],
}

/// Powertrain state. Continuous fields are integrated; `lock*`, `gear_*` and `events` are
/// discrete and change only at events inside [`Powertrain::step`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct State {
    /// Simulated time (s).
    pub t_s: f64,
    /// Flywheel = engine speed ω_f (rad/s).
    pub w_f: f64,
    /// Odd clutch disk / input shaft speed ω_c1 (rad/s).
    pub w_c1: f64,
    /// Even clutch disk / input shaft speed ω_c2 (rad/s).
    pub w_c2: f64,
    /// Output (wheel) speed ω_out (rad/s).
    pub w_out: f64,
    /// Bearing position of clutch 1 (mm).
    pub x1_mm: f64,
    /// Bearing position of clutch 2 (mm).
    pub x2_mm: f64,
    /// Engine torque after the first-order lag (N·m).
    pub engine_torque_nm: f64,
    /// Idle-governor integral (N·m).
    pub idle_int_nm: f64,
    /// Temperatures of (16).
    pub thermal: Thermal5State,
    /// Engine work ∫T_e·ω_f dt (J).
    pub e_engine_j: f64,
    /// Friction work of clutch 1 ∫T_fc1·ω_fc1 dt (J).
    pub e_fric1_j: f64,
    /// Friction work of clutch 2 (J).
    pub e_fric2_j: f64,
    /// Synchroniser and dog-engagement losses (J).
    pub e_sync_j: f64,
    /// Work against the road load, grade and brake ∫T_load·ω_out dt (J).
    pub e_load_j: f64,
    /// Distance travelled (m).
    pub distance_m: f64,
    /// Clutch 1 locked (stick).
    pub lock1: bool,
    /// Clutch 2 locked (stick).
    pub lock2: bool,
    /// Odd-shaft gear selector.
    pub gear_odd: GearShaft,
    /// Even-shaft gear selector.
    pub gear_even: GearShaft,
    /// Event counters.
    pub events: EventCounts,
}

impl State {
    /// Vehicle at rest, engine at `engine_rpm`, both clutches open (x = 0), both shafts in
    /// neutral, odd/even input shafts at rest, all temperatures at `theta_c`.
    pub fn at_rest(engine_rpm: f64, theta_c: f64) -> State {
        State {
            t_s: 0.0,
            w_f: engine_rpm * engine::RPM,
            w_c1: 0.0,
            w_c2: 0.0,
            w_out: 0.0,
            x1_mm: 0.0,
            x2_mm: 0.0,
            engine_torque_nm: 0.0,
            idle_int_nm: 0.0,
            thermal: Thermal5State::uniform(theta_c),
            e_engine_j: 0.0,
            e_fric1_j: 0.0,
            e_fric2_j: 0.0,
            e_sync_j: 0.0,
            e_load_j: 0.0,
            distance_m: 0.0,
            lock1: false,
            lock2: false,
            gear_odd: GearShaft::default(),
            gear_even: GearShaft::default(),
            events: EventCounts::default(),
        }
    }

    /// Speeds as an array in body order (f, c1, c2, out).
    pub fn speeds(&self) -> [f64; 4] {
        [self.w_f, self.w_c1, self.w_c2, self.w_out]
    }

    fn set_speeds(&mut self, w: [f64; 4]) {
        self.w_f = w[F];
        self.w_c1 = w[C1];
        self.w_c2 = w[C2];
        self.w_out = w[OUT];
    }

    /// Slip of clutch `i` (0 or 1), ω_f − ω_ci (rad/s).
    pub fn slip(&self, i: usize) -> f64 {
        if i == 0 {
            self.w_f - self.w_c1
        } else {
            self.w_f - self.w_c2
        }
    }

    pub fn locked(&self, i: usize) -> bool {
        if i == 0 {
            self.lock1
        } else {
            self.lock2
        }
    }

    fn set_locked(&mut self, i: usize, v: bool) {
        if i == 0 {
            self.lock1 = v
        } else {
            self.lock2 = v
        }
    }

    /// Kinetic energy of the four bodies (J).
    pub fn kinetic_energy(&self, p: &Params) -> f64 {
        let j = driveline::inertias(&p.driveline);
        let w = self.speeds();
        0.5 * (0..4).map(|i| j[i] * w[i] * w[i]).sum::<f64>()
    }
}

impl OdeState for State {
    fn axpy(&self, k: f64, d: &Self) -> Self {
        State {
            t_s: self.t_s + k * d.t_s,
            w_f: self.w_f + k * d.w_f,
            w_c1: self.w_c1 + k * d.w_c1,
            w_c2: self.w_c2 + k * d.w_c2,
            w_out: self.w_out + k * d.w_out,
            x1_mm: self.x1_mm + k * d.x1_mm,
            x2_mm: self.x2_mm + k * d.x2_mm,
            engine_torque_nm: self.engine_torque_nm + k * d.engine_torque_nm,
            idle_int_nm: self.idle_int_nm + k * d.idle_int_nm,
            thermal: self.thermal.axpy(k, &d.thermal),
            e_engine_j: self.e_engine_j + k * d.e_engine_j,
            e_fric1_j: self.e_fric1_j + k * d.e_fric1_j,
            e_fric2_j: self.e_fric2_j + k * d.e_fric2_j,
            e_sync_j: self.e_sync_j + k * d.e_sync_j,
            e_load_j: self.e_load_j + k * d.e_load_j,
            distance_m: self.distance_m + k * d.distance_m,
            ..*self
        }
    }
}

/// Inputs held constant over a step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Inputs {
    /// Clutch 1 actuator request (mm).
    pub x1_ref_mm: f64,
    /// Clutch 2 actuator request (mm).
    pub x2_ref_mm: f64,
    /// Odd-shaft gear request (N, 1, 3, 5; an even gear or reverse here means neutral).
    pub gear_odd_req: Gear,
    /// Even-shaft gear request (N, 2, 4, 6, R; an odd gear here means neutral).
    pub gear_even_req: Gear,
    /// Accelerator pedal, fraction 0..1.
    pub pedal: f64,
    /// External engine torque request (N·m), `None` when inactive.
    pub engine_torque_request_nm: Option<f64>,
    /// Brake, fraction 0..1.
    pub brake: f64,
    /// Road grade, rise over run (0.05 = 5 % uphill).
    pub grade: f64,
    /// Housing air temperature θ_h (°C).
    pub theta_h_c: f64,
}

impl Default for Inputs {
    fn default() -> Self {
        Inputs {
            x1_ref_mm: 0.0,
            x2_ref_mm: 0.0,
            gear_odd_req: Gear::N,
            gear_even_req: Gear::N,
            pedal: 0.0,
            engine_torque_request_nm: None,
            brake: 0.0,
            grade: 0.0,
            theta_h_c: 25.0,
        }
    }
}

/// Algebraic outputs at a state (what sensors and the thermal model see).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Outputs {
    /// Engine torque T_e (N·m).
    pub t_e_nm: f64,
    /// Engine torque command before the lag (N·m).
    pub t_e_cmd_nm: f64,
    /// Torque transmitted by clutch 1 from flywheel to disk (N·m): (13) when slipping, the
    /// constraint torque when locked.
    pub t_fc1_nm: f64,
    /// Same for clutch 2.
    pub t_fc2_nm: f64,
    /// Slips ω_f − ω_c (rad/s).
    pub slip1_radps: f64,
    pub slip2_radps: f64,
    /// Friction powers T_fc·ω_fc (W).
    pub p_fric1_w: f64,
    pub p_fric2_w: f64,
    /// Static capacities 2·R_μ(0, θ)·F (N·m).
    pub capacity1_nm: f64,
    pub capacity2_nm: f64,
    /// Thermal contact flags.
    pub beta1: f64,
    pub beta2: f64,
    /// Load, grade and brake torque at the wheels (N·m).
    pub t_load_nm: f64,
    /// Synchroniser torques on the input shafts (N·m).
    pub t_sync_odd_nm: f64,
    pub t_sync_even_nm: f64,
    /// Synchroniser power loss (W).
    pub p_sync_w: f64,
    /// Body accelerations (f, c1, c2, out) (rad/s²).
    pub acc: [f64; 4],
    /// Vehicle speed (m/s) and acceleration (m/s²).
    pub vehicle_speed_mps: f64,
    pub vehicle_accel_mps2: f64,
    /// Idle-governor integral rate (N·m/s).
    pub idle_int_rate: f64,
}

/// What happened in one [`Powertrain::step`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepReport {
    /// Outputs at the end of the step (left at the default by [`Powertrain::advance`]).
    pub outputs: Outputs,
    /// Clutches that locked / broke away during the step.
    pub locked: [bool; 2],
    pub unlocked: [bool; 2],
    /// Shafts whose gear engaged during the step.
    pub engaged: [bool; 2],
    /// Events located inside the step.
    pub events: u32,
}

/// The powertrain model with its parameters and hooks.
#[derive(Debug, Clone)]
pub struct Powertrain<H: Hooks = Nominal> {
    pub p: Params,
    pub hooks: H,
    thermal: Thermal5,
    j: [f64; 4],
}

impl Powertrain<Nominal> {
    /// Nominal model.
    pub fn new(p: Params) -> Self {
        Self::with_hooks(p, Nominal)
    }
}

impl<H: Hooks> Powertrain<H> {
    /// Model with reality-effect hooks.
    pub fn with_hooks(p: Params, hooks: H) -> Self {
        Powertrain {
            p,
            hooks,
            thermal: Thermal5::new(p.thermal5),
            j: driveline::inertias(&p.driveline),
        }
    }

    /// Inertias (f, c1, c2, out) (kg·m²).
    pub fn inertias(&self) -> [f64; 4] {
        self.j
    }

    fn links(&self, s: &State) -> Links {
        let k = |g: &GearShaft| driveline::overall_ratio(&self.p.driveline, g.engaged);
        Links {
            clutch1: s.lock1,
            clutch2: s.lock2,
            k_odd: k(&s.gear_odd),
            k_even: k(&s.gear_even),
        }
    }

    fn groups(&self, s: &State) -> Groups {
        let mut l = self.links(s);
        match Groups::new(l) {
            Ok(g) => g,
            Err(_) => {
                // `step` never leaves a tie-up; for a hand-made state, release clutch 2.
                l.clutch2 = false;
                Groups::new(l).unwrap_or_else(|_| {
                    Groups::new(Links::default()).expect("no links never tie up")
                })
            }
        }
    }

    /// Context of clutch `i` at state `s`.
    pub fn clutch_context(&self, s: &State, i: usize) -> ClutchContext {
        let (x, th, pp, e) = if i == 0 {
            (s.x1_mm, s.thermal.c1, s.thermal.pp1, s.e_fric1_j)
        } else {
            (s.x2_mm, s.thermal.c2, s.thermal.pp2, s.e_fric2_j)
        };
        ClutchContext {
            clutch: i,
            x_to_mm: x,
            slip_radps: s.slip(i),
            theta_c: th,
            theta_pp: pp,
            theta_cd: s.thermal.cd,
            e_fric_j: e,
        }
    }

    /// What holds over an integration step: the rigid groups of the links (locks and gears change
    /// only at events, never between RK4 stages) and the grade torque of the held inputs.
    fn frozen(&self, s: &State, u: &Inputs) -> Frozen {
        Frozen {
            g: self.groups(s),
            grade_nm: self.grade_torque(u),
        }
    }

    /// Grade torque of the inputs (N·m); a non-finite grade counts as level.
    fn grade_torque(&self, u: &Inputs) -> f64 {
        let grade = if u.grade.is_finite() { u.grade } else { 0.0 };
        driveline::grade_torque(&self.p.driveline, grade)
    }

    /// The step's invariants at `s` for the grade torque `grade_nm`, reusing `last` while the
    /// links are those of `s` (they change only at lock, break-away and gear events).
    fn frozen_at(&self, s: &State, grade_nm: f64, last: &mut Option<Frozen>) -> Frozen {
        if let Some(f) = *last {
            if f.g.links == self.links(s) {
                return f;
            }
        }
        let f = Frozen {
            g: self.groups(s),
            grade_nm,
        };
        *last = Some(f);
        f
    }

    /// The torques, accelerations and powers at a state: what the derivative and the outputs
    /// share.
    fn forces(&self, fz: &Frozen, s: &State, u: &Inputs) -> Forces {
        let p = &self.p;
        let g = &fz.g;
        let w = s.speeds();
        let slips = driveline::slips(&w);
        let ctx = [self.clutch_context(s, 0), self.clutch_context(s, 1)];
        let locked = [g.links.clutch1, g.links.clutch2];
        let mut tc = [0.0; 2];
        for i in 0..2 {
            if !locked[i] {
                tc[i] = self.hooks.clutch_torque(&p.clutch, &ctx[i]);
            }
        }
        // Synchronisers.
        let sync = |gs: &GearShaft, w_c: f64| -> (f64, f64) {
            if gs.syncing() {
                if let Some(k) = driveline::overall_ratio(&p.driveline, gs.target) {
                    return (driveline::sync_torque(&p.driveline, w_c, k, w[OUT]), k);
                }
            }
            (0.0, 0.0)
        };
        let (ts_odd, k_so) = sync(&s.gear_odd, w[C1]);
        let (ts_even, k_se) = sync(&s.gear_even, w[C2]);
        let p_sync = -(ts_odd * (w[C1] - k_so * w[OUT]) + ts_even * (w[C2] - k_se * w[OUT]));
        // Engine.
        let ein = EngineInputs {
            pedal: u.pedal,
            torque_request_nm: u.engine_torque_request_nm,
        };
        let (cmd, di) = engine::command(&p.engine, w[F], s.idle_int_nm, &ein);
        let cmd = self.hooks.engine_command(cmd, w[F]);
        let t_e = s.engine_torque_nm;
        // Load.
        let t_load = driveline::load_torque_graded(&p.driveline, w[OUT], fz.grade_nm, u.brake);
        // External torques per body and accelerations.
        let t = [
            t_e - tc[0] - tc[1],
            tc[0] + ts_odd,
            tc[1] + ts_even,
            -t_load - k_so * ts_odd - k_se * ts_even,
        ];
        let acc = g.accelerations(&self.j, &t);
        for i in 0..2 {
            if locked[i] {
                tc[i] = g.link_torque(i, &self.j, &t, &acc);
            }
        }
        let p_fric = [
            if locked[0] { 0.0 } else { tc[0] * slips[0] },
            if locked[1] { 0.0 } else { tc[1] * slips[1] },
        ];
        let beta = [
            self.hooks.clutch_beta(&p.clutch, &ctx[0]),
            self.hooks.clutch_beta(&p.clutch, &ctx[1]),
        ];
        Forces {
            w,
            slips,
            ctx,
            tc,
            ts_odd,
            ts_even,
            p_sync,
            cmd,
            di,
            t_e,
            t_load,
            acc,
            p_fric,
            beta,
        }
    }

    /// Time derivative of the continuous state from its forces (discrete fields copied).
    fn derivative_from(&self, s: &State, u: &Inputs, fc: &Forces) -> State {
        let p = &self.p;
        let tin = ThermalInputs {
            p_fric1_w: fc.p_fric[0],
            p_fric2_w: fc.p_fric[1],
            beta1: fc.beta[0],
            beta2: fc.beta[1],
            theta_h_c: u.theta_h_c,
            w_f_radps: fc.w[F],
        };
        let mut dth = self.thermal.derivative(&s.thermal, &tin);
        let extra = self.hooks.extra_heat(&s.thermal, &tin);
        dth = dth.axpy(1.0, &extra);
        let rw = p.driveline.wheel_radius_m;
        State {
            t_s: 1.0,
            w_f: fc.acc[F],
            w_c1: fc.acc[C1],
            w_c2: fc.acc[C2],
            w_out: fc.acc[OUT],
            x1_mm: actuator::derivative(&p.actuator, s.x1_mm, u.x1_ref_mm),
            x2_mm: actuator::derivative(&p.actuator, s.x2_mm, u.x2_ref_mm),
            engine_torque_nm: engine::torque_rate(&p.engine, fc.t_e, fc.cmd),
            idle_int_nm: fc.di,
            thermal: dth,
            e_engine_j: fc.t_e * fc.w[F],
            e_fric1_j: fc.p_fric[0],
            e_fric2_j: fc.p_fric[1],
            e_sync_j: fc.p_sync,
            e_load_j: fc.t_load * fc.w[OUT],
            distance_m: rw * fc.w[OUT],
            ..*s
        }
    }

    /// Algebraic outputs from the forces (the static capacities are computed here only).
    fn outputs_from(&self, fc: &Forces) -> Outputs {
        let p = &self.p;
        let rw = p.driveline.wheel_radius_m;
        let capacity = [
            self.hooks.clutch_capacity(&p.clutch, &fc.ctx[0]),
            self.hooks.clutch_capacity(&p.clutch, &fc.ctx[1]),
        ];
        Outputs {
            t_e_nm: fc.t_e,
            t_e_cmd_nm: fc.cmd,
            t_fc1_nm: fc.tc[0],
            t_fc2_nm: fc.tc[1],
            slip1_radps: fc.slips[0],
            slip2_radps: fc.slips[1],
            p_fric1_w: fc.p_fric[0],
            p_fric2_w: fc.p_fric[1],
            capacity1_nm: capacity[0],
            capacity2_nm: capacity[1],
            beta1: fc.beta[0],
            beta2: fc.beta[1],
            t_load_nm: fc.t_load,
            t_sync_odd_nm: fc.ts_odd,
            t_sync_even_nm: fc.ts_even,
            p_sync_w: fc.p_sync,
            acc: fc.acc,
            vehicle_speed_mps: rw * fc.w[OUT],
            vehicle_accel_mps2: rw * fc.acc[OUT],
            idle_int_rate: fc.di,
        }
    }

    /// Derivative and outputs at a state.
    pub fn eval(&self, s: &State, u: &Inputs) -> (State, Outputs) {
        let fc = self.forces(&self.frozen(s, u), s, u);
        (self.derivative_from(s, u, &fc), self.outputs_from(&fc))
    }

    /// Time derivative of the continuous state (discrete fields copied).
    pub fn derivative(&self, s: &State, u: &Inputs) -> State {
        self.derivative_in(&self.frozen(s, u), s, u)
    }

    /// The derivative with the step's invariants given (one per RK4 stage).
    #[inline]
    fn derivative_in(&self, fz: &Frozen, s: &State, u: &Inputs) -> State {
        self.derivative_from(s, u, &self.forces(fz, s, u))
    }

    /// Algebraic outputs at a state.
    pub fn outputs(&self, s: &State, u: &Inputs) -> Outputs {
        self.outputs_from(&self.forces(&self.frozen(s, u), s, u))
    }

    /// Locks clutch `i` if the links allow it and the torque needed to stay locked is within the
    /// static capacity; projects the speeds and books the lost kinetic energy as friction heat.
    fn try_lock(&self, s: &mut State, u: &Inputs, i: usize) -> bool {
        let mut trial = *s;
        trial.set_locked(i, true);
        let Ok(g) = Groups::new(self.links(&trial)) else {
            return false;
        };
        let (w, loss) = g.project(&self.j, &s.speeds());
        trial.set_speeds(w);
        let out = self.outputs(&trial, u);
        let (need, cap) = if i == 0 {
            (out.t_fc1_nm, out.capacity1_nm)
        } else {
            (out.t_fc2_nm, out.capacity2_nm)
        };
        if need.abs() > cap {
            return false;
        }
        self.book_friction_loss(&mut trial, i, loss);
        trial.events.locks[i] += 1;
        *s = trial;
        true
    }

    fn book_friction_loss(&self, s: &mut State, i: usize, loss: f64) {
        let a = &self.p.thermal5;
        if i == 0 {
            s.e_fric1_j += loss;
            s.thermal.pp1 += a.alpha3_k_per_j * loss;
            s.thermal.c1 += a.alpha7_k_per_j * loss;
        } else {
            s.e_fric2_j += loss;
            s.thermal.pp2 += a.alpha3_k_per_j * loss;
            s.thermal.c2 += a.alpha7_k_per_j * loss;
        }
        s.thermal.cd += a.alpha9_k_per_j * loss;
    }

    /// Gear selectors: requests, select timers, dog engagement when synchronised.
    fn update_gears(&self, s: &mut State, u: &Inputs, dt: f64, rep: &mut StepReport) {
        // A gear of the other shaft cannot be selected here: the fork stays in neutral.
        let on = |g: Gear, shaft: usize| if g.shaft() == Some(shaft) { g } else { Gear::N };
        s.gear_odd.request(on(u.gear_odd_req, 0));
        s.gear_even.request(on(u.gear_even_req, 1));
        for shaft in 0..2 {
            let gs = if shaft == 0 { s.gear_odd } else { s.gear_even };
            if !gs.syncing() {
                continue;
            }
            let mut gs2 = gs;
            gs2.timer_s += dt;
            let k = driveline::overall_ratio(&self.p.driveline, gs.target).unwrap_or(0.0);
            let w_c = if shaft == 0 { s.w_c1 } else { s.w_c2 };
            let ready = gs2.timer_s >= self.p.driveline.gear_select_time_s
                && (w_c - k * s.w_out).abs() <= self.p.driveline.sync_tolerance_radps;
            if ready {
                gs2.engaged = gs2.target;
            }
            if shaft == 0 {
                s.gear_odd = gs2
            } else {
                s.gear_even = gs2
            }
            if ready {
                // Engaging with this shaft's clutch locked while the other path is also closed
                // would tie the gearbox up: that clutch is released.
                if Groups::new(self.links(s)).is_err() && s.locked(shaft) {
                    s.set_locked(shaft, false);
                    s.events.unlocks[shaft] += 1;
                    rep.unlocked[shaft] = true;
                }
                let g = self.groups(s);
                let (w, loss) = g.project(&self.j, &s.speeds());
                s.set_speeds(w);
                s.e_sync_j += loss;
                s.events.gear_engagements[shaft] += 1;
                rep.engaged[shaft] = true;
            }
        }
    }

    /// Break-away: a locked clutch whose needed torque exceeds its static capacity slips.
    /// Returns the forces at the final `s` when it computed them (a clutch still locked), for the
    /// step's first RK4 stage.
    fn check_breakaway(
        &self,
        s: &mut State,
        u: &Inputs,
        grade_nm: f64,
        fz: &mut Option<Frozen>,
        rep: &mut StepReport,
    ) -> Option<Forces> {
        for _ in 0..2 {
            if !s.locked(0) && !s.locked(1) {
                return None;
            }
            let fc = self.forces(&self.frozen_at(s, grade_nm, fz), s, u);
            let out = self.outputs_from(&fc);
            let mut changed = false;
            for i in 0..2 {
                let (need, cap) = if i == 0 {
                    (out.t_fc1_nm, out.capacity1_nm)
                } else {
                    (out.t_fc2_nm, out.capacity2_nm)
                };
                if s.locked(i) && need.abs() > cap {
                    s.set_locked(i, false);
                    s.events.unlocks[i] += 1;
                    rep.unlocked[i] = true;
                    changed = true;
                    break;
                }
            }
            if !changed {
                return Some(fc);
            }
        }
        None
    }

    /// Advances the state by `dt` seconds with the inputs held: gear events and break-away at the
    /// start, RK4 with the step split at each located slip zero crossing (lock events).
    pub fn step(&self, s: &mut State, u: &Inputs, dt: f64) -> StepReport {
        let mut rep = self.advance(s, u, dt);
        rep.outputs = self.outputs(s, u);
        rep
    }

    /// [`Self::step`] without the end-of-step outputs (`outputs` left at its default): for a
    /// caller that needs them only when a frame is due ([`Self::outputs`] then).
    pub fn advance(&self, s: &mut State, u: &Inputs, dt: f64) -> StepReport {
        let mut rep = StepReport::default();
        if !(dt.is_finite() && dt > 0.0) {
            return rep;
        }
        self.update_gears(s, u, dt, &mut rep);
        // The groups of the links, rebuilt only when an event changes them.
        let mut last = None;
        let grade_nm = self.grade_torque(u);
        // The forces at the step's start, when the break-away check computed them and nothing
        // changed the state since: RK4's first stage reuses them (the same numbers).
        let mut start = self.check_breakaway(s, u, grade_nm, &mut last, &mut rep);
        // A slipping clutch sitting exactly at zero slip may lock at once.
        for i in 0..2 {
            if !s.locked(i) && s.slip(i) == 0.0 && self.try_lock(s, u, i) {
                rep.locked[i] = true;
                start = None;
            }
        }
        let max_events = self.p.integrator.max_events_per_step as u32;
        let mut h_left = dt;
        let mut skip = [false; 2];
        loop {
            let s0 = *s;
            // The links hold over the step: one set of groups for d0 and the RK4 stages, and d0
            // (the slip rates for event location) is RK4's first stage.
            let fz = self.frozen_at(&s0, grade_nm, &mut last);
            let f = |x: &State| self.derivative_in(&fz, x, u);
            let d0 = match start.take() {
                Some(fc) => self.derivative_from(&s0, u, &fc),
                None => f(&s0),
            };
            let s1 = rk4_step_from(&s0, &d0, h_left, f);
            let first = first_slip_crossing(&s0, &s1, &d0, h_left, skip);
            match first {
                Some((i, frac)) if rep.events < max_events => {
                    let h1 = frac * h_left;
                    *s = if h1 > 0.0 {
                        rk4_step_from(&s0, &d0, h1, f)
                    } else {
                        s0
                    };
                    h_left -= h1;
                    rep.events += 1;
                    let (a, a1) = (s0.slip(i), s.slip(i));
                    if a * a1 <= 0.0 || a1.abs() <= 0.05 * a.abs() {
                        if self.try_lock(s, u, i) {
                            rep.locked[i] = true;
                        } else {
                            skip[i] = true;
                        }
                    }
                    if h_left <= 1e-12 * dt {
                        break;
                    }
                }
                _ => {
                    *s = s1;
                    break;
                }
            }
        }
        // Remove round-off drift from the rigid links.
        let fz = self.frozen_at(s, grade_nm, &mut last);
        let (w, _) = fz.g.project(&self.j, &s.speeds());
        s.set_speeds(w);
        rep
    }
}

/// Earliest predicted zero crossing of a slipping clutch (not `skip`ped) over the step `h` from
/// `s0` (slip rates `d0`) to `s1`: the clutch and the fraction of the step. From the RK4 end point
/// (sign change) or from the slip rate at the start (the cube-root friction makes RK4's own
/// stages straddle zero, so the end point alone can miss a crossing).
#[inline]
fn first_slip_crossing(
    s0: &State,
    s1: &State,
    d0: &State,
    h: f64,
    skip: [bool; 2],
) -> Option<(usize, f64)> {
    let mut first: Option<(usize, f64)> = None;
    for (i, &skipped) in skip.iter().enumerate() {
        if s0.locked(i) || skipped {
            continue;
        }
        let (a, b) = (s0.slip(i), s1.slip(i));
        let rate = d0.w_f - if i == 0 { d0.w_c1 } else { d0.w_c2 };
        let mut frac = f64::INFINITY;
        if a == 0.0 {
            frac = 0.0;
        } else {
            if a * b < 0.0 || b == 0.0 {
                frac = a / (a - b);
            }
            if a * rate < 0.0 && a.abs() <= h * rate.abs() {
                frac = frac.min(-a / rate / h);
            }
        }
        if frac.is_finite() && first.is_none_or(|(_, f)| frac < f) {
            first = Some((i, frac.clamp(0.0, 1.0)));
        }
    }
    first
}

impl<H: Hooks> OdeSystem for Powertrain<H> {
    type State = State;
    type Input = Inputs;
    fn derivative(&self, x: &State, u: &Inputs) -> State {
        Powertrain::derivative(self, x, u)
    }
}

/// The invariants of one integration step (see [`Powertrain::step`]).
#[derive(Debug, Clone, Copy)]
struct Frozen {
    g: Groups,
    /// Grade torque at the wheels (N·m).
    grade_nm: f64,
}

/// Torques, accelerations and powers at a state.
#[derive(Debug, Clone, Copy)]
struct Forces {
    w: [f64; 4],
    slips: [f64; 2],
    ctx: [ClutchContext; 2],
    /// Clutch torques: (13) when slipping, the link torque when locked (N·m).
    tc: [f64; 2],
    ts_odd: f64,
    ts_even: f64,
    p_sync: f64,
    /// Engine torque command after the hooks (N·m) and the idle-integral rate.
    cmd: f64,
    di: f64,
    t_e: f64,
    t_load: f64,
    acc: [f64; 4],
    p_fric: [f64; 2],
    beta: [f64; 2],
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> Powertrain {
        Powertrain::new(Params::default())
    }

    /// A slipping clutch 1 (engaged past its kiss point, 1 500 rpm of slip), clutch 2 open, the
    /// engine pulling, the brake on.
    fn slipping() -> (State, Inputs) {
        let mut s = State::at_rest(2000.0, 80.0);
        s.x1_mm = 6.0;
        s.w_c1 = 500.0 * engine::RPM;
        s.w_out = 3.0;
        s.engine_torque_nm = 120.0;
        let u = Inputs {
            x1_ref_mm: 6.0,
            pedal: 0.4,
            brake: 0.2,
            ..Inputs::default()
        };
        (s, u)
    }

    /// Newton for a flywheel alone: with both clutches open and both shafts in neutral, the
    /// engine's torque accelerates the flywheel by T_e / J_f and nothing else moves it.
    #[test]
    fn an_open_driveline_leaves_the_flywheel_to_the_engine_alone() {
        let m = model();
        let mut s = State::at_rest(1500.0, 40.0);
        s.engine_torque_nm = 80.0;
        let d = m.derivative(&s, &Inputs::default());
        let j = driveline::inertias(&m.p.driveline);
        assert!(
            (d.w_f - 80.0 / j[F]).abs() < 1e-12 * (80.0 / j[F]),
            "{}",
            d.w_f
        );
        assert_eq!((d.w_c1, d.w_c2), (0.0, 0.0));
        assert_eq!((d.e_fric1_j, d.e_fric2_j), (0.0, 0.0));
    }

    /// The power balance of the derivative itself: the kinetic energy's rate Σ J·ω·dω/dt equals
    /// the engine's power minus the friction, synchroniser and load powers the state integrates.
    #[test]
    fn the_energy_rates_balance_the_kinetic_energy_rate() {
        let m = model();
        let (s, u) = slipping();
        let d = m.derivative(&s, &u);
        assert!(
            d.e_fric1_j > 1000.0,
            "the clutch slips with torque: {}",
            d.e_fric1_j
        );
        let j = driveline::inertias(&m.p.driveline);
        let w = s.speeds();
        let a = [d.w_f, d.w_c1, d.w_c2, d.w_out];
        let ke_rate: f64 = (0..4).map(|i| j[i] * w[i] * a[i]).sum();
        let balance = d.e_engine_j - d.e_fric1_j - d.e_fric2_j - d.e_sync_j - d.e_load_j;
        assert!(
            (ke_rate - balance).abs() < 1e-9 * d.e_engine_j.abs(),
            "dKE/dt {ke_rate} W, balance {balance} W"
        );
    }

    /// The kinetic energy is ½·J·ω² of each body: a spinning flywheel alone, then every body.
    #[test]
    fn kinetic_energy_is_half_j_omega_squared() {
        let p = Params::default();
        let j = driveline::inertias(&p.driveline);
        let s = State::at_rest(3000.0, 25.0);
        let w = 3000.0 * engine::RPM;
        assert!((s.kinetic_energy(&p) - 0.5 * j[F] * w * w).abs() < 1e-9);
        let (s, _) = slipping();
        let expected = 0.5
            * (j[F] * s.w_f.powi(2)
                + j[C1] * s.w_c1.powi(2)
                + j[C2] * s.w_c2.powi(2)
                + j[OUT] * s.w_out.powi(2));
        assert!((s.kinetic_energy(&p) - expected).abs() < 1e-9 * expected);
    }

    /// A clutch that slips heats: the friction power is the clutch torque times the slip, and
    /// positive whichever way it slips.
    #[test]
    fn friction_power_is_torque_times_slip_and_never_negative() {
        let m = model();
        let (mut s, u) = slipping();
        for w_c1 in [0.0, 100.0, 300.0, 400.0] {
            s.w_c1 = w_c1;
            let (d, o) = m.eval(&s, &u);
            assert!(
                (o.p_fric1_w - o.t_fc1_nm * o.slip1_radps).abs()
                    < 1e-9 * o.p_fric1_w.abs().max(1.0)
            );
            assert!(o.p_fric1_w >= 0.0, "{w_c1}: {}", o.p_fric1_w);
            assert_eq!(d.e_fric1_j, o.p_fric1_w);
        }
    }
}

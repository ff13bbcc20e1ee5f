//! Launch and shift strategy on top of the decoupling controller (`control`, (23)–(27)).
//!
//! Modes (reported as `TcuState`):
//! - **Neutral** (lever P/N): both clutches wait just before their kiss point, gear 1 (or R) and
//!   its neighbour preselected.
//! - **Creep** (lever D/R, pedal released): with the brake on at standstill the start clutch waits
//!   at its kiss point; otherwise the clutch-speed loop PI_c + (27) drives the clutch shaft toward
//!   idle speed minus a creep slip with a limited torque, the engine on its own idle governor.
//! - **Launch** (pedal pressed): engine-speed target from the pedal, clutch-speed reference with a
//!   pedal-dependent acceleration (ramped in with a jerk limit). PI_c + (27) give T_fc,ref and the
//!   inverse of (13) gives x_to,ref; PI_e + (24) give the engine torque request. When the slip to
//!   the engine's profile falls to `sync_slip_radps` a synchronisation phase brings the slip to
//!   zero along s(τ) = (s0 + δ)(1 − τ/T)² − δ with T = 2 s0/α (continuous slip rate at its start,
//!   zero slip rate at lock-up: the engine and clutch accelerations match, so there is no jolt).
//! - **Drive**: lock-up detected (|slip| below a threshold for a few cycles), the clutch is clamped
//!   with capacity (1 + margin)·|T_e| + offset (raised at once, lowered at a rate), the engine
//!   request blends to the driver's demand and is then released. The other shaft preselects the
//!   next gear; the shift schedule (vehicle speed × pedal tables) decides up- and downshifts.
//! - **Upshift** (clutch to clutch): torque phase (on-coming torque ramps up to the transmitted
//!   torque while the off-going capacity ramps to zero), then inertia phase (off-going open, the
//!   on-coming clutch carries the driver's torque and PI_e with an engine torque request pulls the
//!   engine down to the new shaft along a smoothstep slip profile), lock-up, Drive.
//! - **Downshift**: inertia phase first (the off-going clutch keeps part of the demand while the
//!   engine torque request raises the engine to the new shaft's speed), then the torque phase
//!   hands over to the on-coming clutch, lock-up, Drive.
//!
//! Everything is computed from measurements and the estimated temperatures; time is an argument.

use super::config::{LaunchCfg, TcuConfig};
use super::control::{
    approach, driver_demand, engine_range, load_estimate, ClutchModel, Pi, Reduced,
};
use super::inputs::Measurements;
use crate::can::messages::{GearLever, TcuState};
use crate::model::driveline;
use crate::model::engine::RPM;
use crate::model::gear::Gear;

/// What the strategy asks for in one cycle.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Command {
    /// Bearing position requests (mm).
    pub x_ref: [f64; 2],
    /// Clutch torque references (N·m): slipping clutches T_fc,ref, clamped clutches the capacity.
    pub t_ref: [f64; 2],
    /// Engine torque request, `None` when released.
    pub engine_req: Option<f64>,
    /// Gear requests (odd, even shaft).
    pub gear_req: [Gear; 2],
    /// Gear transmitting torque (`N` when none).
    pub gear_active: Gear,
    pub state: TcuState,
    /// References for diagnostics (rad/s).
    pub w_e_ref: f64,
    pub w_c_ref: f64,
    /// Short name of the phase, for traces.
    pub phase: &'static str,
}

/// Inputs of one strategy step.
#[derive(Debug, Clone, Copy)]
pub struct Ctx<'a> {
    pub cfg: &'a TcuConfig,
    pub model: &'a ClutchModel,
    pub m: &'a Measurements,
    /// Estimated clutch temperatures (°C).
    pub theta: [f64; 2],
    /// Time since the previous step (s).
    pub dt: f64,
    /// Filtered output-shaft acceleration (rad/s²).
    pub w_out_dot: f64,
    /// Over-temperature torque limitation active.
    pub limit_torque: bool,
}

impl Ctx<'_> {
    fn reduced(&self) -> Reduced {
        Reduced::new(&self.cfg.physics.driveline, self.m.gear[0], self.m.gear[1])
    }
    fn k(&self, gear: Gear) -> f64 {
        driveline::overall_ratio(&self.cfg.physics.driveline, gear).unwrap_or(0.0)
    }
    /// Vehicle speed (km/h, signed).
    fn v_kmh(&self) -> f64 {
        self.m.w_out * self.cfg.physics.driveline.wheel_radius_m * 3.6
    }
    fn idle(&self) -> f64 {
        self.cfg.physics.engine.idle_speed_rpm * RPM
    }
    fn demand(&self) -> f64 {
        let d = driver_demand(&self.cfg.physics.engine, self.m.pedal, self.m.w_e);
        if self.limit_torque {
            d.min(self.cfg.safety.over_temp_engine_torque_nm)
        } else {
            d
        }
    }
    fn load(&self) -> f64 {
        load_estimate(&self.cfg.physics.driveline, self.m.w_out)
    }
    fn standby(&self, i: usize) -> f64 {
        (self.model.kiss_point(self.theta[i]) - self.cfg.control.standby_gap_mm).max(0.0)
    }
    fn engine_limits(&self) -> (f64, f64) {
        let (lo, hi) = engine_range(&self.cfg.physics.engine, self.m.w_e);
        let hi = if self.limit_torque {
            hi.min(self.cfg.safety.over_temp_engine_torque_nm)
        } else {
            hi
        };
        (lo, hi.max(lo))
    }
    fn pedal_on(&self) -> bool {
        self.m.pedal * 100.0 > self.cfg.creep.pedal_on_pct
    }
    /// Largest clutch torque reference at the measured slip.
    fn t_max(&self, i: usize) -> f64 {
        self.cfg
            .control
            .max_torque_nm
            .min(self.model.max_torque(self.m.slip(i), self.theta[i]))
            .max(0.0)
    }
    /// Position for a slipping clutch's torque reference.
    fn x_slip(&self, i: usize, t: f64) -> f64 {
        if t <= 0.0 {
            return self.standby(i);
        }
        self.model.position_for(t, self.m.slip(i), self.theta[i])
    }
    /// Position for a locked clutch's capacity reference.
    fn x_clamp(&self, i: usize, cap: f64) -> f64 {
        if cap <= 0.0 {
            return self.standby(i);
        }
        self.model.clamp_position_for(cap, self.theta[i])
    }
    /// Anti-stall limit on a slipping clutch's torque: unlimited above `safety.
    /// antistall_free_idle_fraction` of idle (95 %); below it the clutch may take at most a share
    /// of the engine's full-load torque that falls from `antistall_max_share` (90 %) there to 0 at
    /// `antistall_zero_idle_fraction` of idle (70 %), so the engine always keeps torque to recover.
    fn stall_limit(&self) -> f64 {
        let idle = self.idle();
        let s = &self.cfg.safety;
        let (free, zero) = (
            s.antistall_free_idle_fraction,
            s.antistall_zero_idle_fraction,
        );
        if self.m.w_e >= free * idle {
            return f64::INFINITY;
        }
        let share = s.antistall_max_share
            * ((self.m.w_e - zero * idle) / ((free - zero) * idle)).clamp(0.0, 1.0);
        share * crate::model::engine::full_load(&self.cfg.physics.engine, self.m.w_e)
    }
}

/// The start gear of a lever position: 1st (odd shaft) for D, reverse (even shaft) for R.
pub(crate) fn start_gear(lever: GearLever) -> Option<Gear> {
    match lever {
        GearLever::D => Some(Gear::G1),
        GearLever::R => Some(Gear::R),
        _ => None,
    }
}

/// What one shift phase commands this cycle: clutch torque references and positions, the engine
/// request and speed reference, and the phase's name.
struct PhaseOut {
    t: [f64; 2],
    x: [f64; 2],
    engine_req: Option<f64>,
    w_e_ref: f64,
    phase: &'static str,
}

impl PhaseOut {
    /// Both clutches at standby without torque, no engine request, the engine speed as measured.
    fn standby(ctx: &Ctx, phase: &'static str) -> PhaseOut {
        PhaseOut {
            t: [0.0; 2],
            x: [ctx.standby(0), ctx.standby(1)],
            engine_req: None,
            w_e_ref: ctx.m.w_e,
            phase,
        }
    }
}

/// A shift's command: its phase's references, the gears of both shafts, the active gear (the
/// new one from the upshift's inertia phase or the downshift's torque phase on) and the state.
fn shift_command(ctx: &Ctx, s: &Shift, out: &PhaseOut) -> Command {
    let mut gear_req = [Gear::N; 2];
    gear_req[s.a] = s.from;
    gear_req[s.o] = s.to;
    Command {
        x_ref: out.x,
        t_ref: out.t,
        engine_req: out.engine_req,
        gear_req,
        gear_active: if s.phase == ShiftPhase::Inertia && s.up
            || !s.up && s.phase == ShiftPhase::Torque
        {
            s.to
        } else {
            s.from
        },
        state: if s.up {
            TcuState::Upshift
        } else {
            TcuState::Downshift
        },
        w_e_ref: out.w_e_ref,
        w_c_ref: ctx.m.w_c[s.o],
        phase: out.phase,
    }
}

fn shaft(gear: Gear) -> usize {
    gear.shaft().unwrap_or(0)
}

/// Shift schedule: the gear the tables want from gear `g` at speed `v_kmh` and pedal `p` (0..1);
/// one step at a time.
pub(crate) fn scheduled_gear(cfg: &TcuConfig, g: Gear, v_kmh: f64, p: f64) -> Gear {
    let Some(n) = g.number() else {
        return g;
    };
    let s = &cfg.shift;
    let lerp = |a: f64, b: f64| a + (b - a) * p.clamp(0.0, 1.0);
    let gi = usize::from(n);
    if let Some(up) = g.up() {
        if v_kmh > lerp(s.up_kmh_0[gi - 1], s.up_kmh_100[gi - 1]) {
            return up;
        }
    }
    if let Some(down) = g.down() {
        if v_kmh < lerp(s.down_kmh_0[gi - 2], s.down_kmh_100[gi - 2]) {
            return down;
        }
    }
    g
}

/// The gear to preselect on the idle shaft while driving in `g`.
fn preselect(cfg: &TcuConfig, g: Gear, v_kmh: f64, p: f64) -> Gear {
    let (Some(n), Some(lower), Some(higher)) = (g.number(), g.down(), g.up()) else {
        // Reverse: 1st beside it; 1st (or neutral): 2nd; 6th: 5th.
        return match g {
            Gear::R => Gear::G1,
            Gear::G6 => Gear::G5,
            _ => Gear::G2,
        };
    };
    let s = &cfg.shift;
    let lerp = |a: f64, b: f64| a + (b - a) * p.clamp(0.0, 1.0);
    let gi = usize::from(n);
    let up = lerp(s.up_kmh_0[gi - 1], s.up_kmh_100[gi - 1]);
    let down = lerp(s.down_kmh_0[gi - 2], s.down_kmh_100[gi - 2]);
    if v_kmh >= 0.5 * (up + down) {
        higher
    } else {
        lower
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Sync {
    tau: f64,
    s0: f64,
    duration: f64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Launch {
    a: usize,
    gear: Gear,
    /// Clutch-shaft speed at the start (rad/s).
    w_c0: f64,
    w_c_ref: f64,
    alpha: f64,
    w_e_prof: f64,
    sync: Option<Sync>,
    lock_count: u32,
    pedal_off_s: f64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Drive {
    a: usize,
    gear: Gear,
    cap: f64,
    blend: Option<f64>,
    since_s: f64,
    slip_count: u32,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Creep {
    a: usize,
    gear: Gear,
    w_c_ref: f64,
    t_ref: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ShiftPhase {
    Torque,
    Inertia,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Shift {
    up: bool,
    /// Off-going clutch and gear.
    a: usize,
    from: Gear,
    /// On-coming clutch and gear.
    o: usize,
    to: Gear,
    phase: ShiftPhase,
    tau: f64,
    /// Torque the shift hands over (N·m, ≥ 0).
    t_tr: f64,
    /// Off-going torque at the start of the current phase.
    t_a0: f64,
    /// Slip of the on-coming clutch at the start of the inertia phase and its duration.
    s0: f64,
    duration: f64,
    lock_count: u32,
    total_s: f64,
    t_e_req: f64,
    /// Inertia phase: when the slip was released toward lock-up.
    release: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    Neutral,
    Creep(Creep),
    Launch(Launch),
    Drive(Drive),
    Shift(Shift),
}

/// The strategy's state: mode, PI controllers and the last command.
#[derive(Debug, Clone)]
pub struct Strategy {
    mode: Mode,
    pi_c: [Pi; 2],
    pi_e: Pi,
    last: Command,
    since_shift_s: f64,
    /// Previous engine feed-forward (for the lag compensation); `None` after a reset.
    ff_prev: Option<f64>,
    /// Step counter and, per clutch, the step and position of the last lead-compensated request.
    steps: u64,
    lead_prev: [Option<(u64, f64)>; 2],
}

impl Strategy {
    pub fn new(cfg: &TcuConfig) -> Self {
        let k = &cfg.control;
        Self {
            mode: Mode::Neutral,
            pi_c: [Pi::new(
                k.clutch_kp_per_s,
                k.clutch_ki_per_s2,
                k.clutch_integral_limit_nm,
            ); 2],
            pi_e: Pi::new(
                k.engine_kp_per_s,
                k.engine_ki_per_s2,
                k.engine_integral_limit_nm,
            ),
            last: Command::default(),
            since_shift_s: 1e9,
            ff_prev: None,
            steps: 0,
            lead_prev: [None; 2],
        }
    }

    /// The controller gains of `cfg` (a calibration written on the bus); the integrators keep
    /// their state.
    pub fn set_gains(&mut self, cfg: &TcuConfig) {
        let k = &cfg.control;
        for pi in &mut self.pi_c {
            pi.kp = k.clutch_kp_per_s;
            pi.ki = k.clutch_ki_per_s2;
            pi.integral_max = k.clutch_integral_limit_nm;
        }
        self.pi_e.kp = k.engine_kp_per_s;
        self.pi_e.ki = k.engine_ki_per_s2;
        self.pi_e.integral_max = k.engine_integral_limit_nm;
    }

    /// Lead on the position request of a slipping clutch, x + (τ_a + d)·ẋ, cancelling the
    /// actuator's first-order lag τ_a (the nominal actuator of the parameter file) and, to first
    /// order, the command delay d (`control.command_delay_s`), so the torque follows the
    /// inverse's position without the lag's error (it matters near lock-up, where the inverse's
    /// position rises steeply as the friction coefficient falls with the slip). Only between two
    /// consecutive requests above the kiss point.
    fn lead(&mut self, ctx: &Ctx, i: usize, x_des: f64) -> f64 {
        let kiss = ctx.model.kiss_point(ctx.theta[i]);
        let prev = self.lead_prev[i];
        self.lead_prev[i] = Some((self.steps, x_des));
        match prev {
            Some((k, p))
                if k + 1 == self.steps
                    && p > kiss
                    && x_des > kiss
                    && ctx.dt >= ctx.cfg.control.min_lead_dt_s =>
            {
                let tau = ctx.cfg.physics.actuator.tau_s + ctx.cfg.control.command_delay_s;
                x_des + tau * (x_des - p) / ctx.dt
            }
            _ => x_des,
        }
    }

    fn reset_engine(&mut self) {
        self.pi_e.reset(0.0);
        self.ff_prev = None;
    }

    /// The last command.
    pub fn last(&self) -> &Command {
        &self.last
    }

    /// Makes `cmd` the last command: what was sent instead of this step's own command (the
    /// kiss-point routine's clutch and neutral shaft), so the gear requests that follow hold a
    /// shaft's gear until its clutch is open ([`Self::safe_gear_req`]).
    pub fn override_last(&mut self, cmd: &Command) {
        self.last = *cmd;
    }

    /// Restarts from the measurements (after Init or the safe state): the mode follows the lever
    /// and the vehicle speed; integrators are cleared.
    pub fn restart(&mut self, ctx: &Ctx) {
        self.pi_c.iter_mut().for_each(|p| p.reset(0.0));
        self.reset_engine();
        self.mode = Self::initial_mode(ctx);
    }

    fn initial_mode(ctx: &Ctx) -> Mode {
        let Some(g0) = start_gear(ctx.m.lever) else {
            return Mode::Neutral;
        };
        let a = shaft(g0);
        let creep = Mode::Creep(Creep {
            a,
            gear: g0,
            w_c_ref: ctx.m.w_c[a],
            t_ref: 0.0,
        });
        if ctx.v_kmh().abs() < 2.0 * ctx.cfg.creep.standstill_kmh.max(1.0) || g0 != Gear::G1 {
            return creep;
        }
        // Moving forward: engage the engaged gear closest to the schedule's, else creep/wait.
        let want = scheduled_from_speed(ctx);
        let mut best: Option<(Gear, usize)> = None;
        let steps = |g: Gear| Some(g.number()?.abs_diff(want.number()?));
        for (i, &g) in ctx.m.gear.iter().enumerate() {
            if let Some(d) = steps(g) {
                if best.is_none_or(|(bg, _)| steps(bg).is_none_or(|bd| d < bd)) {
                    best = Some((g, i));
                }
            }
        }
        match best {
            Some((g, i)) => Mode::Launch(Launch::new(ctx, i, g)),
            None => creep,
        }
    }

    /// One strategy step.
    pub fn step(&mut self, ctx: &Ctx) -> Command {
        // Lever changes.
        let want_start = start_gear(ctx.m.lever);
        match (&self.mode, want_start) {
            (Mode::Neutral, Some(_)) => self.mode = Self::initial_mode(ctx),
            (Mode::Neutral, None) => {}
            (_, None) => self.mode = Mode::Neutral,
            (Mode::Creep(c), Some(g0)) if c.gear != g0 => self.mode = Mode::Neutral,
            (Mode::Launch(l), Some(g0)) if g0.is_reverse() != l.gear.is_reverse() => {
                self.mode = Mode::Neutral
            }
            (Mode::Drive(d), Some(g0)) if g0.is_reverse() != d.gear.is_reverse() => {
                self.mode = Mode::Neutral
            }
            _ => {}
        }
        self.since_shift_s += ctx.dt;
        self.steps += 1;
        let mut cmd = match self.mode {
            Mode::Neutral => self.neutral(ctx),
            Mode::Creep(c) => self.creep(ctx, c),
            Mode::Launch(l) => self.launch(ctx, l),
            Mode::Drive(d) => self.drive(ctx, d),
            Mode::Shift(s) => self.shift(ctx, s),
        };
        // Anti-stall: near idle (`safety.antistall_release_idle_fraction`) the engine's own idle
        // governor gets the engine back unless the request asks for more than the driver would.
        if ctx.m.w_e < ctx.cfg.safety.antistall_release_idle_fraction * ctx.idle()
            && cmd.engine_req.is_some_and(|t| t < ctx.demand().max(0.0))
        {
            cmd.engine_req = None;
        }
        self.last = cmd;
        cmd
    }

    fn neutral(&mut self, ctx: &Ctx) -> Command {
        let g0 = start_gear(ctx.m.lever).unwrap_or(Gear::G1);
        let mut gear_req = [Gear::G1, Gear::G2];
        if g0.is_reverse() {
            gear_req[1] = Gear::R;
        }
        Command {
            x_ref: [ctx.standby(0), ctx.standby(1)],
            gear_req: self.safe_gear_req(ctx, gear_req),
            state: TcuState::Neutral,
            phase: "neutral",
            ..Default::default()
        }
    }

    /// Gear requests only change on a shaft whose clutch is open (measured position before the
    /// kiss point); otherwise the previous request stays.
    fn safe_gear_req(&self, ctx: &Ctx, want: [Gear; 2]) -> [Gear; 2] {
        let mut out = want;
        for i in 0..2 {
            let open = ctx.m.x_mm[i] < ctx.model.kiss_point(ctx.theta[i]);
            if !open && ctx.m.gear[i] != want[i] {
                out[i] = self.last.gear_req[i];
            }
        }
        out
    }

    /// One creep cycle: to launch once the pedal is pressed with the gear engaged; else the
    /// creep torque released (brake, no gear) or following the creep clutch-speed reference.
    fn creep(&mut self, ctx: &Ctx, mut c: Creep) -> Command {
        let a = c.a;
        let o = 1 - a;
        let mut want = [Gear::N; 2];
        want[a] = c.gear;
        want[o] = if c.gear.is_reverse() {
            Gear::G1
        } else {
            Gear::G2
        };
        let gear_req = self.safe_gear_req(ctx, want);
        let engaged = ctx.m.gear[a] == c.gear;
        if ctx.pedal_on() && engaged {
            let l = Launch::new(ctx, a, c.gear);
            self.pi_c[a].reset(0.0);
            self.reset_engine();
            self.mode = Mode::Launch(l);
            return self.launch(ctx, l);
        }
        // The brake releases the creep torque (at standstill and while rolling).
        let (t, phase) = if !engaged || ctx.m.brake {
            (self.creep_release(ctx, &mut c, engaged), "hold")
        } else {
            (self.creep_torque(ctx, &mut c), "creep")
        };
        let x_a = if t > 0.0 {
            ctx.x_slip(a, t)
        } else {
            ctx.standby(a)
        };
        self.mode = Mode::Creep(c);
        let mut x_ref = [0.0; 2];
        x_ref[a] = x_a;
        x_ref[o] = ctx.standby(o);
        let mut t_ref = [0.0; 2];
        t_ref[a] = t;
        Command {
            x_ref,
            t_ref,
            engine_req: None,
            gear_req,
            gear_active: if engaged { c.gear } else { Gear::N },
            state: TcuState::Creep,
            w_e_ref: ctx.idle(),
            w_c_ref: c.w_c_ref,
            phase,
        }
    }

    /// Creep torque released at `creep.release_rate_nm_per_s` (brake pressed or gear not
    /// engaged): the reference follows the clutch, the integrator is reset; the torque still
    /// applied, nothing below `creep.min_hold_torque_nm` or without the gear.
    fn creep_release(&mut self, ctx: &Ctx, c: &mut Creep, engaged: bool) -> f64 {
        let a = c.a;
        c.w_c_ref = ctx.m.w_c[a];
        c.t_ref = approach(c.t_ref, 0.0, ctx.cfg.creep.release_rate_nm_per_s, ctx.dt);
        self.pi_c[a].reset(0.0);
        if c.t_ref > ctx.cfg.creep.min_hold_torque_nm && engaged {
            c.t_ref
        } else {
            0.0
        }
    }

    /// Creep torque that brings the clutch speed toward idle minus the creep slip at the creep
    /// acceleration, with `creep.gain_share` of the launch gains (the creep torque sits near the
    /// kiss point, where the actuator lag matters most); the torque rises at most at
    /// `creep.torque_rise_nm_per_s` so the idle governor keeps up.
    fn creep_torque(&mut self, ctx: &Ctx, c: &mut Creep) -> f64 {
        let cfg = ctx.cfg;
        let a = c.a;
        let target = (ctx.m.w_e.min(ctx.idle()) - cfg.creep.slip_radps).max(0.0);
        let alpha =
            cfg.creep.accel_mps2 / cfg.physics.driveline.wheel_radius_m * ctx.k(c.gear).abs();
        let prev = c.w_c_ref;
        c.w_c_ref = approach(c.w_c_ref, target, alpha, ctx.dt);
        let win = cfg.creep.reference_window_radps;
        c.w_c_ref = c.w_c_ref.clamp(ctx.m.w_c[a] - win, ctx.m.w_c[a] + win);
        let w_dot_ref = if ctx.dt > 0.0 {
            (c.w_c_ref - prev) / ctx.dt
        } else {
            0.0
        };
        let e = c.w_c_ref - ctx.m.w_c[a];
        let pi = self.pi_c[a];
        let w_dot_cmd = w_dot_ref + cfg.creep.gain_share * (pi.kp * e + pi.integral);
        let r = ctx.reduced();
        let raw = r.decouple(a, r.v_c_for(a, w_dot_cmd), 0.0, ctx.load());
        let hi = cfg
            .creep
            .max_torque_nm
            .min(ctx.t_max(a))
            .min(c.t_ref + cfg.creep.torque_rise_nm_per_s * ctx.dt)
            .min(ctx.stall_limit());
        let t = raw.clamp(0.0, hi.max(0.0));
        self.pi_c[a].integrate(e, ctx.dt, raw >= hi, raw <= 0.0);
        c.t_ref = t;
        t
    }

    /// One launch cycle: the clutch-speed reference (jerk-limited, within what the engine has
    /// left), the engine-speed reference (profile, then synchronisation), the clutch torque by
    /// PI_c and the decoupling law (27), the engine torque by PI_e and (24); after
    /// `lock_cycles` cycles locked, drive.
    fn launch(&mut self, ctx: &Ctx, mut l: Launch) -> Command {
        let r = ctx.reduced();
        if let Some(cmd) = self.leave_launch(ctx, &r, &mut l) {
            return cmd;
        }
        let (w_tgt, alpha_tgt) = Launch::targets(ctx, l.a, l.gear, l.w_c0);
        let w_dot_prof = l.engine_profile_rate(ctx, w_tgt);
        l.advance_clutch_reference(ctx, &r, alpha_tgt, w_dot_prof);
        let (w_e_ref, w_e_dot_ref) = l.advance_engine_reference(ctx, w_dot_prof);
        let t_a = self.launch_clutch_torque(ctx, &r, &l);
        let t_e = self.engine_law(ctx, &r, w_e_ref, w_e_dot_ref, t_a);
        l.count_lock(ctx);
        let cmd = self.launch_command(ctx, &l, t_a, t_e, w_e_ref);
        self.mode = if l.lock_count >= ctx.cfg.control.lock_cycles {
            Mode::Drive(Drive {
                a: l.a,
                gear: l.gear,
                cap: t_a,
                blend: Some(t_e),
                since_s: 0.0,
                slip_count: 0,
            })
        } else {
            Mode::Launch(l)
        };
        cmd
    }

    /// Back to creep when the launch gear is lost (creep waits for it) or the pedal has been
    /// released for `launch.pedal_off_s` before synchronisation; counts the pedal-off time.
    fn leave_launch(&mut self, ctx: &Ctx, r: &Reduced, l: &mut Launch) -> Option<Command> {
        let a = l.a;
        if r.k[a] == 0.0 || ctx.m.gear[a] != l.gear {
            self.mode = Mode::Creep(Creep {
                a,
                gear: start_gear(ctx.m.lever).unwrap_or(Gear::G1),
                w_c_ref: ctx.m.w_c[a],
                t_ref: 0.0,
            });
            return Some(self.creep_now(ctx));
        }
        l.pedal_off_s = if ctx.pedal_on() {
            0.0
        } else {
            l.pedal_off_s + ctx.dt
        };
        if l.pedal_off_s > ctx.cfg.launch.pedal_off_s
            && l.sync.is_none()
            && l.gear == start_gear(ctx.m.lever).unwrap_or(Gear::G1)
        {
            self.mode = Mode::Creep(Creep {
                a,
                gear: l.gear,
                w_c_ref: ctx.m.w_c[a],
                t_ref: self.last.t_ref[a],
            });
            return Some(self.creep_now(ctx));
        }
        None
    }

    /// PI_c and the decoupling law (27): the clutch torque that follows the launch's clutch
    /// reference, within the clutch's capacity and the anti-stall limit.
    fn launch_clutch_torque(&mut self, ctx: &Ctx, r: &Reduced, l: &Launch) -> f64 {
        let a = l.a;
        let e_c = l.w_c_ref - ctx.m.w_c[a];
        let w_dot_cmd = self.pi_c[a].output(l.alpha, e_c);
        let raw = r.decouple(a, r.v_c_for(a, w_dot_cmd), 0.0, ctx.load());
        let hi = ctx.t_max(a).min(ctx.stall_limit());
        let t_a = raw.clamp(0.0, hi);
        self.pi_c[a].integrate(e_c, ctx.dt, raw >= hi, raw <= 0.0);
        t_a
    }

    /// The launch cycle's command: the active clutch at the position of its torque (with the
    /// actuator lead), the other at standby with the next gear preselected.
    fn launch_command(
        &mut self,
        ctx: &Ctx,
        l: &Launch,
        t_a: f64,
        t_e: f64,
        w_e_ref: f64,
    ) -> Command {
        let a = l.a;
        let o = 1 - a;
        let x_a = self.lead(ctx, a, ctx.x_slip(a, t_a));
        let mut x_ref = [0.0; 2];
        x_ref[a] = x_a;
        x_ref[o] = ctx.standby(o);
        let mut t_ref = [0.0; 2];
        t_ref[a] = t_a;
        let mut want = [Gear::N; 2];
        want[a] = l.gear;
        want[o] = preselect(ctx.cfg, l.gear, ctx.v_kmh(), ctx.m.pedal);
        Command {
            x_ref,
            t_ref,
            engine_req: Some(t_e),
            gear_req: self.safe_gear_req(ctx, want),
            gear_active: l.gear,
            state: TcuState::Launch,
            w_e_ref,
            w_c_ref: l.w_c_ref,
            phase: if l.sync.is_some() { "sync" } else { "launch" },
        }
    }

    fn creep_now(&mut self, ctx: &Ctx) -> Command {
        match self.mode {
            Mode::Creep(c) => self.creep(ctx, c),
            _ => self.neutral(ctx),
        }
    }

    /// One drive cycle: the engine request blended back to the driver, the active clutch clamped
    /// above the engine torque, the next gear preselected; then back to creep at a stop, or a
    /// shift when the schedule asks for one.
    fn drive(&mut self, ctx: &Ctx, mut d: Drive) -> Command {
        let a = d.a;
        let o = 1 - a;
        d.since_s += ctx.dt;
        if ctx.m.gear[a] != d.gear {
            // The gear fell out (should not happen): re-engage through creep/launch.
            self.mode = Self::initial_mode(ctx);
            return self.step_mode(ctx);
        }
        d.advance(ctx);
        let mut x_ref = [0.0; 2];
        x_ref[a] = ctx.x_clamp(a, d.cap);
        x_ref[o] = ctx.standby(o);
        let mut t_ref = [0.0; 2];
        t_ref[a] = d.cap;
        let mut want = [Gear::N; 2];
        want[a] = d.gear;
        want[o] = preselect(ctx.cfg, d.gear, ctx.v_kmh(), ctx.m.pedal);
        let gear_req = self.safe_gear_req(ctx, want);
        let cmd = Command {
            x_ref,
            t_ref,
            engine_req: d.blend,
            gear_req,
            gear_active: d.gear,
            state: TcuState::Drive,
            w_e_ref: ctx.m.w_e,
            w_c_ref: ctx.m.w_c[a],
            phase: "drive",
        };
        match d.stop(ctx) {
            Some(c) => self.mode = Mode::Creep(c),
            None => {
                self.mode = Mode::Drive(d);
                self.shift_if_scheduled(ctx, d);
            }
        }
        cmd
    }

    /// Shift decision, once `shift.settle_s` in the gear. A downshift whose engine would otherwise
    /// lug toward idle (`shift.lugging_idle_fraction`) does not wait for that, the interval since
    /// the last shift nor the engine-request blend; no upshift while
    /// braking; the next gear must be engaged on the other shaft.
    fn shift_if_scheduled(&mut self, ctx: &Ctx, d: Drive) {
        if d.gear.is_reverse() {
            return;
        }
        let cfg = ctx.cfg;
        let o = 1 - d.a;
        let g = scheduled_gear(cfg, d.gear, ctx.v_kmh(), ctx.m.pedal);
        let urgent = d.gear.above(g) && ctx.m.w_e < cfg.shift.lugging_idle_fraction * ctx.idle();
        let settled = d.since_s > cfg.shift.settle_s
            && self.since_shift_s > cfg.shift.min_interval_s
            && d.blend.is_none();
        let braking_up = g.above(d.gear) && ctx.m.brake;
        if (settled || urgent) && g != d.gear && !braking_up && ctx.m.gear[o] == g && shaft(g) == o
        {
            self.start_shift(ctx, d, g);
        }
    }

    fn step_mode(&mut self, ctx: &Ctx) -> Command {
        match self.mode {
            Mode::Neutral => self.neutral(ctx),
            Mode::Creep(c) => self.creep(ctx, c),
            Mode::Launch(l) => self.launch(ctx, l),
            Mode::Drive(d) => self.drive(ctx, d),
            Mode::Shift(s) => self.shift(ctx, s),
        }
    }

    fn start_shift(&mut self, ctx: &Ctx, d: Drive, to: Gear) {
        let up = to.above(d.gear);
        let t_tr = ctx.demand().max(0.0);
        self.reset_engine();
        self.pi_c[1 - d.a].reset(0.0);
        let mut s = Shift {
            up,
            a: d.a,
            from: d.gear,
            o: 1 - d.a,
            to,
            phase: if up {
                ShiftPhase::Torque
            } else {
                ShiftPhase::Inertia
            },
            tau: 0.0,
            t_tr,
            t_a0: d.cap,
            s0: 0.0,
            duration: ctx.cfg.shift.torque_phase_s,
            lock_count: 0,
            total_s: 0.0,
            t_e_req: ctx.m.t_e,
            release: None,
        };
        if !up {
            Self::begin_inertia(ctx, &mut s);
        }
        self.mode = Mode::Shift(s);
    }

    /// Inertia-phase duration: the smoothstep's peak engine acceleration 1.5·|s0|/T must stay
    /// within `engine_authority` of what the engine torque range leaves after the clutch torque
    /// (taken as at least `shift.min_authority_nm`).
    fn begin_inertia(ctx: &Ctx, s: &mut Shift) {
        let cfg = ctx.cfg;
        let w_co = ctx.m.w_c[s.o];
        s.phase = ShiftPhase::Inertia;
        s.tau = 0.0;
        s.s0 = ctx.m.w_e - w_co;
        let (lo, hi) = ctx.engine_limits();
        let j = cfg.physics.driveline.j_eq_kgm2;
        let avail = if s.up {
            // Engine pulled down: clutch torque plus engine drag.
            s.t_tr - lo
        } else {
            // Engine pushed up: full load minus what the off-going clutch keeps.
            hi - cfg.shift.downshift_offgoing_fraction * s.t_tr
        }
        .max(cfg.shift.min_authority_nm);
        let t_needed = 1.5 * s.s0.abs() * j / (cfg.shift.engine_authority * avail);
        s.duration = t_needed.clamp(cfg.shift.min_inertia_phase_s, cfg.shift.max_inertia_phase_s);
        s.t_a0 = if s.up {
            0.0
        } else {
            cfg.shift.downshift_offgoing_fraction * s.t_tr
        };
    }

    fn shift(&mut self, ctx: &Ctx, mut s: Shift) -> Command {
        s.tau += ctx.dt;
        s.total_s += ctx.dt;
        // The vehicle is slowing too fast for the shift (hard braking toward a stop): open both
        // clutches and let creep/hold take over in the start gear.
        let h = &ctx.cfg.shift;
        if ctx.m.w_c[s.o] < h.abort_clutch_idle_fraction * ctx.idle()
            || ctx.m.w_e < h.abort_engine_idle_fraction * ctx.idle()
        {
            let start = start_gear(ctx.m.lever).unwrap_or(Gear::G1);
            self.since_shift_s = 0.0;
            self.mode = Mode::Creep(Creep {
                a: shaft(start),
                gear: start,
                w_c_ref: ctx.m.w_c[shaft(start)],
                t_ref: 0.0,
            });
            return self.creep_now(ctx);
        }
        s.t_tr = ctx.demand().max(0.0);
        let out = match (s.up, s.phase) {
            (true, ShiftPhase::Torque) => self.upshift_torque(ctx, &mut s),
            (true, ShiftPhase::Inertia) => self.upshift_inertia(ctx, &mut s),
            (false, ShiftPhase::Inertia) => self.downshift_inertia(ctx, &mut s),
            (false, ShiftPhase::Torque) => self.downshift_torque(ctx, &mut s),
        };
        let slip_o = ctx.m.slip(s.o);
        let k = &ctx.cfg.control;
        let locking = !(s.up && s.phase == ShiftPhase::Torque);
        if locking && slip_o.abs() < k.lock_slip_radps && (s.phase == ShiftPhase::Torque || s.up) {
            s.lock_count += 1;
        } else {
            s.lock_count = 0;
        }
        let cmd = shift_command(ctx, &s, &out);
        self.after_shift_cycle(ctx, s, out.t[s.o]);
        cmd
    }

    /// Upshift, torque phase: the on-coming clutch ramps up to the transmitted torque, the
    /// off-going capacity to zero.
    fn upshift_torque(&mut self, ctx: &Ctx, s: &mut Shift) -> PhaseOut {
        let (cfg, k) = (ctx.cfg, &ctx.cfg.control);
        let (a, o) = (s.a, s.o);
        let mut out = PhaseOut::standby(ctx, "upshift-torque");
        let u = (s.tau / cfg.shift.torque_phase_s).min(1.0);
        out.t[o] = u * s.t_tr;
        let cap_a = (1.0 - u) * ((1.0 + k.clamp_margin) * s.t_tr + k.clamp_offset_nm);
        out.t[a] = cap_a;
        out.x[o] = self.lead(ctx, o, ctx.x_slip(o, out.t[o]));
        out.x[a] = ctx.x_clamp(a, cap_a);
        if u >= 1.0 {
            Self::begin_inertia(ctx, s);
        }
        out
    }

    /// Upshift, inertia phase: the off-going clutch open, the on-coming one carries the demand;
    /// PI_e pulls the engine down along a smoothstep to a small positive slip, holds it until the
    /// engine torque is back near the on-coming clutch's torque (`shift.release_torque_*`, at the
    /// latest `release_timeout_s` after the smoothstep; so lock-up does not drop the
    /// acceleration), then lets the slip cross zero over `release_ramp_s`. (At least
    /// `min_oncoming_nm`: with the pedal off the on-coming clutch still has to pull the engine
    /// down to its shaft.)
    fn upshift_inertia(&mut self, ctx: &Ctx, s: &mut Shift) -> PhaseOut {
        let (k, h) = (&ctx.cfg.control, &ctx.cfg.shift);
        let o = s.o;
        let r = ctx.reduced();
        let (w_co, alpha_co) = (ctx.m.w_c[o], r.k[o] * ctx.w_out_dot);
        let delta = k.lock_undershoot_radps;
        let mut out = PhaseOut::standby(ctx, "upshift-inertia");
        out.t[o] = s.t_tr.max(h.min_oncoming_nm).min(ctx.t_max(o));
        out.x[o] = self.lead(ctx, o, ctx.x_slip(o, out.t[o]));
        let hold = k.lock_hold_slip_radps;
        let (mut s_ref, mut ds) = smoothstep(s.s0, hold, s.tau, s.duration);
        if s.tau >= s.duration {
            let recovered = ctx.m.t_e
                >= out.t[o] - (h.release_torque_share * out.t[o]).max(h.release_torque_nm);
            if s.release.is_none() && (recovered || s.tau >= s.duration + h.release_timeout_s) {
                s.release = Some(s.tau);
            }
            if let Some(t_rel) = s.release {
                let u = ((s.tau - t_rel) / h.release_ramp_s).min(1.0);
                s_ref = hold - (hold + delta) * u;
                ds = if u < 1.0 {
                    -(hold + delta) / h.release_ramp_s
                } else {
                    0.0
                };
            }
        }
        out.w_e_ref = w_co + s_ref;
        let w_e_dot_ref = alpha_co + ds;
        let t_e = self.engine_law(ctx, &r, out.w_e_ref, w_e_dot_ref, out.t[o]);
        s.t_e_req = t_e;
        out.engine_req = Some(t_e);
        out
    }

    /// Downshift, inertia phase: the off-going clutch keeps part of the demand while the engine
    /// rises to the new shaft; the torque phase follows near synchronism
    /// (`shift.downshift_sync_radps`, at the latest `downshift_sync_timeout_s` after the
    /// smoothstep).
    fn downshift_inertia(&mut self, ctx: &Ctx, s: &mut Shift) -> PhaseOut {
        let (a, o) = (s.a, s.o);
        let r = ctx.reduced();
        let (w_co, alpha_co) = (ctx.m.w_c[o], r.k[o] * ctx.w_out_dot);
        let delta = ctx.cfg.control.lock_undershoot_radps;
        let slip_o = ctx.m.slip(o);
        let mut out = PhaseOut::standby(ctx, "downshift-inertia");
        out.t[a] = s.t_a0.min(ctx.t_max(a));
        out.x[a] = if out.t[a] > 0.0 {
            ctx.x_slip(a, out.t[a])
        } else {
            ctx.standby(a)
        };
        let (s_ref, ds) = smoothstep(s.s0, delta, s.tau, s.duration);
        out.w_e_ref = w_co + s_ref;
        let w_e_dot_ref = alpha_co + ds;
        let t_e = self.engine_law(ctx, &r, out.w_e_ref, w_e_dot_ref, out.t[a]);
        s.t_e_req = t_e;
        out.engine_req = Some(t_e);
        let h = &ctx.cfg.shift;
        if s.tau >= s.duration && (slip_o - delta).abs() < h.downshift_sync_radps
            || s.tau >= s.duration + h.downshift_sync_timeout_s
        {
            s.phase = ShiftPhase::Torque;
            s.tau = 0.0;
        }
        out
    }

    /// Downshift, torque phase: the on-coming clutch takes over near synchronism, the engine
    /// held just above it.
    fn downshift_torque(&mut self, ctx: &Ctx, s: &mut Shift) -> PhaseOut {
        let (cfg, k) = (ctx.cfg, &ctx.cfg.control);
        let (a, o) = (s.a, s.o);
        let r = ctx.reduced();
        let (w_co, alpha_co) = (ctx.m.w_c[o], r.k[o] * ctx.w_out_dot);
        let delta = k.lock_undershoot_radps;
        let mut out = PhaseOut::standby(ctx, "downshift-torque");
        let u = (s.tau / cfg.shift.torque_phase_s).min(1.0);
        out.t[o] = u * (s.t_tr + k.clamp_offset_nm);
        out.t[a] = (1.0 - u) * s.t_a0;
        out.x[o] = self.lead(ctx, o, ctx.x_slip(o, out.t[o]));
        out.x[a] = if out.t[a] > 0.0 {
            ctx.x_slip(a, out.t[a])
        } else {
            ctx.standby(a)
        };
        out.w_e_ref = w_co + delta * (1.0 - 2.0 * u);
        let t_e = self.engine_law(ctx, &r, out.w_e_ref, alpha_co, out.t[o] + out.t[a]);
        s.t_e_req = t_e;
        out.engine_req = Some(t_e);
        out
    }

    /// The mode after a shift's cycle: drive in the new gear once the on-coming clutch has been
    /// locked for `lock_cycles` cycles (or nearly so, `shift.fallback_lock_slip_radps`, after
    /// `fallback_lock_s`), a fresh start from the measurements when the shift has not completed in
    /// `abort_s`, else the shift goes on. `t_o`: the on-coming clutch's torque reference this
    /// cycle.
    fn after_shift_cycle(&mut self, ctx: &Ctx, s: Shift, t_o: f64) {
        let slip_o = ctx.m.slip(s.o);
        let h = &ctx.cfg.shift;
        if s.lock_count >= ctx.cfg.control.lock_cycles
            || (s.total_s > h.fallback_lock_s && slip_o.abs() < h.fallback_lock_slip_radps)
        {
            self.since_shift_s = 0.0;
            self.mode = Mode::Drive(Drive {
                a: s.o,
                gear: s.to,
                cap: t_o.max(s.t_tr),
                blend: Some(s.t_e_req),
                since_s: 0.0,
                slip_count: 0,
            });
        } else if s.total_s > h.abort_s {
            // The shift did not complete: re-engage an engaged gear like a launch (or creep when
            // slow), from the measurements.
            self.since_shift_s = 0.0;
            self.pi_c.iter_mut().for_each(|p| p.reset(0.0));
            self.reset_engine();
            self.mode = Self::initial_mode(ctx);
        } else {
            self.mode = Mode::Shift(s);
        }
    }

    /// PI_e and (24): T_e,ref = J_eq (ω̇_e,ref + kp e + ki ∫e) + ΣT_fc,ref, within the engine's
    /// range. The feed-forward part J_eq ω̇_e,ref + ΣT_fc,ref gets a lead (τ_e + d)·d/dt that
    /// cancels the engine's first-order torque lag τ_e (the engine ECU's, from the parameter file)
    /// and, to first order, the command delay d.
    fn engine_law(&mut self, ctx: &Ctx, r: &Reduced, w_ref: f64, w_dot_ref: f64, t_c: f64) -> f64 {
        let e = w_ref - ctx.m.w_e;
        let ff = r.j_eq * w_dot_ref + t_c;
        let lead = match self.ff_prev {
            Some(prev) if ctx.dt >= ctx.cfg.control.min_lead_dt_s => {
                (ctx.cfg.physics.engine.torque_lag_s + ctx.cfg.control.command_delay_s)
                    * (ff - prev)
                    / ctx.dt
            }
            _ => 0.0,
        };
        self.ff_prev = Some(ff);
        let raw = ff + lead + r.j_eq * self.pi_e.output(0.0, e);
        let (lo, hi) = ctx.engine_limits();
        let t = raw.clamp(lo, hi);
        self.pi_e.integrate(e, ctx.dt, raw >= hi, raw <= lo);
        t
    }
}

/// Smoothstep from `s0` to `s1` over `duration`: value and rate at `tau`.
fn smoothstep(s0: f64, s1: f64, tau: f64, duration: f64) -> (f64, f64) {
    let u = (tau / duration.max(1e-6)).clamp(0.0, 1.0);
    let h = u * u * (3.0 - 2.0 * u);
    let dh = if tau >= duration {
        0.0
    } else {
        6.0 * u * (1.0 - u) / duration.max(1e-6)
    };
    (s0 + (s1 - s0) * h, (s1 - s0) * dh)
}

fn scheduled_from_speed(ctx: &Ctx) -> Gear {
    let v = ctx.v_kmh();
    let mut g = Gear::G1;
    loop {
        let n = scheduled_gear(ctx.cfg, g, v, ctx.m.pedal);
        if !n.above(g) {
            return g;
        }
        g = n;
    }
}

impl Drive {
    /// One cycle of the engaged clutch: the engine request blended toward the driver's demand at
    /// `blend_rate_nm_per_s` and released within `blend_release_nm` of it; the slip alarm
    /// counted; the clamp capacity raised at once to (1 + margin·boost)·|T_e| + offset·boost
    /// (boost `slip_alarm_boost` after `slip_alarm_cycles` cycles of slip alarm, else 1), lowered
    /// at `clamp_rate_nm_per_s`, at most `max_torque_nm`.
    fn advance(&mut self, ctx: &Ctx) {
        let k = &ctx.cfg.control;
        let demand = ctx.demand();
        if let Some(req) = self.blend {
            let next = approach(req, demand, k.blend_rate_nm_per_s, ctx.dt);
            self.blend = if (next - demand).abs() < k.blend_release_nm {
                None
            } else {
                Some(next)
            };
        }
        if ctx.m.slip(self.a).abs() > k.slip_alarm_radps {
            self.slip_count += 1;
        } else {
            self.slip_count = 0;
        }
        let boost = if self.slip_count >= k.slip_alarm_cycles {
            k.slip_alarm_boost
        } else {
            1.0
        };
        let t_e = ctx
            .m
            .t_e
            .abs()
            .max(demand.abs())
            .max(self.blend.unwrap_or(0.0).abs());
        let target = (1.0 + k.clamp_margin * boost) * t_e + k.clamp_offset_nm * boost;
        self.cap = if target > self.cap {
            target.min(k.max_torque_nm)
        } else {
            approach(self.cap, target, k.clamp_rate_nm_per_s, ctx.dt)
        };
    }

    /// The creep a stop leads to: in the start gear with the pedal off and the engine near idle
    /// (`creep.stop_engine_rpm`), keeping the clamp torque up to the creep torque; in any gear
    /// with the engine near stalling (`creep.stall_idle_fraction`), open (creep waits for the start
    /// gear).
    fn stop(&self, ctx: &Ctx) -> Option<Creep> {
        let cfg = ctx.cfg;
        let start = start_gear(ctx.m.lever).unwrap_or(Gear::G1);
        let low = ctx.m.w_e < cfg.creep.stop_engine_rpm * RPM;
        if (self.gear == start && low && !ctx.pedal_on())
            || ctx.m.w_e < cfg.creep.stall_idle_fraction * ctx.idle()
        {
            return Some(Creep {
                a: shaft(start),
                gear: start,
                w_c_ref: ctx.m.w_c[shaft(start)],
                t_ref: if self.gear == start {
                    self.cap.min(cfg.creep.max_torque_nm)
                } else {
                    0.0
                },
            });
        }
        None
    }
}

impl Sync {
    /// Advances the synchronisation by `dt`: the slip reference falls as a parabola from `s0` to
    /// `delta` below zero over `duration`, and its rate. After the profile, a slip still above
    /// zero is pulled down further at `launch.sync_tail_rate_radps2` (up to
    /// `sync_tail_max_radps` below zero) so that it crosses and the clutch locks.
    fn advance(&mut self, dt: f64, delta: f64, l: &LaunchCfg) -> (f64, f64) {
        let (rate, max) = (l.sync_tail_rate_radps2, l.sync_tail_max_radps);
        self.tau += dt;
        let u = (self.tau / self.duration).min(1.0);
        let tail = (self.tau - self.duration).max(0.0);
        let s_ref = (self.s0 + delta) * (1.0 - u) * (1.0 - u) - delta - (rate * tail).min(max);
        let ds = -2.0 * (self.s0 + delta) * (1.0 - u) / self.duration
            - if tail > 0.0 && rate * tail < max {
                rate
            } else {
                0.0
            };
        (s_ref, ds)
    }
}

impl Launch {
    fn new(ctx: &Ctx, a: usize, gear: Gear) -> Launch {
        Launch {
            a,
            gear,
            w_c0: ctx.m.w_c[a],
            w_c_ref: ctx.m.w_c[a],
            alpha: 0.0,
            w_e_prof: ctx.m.w_e,
            sync: None,
            lock_count: 0,
            pedal_off_s: 0.0,
        }
    }

    /// Rate of the engine-speed profile toward the target `w_tgt`: a first-order approach with
    /// time constant `engine_profile_s`, limited to `engine_rate_rpm_per_s`, so the engine torque
    /// request falls smoothly as the target nears and the engine's torque lag does not flare it.
    fn engine_profile_rate(&self, ctx: &Ctx, w_tgt: f64) -> f64 {
        let cfg = ctx.cfg;
        let rate = cfg.launch.engine_rate_rpm_per_s * RPM;
        ((w_tgt - self.w_e_prof) / cfg.launch.engine_profile_s).clamp(-rate, rate)
    }

    /// The jerk-limited clutch acceleration reference toward `alpha_tgt`, capped by what the
    /// engine has left after following its own profile (the engine flares first), but not below
    /// `launch.min_accel_share` of it:
    /// α ≤ (share·T_full(ω_e) − J_eq ω̇_prof − T̂_L/k)·k²/J_eq2; the clutch-speed reference
    /// integrates it, kept within `reference_window_radps` of the measured clutch speed.
    fn advance_clutch_reference(
        &mut self,
        ctx: &Ctx,
        r: &Reduced,
        alpha_tgt: f64,
        w_dot_prof: f64,
    ) {
        let cfg = ctx.cfg;
        let k = r.k[self.a];
        let (_, t_full) = ctx.engine_limits();
        let share = cfg.launch.engine_torque_share;
        let alpha_avail =
            (share * t_full - r.j_eq * w_dot_prof.max(0.0) - ctx.load() / k) * k * k / r.j_eq2;
        let alpha_tgt = alpha_tgt.min(alpha_avail.max(cfg.launch.min_accel_share * alpha_tgt));
        let jerk = alpha_tgt.max(1.0) / cfg.launch.jerk_time_s.max(1e-3);
        self.alpha = approach(self.alpha, alpha_tgt, jerk, ctx.dt);
        self.w_c_ref += self.alpha * ctx.dt;
        let w_c = ctx.m.w_c[self.a];
        let win = cfg.launch.reference_window_radps;
        self.w_c_ref = self.w_c_ref.clamp(w_c - win, w_c + win);
    }

    /// The engine-speed reference and its rate: the profile advanced at `w_dot_prof`, then,
    /// once the profile is within `sync_slip_radps` of the clutch, the synchronisation phase.
    fn advance_engine_reference(&mut self, ctx: &Ctx, w_dot_prof: f64) -> (f64, f64) {
        let w_c = ctx.m.w_c[self.a];
        let prof_prev = self.w_e_prof;
        self.w_e_prof += w_dot_prof * ctx.dt;
        let w_e_dot_ref = if ctx.dt > 0.0 {
            (self.w_e_prof - prof_prev) / ctx.dt
        } else {
            0.0
        };
        if self.sync.is_none()
            && self.w_e_prof - w_c <= ctx.cfg.launch.sync_slip_radps
            && self.alpha > 0.0
        {
            let s0 = ctx.m.slip(self.a).max(1.0);
            self.sync = Some(Sync {
                tau: 0.0,
                s0,
                duration: (2.0 * s0 / self.alpha.max(1.0)).max(ctx.cfg.launch.min_sync_time_s),
            });
        }
        let delta = ctx.cfg.control.lock_undershoot_radps;
        match self.sync.as_mut() {
            Some(s) => {
                let (s_ref, ds) = s.advance(ctx.dt, delta, &ctx.cfg.launch);
                (w_c + s_ref, self.alpha + ds)
            }
            None => (self.w_e_prof, w_e_dot_ref),
        }
    }

    /// Lock-up detection: cycles in a row synchronised with the slip below `lock_slip_radps`.
    fn count_lock(&mut self, ctx: &Ctx) {
        if ctx.m.slip(self.a).abs() < ctx.cfg.control.lock_slip_radps && self.sync.is_some() {
            self.lock_count += 1;
        } else {
            self.lock_count = 0;
        }
    }

    /// Engine-speed target and clutch acceleration target of a launch at the current pedal:
    /// target n(p), at least `target_min_sync_slips`·`sync_slip_radps` above `w_c0`; acceleration
    /// the larger of the pedal-consistent one (the driver's demand at the target speed would hold
    /// it after lock-up) and the one that locks up in `lockup_time_s` from the clutch speed `w_c0`
    /// at the start.
    fn targets(ctx: &Ctx, a: usize, gear: Gear, w_c0: f64) -> (f64, f64) {
        let cfg = ctx.cfg;
        let l = &cfg.launch;
        let p = ctx.m.pedal;
        let n = if ctx.limit_torque {
            l.engine_rpm_0
        } else {
            l.engine_rpm_0 + (l.engine_rpm_100 - l.engine_rpm_0) * p
        };
        let w_tgt = (n * RPM).max(w_c0 + l.target_min_sync_slips * l.sync_slip_radps);
        let r = Reduced::new(
            &cfg.physics.driveline,
            if a == 0 { gear } else { Gear::N },
            if a == 1 { gear } else { Gear::N },
        );
        let k = r.k[a];
        let d = driver_demand(&cfg.physics.engine, p, w_tgt);
        let d = if ctx.limit_torque {
            d.min(cfg.safety.over_temp_engine_torque_nm)
        } else {
            d
        };
        let tl = ctx.load();
        let alpha_cons = if k != 0.0 {
            (d - tl / k) / (r.j_eq + r.j_eq2 / (k * k))
        } else {
            0.0
        };
        let alpha_min = (w_tgt - w_c0).max(0.0) / l.lockup_time_s;
        // At lock-up the engine has to accelerate with the clutch: leave it the rest of its
        // full-load torque at the target speed (`launch.engine_torque_share`: 5 %) for that, or
        // the lock-up comes with a jolt.
        let mut t_full = crate::model::engine::full_load(&cfg.physics.engine, w_tgt);
        if ctx.limit_torque {
            t_full = t_full.min(cfg.safety.over_temp_engine_torque_nm);
        }
        let alpha_cap = if k != 0.0 {
            (l.engine_torque_share * t_full - tl / k) / (r.j_eq + r.j_eq2 / (k * k))
        } else {
            0.0
        };
        (w_tgt, alpha_cons.max(alpha_min).min(alpha_cap).max(0.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedule_has_hysteresis_and_one_step() {
        let c = TcuConfig::default();
        assert_eq!(scheduled_gear(&c, Gear::G1, 10.0, 0.5), Gear::G1);
        assert_eq!(scheduled_gear(&c, Gear::G1, 40.0, 0.5), Gear::G2);
        // Between the down and up speeds of 2: stays.
        let up = 0.5 * (c.shift.up_kmh_0[1] + c.shift.up_kmh_100[1]);
        let down = 0.5 * (c.shift.down_kmh_0[0] + c.shift.down_kmh_100[0]);
        let mid = 0.5 * (up + down);
        assert_eq!(scheduled_gear(&c, Gear::G2, mid, 0.5), Gear::G2);
        assert_eq!(scheduled_gear(&c, Gear::G2, down - 1.0, 0.5), Gear::G1);
        assert_eq!(
            scheduled_gear(&c, Gear::G6, 0.0, 0.0),
            Gear::G5,
            "one step at a time"
        );
    }

    #[test]
    fn smoothstep_ends_flat() {
        let (s, ds) = smoothstep(10.0, -1.0, 0.0, 0.5);
        assert_eq!((s, ds), (10.0, 0.0));
        let (s, ds) = smoothstep(10.0, -1.0, 0.5, 0.5);
        assert_eq!((s, ds), (-1.0, 0.0));
        let (_, ds) = smoothstep(10.0, -1.0, 0.25, 0.5);
        assert!((ds + 1.5 * 11.0 / 0.5).abs() < 1e-9, "peak rate 1.5 Δ/T");
    }
}

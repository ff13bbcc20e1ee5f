//! The virtual transmission control unit as a pure core `Tcu::step(now, inputs) -> outputs`
//! (paper Sects. 4–5): thermal estimator (17) ([`estimator`]), decoupling controller (23)–(27)
//! with the torque-characteristic inverse of (13) ([`control`]), launch and shift strategy
//! ([`strategy`]) and safety, around the bus contract's frames.
//!
//! One step:
//! 1. every frame received since the previous step goes through E2E, decoding and plausibility
//!    ([`inputs`]);
//! 2. input health: a message without a valid frame for `timeout_cycles` cycles puts the TCU in
//!    the **safe state** — both clutches opened at a controlled rate, the engine torque request
//!    released, the fault code (which message, and why: timeout, CRC, counter, implausible value)
//!    in TCU_Status. The safe state is commanded in the same step that detects the fault, i.e. in
//!    the first output after it. When every input is fresh again with `recovery_frames` valid
//!    frames in a row, the strategy restarts from the measurements;
//! 3. the thermal estimator advances by the time since the previous step;
//! 4. over-temperature: above `over_temp_warn_c` the fault code says ClutchOverTempWarning, above
//!    `over_temp_limit_c` ClutchOverTempLimit and the engine torque request and launch targets are
//!    limited;
//! 5. the strategy computes positions, torque references, engine request and gear requests;
//! 6. the outputs are made finite and clamped to the DBC ranges (a non-finite internal value gives
//!    FaultCode InternalNonFinite and holds the previous finite command), encoded and E2E
//!    protected.
//!
//! While the kiss-point adaptation routine runs ([`routine`], UDS RoutineControl 0x0201; started
//! with [`Tcu::start_kiss_point_routine`]), step 5's command is the strategy's with the routine's
//! clutch position, its shaft in neutral and the other clutch open; the strategy keeps running
//! underneath (Neutral: the lever is in P or N) and takes over when the routine ends.
//!
//! No clock, no socket: `now` is the time since the TCU started, and frames carry their arrival
//! time on the same time base.
//!
//! Timing policy, written once here for the daemon and the lockstep sim (quinn-proto's
//! `poll_timeout`): a DCT_Sensors frame (the plant's sensor message) is the cycle's trigger — the
//! shell steps the core when one arrives; without one, [`Tcu::poll_timeout`] says when the core
//! must run by itself: [`SENSOR_SILENCE`] after the last sensor frame, then every [`CYCLE`], so the
//! safe state is commanded when the sensors go silent. The cycle is TCU_ClutchCmd's cycle time in
//! the DBC (`GenMsgCycleTime`).

pub mod calibration;
pub mod config;
pub mod control;
pub mod estimator;
pub mod inputs;
pub mod routine;
pub mod sender;
pub mod strategy;

pub use config::{TcuConfig, TcuConfigError};

/// A DCT_Sensors frame: the plant's sensor message, which marks each of its cycles (a lockstep
/// bench counts bus time in them, whatever their content).
pub(crate) fn is_cycle_frame(f: &CanFrame) -> bool {
    f.standard_id() == Some(ids::DCT_SENSORS)
}

/// A DCT_Sensors frame with its E2E CRC right: the trigger of a TCU cycle in real time (the
/// sync). A frame whose CRC is wrong (corrupted, or a flood of garbage on that id) triggers
/// nothing: it is checked and counted by the inputs at the next computation, so a bad-CRC flood
/// cannot drive the TCU at the flood's rate.
pub(crate) fn is_sync_frame(f: &CanFrame) -> bool {
    is_cycle_frame(f) && crate::can::e2e::crc_ok(ids::DCT_SENSORS, f.bytes())
}

/// The TCU's computation cycle: TCU_ClutchCmd's cycle time in the DBC.
pub const CYCLE: Duration = Duration::from_millis(TcuClutchCmd::CYCLE_MS as u64);

/// Without a DCT_Sensors frame for this long the core runs by itself (a sensor frame later than
/// its cycle is waited for until the next cycle's slot): two cycles after the last one.
pub const SENSOR_SILENCE: Duration = Duration::from_millis(2 * TcuClutchCmd::CYCLE_MS as u64);

pub use inputs::{Input, Measurements, TimedFrame, Verdict};

use crate::can::e2e::E2eSender;
use crate::can::messages::{
    ids, FaultCode, GearEvenReq, GearOddReq, TcuClutchCmd, TcuEngineReq, TcuEstimates, TcuGearCmd,
    TcuState, TcuStatus,
};
use crate::can::CanFrame;
use control::{approach, ClutchModel};
use estimator::{EstimatorInputs, ThermalEstimator};
use inputs::{Health, InputCounters, InputMonitor};
use routine::{KissRoutine, RoutineInputs, RoutineRefusal, RoutineState};
use std::time::Duration;
use strategy::{Command, Ctx, Strategy};

/// Inputs of one step: the frames received since the previous step, in arrival order.
#[derive(Debug, Clone, Copy, Default)]
pub struct TcuInputs<'a> {
    pub frames: &'a [TimedFrame],
}

/// Internal values of one step, for traces, plots and tests.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TcuTrace {
    pub t_s: f64,
    pub state: TcuState,
    pub fault: FaultCode,
    pub phase: &'static str,
    pub x_ref_mm: [f64; 2],
    pub t_ref_nm: [f64; 2],
    pub engine_req_nm: Option<f64>,
    pub w_e_ref_radps: f64,
    pub w_c_ref_radps: f64,
    pub theta_est_c: [f64; 2],
    pub theta_body_c: f64,
    pub power_est_w: [f64; 2],
    pub torque_est_nm: [f64; 2],
    pub measurements: Measurements,
}

/// Outputs of one step: the five TCU messages (typed) and their encoded, E2E-protected frames.
#[derive(Debug, Clone, PartialEq)]
pub struct TcuOutputs {
    pub clutch_cmd: TcuClutchCmd,
    pub engine_req: TcuEngineReq,
    pub gear_cmd: TcuGearCmd,
    pub status: TcuStatus,
    pub estimates: TcuEstimates,
    /// The frames to send, in the order above.
    pub frames: Vec<CanFrame>,
    pub trace: TcuTrace,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Top {
    Init,
    Run,
    Safe,
}

/// The TCU core.
#[derive(Debug, Clone)]
pub struct Tcu {
    cfg: TcuConfig,
    model: ClutchModel,
    inputs: InputMonitor,
    est: ThermalEstimator,
    strategy: Strategy,
    routine: KissRoutine,
    tx: E2eSender,
    top: Top,
    last_now: Option<Duration>,
    /// Time of the last step that had a DCT_Sensors frame.
    last_sync: Option<Duration>,
    start: Duration,
    safe_fault: FaultCode,
    safe_x: [f64; 2],
    last_x: [f64; 2],
    warn: bool,
    limit: bool,
    w_out_prev: Option<f64>,
    w_out_dot: f64,
    nonfinite: bool,
    steps: u64,
    safe_entries: u64,
}

impl Tcu {
    /// A TCU starting at time `start` (timeouts of never-seen inputs count from here).
    pub fn new(cfg: TcuConfig, start: Duration) -> Self {
        let model = ClutchModel::with_effects(cfg.physics.clutch, cfg.compensation, cfg.effect_set);
        Self {
            inputs: InputMonitor::new(cfg.inputs, cfg.physics.driveline, start),
            est: ThermalEstimator::new(
                cfg.physics.thermal3,
                cfg.estimator.initial_temp_c,
                cfg.estimator.slip_deadband_radps,
            ),
            strategy: Strategy::new(&cfg),
            routine: KissRoutine::default(),
            tx: E2eSender::new(),
            top: Top::Init,
            last_now: None,
            last_sync: None,
            start,
            safe_fault: FaultCode::None,
            safe_x: [0.0; 2],
            last_x: [0.0; 2],
            warn: false,
            limit: false,
            w_out_prev: None,
            w_out_dot: 0.0,
            nonfinite: false,
            steps: 0,
            safe_entries: 0,
            model,
            cfg,
        }
    }

    pub fn config(&self) -> &TcuConfig {
        &self.cfg
    }

    /// Latest accepted measurements.
    pub fn measurements(&self) -> &Measurements {
        self.inputs.measurements()
    }

    /// Per-input accepted/rejected frame counts.
    pub fn input_counters(&self) -> InputCounters {
        self.inputs.counters()
    }

    /// Input health at `now`.
    pub fn health(&self, now: Duration) -> Health {
        self.inputs.health(now)
    }

    /// Number of times the safe state was entered.
    pub fn safe_entries(&self) -> u64 {
        self.safe_entries
    }

    /// Whether the TCU is in the safe state.
    pub fn in_safe_state(&self) -> bool {
        self.top == Top::Safe
    }

    /// Estimated clutch temperatures (°C).
    pub fn temperatures(&self) -> [f64; 2] {
        self.est.clutch_temps(f64::NAN)
    }

    /// Kiss points x_ISP(θ̂) (9) of the TCU's clutch model at the estimated temperatures (mm).
    pub fn kiss_points(&self) -> [f64; 2] {
        self.temperatures().map(|t| self.model.kiss_point(t))
    }

    /// Starts the kiss-point adaptation routine ([`routine`]) for `clutch` (0 odd, 1 even),
    /// checked against the latest measurements: the TCU running without a fault, standstill,
    /// lever P or N, engine running, pedal released. It acts from the next step.
    pub fn start_kiss_point_routine(&mut self, clutch: usize) -> Result<(), RoutineRefusal> {
        let healthy = self.top == Top::Run;
        self.routine
            .start(clutch, &self.cfg, self.inputs.measurements(), healthy)
    }

    /// Stops a running kiss-point routine (aborted, stopped by the tester): the strategy reopens
    /// the clutch from the next step.
    pub fn stop_kiss_point_routine(&mut self) {
        self.routine.stop();
    }

    /// The kiss-point routine's state.
    pub fn kiss_point_routine(&self) -> RoutineState {
        self.routine.state()
    }

    /// The kiss points the routine has learned (mm), per clutch.
    pub fn learned_kiss_points(&self) -> [Option<f64>; 2] {
        self.routine.learned()
    }

    /// Kiss points learned before a restart of the core (an ECUReset keeps them, as a TCU keeps
    /// its adaptation values in non-volatile memory).
    pub fn restore_learned_kiss_points(&mut self, learned: [Option<f64>; 2]) {
        self.routine.restore_learned(learned);
    }

    /// Sets one calibration on the bus (UDS WriteDataByIdentifier, XCP DOWNLOAD): the whole
    /// calibration is validated with the new value (its key's range and the rules between keys)
    /// and, if valid, takes effect at the next step — the clutch model is rebuilt, the controller
    /// gains change with their integrators kept. A switch takes exactly 0 or 1. On an error
    /// nothing changes.
    pub fn set_calibration(
        &mut self,
        cal: calibration::Calibration,
        value: f64,
    ) -> Result<(), TcuConfigError> {
        if cal.is_switch() && value != 0.0 && value != 1.0 {
            return Err(TcuConfigError::Inconsistent {
                key: cal.key().into(),
                reason: format!("{value} is not a switch value (0 or 1)"),
            });
        }
        let mut c = self.cfg.clone();
        cal.put(&mut c, value);
        c.validate()?;
        self.cfg = c;
        self.model = ClutchModel::with_effects(
            self.cfg.physics.clutch,
            self.cfg.compensation,
            self.cfg.effect_set,
        );
        self.strategy.set_gains(&self.cfg);
        Ok(())
    }

    /// When the core must next run without a new DCT_Sensors frame: at once before its first
    /// step; [`SENSOR_SILENCE`] after the last step that had one; every [`CYCLE`] after its
    /// previous step while the sensors are silent (or were never seen).
    pub fn poll_timeout(&self) -> Duration {
        match (self.last_now, self.last_sync) {
            (None, _) => self.start,
            (Some(step), Some(sync)) if step < sync + SENSOR_SILENCE => sync + SENSOR_SILENCE,
            (Some(step), _) => step + CYCLE,
        }
    }

    /// Feeds frames without computing (the daemon calls this between computations so frame
    /// arrival times are checked as they come).
    pub fn receive(&mut self, frames: &[TimedFrame]) {
        for f in frames {
            self.inputs.accept(f);
        }
    }

    /// One TCU cycle at `now`.
    pub fn step(&mut self, now: Duration, inputs: &TcuInputs) -> TcuOutputs {
        let dt = self.advance(now, inputs);
        let m = *self.inputs.measurements();
        self.filter_output_accel(&m, dt);
        let health = self.estimate(&m, self.inputs.health(now), dt);
        let theta = self.est.clutch_temps(if m.theta_h.is_finite() {
            m.theta_h
        } else {
            self.cfg.compensation.calibration_temp_c
        });
        self.update_over_temperature(theta);
        let grace = now.saturating_sub(self.start) >= CYCLE * self.cfg.inputs.timeout_cycles;
        let restart = self.top_transition(&health);
        let ctx = Ctx {
            cfg: &self.cfg,
            model: &self.model,
            m: &m,
            theta,
            dt,
            w_out_dot: self.w_out_dot,
            limit_torque: self.limit,
        };
        if restart {
            self.top = Top::Run;
            self.strategy.restart(&ctx);
        }
        let cmd = match self.top {
            Top::Init => Command {
                x_ref: [self.cfg.control.open_position_mm; 2],
                state: TcuState::Init,
                phase: "init",
                ..Default::default()
            },
            Top::Safe => self.safe_command(dt),
            Top::Run => self.strategy.step(&ctx),
        };
        let cmd = self.apply_routine(cmd, &m, theta, now);
        let cmd = self.finite_and_in_range(cmd);
        let fault = self.fault_code(grace, &health);
        let trace = TcuTrace {
            t_s: now.as_secs_f64(),
            state: cmd.state,
            fault,
            phase: cmd.phase,
            x_ref_mm: cmd.x_ref,
            t_ref_nm: cmd.t_ref,
            engine_req_nm: cmd.engine_req,
            w_e_ref_radps: cmd.w_e_ref,
            w_c_ref_radps: cmd.w_c_ref,
            theta_est_c: theta,
            theta_body_c: self.est.state().map_or(f64::NAN, |s| s.body),
            power_est_w: self.est.power_w,
            torque_est_nm: self.est.torque_nm,
            measurements: m,
        };
        self.encode(&cmd, fault, theta, trace)
    }

    /// Takes the cycle's frames and returns the time since the last step (s, at most 0.1; 0 at
    /// the first).
    fn advance(&mut self, now: Duration, inputs: &TcuInputs) -> f64 {
        self.steps += 1;
        if inputs.frames.iter().any(|f| is_sync_frame(&f.frame)) {
            self.last_sync = Some(now);
        }
        self.receive(inputs.frames);
        let dt = match self.last_now {
            Some(prev) => now.saturating_sub(prev).as_secs_f64().min(0.1),
            None => 0.0,
        };
        self.last_now = Some(now);
        dt
    }

    /// Output-shaft acceleration, filtered (time constant `control.accel_filter_s`).
    fn filter_output_accel(&mut self, m: &Measurements, dt: f64) {
        if self.inputs.all_seen() && dt > 0.0 {
            if let Some(prev) = self.w_out_prev {
                let raw = (m.w_out - prev) / dt;
                let a = dt / (self.cfg.control.accel_filter_s + dt);
                if raw.is_finite() {
                    self.w_out_dot += a * (raw - self.w_out_dot);
                }
            }
            self.w_out_prev = Some(m.w_out);
        }
    }

    /// Updates the thermal estimator (when every sensor value is there and fresh) and returns
    /// the inputs' health with a failed update as a fault like a missing input: the temperature
    /// estimate the torque inversion needs is gone.
    fn estimate(&mut self, m: &Measurements, health: Health, dt: f64) -> Health {
        if self.inputs.all_seen() && health.all_fresh {
            let u = EstimatorInputs {
                x_mm: m.x_mm,
                slip_radps: [m.slip(0), m.slip(1)],
                theta_h_c: m.theta_h,
            };
            self.est.update(&self.model, &u, dt);
        }
        if self.est.failed() {
            health.with_internal_fault(FaultCode::InternalNonFinite)
        } else {
            health
        }
    }

    /// Over-temperature warning and limit, with hysteresis.
    fn update_over_temperature(&mut self, theta: [f64; 2]) {
        let tmax = theta[0].max(theta[1]);
        let s = self.cfg.safety;
        let hys = s.over_temp_hysteresis_c;
        self.warn = tmax > s.over_temp_warn_c || (self.warn && tmax > s.over_temp_warn_c - hys);
        self.limit = tmax > s.over_temp_limit_c || (self.limit && tmax > s.over_temp_limit_c - hys);
    }

    /// The top-level state's transitions: a stale input sends a running TCU to the safe state;
    /// returns whether the strategy (re)starts (every input seen and fresh from init, or
    /// recovered from the safe state).
    fn top_transition(&mut self, health: &Health) -> bool {
        match self.top {
            Top::Init => self.inputs.all_seen() && health.all_fresh,
            Top::Run => {
                if !health.all_fresh {
                    self.enter_safe(health.fault.unwrap_or(FaultCode::InternalNonFinite));
                }
                false
            }
            Top::Safe => {
                if let Some(f) = health.fault {
                    self.safe_fault = f;
                }
                health.recovered
            }
        }
    }

    /// A running kiss-point routine's cycle (aborted outside the run state): its clutch at the
    /// routine's position with its shaft in neutral, the other clutch open; remembered as the
    /// strategy's last command.
    fn apply_routine(
        &mut self,
        mut cmd: Command,
        m: &Measurements,
        theta: [f64; 2],
        now: Duration,
    ) -> Command {
        let RoutineState::Running { clutch } = self.routine.state() else {
            return cmd;
        };
        let u = RoutineInputs {
            cfg: &self.cfg,
            m,
            now_s: now.as_secs_f64(),
            model_kiss_mm: self.model.kiss_point(theta[clutch]),
            healthy: self.top == Top::Run,
        };
        let Some(r) = self.routine.step(&u) else {
            return cmd;
        };
        cmd.x_ref[r.clutch] = r.x_ref_mm;
        cmd.x_ref[1 - r.clutch] = self.cfg.control.open_position_mm;
        cmd.t_ref = [0.0; 2];
        cmd.gear_req[r.clutch] = crate::model::gear::Gear::N;
        cmd.phase = r.phase;
        self.strategy.override_last(&cmd);
        cmd
    }

    /// The safe state's command: both clutches opened at the safe rate, the gears as they were.
    fn safe_command(&mut self, dt: f64) -> Command {
        let s = self.cfg.safety;
        for i in 0..2 {
            self.safe_x[i] = approach(
                self.safe_x[i],
                self.cfg.control.open_position_mm,
                s.open_rate_mm_per_s,
                dt,
            );
        }
        let last = *self.strategy.last();
        Command {
            x_ref: self.safe_x,
            gear_req: last.gear_req,
            state: TcuState::SafeState,
            phase: "safe",
            ..Default::default()
        }
    }

    /// Finite outputs, always (a non-finite command holds the last positions without torque),
    /// the positions within the actuator's range; remembered for the next cycle.
    fn finite_and_in_range(&mut self, mut cmd: Command) -> Command {
        self.nonfinite = !(cmd.x_ref.iter().all(|v| v.is_finite())
            && cmd.t_ref.iter().all(|v| v.is_finite())
            && cmd.engine_req.is_none_or(f64::is_finite));
        if self.nonfinite {
            cmd.x_ref = self.last_x;
            cmd.t_ref = [0.0; 2];
            cmd.engine_req = None;
        }
        let xmax = self.cfg.physics.actuator.x_max_mm;
        for x in cmd.x_ref.iter_mut() {
            *x = x.clamp(self.cfg.physics.actuator.x_min_mm, xmax);
        }
        self.last_x = cmd.x_ref;
        if self.top != Top::Safe {
            self.safe_x = cmd.x_ref;
        }
        cmd
    }

    /// The fault code this cycle reports: the safe state's; in init, an input's once the
    /// start-up grace is over; else a non-finite command, a refused lever, over-temperature.
    fn fault_code(&self, grace: bool, health: &Health) -> FaultCode {
        if self.top == Top::Safe {
            self.safe_fault
        } else if self.top == Top::Init {
            if grace {
                health.fault.unwrap_or(FaultCode::None)
            } else {
                FaultCode::None
            }
        } else if self.nonfinite {
            FaultCode::InternalNonFinite
        } else if self.inputs.lever_refused() {
            FaultCode::ImplausibleLever
        } else if self.limit {
            FaultCode::ClutchOverTempLimit
        } else if self.warn {
            FaultCode::ClutchOverTempWarning
        } else {
            FaultCode::None
        }
    }

    fn enter_safe(&mut self, fault: FaultCode) {
        self.top = Top::Safe;
        self.safe_fault = fault;
        self.safe_x = self.last_x;
        self.safe_entries += 1;
    }

    fn encode(
        &mut self,
        cmd: &Command,
        fault: FaultCode,
        theta: [f64; 2],
        trace: TcuTrace,
    ) -> TcuOutputs {
        let clutch_cmd = TcuClutchCmd {
            clutch1_pos_req: TcuClutchCmd::saturate_clutch1_pos_req(cmd.x_ref[0]),
            clutch2_pos_req: TcuClutchCmd::saturate_clutch2_pos_req(cmd.x_ref[1]),
            ..Default::default()
        };
        let engine_req = TcuEngineReq {
            eng_torque_req: TcuEngineReq::saturate_eng_torque_req(cmd.engine_req.unwrap_or(0.0)),
            eng_torque_req_active: cmd.engine_req.is_some(),
            ..Default::default()
        };
        let gear_cmd = TcuGearCmd {
            // The strategy requests each shaft's gears only on that shaft (`safe_gear_req`, the
            // shift's from/to on their clutches' shafts): the conversions cannot fail.
            gear_odd_req: GearOddReq::try_from(cmd.gear_req[0]).unwrap_or(GearOddReq::N),
            gear_even_req: GearEvenReq::try_from(cmd.gear_req[1]).unwrap_or(GearEvenReq::N),
            ..Default::default()
        };
        let status = TcuStatus {
            gear_active: cmd.gear_active.into(),
            tcu_state: cmd.state,
            fault_code: fault,
            ..Default::default()
        };
        let estimates = TcuEstimates {
            clutch1_temp_est: TcuEstimates::saturate_clutch1_temp_est(theta[0]),
            clutch2_temp_est: TcuEstimates::saturate_clutch2_temp_est(theta[1]),
            clutch1_torque_req: TcuEstimates::saturate_clutch1_torque_req(cmd.t_ref[0]),
            clutch2_torque_req: TcuEstimates::saturate_clutch2_torque_req(cmd.t_ref[1]),
        };
        let mut frames = Vec::with_capacity(5);
        let encoded = [
            (ids::TCU_CLUTCH_CMD, clutch_cmd.encode()),
            (ids::TCU_ENGINE_REQ, engine_req.encode()),
            (ids::TCU_GEAR_CMD, gear_cmd.encode()),
            (ids::TCU_STATUS, status.encode()),
            (ids::TCU_ESTIMATES, estimates.encode()),
        ];
        for (id, data) in encoded {
            // Every value was fitted to its DBC range above, so encoding cannot fail; a failure
            // would drop that one frame (the receiver's timeout then reports it), never panic.
            if let Ok(mut d) = data {
                self.tx.protect(id, &mut d);
                if let Ok(f) = CanFrame::standard(id, &d) {
                    frames.push(f);
                }
            }
        }
        TcuOutputs {
            clutch_cmd,
            engine_req,
            gear_cmd,
            status,
            estimates,
            frames,
            trace,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    /// A DCT_Sensors frame at `at`, its E2E CRC right or (`crc_ok` false) wrong.
    fn sensors_with(at: Duration, crc_ok: bool) -> TimedFrame {
        let mut data = [0u8; 8];
        crate::can::e2e::protect(ids::DCT_SENSORS, &mut data, 1);
        if !crc_ok {
            data[crate::can::e2e::CRC_BYTE] ^= 0x5A;
        }
        TimedFrame {
            at,
            frame: CanFrame::standard(ids::DCT_SENSORS, &data).unwrap(),
        }
    }

    fn sensors(at: Duration) -> TimedFrame {
        sensors_with(at, true)
    }

    /// A DCT_Sensors frame with a wrong CRC (a garbage flood on that id) is no sync: it neither
    /// triggers nor moves the deadline, so a flood cannot drive the TCU at its own rate.
    #[test]
    fn only_a_sensor_frame_with_its_crc_right_is_a_sync() {
        assert!(is_sync_frame(&sensors(ms(0)).frame));
        assert!(!is_sync_frame(&sensors_with(ms(0), false).frame));
        let short = CanFrame::standard(ids::DCT_SENSORS, &[0; 4]).unwrap();
        assert!(!is_sync_frame(&short));
        let mut tcu = Tcu::new(TcuConfig::default(), ms(5));
        tcu.step(
            ms(5),
            &TcuInputs {
                frames: &[sensors(ms(5))],
            },
        );
        assert_eq!(tcu.poll_timeout(), ms(25));
        tcu.step(
            ms(12),
            &TcuInputs {
                frames: &[sensors_with(ms(12), false)],
            },
        );
        assert_eq!(
            tcu.poll_timeout(),
            ms(25),
            "a bad-CRC frame moved the deadline"
        );
    }

    /// The timing policy: at once before the first step; two cycles after the last sensor frame;
    /// then every cycle while the sensors are silent; a sensor frame puts the deadline back.
    #[test]
    fn poll_timeout_follows_the_sensor_frames_and_falls_back_every_cycle() {
        assert_eq!(CYCLE, ms(10), "the DBC's TCU_ClutchCmd cycle");
        let mut tcu = Tcu::new(TcuConfig::default(), ms(5));
        assert_eq!(tcu.poll_timeout(), ms(5));
        // (step at ms, with a DCT_Sensors frame, poll_timeout after it ms)
        let steps = [
            (5, false, 15),  // never a sensor frame: a cycle after the previous step
            (17, true, 37),  // a sensor frame: the next own run two cycles later, not one
            (30, false, 37), // a step without one (another node's frame) does not move it
            (37, false, 47), // silent: every cycle from there
            (47, false, 57),
            (52, true, 72),
        ];
        for (at, sync, next) in steps {
            let frames = if sync { vec![sensors(ms(at))] } else { vec![] };
            tcu.step(ms(at), &TcuInputs { frames: &frames });
            assert_eq!(tcu.poll_timeout(), ms(next), "after the step at {at} ms");
        }
    }
}

//! The kiss-point adaptation routine (issue 16, UDS RoutineControl 0x0201): a pure state machine
//! that learns where one clutch starts to transmit torque, i.e. the kiss point x_ISP(θ) of (9)
//! at which the flat-spring compression u_fs of (7) and so the torque of (13) leave zero.
//!
//! At standstill, lever in P or N, engine running: the clutch's shaft goes to neutral and the
//! clutch fully open (the other one stays open too), then
//! 1. **settle**: once the shaft reads neutral, the mean input-shaft speed of consecutive windows
//!    of `settle_window_s` until two agree within `steady_rpm` (spun down or steady);
//! 2. **approach**: to `start_before_kiss_mm` before the model's x_ISP(θ̂) at
//!    `approach_rate_mm_per_s`, then **hold** there for `hold_s`, the speed baseline ω₀ being the
//!    hold's mean;
//! 3. **ramp**: closes at `ramp_rate_mm_per_s` (r), recording (t, measured position, measured
//!    shaft speed) every cycle, until the speed has left ω₀ by `detect_rpm` toward the engine.
//!
//! Lag-corrected estimate. Past the kiss point (13) gives T = k·(x − x_k) (the spring (10) is
//! linear to < 1 % over the few µm involved, the friction (6) constant at the idle slip), the
//! bearing moves as x(t) = x_k + r·(t − t₀), so the free shaft (inertia J, no load in neutral)
//! speeds up as Δω(t) = k·r/(2J)·(t − t₀)²: √Δω is linear in t. The onset t₀ is where the
//! least-squares line of √Δω over the samples between `fit_floor_rpm` and `detect_rpm` crosses
//! zero — this removes the detection lag (the time the speed needs to rise above the sensor's
//! 0.5 rpm quantisation and noise). The kiss point is the *measured* position at t₀, from the
//! least-squares line of the measured positions over `position_fit_s` before the detection
//! (0.001 mm quantisation and noise averaged): reading the bearing rather than the request
//! removes the actuator lag (first order plus command delay) and makes the estimate independent
//! of the rate. With a drag on the shaft the estimate is where the torque of (13) exceeds the
//! drag, as in production.
//!
//! The learned value is x_ISP at the clutch's current temperature; it is kept per clutch
//! ([`KissRoutine::learned`]). No clock: the TCU passes its step's time.

use super::config::{KissRoutineCfg, TcuConfig};
use super::control::approach;
use super::inputs::Measurements;
use crate::can::messages::GearLever;
use crate::model::engine::RPM;
use std::collections::VecDeque;

/// A start or run condition that does not hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum Condition {
    #[error("vehicle not at standstill")]
    NotAtStandstill,
    #[error("gear lever not in P or N")]
    LeverNotParkOrNeutral,
    #[error("engine not running")]
    EngineNotRunning,
    #[error("TCU in its safe state or not yet running (input fault)")]
    FaultOrSafeState,
    #[error("accelerator pedal pressed")]
    PedalPressed,
}

/// Why a start was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum RoutineRefusal {
    #[error(transparent)]
    Condition(#[from] Condition),
    #[error("no clutch {0} (0 or 1)")]
    InvalidClutch(usize),
    #[error("the routine is already running")]
    AlreadyRunning,
}

/// Why a running routine was aborted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum AbortReason {
    #[error(transparent)]
    Condition(#[from] Condition),
    #[error("timeout")]
    Timeout,
    #[error("stopped by the tester")]
    StoppedByTester,
    #[error("the shaft did not move up to the end of the ramp")]
    ShaftDidNotMove,
    #[error("the shaft moved before the ramp started (kiss point below the search range)")]
    ShaftMovedEarly,
}

impl Condition {
    /// The reason byte of RoutineControl's result (docs/diagnostics.md).
    pub fn code(self) -> u8 {
        match self {
            Condition::NotAtStandstill => 1,
            Condition::LeverNotParkOrNeutral => 2,
            Condition::EngineNotRunning => 3,
            Condition::FaultOrSafeState => 4,
            Condition::PedalPressed => 5,
        }
    }
}

impl AbortReason {
    /// The reason byte of RoutineControl's result: a condition's code (1–5), then 6 timeout,
    /// 7 stopped by the tester, 8 the shaft did not move, 9 it moved before the ramp.
    pub fn code(self) -> u8 {
        match self {
            AbortReason::Condition(c) => c.code(),
            AbortReason::Timeout => 6,
            AbortReason::StoppedByTester => 7,
            AbortReason::ShaftDidNotMove => 8,
            AbortReason::ShaftMovedEarly => 9,
        }
    }
}

/// The routine's state as RoutineControl reports it. `clutch` is 0 (odd) or 1 (even).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum RoutineState {
    #[default]
    Idle,
    Running {
        clutch: usize,
    },
    Done {
        clutch: usize,
        kiss_mm: f64,
    },
    Aborted {
        clutch: usize,
        reason: AbortReason,
    },
}

impl RoutineState {
    /// The status byte of RoutineControl's result: 0 idle, 1 running, 2 done, 3 aborted.
    pub fn code(self) -> u8 {
        match self {
            RoutineState::Idle => 0,
            RoutineState::Running { .. } => 1,
            RoutineState::Done { .. } => 2,
            RoutineState::Aborted { .. } => 3,
        }
    }
}

/// Whether the routine may start or keep running: the TCU running without a fault (`healthy`),
/// standstill, lever P/N, engine running, pedal released.
pub fn check(cfg: &TcuConfig, m: &Measurements, healthy: bool) -> Result<(), Condition> {
    let k = &cfg.kiss_routine;
    let v_kmh = m.w_out * cfg.physics.driveline.wheel_radius_m * 3.6;
    let idle = cfg.physics.engine.idle_speed_rpm * RPM;
    // Written so that a NaN measurement fails the condition.
    let standstill = v_kmh.abs() < k.max_vehicle_kmh;
    let running = m.w_e > k.engine_running_idle_fraction * idle;
    if !healthy {
        Err(Condition::FaultOrSafeState)
    } else if !matches!(m.lever, GearLever::P | GearLever::N) {
        Err(Condition::LeverNotParkOrNeutral)
    } else if !standstill {
        Err(Condition::NotAtStandstill)
    } else if !running {
        Err(Condition::EngineNotRunning)
    } else if m.pedal * 100.0 > cfg.creep.pedal_on_pct {
        Err(Condition::PedalPressed)
    } else {
        Ok(())
    }
}

/// What a running routine commands this cycle: the clutch's position request (mm); its shaft in
/// neutral and the other clutch open are the caller's.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RoutineCommand {
    pub clutch: usize,
    pub x_ref_mm: f64,
    /// Short name of the phase, for traces.
    pub phase: &'static str,
}

/// One cycle's inputs of a running routine.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RoutineInputs<'a> {
    pub cfg: &'a TcuConfig,
    pub m: &'a Measurements,
    /// Time of the step (s, the TCU's time base).
    pub now_s: f64,
    /// The model's kiss point x_ISP(θ̂) (9) of the routine's clutch (mm).
    pub model_kiss_mm: f64,
    /// The TCU is running without a fault.
    pub healthy: bool,
}

/// A running mean.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Mean {
    sum: f64,
    n: u32,
}

impl Mean {
    fn push(&mut self, v: f64) {
        self.sum += v;
        self.n += 1;
    }
    fn get(&self) -> Option<f64> {
        (self.n > 0).then(|| self.sum / f64::from(self.n))
    }
}

/// One ramp sample: time (s), measured position (mm), speed above the baseline toward the
/// engine (rpm).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Sample {
    t: f64,
    x: f64,
    dw_rpm: f64,
}

#[derive(Debug, Clone, PartialEq)]
enum Phase {
    /// Open, neutral requested; windows of the shaft speed (rpm) once neutral is read.
    Settle {
        since: Option<f64>,
        window: Mean,
        prev: Option<f64>,
    },
    /// To the ramp's start; `w0` the settled speed (rpm).
    Approach {
        w0: f64,
    },
    Hold {
        w0: f64,
        until: f64,
        window: Mean,
    },
    /// `w0` the baseline (rpm), `sign` the direction the engine pulls, `t0` the ramp's start.
    Ramp {
        w0: f64,
        sign: f64,
        t0: f64,
        samples: VecDeque<Sample>,
    },
}

#[derive(Debug, Clone, PartialEq)]
struct Run {
    clutch: usize,
    start_s: Option<f64>,
    last_s: Option<f64>,
    x_cmd: f64,
    phase: Phase,
}

/// The routine: its state, the running routine's data and the learned kiss points.
#[derive(Debug, Clone, Default)]
pub(crate) struct KissRoutine {
    state: RoutineState,
    run: Option<Run>,
    learned: [Option<f64>; 2],
}

impl KissRoutine {
    pub fn state(&self) -> RoutineState {
        self.state
    }

    /// The kiss points learned so far (mm), per clutch.
    pub fn learned(&self) -> [Option<f64>; 2] {
        self.learned
    }

    /// Kiss points learned before a restart (the routine itself starts idle).
    pub fn restore_learned(&mut self, learned: [Option<f64>; 2]) {
        self.learned = learned;
    }

    /// Starts for `clutch` (0 or 1) if the conditions hold (see [`check`]); a finished or aborted
    /// run is replaced.
    pub fn start(
        &mut self,
        clutch: usize,
        cfg: &TcuConfig,
        m: &Measurements,
        healthy: bool,
    ) -> Result<(), RoutineRefusal> {
        if clutch > 1 {
            return Err(RoutineRefusal::InvalidClutch(clutch));
        }
        if self.run.is_some() {
            return Err(RoutineRefusal::AlreadyRunning);
        }
        check(cfg, m, healthy)?;
        self.run = Some(Run {
            clutch,
            start_s: None,
            last_s: None,
            x_cmd: cfg.control.open_position_mm,
            phase: Phase::Settle {
                since: None,
                window: Mean::default(),
                prev: None,
            },
        });
        self.state = RoutineState::Running { clutch };
        Ok(())
    }

    /// Stops a running routine (aborted, "stopped by the tester"); the strategy takes the clutch
    /// back and reopens it. Nothing happens when none runs.
    pub fn stop(&mut self) {
        self.abort(AbortReason::StoppedByTester);
    }

    /// Aborts a running routine with `reason`.
    pub fn abort(&mut self, reason: AbortReason) {
        if let Some(r) = self.run.take() {
            self.state = RoutineState::Aborted {
                clutch: r.clutch,
                reason,
            };
        }
    }

    /// One cycle: the command while running, `None` otherwise (also in the cycle it finishes or
    /// aborts: the strategy then commands the clutch again).
    pub fn step(&mut self, u: &RoutineInputs) -> Option<RoutineCommand> {
        let run = self.run.as_mut()?;
        let k = u.cfg.kiss_routine;
        let start = *run.start_s.get_or_insert(u.now_s);
        let dt = run.last_s.map_or(0.0, |l| (u.now_s - l).max(0.0));
        run.last_s = Some(u.now_s);
        if let Err(c) = check(u.cfg, u.m, u.healthy) {
            self.abort(c.into());
            return None;
        }
        if u.now_s - start > k.timeout_s {
            self.abort(AbortReason::Timeout);
            return None;
        }
        match advance(run, u, dt) {
            Ok(None) => Some(RoutineCommand {
                clutch: run.clutch,
                x_ref_mm: run.x_cmd,
                phase: phase_name(&run.phase),
            }),
            Ok(Some(kiss_mm)) => {
                let clutch = run.clutch;
                self.run = None;
                self.learned[clutch] = Some(kiss_mm);
                self.state = RoutineState::Done { clutch, kiss_mm };
                None
            }
            Err(reason) => {
                self.abort(reason);
                None
            }
        }
    }
}

fn phase_name(p: &Phase) -> &'static str {
    match p {
        Phase::Settle { .. } => "kiss_settle",
        Phase::Approach { .. } | Phase::Hold { .. } => "kiss_approach",
        Phase::Ramp { .. } => "kiss_ramp",
    }
}

/// The shaft speed of the routine's clutch (rpm).
fn shaft_rpm(u: &RoutineInputs, clutch: usize) -> f64 {
    u.m.w_c[clutch] / RPM
}

/// Advances the running routine by one cycle: `Ok(Some(kiss))` when learned.
fn advance(run: &mut Run, u: &RoutineInputs, dt: f64) -> Result<Option<f64>, AbortReason> {
    let k = u.cfg.kiss_routine;
    let c = run.clutch;
    let w = shaft_rpm(u, c);
    let start_x = (u.model_kiss_mm - k.start_before_kiss_mm).max(u.cfg.control.open_position_mm);
    match &mut run.phase {
        Phase::Settle {
            since,
            window,
            prev,
        } => {
            if u.m.gear[c] != crate::model::gear::Gear::N {
                return Ok(None);
            }
            let begin = *since.get_or_insert(u.now_s);
            window.push(w);
            if u.now_s - begin >= k.settle_window_s {
                let mean = window.get().unwrap_or(w);
                if prev.is_some_and(|p| (mean - p).abs() < k.steady_rpm) {
                    run.phase = Phase::Approach { w0: mean };
                } else {
                    *prev = Some(mean);
                    *since = Some(u.now_s);
                    *window = Mean::default();
                }
            }
        }
        Phase::Approach { w0 } => {
            early_motion(u, *w0, w)?;
            run.x_cmd = approach(run.x_cmd, start_x, k.approach_rate_mm_per_s, dt);
            if run.x_cmd == start_x {
                run.phase = Phase::Hold {
                    w0: *w0,
                    until: u.now_s + k.hold_s,
                    window: Mean::default(),
                };
            }
        }
        Phase::Hold { w0, until, window } => {
            early_motion(u, *w0, w)?;
            window.push(w);
            if u.now_s >= *until {
                let w0 = window.get().unwrap_or(*w0);
                let sign = if u.m.w_e / RPM >= w0 { 1.0 } else { -1.0 };
                run.phase = Phase::Ramp {
                    w0,
                    sign,
                    t0: u.now_s,
                    samples: VecDeque::new(),
                };
            }
        }
        Phase::Ramp {
            w0,
            sign,
            t0,
            samples,
        } => {
            run.x_cmd += k.ramp_rate_mm_per_s * dt;
            return ramp(&k, u, c, (*w0, *sign, *t0), samples, run.x_cmd);
        }
    }
    Ok(None)
}

/// The shaft must not move toward the engine before the ramp (the kiss point would lie before
/// the search range).
fn early_motion(u: &RoutineInputs, w0: f64, w: f64) -> Result<(), AbortReason> {
    let sign = if u.m.w_e / RPM >= w0 { 1.0 } else { -1.0 };
    if sign * (w - w0) >= u.cfg.kiss_routine.detect_rpm {
        Err(AbortReason::ShaftMovedEarly)
    } else {
        Ok(())
    }
}

/// One ramp cycle: records the sample, drops those older than the position fit needs; on
/// detection the estimate, at the ramp's end "did not move".
fn ramp(
    k: &KissRoutineCfg,
    u: &RoutineInputs,
    c: usize,
    (w0, sign, t0): (f64, f64, f64),
    samples: &mut VecDeque<Sample>,
    x_cmd: f64,
) -> Result<Option<f64>, AbortReason> {
    let s = Sample {
        t: u.now_s,
        x: u.m.x_mm[c],
        dw_rpm: sign * (shaft_rpm(u, c) - w0),
    };
    samples.push_back(s);
    // Keep the position fit's window plus the onset's own samples (the onset lies within the
    // window before the detection as long as the fit floor is reached within it).
    while samples
        .front()
        .is_some_and(|f| s.t - f.t > 2.0 * k.position_fit_s)
    {
        samples.pop_front();
    }
    if s.dw_rpm >= k.detect_rpm {
        // The actuator's transient at the ramp's start is no part of the line.
        let from = t0 + 0.1 * k.position_fit_s;
        return estimate(k, samples.make_contiguous(), from).map(Some);
    }
    if x_cmd > u.model_kiss_mm + k.end_beyond_kiss_mm {
        return Err(AbortReason::ShaftDidNotMove);
    }
    Ok(None)
}

/// Least-squares line y = a + b·t through `pts`: (a, b), `None` when degenerate.
fn line(pts: impl Iterator<Item = (f64, f64)> + Clone) -> Option<(f64, f64)> {
    let n = pts.clone().count() as f64;
    if n < 2.0 {
        return None;
    }
    let (st, sy) = pts
        .clone()
        .fold((0.0, 0.0), |(a, b), (t, y)| (a + t, b + y));
    let (mt, my) = (st / n, sy / n);
    let (sxx, sxy) = pts.fold((0.0, 0.0), |(a, b), (t, y)| {
        (a + (t - mt) * (t - mt), b + (t - mt) * (y - my))
    });
    let spread = sxx > 0.0;
    if !spread {
        return None;
    }
    let b = sxy / sxx;
    Some((my - b * mt, b))
}

/// The kiss point from the ramp's samples (the last one at the detection): the onset t₀ where
/// the line of √Δω over the last run of samples at or above `fit_floor_rpm` crosses zero, and
/// the line of the measured positions over `position_fit_s` before the detection (not before
/// `from`) evaluated at t₀. Falls back to the detection's own sample when a line is degenerate.
fn estimate(k: &KissRoutineCfg, samples: &[Sample], from: f64) -> Result<f64, AbortReason> {
    let last = samples.last().ok_or(AbortReason::ShaftDidNotMove)?;
    let first_fit = samples
        .iter()
        .rposition(|s| s.dw_rpm < k.fit_floor_rpm)
        .map_or(0, |i| i + 1);
    let onset = samples[first_fit..]
        .iter()
        .map(|s| (s.t, s.dw_rpm.max(0.0).sqrt()));
    let t_on = match line(onset) {
        Some((a, b)) if b > 0.0 => (-a / b).min(last.t),
        _ => last.t,
    };
    let lo = (last.t - k.position_fit_s).max(from);
    let pos = samples.iter().filter(|s| s.t >= lo).map(|s| (s.t, s.x));
    Ok(match line(pos) {
        Some((a, b)) => a + b * t_on,
        None => last.x,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::gear::Gear;

    fn idle_meas() -> Measurements {
        Measurements {
            w_e: 800.0 * RPM,
            lever: GearLever::N,
            theta_h: 25.0,
            x_mm: [0.0; 2],
            gear: [Gear::G1, Gear::G2],
            brake: true,
            ..Default::default()
        }
    }

    #[test]
    fn refusals_name_the_condition() {
        let cfg = TcuConfig::default();
        let mut r = KissRoutine::default();
        let m = idle_meas();
        let cases = [
            (
                Measurements { w_out: 10.0, ..m },
                true,
                Condition::NotAtStandstill,
            ),
            (
                Measurements {
                    lever: GearLever::D,
                    ..m
                },
                true,
                Condition::LeverNotParkOrNeutral,
            ),
            (
                Measurements { w_e: 0.0, ..m },
                true,
                Condition::EngineNotRunning,
            ),
            (
                Measurements { pedal: 0.3, ..m },
                true,
                Condition::PedalPressed,
            ),
            (m, false, Condition::FaultOrSafeState),
        ];
        for (mm, healthy, want) in cases {
            assert_eq!(
                r.start(0, &cfg, &mm, healthy),
                Err(RoutineRefusal::Condition(want))
            );
            assert_eq!(r.state(), RoutineState::Idle);
        }
        assert_eq!(
            r.start(2, &cfg, &m, true),
            Err(RoutineRefusal::InvalidClutch(2))
        );
        assert_eq!(r.start(1, &cfg, &m, true), Ok(()));
        assert_eq!(r.state(), RoutineState::Running { clutch: 1 });
        assert_eq!(
            r.start(0, &cfg, &m, true),
            Err(RoutineRefusal::AlreadyRunning)
        );
        r.stop();
        assert_eq!(
            r.state(),
            RoutineState::Aborted {
                clutch: 1,
                reason: AbortReason::StoppedByTester
            }
        );
        assert_eq!(r.state().code(), 3);
        assert_eq!(AbortReason::StoppedByTester.code(), 7);
    }

    /// Synthetic ramp: bearing x = x_k + r (t − t_k) (measured with the actuator's lag as an
    /// offset in time), shaft speed k r/(2J)(t − t_k)² quantised to 0.5 rpm: the estimate is the
    /// kiss point within a micrometre.
    #[test]
    fn the_onset_fit_removes_the_detection_lag() {
        let k = KissRoutineCfg::default();
        let (xk, tk, r, a) = (4.0, 10.0, k.ramp_rate_mm_per_s, 2200.0);
        let mut samples = Vec::new();
        let mut t = 0.0;
        loop {
            let x = xk + r * (t - tk);
            let dw = if t > tk { a * (t - tk) * (t - tk) } else { 0.0 };
            let dw = (dw / 0.5).round() * 0.5;
            samples.push(Sample { t, x, dw_rpm: dw });
            if dw >= k.detect_rpm {
                break;
            }
            t += 0.01;
        }
        let est = estimate(&k, &samples, 0.0).unwrap();
        let naive = samples.last().unwrap().x;
        assert!((est - xk).abs() < 1e-3, "estimate {est}");
        assert!(naive - xk > 0.01, "the detection alone lags: {naive}");
    }
}

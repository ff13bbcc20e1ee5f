//! The TCU's input side: every received frame of ENG_Status, DRV_Pedal, DCT_Sensors and
//! DCT_Actuators goes through, in order,
//! 1. E2E (`can::e2e::E2eChecker`): CRC-8/SAE-J1850 and alive counter — a bad CRC or a wrong DLC,
//!    a repeated counter (frozen sender) or a jump of more than `max_counter_skip` lost frames
//!    rejects the frame;
//! 2. decoding with the generated message types (values outside the DBC's value tables or ranges
//!    reject the frame);
//! 3. plausibility: engine speed above its limit or changing faster than physically possible,
//!    output-shaft speed jumps, input-shaft speed inconsistent with the engaged gear, housing
//!    temperature out of range, bearing position out of range.
//!
//! Accepted frames update the [`Measurements`]; rejected ones only record why. A message whose
//! last accepted frame is `timeout_cycles` cycles old (counted from the start before its first
//! frame) is *missing*; the [`Health`] then carries a fault code naming the message and the cause
//! (the reason its frames were rejected, or a plain timeout when none arrived). Recovery needs
//! every message fresh again with `recovery_frames` consecutive accepted frames each.
//!
//! Pure: the arrival time of each frame is an argument.

use super::config::InputsCfg;
use super::sender::SenderMonitor;
use crate::can::codec::CodecError;
use crate::can::e2e::{E2eChecker, E2eConfig, E2eError};
use crate::can::messages::{
    ids, message_def, DctActuators, DctSensors, DrvPedal, EngStatus, FaultCode, GearLever,
};
use crate::can::CanFrame;
use crate::model::driveline;
use crate::model::engine::RPM;
use crate::model::gear::Gear;
use crate::model::params::DrivelineParams;
use std::time::Duration;

/// A received frame and its arrival time on the TCU's time base.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimedFrame {
    pub at: Duration,
    pub frame: CanFrame,
}

/// The monitored input messages, in the priority order of their fault codes.
pub(crate) const INPUTS: [Input; 4] = [
    Input::EngStatus,
    Input::Sensors,
    Input::Actuators,
    Input::Pedal,
];

/// One input message of the TCU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
pub enum Input {
    EngStatus,
    Pedal,
    Sensors,
    Actuators,
}

impl Input {
    pub fn id(self) -> u16 {
        match self {
            Input::EngStatus => ids::ENG_STATUS,
            Input::Pedal => ids::DRV_PEDAL,
            Input::Sensors => ids::DCT_SENSORS,
            Input::Actuators => ids::DCT_ACTUATORS,
        }
    }
    fn index(self) -> usize {
        match self {
            Input::EngStatus => 0,
            Input::Pedal => 1,
            Input::Sensors => 2,
            Input::Actuators => 3,
        }
    }
    fn from_id(id: u32) -> Option<Input> {
        INPUTS.into_iter().find(|i| u32::from(i.id()) == id)
    }
    /// Fault codes (timeout, CRC, counter) of this message.
    pub fn codes(self) -> (FaultCode, FaultCode, FaultCode) {
        match self {
            Input::EngStatus => (
                FaultCode::EngStatusTimeout,
                FaultCode::EngStatusCrc,
                FaultCode::EngStatusCounter,
            ),
            Input::Pedal => (
                FaultCode::PedalTimeout,
                FaultCode::PedalCrc,
                FaultCode::PedalCounter,
            ),
            Input::Sensors => (
                FaultCode::SensorsTimeout,
                FaultCode::SensorsCrc,
                FaultCode::SensorsCounter,
            ),
            Input::Actuators => (
                FaultCode::ActuatorsTimeout,
                FaultCode::ActuatorsCrc,
                FaultCode::ActuatorsCounter,
            ),
        }
    }
    fn cycle(self) -> Duration {
        Duration::from_millis(u64::from(
            message_def(u32::from(self.id())).map_or(10, |m| m.cycle_ms),
        ))
    }
}

/// The latest accepted measurements (SI units: rad/s, N·m, °C, mm; pedal 0..1).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Measurements {
    /// Engine = flywheel speed ω_e (rad/s).
    pub w_e: f64,
    /// Actual engine torque (N·m).
    pub t_e: f64,
    /// Accelerator pedal, fraction 0..1.
    pub pedal: f64,
    pub brake: bool,
    pub lever: GearLever,
    /// Input-shaft speeds ω_c1, ω_c2 (rad/s).
    pub w_c: [f64; 2],
    /// Output-shaft speed ω_out (rad/s).
    pub w_out: f64,
    /// Housing air temperature θ_h (°C).
    pub theta_h: f64,
    /// Measured bearing positions (mm).
    pub x_mm: [f64; 2],
    /// Engaged gear per shaft (odd, even).
    pub gear: [Gear; 2],
}

impl Default for Measurements {
    fn default() -> Self {
        Measurements {
            w_e: 0.0,
            t_e: 0.0,
            pedal: 0.0,
            brake: true,
            lever: GearLever::P,
            w_c: [0.0; 2],
            w_out: 0.0,
            theta_h: f64::NAN,
            x_mm: [0.0; 2],
            gear: [Gear::N; 2],
        }
    }
}

impl Measurements {
    /// Slip ω_e − ω_ci of clutch `i` (rad/s).
    pub fn slip(&self, i: usize) -> f64 {
        self.w_e - self.w_c[i]
    }
}

/// What happened to one frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    Accepted,
    Rejected(FaultCode),
    /// Not an input of the TCU.
    Ignored,
}

#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Channel {
    last_valid: Option<Duration>,
    /// Why the frames since the last accepted one were rejected (most recent reason).
    cause: Option<FaultCode>,
    consecutive_valid: u32,
    accepted: u64,
    rejected: u64,
}

/// Input health at a time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Health {
    /// Every input is fresh (none missing).
    pub all_fresh: bool,
    /// The fault of the highest-priority missing input.
    pub fault: Option<FaultCode>,
    /// The missing input and the time of its last accepted frame.
    pub missing: Option<(Input, Option<Duration>)>,
    /// Every input has at least `recovery_frames` consecutive accepted frames and is fresh.
    pub recovered: bool,
}

impl Health {
    /// This health with an internal fault: not fresh, not recovered, the input's code first.
    pub fn with_internal_fault(self, code: FaultCode) -> Health {
        Health {
            all_fresh: false,
            fault: self.fault.or(Some(code)),
            recovered: false,
            ..self
        }
    }
}

/// Per-message counters for diagnostics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct InputCounters {
    pub accepted: [u64; 4],
    pub rejected: [u64; 4],
}

/// E2E, decoding and plausibility of the TCU's inputs.
#[derive(Debug, Clone)]
pub struct InputMonitor {
    cfg: InputsCfg,
    driveline: DrivelineParams,
    checker: E2eChecker,
    ch: [Channel; 4],
    start: Duration,
    meas: Measurements,
    seen: [bool; 4],
    /// CRC-valid frames per input, for a second sender on its id.
    senders: [SenderMonitor; 4],
    /// A lever move into D or R refused at speed (the previous lever stays in force).
    lever_refused: bool,
}

impl InputMonitor {
    pub fn new(cfg: InputsCfg, driveline: DrivelineParams, start: Duration) -> Self {
        let ids = INPUTS.map(Input::id);
        Self {
            cfg,
            driveline,
            checker: E2eChecker::for_ids(
                E2eConfig {
                    timeout_cycles: cfg.timeout_cycles,
                },
                start,
                ids,
            ),
            ch: [Channel::default(); 4],
            start,
            meas: Measurements::default(),
            seen: [false; 4],
            senders: Default::default(),
            lever_refused: false,
        }
    }

    /// A lever move into D or R is being refused (the vehicle is moving).
    pub fn lever_refused(&self) -> bool {
        self.lever_refused
    }

    /// Whether an input's id is flooded with frames that fail the CRC at `now`.
    pub fn flooded(&self, input: Input, now: Duration) -> bool {
        self.senders[input.index()].flooded(now, input.cycle())
    }

    /// Whether a second sender is evident on an input's id at `now`.
    pub fn second_sender(&self, input: Input, now: Duration) -> bool {
        self.senders[input.index()].evident(now, input.cycle())
    }

    pub fn measurements(&self) -> &Measurements {
        &self.meas
    }

    /// Whether every input has been accepted at least once.
    pub fn all_seen(&self) -> bool {
        self.seen.iter().all(|&s| s)
    }

    pub fn counters(&self) -> InputCounters {
        InputCounters {
            accepted: self.ch.map(|c| c.accepted),
            rejected: self.ch.map(|c| c.rejected),
        }
    }

    /// Time of the last accepted frame of an input.
    pub fn last_valid(&self, input: Input) -> Option<Duration> {
        self.ch[input.index()].last_valid
    }

    /// Checks one frame and, when it passes, takes its values.
    pub fn accept(&mut self, f: &TimedFrame) -> Verdict {
        let Some(input) = Input::from_id(f.frame.raw_id()) else {
            return Verdict::Ignored;
        };
        if f.frame.standard_id().is_none() {
            return Verdict::Ignored;
        }
        let verdict = self.check(input, f);
        let limit = input.cycle() * self.cfg.timeout_cycles;
        let c = &mut self.ch[input.index()];
        match verdict {
            Ok(()) => {
                // A frame after a timeout starts a new run of valid frames.
                let after_gap = c.last_valid.is_none_or(|t| f.at.saturating_sub(t) >= limit);
                c.consecutive_valid = if after_gap {
                    1
                } else {
                    c.consecutive_valid.saturating_add(1)
                };
                c.last_valid = Some(f.at);
                c.cause = None;
                c.accepted += 1;
                self.seen[input.index()] = true;
                Verdict::Accepted
            }
            Err(code) => {
                c.cause = Some(code);
                c.consecutive_valid = 0;
                c.rejected += 1;
                Verdict::Rejected(code)
            }
        }
    }

    /// One received frame checked and, when valid, applied to the measurements: its E2E
    /// protection, then its decoded values' plausibility.
    fn check(&mut self, input: Input, f: &TimedFrame) -> Result<(), FaultCode> {
        self.check_e2e(input, f)?;
        // Time since the previous accepted frame, at least one cycle: a frame carries at least a
        // cycle of physics even when a sender's scheduling delay delivers several at once.
        let prev_at = self.ch[input.index()].last_valid;
        let dt = prev_at.map(|p| f.at.saturating_sub(p).max(input.cycle()).as_secs_f64());
        let data = f.frame.bytes();
        match input {
            Input::EngStatus => self.apply_engine(data, dt),
            Input::Pedal => self.apply_pedal(data),
            Input::Sensors => self.apply_sensors(data, dt),
            Input::Actuators => self.apply_actuators(data),
        }
    }

    /// The frame's E2E protection (CRC, alive counter), counted in its sender's record; a counter
    /// skip of at most `max_counter_skip` passes.
    fn check_e2e(&mut self, input: Input, f: &TimedFrame) -> Result<(), FaultCode> {
        let (_, crc_code, counter_code) = input.codes();
        let e2e = self.checker.check(f.at, f.frame.raw_id(), f.frame.bytes());
        if matches!(e2e, Err(E2eError::BadCrc { .. })) {
            self.senders[input.index()].bad_crc(f.at, input.cycle());
        } else {
            let counter_error = matches!(
                e2e,
                Err(E2eError::CounterSkipped { .. } | E2eError::CounterRepeated { .. })
            );
            self.senders[input.index()].frame(f.at, counter_error, input.cycle());
        }
        match e2e {
            Ok(()) => Ok(()),
            Err(E2eError::CounterSkipped { skipped, .. })
                if skipped <= self.cfg.max_counter_skip =>
            {
                Ok(())
            }
            Err(E2eError::CounterSkipped { .. }) | Err(E2eError::CounterRepeated { .. }) => {
                Err(counter_code)
            }
            Err(_) => Err(crc_code),
        }
    }

    /// ENG_Status: the engine speed within `max_engine_rpm` and, `dt` after the previous frame,
    /// within `max_engine_rate_rpm_per_s` of it (plus 1 rpm).
    fn apply_engine(&mut self, data: &[u8], dt: Option<f64>) -> Result<(), FaultCode> {
        let cfg = self.cfg;
        let m = EngStatus::decode(data).map_err(|e| decode_code(&e, Input::EngStatus))?;
        let w = m.eng_speed * RPM;
        if m.eng_speed > cfg.max_engine_rpm || !w.is_finite() {
            return Err(FaultCode::ImplausibleSpeed);
        }
        if let Some(dt) = dt {
            let bound = (cfg.max_engine_rate_rpm_per_s * dt + 1.0) * RPM;
            if (w - self.meas.w_e).abs() > bound {
                return Err(FaultCode::ImplausibleSpeed);
            }
        }
        self.meas.w_e = w;
        self.meas.t_e = m.eng_torque_act;
        Ok(())
    }

    /// DRV_Pedal: pedal and brake; into D or R only below walking pace: a moving vehicle keeps
    /// its lever (a spoofed or mistaken R at speed is refused and reported, not obeyed).
    fn apply_pedal(&mut self, data: &[u8]) -> Result<(), FaultCode> {
        let m = DrvPedal::decode(data).map_err(|e| decode_code(&e, Input::Pedal))?;
        self.meas.pedal = (m.accel_pedal / 100.0).clamp(0.0, 1.0);
        self.meas.brake = m.brake_switch;
        let engages =
            matches!(m.gear_lever, GearLever::D | GearLever::R) && m.gear_lever != self.meas.lever;
        let moving = self.seen[Input::Sensors.index()]
            && self.meas.w_out.abs() > self.cfg.max_lever_engage_out_rpm * RPM;
        self.lever_refused = engages && moving;
        if !self.lever_refused {
            self.meas.lever = m.gear_lever;
        }
        Ok(())
    }

    /// DCT_Sensors: the housing temperature in its range, the shaft speeds plausible (input
    /// shafts within 1.5 × `max_engine_rpm`, the output's rate within `max_out_rate_rpm_per_s`,
    /// an input shaft with its gear engaged turning with the output).
    fn apply_sensors(&mut self, data: &[u8], dt: Option<f64>) -> Result<(), FaultCode> {
        let cfg = self.cfg;
        let m = DctSensors::decode(data).map_err(|e| decode_code(&e, Input::Sensors))?;
        if !(cfg.housing_temp_min_c..=cfg.housing_temp_max_c).contains(&m.housing_temp) {
            return Err(FaultCode::ImplausibleTemp);
        }
        let w_c = [m.in_shaft1_speed * RPM, m.in_shaft2_speed * RPM];
        let w_out = m.out_shaft_speed * RPM;
        if w_c.iter().any(|w| w.abs() > cfg.max_engine_rpm * RPM * 1.5) {
            return Err(FaultCode::ImplausibleSpeed);
        }
        if let Some(dt) = dt {
            let bound = (cfg.max_out_rate_rpm_per_s * dt + 1.0) * RPM;
            if (w_out - self.meas.w_out).abs() > bound {
                return Err(FaultCode::ImplausibleSpeed);
            }
        }
        // A gross mismatch (the gear state comes from DCT_Actuators, possibly a cycle older) is
        // not a transmission.
        for (shaft, &g) in self.meas.gear.iter().enumerate() {
            if let Some(k) = driveline::overall_ratio(&self.driveline, g) {
                if (w_c[shaft] - k * w_out).abs() > cfg.max_shaft_mismatch_radps {
                    return Err(FaultCode::ImplausibleSpeed);
                }
            }
        }
        self.meas.w_c = w_c;
        self.meas.w_out = w_out;
        self.meas.theta_h = m.housing_temp;
        Ok(())
    }

    /// DCT_Actuators: clutch positions within `max_position_mm`, and the engaged gears.
    fn apply_actuators(&mut self, data: &[u8]) -> Result<(), FaultCode> {
        let m = DctActuators::decode(data).map_err(|e| decode_code(&e, Input::Actuators))?;
        let cfg = self.cfg;
        if m.clutch1_pos > cfg.max_position_mm || m.clutch2_pos > cfg.max_position_mm {
            return Err(FaultCode::ImplausiblePosition);
        }
        self.meas.x_mm = [m.clutch1_pos, m.clutch2_pos];
        self.meas.gear = [m.gear_odd_act.into(), m.gear_even_act.into()];
        Ok(())
    }

    /// Input health at `now`.
    pub fn health(&self, now: Duration) -> Health {
        let mut missing = None;
        let mut all_fresh = true;
        let mut recovered = true;
        let mut spoofed = None;
        let mut flood = None;
        for input in INPUTS {
            let c = &self.ch[input.index()];
            let reference = c.last_valid.unwrap_or(self.start);
            let limit = input.cycle() * self.cfg.timeout_cycles;
            let window = self.senders[input.index()].window(now, input.cycle());
            // A second sender makes the input's values untrustworthy: as good as missing.
            let second = window.evident();
            if second && spoofed.is_none() {
                spoofed = Some(input);
            }
            // So does a flood of corrupted frames beside the real sender's valid ones.
            let flooded = window.flooded();
            if flooded && !second && spoofed.is_none() && flood.is_none() {
                flood = Some(input);
            }
            let stale = now.saturating_sub(reference) >= limit || second || flooded;
            if stale {
                all_fresh = false;
                if missing.is_none() {
                    missing = Some((input, c.last_valid));
                }
            }
            if stale || c.consecutive_valid < self.cfg.recovery_frames {
                recovered = false;
            }
        }
        let fault = missing.map(|(input, _)| {
            let c = &self.ch[input.index()];
            if spoofed == Some(input) {
                FaultCode::SecondSender
            } else if flood == Some(input) {
                input.codes().1
            } else {
                c.cause.unwrap_or(input.codes().0)
            }
        });
        Health {
            all_fresh,
            fault,
            missing,
            recovered,
        }
    }
}

fn decode_code(e: &CodecError, input: Input) -> FaultCode {
    match (e, input) {
        (CodecError::WrongDlc { .. }, _) => input.codes().1,
        (CodecError::UnknownValue { .. }, Input::Actuators) => FaultCode::ImplausibleGear,
        (_, Input::Sensors) | (_, Input::EngStatus) => FaultCode::ImplausibleSpeed,
        // An out-of-range pedal or an unknown lever position: an implausible driver input.
        (_, Input::Pedal) | (_, Input::Actuators) => FaultCode::ImplausiblePosition,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::e2e::E2eSender;
    use crate::tcu::config::TcuConfig;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    fn eng(tx: &mut E2eSender, rpm: f64) -> CanFrame {
        let mut d = EngStatus {
            eng_speed: rpm,
            eng_torque_act: 10.0,
            ..Default::default()
        }
        .encode()
        .unwrap();
        tx.protect(ids::ENG_STATUS, &mut d);
        CanFrame::standard(ids::ENG_STATUS, &d).unwrap()
    }

    fn monitor() -> InputMonitor {
        let c = TcuConfig::default();
        InputMonitor::new(c.inputs, c.physics.driveline, ms(0))
    }

    #[test]
    fn crc_counter_and_jumps_are_rejected_with_their_codes() {
        let mut m = monitor();
        let mut tx = E2eSender::new();
        let f = eng(&mut tx, 800.0);
        assert_eq!(
            m.accept(&TimedFrame {
                at: ms(10),
                frame: f
            }),
            Verdict::Accepted
        );
        // Same frame again: counter repeated.
        assert_eq!(
            m.accept(&TimedFrame {
                at: ms(20),
                frame: f
            }),
            Verdict::Rejected(FaultCode::EngStatusCounter)
        );
        let mut bad = eng(&mut tx, 800.0);
        let mut bytes = [0u8; 8];
        bytes.copy_from_slice(bad.bytes());
        bytes[7] ^= 0x55;
        bad = CanFrame::standard(ids::ENG_STATUS, &bytes).unwrap();
        assert_eq!(
            m.accept(&TimedFrame {
                at: ms(30),
                frame: bad
            }),
            Verdict::Rejected(FaultCode::EngStatusCrc)
        );
        // One lost frame (the corrupted one): accepted.
        let f = eng(&mut tx, 810.0);
        assert_eq!(
            m.accept(&TimedFrame {
                at: ms(40),
                frame: f
            }),
            Verdict::Accepted
        );
        // 2000 rpm in 10 ms is not an engine.
        let f = eng(&mut tx, 2800.0);
        assert_eq!(
            m.accept(&TimedFrame {
                at: ms(50),
                frame: f
            }),
            Verdict::Rejected(FaultCode::ImplausibleSpeed)
        );
        assert!((m.measurements().w_e - 810.0 * RPM).abs() < 1e-9);
    }

    #[test]
    fn timeout_after_three_cycles_names_the_cause() {
        let mut m = monitor();
        let mut tx = E2eSender::new();
        let f = eng(&mut tx, 800.0);
        m.accept(&TimedFrame {
            at: ms(100),
            frame: f,
        });
        // Frozen counter afterwards.
        for k in 1..5 {
            m.accept(&TimedFrame {
                at: ms(100 + 10 * k),
                frame: f,
            });
        }
        let h = m.health(ms(129));
        assert_ne!(h.missing.map(|x| x.0), Some(Input::EngStatus));
        let h = m.health(ms(130));
        // Other inputs never arrived: they are missing too, but ENG_Status has priority.
        assert_eq!(h.missing.map(|x| x.0), Some(Input::EngStatus));
        assert_eq!(h.fault, Some(FaultCode::EngStatusCounter));
        assert!(!h.all_fresh && !h.recovered);
    }

    fn frame(tx: &mut E2eSender, id: u16, mut d: [u8; 8]) -> CanFrame {
        tx.protect(id, &mut d);
        CanFrame::standard(id, &d).unwrap()
    }

    fn pedal(tx: &mut E2eSender, lever: GearLever) -> CanFrame {
        let d = DrvPedal {
            accel_pedal: 100.0,
            gear_lever: lever,
            ..Default::default()
        }
        .encode()
        .unwrap();
        frame(tx, ids::DRV_PEDAL, d)
    }

    fn sensors(tx: &mut E2eSender, out_rpm: f64) -> CanFrame {
        let d = DctSensors {
            out_shaft_speed: out_rpm,
            housing_temp: 40.0,
            ..Default::default()
        }
        .encode()
        .unwrap();
        frame(tx, ids::DCT_SENSORS, d)
    }

    fn actuators(tx: &mut E2eSender) -> CanFrame {
        let d = DctActuators::default().encode().unwrap();
        frame(tx, ids::DCT_ACTUATORS, d)
    }

    fn at(m: &mut InputMonitor, t: u64, f: CanFrame) -> Verdict {
        m.accept(&TimedFrame {
            at: ms(t),
            frame: f,
        })
    }

    /// Moving at 600 rpm of output shaft (about 20 km/h): a lever move N → R is refused (the
    /// frame itself is accepted, the lever stays N); below walking pace it is obeyed.
    #[test]
    fn a_lever_move_into_r_at_speed_is_refused() {
        let mut m = monitor();
        let (mut ts, mut tp) = (E2eSender::new(), E2eSender::new());
        assert_eq!(at(&mut m, 10, sensors(&mut ts, 600.0)), Verdict::Accepted);
        assert_eq!(
            at(&mut m, 10, pedal(&mut tp, GearLever::N)),
            Verdict::Accepted
        );
        assert_eq!(
            at(&mut m, 20, pedal(&mut tp, GearLever::R)),
            Verdict::Accepted
        );
        assert_eq!(m.measurements().lever, GearLever::N);
        assert!(m.lever_refused());
        // Back to N: nothing refused any more.
        at(&mut m, 30, pedal(&mut tp, GearLever::N));
        assert!(!m.lever_refused());
        // Slowing down to 100 rpm (2 500 rpm/s), then R again: obeyed.
        let mut rpm = 600.0;
        let mut t = 20;
        while rpm > 100.0 {
            rpm -= 25.0;
            t += 10;
            assert_eq!(
                at(&mut m, t, sensors(&mut ts, rpm)),
                Verdict::Accepted,
                "{rpm}"
            );
        }
        at(&mut m, t + 5, pedal(&mut tp, GearLever::R));
        assert_eq!(m.measurements().lever, GearLever::R);
        assert!(!m.lever_refused());
    }

    /// A second node sending DRV_Pedal with valid CRCs and its own counter, 3 ms after the real
    /// driver: the input is taken as missing with FaultCode SecondSender within a window of ten
    /// cycles, and is healthy again a window after the second node stops.
    #[test]
    fn a_second_pedal_sender_is_named() {
        let mut m = monitor();
        let (mut te, mut ts, mut ta, mut tp, mut spoof) = (
            E2eSender::new(),
            E2eSender::new(),
            E2eSender::new(),
            E2eSender::new(),
            E2eSender::new(),
        );
        // The spoofer's counter runs 8 ahead of the driver's.
        for _ in 0..8 {
            pedal(&mut spoof, GearLever::R);
        }
        let mut first = None;
        for k in 1..=60u64 {
            let t = 10 * k;
            at(&mut m, t, eng(&mut te, 800.0));
            at(&mut m, t, sensors(&mut ts, 0.0));
            at(&mut m, t, actuators(&mut ta));
            at(&mut m, t, pedal(&mut tp, GearLever::N));
            if k <= 30 {
                at(&mut m, t + 3, pedal(&mut spoof, GearLever::R));
            }
            let h = m.health(ms(t + 4));
            if k < 30 && h.fault == Some(FaultCode::SecondSender) && first.is_none() {
                first = Some(t + 3);
                assert_eq!(h.missing.map(|x| x.0), Some(Input::Pedal));
                assert!(!h.all_fresh);
            }
            if k == 50 {
                assert_eq!(h.fault, None, "the second sender stopped at 303 ms");
                assert!(h.all_fresh);
            }
        }
        assert!(first.is_some_and(|t| t <= 100), "found at {first:?}");
    }

    /// Issue 12: a flood of bad-CRC DCT_Sensors frames (4 per ms) beside the real plant's valid
    /// ones. The valid frames keep the input fresh, so before the flood check the TCU drove on
    /// under it; now the input is missing with SensorsCrc within the first cycle of the flood,
    /// and healthy again (with its recovery frames) a window after the flood ends.
    #[test]
    fn a_bad_crc_flood_beside_the_real_sender_is_a_crc_fault() {
        let mut m = monitor();
        let (mut te, mut ts, mut ta, mut tp) = (
            E2eSender::new(),
            E2eSender::new(),
            E2eSender::new(),
            E2eSender::new(),
        );
        let mut flood = sensors(&mut E2eSender::new(), 0.0).bytes().to_vec();
        flood[7] ^= 0xFF;
        let flood = CanFrame::standard(ids::DCT_SENSORS, &flood).unwrap();
        let (mut detected, mut healthy_after) = (None, None);
        for t in 1..=600u64 {
            if t % 10 == 0 {
                at(&mut m, t, eng(&mut te, 800.0));
                assert_eq!(at(&mut m, t, sensors(&mut ts, 0.0)), Verdict::Accepted);
                at(&mut m, t, actuators(&mut ta));
                at(&mut m, t, pedal(&mut tp, GearLever::N));
            }
            if (200..400).contains(&t) {
                for _ in 0..4 {
                    assert_eq!(
                        at(&mut m, t, flood),
                        Verdict::Rejected(FaultCode::SensorsCrc)
                    );
                }
            }
            let h = m.health(ms(t));
            if t < 200 {
                assert!(h.all_fresh && h.fault.is_none(), "before the flood, {t} ms");
            } else if t < 400 {
                if h.fault.is_some() && detected.is_none() {
                    detected = Some(t);
                }
                if detected.is_some() {
                    assert_eq!(h.fault, Some(FaultCode::SensorsCrc), "{t} ms");
                    assert!(!h.all_fresh && !h.recovered);
                }
            } else if h.recovered && healthy_after.is_none() {
                healthy_after = Some(t);
            }
        }
        assert!(
            detected.is_some_and(|t| t <= 210),
            "detected at {detected:?}"
        );
        assert!(
            healthy_after.is_some_and(|t| t <= 400 + 100 + 20),
            "healthy again at {healthy_after:?}"
        );
    }
}

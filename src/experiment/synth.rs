//! Synthetic rig data for tests and for identification checks with known parameters: the
//! paper's Sect. 3.3 experiment — input side held at a dyno speed, clutch outputs braked
//! (ω_c = 0, so the slip is the dyno speed), periodic x_to requests driving
//! partial engagements while the clutches heat up, then a cooling phase with both clutches open —
//! sampled every 10 ms into the contract's frames (so quantisation and the decode path are those
//! of a real log) with configurable sensor noise. Reality effects enter through [`Hooks`].
//!
//! With both speeds imposed the driveline (18) drops out; what remains of the powertrain is the
//! actuator lag, the clutch torque (13) through the hooks and the 5-state thermal model (16),
//! integrated here by RK4 as [`RigModel`] (the plant's rig mode does the same with its own
//! sensors; this generator exists so the diagnosis can be tested without the plant).
//!
//! Pure: the clock is the simulation's own time, the noise comes from a seeded generator.

use crate::can::candump::LogRecord;
use crate::can::codec::MessageDef;
use crate::can::e2e::E2eSender;
use crate::can::messages::{
    BenchTemps, BenchTorque, DctActuators, DctSensors, EngStatus, SimTruth, TcuClutchCmd,
};
use crate::can::CanFrame;
use crate::gap::fit::stats::Rng;
use crate::model::actuator;
use crate::model::integrator::{rk4_step, OdeState, OdeSystem};
use crate::model::params::Params;
use crate::model::powertrain::{ClutchContext, Hooks};
use crate::model::thermal::{Thermal5, Thermal5State, ThermalInputs};
use crate::records::dataset::{Dataset, DatasetError, DEFAULT_DT_S};
use std::time::Duration;

/// State of the rig: bearing positions, the five temperatures of (16), friction energies.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RigState {
    pub x_mm: [f64; 2],
    pub thermal: Thermal5State,
    pub e_fric_j: [f64; 2],
}

impl OdeState for RigState {
    fn axpy(&self, k: f64, d: &Self) -> Self {
        RigState {
            x_mm: [self.x_mm[0] + k * d.x_mm[0], self.x_mm[1] + k * d.x_mm[1]],
            thermal: self.thermal.axpy(k, &d.thermal),
            e_fric_j: [
                self.e_fric_j[0] + k * d.e_fric_j[0],
                self.e_fric_j[1] + k * d.e_fric_j[1],
            ],
        }
    }
}

/// Inputs of the rig held over a step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RigInput {
    pub x_ref_mm: [f64; 2],
    /// Dyno speed = slip of both clutches (rad/s).
    pub slip_radps: f64,
    pub theta_h_c: f64,
}

/// Rig dynamics: actuators, clutch torques through the hooks, thermal model (16).
#[derive(Debug, Clone)]
pub struct RigModel<H: Hooks> {
    pub p: Params,
    pub hooks: H,
    thermal: Thermal5,
}

impl<H: Hooks> RigModel<H> {
    pub fn new(p: Params, hooks: H) -> Self {
        RigModel {
            p,
            hooks,
            thermal: Thermal5::new(p.thermal5),
        }
    }

    fn context(&self, s: &RigState, u: &RigInput, i: usize) -> ClutchContext {
        let th = &s.thermal;
        ClutchContext {
            clutch: i,
            x_to_mm: s.x_mm[i],
            slip_radps: u.slip_radps,
            theta_c: if i == 0 { th.c1 } else { th.c2 },
            theta_pp: if i == 0 { th.pp1 } else { th.pp2 },
            theta_cd: th.cd,
            e_fric_j: s.e_fric_j[i],
        }
    }

    /// Clutch torques (N·m) at a state.
    pub fn torques(&self, s: &RigState, u: &RigInput) -> [f64; 2] {
        [0, 1].map(|i| {
            self.hooks
                .clutch_torque(&self.p.clutch, &self.context(s, u, i))
        })
    }

    /// Derivative of the rig state.
    pub fn eval(&self, s: &RigState, u: &RigInput) -> RigState {
        let ctx = [self.context(s, u, 0), self.context(s, u, 1)];
        let tq = ctx.map(|c| self.hooks.clutch_torque(&self.p.clutch, &c));
        let beta = ctx.map(|c| self.hooks.clutch_beta(&self.p.clutch, &c));
        let pw = [tq[0] * u.slip_radps, tq[1] * u.slip_radps];
        let tin = ThermalInputs {
            p_fric1_w: pw[0],
            p_fric2_w: pw[1],
            beta1: beta[0],
            beta2: beta[1],
            theta_h_c: u.theta_h_c,
            w_f_radps: u.slip_radps,
        };
        let dth = self
            .thermal
            .derivative(&s.thermal, &tin)
            .axpy(1.0, &self.hooks.extra_heat(&s.thermal, &tin));
        RigState {
            x_mm: [0, 1].map(|i| actuator::derivative(&self.p.actuator, s.x_mm[i], u.x_ref_mm[i])),
            thermal: dth,
            e_fric_j: pw,
        }
    }
}

impl<H: Hooks> OdeSystem for RigModel<H> {
    type State = RigState;
    type Input = RigInput;
    fn derivative(&self, x: &RigState, u: &RigInput) -> RigState {
        self.eval(x, u)
    }
}

/// A rig experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct RigExperiment {
    /// x_to request over one period: (time in the period (s), x_to (mm)), linear in between,
    /// held at the last value until the period ends.
    pub profile: Vec<(f64, f64)>,
    /// Period of the engagements (s).
    pub period_s: f64,
    /// Number of engagements.
    pub engagements: usize,
    /// Clutches engaged in turn (engagement k uses `clutches[k % len]`).
    pub clutches: Vec<usize>,
    /// Dyno speeds cycled over the engagements (rpm).
    pub dyno_rpm: Vec<f64>,
    /// Cooling phase after the engagements, both clutches open (s).
    pub cooling_s: f64,
    /// Open time before the first engagement (s).
    pub lead_s: f64,
    /// Housing air temperature (°C).
    pub theta_h_c: f64,
    /// Initial temperature of every thermal mass (°C).
    pub theta0_c: f64,
    /// Request while open (mm).
    pub x_open_mm: f64,
}

impl RigExperiment {
    /// An identification-like experiment: a ramp to 6.6 mm, hold, release, alternating clutches.
    pub fn identification(engagements: usize, cooling_s: f64) -> Self {
        RigExperiment {
            profile: vec![(0.0, 3.0), (1.2, 6.6), (2.2, 6.6), (2.8, 3.0)],
            period_s: 8.0,
            engagements,
            clutches: vec![0, 1],
            dyno_rpm: vec![1200.0, 30.0, 1800.0, 300.0, 1500.0],
            cooling_s,
            lead_s: 2.0,
            theta_h_c: 25.0,
            theta0_c: 25.0,
            x_open_mm: 3.0,
        }
    }

    /// A validation-like experiment with another profile: two-step ramp to 7.4 mm (past
    /// x_to,max), different dyno speeds.
    pub fn validation(engagements: usize, cooling_s: f64) -> Self {
        RigExperiment {
            profile: vec![
                (0.0, 3.0),
                (0.6, 5.2),
                (1.4, 5.4),
                (2.2, 7.4),
                (2.7, 7.4),
                (3.3, 3.0),
            ],
            period_s: 9.0,
            engagements,
            clutches: vec![1, 0],
            dyno_rpm: vec![900.0, 2200.0, 120.0],
            cooling_s,
            lead_s: 2.0,
            theta_h_c: 30.0,
            theta0_c: 30.0,
            x_open_mm: 3.0,
        }
    }

    /// Total duration (s).
    pub fn duration(&self) -> f64 {
        self.lead_s + self.engagements as f64 * self.period_s + self.cooling_s
    }

    /// Request of each clutch (mm) and dyno speed (rpm) at time `t`.
    pub fn setpoint(&self, t: f64) -> ([f64; 2], f64) {
        let mut x = [self.x_open_mm; 2];
        let tt = t - self.lead_s;
        let k = if tt >= 0.0 {
            (tt / self.period_s).floor() as usize
        } else {
            0
        };
        let rpm = self.dyno_rpm[k.min(self.engagements.saturating_sub(1)) % self.dyno_rpm.len()];
        if tt >= 0.0 && k < self.engagements {
            let c = self.clutches[k % self.clutches.len()];
            let tau = tt - k as f64 * self.period_s;
            x[c] = profile_at(&self.profile, tau);
        }
        (x, rpm)
    }
}

fn profile_at(p: &[(f64, f64)], t: f64) -> f64 {
    if p.is_empty() {
        return 0.0;
    }
    if t <= p[0].0 {
        return p[0].1;
    }
    for w in p.windows(2) {
        if t <= w[1].0 {
            let f = (t - w[0].0) / (w[1].0 - w[0].0).max(1e-12);
            return w[0].1 + f * (w[1].1 - w[0].1);
        }
    }
    p[p.len() - 1].1
}

/// Sensor noise (1 σ) added before the contract's quantisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorNoise {
    pub torque_nm: f64,
    pub temp_c: f64,
    pub pos_mm: f64,
    pub speed_rpm: f64,
}

impl Default for SensorNoise {
    fn default() -> Self {
        SensorNoise {
            torque_nm: 0.3,
            temp_c: 0.15,
            pos_mm: 0.002,
            speed_rpm: 0.5,
        }
    }
}

/// Errors of the synthetic generator.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SynthError {
    #[error("invalid experiment: {0}")]
    Experiment(String),
    #[error(transparent)]
    Dataset(#[from] DatasetError),
}

fn clamp_to(def: &MessageDef, si: usize, v: f64) -> f64 {
    let s = &def.signals[si];
    v.clamp(s.min, s.max)
}

/// Simulates the rig experiment and returns the frames the plant and the rig script would put on
/// the bus (10 ms cycle), including SIM_Truth (which the diagnosis must ignore).
pub fn rig_frames<H: Hooks>(
    p: &Params,
    hooks: H,
    exp: &RigExperiment,
    noise: SensorNoise,
    seed: u64,
    step_s: f64,
) -> Result<Vec<LogRecord>, SynthError> {
    check_experiment(exp, step_s)?;
    let rig = RigModel::new(*p, hooks);
    let mut rng = Rng::new(seed);
    let mut s = RigState {
        thermal: Thermal5State::uniform(exp.theta0_c),
        ..RigState::default()
    };
    let sample_every = (DEFAULT_DT_S / step_s).round().max(1.0) as usize;
    let steps = (exp.duration() / step_s).round() as usize;
    let mut e2e = E2eSender::new();
    let mut out = Vec::with_capacity(steps / sample_every * 7 + 7);
    let t_base = Duration::from_secs(1_700_000_000);
    let rpm_to = crate::records::dataset::RPM_TO_RADPS;
    for k in 0..=steps {
        let t = k as f64 * step_s;
        let (x, rpm) = exp.setpoint(t);
        let u = RigInput {
            x_ref_mm: x,
            slip_radps: rpm * rpm_to,
            theta_h_c: exp.theta_h_c,
        };
        if k % sample_every == 0 {
            let tq = rig.torques(&s, &u);
            let ts = t_base + Duration::from_micros((t * 1e6).round() as u64);
            for (id, mut data, protect) in sample_messages(&s, &u, tq, rpm, noise, &mut rng) {
                if protect {
                    e2e.protect(id, &mut data);
                }
                if let Ok(f) = CanFrame::standard(id, &data) {
                    out.push(LogRecord {
                        timestamp: ts,
                        iface: "sim".into(),
                        frame: f,
                        direction: None,
                    });
                }
            }
        }
        if k == steps {
            break;
        }
        s = rk4_step(&rig, &s, &u, step_s);
    }
    Ok(out)
}

/// The experiment's checks: a profile, clutches 0 or 1 and dyno speeds given, a positive
/// period and integration step.
fn check_experiment(exp: &RigExperiment, step_s: f64) -> Result<(), SynthError> {
    if exp.profile.is_empty() || exp.clutches.is_empty() || exp.dyno_rpm.is_empty() {
        return Err(SynthError::Experiment(
            "profile, clutches and dyno_rpm must not be empty".into(),
        ));
    }
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if exp.clutches.iter().any(|c| *c > 1) || !positive(exp.period_s) || !positive(step_s) {
        return Err(SynthError::Experiment(
            "clutches are 0 or 1; period and step must be positive".into(),
        ));
    }
    Ok(())
}

/// One sample's messages as (id, payload, whether E2E-protected), those that encode: the rig's
/// state `s`, torques `tq` and dyno speed `rpm` as the sensors read them (noise drawn from
/// `rng` in the messages' order, clamped to the contract's ranges), the requests of `u`, and the
/// true clutch temperatures.
fn sample_messages(
    s: &RigState,
    u: &RigInput,
    tq: [f64; 2],
    rpm: f64,
    noise: SensorNoise,
    rng: &mut Rng,
) -> Vec<(u16, [u8; 8], bool)> {
    let mut msgs = Vec::with_capacity(7);
    let mut message = |id: u16, data: Option<[u8; 8]>, protect: bool| {
        if let Some(data) = data {
            msgs.push((id, data, protect));
        }
    };
    let n = |rng: &mut Rng, s: f64| s * rng.normal();
    let d = EngStatus::def();
    let m = EngStatus {
        eng_speed: clamp_to(d, 0, rpm + n(rng, noise.speed_rpm)),
        eng_torque_act: clamp_to(d, 1, tq[0] + tq[1]),
        ..Default::default()
    };
    message(EngStatus::ID, m.encode().ok(), true);
    let d = DctSensors::def();
    let m = DctSensors {
        in_shaft1_speed: clamp_to(d, 0, n(rng, noise.speed_rpm)),
        in_shaft2_speed: clamp_to(d, 1, n(rng, noise.speed_rpm)),
        out_shaft_speed: 0.0,
        housing_temp: clamp_to(d, 3, u.theta_h_c),
        ..Default::default()
    };
    message(DctSensors::ID, m.encode().ok(), true);
    let d = DctActuators::def();
    let m = DctActuators {
        clutch1_pos: clamp_to(d, 0, s.x_mm[0] + n(rng, noise.pos_mm)),
        clutch2_pos: clamp_to(d, 1, s.x_mm[1] + n(rng, noise.pos_mm)),
        ..Default::default()
    };
    message(DctActuators::ID, m.encode().ok(), true);
    let d = BenchTorque::def();
    let m = BenchTorque {
        clutch1_torque: clamp_to(d, 0, tq[0] + n(rng, noise.torque_nm)),
        clutch2_torque: clamp_to(d, 1, tq[1] + n(rng, noise.torque_nm)),
    };
    message(BenchTorque::ID, m.encode().ok(), false);
    let d = BenchTemps::def();
    let th = s.thermal;
    let m = BenchTemps {
        pressure_plate1_temp: clamp_to(d, 0, th.pp1 + n(rng, noise.temp_c)),
        pressure_plate2_temp: clamp_to(d, 1, th.pp2 + n(rng, noise.temp_c)),
        central_disk_temp: clamp_to(d, 2, th.cd + n(rng, noise.temp_c)),
    };
    message(BenchTemps::ID, m.encode().ok(), false);
    let d = TcuClutchCmd::def();
    let m = TcuClutchCmd {
        clutch1_pos_req: clamp_to(d, 0, u.x_ref_mm[0]),
        clutch2_pos_req: clamp_to(d, 1, u.x_ref_mm[1]),
        ..Default::default()
    };
    message(TcuClutchCmd::ID, m.encode().ok(), true);
    let d = SimTruth::def();
    let m = SimTruth {
        clutch1_temp_true: clamp_to(d, 0, th.c1),
        clutch2_temp_true: clamp_to(d, 1, th.c2),
    };
    message(SimTruth::ID, m.encode().ok(), false);
    msgs
}

/// [`rig_frames`] decoded into a dataset, as a log of the experiment would be.
pub fn rig_dataset<H: Hooks>(
    name: &str,
    p: &Params,
    hooks: H,
    exp: &RigExperiment,
    noise: SensorNoise,
    seed: u64,
    step_s: f64,
) -> Result<Dataset, SynthError> {
    let frames = rig_frames(p, hooks, exp, noise, seed, step_s)?;
    Ok(Dataset::from_records(
        name,
        frames.into_iter().map(Ok),
        DEFAULT_DT_S,
    )?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::powertrain::Nominal;
    use crate::records::dataset::Col;

    #[test]
    fn rig_heats_and_torque_follows_13() {
        let p = Params::default();
        let exp = RigExperiment::identification(6, 20.0);
        let frames = rig_frames(&p, Nominal, &exp, SensorNoise::default(), 1, 0.005).unwrap();
        let truth: Vec<f64> = frames
            .iter()
            .filter(|r| r.frame.raw_id() == u32::from(SimTruth::ID))
            .map(|r| SimTruth::decode(r.frame.bytes()).unwrap().clutch1_temp_true)
            .collect();
        let d = Dataset::from_records("rig", frames.into_iter().map(Ok), DEFAULT_DT_S).unwrap();
        assert!((d.duration() - exp.duration()).abs() < 0.02);
        assert_eq!(d.stats.ignored_truth, d.stats.records / 7);
        assert_eq!(d.stats.dropped_e2e, 0);
        // The central disk heats while engaging.
        let cd = d.req(Col::Cd);
        let k_end = ((exp.lead_s + 6.0 * exp.period_s) / d.dt) as usize;
        assert!(cd[k_end] > cd[0] + 1.0, "{} {}", cd[0], cd[k_end]);
        // First engagement (clutch 1, 1200 rpm): the torque at the hold is (13) at the true clutch
        // temperature, within sensor noise and quantisation.
        let k = ((exp.lead_s + 1.8) / d.dt).round() as usize;
        let x = d.req(Col::X1)[k];
        let w = d.req(Col::Wf)[k] - d.req(Col::Wc1)[k];
        let t13 = crate::model::clutch::torque(&p.clutch, x, w, truth[k]);
        assert!(truth[k] > 26.0, "heated: {}", truth[k]);
        assert!(
            (d.req(Col::T1)[k] - t13).abs() < 1.5,
            "{} vs {t13}",
            d.req(Col::T1)[k]
        );
        assert!(d.get(Col::X1Req).is_some());
    }
}

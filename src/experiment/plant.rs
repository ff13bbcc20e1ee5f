//! Bench experiments run on the plant core in process (no bus, no clock): the rig's partial
//! engagements commanded over TCU_ClutchCmd as `scripts/rig_partial_engagements.py` does (so the
//! log carries the position requests), and open-loop launches in vehicle mode commanded over
//! DRV_Pedal, TCU_GearCmd and TCU_ClutchCmd. The frames the plant sends and the commands are
//! returned as a candump-like record list, decoded later exactly as a recorded log.
//!
//! [`experiment_records`] runs the training and validation experiments of `ddct gap experiment`
//! (rig partial engagements with a cooling phase, a low-slip rig run of a preheated clutch,
//! open-loop launches; the validation experiments use another x_to profile, dyno speed and other
//! launches) with a truth from the effect library in the plant's effect set — records to try
//! `ddct gap diagnose` by hand and to close the loop (`config/gap_closed_loop_<effect>.toml`).
//! The blind test draws its truths from the independent generator (`src/truth/`) instead.

use crate::can::candump::LogRecord;
use crate::can::e2e::E2eSender;
use crate::can::messages::{
    DrvPedal, GearEvenReq, GearLever, GearOddReq, TcuClutchCmd, TcuGearCmd,
};
use crate::can::{CanFrame, Received};
use crate::experiment::synth::RigExperiment;
use crate::model::effects::{EffectId, EffectSet};
use crate::model::gear::Gear;
use crate::model::params::Params;
use crate::plant::core::CYCLE;
use crate::plant::{Mode, Plant, PlantConfig, StepPolicy};
use crate::records::dataset::{Dataset, DEFAULT_DT_S};
use std::time::Duration;

/// Epoch of the records (s): a plausible candump timestamp.
const T_BASE_S: u64 = 1_700_000_000;

/// Errors of an experiment definition.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ExperimentError {
    #[error("invalid experiment: {0}")]
    Invalid(String),
}

fn record(t: Duration, frame: CanFrame) -> LogRecord {
    LogRecord {
        timestamp: Duration::from_secs(T_BASE_S) + t,
        iface: "sim".into(),
        frame,
        direction: None,
    }
}

/// Runs a plant for `duration_s`, calling `commands(t)` at every plant cycle ([`CYCLE`]) for the frames a
/// test script would send at that instant (E2E applied here). Returns every frame on the "bus".
pub fn run_plant(
    cfg: PlantConfig,
    duration_s: f64,
    mut commands: impl FnMut(f64) -> Vec<(u16, [u8; 8])>,
) -> Vec<LogRecord> {
    let mut plant = Plant::new(cfg);
    let mut e2e = E2eSender::new();
    let cycles = (duration_s / CYCLE.as_secs_f64()).round() as u64;
    let mut out = Vec::with_capacity(cycles as usize * 9);
    for k in 0..=cycles {
        let t = CYCLE * u32::try_from(k).unwrap_or(u32::MAX);
        let mut rx = Vec::new();
        for (id, mut data) in commands(t.as_secs_f64()) {
            e2e.protect(id, &mut data);
            if let Ok(frame) = CanFrame::standard(id, &data) {
                out.push(record(t, frame));
                rx.push(Received {
                    frame,
                    timestamp: t,
                });
            }
        }
        let o = plant.step(t, &rx);
        for f in o.frames {
            out.push(record(f.due, f.frame));
        }
    }
    out.sort_by_key(|r| r.timestamp);
    out
}

/// The rig experiment on the plant (rig mode, dyno at the experiment's first speed, positions
/// commanded over TCU_ClutchCmd every 10 ms). `cfg` supplies parameters, effects, noise, seed and
/// initial temperatures; its mode and rig speed are set here.
pub fn rig(mut cfg: PlantConfig, exp: &RigExperiment) -> Result<Vec<LogRecord>, ExperimentError> {
    if exp.dyno_rpm.is_empty() || exp.profile.is_empty() || exp.clutches.is_empty() {
        return Err(ExperimentError::Invalid(
            "rig: profile, clutches and dyno speed must not be empty".into(),
        ));
    }
    if exp.dyno_rpm.iter().any(|r| *r != exp.dyno_rpm[0]) {
        return Err(ExperimentError::Invalid(
            "rig on the plant: one dyno speed per run".into(),
        ));
    }
    cfg.mode = Mode::Rig;
    cfg.rig_profile = None;
    cfg.scenario = None;
    cfg.rig.input_speed_rpm = exp.dyno_rpm[0];
    cfg.initial.temperature_c = exp.theta0_c;
    cfg.initial.housing_c = exp.theta_h_c;
    cfg.housing.target_c = exp.theta_h_c;
    let e = exp.clone();
    Ok(run_plant(cfg, exp.duration(), move |t| {
        let (x, _) = e.setpoint(t);
        let m = TcuClutchCmd {
            clutch1_pos_req: x[0],
            clutch2_pos_req: x[1],
            ..Default::default()
        };
        m.encode()
            .map(|d| vec![(TcuClutchCmd::ID, d)])
            .unwrap_or_default()
    }))
}

/// One open-loop launch of the vehicle from rest in first gear.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Launch {
    /// Accelerator pedal during the launch (%).
    pub pedal_pct: f64,
    /// Clutch 1 position at the start of the ramp (mm) (near the kiss point).
    pub x_start_mm: f64,
    /// Clutch 1 position at the end of the ramp (mm).
    pub x_end_mm: f64,
    /// Ramp duration (s).
    pub ramp_s: f64,
    /// Time driving after the ramp before releasing and braking (s).
    pub hold_s: f64,
}

/// A sequence of launches: each one brakes to rest, selects first gear, launches, holds, then
/// releases the pedal, opens the clutch and brakes to a stop.
#[derive(Debug, Clone, PartialEq)]
pub struct LaunchPlan {
    pub launches: Vec<Launch>,
    /// Standstill time before each launch (s).
    pub rest_s: f64,
    /// Braking time after each launch (s).
    pub stop_s: f64,
    /// Initial temperature of the clutches (°C) (a preheated clutch launches differently).
    pub theta0_c: f64,
}

impl LaunchPlan {
    fn cycle(&self, l: &Launch) -> f64 {
        self.rest_s + l.ramp_s + l.hold_s + self.stop_s
    }

    pub fn duration(&self) -> f64 {
        self.launches.iter().map(|l| self.cycle(l)).sum::<f64>() + 1.0
    }

    /// (pedal %, brake switch, clutch 1 request mm) at time `t`.
    pub fn command(&self, t: f64) -> (f64, bool, f64) {
        let mut t0 = 0.0;
        for l in &self.launches {
            let c = self.cycle(l);
            if t < t0 + c {
                let tau = t - t0;
                if tau < self.rest_s {
                    return (0.0, true, 0.0);
                }
                let tau = tau - self.rest_s;
                if tau < l.ramp_s {
                    let f = tau / l.ramp_s;
                    return (
                        l.pedal_pct,
                        false,
                        l.x_start_mm + f * (l.x_end_mm - l.x_start_mm),
                    );
                }
                let tau = tau - l.ramp_s;
                if tau < l.hold_s {
                    return (l.pedal_pct, false, l.x_end_mm);
                }
                return (0.0, true, 0.0);
            }
            t0 += c;
        }
        (0.0, true, 0.0)
    }
}

/// Open-loop launches on the plant in vehicle mode (the commands a simple test script would send).
pub fn launches(mut cfg: PlantConfig, plan: &LaunchPlan) -> Vec<LogRecord> {
    cfg.mode = Mode::Vehicle;
    cfg.scenario = None;
    cfg.rig_profile = None;
    cfg.initial.temperature_c = plan.theta0_c;
    cfg.initial.gear_odd = Gear::G1;
    cfg.initial.gear_even = Gear::N;
    let plan = plan.clone();
    run_plant(cfg, plan.duration(), move |t| {
        let (pedal, brake, x1) = plan.command(t);
        let mut v = Vec::with_capacity(3);
        if let Ok(d) = (DrvPedal {
            accel_pedal: pedal,
            brake_switch: brake,
            gear_lever: GearLever::D,
            ..Default::default()
        })
        .encode()
        {
            v.push((DrvPedal::ID, d));
        }
        if let Ok(d) = (TcuGearCmd {
            gear_odd_req: GearOddReq::G1,
            gear_even_req: GearEvenReq::N,
            ..Default::default()
        })
        .encode()
        {
            v.push((TcuGearCmd::ID, d));
        }
        if let Ok(d) = (TcuClutchCmd {
            clutch1_pos_req: x1,
            clutch2_pos_req: 0.0,
            ..Default::default()
        })
        .encode()
        {
            v.push((TcuClutchCmd::ID, d));
        }
        v
    })
}

/// A truth of the plant-based experiments: `none`, a library effect or an effect the library
/// lacks (`ddct gap experiment --truth`), carried by the plant's effect set.
/// In JSON: `effect` (`none` or the effect's identifier), `kind` (`none`, `library` or
/// `outside_library`), `subsystem` (`none` or the effect's) and `params`.
#[derive(Debug, Clone, PartialEq)]
pub struct PlantTruth {
    /// The plant's effect, `None` for the nominal plant.
    pub effect: Option<EffectId>,
    /// Its parameters (empty for the nominal plant).
    pub params: Vec<f64>,
}

impl PlantTruth {
    /// The nominal plant.
    pub fn none() -> PlantTruth {
        PlantTruth {
            effect: None,
            params: Vec::new(),
        }
    }

    pub fn set(&self) -> EffectSet {
        match self.effect {
            Some(id) => EffectSet::single(id, &self.params).unwrap_or_default(),
            None => EffectSet::nominal(),
        }
    }

    /// `none`, `library` or `outside_library`.
    pub fn kind(&self) -> &'static str {
        match self.effect {
            None => "none",
            Some(id) if id.in_library() => "library",
            Some(_) => "outside_library",
        }
    }
}

impl serde::Serialize for PlantTruth {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let mut st = s.serialize_struct("PlantTruth", 4)?;
        st.serialize_field("effect", self.effect.map_or("none", EffectId::as_str))?;
        st.serialize_field("kind", self.kind())?;
        st.serialize_field(
            "subsystem",
            self.effect.map_or("none", |e| e.subsystem().as_str()),
        )?;
        st.serialize_field("params", &self.params)?;
        st.end()
    }
}

/// The training and validation experiments, decoded.
#[derive(Debug, Clone, PartialEq)]
pub struct Experiments {
    pub train: Vec<Dataset>,
    pub validate: Vec<Dataset>,
}

/// Training rig: partial engagements of both clutches in turn at 2000 rpm, then cooling.
pub fn train_rig() -> RigExperiment {
    RigExperiment {
        profile: vec![(0.0, 0.0), (0.3, 3.6), (1.3, 5.8), (2.1, 5.8), (2.6, 0.0)],
        period_s: 5.0,
        engagements: 40,
        clutches: vec![0, 1],
        dyno_rpm: vec![2000.0],
        cooling_s: 300.0,
        lead_s: 2.0,
        theta_h_c: 25.0,
        theta0_c: 25.0,
        x_open_mm: 0.0,
    }
}

/// Training low-slip rig: a preheated clutch engaged at 15 rpm (static friction regime).
pub fn train_low_slip() -> RigExperiment {
    RigExperiment {
        profile: vec![(0.0, 0.0), (0.3, 3.4), (1.5, 6.0), (2.5, 6.0), (3.0, 0.0)],
        period_s: 5.0,
        engagements: 16,
        clutches: vec![0, 1],
        dyno_rpm: vec![15.0],
        cooling_s: 20.0,
        lead_s: 2.0,
        theta_h_c: 25.0,
        theta0_c: 200.0,
        x_open_mm: 0.0,
    }
}

/// Validation rig: a staircase profile at 1800 rpm.
pub fn validate_rig() -> RigExperiment {
    RigExperiment {
        profile: vec![
            (0.0, 0.0),
            (0.25, 3.8),
            (0.9, 4.9),
            (1.7, 4.9),
            (2.6, 6.0),
            (3.3, 6.0),
            (3.7, 0.0),
        ],
        period_s: 6.0,
        engagements: 36,
        clutches: vec![1, 0],
        dyno_rpm: vec![1800.0],
        cooling_s: 200.0,
        lead_s: 2.0,
        theta_h_c: 25.0,
        theta0_c: 25.0,
        x_open_mm: 0.0,
    }
}

/// Validation low-slip rig: a preheated clutch at 8 rpm with a two-step profile.
pub fn validate_low_slip() -> RigExperiment {
    RigExperiment {
        profile: vec![
            (0.0, 0.0),
            (0.3, 4.2),
            (1.0, 5.2),
            (1.8, 5.2),
            (2.4, 6.3),
            (3.0, 6.3),
            (3.4, 0.0),
        ],
        period_s: 5.0,
        engagements: 12,
        clutches: vec![1, 0],
        dyno_rpm: vec![8.0],
        cooling_s: 20.0,
        lead_s: 2.0,
        theta_h_c: 25.0,
        theta0_c: 170.0,
        x_open_mm: 0.0,
    }
}

fn launch_plan(pedals: &[f64], x_end: &[f64], ramp: f64, theta0: f64) -> LaunchPlan {
    LaunchPlan {
        launches: pedals
            .iter()
            .zip(x_end)
            .map(|(p, x)| Launch {
                pedal_pct: *p,
                x_start_mm: 3.7,
                x_end_mm: *x,
                ramp_s: ramp,
                hold_s: 3.0,
            })
            .collect(),
        rest_s: 2.0,
        stop_s: 6.0,
        theta0_c: theta0,
    }
}

/// The records of the experiments, named `train_*` and `validate_*`, with the plant
/// carrying `truth` (the frames a candump of the bench would hold, SIM_Truth included).
pub fn experiment_records(
    truth: &PlantTruth,
    seed: u64,
    plant_params: &Params,
) -> Vec<(String, Vec<LogRecord>)> {
    // Reality at the reference step: the records are the fixed 1 ms RK4 integration.
    let c = PlantConfig {
        effects: truth.set(),
        params: *plant_params,
        step: StepPolicy::Fixed,
        ..PlantConfig::default()
    };
    // On the rig the dyno holds the input speed and the brake the output: the sliding
    // acceleration is zero, so `sliding_acceleration_friction` cannot act there. The plant's rig
    // mode feeds the free flywheel acceleration of its integration step into the effect instead
    // (the dyno resets the speed afterwards), which turns it into a ±g torque jitter; the rig
    // runs of this truth therefore leave it out (reported to the plant's owner).
    let mut rig_cfg = c.clone();
    rig_cfg
        .effects
        .remove(EffectId::SlidingAccelerationFriction);
    enum Run {
        Rig(RigExperiment),
        Launches(LaunchPlan),
    }
    let plan = [
        ("train_rig", Run::Rig(train_rig())),
        ("train_low_slip", Run::Rig(train_low_slip())),
        (
            "train_launches",
            Run::Launches(launch_plan(
                &[25.0, 35.0, 45.0, 30.0, 40.0],
                &[5.3, 5.5, 5.8, 5.6, 5.4],
                2.0,
                120.0,
            )),
        ),
        ("validate_rig", Run::Rig(validate_rig())),
        ("validate_low_slip", Run::Rig(validate_low_slip())),
        (
            "validate_launches",
            Run::Launches(launch_plan(
                &[30.0, 50.0, 38.0, 27.0],
                &[5.6, 5.9, 5.5, 5.2],
                1.5,
                150.0,
            )),
        ),
    ];
    plan.into_iter()
        .zip(1u64..)
        .map(|((name, run), k)| {
            // Every record its own sensor-noise seed.
            let noise_seed = seed.wrapping_mul(7).wrapping_add(k);
            let records = match run {
                Run::Rig(exp) => {
                    let cfg = PlantConfig {
                        seed: noise_seed,
                        ..rig_cfg.clone()
                    };
                    rig(cfg, &exp).expect("valid rig")
                }
                Run::Launches(plan) => {
                    let cfg = PlantConfig {
                        seed: noise_seed,
                        ..c.clone()
                    };
                    launches(cfg, &plan)
                }
            };
            (name.to_string(), records)
        })
        .collect()
}

/// Generates the experiments with the plant carrying `truth`, decoded.
pub fn experiments(truth: &PlantTruth, seed: u64, plant_params: &Params) -> Experiments {
    let mut train = Vec::new();
    let mut validate = Vec::new();
    for (name, recs) in experiment_records(truth, seed, plant_params) {
        let d = Dataset::from_records(&name, recs.into_iter().map(Ok), DEFAULT_DT_S)
            .expect("plant records decode");
        if name.starts_with("train") {
            train.push(d);
        } else {
            validate.push(d);
        }
    }
    Experiments { train, validate }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::records::dataset::{Col, Dataset, DEFAULT_DT_S};

    #[test]
    fn rig_on_the_plant_logs_requests_and_heats() {
        let mut exp = RigExperiment::identification(4, 10.0);
        exp.dyno_rpm = vec![1500.0];
        let recs = rig(PlantConfig::default(), &exp).unwrap();
        let d = Dataset::from_records("rig", recs.into_iter().map(Ok), DEFAULT_DT_S).unwrap();
        assert!(d.get(Col::X1Req).is_some());
        assert!(d.stats.ignored_truth > 0);
        assert_eq!(d.stats.dropped_e2e, 0);
        let t1 = d.req(Col::T1).iter().fold(0.0f64, |m, v| m.max(*v));
        let t2 = d.req(Col::T2).iter().fold(0.0f64, |m, v| m.max(*v));
        assert!(t1 > 100.0 && t2 > 100.0, "{t1} {t2}");
        assert!((d.req(Col::Wf)[100] - 1500.0 * crate::records::dataset::RPM_TO_RADPS).abs() < 1.0);
    }

    #[test]
    fn launches_move_the_vehicle_and_lock_the_clutch() {
        let plan = LaunchPlan {
            launches: vec![Launch {
                pedal_pct: 35.0,
                x_start_mm: 3.8,
                x_end_mm: 5.6,
                ramp_s: 2.0,
                hold_s: 3.0,
            }],
            rest_s: 2.0,
            stop_s: 6.0,
            theta0_c: 60.0,
        };
        let recs = launches(PlantConfig::default(), &plan);
        let d = Dataset::from_records("launch", recs.into_iter().map(Ok), DEFAULT_DT_S).unwrap();
        let wout = d.get(Col::Wout).unwrap();
        let vmax = wout.iter().fold(0.0f64, |m, v| m.max(*v));
        assert!(vmax > 5.0, "output speed {vmax}");
        let slip = d.slip(0);
        let k_end = ((plan.rest_s + 4.5) / d.dt) as usize;
        assert!(
            slip[k_end].abs() < 1.0,
            "locked by then: slip {}",
            slip[k_end]
        );
        assert!(d.get(Col::Te).is_some());
    }
}

//! `ddct sim`: the plant and TCU cores in one process, in lockstep and simulated time —
//! deterministic and far faster than real time. They exchange the encoded, E2E-protected frames
//! of the bus contract directly (no bus, no clock): every millisecond the plant integrates and
//! hands over the frames due; the TCU computes on each DCT_Sensors frame (the bench's sync) or,
//! when none came, 10 ms after its previous computation (the daemon's fallback), and its frames
//! reach the plant's next integration step.
//!
//! Every TCU cycle a [`Row`] is recorded from the frames on the "bus" (decoded with the generated
//! types, so exactly what a bench sees: ENG_Status, DCT_Sensors, DCT_Actuators, BENCH_*, SIM_Truth,
//! DRV_Pedal and the TCU's own messages) plus the TCU's internal references ([`crate::tcu::TcuTrace`]).
//! [`metrics`] turns the rows into the acceptance figures; [`plots`] into SVG figures.
//!
//! Frame faults for safety tests ([`Injection`]) act between the plant and the TCU.

pub mod buslog;
pub mod html;
pub mod logplot;
pub mod metrics;
pub mod plots;
pub mod row;
pub mod scenario;
pub mod verdict;

pub use row::Row;
pub use scenario::{ScenarioError, SimScenario, TcuOverrides};

use crate::can::e2e::CRC_BYTE;
use crate::can::messages::{
    ids, BenchTemps, BenchTorque, BenchVehicle, DctActuators, DctSensors, DrvPedal, EngStatus,
    SimTruth, TcuClutchCmd, TcuEngineReq, TcuEstimates, TcuGearCmd, TcuStatus,
};
use crate::can::{CanFrame, Received};
use crate::plant::Plant;
use crate::tcu::{Tcu, TcuConfig, TcuInputs, TimedFrame};
use metrics::Metrics;
use serde::Serialize;
use std::time::Duration;

/// A plant as the simulation drives it: integrate to `now` with the frames received (stamped on
/// the same time base), return the frames it sends with their due times (a due time may lie up to
/// one cycle after `now`; the runner holds them until then).
pub trait PlantNode {
    fn advance(&mut self, now: Duration, rx: &[Received]) -> Vec<(Duration, CanFrame)>;
    /// When the node next needs to run: received frames take effect and frames are produced only
    /// then (the simulation skips the times in between).
    fn poll_timeout(&self) -> Duration;
}

impl PlantNode for Plant {
    fn poll_timeout(&self) -> Duration {
        Plant::poll_timeout(self)
    }

    fn advance(&mut self, now: Duration, rx: &[Received]) -> Vec<(Duration, CanFrame)> {
        self.step(now, rx)
            .frames
            .into_iter()
            .map(|f| (f.due, f.frame))
            .collect()
    }
}

/// A frame fault between the plant and the TCU, active in [from_s, to_s).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Injection {
    pub id: u16,
    pub kind: InjectionKind,
    pub from_s: f64,
    pub to_s: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum InjectionKind {
    /// The message is not delivered.
    Stop,
    /// Delivered with a corrupted CRC byte.
    CorruptCrc,
    /// Delivered with the alive counter frozen at its value when the fault started (CRC valid).
    FreezeCounter,
}

/// Latest decoded value of every message.
#[derive(Debug, Clone, Default)]
struct BusView {
    row: Row,
}

impl BusView {
    /// Updates the row with a frame's decoded values (a frame that does not decode is ignored).
    fn take(&mut self, f: &CanFrame) {
        let Some(id) = f.standard_id() else { return };
        let d = f.bytes();
        match id {
            ids::TCU_CLUTCH_CMD
            | ids::TCU_ENGINE_REQ
            | ids::TCU_GEAR_CMD
            | ids::TCU_STATUS
            | ids::TCU_ESTIMATES => self.take_tcu(id, d),
            _ => self.take_plant(id, d),
        }
    }

    /// A frame of the plant, the driver or the bench (engine, pedal, sensors, actuators, bench
    /// measurements, the simulation's truth).
    fn take_plant(&mut self, id: u16, d: &[u8]) {
        let r = &mut self.row;
        match id {
            ids::DRV_PEDAL => {
                if let Ok(m) = DrvPedal::decode(d) {
                    r.pedal_pct = m.accel_pedal;
                    r.brake = m.brake_switch;
                }
            }
            ids::ENG_STATUS => {
                if let Ok(m) = EngStatus::decode(d) {
                    r.n_e_rpm = m.eng_speed;
                    r.t_e_nm = m.eng_torque_act;
                }
            }
            ids::DCT_SENSORS => {
                if let Ok(m) = DctSensors::decode(d) {
                    r.n_c_rpm = [m.in_shaft1_speed, m.in_shaft2_speed];
                    r.n_out_rpm = m.out_shaft_speed;
                    r.housing_c = m.housing_temp;
                }
            }
            ids::DCT_ACTUATORS => {
                if let Ok(m) = DctActuators::decode(d) {
                    r.x_mm = [m.clutch1_pos, m.clutch2_pos];
                    r.gear_act = [m.gear_odd_act.into(), m.gear_even_act.into()];
                }
            }
            ids::BENCH_TORQUE => {
                if let Ok(m) = BenchTorque::decode(d) {
                    r.t_act_nm = [m.clutch1_torque, m.clutch2_torque];
                }
            }
            ids::BENCH_TEMPS => {
                if let Ok(m) = BenchTemps::decode(d) {
                    r.theta_pp_c = [m.pressure_plate1_temp, m.pressure_plate2_temp];
                    r.theta_cd_c = m.central_disk_temp;
                }
            }
            ids::BENCH_VEHICLE => {
                if let Ok(m) = BenchVehicle::decode(d) {
                    r.v_kmh = m.vehicle_speed;
                    r.accel_mps2 = m.vehicle_accel;
                    r.grade_pct = m.road_grade;
                }
            }
            ids::SIM_TRUTH => {
                if let Ok(m) = SimTruth::decode(d) {
                    r.theta_true_c = [m.clutch1_temp_true, m.clutch2_temp_true];
                }
            }
            _ => {}
        }
    }

    /// A frame of the TCU (commands, requests, status, estimates).
    fn take_tcu(&mut self, id: u16, d: &[u8]) {
        let r = &mut self.row;
        match id {
            ids::TCU_CLUTCH_CMD => {
                if let Ok(m) = TcuClutchCmd::decode(d) {
                    r.x_ref_mm = [m.clutch1_pos_req, m.clutch2_pos_req];
                }
            }
            ids::TCU_ENGINE_REQ => {
                if let Ok(m) = TcuEngineReq::decode(d) {
                    r.eng_req_nm = m.eng_torque_req_active.then_some(m.eng_torque_req);
                }
            }
            ids::TCU_GEAR_CMD => {
                if let Ok(m) = TcuGearCmd::decode(d) {
                    r.gear_req = [m.gear_odd_req.into(), m.gear_even_req.into()];
                }
            }
            ids::TCU_STATUS => {
                if let Ok(m) = TcuStatus::decode(d) {
                    r.state = m.tcu_state;
                    r.fault = m.fault_code;
                    r.gear_active = m.gear_active.into();
                }
            }
            ids::TCU_ESTIMATES => {
                if let Ok(m) = TcuEstimates::decode(d) {
                    r.theta_est_c = [m.clutch1_temp_est, m.clutch2_temp_est];
                    r.t_ref_nm = [m.clutch1_torque_req, m.clutch2_torque_req];
                }
            }
            _ => {}
        }
    }
}

/// Options of a run.
#[derive(Debug, Clone, Default)]
pub struct SimOptions {
    pub injections: Vec<Injection>,
    /// Count the frames instead of keeping them (`SimRun::frames` left empty): memory then no
    /// longer grows with the frames of a long scenario.
    pub drop_frames: bool,
    /// Feed the rows to the metrics only instead of also keeping them (`SimRun::rows` left
    /// empty; `SimRun::metrics` is computed either way): memory then no longer grows with the
    /// length of the run. For callers that need no row (no CSV, no figure).
    pub drop_rows: bool,
}

/// Everything a run produced.
#[derive(Debug, Clone, Serialize)]
pub struct SimRun {
    pub scenario: String,
    pub description: String,
    pub duration_s: f64,
    /// One row per TCU cycle (empty with `SimOptions::drop_rows`).
    pub rows: Vec<Row>,
    /// The metrics of all the rows, computed as they came (with the scenario's calibration).
    #[serde(skip)]
    pub metrics: Metrics,
    /// Every frame the plant sent (after injections) and the TCU sent, with its time (empty
    /// with `SimOptions::drop_frames`).
    #[serde(skip)]
    pub frames: Vec<(Duration, CanFrame)>,
    /// How many frames went over the bus.
    pub frame_count: u64,
    pub tcu_steps: u64,
    pub safe_entries: u64,
    pub config: SimConfigSummary,
}

/// The switches a run used.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct SimConfigSummary {
    pub temperature_compensation: bool,
    pub slip_compensation: bool,
    pub tcu_initial_temp_c: Option<f64>,
    pub plant_temperature_c: f64,
}

fn apply_injection(
    inj: &[Injection],
    frozen: &mut [Option<u8>],
    t: Duration,
    f: CanFrame,
) -> Option<CanFrame> {
    let ts = t.as_secs_f64();
    let mut data = [0u8; 8];
    let b = f.bytes();
    data[..b.len()].copy_from_slice(b);
    let mut out = Some(f);
    for (k, i) in inj.iter().enumerate() {
        if f.standard_id() != Some(i.id) {
            continue;
        }
        let active = ts >= i.from_s && ts < i.to_s;
        if !active {
            frozen[k] = None;
            continue;
        }
        match i.kind {
            InjectionKind::Stop => out = None,
            InjectionKind::CorruptCrc => {
                data[CRC_BYTE] ^= 0xA5;
                out = CanFrame::standard(i.id, &data[..b.len()]).ok();
            }
            InjectionKind::FreezeCounter => {
                let c = *frozen[k].get_or_insert(crate::can::e2e::counter_of(&data));
                crate::can::e2e::protect(i.id, &mut data, c);
                out = CanFrame::standard(i.id, &data[..b.len()]).ok();
            }
        }
    }
    out
}

/// Runs a plant node and a TCU in lockstep for `duration`.
pub fn run_with(
    plant: &mut dyn PlantNode,
    tcu: &mut Tcu,
    duration: Duration,
    opts: &SimOptions,
) -> SimTrace {
    run_with_hook(plant, tcu, duration, opts, &mut |_, _| {})
}

/// [`run_with`], calling `before_step(t, tcu)` before each TCU computation at `t`: a tester
/// acting on the TCU core during the run (starting or stopping a diagnostic routine).
pub fn run_with_hook(
    plant: &mut dyn PlantNode,
    tcu: &mut Tcu,
    duration: Duration,
    opts: &SimOptions,
    before_step: &mut dyn FnMut(Duration, &mut Tcu),
) -> SimTrace {
    let ms = Duration::from_millis(1);
    let mut to_plant: Vec<Received> = Vec::new();
    let mut pending: Vec<(Duration, CanFrame)> = Vec::new();
    let mut inbox: Vec<TimedFrame> = Vec::new();
    let mut view = BusView::default();
    let mut rec = Recorder::new(opts, tcu.config(), duration);
    let mut frozen = vec![None; opts.injections.len()];
    let mut t = Duration::ZERO;
    // On the 1 ms grid, visiting only the instants where something happens: the plant's cycle,
    // a frame falling due, the TCU's poll timeout (a frame due between two grid points is
    // delivered at the next one, as a 1 ms loop would).
    let ceil_ms =
        |d: Duration| ms * u32::try_from(d.as_nanos().div_ceil(ms.as_nanos())).unwrap_or(u32::MAX);
    while t <= duration {
        if t >= plant.poll_timeout() {
            let out = plant.advance(t, &to_plant);
            to_plant.clear();
            pending.extend(out);
            pending.sort_by_key(|(due, _)| *due);
        }
        let due = pending.partition_point(|(d, _)| *d <= t);
        let mut sync = false;
        for (d, f) in pending.drain(..due) {
            let Some(f) = apply_injection(&opts.injections, &mut frozen, d, f) else {
                continue;
            };
            rec.frame(&mut view, d, f);
            if crate::tcu::is_sync_frame(&f) {
                sync = true;
            }
            inbox.push(TimedFrame { at: d, frame: f });
        }
        let fallback = t >= tcu.poll_timeout();
        if sync || fallback {
            before_step(t, tcu);
            let o = tcu.step(t, &TcuInputs { frames: &inbox });
            inbox.clear();
            for f in &o.frames {
                rec.frame(&mut view, t, *f);
                to_plant.push(Received {
                    frame: *f,
                    timestamp: t,
                });
            }
            let mut r = view.row;
            r.t_s = t.as_secs_f64();
            r.n_e_ref_rpm = o.trace.w_e_ref_radps / crate::model::engine::RPM;
            r.n_c_ref_rpm = o.trace.w_c_ref_radps / crate::model::engine::RPM;
            r.phase = o.trace.phase;
            rec.row(r);
        }
        let next = [
            Some(plant.poll_timeout()),
            Some(tcu.poll_timeout()),
            pending.first().map(|(d, _)| *d),
        ]
        .into_iter()
        .flatten()
        .min()
        .unwrap_or(duration);
        t = ceil_ms(next).max(t + ms);
    }
    rec.finish()
}

/// What a run records as it goes: every frame counted (and kept unless
/// `SimOptions::drop_frames`), every row fed to the metrics (and kept unless
/// `SimOptions::drop_rows`).
struct Recorder {
    keep_frames: bool,
    keep_rows: bool,
    rows: Vec<Row>,
    metrics: metrics::Stream,
    frames: Vec<(Duration, CanFrame)>,
    frame_count: u64,
    tcu_steps: u64,
}

impl Recorder {
    fn new(opts: &SimOptions, cfg: &TcuConfig, duration: Duration) -> Self {
        let rows = if opts.drop_rows {
            Vec::new()
        } else {
            Vec::with_capacity((duration.as_millis() / 10 + 2) as usize)
        };
        Self {
            keep_frames: !opts.drop_frames,
            keep_rows: !opts.drop_rows,
            rows,
            metrics: metrics::Stream::new(cfg),
            frames: Vec::new(),
            frame_count: 0,
            tcu_steps: 0,
        }
    }

    /// A frame on the bus at `at`: decoded into `view`, counted, kept.
    fn frame(&mut self, view: &mut BusView, at: Duration, f: CanFrame) {
        view.take(&f);
        self.frame_count += 1;
        if self.keep_frames {
            self.frames.push((at, f));
        }
    }

    /// The row of one TCU computation.
    fn row(&mut self, r: Row) {
        self.tcu_steps += 1;
        self.metrics.push(&r);
        if self.keep_rows {
            self.rows.push(r);
        }
    }

    fn finish(self) -> SimTrace {
        SimTrace {
            rows: self.rows,
            metrics: self.metrics.finish(),
            frames: self.frames,
            frame_count: self.frame_count,
            tcu_steps: self.tcu_steps,
        }
    }
}

/// What [`run_with`] recorded.
#[derive(Debug, Clone)]
pub struct SimTrace {
    /// One row per TCU cycle (empty with `SimOptions::drop_rows`).
    pub rows: Vec<Row>,
    /// The metrics of all the rows (with the TCU's calibration).
    pub metrics: Metrics,
    /// Every frame with its time (empty with `SimOptions::drop_frames`).
    pub frames: Vec<(Duration, CanFrame)>,
    pub frame_count: u64,
    pub tcu_steps: u64,
}

/// Runs a scenario: the plant core of `plant` with the scenario's configuration and the TCU core
/// with `base` plus the scenario's overrides.
pub fn run_scenario(sc: &SimScenario, base: &TcuConfig, opts: &SimOptions) -> SimRun {
    let mut cfg = base.clone();
    sc.tcu.apply(&mut cfg);
    let mut plant = Plant::new(sc.plant.clone());
    let mut tcu = Tcu::new(cfg.clone(), Duration::ZERO);
    let duration = Duration::from_secs_f64(sc.duration_s);
    let SimTrace {
        rows,
        metrics,
        frames,
        frame_count,
        tcu_steps,
    } = run_with(&mut plant, &mut tcu, duration, opts);
    SimRun {
        scenario: sc.name.clone(),
        description: sc.description.clone(),
        duration_s: sc.duration_s,
        rows,
        metrics,
        frames,
        frame_count,
        tcu_steps,
        safe_entries: tcu.safe_entries(),
        config: SimConfigSummary {
            temperature_compensation: cfg.compensation.temperature,
            slip_compensation: cfg.compensation.slip,
            tcu_initial_temp_c: cfg.estimator.initial_temp_c,
            plant_temperature_c: sc.plant.initial.temperature_c,
        },
    }
}

/// The rows of a run as CSV (one header line; `-` for an inactive engine request).
pub fn rows_csv(rows: &[Row]) -> String {
    use std::fmt::Write as _;
    let mut s = String::from(
        "t_s,state,phase,fault,pedal_pct,brake,gear_active,gear_odd,gear_even,n_e_rpm,n_e_ref_rpm,\
         n_c1_rpm,n_c2_rpm,n_c_ref_rpm,n_out_rpm,x1_mm,x1_ref_mm,x2_mm,x2_ref_mm,t_ref1_nm,\
         t_act1_nm,t_ref2_nm,t_act2_nm,eng_req_nm,t_e_nm,accel_mps2,v_kmh,grade_pct,housing_c,\
         theta_est1_c,theta_true1_c,theta_est2_c,theta_true2_c\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{:.3},{},{},{},{:.1},{},{},{},{},{:.1},{:.1},{:.1},{:.1},{:.1},{:.1},{:.3},{:.3},{:.3},{:.3},\
             {:.1},{:.1},{:.1},{:.1},{},{:.1},{:.3},{:.2},{:.1},{:.0},{:.1},{:.1},{:.1},{:.1}",
            r.t_s,
            r.state.label(),
            r.phase,
            r.fault.label(),
            r.pedal_pct,
            u8::from(r.brake),
            r.gear_active.code(),
            r.gear_act[0].code(),
            r.gear_act[1].code(),
            r.n_e_rpm,
            r.n_e_ref_rpm,
            r.n_c_rpm[0],
            r.n_c_rpm[1],
            r.n_c_ref_rpm,
            r.n_out_rpm,
            r.x_mm[0],
            r.x_ref_mm[0],
            r.x_mm[1],
            r.x_ref_mm[1],
            r.t_ref_nm[0],
            r.t_act_nm[0],
            r.t_ref_nm[1],
            r.t_act_nm[1],
            r.eng_req_nm.map_or("-".to_string(), |v| format!("{v:.1}")),
            r.t_e_nm,
            r.accel_mps2,
            r.v_kmh,
            r.grade_pct,
            r.housing_c,
            r.theta_est_c[0],
            r.theta_true_c[0],
            r.theta_est_c[1],
            r.theta_true_c[1],
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::metrics::reference::assert_same;
    use super::*;
    use std::path::Path;

    fn launch(seconds: f64) -> SimScenario {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut sc = SimScenario::load(&root.join("config/scenarios/launch_50.toml")).unwrap();
        sc.duration_s = seconds;
        sc
    }

    /// In lockstep the TCU computes once per plant cycle (a DCT_Sensors frame every 10 ms of the
    /// DBC, at 0 … 1 000 ms), one row per computation, in time order a cycle apart.
    #[test]
    fn the_tcu_computes_once_per_plant_cycle_with_one_row_each() {
        let r = run_scenario(&launch(1.0), &TcuConfig::default(), &SimOptions::default());
        let cycle_s = f64::from(crate::can::messages::DctSensors::CYCLE_MS) * 1e-3;
        let sensors = r
            .frames
            .iter()
            .filter(|(_, f)| f.standard_id() == Some(crate::can::messages::ids::DCT_SENSORS))
            .count();
        assert_eq!(sensors, 101);
        assert_eq!(r.tcu_steps, 101);
        assert_eq!(r.rows.len(), 101);
        assert!(r
            .rows
            .windows(2)
            .all(|w| ((w[1].t_s - w[0].t_s) - cycle_s).abs() < 1e-9));
        assert_eq!(r.frame_count, r.frames.len() as u64);
    }

    /// Dropping the frames changes nothing but the memory: the same count, the same rows.
    #[test]
    fn dropping_the_frames_keeps_the_count_and_the_rows() {
        let sc = launch(0.5);
        let kept = run_scenario(&sc, &TcuConfig::default(), &SimOptions::default());
        let opts = SimOptions {
            drop_frames: true,
            ..SimOptions::default()
        };
        let dropped = run_scenario(&sc, &TcuConfig::default(), &opts);
        assert!(dropped.frames.is_empty());
        assert_eq!(dropped.frame_count, kept.frame_count);
        assert_eq!(dropped.rows, kept.rows);
    }

    /// Dropping the rows keeps the metrics: the stream's are those of the rows kept.
    #[test]
    fn dropping_the_rows_keeps_the_metrics() {
        let sc = launch(3.0);
        let cfg = TcuConfig::default();
        let kept = run_scenario(&sc, &cfg, &SimOptions::default());
        let opts = SimOptions {
            drop_rows: true,
            ..SimOptions::default()
        };
        let dropped = run_scenario(&sc, &cfg, &opts);
        assert!(dropped.rows.is_empty() && kept.rows.len() == 301);
        assert_eq!(dropped.tcu_steps, kept.tcu_steps);
        assert_eq!(dropped.frames, kept.frames);
        let slice = metrics::compute(&kept.rows, &cfg);
        assert_eq!(format!("{:?}", dropped.metrics), format!("{slice:?}"));
        assert_eq!(format!("{:?}", kept.metrics), format!("{slice:?}"));
        assert_eq!(dropped.metrics.launches.len(), 1);
    }

    /// Every scenario of config/scenarios: the metrics' stream gives what the slice
    /// computation gave.
    #[test]
    fn the_metrics_stream_matches_the_slice_computation_on_every_scenario() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/scenarios");
        let cfg = TcuConfig::default();
        let opts = SimOptions {
            drop_frames: true,
            ..SimOptions::default()
        };
        let mut names = Vec::new();
        for e in std::fs::read_dir(&dir).unwrap() {
            let p = e.unwrap().path();
            if p.extension().is_some_and(|x| x == "toml") {
                let sc = SimScenario::load(&p).unwrap();
                let run = run_scenario(&sc, &cfg, &opts);
                let want = metrics::reference::compute(&run.rows, &cfg);
                assert_same(&metrics::compute(&run.rows, &cfg), &want, &sc.name);
                // As the run computed them, with the scenario's calibration.
                assert_same(&run.metrics, &want, &sc.name);
                names.push(sc.name);
            }
        }
        for must in ["launch_shift_20s", "drive_60s", "soak_600s"] {
            assert!(names.iter().any(|n| n == must), "{must} not found");
        }
    }
}

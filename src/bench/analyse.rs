//! The analysis of a bench recording (`ddct bench`, and `ddct bench --analyze LOG` on a log
//! recorded elsewhere): the same metrics as `ddct sim` on what the recorder saw, next to the
//! lockstep simulation of the same scenario, the timing, and the verdict of the scenario's
//! `[limits]` ([`analyse`]); the HTML report of it ([`html_report`]). Pure: the figures and the
//! CSV come back as text with the names to write them under; the caller writes them.

use super::timing::{timing, Timing};
use super::LOCKSTEP_TIMEOUT;
use crate::can::candump::{LogError, LogReader};
use crate::can::messages::{ids, TcuState};
use crate::can::CanFrame;
use crate::daemon::plant::PlantReport;
use crate::daemon::tcu::TcuReport;
use crate::sim::buslog::{self, Spread, TimeAxis};
use crate::sim::html::{self, Table};
use crate::sim::metrics::{self, Metrics};
use crate::sim::verdict::{self, Check};
use crate::sim::{self, plots, SimOptions, SimScenario};
use crate::tcu::TcuConfig;
use serde::Serialize;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// What `ddct bench` prints with `--json`.
#[derive(Debug, Serialize)]
pub struct BenchSummary {
    pub iface: String,
    pub scenario: String,
    pub description: String,
    pub duration_s: f64,
    pub bus: Metrics,
    pub sim: Option<Metrics>,
    pub sim_wall_s: Option<f64>,
    pub timing: Timing,
    pub plant: Option<PlantReport>,
    pub tcu: Option<TcuReport>,
    pub log: PathBuf,
    pub plots: Vec<PathBuf>,
    /// First and last DCT_Sensors frame, relative to the first frame of the log (s).
    pub plant_window: Option<(f64, f64)>,
    /// The clock of the physics (rows, windows, plots): bus or receive time.
    pub time_axis: TimeAxis,
    /// The checks of the scenario's `[limits]` on the bus run (`crate::sim::verdict`).
    pub verdict: Vec<Check>,
}

/// What the bench recorded: the bus (a live run, or a log recorded elsewhere), the echo and the
/// daemons' reports.
pub struct Recorded {
    pub iface: String,
    pub frames: Vec<(Duration, CanFrame)>,
    pub echo: Option<Vec<(Duration, CanFrame)>>,
    pub plant: Option<PlantReport>,
    pub tcu: Option<TcuReport>,
    /// Where the bus's log is.
    pub log: PathBuf,
}

impl Recorded {
    /// A candump `-l` log recorded elsewhere (`log` names it), read from `input`: its frames in
    /// time order, no echo and no daemon reports; each unreadable line goes to `bad_line`.
    pub fn from_log(input: impl Read, log: PathBuf, mut bad_line: impl FnMut(LogError)) -> Self {
        let mut frames = Vec::new();
        for r in LogReader::new(input) {
            match r {
                Ok(rec) => frames.push((rec.timestamp, rec.frame)),
                Err(e) => bad_line(e),
            }
        }
        frames.sort_by_key(|x| x.0);
        Recorded {
            iface: "log".to_string(),
            frames,
            echo: None,
            plant: None,
            tcu: None,
            log,
        }
    }
}

/// An analysis: the summary, and the files it made (figures and CSV) with their paths, in the
/// order to write them.
pub struct Analysis {
    pub summary: BenchSummary,
    pub files: Vec<(PathBuf, String)>,
}

/// The analysis of a recording: metrics, figures and CSV (named in `out`), the lockstep
/// simulation of the same scenario beside it, the timing and the verdict of the scenario's
/// limits; the physics read on `axis`.
pub fn analyse(
    out: &Path,
    sc: &SimScenario,
    cfg: &TcuConfig,
    r: Recorded,
    axis: TimeAxis,
) -> Analysis {
    let mut files = Vec::new();
    let mut plots = Vec::new();
    let physics = buslog::on_axis(&r.frames, axis);
    let rows = buslog::rows(&physics);
    let mut tcfg = cfg.clone();
    sc.tcu.apply(&mut tcfg);
    let bus = metrics::compute(&rows, &tcfg);
    let p = out.join(format!("{}_bus.svg", sc.name));
    let title = format!("{} on {} (recorded): {}", sc.name, r.iface, sc.description);
    files.push((p.clone(), plots::run_figure(&title, &rows)));
    plots.push(p);
    files.push((
        out.join(format!("{}_bus.csv", sc.name)),
        sim::rows_csv(&rows),
    ));
    // The same scenario in lockstep simulation, for comparison.
    let t0 = Instant::now();
    let srun = sim::run_scenario(sc, cfg, &SimOptions::default());
    let sim_wall = t0.elapsed().as_secs_f64();
    let simm = metrics::compute(&srun.rows, &tcfg);
    let p = out.join(format!("{}_sim.svg", sc.name));
    let title = format!("{} in lockstep simulation: {}", sc.name, sc.description);
    files.push((p.clone(), plots::run_figure(&title, &srun.rows)));
    plots.push(p);
    let t0 = physics.first().map_or(Duration::ZERO, |f| f.0);
    let sensors: Vec<f64> = physics
        .iter()
        .filter(|(_, f)| f.standard_id() == Some(ids::DCT_SENSORS))
        .map(|(t, _)| t.saturating_sub(t0).as_secs_f64())
        .collect();
    let plant_window = sensors.first().zip(sensors.last()).map(|(a, b)| (*a, *b));
    let timing = timing(&r.frames, r.echo.as_deref());
    let latency_ratio = timing
        .echo_latency
        .as_ref()
        .filter(|e| e.n > 0 && e.p99_us > 0.0 && timing.tcu_latency.n > 0)
        .map(|e| timing.tcu_latency.p99_us / e.p99_us);
    let in_run = Metrics {
        status_events: run_events(&bus, plant_window),
        ..bus.clone()
    };
    let mut verdict = verdict::judge(sc.limits.as_ref(), &in_run, latency_ratio);
    verdict.extend(r.plant.as_ref().and_then(lockstep_check));
    let summary = BenchSummary {
        verdict,
        plant_window,
        time_axis: axis,
        iface: r.iface,
        scenario: sc.name.clone(),
        description: sc.description.clone(),
        duration_s: sc.duration_s,
        bus,
        sim: Some(simm),
        sim_wall_s: Some(sim_wall),
        timing,
        plant: r.plant,
        tcu: r.tcu,
        log: r.log,
        plots,
    };
    Analysis { summary, files }
}

/// The TCU's status while the plant ran and the TCU was past Init: the one set of events both
/// the verdict's fault check and the printed fault codes read. The TCU starts before the plant
/// (Init, waiting for its inputs) and stops after it (an ENG_Status timeout once the plant's
/// last frame is gone): neither is a fault of the run.
fn run_events(bus: &Metrics, plant_window: Option<(f64, f64)>) -> Vec<metrics::StatusEvent> {
    bus.status_events
        .iter()
        .filter(|e| e.state != TcuState::Init)
        .filter(|e| plant_window.is_none_or(|(a, b)| e.t_s >= a && e.t_s <= b))
        .copied()
        .collect()
}

/// A lockstep run's own check: the TCU answered every plant cycle within the lockstep timeout
/// (a cycle without its answer was simulated on the TCU's previous command, as a free-running
/// plant would).
fn lockstep_check(p: &PlantReport) -> Option<Check> {
    p.lockstep.as_ref()?;
    Some(Check {
        name: "lockstep_answers",
        limit: format!(
            "every cycle answered within {} s",
            LOCKSTEP_TIMEOUT.as_secs_f64()
        ),
        measured: format!("{} of {} cycles unanswered", p.lockstep_timeouts, p.cycles),
        pass: p.lockstep_timeouts == 0,
    })
}

impl BenchSummary {
    /// The runs whose metrics the summary holds, with their names: the bus's, then the lockstep
    /// simulation's when there is one.
    pub fn runs(&self) -> impl Iterator<Item = (&'static str, &Metrics)> {
        [("bus", Some(&self.bus)), ("sim", self.sim.as_ref())]
            .into_iter()
            .filter_map(|(name, m)| Some((name, m?)))
    }

    /// The TCU's status events while the plant ran and the TCU was past Init: the events the
    /// verdict's fault check reads.
    pub fn run_events(&self) -> Vec<metrics::StatusEvent> {
        run_events(&self.bus, self.plant_window)
    }
}

/// A number at two decimals, `-` for none.
pub fn f2(v: Option<f64>) -> String {
    v.map_or("-".into(), |x| format!("{x:.2}"))
}

/// The run as a self-contained HTML page: verdict, launches, shifts, timing, and the `figures`
/// (file name, SVG text).
pub fn html_report(s: &BenchSummary, figures: &[(String, String)]) -> String {
    html::report(
        &format!("ddct bench: {} on {}", s.scenario, s.iface),
        &s.description,
        verdict::passed(&s.verdict),
        &[
            html::verdict_table(&s.verdict),
            launches_table(s),
            shifts_table(s),
            timing_table(&s.timing),
        ],
        figures,
    )
}

/// A table with its caption and head, no row yet.
fn empty_table(caption: &str, head: &[&str]) -> Table {
    Table {
        caption: caption.into(),
        head: head.iter().map(|x| x.to_string()).collect(),
        rows: Vec::new(),
    }
}

/// The HTML table of every run's launches.
fn launches_table(s: &BenchSummary) -> Table {
    let mut launches = empty_table(
        "Launches (|Terr|300: peak torque error in the first 300 ms, N·m; a_pk600: peak \
         acceleration in the first 600 ms, m/s²)",
        &[
            "run",
            "pedal %",
            "lock-up s",
            "flare rpm",
            "spike m/s²",
            "stall",
            "|Terr|300",
            "a_pk600",
        ],
    );
    for (name, m) in s.runs() {
        for l in &m.launches {
            launches.rows.push(vec![
                name.into(),
                format!("{:.0}", l.pedal_pct),
                f2(l.lockup_s),
                format!("{:.0}", l.flare_rpm),
                f2(l.lockup_spike_mps2),
                l.stall.to_string(),
                format!("{:.1}", l.peak_torque_error_300ms_nm),
                format!("{:.2}", l.peak_accel_600ms_mps2),
            ]);
        }
    }
    launches
}

/// The HTML table of every run's shifts.
fn shifts_table(s: &BenchSummary) -> Table {
    let mut shifts = empty_table(
        "Shifts",
        &["run", "shift", "duration s", "min accel m/s²", "completed"],
    );
    for (name, m) in s.runs() {
        for x in &m.shifts {
            shifts.rows.push(vec![
                name.into(),
                format!("{}→{}", x.from, x.to),
                format!("{:.2}", x.duration_s),
                format!("{:.2}", x.min_accel_mps2),
                x.completed.to_string(),
            ]);
        }
    }
    shifts
}

/// The HTML table of the bus timing: the TCU's reaction, the bare echo's, the periods' jitter.
fn timing_table(t: &Timing) -> Table {
    let mut timing = empty_table(
        "Timing (recorder receive timestamps, µs)",
        &["what", "n", "p50", "p99", "max"],
    );
    let mut line = |name: &str, x: &Spread| {
        timing.rows.push(vec![
            name.into(),
            x.n.to_string(),
            format!("{:.0}", x.p50_us),
            format!("{:.0}", x.p99_us),
            format!("{:.0}", x.max_us),
        ])
    };
    line("DCT_Sensors → TCU_ClutchCmd (TCU daemon)", &t.tcu_latency);
    if let Some(e) = &t.echo_latency {
        line("bare frame echo, same bus", e);
    }
    line("TCU_ClutchCmd |interval − 10 ms|", &t.clutch_cmd_jitter);
    line("DCT_Sensors |interval − 10 ms|", &t.sensors_jitter);
    timing
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::candump::LogWriter;

    /// The lockstep simulation's own frames, written as a candump log and analysed as a log
    /// recorded elsewhere: the bus's launches and shifts are the simulation's, the verdict
    /// passes, and the figures and CSV are named after the scenario in `out`.
    #[test]
    fn a_log_of_the_simulation_analyses_as_the_simulation() {
        let sc = SimScenario::load(Path::new("config/scenarios/launch_50.toml")).unwrap();
        let cfg = TcuConfig::default();
        let run = sim::run_scenario(&sc, &cfg, &SimOptions::default());
        let mut w = LogWriter::new(Vec::new());
        for (t, f) in &run.frames {
            w.write_frame(*t, "sim", f, None).unwrap();
        }
        let text = w.into_inner();
        let mut bad = 0;
        let r = Recorded::from_log(text.as_slice(), "x.log".into(), |_| bad += 1);
        assert_eq!((bad, r.frames.len()), (0, run.frames.len()));
        let a = analyse(Path::new("out"), &sc, &cfg, r, TimeAxis::Bus);
        let s = &a.summary;
        let sim = s.sim.as_ref().unwrap();
        assert_eq!(s.bus.launches.len(), sim.launches.len());
        assert_eq!(s.bus.shifts.len(), sim.shifts.len());
        assert!(verdict::passed(&s.verdict), "{:?}", s.verdict);
        let names: Vec<_> = a.files.iter().map(|(p, _)| p.clone()).collect();
        assert_eq!(
            names,
            [
                "launch_50_bus.svg",
                "launch_50_bus.csv",
                "launch_50_sim.svg"
            ]
            .map(|n| Path::new("out").join(n))
        );
        assert_eq!(s.plots, [names[0].clone(), names[2].clone()]);
        assert!(html_report(s, &[]).contains("<table"));
    }
}

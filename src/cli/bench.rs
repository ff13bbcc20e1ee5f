//! `ddct bench`: the plant and TCU daemons on a bus (vcan, or the in-process bus with `--iface
//! sim`), in real time, playing a `ddct sim` scenario (the plant plays its driver), with a
//! recorder on the bus. Then the same analysis as `ddct sim` on what the recorder saw, next to the
//! lockstep simulation of the same scenario, plus the timing: latency from a DCT_Sensors frame to
//! the TCU_ClutchCmd frame it causes (recorder receive timestamps — the kernel's on SocketCAN),
//! next to a bare frame echo measured on the same bus just before (a responder with the TCU
//! daemon's stack — tokio, one socket, current-thread runtime — that answers each DCT_Sensors-id
//! frame of a 10 ms pinger with a TCU_ClutchCmd-id frame), the TCU_ClutchCmd cycle jitter, and
//! the daemons' overruns and deadline misses.
//!
//! Each daemon and the recorder run on their own thread, runtime and socket (endpoint).
//! `ddct bench --analyze LOG` runs the analysis on a candump log recorded elsewhere.

use super::args::{probe_can, rt_priority, Iface};
use super::shutdown_signal;
use anyhow::Context;
use clap::Args;
use ddct::bench::{bench_run, echo_run, timing, BenchPacing, Net, Timing};
use ddct::can::candump::{LogReader, LogWriter};
use ddct::can::messages::{ids, FaultCode, TcuState};
use ddct::can::{CanFrame, InProcessBus};
use ddct::daemon::os::set_realtime_priority;
use ddct::daemon::plant::PlantReport;
use ddct::daemon::tcu::TcuReport;
use ddct::sim::buslog::{self, Spread, TimeAxis};
use ddct::sim::html::{self, Table};
use ddct::sim::metrics::{self, Metrics};
use ddct::sim::verdict::{self, Check};
use ddct::sim::{self, plots, SimOptions, SimScenario};
use ddct::tcu::TcuConfig;
use serde::Serialize;
use std::io::{BufReader, BufWriter};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

#[derive(Debug, Args)]
pub struct BenchArgs {
    /// CAN interface (e.g. vcan0), or `sim` for the in-process bus.
    #[arg(long, required_unless_present = "analyze")]
    iface: Option<Iface>,
    /// Scenario (a `ddct sim` scenario file; default: the built-in
    /// config/scenarios/launch_shift_20s.toml).
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// TCU calibration (its `params` names the physical parameter file; default: the built-in
    /// config/tcu.toml with config/params.toml, so no working directory is needed).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Output folder: bench.log (candump -l of the run), echo.log, figures, summary.json
    /// (default: out/bench for a run; out/analyze/LOG_STEM with `--analyze LOG`, so an analysis
    /// never overwrites the last run's).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Seconds of bare frame echo measured before the run (0 ..= 600; 0: none).
    #[arg(long, default_value_t = 10.0, value_parser = super::args::number_in(0.0, 600.0, "seconds"))]
    echo: f64,
    /// Analyse a candump -l log instead of running. Needs `--scenario`: the scenario the log
    /// played, whose driver, duration and `[limits]` the analysis and the verdict read (a log
    /// does not say which scenario made it).
    #[arg(long, requires = "scenario")]
    analyze: Option<PathBuf>,
    /// How the daemons keep time: `lockstep` (the plant, paced in real time, waits for the TCU's
    /// answer to each 10 ms cycle, and the TCU counts time in the plant's frames: a host that
    /// stalls them slows the run instead of changing its physics and verdict) or `real-time`
    /// (both free-running on their own clocks, like two ECUs: the verdict then also measures
    /// the host's real-time behaviour).
    #[arg(long, value_enum, default_value_t = PacingArg::Lockstep)]
    pacing: PacingArg,
    /// The clock the analysis reads the recording's physics on (lock-up times, windows, the
    /// plots): `bus` (the plant's simulated time, 10 ms per DCT_Sensors frame: a stalled host or
    /// recorder moves nothing) or `receive` (the recorder's timestamps). Latency and cycle
    /// jitter are always read on the receive timestamps.
    #[arg(long, value_enum, default_value_t = TimeAxisArg::Bus)]
    time: TimeAxisArg,
    /// Run the plant, TCU, echo and recorder threads under the real-time FIFO scheduler at this
    /// priority (1..=99; needs root; a warning when refused).
    #[arg(long, value_parser = rt_priority)]
    rt_priority: Option<i32>,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    json: bool,
    /// Write the verdict (the scenario's `[limits]` checks) as JUnit XML to this file.
    #[arg(long)]
    junit: Option<PathBuf>,
}

/// `--pacing` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum PacingArg {
    Lockstep,
    RealTime,
}

/// `--time` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum TimeAxisArg {
    Bus,
    Receive,
}

impl From<TimeAxisArg> for TimeAxis {
    fn from(t: TimeAxisArg) -> Self {
        match t {
            TimeAxisArg::Bus => TimeAxis::Bus,
            TimeAxisArg::Receive => TimeAxis::Receive,
        }
    }
}

impl From<PacingArg> for BenchPacing {
    fn from(p: PacingArg) -> Self {
        match p {
            PacingArg::Lockstep => BenchPacing::Lockstep,
            PacingArg::RealTime => BenchPacing::RealTime,
        }
    }
}

impl BenchArgs {
    /// The output folder: `--out`, else out/bench for a run and out/analyze/LOG_STEM for
    /// `--analyze LOG`.
    fn out(&self) -> PathBuf {
        match (&self.out, &self.analyze) {
            (Some(o), _) => o.clone(),
            (None, Some(log)) => Path::new("out/analyze").join(
                log.file_stem()
                    .map_or_else(|| "log".into(), |s| s.to_string_lossy().into_owned()),
            ),
            (None, None) => PathBuf::from("out/bench"),
        }
    }
}

/// The default run (`--scenario` omitted): built in, so `ddct bench` works from any directory.
const DEFAULT_SCENARIO: &str = include_str!("../../config/scenarios/launch_shift_20s.toml");

fn realtime(prio: Option<i32>) {
    if let Some(p) = prio {
        if let Err(e) = set_realtime_priority(p) {
            eprintln!("bench: real-time priority {p} refused ({e}); running at normal priority");
        }
    }
}

fn write_log(path: &Path, iface: &str, frames: &[(Duration, CanFrame)]) -> anyhow::Result<()> {
    let f = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    let mut w = LogWriter::new(BufWriter::new(f));
    for (t, fr) in frames {
        w.write_frame(*t, iface, fr, None)?;
    }
    w.flush()?;
    Ok(())
}

fn read_log(path: &Path) -> anyhow::Result<Vec<(Duration, CanFrame)>> {
    let f = std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let mut out = Vec::new();
    for r in LogReader::new(BufReader::new(f)) {
        match r {
            Ok(rec) => out.push((rec.timestamp, rec.frame)),
            Err(e) => eprintln!("{}: {e}", path.display()),
        }
    }
    out.sort_by_key(|x| x.0);
    Ok(out)
}

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
    /// The checks of the scenario's `[limits]` on the bus run (`ddct::sim::verdict`).
    pub verdict: Vec<Check>,
}

/// What the bench recorded: the bus (a live run, or a log given with `--analyze`), the echo and
/// the daemons' reports.
struct Recorded {
    iface: String,
    frames: Vec<(Duration, CanFrame)>,
    echo: Option<Vec<(Duration, CanFrame)>>,
    plant: Option<PlantReport>,
    tcu: Option<TcuReport>,
    log: PathBuf,
}

pub fn run(a: BenchArgs) -> anyhow::Result<ExitCode> {
    let cfg = super::args::tcu_config(a.config.as_deref())?;
    let sc = match &a.scenario {
        Some(p) => SimScenario::load(p)?,
        None => SimScenario::from_toml_str(
            Path::new("config/scenarios/launch_shift_20s.toml"),
            DEFAULT_SCENARIO,
        )?,
    };
    let out = a.out();
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    let recorded = match &a.analyze {
        Some(p) => Recorded {
            iface: "log".to_string(),
            frames: read_log(p)?,
            echo: None,
            plant: None,
            tcu: None,
            log: p.clone(),
        },
        None => record(&a, &sc, &cfg)?,
    };
    let summary = analyse(&out, &sc, &cfg, recorded, a.time.into())?;
    report(&a, &summary)
}

/// The live part: the echo (if asked), then the daemons playing the scenario, each recording
/// written as a candump log.
fn record(a: &BenchArgs, sc: &SimScenario, cfg: &TcuConfig) -> anyhow::Result<Recorded> {
    let net = match a.iface.clone() {
        Some(Iface::Can(name)) => {
            // A missing interface is named with how to create one. Each daemon thread opens
            // its own socket later, on its own runtime; this check needs none.
            probe_can(&name)?;
            Net::Can(name)
        }
        _ => Net::Sim(InProcessBus::new("sim")),
    };
    let prio = a.rt_priority;
    let echo = if a.echo > 0.0 {
        eprintln!("bench: bare frame echo on {} for {} s", net.name(), a.echo);
        let pb = super::spinner(format!("bare frame echo, {} s", a.echo));
        let e = echo_run(&net, a.echo, move || realtime(prio));
        pb.finish_and_clear();
        let e = e?;
        write_log(&a.out().join("echo.log"), &net.name(), &e)?;
        Some(e)
    } else {
        None
    };
    eprintln!(
        "bench: plant + TCU daemons on {} for {} s ({})",
        net.name(),
        sc.duration_s,
        sc.name
    );
    // The spinner's ticker thread first: threads started after `realtime` inherit SCHED_FIFO.
    let pb = super::spinner(format!(
        "{}, {} s in real time ({:?})",
        sc.name, sc.duration_s, a.pacing
    ));
    realtime(prio);
    let r = bench_run(
        &net,
        sc,
        cfg,
        a.pacing.into(),
        move || realtime(prio),
        shutdown_signal,
    );
    pb.finish_and_clear();
    let r = r?;
    if !r.settled {
        eprintln!(
            "bench: the recording did not settle within a second of the plant's end \
             (a plant frame or the TCU's last answer missing)"
        );
    }
    let log = a.out().join("bench.log");
    write_log(&log, &net.name(), &r.frames)?;
    Ok(Recorded {
        iface: net.name(),
        frames: r.frames,
        echo,
        plant: Some(r.plant),
        tcu: Some(r.tcu),
        log,
    })
}

/// The analysis of a recording: metrics, figures and CSV in `out`, the lockstep simulation of
/// the same scenario beside it, the timing and the verdict of the scenario's limits.
fn analyse(
    out: &Path,
    sc: &SimScenario,
    cfg: &TcuConfig,
    r: Recorded,
    axis: TimeAxis,
) -> anyhow::Result<BenchSummary> {
    let mut plots = Vec::new();
    let physics = buslog::on_axis(&r.frames, axis);
    let rows = buslog::rows(&physics);
    let mut tcfg = cfg.clone();
    sc.tcu.apply(&mut tcfg);
    let bus = metrics::compute(&rows, &tcfg);
    let p = out.join(format!("{}_bus.svg", sc.name));
    let title = format!("{} on {} (recorded): {}", sc.name, r.iface, sc.description);
    std::fs::write(&p, plots::run_figure(&title, &rows))?;
    plots.push(p);
    std::fs::write(
        out.join(format!("{}_bus.csv", sc.name)),
        sim::rows_csv(&rows),
    )?;
    // The same scenario in lockstep simulation, for comparison.
    let t0 = Instant::now();
    let srun = sim::run_scenario(sc, cfg, &SimOptions::default());
    let sim_wall = t0.elapsed().as_secs_f64();
    let simm = metrics::compute(&srun.rows, &tcfg);
    let p = out.join(format!("{}_sim.svg", sc.name));
    let title = format!("{} in lockstep simulation: {}", sc.name, sc.description);
    std::fs::write(&p, plots::run_figure(&title, &srun.rows))?;
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
    Ok(BenchSummary {
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
    })
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
            ddct::bench::LOCKSTEP_TIMEOUT.as_secs_f64()
        ),
        measured: format!("{} of {} cycles unanswered", p.lockstep_timeouts, p.cycles),
        pass: p.lockstep_timeouts == 0,
    })
}

/// Writes summary.json, report.html and the JUnit file, prints the summary and the verdict;
/// the exit code is the verdict's.
fn report(a: &BenchArgs, summary: &BenchSummary) -> anyhow::Result<ExitCode> {
    std::fs::write(
        a.out().join("summary.json"),
        serde_json::to_string_pretty(summary)?,
    )?;
    let runs = [(summary.scenario.clone(), summary.verdict.clone())];
    if a.json {
        println!("{}", serde_json::to_string_pretty(summary)?);
    } else {
        print_summary(summary);
        println!();
        print!("{}", verdict::table(&runs));
    }
    eprintln!(
        "bench: summary in {}",
        a.out().join("summary.json").display()
    );
    let html = a.out().join("report.html");
    std::fs::write(&html, html_report(summary)?)
        .with_context(|| format!("writing {}", html.display()))?;
    eprintln!("bench: report in {}", html.display());
    if let Some(path) = &a.junit {
        std::fs::write(path, verdict::junit("ddct bench", &runs))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if verdict::passed(&summary.verdict) {
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!("bench: FAIL ({})", summary.scenario);
        Ok(ExitCode::FAILURE)
    }
}

fn f1(v: Option<f64>) -> String {
    v.map_or("-".into(), |x| format!("{x:.2}"))
}

/// The runs whose metrics a summary holds, with their names: the bus's, then the lockstep
/// simulation's when there is one.
fn runs(s: &BenchSummary) -> impl Iterator<Item = (&'static str, &Metrics)> {
    [("bus", Some(&s.bus)), ("sim", s.sim.as_ref())]
        .into_iter()
        .filter_map(|(name, m)| Some((name, m?)))
}

/// The run as a self-contained HTML page: verdict, launches, shifts, timing, the figures.
fn html_report(s: &BenchSummary) -> anyhow::Result<String> {
    let mut figures = Vec::new();
    for p in &s.plots {
        let svg = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
        figures.push((
            p.file_name()
                .map_or(String::new(), |n| n.to_string_lossy().into()),
            svg,
        ));
    }
    Ok(html::report(
        &format!("ddct bench: {} on {}", s.scenario, s.iface),
        &s.description,
        verdict::passed(&s.verdict),
        &[
            html::verdict_table(&s.verdict),
            launches_table(s),
            shifts_table(s),
            timing_table(&s.timing),
        ],
        &figures,
    ))
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
    for (name, m) in runs(s) {
        for l in &m.launches {
            launches.rows.push(vec![
                name.into(),
                format!("{:.0}", l.pedal_pct),
                f1(l.lockup_s),
                format!("{:.0}", l.flare_rpm),
                f1(l.lockup_spike_mps2),
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
    for (name, m) in runs(s) {
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

/// The summary for a terminal: launches, shifts, the bus's estimator and faults, timing, the
/// daemons, and where the log and plots are.
fn print_summary(s: &BenchSummary) {
    println!(
        "== ddct bench: {} on {} ({:.0} s): {}",
        s.scenario, s.iface, s.duration_s, s.description
    );
    println!();
    print_launches(s);
    println!();
    print_shifts(s);
    println!();
    print_bus_findings(s);
    println!();
    print_timing(&s.timing);
    print_daemons(s);
    println!();
    println!("log: {}", s.log.display());
    for p in &s.plots {
        println!("plot: {}", p.display());
    }
}

/// One line per launch of every run.
fn print_launches(s: &BenchSummary) {
    println!(
        "{:<10} {:>7} {:>9} {:>8} {:>8} {:>6} {:>10} {:>9}",
        "run", "pedal%", "lockup_s", "flare", "spike", "stall", "|Terr|300", "a_pk600"
    );
    for (name, m) in runs(s) {
        for l in &m.launches {
            println!(
                "{:<10} {:>7.0} {:>9} {:>8.0} {:>8} {:>6} {:>10.1} {:>9.2}",
                name,
                l.pedal_pct,
                f1(l.lockup_s),
                l.flare_rpm,
                f1(l.lockup_spike_mps2),
                l.stall,
                l.peak_torque_error_300ms_nm,
                l.peak_accel_600ms_mps2
            );
        }
    }
}

/// One line per shift of every run.
fn print_shifts(s: &BenchSummary) {
    println!(
        "{:<10} {:>7} {:>10} {:>10} {:>10}",
        "run", "shift", "duration", "min_accel", "completed"
    );
    for (name, m) in runs(s) {
        for x in &m.shifts {
            println!(
                "{:<10} {:>4}->{:<2} {:>10.2} {:>10.2} {:>10}",
                name, x.from, x.to, x.duration_s, x.min_accel_mps2, x.completed
            );
        }
    }
}

/// The bus's temperature estimator against SIM_Truth, and the fault codes on the bus while the
/// plant ran.
fn print_bus_findings(s: &BenchSummary) {
    let e = &s.bus.estimator;
    println!(
        "estimator vs SIM_Truth (bus): RMSE {:.2} / {:.2} °C, max {:.2} / {:.2} °C",
        e.rmse_c[0], e.rmse_c[1], e.max_abs_c[0], e.max_abs_c[1]
    );
    let faults: Vec<_> = run_events(&s.bus, s.plant_window)
        .iter()
        .filter(|x| x.fault != FaultCode::None)
        .map(|x| format!("{:.2}s {:?}", x.t_s, x.fault))
        .collect();
    println!(
        "fault codes on the bus: {}",
        if faults.is_empty() {
            "none".into()
        } else {
            faults.join(", ")
        }
    );
}

/// The bus timing table: the TCU's reaction, the bare echo's, the periods' jitter.
fn print_timing(t: &Timing) {
    println!(
        "{:<44} {:>6} {:>9} {:>9} {:>9}",
        "timing (recorder receive timestamps)", "n", "p50_us", "p99_us", "max_us"
    );
    let line = |name: &str, x: &Spread| {
        println!(
            "{:<44} {:>6} {:>9.0} {:>9.0} {:>9.0}",
            name, x.n, x.p50_us, x.p99_us, x.max_us
        )
    };
    line("DCT_Sensors -> TCU_ClutchCmd (TCU daemon)", &t.tcu_latency);
    if let Some(e) = &t.echo_latency {
        line("bare frame echo, same bus", e);
    }
    line("TCU_ClutchCmd |interval - 10 ms|", &t.clutch_cmd_jitter);
    line("DCT_Sensors |interval - 10 ms| (plant)", &t.sensors_jitter);
}

/// What the daemons reported (a live run) and how fast the lockstep simulation ran.
fn print_daemons(s: &BenchSummary) {
    if let Some(tc) = &s.tcu {
        println!(
            "TCU daemon: {} computations ({} sync, {} fallback), overruns {}, deadline misses {}, compute p99 {} us",
            tc.computations,
            tc.sync_computations,
            tc.fallback_computations,
            tc.overruns,
            tc.deadline_misses,
            tc.compute_p99_us.map_or("-".into(), |v| format!("{v:.0}"))
        );
    }
    if let Some(p) = &s.plant {
        match &p.lockstep {
            Some(_) => println!(
                "plant daemon: {} cycles in lockstep with the TCU, {} without its answer in time, wall {:.2} s for {:.2} s simulated",
                p.cycles, p.lockstep_timeouts, p.wall_time_s, p.sim_time_s
            ),
            None => println!(
                "plant daemon: {} cycles, overruns {}, deadline misses {}",
                p.cycles, p.overruns, p.deadline_misses
            ),
        }
    }
    if let Some(w) = s.sim_wall_s {
        println!(
            "lockstep simulation of the same scenario: {:.3} s wall for {:.0} s simulated ({:.0}x real time)",
            w,
            s.duration_s,
            s.duration_s / w.max(1e-9)
        );
    }
}

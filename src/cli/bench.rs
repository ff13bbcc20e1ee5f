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
use ddct::bench::analyse::{analyse, f2, html_report, BenchSummary, Recorded};
use ddct::bench::{bench_run, echo_run, BenchPacing, Net, Timing};
use ddct::can::candump::LogWriter;
use ddct::can::messages::FaultCode;
use ddct::can::{CanFrame, InProcessBus};
use ddct::daemon::os::set_realtime_priority;
use ddct::sim::buslog::{Spread, TimeAxis};
use ddct::sim::verdict;
use ddct::sim::SimScenario;
use ddct::tcu::TcuConfig;
use std::io::{BufReader, BufWriter};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

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
        Some(p) => {
            let f = std::fs::File::open(p).with_context(|| format!("opening {}", p.display()))?;
            Recorded::from_log(BufReader::new(f), p.clone(), |e| {
                eprintln!("{}: {e}", p.display())
            })
        }
        None => record(&a, &sc, &cfg)?,
    };
    let analysis = analyse(&out, &sc, &cfg, recorded, a.time.into());
    for (path, text) in &analysis.files {
        std::fs::write(path, text)?;
    }
    report(&a, &analysis.summary)
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
    std::fs::write(&html, html_page(summary)?)
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

/// The run as a self-contained HTML page, with the figures the analysis wrote.
fn html_page(s: &BenchSummary) -> anyhow::Result<String> {
    let mut figures = Vec::new();
    for p in &s.plots {
        let svg = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
        figures.push((
            p.file_name()
                .map_or(String::new(), |n| n.to_string_lossy().into()),
            svg,
        ));
    }
    Ok(html_report(s, &figures))
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
    for (name, m) in s.runs() {
        for l in &m.launches {
            println!(
                "{:<10} {:>7.0} {:>9} {:>8.0} {:>8} {:>6} {:>10.1} {:>9.2}",
                name,
                l.pedal_pct,
                f2(l.lockup_s),
                l.flare_rpm,
                f2(l.lockup_spike_mps2),
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
    for (name, m) in s.runs() {
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
    let faults: Vec<_> = s
        .run_events()
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

//! `ddct sim`: plant and TCU cores in lockstep, in simulated time (issue 6).

use anyhow::Context;
use clap::Args;
use ddct::sim::metrics::{self, Metrics};
use ddct::sim::verdict::{self, Check};
use ddct::sim::{self, plots, SimOptions, SimScenario};
use serde::Serialize;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

#[derive(Debug, Args)]
pub struct SimArgs {
    /// Scenario file(s) (config/scenarios/*.toml); repeatable, run in parallel (`--jobs`), reported
    /// in the order given.
    #[arg(long, required = true)]
    scenario: Vec<PathBuf>,
    /// Scenarios run at once (default: the machine's cores).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=256))]
    jobs: Option<u16>,
    /// TCU calibration (its `params` names the physical parameter file; default: the built-in
    /// config/tcu.toml with config/params.toml, so no working directory is needed).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Print the summary with every metric as JSON instead of tables.
    #[arg(long)]
    json: bool,
    /// Write per scenario an SVG figure (<name>.svg) and the rows as CSV (<name>.csv) here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write the verdicts (each scenario's `[limits]` checks) as JUnit XML to this file.
    #[arg(long)]
    junit: Option<PathBuf>,
}

/// One scenario's result.
#[derive(Debug, Serialize)]
pub struct ScenarioSummary {
    pub scenario: String,
    pub description: String,
    pub temperature_compensation: bool,
    pub slip_compensation: bool,
    pub simulated_s: f64,
    pub wall_s: f64,
    /// Simulated time over wall time.
    pub realtime_ratio: f64,
    pub tcu_steps: u64,
    pub frames: u64,
    /// The process's peak resident memory after this scenario (MiB; Linux, else absent; with
    /// several scenarios at once, the peak of the process so far).
    pub peak_rss_mib: Option<f64>,
    pub plot: Option<PathBuf>,
    pub csv: Option<PathBuf>,
    pub metrics: Metrics,
    /// The checks of the scenario's `[limits]` (docs: `ddct::sim::verdict`).
    pub verdict: Vec<Check>,
}

pub fn run(args: SimArgs) -> anyhow::Result<ExitCode> {
    let cfg = super::args::tcu_config(args.config.as_deref())?;
    if let Some(dir) = &args.out {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    // Every scenario loaded (and its errors reported) before any runs.
    let scenarios = args
        .scenario
        .iter()
        .map(|p| SimScenario::load(p))
        .collect::<Result<Vec<_>, _>>()?;
    let jobs = args
        .jobs
        .map(usize::from)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .min(scenarios.len())
        .max(1);
    let pb = super::spinner(format!(
        "{} scenario(s), {} s simulated, on {jobs} thread(s)",
        scenarios.len(),
        scenarios.iter().map(|s| s.duration_s).sum::<f64>()
    ));
    let out = ddct::par::map(jobs, &scenarios, |_, sc| {
        run_one(sc, &cfg, args.out.as_deref())
    })
    .into_iter()
    .collect::<anyhow::Result<Vec<_>>>()?;
    pb.finish_and_clear();
    if args.json {
        println!("{}", serde_json::to_string_pretty(&out)?);
    }
    let runs: Vec<(String, Vec<Check>)> = out
        .iter()
        .map(|s| (s.scenario.clone(), s.verdict.clone()))
        .collect();
    if !args.json {
        print_tables(&out);
        println!();
        print!("{}", verdict::table(&runs));
    }
    if let Some(path) = &args.junit {
        std::fs::write(path, verdict::junit("ddct sim", &runs))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let failed: Vec<&str> = runs
        .iter()
        .filter(|(_, c)| !verdict::passed(c))
        .map(|(n, _)| n.as_str())
        .collect();
    if failed.is_empty() {
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!("FAIL: {}", failed.join(", "));
        Ok(ExitCode::FAILURE)
    }
}

/// One scenario: the lockstep run, its metrics and verdict, the figure and CSV under `dir`.
fn run_one(
    sc: &SimScenario,
    cfg: &ddct::tcu::TcuConfig,
    dir: Option<&std::path::Path>,
) -> anyhow::Result<ScenarioSummary> {
    let t0 = Instant::now();
    // The rows only for the figure and the CSV: without them memory stays flat in the length
    // of the scenario (the metrics are computed as the rows come).
    let opts = SimOptions {
        drop_frames: true,
        drop_rows: dir.is_none(),
        ..SimOptions::default()
    };
    let run = sim::run_scenario(sc, cfg, &opts);
    let wall = t0.elapsed().as_secs_f64();
    let m = run.metrics;
    let (mut plot, mut csv) = (None, None);
    if let Some(dir) = dir {
        let p = dir.join(format!("{}.svg", run.scenario));
        let title = format!("{}: {}", run.scenario, run.description);
        std::fs::write(&p, plots::run_figure(&title, &run.rows))
            .with_context(|| format!("writing {}", p.display()))?;
        plot = Some(p);
        let c = dir.join(format!("{}.csv", run.scenario));
        std::fs::write(&c, sim::rows_csv(&run.rows))
            .with_context(|| format!("writing {}", c.display()))?;
        csv = Some(c);
    }
    Ok(ScenarioSummary {
        scenario: run.scenario.clone(),
        description: run.description.clone(),
        temperature_compensation: run.config.temperature_compensation,
        slip_compensation: run.config.slip_compensation,
        simulated_s: run.duration_s,
        wall_s: wall,
        realtime_ratio: run.duration_s / wall.max(1e-9),
        tcu_steps: run.tcu_steps,
        frames: run.frame_count,
        peak_rss_mib: super::peak_rss_mib(),
        plot,
        csv,
        verdict: verdict::judge(sc.limits.as_ref(), &m, None),
        metrics: m,
    })
}

fn opt(v: Option<f64>, prec: usize) -> String {
    v.map_or("-".into(), |x| format!("{x:.prec$}"))
}

/// The text tables of a run: launches, torque error by slip, shifts, the runs themselves, and
/// where the plots went.
fn print_tables(out: &[ScenarioSummary]) {
    print_launches(out);
    print_torque_error_by_slip(out);
    print_shifts(out);
    print_runs(out);
    for s in out {
        if let Some(p) = &s.plot {
            println!("plot: {}", p.display());
        }
    }
}

/// One line per launch: its pedal, the compensations on, and its quality metrics.
fn print_launches(out: &[ScenarioSummary]) {
    println!(
        "{:<22} {:>6} {:>5} {:>5} {:>8} {:>8} {:>7} {:>7} {:>8} {:>8} {:>8}",
        "scenario",
        "pedal%",
        "temp",
        "slip",
        "lockup_s",
        "flare",
        "spike",
        "stall",
        "|Terr|300",
        "a_pk600",
        "E_kJ"
    );
    for s in out {
        for l in &s.metrics.launches {
            println!(
                "{:<22} {:>6.0} {:>5} {:>5} {:>8} {:>8.0} {:>7} {:>7} {:>8.1} {:>8.2} {:>8.1}",
                s.scenario,
                l.pedal_pct,
                if s.temperature_compensation {
                    "on"
                } else {
                    "off"
                },
                if s.slip_compensation { "on" } else { "off" },
                opt(l.lockup_s, 2),
                l.flare_rpm,
                opt(l.lockup_spike_mps2, 2),
                l.stall,
                l.peak_torque_error_300ms_nm,
                l.peak_accel_600ms_mps2,
                l.friction_energy_kj
            );
        }
    }
}

/// Fig. 14: mean T_ref − T_actual of the launch clutch per slip bin (rad/s), as % of T_ref, one
/// line per launch (nothing without a launch).
fn print_torque_error_by_slip(out: &[ScenarioSummary]) {
    if out.iter().any(|s| !s.metrics.launches.is_empty()) {
        println!();
        let edges = metrics::SLIP_BINS_RADPS;
        let mut head = format!("{:<22} {:>6}", "T_ref-T_act (% T_ref)", "pedal%");
        for w in edges.windows(2) {
            head.push_str(&format!(" {:>9}", format!("{}-{}", w[1], w[0])));
        }
        println!("{head}   (slip bins, rad/s)");
        for s in out {
            for l in &s.metrics.launches {
                let mut line = format!("{:<22} {:>6.0}", s.scenario, l.pedal_pct);
                for b in &l.torque_error_by_slip {
                    line.push_str(&format!(
                        " {:>9}",
                        b.mean_rel_error
                            .map_or("-".into(), |e| format!("{:.1}", 100.0 * e))
                    ));
                }
                println!("{line}");
            }
        }
    }
}

/// One line per gear shift of every scenario (nothing without a shift).
fn print_shifts(out: &[ScenarioSummary]) {
    let shifts: Vec<_> = out
        .iter()
        .flat_map(|s| s.metrics.shifts.iter().map(move |x| (s, x)))
        .collect();
    if !shifts.is_empty() {
        println!();
        println!(
            "{:<22} {:>8} {:>6} {:>10} {:>10} {:>12} {:>10}",
            "scenario", "t_s", "shift", "duration_s", "completed", "min_accel", "max_rpm"
        );
        for (s, x) in shifts {
            println!(
                "{:<22} {:>8.2} {:>3}->{:<2} {:>10.2} {:>10} {:>12.2} {:>10.0}",
                s.scenario,
                x.t_start_s,
                x.from,
                x.to,
                x.duration_s,
                x.completed,
                x.min_accel_mps2,
                x.max_engine_rpm
            );
        }
    }
}

/// One line per scenario: simulated and wall time, the temperature estimator's errors and the
/// faults the TCU reported.
fn print_runs(out: &[ScenarioSummary]) {
    println!();
    println!(
        "{:<22} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>10}",
        "scenario", "sim_s", "wall_s", "x_realtm", "est_rmse", "est_max", "true_max", "faults"
    );
    for s in out {
        let e = &s.metrics.estimator;
        let faults = s
            .metrics
            .status_events
            .iter()
            .filter(|e| e.fault != ddct::can::messages::FaultCode::None)
            .count();
        println!(
            "{:<22} {:>9.1} {:>9.3} {:>9.0} {:>9.2} {:>9.2} {:>9.1} {:>10}",
            s.scenario,
            s.simulated_s,
            s.wall_s,
            s.realtime_ratio,
            e.rmse_c[0].max(e.rmse_c[1]),
            e.max_abs_c[0].max(e.max_abs_c[1]),
            e.max_true_c[0].max(e.max_true_c[1]),
            faults
        );
    }
}

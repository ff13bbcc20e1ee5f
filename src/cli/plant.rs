//! `ddct plant`: the plant daemon (issue 5) — the simulated dual-clutch transmission on a bus.

use super::args::{open_can, Iface, Speed};
use super::{announce_ready, runtime, shutdown_signal};
use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use ddct::can::{EndpointConfig, InProcessBus, ManualClock};
use ddct::daemon::plant::{run as run_plant, Lockstep, Pacing, PlantDaemonConfig, PlantReport};
use ddct::daemon::wall_clock;
use ddct::model::effects::EffectSet;
use ddct::plant::{Mode, PlantConfig, RigProfile, Scenario};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    Vehicle,
    Rig,
}

#[derive(Debug, Args)]
pub struct PlantArgs {
    /// CAN interface (e.g. vcan0), or `sim` for the in-process bus.
    #[arg(long, required_unless_present = "list_effects")]
    iface: Option<Iface>,
    /// Print the reality-effect library (identifiers, subsystems, equations, parameters with
    /// units, plausible ranges and bounds) as a Markdown table, or JSON with --json, and exit.
    #[arg(long)]
    list_effects: bool,
    /// Plant configuration (default: the built-in config/plant.toml).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Operating mode (default: the config's).
    #[arg(long, value_enum)]
    mode: Option<ModeArg>,
    /// Vehicle mode: the driver (pedal, brake, lever, grade over time), from a driver scenario
    /// (config/scenarios/driver_*.toml) or a `ddct sim` scenario (which also brings its plant
    /// configuration: initial state, effects, faults); the plant then sends DRV_Pedal. Without it
    /// the driver is DRV_Pedal on the bus (on `--iface sim` the built-in
    /// config/scenarios/driver_launch.toml).
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Rig mode: built-in x_to profile (config/rig/*.toml) instead of TCU_ClutchCmd from the bus.
    #[arg(long)]
    rig_profile: Option<PathBuf>,
    /// Rig mode: dyno speed holding the input side (rpm, 0 ..= 6000); overrides the config and
    /// the profile.
    #[arg(long, value_parser = super::args::number_in(0.0, 6000.0, "rpm"))]
    input_speed: Option<f64>,
    /// Reality effects file ([effects.<id>] tables); replaces the config's effects.
    #[arg(long)]
    effects: Option<PathBuf>,
    /// Faults file ([[faults]] tables); added to the config's faults.
    #[arg(long)]
    faults: Option<PathBuf>,
    /// Record every frame sent and received into this candump -l log.
    #[arg(long)]
    log: Option<PathBuf>,
    /// Stop after this many seconds of simulated time (default: until SIGINT/SIGTERM; with a
    /// built-in rig profile or on `--iface sim`, the profile's or scenario's length).
    #[arg(long, value_parser = super::args::seconds)]
    duration: Option<Duration>,
    /// Run simulated time this many times faster than wall time (`max`: as fast as possible,
    /// only on `--iface sim`, the default there).
    #[arg(long)]
    speed: Option<Speed>,
    /// Lockstep with a controller: after each cycle wait for its answers (a frame of each
    /// MESSAGE, comma-separated; default TCU_ClutchCmd; e.g. TCU_ClutchCmd,DRV_Pedal with a
    /// scripted driver) before simulating the next, never faster than --speed; makes a bus
    /// experiment independent of the host's scheduling.
    #[arg(long, value_name = "MESSAGE[,MESSAGE]", num_args = 0..=1, default_missing_value = "TCU_ClutchCmd")]
    lockstep: Option<String>,
    /// Lockstep: seconds of wall time to wait for an answer before simulating on without it.
    #[arg(long, default_value = "1", value_parser = super::args::seconds)]
    lockstep_timeout: Duration,
    /// Sensor-noise seed (default: the config's).
    #[arg(long)]
    seed: Option<u64>,
    /// Once the daemon's socket is open and its signal handlers installed, write its pid to this
    /// file (a CAN interface only; a bench script may wait for it).
    #[arg(long)]
    ready_file: Option<PathBuf>,
    /// Print the exit report as JSON on stdout.
    #[arg(long)]
    json: bool,
}

fn build_config(a: &PlantArgs) -> anyhow::Result<PlantConfig> {
    // A sim scenario (`ddct sim`'s format) carries its plant configuration and driver.
    let sim_scenario = match &a.scenario {
        Some(p) if ddct::sim::scenario::is_sim_scenario(p)? => {
            if a.config.is_some() {
                bail!(
                    "--scenario {}: a sim scenario carries its plant configuration (its `plant` \
                     key names the base); drop --config",
                    p.display()
                );
            }
            Some(ddct::sim::SimScenario::load(p)?)
        }
        _ => None,
    };
    let mut cfg = match (&sim_scenario, &a.config) {
        (Some(sc), _) => sc.plant.clone(),
        (None, Some(p)) => PlantConfig::load(p)?,
        (None, None) => PlantConfig::default(),
    };
    if let Some(m) = a.mode {
        cfg.mode = match m {
            ModeArg::Vehicle => Mode::Vehicle,
            ModeArg::Rig => Mode::Rig,
        };
    }
    if let Some(s) = a.seed {
        cfg.seed = s;
    }
    if let Some(p) = &a.scenario {
        if cfg.mode != Mode::Vehicle {
            bail!("--scenario is for vehicle mode (the rig takes --rig-profile)");
        }
        if sim_scenario.is_none() {
            cfg.scenario = Some(Scenario::load(p)?);
        }
    }
    if let Some(p) = &a.rig_profile {
        if cfg.mode != Mode::Rig {
            bail!("--rig-profile is for rig mode (add --mode rig)");
        }
        cfg.rig_profile = Some(RigProfile::load(p)?);
    }
    if let Some(rpm) = a.input_speed {
        if cfg.mode != Mode::Rig {
            bail!("--input-speed is for rig mode (add --mode rig)");
        }
        cfg.rig.input_speed_rpm = rpm;
        if let Some(p) = cfg.rig_profile.as_mut() {
            p.input_speed_rpm = rpm;
        }
    }
    if a.iface == Some(Iface::Sim) && cfg.mode == Mode::Vehicle && cfg.scenario.is_none() {
        cfg.scenario = Some(Scenario::builtin());
    }
    if let Some(p) = &a.effects {
        cfg.effects = EffectSet::load(p).with_context(|| format!("--effects {}", p.display()))?;
    }
    if let Some(p) = &a.faults {
        let more = cfg.load_faults(p)?;
        cfg.faults.extend(more);
    }
    cfg.check_faults()?;
    Ok(cfg)
}

fn list_effects(json: bool) -> anyhow::Result<ExitCode> {
    use ddct::model::effects::EffectId;
    if json {
        let v: Vec<_> = EffectId::ALL
            .iter()
            .map(|id| {
                let s = id.spec();
                serde_json::json!({
                    "id": id.as_str(),
                    "subsystem": s.subsystem.as_str(),
                    "in_library": s.in_library,
                    "equation": s.equation,
                    "description": s.description,
                    "params": s.params.iter().map(|p| serde_json::json!({
                        "name": p.name, "unit": p.unit, "nominal": p.nominal, "typical": p.typical,
                        "plausible": [p.plausible.0, p.plausible.1], "min_effect": p.min_effect,
                        "bounds": [p.bounds.0, p.bounds.1], "doc": p.doc,
                    })).collect::<Vec<_>>(),
                })
            })
            .collect();
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(ExitCode::SUCCESS);
    }
    println!(
        "| id | subsystem | library | parameter | unit | nominal | typical | plausible | bounds |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for id in EffectId::ALL {
        let s = id.spec();
        for (i, p) in s.params.iter().enumerate() {
            let (idc, sub, lib) = if i == 0 {
                (
                    format!("`{id}`"),
                    s.subsystem.as_str().to_string(),
                    if s.in_library { "yes" } else { "no (outside)" }.to_string(),
                )
            } else {
                (String::new(), String::new(), String::new())
            };
            let plaus = if p.min_effect > 0.0 {
                format!(
                    "{} … {}, except {} … {}",
                    p.plausible.0,
                    p.plausible.1,
                    p.nominal - p.min_effect,
                    p.nominal + p.min_effect
                )
            } else {
                format!("{} … {}", p.plausible.0, p.plausible.1)
            };
            println!(
                "| {idc} | {sub} | {lib} | `{}` | {} | {} | {} | {plaus} | {} … {} |",
                p.name, p.unit, p.nominal, p.typical, p.bounds.0, p.bounds.1
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

pub fn run(a: PlantArgs) -> anyhow::Result<ExitCode> {
    if a.list_effects {
        return list_effects(a.json);
    }
    let cfg = build_config(&a)?;
    let Some(iface) = a.iface.clone() else {
        bail!("--iface is required");
    };
    let sim = iface.is_sim();
    let speed = pacing_speed(&a, sim)?;
    let duration = run_duration(&a, &cfg, sim, speed)?;
    let lockstep = parse_lockstep(&a, sim, speed)?;
    let rt = runtime()?;
    let report: PlantReport = rt.block_on(async {
        if sim {
            run_on_sim(&a, cfg, speed, duration, lockstep).await
        } else {
            run_on_can(&a, &iface, cfg, speed, duration, lockstep).await
        }
    })?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    }
    eprint!("{}", report.summary());
    Ok(ExitCode::SUCCESS)
}

/// The real-time speed factor (`None`: as fast as possible, on the in-process bus only; a real
/// bus runs at 1 unless told otherwise).
fn pacing_speed(a: &PlantArgs, sim: bool) -> anyhow::Result<Option<f64>> {
    Ok(match a.speed {
        None if sim => None,
        None => Some(1.0),
        Some(Speed::Max) if sim => None,
        Some(Speed::Max) => {
            bail!("--speed max needs --iface sim (a real bus runs in scaled real time)")
        }
        Some(Speed::Factor(k)) => Some(k),
    })
}

/// How much simulated time to run: `--duration`, else a rig profile's length, else (as fast
/// as possible on the in-process bus, where it is required) the scenario's.
fn run_duration(
    a: &PlantArgs,
    cfg: &PlantConfig,
    sim: bool,
    speed: Option<f64>,
) -> anyhow::Result<Option<Duration>> {
    let mut duration = a.duration;
    if duration.is_none() {
        if let (Mode::Rig, Some(p)) = (cfg.mode, &cfg.rig_profile) {
            duration = Some(Duration::from_secs_f64(p.duration_s()));
        } else if sim && speed.is_none() {
            match (&cfg.mode, &cfg.scenario) {
                (Mode::Vehicle, Some(s)) => duration = Some(Duration::from_secs_f64(s.duration_s)),
                _ => bail!("--iface sim at --speed max needs --duration (or a rig profile)"),
            }
        }
    }
    Ok(duration)
}

/// `--lockstep`: the messages named (each one of the contract), in real-time pacing only.
fn parse_lockstep(
    a: &PlantArgs,
    sim: bool,
    speed: Option<f64>,
) -> anyhow::Result<Option<Lockstep>> {
    let Some(names) = &a.lockstep else {
        return Ok(None);
    };
    let mut messages = Vec::new();
    for name in names.split(',').map(str::trim) {
        let def = ddct::can::messages::message_by_name(name).with_context(|| {
            format!("--lockstep {names}: {name:?} is not a message of the contract")
        })?;
        messages.push(def.id);
    }
    if sim && speed.is_none() {
        bail!("--lockstep needs real-time pacing (--speed K)");
    }
    Ok(Some(Lockstep {
        messages,
        timeout: a.lockstep_timeout,
    }))
}

/// The plant alone on the in-process bus: in scaled real time, or as fast as possible on the
/// bus's own clock (`speed` `None`).
async fn run_on_sim(
    a: &PlantArgs,
    cfg: PlantConfig,
    speed: Option<f64>,
    duration: Option<Duration>,
    lockstep: Option<Lockstep>,
) -> anyhow::Result<PlantReport> {
    let (bus, pacing) = match speed {
        None => {
            let clock = Arc::new(ManualClock::new(wall_clock()));
            let bus = InProcessBus::with_clock("sim", clock.clone());
            (bus, Pacing::Virtual { clock: Some(clock) })
        }
        Some(k) => (InProcessBus::new("sim"), Pacing::RealTime { speed: k }),
    };
    let ep = bus.endpoint(EndpointConfig::default());
    let c = PlantDaemonConfig {
        plant: cfg,
        pacing,
        duration,
        log: a.log.clone(),
        lockstep,
    };
    let pb = super::spinner("the plant on the in-process bus");
    let r = run_plant(ep, shutdown_signal(), c).await;
    pb.finish_and_clear();
    Ok(r?)
}

/// The plant on a CAN interface, in real time (at `speed`, 1 by default), until a signal or
/// its duration.
async fn run_on_can(
    a: &PlantArgs,
    iface: &Iface,
    cfg: PlantConfig,
    speed: Option<f64>,
    duration: Option<Duration>,
    lockstep: Option<Lockstep>,
) -> anyhow::Result<PlantReport> {
    let bus = open_can(&iface.to_string())?;
    let c = PlantDaemonConfig {
        plant: cfg,
        pacing: Pacing::RealTime {
            speed: speed.unwrap_or(1.0),
        },
        duration,
        log: a.log.clone(),
        lockstep,
    };
    let stop = shutdown_signal();
    announce_ready(a.ready_file.as_deref())?;
    Ok(run_plant(bus, stop, c).await?)
}

//! `ddct plant`: the plant daemon (issue 5) — the simulated dual-clutch transmission on a bus.

use super::{runtime, shutdown_signal};
use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use ddct::can::socketcan::SocketCanBus;
use ddct::can::{EndpointConfig, InProcessBus, ManualClock};
use ddct::daemon::plant::{run as run_plant, Pacing, PlantDaemonConfig, PlantReport};
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
    #[arg(long)]
    iface: String,
    /// Plant configuration (default: the built-in config/plant.toml).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Operating mode (default: the config's).
    #[arg(long, value_enum)]
    mode: Option<ModeArg>,
    /// Vehicle mode: built-in driver scenario (pedal, brake, lever, grade over time); the plant
    /// then sends DRV_Pedal. Without it the driver is DRV_Pedal on the bus (on `--iface sim` the
    /// built-in config/scenarios/driver_launch.toml).
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Rig mode: built-in x_to profile (config/rig/*.toml) instead of TCU_ClutchCmd from the bus.
    #[arg(long)]
    rig_profile: Option<PathBuf>,
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
    #[arg(long)]
    duration: Option<f64>,
    /// Run simulated time this many times faster than wall time (`max`: as fast as possible,
    /// only on `--iface sim`, the default there).
    #[arg(long)]
    speed: Option<String>,
    /// Sensor-noise seed (default: the config's).
    #[arg(long)]
    seed: Option<u64>,
    /// Print the exit report as JSON on stdout.
    #[arg(long)]
    json: bool,
}

fn build_config(a: &PlantArgs) -> anyhow::Result<PlantConfig> {
    let mut cfg = match &a.config {
        Some(p) => PlantConfig::load(p)?,
        None => PlantConfig::default(),
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
        cfg.scenario = Some(Scenario::load(p)?);
    }
    if let Some(p) = &a.rig_profile {
        if cfg.mode != Mode::Rig {
            bail!("--rig-profile is for rig mode (add --mode rig)");
        }
        cfg.rig_profile = Some(RigProfile::load(p)?);
    }
    if a.iface == "sim" && cfg.mode == Mode::Vehicle && cfg.scenario.is_none() {
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

pub fn run(a: PlantArgs) -> anyhow::Result<ExitCode> {
    let cfg = build_config(&a)?;
    let sim = a.iface == "sim";
    let speed: Option<f64> = match a.speed.as_deref() {
        None if sim => None,
        None => Some(1.0),
        Some("max") if sim => None,
        Some("max") => bail!("--speed max needs --iface sim (a real bus runs in scaled real time)"),
        Some(s) => {
            let k: f64 = s
                .parse()
                .ok()
                .filter(|k: &f64| k.is_finite() && *k > 0.0 && *k <= 1000.0)
                .with_context(|| format!("--speed {s}: must be a number in (0, 1000] or `max`"))?;
            Some(k)
        }
    };
    let mut duration = match a.duration {
        Some(d) if d.is_finite() && d > 0.0 => Some(Duration::from_secs_f64(d)),
        Some(d) => bail!("--duration {d}: must be a positive number of seconds"),
        None => None,
    };
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
    let rt = runtime()?;
    let report: PlantReport = rt.block_on(async {
        if sim {
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
            };
            anyhow::Ok(run_plant(ep, shutdown_signal(), c).await?)
        } else {
            let bus = SocketCanBus::open(&a.iface, false)
                .with_context(|| format!("opening CAN interface {}", a.iface))?;
            let c = PlantDaemonConfig {
                plant: cfg,
                pacing: Pacing::RealTime {
                    speed: speed.unwrap_or(1.0),
                },
                duration,
                log: a.log.clone(),
            };
            anyhow::Ok(run_plant(bus, shutdown_signal(), c).await?)
        }
    })?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    }
    eprint!("{}", report.summary());
    Ok(ExitCode::SUCCESS)
}

//! `ddct tcu`: the TCU daemon (issue 6).

use super::args::{nice_value, open_can, rt_priority, Iface};
use super::{announce_ready, runtime, shutdown_signal};
use anyhow::{bail, Context};
use clap::{Args, ValueEnum};
use ddct::can::{EndpointConfig, InProcessBus};
use ddct::daemon::os::{set_nice, set_realtime_priority};
use ddct::daemon::plant::{run as run_plant, Pacing, PlantDaemonConfig};
use ddct::daemon::tcu::{
    run as run_tcu, DiagDaemonConfig, TcuClock, TcuDaemonConfig, TcuReport, INPUT_IDS,
};
use ddct::diag::isotp::IsoTpConfig;
use ddct::diag::stack::{DiagConfig, REQUEST_IDS};
use ddct::plant::{PlantConfig, Scenario};
use ddct::tcu::TcuConfig;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

#[derive(Debug, Args)]
pub struct TcuArgs {
    /// CAN interface (e.g. vcan0), or `sim`: an in-process bus with the plant daemon (built-in
    /// driver) alongside in the same process, in real time.
    #[arg(long)]
    iface: Iface,
    /// TCU calibration (its `params` names the physical parameter file; default: the built-in
    /// config/tcu.toml with config/params.toml, so no working directory is needed).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Record every frame sent and received into this candump -l log.
    #[arg(long)]
    log: Option<PathBuf>,
    /// Stop after this many seconds (default: until SIGINT/SIGTERM; on `sim` the driver
    /// scenario's length).
    #[arg(long, value_parser = super::args::seconds)]
    duration: Option<Duration>,
    /// `--iface sim` only: the plant's driver scenario (default: the built-in
    /// config/scenarios/driver_launch.toml).
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Run under the real-time FIFO scheduler at this priority (1..=99; needs root).
    #[arg(long, value_parser = rt_priority)]
    rt_priority: Option<i32>,
    /// Run at this nice value (-20..=19; below 0 needs root): more of the CPU under the normal
    /// scheduler, which keeps serving the kernel and the other bench processes (unlike
    /// `--rt-priority`, which can starve them on a one-CPU machine).
    #[arg(long, value_parser = nice_value, allow_hyphen_values = true, conflicts_with = "rt_priority")]
    nice: Option<i32>,
    /// The TCU's time: `monotonic` (a real-time bench; the daemon's own stalls are not counted
    /// against the senders) or `bus` (a lockstep bench, the plant run with `--lockstep`: the
    /// plant's simulated time, one cycle per DCT_Sensors frame, so every timeout is exact in
    /// cycles whatever the host's load; not with `--iface sim`).
    #[arg(long, value_enum, default_value_t = ClockArg::Monotonic)]
    clock: ClockArg,
    /// Once the daemon listens (socket open with its filters, signal handlers installed), write
    /// its pid to this file: a bench script waits for it before starting the plant, so no cycle
    /// goes out before the TCU can hear it.
    #[arg(long)]
    ready_file: Option<PathBuf>,
    /// Print the exit report as JSON on stdout.
    #[arg(long)]
    json: bool,
    /// No diagnostics on the bus: no UDS server, no XCP slave, no fault memory (the TCU then
    /// ignores the diagnostic ids).
    #[arg(long, conflicts_with_all = ["fault_memory", "serial"])]
    no_diag: bool,
    /// The fault memory file (DTCs with status, snapshot and extended data): loaded at the
    /// start, written atomically when it changes; a corrupt file is set aside as
    /// `PATH.corrupt` and reported. Default: the fault memory lives only as long as the daemon.
    #[arg(long)]
    fault_memory: Option<PathBuf>,
    /// The ECU serial number read by UDS (DID 0xF18C), at most 16 ASCII characters.
    #[arg(long, value_parser = serial_number, default_value = "DDCT-0001")]
    serial: String,
    /// ISO-TP: the block size the TCU asks of a tester sending a long request (0: no limit).
    #[arg(long, default_value_t = 8)]
    isotp_block_size: u8,
    /// ISO-TP: the separation time the TCU asks of a tester between consecutive frames
    /// (0..=127 ms).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=127))]
    isotp_stmin: u8,
}

/// `--serial`: printable ASCII, 1 to 16 characters.
fn serial_number(s: &str) -> Result<String, String> {
    if s.is_empty() || s.len() > 16 || !s.bytes().all(|b| b.is_ascii_graphic() || b == b' ') {
        return Err(format!(
            "{s:?} is not a serial number: 1 to 16 printable ASCII characters"
        ));
    }
    Ok(s.to_string())
}

/// The diagnostic side of `a`, or none with `--no-diag`. The SecurityAccess seeds are drawn
/// from the wall clock's nanoseconds at the start.
fn diag_config(a: &TcuArgs) -> Option<DiagDaemonConfig> {
    let seed = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(1, |d| d.as_nanos() as u64);
    (!a.no_diag).then(|| DiagDaemonConfig {
        diag: DiagConfig {
            serial: a.serial.clone(),
            seed,
            isotp: IsoTpConfig {
                block_size: a.isotp_block_size,
                st_min: a.isotp_stmin,
                ..IsoTpConfig::default()
            },
        },
        fault_memory: a.fault_memory.clone(),
    })
}

/// `--clock` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ClockArg {
    Monotonic,
    Bus,
}

impl From<ClockArg> for TcuClock {
    fn from(c: ClockArg) -> Self {
        match c {
            ClockArg::Monotonic => TcuClock::Monotonic,
            ClockArg::Bus => TcuClock::Bus,
        }
    }
}

pub fn run(a: TcuArgs) -> anyhow::Result<ExitCode> {
    let cfg = super::args::tcu_config(a.config.as_deref())?;
    check_iface_options(&a)?;
    set_priorities(&a)?;
    let rt = runtime()?;
    let report: TcuReport = rt.block_on(async {
        if a.iface.is_sim() {
            run_with_plant(&a, cfg).await
        } else {
            run_on_can(&a, cfg).await
        }
    })?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    }
    eprint!("{}", report.summary());
    Ok(ExitCode::SUCCESS)
}

/// Refuses the options that do not fit the interface: `--clock bus` on the in-process bus,
/// `--scenario` on a real one.
fn check_iface_options(a: &TcuArgs) -> anyhow::Result<()> {
    if a.clock == ClockArg::Bus && a.iface.is_sim() {
        bail!("--clock bus is for a lockstep bench on a CAN interface (`--iface sim` runs in real time)");
    }
    if a.scenario.is_some() && !a.iface.is_sim() {
        bail!("--scenario is for --iface sim (on a real bus the driver is on the bus)");
    }
    Ok(())
}

/// The process's scheduling: `--rt-priority` and `--nice`, when given.
fn set_priorities(a: &TcuArgs) -> anyhow::Result<()> {
    if let Some(p) = a.rt_priority {
        set_realtime_priority(p).with_context(|| format!("--rt-priority {p}"))?;
    }
    if let Some(n) = a.nice {
        set_nice(n).with_context(|| format!("--nice {n}"))?;
    }
    Ok(())
}

/// `--iface sim`: the TCU with the plant (playing the scenario) on the in-process bus, in real
/// time, until the plant ends; the plant's summary goes to stderr.
async fn run_with_plant(a: &TcuArgs, cfg: TcuConfig) -> anyhow::Result<TcuReport> {
    let bus = InProcessBus::new("sim");
    let plant = PlantConfig {
        scenario: Some(match &a.scenario {
            Some(p) => Scenario::load(p)?,
            None => Scenario::builtin(),
        }),
        ..PlantConfig::default()
    };
    let d = a.duration.unwrap_or_else(|| {
        Duration::from_secs_f64(plant.scenario.as_ref().map_or(10.0, |s| s.duration_s))
    });
    let stop = Arc::new(tokio::sync::Notify::new());
    let stop2 = stop.clone();
    let plant_cfg = PlantDaemonConfig {
        plant,
        pacing: Pacing::RealTime { speed: 1.0 },
        duration: Some(d),
        log: None,
        lockstep: None,
    };
    let tcu_cfg = TcuDaemonConfig {
        tcu: cfg,
        duration: Some(d),
        log: a.log.clone(),
        clock: Default::default(),
        diag: diag_config(a),
    };
    let plant_ep = bus.endpoint(EndpointConfig::default());
    let tcu_ep = bus.endpoint(EndpointConfig::default());
    let (plant_stop, tcu_stop) = (shutdown_signal(), shutdown_signal());
    announce_ready(a.ready_file.as_deref())?;
    let (p, t) = tokio::join!(
        async {
            let r = run_plant(plant_ep, plant_stop, plant_cfg).await;
            stop2.notify_one();
            r
        },
        run_tcu(
            tcu_ep,
            async {
                tokio::select! {
                    _ = tcu_stop => {}
                    _ = stop.notified() => {}
                }
            },
            tcu_cfg
        )
    );
    let p = p?;
    eprint!("{}", p.summary());
    Ok(t?)
}

/// The TCU alone on a CAN interface (reading only its input messages) until a signal or
/// `--duration`.
async fn run_on_can(a: &TcuArgs, cfg: TcuConfig) -> anyhow::Result<TcuReport> {
    let bus = open_can(&a.iface.to_string())?;
    let diag = diag_config(a);
    let mut listen = INPUT_IDS.to_vec();
    if diag.is_some() {
        listen.extend(REQUEST_IDS);
    }
    bus.set_filter_ids(&listen)?;
    let c = TcuDaemonConfig {
        tcu: cfg,
        duration: a.duration,
        log: a.log.clone(),
        clock: a.clock.into(),
        diag,
    };
    let stop = shutdown_signal();
    announce_ready(a.ready_file.as_deref())?;
    Ok(run_tcu(bus, stop, c).await?)
}

//! The plant daemon loop: the pure [`Plant`] core on a [`Bus`], in real time or faster.
//!
//! - [`Pacing::RealTime`]: one plant cycle (10 ms of simulated time) per `10 ms / speed` of wall
//!   time, on absolute deadlines (`Periodic`, no drift); late wake-ups are counted as deadline
//!   misses, cycles whose work did not finish before the next deadline as overruns, and skipped
//!   cycles are integrated (the core catches up to the simulated time of the deadline) but their
//!   frames are sent late rather than dropped. Received frames are applied at their (scaled)
//!   receive time; frames a fault delays are sent at their due time. The bus is read at the
//!   deadlines (and before a delayed frame is sent, so the log stays in time order), up to
//!   [`DRAIN_BUDGET`] frames in one batch; when more were waiting (a flood), the rest every
//!   [`FLOOD_PACE`] until the queue is empty — never a wake-up per frame.
//! - Lockstep ([`PlantDaemonConfig::lockstep`], real-time pacing): after sending cycle n the
//!   plant waits for the answers (a frame of each lockstep message: the TCU's TCU_ClutchCmd, and
//!   on a bench with a scripted driver its DRV_Pedal) before it
//!   simulates cycle n+1, and never runs faster than `speed`. The run is then deterministic
//!   whatever the host's scheduling (a loaded CI machine, User-Mode Linux): the experiment gives
//!   the same frames over a real bus as in process. No deadlines, so no misses are counted; the
//!   cycles whose answer did not come within the timeout are.
//! - [`Pacing::Virtual`]: as fast as possible in simulated time (the in-process bus's
//!   `ManualClock`, if given, follows the simulated time), yielding to other tasks every cycle.
//!
//! Time mapping: simulated time = (monotonic time − start) · speed; a received frame's kernel
//! timestamp (wall clock) is placed on that base by its age at reading ([`TimeBase`]), so a step
//! of the system clock neither holds the TCU's commands back nor replays them early. The candump tap (`log`) records
//! every frame sent and received: at speed 1 with the real wall-clock time of sending (received
//! frames with their kernel timestamps); at any other speed on the simulated time axis (start +
//! simulated time: sent frames at their due time, received ones at their scaled arrival time), so
//! a log of a run at speed 10 has the time axis of the simulation, not ten-fold wall jitter. The loop ends when `shutdown`
//! resolves (SIGINT/SIGTERM in the CLI) or after `duration` of simulated time; the log is flushed
//! either way.

use super::clock::TimeBase;
use super::{
    sleep_until_precise, wall_clock, Link, LinkError, LoopStats, Periodic, DRAIN_BUDGET, FLOOD_PACE,
};
use crate::can::{Bus, BusError, ManualClock, Received};
use crate::model::effects::EffectSet;
use crate::plant::core::CYCLE;
use crate::plant::{OutFrame, Plant, PlantConfig, PlantStats};
use serde::Serialize;
use std::future::Future;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tokio::time::Instant;

/// Refused sends in a row that stop the daemon (about 1.4 s of plant frames at 7 per cycle).
const MAX_SEND_FAILURES: u64 = 1000;

/// How simulated time relates to wall time.
#[derive(Debug, Clone)]
pub enum Pacing {
    /// Simulated time runs `speed` times faster than wall time (1: real time).
    RealTime { speed: f64 },
    /// As fast as possible; `clock` (the in-process bus's) is set to start + simulated time.
    Virtual { clock: Option<Arc<ManualClock>> },
}

/// Daemon configuration.
#[derive(Debug, Clone)]
pub struct PlantDaemonConfig {
    pub plant: PlantConfig,
    pub pacing: Pacing,
    /// Stop after this much simulated time.
    pub duration: Option<Duration>,
    /// candump -l tap of every frame sent and received.
    pub log: Option<PathBuf>,
    /// Lockstep with a controller (real-time pacing only): after sending cycle n the plant waits
    /// for a frame of this message before it simulates cycle n+1 (never faster than `speed`).
    pub lockstep: Option<Lockstep>,
}

/// Lockstep settings (see [`PlantDaemonConfig::lockstep`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Lockstep {
    /// The messages that answer a cycle (e.g. TCU_ClutchCmd): a frame of each is waited for.
    pub messages: Vec<u16>,
    /// Wall time to wait for the answer before simulating on without it.
    pub timeout: Duration,
}

/// A message's DBC name (its id in hex if the DBC has none).
fn message_name(id: u16) -> String {
    crate::can::messages::message_def(u32::from(id))
        .map_or(format!("{id:#x}"), |d| d.name.to_string())
}

/// Errors that stop the daemon.
#[derive(Debug, thiserror::Error)]
pub enum PlantDaemonError {
    #[error(transparent)]
    Link(#[from] LinkError),
    #[error("speed {speed} must be a finite number > 0")]
    Speed { speed: f64 },
}

/// What the daemon did, reported at exit.
#[derive(Debug, Clone, Serialize)]
pub struct PlantReport {
    pub iface: String,
    pub mode: &'static str,
    /// "real_time", "lockstep" or "virtual".
    pub pacing: &'static str,
    pub speed: Option<f64>,
    /// "duration" or "shutdown".
    pub stopped_by: &'static str,
    pub sim_time_s: f64,
    pub wall_time_s: f64,
    pub cycles: u64,
    pub deadline_misses: u64,
    pub overruns: u64,
    pub lateness_p50_us: Option<f64>,
    pub lateness_p99_us: Option<f64>,
    pub lateness_max_us: Option<f64>,
    pub frames_sent: u64,
    pub send_errors: u64,
    pub frames_received: u64,
    pub receive_errors: u64,
    /// Lockstep: the messages waited for (comma-separated), and the cycles whose answers did
    /// not all come in time.
    pub lockstep: Option<String>,
    pub lockstep_timeouts: u64,
    /// Lockstep: the simulated time (s) of the first cycle whose answers did not all come, and
    /// the messages missing then (a TCU that started late misses cycle 0).
    pub lockstep_first_timeout_s: Option<f64>,
    pub lockstep_first_missing: Vec<String>,
    pub log: Option<PathBuf>,
    pub log_frames: Option<u64>,
    pub effects: EffectSet,
    pub faults: usize,
    pub plant: PlantStats,
}

impl PlantReport {
    /// A human-readable summary (several lines).
    pub fn summary(&self) -> String {
        let mut s = format!(
            "plant on {} ({} mode, {}{}): stopped by {} after {:.3} s simulated in {:.3} s\n",
            self.iface,
            self.mode,
            self.pacing,
            self.speed.map_or(String::new(), |k| format!(" x{k}")),
            self.stopped_by,
            self.sim_time_s,
            self.wall_time_s
        );
        s.push_str(&format!(
            "cycles {} deadline_misses {} overruns {} lateness p50 {} us p99 {} us max {} us\n",
            self.cycles,
            self.deadline_misses,
            self.overruns,
            fmt_opt(self.lateness_p50_us),
            fmt_opt(self.lateness_p99_us),
            fmt_opt(self.lateness_max_us)
        ));
        s.push_str(&format!(
            "frames sent {} (send errors {}), received {} (receive errors {}), rx accepted {:?}, rx errors {:?}, input timeouts {:?}\n",
            self.frames_sent,
            self.send_errors,
            self.frames_received,
            self.receive_errors,
            self.plant.rx_accepted,
            self.plant.rx_errors,
            self.plant.input_timeouts
        ));
        if !self.plant.faults_applied.is_empty() {
            s.push_str(&format!("faults applied {:?}\n", self.plant.faults_applied));
        }
        if !self.effects.is_nominal() {
            s.push_str(&format!("effects {:?}\n", self.effects.to_map()));
        }
        if let Some(m) = &self.lockstep {
            s.push_str(&format!(
                "lockstep on {m}: {} cycle(s) without an answer in time{}\n",
                self.lockstep_timeouts,
                self.lockstep_first_timeout_s
                    .map_or(String::new(), |t| format!(
                        " (first at {t:.2} s, missing {})",
                        self.lockstep_first_missing.join(",")
                    ))
            ));
        }
        if let (Some(p), Some(n)) = (&self.log, self.log_frames) {
            s.push_str(&format!("log {} ({n} frames)\n", p.display()));
        }
        s
    }
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or("-".into(), |x| format!("{x:.0}"))
}

struct Shell<B: Bus> {
    link: Link<B>,
    plant: Plant,
    /// Wall clock at the start: the origin of the log's time axis only.
    start_wall: Duration,
    /// Monotonic clock at the start: the origin of the simulated time in real-time pacing.
    start: Instant,
    time: TimeBase,
    speed: f64,
    lockstep_timeouts: u64,
    /// The first lockstep cycle without all its answers: its time and the ids missing.
    lockstep_first_timeout: Option<(Duration, Vec<u16>)>,
    pending: Vec<Received>,
    /// The read batch (reused).
    batch: Vec<Result<Received, BusError>>,
}

impl<B: Bus> Shell<B> {
    /// Monotonic time since the start.
    fn mono(&self) -> Duration {
        Instant::now().saturating_duration_since(self.start)
    }

    /// Restarts both clocks (the pacing loop begins now).
    fn start_clocks(&mut self) {
        self.start = Instant::now();
        self.start_wall = wall_clock();
        self.time = TimeBase::new();
    }

    /// Reads up to [`DRAIN_BUDGET`] frames that are already waiting, in one batch, each placed at
    /// its simulated arrival time (its kernel timestamp's age against the clocks read once after
    /// the batch); returns whether the receive queue was found empty.
    fn drain(&mut self) -> Result<bool, PlantDaemonError> {
        let mut batch = std::mem::take(&mut self.batch);
        let empty = self.link.bus.try_recv_many(DRAIN_BUDGET, &mut batch);
        let (wall, mono) = (wall_clock(), self.mono());
        // In order, up to the first error (the rest of the batch is dropped with the drain).
        let result = batch.drain(..).try_for_each(|rx| match rx {
            Ok(rx) => {
                let st = self
                    .time
                    .arrival(rx.timestamp, wall, mono)
                    .mul_f64(self.speed);
                let lt = self.log_time(rx.timestamp, st);
                self.on_receive(rx, st, lt)
            }
            Err(e) => self.recv_error(e),
        });
        self.batch = batch;
        result?;
        if empty {
            self.time.queue_empty(mono);
        }
        Ok(empty)
    }

    /// Log timestamp of a frame received with kernel timestamp `stamp` at simulated time `sim`:
    /// the kernel timestamp at speed 1 (as candump shows it), start + `sim` otherwise.
    fn log_time(&self, stamp: Duration, sim: Duration) -> Duration {
        if self.speed == 1.0 {
            stamp
        } else {
            self.start_wall + sim
        }
    }

    /// Log timestamp of a frame sent now with simulated due time `due`: the wall clock at speed 1,
    /// start + `due` otherwise.
    fn sent_log_time(&self, due: Duration) -> Duration {
        if self.speed == 1.0 {
            wall_clock()
        } else {
            self.start_wall + due
        }
    }

    fn on_receive(
        &mut self,
        rx: Received,
        sim_time: Duration,
        log_time: Duration,
    ) -> Result<(), PlantDaemonError> {
        self.link.received(&Received {
            frame: rx.frame,
            timestamp: log_time,
        })?;
        self.pending.push(Received {
            frame: rx.frame,
            timestamp: sim_time,
        });
        Ok(())
    }

    async fn send(&mut self, f: &OutFrame, log_time: Duration) -> Result<(), PlantDaemonError> {
        Ok(self.link.send(f.frame, log_time).await?)
    }

    fn recv_error(&mut self, e: BusError) -> Result<(), PlantDaemonError> {
        Ok(self.link.receive_error(e)?)
    }
}

/// Runs the plant on `bus` until `shutdown` resolves or `config.duration` of simulated time has
/// passed.
pub async fn run<B: Bus, S: Future<Output = ()>>(
    bus: B,
    shutdown: S,
    config: PlantDaemonConfig,
) -> Result<PlantReport, PlantDaemonError> {
    let speed = checked_speed(&config.pacing)?;
    let iface = bus.iface().to_string();
    let link = Link::open(bus, config.log.as_deref(), MAX_SEND_FAILURES)?;
    let mut shell = Shell {
        link,
        plant: Plant::new(config.plant.clone()),
        start_wall: wall_clock(),
        start: Instant::now(),
        time: TimeBase::new(),
        speed,
        lockstep_timeouts: 0,
        lockstep_first_timeout: None,
        pending: Vec::new(),
        batch: Vec::with_capacity(DRAIN_BUDGET),
    };
    let wall0 = std::time::Instant::now();
    let mut stats = LoopStats::default();
    tokio::pin!(shutdown);
    let stopped_by = run_paced(&mut shell, &mut shutdown, &config, &mut stats).await?;
    shell.report(iface, stopped_by, &stats, wall0, config)
}

/// The real-time speed factor (1 for virtual pacing, which has none); refused unless finite
/// and positive.
fn checked_speed(pacing: &Pacing) -> Result<f64, PlantDaemonError> {
    match pacing {
        Pacing::RealTime { speed } => {
            if !(speed.is_finite() && *speed > 0.0) {
                return Err(PlantDaemonError::Speed { speed: *speed });
            }
            Ok(*speed)
        }
        Pacing::Virtual { .. } => Ok(1.0),
    }
}

/// The pacing loop `config` asks for (real time, lockstep or virtual), run to its end; returns
/// what stopped it.
async fn run_paced<B: Bus, S: Future<Output = ()>>(
    shell: &mut Shell<B>,
    shutdown: &mut std::pin::Pin<&mut S>,
    config: &PlantDaemonConfig,
    stats: &mut LoopStats,
) -> Result<&'static str, PlantDaemonError> {
    match (&config.pacing, config.lockstep.clone()) {
        (Pacing::RealTime { .. }, Some(ls)) => {
            run_lockstep(shell, shutdown, config.duration, ls, stats).await
        }
        (Pacing::RealTime { .. }, None) => {
            run_real_time(shell, shutdown, config.duration, stats).await
        }
        (Pacing::Virtual { clock }, _) => {
            run_virtual(shell, shutdown, config.duration, clock.clone(), stats).await
        }
    }
}

impl<B: Bus> Shell<B> {
    /// The exit report (the candump tap is flushed and closed first); `wall0`: when the
    /// daemon started.
    fn report(
        mut self,
        iface: String,
        stopped_by: &'static str,
        stats: &LoopStats,
        wall0: std::time::Instant,
        config: PlantDaemonConfig,
    ) -> Result<PlantReport, PlantDaemonError> {
        let log_frames = self.link.finish()?;
        let (pacing, speed) = match config.pacing {
            Pacing::RealTime { speed } if config.lockstep.is_some() => ("lockstep", Some(speed)),
            Pacing::RealTime { speed } => ("real_time", Some(speed)),
            Pacing::Virtual { .. } => ("virtual", None),
        };
        let plant = self.plant.config();
        Ok(PlantReport {
            iface,
            mode: plant.mode.as_str(),
            pacing,
            speed,
            stopped_by,
            sim_time_s: self.plant.time().as_secs_f64(),
            wall_time_s: wall0.elapsed().as_secs_f64(),
            cycles: stats.cycles,
            deadline_misses: stats.deadline_misses,
            overruns: stats.overruns,
            lateness_p50_us: stats.lateness_percentile_us(0.5),
            lateness_p99_us: stats.lateness_percentile_us(0.99),
            lateness_max_us: stats.lateness_percentile_us(1.0),
            frames_sent: self.link.sent,
            send_errors: self.link.send_errors,
            frames_received: self.link.received,
            receive_errors: self.link.receive_errors,
            lockstep: config.lockstep.map(|l| {
                l.messages
                    .iter()
                    .map(|&m| message_name(m))
                    .collect::<Vec<_>>()
                    .join(",")
            }),
            lockstep_timeouts: self.lockstep_timeouts,
            lockstep_first_timeout_s: self
                .lockstep_first_timeout
                .as_ref()
                .map(|(t, _)| t.as_secs_f64()),
            lockstep_first_missing: self
                .lockstep_first_timeout
                .as_ref()
                .map(|(_, ids)| ids.iter().map(|&id| message_name(id)).collect())
                .unwrap_or_default(),
            log: config.log,
            log_frames,
            effects: plant.effects,
            faults: plant.faults.len(),
            plant: self.plant.stats().clone(),
        })
    }
}

async fn run_real_time<B: Bus, S: Future<Output = ()>>(
    shell: &mut Shell<B>,
    shutdown: &mut std::pin::Pin<&mut S>,
    duration: Option<Duration>,
    stats: &mut LoopStats,
) -> Result<&'static str, PlantDaemonError> {
    let period = CYCLE.div_f64(shell.speed);
    shell.start_clocks();
    let start = shell.start;
    let mut timer = Periodic::new(start, period);
    // Frames a fault delays past their cycle, sorted by due time.
    let mut later: Vec<OutFrame> = Vec::new();
    let speed = shell.speed;
    let wall_of = move |sim: Duration| start + sim.div_f64(speed);
    // More frames waiting at the last read than it took: read on the pace timer until the
    // queue is found empty again.
    let mut flooded = false;
    let mut pace_at = start;
    loop {
        let next_tx = later.first().map(|f| wall_of(f.due));
        tokio::select! {
            biased;
            _ = shutdown.as_mut() => return Ok("shutdown"),
            _ = sleep_until_precise(timer.next_deadline()) => {
                let tick = timer.fire(Instant::now());
                stats.record(&tick, period);
                let sim_now = CYCLE * u32::try_from(tick.cycle).unwrap_or(u32::MAX);
                if duration.is_some_and(|d| sim_now > d) {
                    return Ok("duration");
                }
                // Frames that are already waiting (received before this deadline), at most a
                // budget: under a flood the rest is read between deadlines, on the pace timer.
                flooded = !shell.drain()?;
                pace_at = Instant::now() + FLOOD_PACE;
                let rx = std::mem::take(&mut shell.pending);
                let out = shell.plant.step(sim_now, &rx);
                for f in out.frames {
                    if f.due <= sim_now {
                        let lt = shell.sent_log_time(f.due);
                        shell.send(&f, lt).await?;
                    } else {
                        let pos = later.partition_point(|g| g.due <= f.due);
                        later.insert(pos, f);
                    }
                }
                if Instant::now() >= timer.next_deadline() {
                    stats.overruns += 1;
                }
                if tick.cycle % 100 == 0 {
                    shell.link.flush()?;
                }
            }
            _ = async { if let Some(w) = next_tx { tokio::time::sleep_until(w).await } }, if next_tx.is_some() => {
                // What arrived before is read first, so the log stays in time order.
                flooded = !shell.drain()?;
                let now_sim = Instant::now().saturating_duration_since(start).mul_f64(speed);
                while later.first().is_some_and(|f| f.due <= now_sim) {
                    let f = later.remove(0);
                    let lt = shell.sent_log_time(f.due);
                    shell.send(&f, lt).await?;
                }
            }
            _ = tokio::time::sleep_until(pace_at), if flooded => {
                flooded = !shell.drain()?;
                pace_at = Instant::now() + FLOOD_PACE;
            }
        }
    }
}

async fn run_lockstep<B: Bus, S: Future<Output = ()>>(
    shell: &mut Shell<B>,
    shutdown: &mut std::pin::Pin<&mut S>,
    duration: Option<Duration>,
    ls: Lockstep,
    stats: &mut LoopStats,
) -> Result<&'static str, PlantDaemonError> {
    let speed = shell.speed;
    shell.start_clocks();
    let start = shell.start;
    let mut cycle: u64 = 0;
    loop {
        let sim_now = CYCLE * u32::try_from(cycle).unwrap_or(u32::MAX);
        if duration.is_some_and(|d| sim_now > d) {
            return Ok("duration");
        }
        // Not faster than `speed`: cycle n no earlier than start + n·period.
        let earliest = start + sim_now.div_f64(speed);
        let late_by = Instant::now().saturating_duration_since(earliest);
        if late_by.is_zero() {
            sleep_until_precise(earliest).await;
        }
        stats.cycles += 1;
        let rx = std::mem::take(&mut shell.pending);
        let out = shell.plant.step(sim_now, &rx);
        for f in out.frames {
            // Fault-delayed frames go out with their cycle (lockstep has no wall time to wait in).
            shell
                .send(&f, shell.start_wall + f.due.max(sim_now))
                .await?;
        }
        // Wait for the answers to this cycle; frames received meanwhile act from the next cycle
        // on (stamped mid-cycle in the log).
        let stamp = sim_now + CYCLE / 2;
        let give_up = Instant::now() + ls.timeout;
        let mut waiting = ls.messages.clone();
        while !waiting.is_empty() {
            tokio::select! {
                biased;
                _ = shutdown.as_mut() => return Ok("shutdown"),
                rx = shell.link.bus.recv() => match rx {
                    Ok(rx) => {
                        if let Some(id) = rx.frame.standard_id() {
                            waiting.retain(|&m| m != id);
                        }
                        shell.on_receive(rx, stamp, shell.start_wall + stamp)?;
                    }
                    Err(e) => shell.recv_error(e)?,
                },
                _ = tokio::time::sleep_until(give_up) => {
                    shell.lockstep_timeouts += 1;
                    shell
                        .lockstep_first_timeout
                        .get_or_insert_with(|| (sim_now, waiting.clone()));
                    break;
                }
            }
        }
        if cycle % 100 == 0 {
            shell.link.flush()?;
        }
        cycle += 1;
    }
}

async fn run_virtual<B: Bus, S: Future<Output = ()>>(
    shell: &mut Shell<B>,
    shutdown: &mut std::pin::Pin<&mut S>,
    duration: Option<Duration>,
    clock: Option<Arc<ManualClock>>,
    stats: &mut LoopStats,
) -> Result<&'static str, PlantDaemonError> {
    use crate::can::Clock;
    let base = clock.as_ref().map_or_else(wall_clock, |c| c.now());
    shell.start_wall = base;
    let set_clock = |sim: Duration| {
        if let Some(c) = &clock {
            c.set(base + sim);
        }
    };
    let mut cycle: u64 = 0;
    loop {
        let sim_now = CYCLE * u32::try_from(cycle).unwrap_or(u32::MAX);
        if duration.is_some_and(|d| sim_now > d) {
            return Ok("duration");
        }
        set_clock(sim_now);
        loop {
            match shell.link.bus.try_recv() {
                Ok(Some(rx)) => {
                    // Frames of other nodes are stamped by the shared clock: base + sim time.
                    let st = rx.timestamp.saturating_sub(base).min(sim_now);
                    shell.on_receive(rx, st, base + st)?;
                }
                Ok(None) => break,
                Err(e) => {
                    shell.recv_error(e)?;
                    break;
                }
            }
        }
        let rx = std::mem::take(&mut shell.pending);
        let out = shell.plant.step(sim_now, &rx);
        stats.cycles += 1;
        for f in out.frames {
            let due = f.due.max(sim_now);
            set_clock(due);
            shell.send(&f, base + due).await?;
        }
        cycle += 1;
        tokio::select! {
            biased;
            _ = shutdown.as_mut() => return Ok("shutdown"),
            _ = tokio::task::yield_now() => {}
        }
    }
}

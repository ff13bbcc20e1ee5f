//! The TCU daemon loop: the pure [`Tcu`] core on a [`Bus`], in real time.
//!
//! - One time base ([`TimeBase`]): monotonic time since the start with the daemon's own stalls
//!   taken out ("live" time). Every received frame — read blocking or not — carries its kernel
//!   receive timestamp, mapped onto that base, and is queued; a wall-clock step changes nothing.
//! - The arrival of a DCT_Sensors frame (the plant's 10 ms sensor message, the bench's sync)
//!   triggers a computation at once: `Tcu::step` with the queued frames, then the five TCU
//!   messages are sent. Sync frames closer than half a cycle to the previous computed one (a
//!   flood) trigger none; they are consumed by the next computation like any other frame, at
//!   the latest on the next timer deadline.
//! - Fallback: a periodic timer on absolute deadlines (`Periodic`, one cycle, no drift) computes
//!   on a deadline when the core asks for it ([`Tcu::poll_timeout`] on the live time base: the
//!   sensors silent for two cycles, then every cycle — the policy the lockstep sim uses too), so
//!   the safe state is commanded even when the sensors go silent. The timer is served before the bus, so a
//!   flood cannot starve it, and its lateness tells a stall of the daemon (see `clock`).
//! - Bounded work: each wake-up reads at most [`DRAIN_BUDGET`] further frames and computes at most
//!   [`MAX_SYNCS_PER_WAKE`] times, so the loop returns to its timer and to signals every cycle
//!   whatever arrives; frames left queued are read on the next wake-ups (the kernel drops what
//!   its receive queue cannot hold).
//! - Paced reads under a flood: a cycle with more than [`FLOOD_FRAMES_PER_CYCLE`] frames received
//!   switches the next cycle from a wake-up per frame to a read of everything queued every
//!   [`FLOOD_PACE`] (a sync frame then waits up to that long). A wake-up costs the same system
//!   calls (poll, a read that finds the queue empty, the clocks) whether it brings one frame or
//!   twenty, so a flood no longer buys the flooder the TCU's CPU: under User-Mode Linux, where a
//!   system call costs tens of µs, a 2 500 frames/s flood had the TCU take a third of the guest's
//!   CPU and lose its priority to the scheduler. The clocks are read once per wake-up, not per
//!   frame.
//! - A computation whose work (step + sends) takes longer than a cycle counts as an overrun; late
//!   fallback wake-ups count as deadline misses (`LoopStats`).
//! - Bus time ([`TcuClock::Bus`], a lockstep bench: the plant run with `--lockstep`): the core's
//!   time is the plant's simulated time, counted in DCT_Sensors frames ([`BusClock`]); a
//!   computation runs on each of them, and the fallback timer computes (moving bus time on a
//!   cycle each time) only after [`BUS_SILENCE`] of live time without one. Every timeout is then
//!   exact in cycles on a host that starves the daemons.
//! - Clean shutdown on the `shutdown` future (SIGINT/SIGTERM in the CLI) or after `duration`;
//!   the candump tap (`log`) is flushed either way.

use super::clock::{BusClock, TimeBase};
use super::diag::DiagShell;
pub use super::diag::{DiagDaemonConfig, DiagReport, FAULT_MEMORY_SAVE_EVERY};
use super::{wall_clock, Link, LinkError, LoopStats, Micros, Periodic, DRAIN_BUDGET, FLOOD_PACE};
use crate::can::messages::{ids, FaultCode, TcuState};
use crate::can::{Bus, BusError, CanFrame, Received};
use crate::diag::stack::DiagStack;
use crate::tcu::inputs::InputCounters;
use crate::tcu::{is_cycle_frame, is_sync_frame, Tcu, TcuConfig, TcuInputs, TimedFrame};
use serde::Serialize;
use std::future::Future;
use std::path::PathBuf;
use std::time::Duration;
use tokio::time::Instant;

/// Refused sends in a row that stop the daemon (20 cycles of TCU frames).
const MAX_SEND_FAILURES: u64 = 100;

pub use crate::tcu::CYCLE;

/// Frames received this soon after the sync frame belong to the same plant cycle.
const BURST: Duration = Duration::from_millis(2);

/// Computations per wake-up at most (a burst of sync frames delayed by the scheduler).
pub const MAX_SYNCS_PER_WAKE: usize = 4;

/// Stalls kept in the exit report's `stall_log`.
pub const STALL_LOG_LEN: usize = 256;

/// Frames received in one cycle above which the next cycle reads the bus on the pace timer (the
/// four inputs send 4–5 frames a cycle; a scheduling delay's backlog is a few dozen at most).
pub const FLOOD_FRAMES_PER_CYCLE: u64 = 48;

/// Bus time: live time without a DCT_Sensors frame after which the fallback timer computes
/// (and moves bus time on), so a dead plant still ends in the safe state.
pub const BUS_SILENCE: Duration = Duration::from_secs(2);

/// The TCU's time source.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TcuClock {
    /// Monotonic time with the daemon's stalls taken out (a real-time bench).
    #[default]
    Monotonic,
    /// The plant's simulated time in its sync frames (a lockstep bench).
    Bus,
}

/// The messages the TCU reads (a SocketCAN socket can filter on them).
pub const INPUT_IDS: [u16; 4] = [
    ids::ENG_STATUS,
    ids::DRV_PEDAL,
    ids::DCT_SENSORS,
    ids::DCT_ACTUATORS,
];

/// Daemon configuration.
#[derive(Debug, Clone)]
pub struct TcuDaemonConfig {
    pub tcu: TcuConfig,
    /// Stop after this much time.
    pub duration: Option<Duration>,
    /// candump -l tap of every frame sent and received.
    pub log: Option<PathBuf>,
    /// The core's time source.
    pub clock: TcuClock,
    /// UDS, XCP and the fault memory on the bus (`None`: the TCU ignores diagnostic frames).
    pub diag: Option<DiagDaemonConfig>,
}

/// Errors that stop the daemon.
#[derive(Debug, thiserror::Error)]
pub enum TcuDaemonError {
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The fault memory file could not be read (a corrupt one is set aside instead).
    #[error(transparent)]
    FaultMemory(#[from] crate::diag::store::StoreError),
}

/// What the daemon did, reported at exit.
#[derive(Debug, Clone, Serialize)]
pub struct TcuReport {
    pub iface: String,
    /// "duration" or "shutdown".
    pub stopped_by: &'static str,
    pub clock: TcuClock,
    pub wall_time_s: f64,
    /// The core's time at the last computation (bus time: simulated seconds computed).
    pub core_time_s: f64,
    pub computations: u64,
    /// Computations triggered by a DCT_Sensors frame.
    pub sync_computations: u64,
    /// Computations of the fallback timer.
    pub fallback_computations: u64,
    /// Computations (step + send) longer than a cycle.
    pub overruns: u64,
    /// Fallback timer wake-ups later than half a cycle, plus skipped cycles.
    pub deadline_misses: u64,
    pub timer_lateness_p99_us: Option<f64>,
    pub timer_lateness_max_us: Option<f64>,
    /// Stalls of the daemon (timer more than `clock::STALL_TOLERANCE` late), not counted
    /// against any sender's timeout: how many, their total and the longest (s).
    pub stalls: u64,
    pub stall_total_s: f64,
    pub stall_longest_s: f64,
    /// The first [`STALL_LOG_LEN`] stalls: when each was noticed (wall clock, s since the Unix
    /// epoch, the clock of the bus's timestamps) and how long it was (s), so a bench can tell
    /// whether the host held the TCU back at a given moment.
    pub stall_log: Vec<(f64, f64)>,
    /// Cycles whose bus reads were paced (more than [`FLOOD_FRAMES_PER_CYCLE`] frames in the
    /// cycle before).
    pub paced_cycles: u64,
    /// Sync frames that arrived within half a cycle of the previous computation (no computation
    /// of their own).
    pub syncs_coalesced: u64,
    /// Time from the receipt of a DCT_Sensors frame to the last TCU frame sent (µs).
    pub compute_p50_us: Option<f64>,
    pub compute_p99_us: Option<f64>,
    pub compute_max_us: Option<f64>,
    /// Time between the ends of consecutive computations' sends, i.e. the period of the TCU's
    /// frames on the bus as the daemon sent them (µs; nominal one cycle). A flood or a stall
    /// that makes the TCU miss cycles shows here.
    pub send_gap_p99_us: Option<f64>,
    pub send_gap_max_us: Option<f64>,
    pub frames_sent: u64,
    pub send_errors: u64,
    pub frames_received: u64,
    pub receive_errors: u64,
    pub safe_entries: u64,
    pub final_state: TcuState,
    pub final_fault: FaultCode,
    pub inputs: InputCounters,
    pub log: Option<PathBuf>,
    pub log_frames: Option<u64>,
    /// The diagnostic side, when on.
    pub diag: Option<DiagReport>,
}

impl TcuReport {
    /// A human-readable summary (several lines).
    pub fn summary(&self) -> String {
        let f = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.0}"));
        format!(
            "tcu on {} ({:?} clock): stopped by {} after {:.3} s (core time {:.3} s)\n\
             computations {} (sync {} fallback {}, coalesced syncs {}) overruns {} deadline_misses {} timer lateness p99 {} us max {} us\n\
             stalls {} (total {:.3} s, longest {:.3} s)\n\
             compute p50 {} us p99 {} us max {} us; frames every p99 {} us max {} us\n\
             frames sent {} (errors {}) received {} (errors {}); safe-state entries {}; final {:?} / {:?}\n",
            self.iface,
            self.clock,
            self.stopped_by,
            self.wall_time_s,
            self.core_time_s,
            self.computations,
            self.sync_computations,
            self.fallback_computations,
            self.syncs_coalesced,
            self.overruns,
            self.deadline_misses,
            f(self.timer_lateness_p99_us),
            f(self.timer_lateness_max_us),
            self.stalls,
            self.stall_total_s,
            self.stall_longest_s,
            f(self.compute_p50_us),
            f(self.compute_p99_us),
            f(self.compute_max_us),
            f(self.send_gap_p99_us),
            f(self.send_gap_max_us),
            self.frames_sent,
            self.send_errors,
            self.frames_received,
            self.receive_errors,
            self.safe_entries,
            self.final_state,
            self.final_fault,
        )
    }
}

/// The clocks as read once per wake-up (the wall clock and monotonic time since the start, at
/// the same moment): every frame read in that wake-up is placed against them.
#[derive(Debug, Clone, Copy, Default)]
struct WakeClocks {
    wall: Duration,
    mono: Duration,
}

struct Shell<B: Bus> {
    link: Link<B>,
    tcu: Tcu,
    start: Instant,
    time: TimeBase,
    /// Bus time, on a lockstep bench.
    bus_clock: Option<BusClock>,
    inbox: Vec<TimedFrame>,
    coalesced: u64,
    computations: u64,
    sync: u64,
    fallback: u64,
    overruns: u64,
    /// Computation times.
    compute: Micros,
    /// Gaps between the ends of consecutive computations' sends.
    send_gap: Micros,
    last_sent: Option<Instant>,
    last_sync: Option<Instant>,
    /// Time of the last frame received.
    last_at: Duration,
    /// The timer's pending deadline (since the start).
    deadline: Duration,
    /// Arrival of the last sync frame that had a computation of its own.
    last_sync_at: Option<Duration>,
    last_now: Duration,
    last_state: (TcuState, FaultCode),
    clocks: WakeClocks,
    /// Frames received since the last timer tick.
    cycle_frames: u64,
    /// The bus is read on the pace timer, not on every frame (a flood).
    paced: bool,
    paced_cycles: u64,
    /// The read batch (reused).
    batch: Vec<Result<Received, BusError>>,
    /// The core deadline whose wake-up has fired (each is armed once).
    core_fired: Option<Instant>,
    stall_log: Vec<(f64, f64)>,
    /// The diagnostic side, when on.
    diag: Option<DiagShell>,
}

impl<B: Bus> Shell<B> {
    /// Monotonic time since the start.
    fn mono(&self) -> Duration {
        Instant::now().saturating_duration_since(self.start)
    }

    /// Reads the clocks for this wake-up and takes note of a stall (the timer's pending deadline
    /// long past) before any frame read now is placed on the time base.
    fn woke(&mut self) {
        self.clocks = WakeClocks {
            wall: wall_clock(),
            mono: self.mono(),
        };
        if let Some(stall) = self.time.woke(self.clocks.mono, self.deadline) {
            if self.stall_log.len() < STALL_LOG_LEN {
                self.stall_log
                    .push((self.clocks.wall.as_secs_f64(), stall.as_secs_f64()));
            }
        }
    }

    /// At a timer tick: whether the cycle now starting reads the bus on the pace timer.
    fn pace_next_cycle(&mut self) {
        self.paced = self.cycle_frames > FLOOD_FRAMES_PER_CYCLE;
        self.paced_cycles += u64::from(self.paced);
        self.cycle_frames = 0;
    }

    /// When the core next needs to run by itself ([`Tcu::poll_timeout`] on the live time base),
    /// as a monotonic instant.
    fn core_deadline(&self) -> Instant {
        self.start + self.time.mono_of(self.tcu.poll_timeout())
    }

    /// The core's own deadline has come (on the live time base), or a coalesced sync frame
    /// waits: a fallback computation is due.
    fn fallback_due(&self, mono: Duration) -> bool {
        self.time.live(mono) >= self.tcu.poll_timeout() || self.sync_queued()
    }

    /// When the next paced read is due.
    fn next_read(&self) -> Instant {
        self.start + self.clocks.mono + FLOOD_PACE
    }

    /// Queues a received frame at its arrival on the TCU's time base (against the clocks of this
    /// wake-up: call [`Self::woke`] first).
    fn on_receive(&mut self, rx: Received) -> Result<(), TcuDaemonError> {
        self.link.received(&rx)?;
        self.cycle_frames += 1;
        if let Some(d) = &mut self.diag {
            if rx.frame.standard_id().is_some_and(DiagStack::handles) {
                d.on_frame(rx.frame);
                return Ok(());
            }
        }
        let at = if let Some(bc) = &mut self.bus_clock {
            if is_cycle_frame(&rx.frame) {
                bc.sync()
            } else {
                bc.stamp()
            }
        } else {
            let WakeClocks { wall, mono } = self.clocks;
            self.time.live(self.time.arrival(rx.timestamp, wall, mono))
        };
        // Frames are read in the order they arrived: never place one before an earlier one (a
        // stall noted between two reads moves the live time base back).
        let at = at.max(self.last_at);
        self.last_at = at;
        self.inbox.push(TimedFrame {
            at,
            frame: rx.frame,
        });
        Ok(())
    }

    /// Reads up to [`DRAIN_BUDGET`] frames that are already waiting (after [`Self::woke`]), in
    /// one batch.
    fn drain(&mut self) -> Result<(), TcuDaemonError> {
        let mut batch = std::mem::take(&mut self.batch);
        let empty = self.link.bus.try_recv_many(DRAIN_BUDGET, &mut batch);
        // In order, up to the first error (the rest of the batch is dropped with the drain).
        let result = batch.drain(..).try_for_each(|rx| match rx {
            Ok(rx) => self.on_receive(rx),
            Err(e) => self.recv_error(e),
        });
        self.batch = batch;
        result?;
        if empty {
            self.time.queue_empty(self.clocks.mono);
        }
        Ok(())
    }

    /// The next queued sync frame that is due a computation of its own: half a cycle or more
    /// after the previous sync frame that had one.
    fn next_sync(&mut self) -> Option<Duration> {
        let last = self.last_sync_at;
        self.inbox
            .iter()
            .filter(|f| self.is_sync(f))
            .find(|f| last.is_none_or(|t| f.at >= t + CYCLE / 2))
            .map(|f| f.at)
    }

    fn recv_error(&mut self, e: BusError) -> Result<(), TcuDaemonError> {
        Ok(self.link.receive_error(e)?)
    }

    async fn send(&mut self, f: CanFrame) -> Result<(), TcuDaemonError> {
        Ok(self.link.send(f, wall_clock()).await?)
    }

    /// Bus time: no sync frame computed for [`BUS_SILENCE`] of live time (`mono`: now) since
    /// the last one. Before the plant's first cycle the TCU waits (bus time has not begun).
    fn bus_silent(&self, mono: Duration) -> bool {
        let Some(since) = self
            .last_sync
            .map(|t| t.saturating_duration_since(self.start))
        else {
            return false;
        };
        self.time.live(mono).saturating_sub(self.time.live(since)) >= BUS_SILENCE
    }

    /// A frame that triggers a computation: in real time a DCT_Sensors frame with its CRC right
    /// (a garbage flood on that id drives nothing); on a lockstep bench every DCT_Sensors frame,
    /// since each is a plant cycle the plant waits on (a corrupted one is the inputs' to judge).
    fn is_sync(&self, f: &TimedFrame) -> bool {
        if self.bus_clock.is_some() {
            is_cycle_frame(&f.frame)
        } else {
            is_sync_frame(&f.frame)
        }
    }

    /// A DCT_Sensors frame is queued (coalesced, not yet computed).
    fn sync_queued(&self) -> bool {
        self.inbox.iter().any(|f| self.is_sync(f))
    }

    /// Computes for each queued DCT_Sensors frame that is due one (a burst after a scheduling
    /// delay is computed at its own spacing), in order, at most [`MAX_SYNCS_PER_WAKE`] times.
    async fn run_syncs(&mut self) -> Result<(), TcuDaemonError> {
        for _ in 0..MAX_SYNCS_PER_WAKE {
            let Some(at) = self.next_sync() else { break };
            self.compute(Some(at)).await?;
        }
        Ok(())
    }

    /// One computation. A sync computation runs at the DCT_Sensors frame's receive time (so a
    /// burst of frames delayed by the scheduler is computed at their own 10 ms spacing), a
    /// fallback one at the current time; never earlier than the previous one.
    async fn compute(&mut self, sync: Option<Duration>) -> Result<(), TcuDaemonError> {
        let t0 = Instant::now();
        // Frames already waiting belong to this computation too.
        self.woke();
        self.drain()?;
        let now = match (sync, &mut self.bus_clock) {
            (Some(at), _) => at,
            (None, Some(bc)) => bc.idle(),
            (None, None) => self.time.live(t0.saturating_duration_since(self.start)),
        }
        .max(self.last_now);
        self.last_now = now;
        // Frames up to the computation's time (with the rest of the sender's burst: the plant
        // sends DCT_Actuators just after DCT_Sensors); later ones, of a later cycle, wait.
        let horizon = now + BURST;
        // Every frame up to the horizon, wherever it sits in the queue: no frame blocks another.
        let (inbox, later): (Vec<TimedFrame>, Vec<TimedFrame>) =
            self.inbox.drain(..).partition(|f| f.at <= horizon);
        self.inbox = later;
        let syncs_in = inbox.iter().filter(|f| self.is_sync(f)).count() as u64;
        self.coalesced += syncs_in.saturating_sub(u64::from(sync.is_some()));
        let t_recv = t0.elapsed();
        let mut out = self.tcu.step(now, &TcuInputs { frames: &inbox });
        self.last_state = (out.status.tcu_state, out.status.fault_code);
        let t_step = t0.elapsed();
        let mut slowest_send = Duration::ZERO;
        for f in std::mem::take(&mut out.frames) {
            let ts = Instant::now();
            self.send(f).await?;
            slowest_send = slowest_send.max(ts.elapsed());
        }
        let sent = Instant::now();
        if let Some(prev) = self.last_sent.replace(sent) {
            self.send_gap.record(sent.saturating_duration_since(prev));
        }
        let took = t0.elapsed();
        if took > 5 * CYCLE {
            tracing::warn!(
                "slow TCU computation: {:?} (receive {:?}, step {:?}, slowest send {:?}, {} frames in)",
                took,
                t_recv,
                t_step - t_recv,
                slowest_send,
                inbox.len()
            );
        }
        self.computations += 1;
        if sync.is_some() {
            self.sync += 1;
        } else {
            self.fallback += 1;
        }
        if took > CYCLE {
            self.overruns += 1;
        }
        self.compute.record(took);
        if sync.is_some() {
            self.last_sync = Some(t0);
            self.last_sync_at = sync;
        }
        if self.computations % 100 == 0 {
            self.link.flush()?;
        }
        // The diagnostic side after the control frames are out: the fault memory's tests and
        // the cycle's DAQ packets.
        let diag_now = self.time.live(self.mono());
        if let Some(d) = &mut self.diag {
            d.after_step(diag_now, now, &out, &mut self.tcu);
        }
        self.flush_diag().await
    }

    /// Sends what the diagnostic side has due now (XCP packets, ISO-TP frames paced by the
    /// tester's STmin and block size), then performs an ECUReset whose response is out and saves
    /// the fault memory when due.
    async fn flush_diag(&mut self) -> Result<(), TcuDaemonError> {
        loop {
            let now = self.time.live(self.mono());
            let Some(d) = &mut self.diag else {
                return Ok(());
            };
            d.serve_pending(now, &mut self.tcu);
            d.core.handle_timeout(now, &mut self.tcu);
            let Some(f) = d.core.poll_transmit(now) else {
                d.reset_if_due(self.last_now, &mut self.tcu);
                d.save_if_due(false);
                return Ok(());
            };
            d.sent += 1;
            self.send(f).await?;
            let at = self.time.live(self.mono());
            if let Some(d) = &mut self.diag {
                d.core.sent(at);
            }
        }
    }

    /// When the diagnostic side next needs to run by itself, as a monotonic instant.
    fn diag_deadline(&self) -> Option<Instant> {
        let at = self.diag.as_ref()?.core.poll_timeout()?;
        Some(self.start + self.time.mono_of(at))
    }
}

/// Runs the TCU on `bus` until `shutdown` resolves or `duration` has passed.
pub async fn run<B: Bus, S: Future<Output = ()>>(
    bus: B,
    shutdown: S,
    config: TcuDaemonConfig,
) -> Result<TcuReport, TcuDaemonError> {
    let iface = bus.iface().to_string();
    let link = Link::open(bus, config.log.as_deref(), MAX_SEND_FAILURES)?;
    let start = Instant::now();
    let mut shell = Shell::new(link, &config, start);
    shell.diag = match &config.diag {
        Some(d) => Some(DiagShell::open(d, &config.tcu)?),
        None => None,
    };
    let far = start + Duration::from_secs(86_400 * 365);
    let mut timer = Periodic::new(start, CYCLE);
    let mut stats = LoopStats::default();
    tokio::pin!(shutdown);
    let stopped_by = loop {
        let (core_at, core_armed) = shell.arm(timer.next_deadline());
        let diag_at = shell.diag_deadline();
        tokio::select! {
            biased;
            _ = shutdown.as_mut() => break "shutdown",
            _ = tokio::time::sleep_until(timer.next_deadline()) => {
                if shell.on_tick(&mut timer, &mut stats, config.duration).await? {
                    break "duration";
                }
            }
            // The core's own deadline between two ticks (the sensors silent for two cycles): at
            // that time, not at the next tick, so the TCU's frames are never more than the
            // silence apart. Armed once per deadline.
            _ = tokio::time::sleep_until(core_at), if core_armed => {
                shell.on_core_deadline(core_at).await?;
            }
            // The diagnostic side's timers (ISO-TP pacing and timeouts, the UDS session).
            _ = tokio::time::sleep_until(diag_at.unwrap_or(far)), if diag_at.is_some() => {
                shell.woke();
                shell.flush_diag().await?;
            }
            // A flood: everything queued, every FLOOD_PACE.
            _ = tokio::time::sleep_until(shell.next_read()), if shell.paced => {
                shell.on_paced_read().await?;
            }
            rx = shell.link.bus.recv(), if !shell.paced => shell.on_bus_wake(rx).await?,
        }
    };
    shell.report(iface, stopped_by, config, &stats)
}

impl<B: Bus> Shell<B> {
    /// The shell at the start: a fresh core on `link`, nothing received or computed yet.
    fn new(link: Link<B>, config: &TcuDaemonConfig, start: Instant) -> Self {
        Shell {
            link,
            tcu: Tcu::new(config.tcu.clone(), Duration::ZERO),
            start,
            time: TimeBase::new(),
            bus_clock: (config.clock == TcuClock::Bus).then(|| BusClock::new(CYCLE)),
            inbox: Vec::new(),
            coalesced: 0,
            computations: 0,
            sync: 0,
            fallback: 0,
            overruns: 0,
            compute: Micros::default(),
            send_gap: Micros::default(),
            last_sent: None,
            last_sync: None,
            last_at: Duration::ZERO,
            deadline: Duration::ZERO,
            last_sync_at: None,
            last_now: Duration::ZERO,
            last_state: (TcuState::Init, FaultCode::None),
            clocks: WakeClocks::default(),
            cycle_frames: 0,
            paced: false,
            paced_cycles: 0,
            batch: Vec::with_capacity(DRAIN_BUDGET),
            core_fired: None,
            stall_log: Vec::new(),
            diag: None,
        }
    }

    /// Before each wait: notes the timer's pending deadline (`next_tick`) and returns the core's
    /// own deadline and whether its wake-up is armed (real time only, before the next tick, and
    /// once per deadline).
    fn arm(&mut self, next_tick: Instant) -> (Instant, bool) {
        self.deadline = next_tick.saturating_duration_since(self.start);
        let core_at = self.core_deadline();
        let core_armed =
            self.bus_clock.is_none() && core_at < next_tick && self.core_fired != Some(core_at);
        (core_at, core_armed)
    }

    /// A timer tick: reads what is queued, decides the next cycle's pacing and computes if a
    /// computation is due. Returns whether `duration` has passed (the daemon stops, without
    /// computing).
    async fn on_tick(
        &mut self,
        timer: &mut Periodic,
        stats: &mut LoopStats,
        duration: Option<Duration>,
    ) -> Result<bool, TcuDaemonError> {
        let now = Instant::now();
        let tick = timer.fire(now);
        stats.record(&tick, CYCLE);
        // Frames waiting in the socket are read on every tick too, not only when the
        // receive future is woken, so no queued frame waits longer than a cycle.
        self.woke();
        self.drain()?;
        self.pace_next_cycle();
        self.deadline = timer.next_deadline().saturating_duration_since(self.start);
        let mono = now.saturating_duration_since(self.start);
        if duration.is_some_and(|d| mono >= d) {
            return Ok(true);
        }
        if self.bus_clock.is_some() {
            // Bus time: queued sync frames are computed at their own time; a fallback
            // computation only after BUS_SILENCE of live time without one.
            if self.sync_queued() {
                self.run_syncs().await?;
            } else if self.bus_silent(mono) {
                self.compute(None).await?;
            }
        } else if self.fallback_due(mono) {
            // The core's own deadline (the sensors silent), or a coalesced sync frame
            // still queued: computed on this deadline.
            self.compute(None).await?;
        }
        self.flush_diag().await?;
        Ok(false)
    }

    /// The core's own deadline `core_at` has come between two ticks: reads what is queued and
    /// computes if the core still asks for it.
    async fn on_core_deadline(&mut self, core_at: Instant) -> Result<(), TcuDaemonError> {
        self.core_fired = Some(core_at);
        self.woke();
        self.drain()?;
        if self.fallback_due(self.clocks.mono) {
            self.compute(None).await?;
        }
        Ok(())
    }

    /// A paced read (a flood): everything queued, then the sync computations due.
    async fn on_paced_read(&mut self) -> Result<(), TcuDaemonError> {
        self.woke();
        self.drain()?;
        self.run_syncs().await?;
        self.flush_diag().await
    }

    /// The bus woke the daemon with a frame (or a receive error): queues it with the rest of
    /// what is waiting, then runs the sync computations due.
    async fn on_bus_wake(&mut self, rx: Result<Received, BusError>) -> Result<(), TcuDaemonError> {
        self.woke();
        match rx {
            Ok(rx) => self.on_receive(rx)?,
            Err(e) => self.recv_error(e)?,
        }
        self.drain()?;
        self.run_syncs().await?;
        self.flush_diag().await
    }

    /// The exit report (the candump tap is flushed and closed first).
    fn report(
        mut self,
        iface: String,
        stopped_by: &'static str,
        config: TcuDaemonConfig,
        stats: &LoopStats,
    ) -> Result<TcuReport, TcuDaemonError> {
        let (stalls, stall_total, stall_longest) = self.time.stalls();
        if let Some(d) = &mut self.diag {
            d.save_if_due(true);
        }
        let log_frames = self.link.finish()?;
        Ok(TcuReport {
            iface,
            stopped_by,
            clock: config.clock,
            wall_time_s: self.start.elapsed().as_secs_f64(),
            core_time_s: self.last_now.as_secs_f64(),
            computations: self.computations,
            sync_computations: self.sync,
            fallback_computations: self.fallback,
            overruns: self.overruns,
            deadline_misses: stats.deadline_misses,
            timer_lateness_p99_us: stats.lateness_percentile_us(0.99),
            timer_lateness_max_us: stats.lateness_percentile_us(1.0),
            stalls,
            stall_total_s: stall_total.as_secs_f64(),
            stall_longest_s: stall_longest.as_secs_f64(),
            paced_cycles: self.paced_cycles,
            stall_log: self.stall_log,
            syncs_coalesced: self.coalesced,
            compute_p50_us: self.compute.percentile(0.5),
            compute_p99_us: self.compute.percentile(0.99),
            compute_max_us: self.compute.percentile(1.0),
            send_gap_p99_us: self.send_gap.percentile(0.99),
            send_gap_max_us: self.send_gap.percentile(1.0),
            frames_sent: self.link.sent,
            send_errors: self.link.send_errors,
            frames_received: self.link.received,
            receive_errors: self.link.receive_errors,
            safe_entries: self.tcu.safe_entries(),
            final_state: self.last_state.0,
            final_fault: self.last_state.1,
            inputs: self.tcu.input_counters(),
            log: config.log,
            log_frames,
            diag: self.diag.as_ref().map(DiagShell::report),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::bus::{EndpointConfig, InProcessBus};

    fn ms(v: u32) -> Duration {
        Duration::from_millis(u64::from(v))
    }

    /// The plant's sensor frames (at 3, 13, …, 73 ms: out of phase with the TCU's own 10 ms
    /// timer) stop: the TCU runs by itself at its core's deadline, two cycles after the last one
    /// (93 ms) and every cycle from there (103, 113 …), not at its next timer tick (100 ms): its
    /// frames are never more than the silence apart.
    #[tokio::test(start_paused = true)]
    async fn the_core_deadline_is_kept_between_timer_ticks() {
        let bus = InProcessBus::new("sim");
        let tcu_end = bus.endpoint(EndpointConfig::default());
        let mut plant = bus.endpoint(EndpointConfig::default());
        let config = TcuDaemonConfig {
            tcu: TcuConfig::default(),
            duration: Some(ms(150)),
            log: None,
            clock: TcuClock::Monotonic,
            diag: None,
        };
        let start = Instant::now();
        let plant_side = async {
            let mut cmd_at = Vec::new();
            let mut k = 0u32;
            loop {
                let next_sync = start + ms(3) + ms(10) * k;
                tokio::select! {
                    biased;
                    _ = tokio::time::sleep_until(start + ms(145)) => break cmd_at,
                    _ = tokio::time::sleep_until(next_sync), if k < 8 => {
                        let mut data = [0u8; 8];
                        crate::can::e2e::protect(ids::DCT_SENSORS, &mut data, k as u8);
                        let f = CanFrame::standard(ids::DCT_SENSORS, &data).unwrap();
                        plant.send(f).await.unwrap();
                        k += 1;
                    }
                    rx = plant.recv() => {
                        if rx.unwrap().frame.standard_id() == Some(ids::TCU_CLUTCH_CMD) {
                            cmd_at.push(Instant::now() - start);
                        }
                    }
                }
            }
        };
        let (report, cmd_at) = tokio::join!(
            run(tcu_end, std::future::pending::<()>(), config),
            plant_side
        );
        let report = report.unwrap();
        assert_eq!(report.sync_computations, 8, "{cmd_at:?}");
        let after: Vec<Duration> = cmd_at.iter().copied().filter(|t| *t > ms(73)).collect();
        assert_eq!(&after[..3], &[ms(93), ms(103), ms(113)], "{cmd_at:?}");
        let gap = cmd_at.windows(2).map(|w| w[1] - w[0]).max().unwrap();
        assert!(gap <= crate::tcu::SENSOR_SILENCE, "{cmd_at:?}");
    }
}

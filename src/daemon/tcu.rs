//! The TCU daemon loop: the pure [`Tcu`] core on a [`Bus`], in real time.
//!
//! - Every received frame is stamped with its receive time on the TCU's time base (the bus
//!   timestamp — the kernel's for SocketCAN — minus the wall-clock time of the start) and queued.
//! - The arrival of a DCT_Sensors frame (the plant's 10 ms sensor message, the bench's sync)
//!   triggers a computation at once: `Tcu::step` with the queued frames, then the five TCU
//!   messages are sent.
//! - Fallback: a periodic timer on absolute deadlines (`Periodic`, 10 ms, no drift) computes on
//!   every deadline while no DCT_Sensors frame came for 1.2 cycles (missing or late), so the safe
//!   state is commanded even when the sensors go silent.
//! - A computation whose work (step + sends) takes longer than a cycle counts as an overrun; late
//!   fallback wake-ups count as deadline misses (`LoopStats`).
//! - Clean shutdown on the `shutdown` future (SIGINT/SIGTERM in the CLI) or after `duration`;
//!   the candump tap (`log`) is flushed either way.

use super::{percentile, wall_clock, Link, LinkError, LoopStats, Periodic};
use crate::can::messages::{ids, FaultCode, TcuState};
use crate::can::{Bus, BusError, CanFrame, Received};
use crate::tcu::inputs::InputCounters;
use crate::tcu::{Tcu, TcuConfig, TcuInputs, TimedFrame};
use serde::Serialize;
use std::future::Future;
use std::path::PathBuf;
use std::time::Duration;
use tokio::time::Instant;

/// Refused sends in a row that stop the daemon (20 cycles of TCU frames).
const MAX_SEND_FAILURES: u64 = 100;

/// The TCU's computation cycle (the contract's 10 ms).
pub const CYCLE: Duration = Duration::from_millis(10);

/// Frames received this soon after the sync frame belong to the same plant cycle.
const BURST: Duration = Duration::from_millis(2);

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
}

/// Errors that stop the daemon.
#[derive(Debug, thiserror::Error)]
pub enum TcuDaemonError {
    #[error(transparent)]
    Link(#[from] LinkError),
}

/// What the daemon did, reported at exit.
#[derive(Debug, Clone, Serialize)]
pub struct TcuReport {
    pub iface: String,
    /// "duration" or "shutdown".
    pub stopped_by: &'static str,
    pub wall_time_s: f64,
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
    /// Time from the receipt of a DCT_Sensors frame to the last TCU frame sent (µs).
    pub compute_p50_us: Option<f64>,
    pub compute_p99_us: Option<f64>,
    pub compute_max_us: Option<f64>,
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
}

impl TcuReport {
    /// A human-readable summary (several lines).
    pub fn summary(&self) -> String {
        let f = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.0}"));
        format!(
            "tcu on {}: stopped by {} after {:.3} s\n\
             computations {} (sync {} fallback {}) overruns {} deadline_misses {} timer lateness p99 {} us\n\
             compute p50 {} us p99 {} us max {} us\n\
             frames sent {} (errors {}) received {} (errors {}); safe-state entries {}; final {:?} / {:?}\n",
            self.iface,
            self.stopped_by,
            self.wall_time_s,
            self.computations,
            self.sync_computations,
            self.fallback_computations,
            self.overruns,
            self.deadline_misses,
            f(self.timer_lateness_p99_us),
            f(self.compute_p50_us),
            f(self.compute_p99_us),
            f(self.compute_max_us),
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

struct Shell<B: Bus> {
    link: Link<B>,
    tcu: Tcu,
    start: Instant,
    start_wall: Duration,
    inbox: Vec<TimedFrame>,
    computations: u64,
    sync: u64,
    fallback: u64,
    overruns: u64,
    compute_us: Vec<u32>,
    last_sync: Option<Instant>,
    last_now: Duration,
    last_state: (TcuState, FaultCode),
}

impl<B: Bus> Shell<B> {
    /// Time since the start on the TCU's time base for a bus timestamp (wall clock), never
    /// later than now.
    fn to_tcu(&self, ts: Duration) -> Duration {
        let mono = Instant::now().saturating_duration_since(self.start);
        ts.saturating_sub(self.start_wall).min(mono)
    }

    /// Queues a received frame; returns its time on the TCU's time base when it is a
    /// DCT_Sensors frame (the sync).
    fn on_receive(&mut self, rx: Received) -> Result<Option<Duration>, TcuDaemonError> {
        self.link.received(&rx)?;
        let at = self.to_tcu(rx.timestamp);
        self.inbox.push(TimedFrame {
            at,
            frame: rx.frame,
        });
        Ok((rx.frame.standard_id() == Some(ids::DCT_SENSORS)).then_some(at))
    }

    fn recv_error(&mut self, e: BusError) -> Result<(), TcuDaemonError> {
        Ok(self.link.receive_error(e)?)
    }

    async fn send(&mut self, f: CanFrame) -> Result<(), TcuDaemonError> {
        Ok(self.link.send(f, wall_clock()).await?)
    }

    /// Computes for a DCT_Sensors frame received at `first`, then for every further one the
    /// computation found already queued (a burst after a scheduling delay), in order.
    async fn run_syncs(&mut self, first: Duration) -> Result<(), TcuDaemonError> {
        let mut next = Some(first);
        while let Some(at) = next {
            self.compute(Some(at)).await?;
            next = self
                .inbox
                .iter()
                .find(|f| f.frame.standard_id() == Some(ids::DCT_SENSORS))
                .map(|f| f.at);
        }
        Ok(())
    }

    /// One computation. A sync computation runs at the DCT_Sensors frame's receive time (so a
    /// burst of frames delayed by the scheduler is computed at their own 10 ms spacing), a
    /// fallback one at the current time; never earlier than the previous one.
    async fn compute(&mut self, sync: Option<Duration>) -> Result<(), TcuDaemonError> {
        let t0 = Instant::now();
        // Frames already waiting belong to this computation too.
        loop {
            match self.link.bus.try_recv() {
                Ok(Some(rx)) => {
                    self.on_receive(rx)?;
                }
                Ok(None) => break,
                Err(e) => {
                    self.recv_error(e)?;
                    break;
                }
            }
        }
        let now = sync
            .unwrap_or_else(|| t0.saturating_duration_since(self.start))
            .max(self.last_now);
        self.last_now = now;
        // Frames up to the computation's time (with the rest of the sender's burst: the plant
        // sends DCT_Actuators just after DCT_Sensors); later ones, of a later cycle, wait.
        let horizon = now + BURST;
        let n = self.inbox.iter().take_while(|f| f.at <= horizon).count();
        let inbox: Vec<TimedFrame> = self.inbox.drain(..n).collect();
        let t_recv = t0.elapsed();
        let out = self.tcu.step(now, &TcuInputs { frames: &inbox });
        self.last_state = (out.status.tcu_state, out.status.fault_code);
        let t_step = t0.elapsed();
        let mut slowest_send = Duration::ZERO;
        for f in out.frames {
            let ts = Instant::now();
            self.send(f).await?;
            slowest_send = slowest_send.max(ts.elapsed());
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
        if self.compute_us.len() < 1 << 20 {
            self.compute_us
                .push(took.as_micros().min(u128::from(u32::MAX)) as u32);
        }
        if sync.is_some() {
            self.last_sync = Some(t0);
        }
        if self.computations % 100 == 0 {
            self.link.flush()?;
        }
        Ok(())
    }
}

/// Puts the calling thread under the real-time FIFO scheduler at `priority` (1..=99), as a
/// bench ECU process would run; needs CAP_SYS_NICE (root). Under User-Mode Linux, where every
/// process of the guest shares one virtual CPU, it keeps a busy neighbour from delaying the
/// 10 ms loop (measured: 60 s of `ddct bench` went from a dozen spurious input timeouts to none).
/// The loops block on the bus or a timer every cycle, so they leave the CPU to the kernel.
pub fn set_realtime_priority(priority: i32) -> std::io::Result<()> {
    let param = libc::sched_param {
        sched_priority: priority.clamp(1, 99),
    };
    // SAFETY: plain syscall on the calling thread (pid 0) with a valid parameter struct.
    let rc = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
    if rc == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
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
    let mut shell = Shell {
        link,
        tcu: Tcu::new(config.tcu.clone(), Duration::ZERO),
        start,
        start_wall: wall_clock(),
        inbox: Vec::new(),
        computations: 0,
        sync: 0,
        fallback: 0,
        overruns: 0,
        compute_us: Vec::new(),
        last_sync: None,
        last_now: Duration::ZERO,
        last_state: (TcuState::Init, FaultCode::None),
    };
    let mut timer = Periodic::new(start, CYCLE);
    let mut stats = LoopStats::default();
    let grace = CYCLE.mul_f64(1.2);
    tokio::pin!(shutdown);
    let stopped_by = loop {
        tokio::select! {
            biased;
            _ = shutdown.as_mut() => break "shutdown",
            rx = shell.link.bus.recv() => {
                match rx {
                    Ok(rx) => {
                        if let Some(at) = shell.on_receive(rx)? {
                            shell.run_syncs(at).await?;
                        }
                    }
                    Err(e) => shell.recv_error(e)?,
                }
            }
            _ = tokio::time::sleep_until(timer.next_deadline()) => {
                let now = Instant::now();
                let tick = timer.fire(now);
                stats.record(&tick, CYCLE);
                if config.duration.is_some_and(|d| now.saturating_duration_since(start) >= d) {
                    break "duration";
                }
                // No DCT_Sensors for 1.2 cycles: compute on every deadline until it is back.
                if shell.last_sync.is_none_or(|t| now.saturating_duration_since(t) >= grace) {
                    shell.compute(None).await?;
                }
            }
        }
    };
    let log_frames = shell.link.finish()?;
    Ok(TcuReport {
        iface,
        stopped_by,
        wall_time_s: start.elapsed().as_secs_f64(),
        computations: shell.computations,
        sync_computations: shell.sync,
        fallback_computations: shell.fallback,
        overruns: shell.overruns,
        deadline_misses: stats.deadline_misses,
        timer_lateness_p99_us: stats.lateness_percentile_us(0.99),
        compute_p50_us: percentile(&shell.compute_us, 0.5),
        compute_p99_us: percentile(&shell.compute_us, 0.99),
        compute_max_us: percentile(&shell.compute_us, 1.0),
        frames_sent: shell.link.sent,
        send_errors: shell.link.send_errors,
        frames_received: shell.link.received,
        receive_errors: shell.link.receive_errors,
        safe_entries: shell.tcu.safe_entries(),
        final_state: shell.last_state.0,
        final_fault: shell.last_state.1,
        inputs: shell.tcu.input_counters(),
        log: config.log,
        log_frames,
    })
}

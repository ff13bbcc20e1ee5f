//! The thin real-time shell shared by the plant and TCU daemons: absolute-deadline periodic
//! timing with deadline-miss counting, timing statistics, and a candump tap that records every
//! frame a daemon sends or receives (flushed on shutdown). This is the only place that reads the
//! clock; the cores (`plant`, `tcu`) get `now` as an argument.

pub mod clock;
mod diag;
pub mod os;
pub mod plant;
pub mod tcu;

use crate::can::candump::LogWriter;
use crate::can::{Bus, BusError, CanFrame, Received};
use std::fs::File;
use std::io::{self, BufWriter};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};
use tokio::time::Instant;

/// The runtime each daemon (and each node of a bench) runs on: one thread, with I/O and timers.
pub fn runtime() -> io::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
}

/// One wake-up of a [`Periodic`] timer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tick {
    /// Index of this cycle since the start (cycles skipped after an overrun are not returned).
    pub cycle: u64,
    /// The cycle's deadline, relative to the start.
    pub deadline: Duration,
    /// How late the wake-up was.
    pub late_by: Duration,
    /// Whole cycles skipped because the previous wake-up came more than one period late.
    pub skipped: u64,
}

/// A periodic timer on absolute deadlines `start + k·period` (no drift). When a wake-up comes
/// more than a period late, the missed deadlines are counted and skipped, not bunched.
#[derive(Debug)]
pub struct Periodic {
    start: Instant,
    period: Duration,
    next: u64,
}

impl Periodic {
    pub fn new(start: Instant, period: Duration) -> Self {
        assert!(!period.is_zero(), "period must be positive");
        Self {
            start,
            period,
            next: 0,
        }
    }

    pub fn start(&self) -> Instant {
        self.start
    }

    pub fn period(&self) -> Duration {
        self.period
    }

    /// The next deadline as an instant.
    pub fn next_deadline(&self) -> Instant {
        self.start + self.offset(self.next)
    }

    /// Time from the start to deadline `cycle` (no wrap: saturates after 584 years, not after
    /// 2³² cycles).
    fn offset(&self, cycle: u64) -> Duration {
        let ns = self.period.as_nanos().saturating_mul(u128::from(cycle));
        Duration::from_nanos(u64::try_from(ns).unwrap_or(u64::MAX))
    }

    /// Waits for the next deadline.
    pub async fn tick(&mut self) -> Tick {
        let deadline = self.next_deadline();
        tokio::time::sleep_until(deadline).await;
        self.fire(Instant::now())
    }

    /// Marks the next deadline as reached at `now` (for loops that wait with `select!`).
    pub fn fire(&mut self, now: Instant) -> Tick {
        let cycle = self.next;
        let deadline_rel = self.offset(cycle);
        let late_by = now.saturating_duration_since(self.start + deadline_rel);
        let skipped = (late_by.as_nanos() / self.period.as_nanos()) as u64;
        self.next = cycle + 1 + skipped;
        Tick {
            cycle,
            deadline: deadline_rel,
            late_by,
            skipped,
        }
    }
}

/// Frames a daemon reads without waiting per wake-up (a cycle of every input many times over):
/// under a flood the rest waits for the next wake-up, and the cycle's work goes on.
pub const DRAIN_BUDGET: usize = 64;

/// The period of bus reads while a daemon's inputs are flooded (more waiting than it reads at
/// once): everything queued is read in batches on this pace instead of a wake-up per frame.
pub const FLOOD_PACE: Duration = Duration::from_millis(2);

/// Margin before a deadline below which [`sleep_until_precise`] blocks instead of using tokio's
/// timer (whose granularity is 1 ms).
pub(crate) const PRECISE_MARGIN: Duration = Duration::from_micros(1500);

/// Sleeps until `deadline` with sub-millisecond precision: tokio's timer (1 ms granularity, it
/// rounds up) until [`PRECISE_MARGIN`] before the deadline, then a blocking `std::thread::sleep`
/// (a high-resolution timer) for the rest. It blocks the runtime thread for at most the margin, so
/// it suits single-task daemon loops whose other inputs queue in the kernel meanwhile (a
/// periodic loop faster than ~5 ms would otherwise be late by ~1 ms on every cycle).
pub(crate) async fn sleep_until_precise(deadline: Instant) {
    if let Some(coarse) = deadline.checked_sub(PRECISE_MARGIN) {
        if coarse > Instant::now() {
            tokio::time::sleep_until(coarse).await;
        }
    }
    let now = Instant::now();
    if deadline > now {
        std::thread::sleep(deadline - now);
    }
}

/// Timing statistics of a daemon loop: wake-up lateness percentiles and deadline misses.
#[derive(Debug, Clone, Default)]
pub struct LoopStats {
    pub cycles: u64,
    /// Wake-ups later than the miss threshold, plus skipped cycles.
    pub deadline_misses: u64,
    /// Cycles whose computation did not finish before the next deadline.
    pub overruns: u64,
    lateness: Micros,
}

/// Lateness above which a wake-up counts as a missed deadline, as a fraction of the period.
pub(crate) const MISS_FRACTION: f64 = 0.5;

impl LoopStats {
    /// Records one tick of a loop with the given period.
    pub fn record(&mut self, tick: &Tick, period: Duration) {
        self.cycles += 1;
        self.deadline_misses += tick.skipped;
        if tick.late_by.as_secs_f64() > MISS_FRACTION * period.as_secs_f64() {
            self.deadline_misses += 1;
        }
        self.lateness.record(tick.late_by);
    }

    /// Lateness percentile in microseconds (`q` in 0..=1).
    pub fn lateness_percentile_us(&self, q: f64) -> Option<f64> {
        self.lateness.percentile(q)
    }

    /// One line for logs and summaries.
    pub fn summary(&self) -> String {
        format!(
            "cycles {} deadline_misses {} overruns {} lateness p50 {:.0} us p99 {:.0} us max {:.0} us",
            self.cycles,
            self.deadline_misses,
            self.overruns,
            self.lateness_percentile_us(0.5).unwrap_or(0.0),
            self.lateness_percentile_us(0.99).unwrap_or(0.0),
            self.lateness_percentile_us(1.0).unwrap_or(0.0)
        )
    }
}

/// Durations in microseconds with their percentiles: an HDR histogram (the `hdrhistogram`
/// crate; 3 significant digits up to an hour), so memory stays constant however long a daemon
/// runs and no sample is dropped.
#[derive(Debug, Clone)]
pub(crate) struct Micros(hdrhistogram::Histogram<u64>);

impl Default for Micros {
    fn default() -> Self {
        Self(
            hdrhistogram::Histogram::new_with_bounds(1, 3_600_000_000, 3)
                .expect("constant bounds 1 us .. 1 h at 3 digits are valid"),
        )
    }
}

impl Micros {
    /// Records one duration (beyond an hour: an hour).
    pub fn record(&mut self, d: Duration) {
        let us = u64::try_from(d.as_micros()).unwrap_or(u64::MAX);
        self.0.saturating_record(us);
    }

    /// The `q` quantile (0..=1; 1 is the maximum) in microseconds; `None` with no sample.
    pub fn percentile(&self, q: f64) -> Option<f64> {
        if self.0.is_empty() {
            None
        } else if q >= 1.0 {
            Some(self.0.max() as f64)
        } else {
            Some(self.0.value_at_quantile(q.max(0.0)) as f64)
        }
    }
}

/// Wall-clock time since the Unix epoch, the timestamp base of candump logs.
pub fn wall_clock() -> Duration {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default()
}

/// Records every frame a daemon receives or sends into a candump -l log.
pub(crate) struct LogTap {
    writer: LogWriter<BufWriter<File>>,
    iface: String,
    frames: u64,
}

impl LogTap {
    pub fn create(path: &Path, iface: &str) -> io::Result<Self> {
        Ok(Self {
            writer: LogWriter::new(BufWriter::new(File::create(path)?)),
            iface: iface.to_string(),
            frames: 0,
        })
    }

    pub fn received(&mut self, rx: &Received) -> io::Result<()> {
        self.write(rx.frame, rx.timestamp)
    }

    pub fn sent(&mut self, frame: CanFrame, timestamp: Duration) -> io::Result<()> {
        self.write(frame, timestamp)
    }

    fn write(&mut self, frame: CanFrame, timestamp: Duration) -> io::Result<()> {
        self.frames += 1;
        self.writer
            .write_frame(timestamp, &self.iface, &frame, None)
    }

    pub fn frames(&self) -> u64 {
        self.frames
    }

    pub fn flush(&mut self) -> io::Result<()> {
        self.writer.flush()
    }
}

impl Drop for LogTap {
    fn drop(&mut self) {
        let _ = self.writer.flush();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deadlines_past_two_to_the_32_cycles_do_not_wrap() {
        let start = Instant::now();
        let mut p = Periodic::new(start, Duration::from_millis(10));
        p.next = 1 << 32;
        // 2³² cycles of 10 ms: 42 949 672.96 s (a `u32` cycle would wrap to 0).
        assert_eq!(p.next_deadline() - start, Duration::from_millis(10 << 32));
        assert_eq!(p.offset(u64::MAX), Duration::from_nanos(u64::MAX));
    }

    #[tokio::test(start_paused = true)]
    async fn deadlines_do_not_drift_and_overruns_are_counted() {
        let start = Instant::now();
        let mut p = Periodic::new(start, Duration::from_millis(10));
        let mut stats = LoopStats::default();
        for k in 0..5u64 {
            let t = p.tick().await;
            assert_eq!(t.cycle, k);
            assert_eq!(Instant::now() - start, Duration::from_millis(10 * k));
            stats.record(&t, p.period());
        }
        // A 35 ms stall: the 50 ms deadline is 25 ms late, 60 and 70 are skipped.
        tokio::time::advance(Duration::from_millis(35)).await;
        let t = p.tick().await;
        assert_eq!(
            (t.cycle, t.skipped, t.late_by),
            (5, 2, Duration::from_millis(25))
        );
        stats.record(&t, p.period());
        let t = p.tick().await;
        assert_eq!((t.cycle, t.deadline), (8, Duration::from_millis(80)));
        assert_eq!(stats.deadline_misses, 3);
    }

    #[test]
    fn percentiles() {
        let mut m = Micros::default();
        assert_eq!(m.percentile(0.5), None);
        for us in 1..=100 {
            m.record(Duration::from_micros(us));
        }
        assert_eq!(m.percentile(0.5), Some(50.0));
        assert_eq!(m.percentile(0.99), Some(99.0));
        assert_eq!(m.percentile(1.0), Some(100.0));
        // Three significant digits at any magnitude: 12 345 678 us within 0.1 %.
        let mut big = Micros::default();
        big.record(Duration::from_micros(12_345_678));
        let v = big.percentile(1.0).unwrap();
        assert!((v - 12_345_678.0).abs() <= 12_345.678, "{v}");
    }
}

/// Errors of a daemon's [`Link`].
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    #[error(transparent)]
    Bus(#[from] BusError),
    #[error("log {path}: {source}")]
    Log {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("{failures} consecutive send failures on {iface}")]
    Send {
        iface: String,
        failures: u64,
        /// The last failure.
        #[source]
        last: BusError,
    },
}

/// The bus side of a daemon: the bus, its candump tap and the frame counters. A refused send
/// (a full transmit queue on a busy bus) drops that frame and is counted; only a bus that refuses
/// `max_send_failures` frames in a row is fatal. Error frames and unsupported frames received are
/// counted, other receive errors are fatal.
pub struct Link<B: Bus> {
    pub bus: B,
    tap: Option<LogTap>,
    log_path: PathBuf,
    max_send_failures: u64,
    consecutive_send_errors: u64,
    pub sent: u64,
    pub send_errors: u64,
    pub received: u64,
    pub receive_errors: u64,
}

impl<B: Bus> Link<B> {
    /// Opens the link, creating the candump tap at `log` when given.
    pub fn open(bus: B, log: Option<&Path>, max_send_failures: u64) -> Result<Self, LinkError> {
        let tap = match log {
            Some(p) => Some(
                LogTap::create(p, bus.iface()).map_err(|source| LinkError::Log {
                    path: p.to_path_buf(),
                    source,
                })?,
            ),
            None => None,
        };
        Ok(Self {
            bus,
            tap,
            log_path: log.map(Path::to_path_buf).unwrap_or_default(),
            max_send_failures,
            consecutive_send_errors: 0,
            sent: 0,
            send_errors: 0,
            received: 0,
            receive_errors: 0,
        })
    }

    fn log_error(&self, source: io::Error) -> LinkError {
        LinkError::Log {
            path: self.log_path.clone(),
            source,
        }
    }

    /// Counts a received frame and records it with its (log) timestamp.
    pub fn received(&mut self, rx: &Received) -> Result<(), LinkError> {
        self.received += 1;
        match self.tap.as_mut().map(|tap| tap.received(rx)) {
            Some(Err(e)) => Err(self.log_error(e)),
            _ => Ok(()),
        }
    }

    /// Counts a receive error; Ok when the daemon goes on.
    pub fn receive_error(&mut self, e: BusError) -> Result<(), LinkError> {
        self.receive_errors += 1;
        if e.is_frame_level() {
            tracing::debug!("receive: {}", crate::error_chain::chain(&e));
            Ok(())
        } else {
            Err(e.into())
        }
    }

    /// Sends a frame and records it at `log_time`.
    pub async fn send(&mut self, frame: CanFrame, log_time: Duration) -> Result<(), LinkError> {
        match self.bus.send(frame).await {
            Ok(()) => {
                self.sent += 1;
                self.consecutive_send_errors = 0;
                match self.tap.as_mut().map(|tap| tap.sent(frame, log_time)) {
                    Some(Err(e)) => Err(self.log_error(e)),
                    _ => Ok(()),
                }
            }
            Err(e) => {
                self.send_errors += 1;
                self.consecutive_send_errors += 1;
                if self.consecutive_send_errors == 1 {
                    tracing::warn!("send {:03X}: {e}", frame.raw_id());
                } else {
                    tracing::debug!("send {:03X}: {e}", frame.raw_id());
                }
                if self.consecutive_send_errors >= self.max_send_failures {
                    return Err(LinkError::Send {
                        iface: self.bus.iface().to_string(),
                        failures: self.consecutive_send_errors,
                        last: e,
                    });
                }
                Ok(())
            }
        }
    }

    /// Writes the tap's buffered frames to its file.
    pub fn flush(&mut self) -> Result<(), LinkError> {
        match self.tap.as_mut().map(LogTap::flush) {
            Some(Err(e)) => Err(self.log_error(e)),
            _ => Ok(()),
        }
    }

    /// Flushes the tap; the number of frames it recorded (None without a tap).
    pub fn finish(&mut self) -> Result<Option<u64>, LinkError> {
        self.flush()?;
        Ok(self.tap.as_ref().map(LogTap::frames))
    }
}

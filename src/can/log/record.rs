//! `ddct log record`'s loop: every frame a bus receives written to a candump `-l` log until a
//! count, a duration or a stop signal, with the frames per id ([`record`]). The caller opens the
//! socket (and sizes its receive queue) and the file.

use crate::can::candump::LogWriter;
use crate::can::socketcan::MMSG_BATCH;
use crate::can::{Bus, BusError};
use std::collections::BTreeMap;
use std::future::Future;
use std::io::Write;
use std::time::{Duration, Instant};
use thiserror::Error;

/// After a wake-up the recorder reads everything queued (in `recvmmsg` batches) and then waits
/// this long before it looks again: it needs no latency (every frame carries its kernel
/// timestamp, and the queue holds minutes), and a wake-up per frame of a flood took the CPU the
/// daemons under test need (User-Mode Linux: tens of µs per system call, one CPU).
const RECORD_PACE: Duration = Duration::from_millis(5);

/// Frames read per recorder wake-up at most (the rest on the next one).
const RECORD_BATCH: usize = 1024;

/// How often the log is flushed while frames come.
const FLUSH_EVERY: Duration = Duration::from_millis(200);

/// What a recording wrote.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Recording {
    pub frames: u64,
    /// Frames by raw id.
    pub per_id: BTreeMap<u32, u64>,
}

/// Why a recording stopped early.
#[derive(Debug, Error)]
pub enum RecordError {
    #[error(transparent)]
    Bus(#[from] BusError),
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

/// Records every frame of `bus` (named `iface` in the log) into `writer` until `count` frames,
/// `duration`, or `stop` completes, flushing the log every 200 ms.
pub async fn record<B: Bus, W: Write>(
    bus: &mut B,
    iface: &str,
    writer: &mut LogWriter<W>,
    count: Option<u64>,
    duration: Option<Duration>,
    stop: impl Future<Output = ()>,
) -> Result<Recording, RecordError> {
    let deadline = duration.map(|d| tokio::time::Instant::now() + d);
    tokio::pin!(stop);
    let mut rec = Recording::default();
    let mut last_flush = Instant::now();
    let mut batch = Vec::with_capacity(RECORD_BATCH);
    loop {
        if count.is_some_and(|c| rec.frames >= c) {
            break;
        }
        let until_deadline = async {
            match deadline {
                Some(d) => tokio::time::sleep_until(d).await,
                None => std::future::pending().await,
            }
        };
        let flush_tick = tokio::time::sleep(FLUSH_EVERY);
        tokio::select! {
            rx = bus.recv() => {
                batch.push(rx);
                while !bus.try_recv_many(MMSG_BATCH, &mut batch) && batch.len() < RECORD_BATCH {}
                for rx in batch.drain(..) {
                    if count.is_some_and(|c| rec.frames >= c) {
                        break;
                    }
                    let rx = rx?;
                    writer.write_frame(rx.timestamp, iface, &rx.frame, None)?;
                    rec.frames += 1;
                    *rec.per_id.entry(rx.frame.raw_id()).or_default() += 1;
                }
                if last_flush.elapsed() > FLUSH_EVERY {
                    writer.flush()?;
                    last_flush = Instant::now();
                }
                tokio::time::sleep(RECORD_PACE).await;
            }
            _ = flush_tick => { writer.flush()?; last_flush = Instant::now(); }
            _ = until_deadline => break,
            _ = &mut stop => break,
        }
    }
    writer.flush()?;
    Ok(rec)
}

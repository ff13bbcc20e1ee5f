//! When `ddct log replay` sends each frame of a log: the log's own timing, relative to its first
//! frame, repeated for `--loop` passes ([`schedule`], pure), and the sending itself at that
//! timing scaled by a speed, or as fast as the bus takes the frames ([`play`]).

use super::candump::LogRecord;
use super::{Bus, BusError};
use std::time::Duration;

/// How a replay spaces the frames.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pace {
    /// The log's own timing, `speed` times faster.
    Log { speed: f64 },
    /// As fast as the interface takes them, at least `interval_us` apart.
    MaxRate { interval_us: u64 },
}

/// Sends the frames of `records` on `bus`, `passes` times over, spaced as `pace` says (tokio's
/// clock, from the call); `sent` after each frame. The number of frames sent.
pub async fn play<B: Bus>(
    bus: &mut B,
    records: &[LogRecord],
    pace: Pace,
    passes: u32,
    mut sent: impl FnMut(),
) -> Result<usize, BusError> {
    let stamps: Vec<Duration> = records.iter().map(|r| r.timestamp).collect();
    let start = tokio::time::Instant::now();
    let mut next = start;
    let mut n = 0usize;
    let frames = records.iter().cycle().take(records.len() * passes as usize);
    for (r, at) in frames.zip(schedule(&stamps, passes)) {
        match pace {
            Pace::Log { speed } => {
                tokio::time::sleep_until(start + at.div_f64(speed)).await;
            }
            Pace::MaxRate { interval_us } if interval_us > 0 => {
                tokio::time::sleep_until(next).await;
                next += Duration::from_micros(interval_us);
            }
            Pace::MaxRate { .. } => {}
        }
        bus.send(r.frame).await?;
        n += 1;
        sent();
    }
    Ok(n)
}

/// The send offsets (from the start of the replay, at speed 1) of `passes` passes over frames
/// stamped `stamps`: each pass starts one median frame interval after the last frame of the one
/// before, so a looped cyclic log keeps its cycle across the seam. Stamps that go backwards are
/// sent at once (offsets never decrease within a pass).
pub fn schedule(stamps: &[Duration], passes: u32) -> impl Iterator<Item = Duration> + '_ {
    let t0 = stamps.first().copied().unwrap_or_default();
    let mut latest = Duration::ZERO;
    let rel: Vec<Duration> = stamps
        .iter()
        .map(|t| {
            latest = latest.max(t.saturating_sub(t0));
            latest
        })
        .collect();
    let mut gaps: Vec<Duration> = rel.windows(2).map(|w| w[1] - w[0]).collect();
    gaps.sort_unstable();
    let step = gaps.get(gaps.len() / 2).copied().unwrap_or_default();
    let period = rel.last().copied().unwrap_or_default() + step;
    (0..passes).flat_map(move |p| {
        let base = period * p;
        rel.clone().into_iter().map(move |r| base + r)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: &[u64]) -> Vec<Duration> {
        v.iter().map(|&m| Duration::from_millis(m)).collect()
    }

    #[test]
    fn one_pass_keeps_the_log_timing_from_its_first_frame() {
        let s = ms(&[1000, 1010, 1030]);
        assert_eq!(schedule(&s, 1).collect::<Vec<_>>(), ms(&[0, 10, 30]));
    }

    #[test]
    fn passes_follow_each_other_one_median_interval_apart() {
        // Intervals 10, 10, 50: median 10, so the second pass starts at 70 + 10.
        let s = ms(&[0, 10, 20, 70]);
        assert_eq!(
            schedule(&s, 2).collect::<Vec<_>>(),
            ms(&[0, 10, 20, 70, 80, 90, 100, 150])
        );
    }

    #[test]
    fn backwards_stamps_and_empty_logs_send_at_once() {
        let s = ms(&[100, 90, 120]);
        assert_eq!(schedule(&s, 1).collect::<Vec<_>>(), ms(&[0, 0, 20]));
        assert_eq!(schedule(&[], 3).count(), 0);
    }
}

//! When `ddct log replay` sends each frame of a log: the log's own timing, relative to its first
//! frame, repeated for `--loop` passes. Pure: the shell scales by `--speed` and sleeps.

use std::time::Duration;

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

//! Spikes: samples far from the median of their ±2 neighbours (the two samples at each end of
//! the record, without a full window, are not judged). The running median follows a
//! step or a ramp of the signal exactly, so only departures of one or two samples remain; they
//! are spikes when above twelve robust standard deviations of those departures (1.4826 × their
//! median absolute value, at least the grid's q/√12 on a quantised channel, where most
//! departures are exactly zero) and above 5 % of the channel's range (1st to 99th percentile), so that
//! neither noise nor the quantisation of a quiet channel counts.

/// Robust standard deviations a spike must exceed.
const K: f64 = 12.0;
/// Share of the channel's range a spike must exceed.
const MIN_RANGE_SHARE: f64 = 0.05;
/// Largest share of the samples still "rare" spikes (more is another problem: noise).
const MAX_SHARE: f64 = 0.02;

/// The spikes of a channel.
#[derive(Debug, Clone, PartialEq)]
pub struct Spikes {
    pub count: usize,
    /// Share of the samples.
    pub share: f64,
    /// The largest departure from the local median (the channel's unit).
    pub largest: f64,
}

/// The spike samples of `v` (ascending) and their summary, if any; `grid` is the step of the
/// channel's readings when they lie on one ([`super::quantised::grid_step`]).
pub fn detect(v: &[f64], grid: Option<f64>) -> Option<(Vec<usize>, Spikes)> {
    let (at, dev) = located(v, grid)?;
    let count = at.len();
    let summary = Spikes {
        count,
        share: count as f64 / v.len() as f64,
        largest: at.iter().fold(0.0, |a: f64, &k| a.max(dev[k].abs())),
    };
    Some((at, summary))
}

/// The spike samples of `v` and every sample's departure from its local median.
fn located(v: &[f64], grid: Option<f64>) -> Option<(Vec<usize>, Vec<f64>)> {
    let n = v.len();
    if n < 20 {
        return None;
    }
    // Full windows only: at the record's ends a shortened window's median is no reference.
    let dev: Vec<f64> = (0..n)
        .map(|k| {
            if k < 2 || k + 2 >= n {
                return 0.0;
            }
            let mut w = [0.0; 5];
            let mut m = 0;
            for x in &v[k - 2..k + 3] {
                if x.is_finite() {
                    w[m] = *x;
                    m += 1;
                }
            }
            w[..m].sort_by(f64::total_cmp);
            if m == 0 || !v[k].is_finite() {
                0.0
            } else {
                v[k] - w[m / 2]
            }
        })
        .collect();
    let mut abs: Vec<f64> = dev.iter().map(|d| d.abs()).collect();
    abs.sort_by(f64::total_cmp);
    // Never below the grid's own error: on a coarse grid most departures are exactly zero.
    let scale = (1.4826 * abs[n / 2]).max(grid.map_or(0.0, |q| q / 12f64.sqrt()));
    let mut sorted: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    sorted.sort_by(f64::total_cmp);
    if sorted.is_empty() {
        return None;
    }
    let q = |p: f64| sorted[((sorted.len() - 1) as f64 * p).round() as usize];
    let limit = (K * scale).max(MIN_RANGE_SHARE * (q(0.99) - q(0.01)));
    if limit <= 0.0 {
        return None;
    }
    let at: Vec<usize> = (0..n).filter(|&k| dev[k].abs() > limit).collect();
    let share = at.len() as f64 / n as f64;
    (!at.is_empty() && share <= MAX_SHARE).then_some((at, dev))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn find(v: &[f64]) -> Option<Spikes> {
        detect(v, super::super::quantised::grid_step(v)).map(|(_, s)| s)
    }

    fn samples(v: &[f64]) -> Vec<usize> {
        detect(v, super::super::quantised::grid_step(v)).map_or_else(Vec::new, |(at, _)| at)
    }

    fn noisy(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = crate::gap::fit::stats::Rng::new(seed);
        (0..n)
            .map(|k| {
                // Engagements: torque steps of 150 N·m every 500 samples, with 0.3 N·m noise.
                let on = (k / 250) % 2 == 1;
                (if on { 150.0 } else { 0.0 }) + 0.3 * rng.normal()
            })
            .collect()
    }

    #[test]
    fn rare_large_spikes_are_counted_and_steps_and_noise_are_not() {
        assert_eq!(find(&noisy(10_000, 1)), None);
        let mut v = noisy(10_000, 2);
        for k in [1234, 5678, 9000] {
            v[k] += 400.0;
        }
        let found = find(&v).expect("spikes");
        assert_eq!(found.count, 3);
        assert_eq!(samples(&v), vec![1234, 5678, 9000]);
        assert!((found.largest - 400.0).abs() < 5.0, "{found:?}");
    }

    #[test]
    fn two_steps_of_a_coarse_grid_are_not_a_spike_and_ten_are() {
        // A thermocouple rising 30 °C on a 1 °C grid: nearly every departure from the local
        // median is exactly zero; a fast rise puts a reading two steps off now and then.
        let mut v: Vec<f64> = (0..6_000).map(|k| (k as f64 * 0.005).round()).collect();
        for k in [1_000, 3_000, 5_000] {
            v[k] += 2.0;
        }
        assert_eq!(find(&v), None);
        v[4_000] += 10.0;
        assert_eq!(samples(&v), vec![4_000]);
    }
}

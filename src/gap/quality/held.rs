//! Sample-and-hold: a channel sampled slower than the record and held in between shows runs of
//! exactly equal values of one length (the ratio of the rates) — or a multiple of it where the
//! slow source repeated itself. A slowly varying quantised signal also repeats values, but in
//! runs of every length.

/// Runs needed before a held rate is claimed.
const MIN_RUNS: usize = 10;
/// Share of the samples that must lie in runs of a multiple (±1) of the common length.
const MIN_SHARE: f64 = 0.8;

/// The number of samples each value of `v` is held for, when `v` is held (at least 2), else
/// `None`. The first and last runs (cut by the record's ends) are not counted.
pub fn every(v: &[f64]) -> Option<usize> {
    let runs = runs(v);
    if runs.len() < MIN_RUNS + 2 {
        return None;
    }
    let inner = &runs[1..runs.len() - 1];
    let mut counts = std::collections::BTreeMap::new();
    for &r in inner {
        *counts.entry(r).or_insert(0usize) += 1;
    }
    // The most common run length (the shortest among equals).
    let (&every, _) = counts
        .iter()
        .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(a.0)))?;
    if every < 2 {
        return None;
    }
    let fits = |r: usize| {
        let m = ((r as f64) / every as f64).round().max(1.0) as usize;
        r.abs_diff(m * every) <= 1
    };
    let total: usize = inner.iter().sum();
    let held: usize = inner.iter().filter(|r| fits(**r)).sum();
    (held as f64 >= MIN_SHARE * total as f64).then_some(every)
}

/// The lengths of the runs of exactly equal consecutive values of `v`.
fn runs(v: &[f64]) -> Vec<usize> {
    let mut out = Vec::new();
    let mut len = 0;
    for (k, x) in v.iter().enumerate() {
        if k > 0 && x.to_bits() == v[k - 1].to_bits() {
            len += 1;
        } else {
            if len > 0 {
                out.push(len);
            }
            len = 1;
        }
    }
    if len > 0 {
        out.push(len);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sine with noise, sampled every `every` samples and held (`every` = 1: not held).
    fn series(n: usize, every: usize, seed: u64) -> Vec<f64> {
        let mut rng = crate::gap::fit::stats::Rng::new(seed);
        let mut out = Vec::with_capacity(n);
        let mut held = 0.0;
        for k in 0..n {
            if k % every == 0 {
                held = 20.0 + 5.0 * (k as f64 * 0.001).sin() + 0.3 * rng.normal();
            }
            out.push(held);
        }
        out
    }

    #[test]
    fn a_held_channel_gives_its_rate_and_a_live_one_none() {
        assert_eq!(every(&series(20_000, 100, 1)), Some(100));
        assert_eq!(every(&series(20_000, 10, 2)), Some(10));
        assert_eq!(every(&series(20_000, 1, 3)), None);
    }

    #[test]
    fn a_slow_quantised_signal_is_not_called_held() {
        // A 0.1 °C quantisation of a slow drift without noise repeats values in runs of many
        // lengths.
        let v: Vec<f64> = (0..20_000)
            .map(|k| ((20.0 + 3.0 * (k as f64 * 3e-4).sin()) * 10.0).round() / 10.0)
            .collect();
        assert_eq!(every(&v), None);
    }
}

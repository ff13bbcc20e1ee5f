//! Dropouts: runs of exact zeros inside a channel that reads well away from zero on both sides
//! of the run (a lost message the logger filled with zeros). Neighbours must be beyond 5 % of
//! the channel's range (1st to 99th percentile) and beyond twelve robust noise deviations (from
//! the median absolute first difference) from zero, so that a reading that crosses zero or a
//! quiet channel's noise about zero (a braked shaft's speed) is not a dropout, and the run must
//! be short (at most [`MAX_SECONDS`]: an open clutch between
//! two engagements reads zero for longer); runs cut by the record's ends are not judged.

/// Share of the channel's range a neighbour of the run must be away from zero.
const MIN_RANGE_SHARE: f64 = 0.05;
/// Robust noise deviations a neighbour of the run must be away from zero.
const K: f64 = 12.0;

/// Longest run of zeros that is a dropout (s).
pub const MAX_SECONDS: f64 = 0.25;

/// Longest run of zeros that is a dropout, in samples of a record at `dt` seconds.
pub fn max_len(dt: f64) -> usize {
    (MAX_SECONDS / dt).round().max(1.0) as usize
}

/// The dropout runs of `v` (at most `max_len` samples each): `(first sample, length)`, in order.
pub fn runs(v: &[f64], max_len: usize) -> Vec<(usize, usize)> {
    let mut sorted: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if sorted.len() < 20 {
        return Vec::new();
    }
    sorted.sort_by(f64::total_cmp);
    let q = |p: f64| sorted[((sorted.len() - 1) as f64 * p).round() as usize];
    let limit = (MIN_RANGE_SHARE * (q(0.99) - q(0.01))).max(K * noise(v));
    if limit <= 0.0 {
        return Vec::new();
    }
    let mut out = Vec::new();
    let mut k = 1;
    while k < v.len() {
        if v[k] != 0.0 {
            k += 1;
            continue;
        }
        let start = k;
        while k < v.len() && v[k] == 0.0 {
            k += 1;
        }
        let inside = k < v.len();
        let short = k - start <= max_len;
        if inside && short && v[start - 1].abs() > limit && v[k].abs() > limit {
            out.push((start, k - start));
        }
    }
    out
}

/// Robust standard deviation of `v`'s noise: 1.4826 × the median absolute first difference,
/// over √2.
fn noise(v: &[f64]) -> f64 {
    let mut d: Vec<f64> = v
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| d.is_finite())
        .collect();
    if d.is_empty() {
        return 0.0;
    }
    let mid = d.len() / 2;
    let (_, m, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
    1.4826 * *m / std::f64::consts::SQRT_2
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_runs_inside_a_live_level_are_dropouts_and_an_idle_zero_is_not() {
        // Engagements at 150 N·m every 500 samples; the open clutch reads exact zeros.
        let mut v: Vec<f64> = (0..5_000)
            .map(|k| {
                if (k / 250) % 2 == 1 {
                    150.0 + (k % 7) as f64 * 0.1
                } else {
                    0.0
                }
            })
            .collect();
        assert_eq!(runs(&v, 50), vec![]);
        v[300..308].fill(0.0);
        v[2_760..2_761].fill(0.0);
        assert_eq!(runs(&v, 50), vec![(300, 8), (2_760, 1)]);
        // A braked shaft's speed: noise about zero, exact zeros among readings of ±0.1.
        let quiet: Vec<f64> = (0..5_000)
            .map(|k| [0.0, 0.1, 0.0, -0.1, 0.1][k % 5])
            .collect();
        assert_eq!(runs(&quiet, 50), vec![]);
    }
}

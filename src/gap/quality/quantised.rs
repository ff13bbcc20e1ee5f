//! Quantisation: every reading of the channel on one grid `v0 + k·q`. Every bus signal is on
//! the grid of its DBC factor; the finding is a logger's grid coarser than that (above 1.5 ×
//! the factor) and so coarse against the channel's noise that the reading mostly sits still
//! (more than half of the consecutive readings equal, on a channel that is not held): the noise
//! is hidden, and a floor estimated from consecutive differences would collapse. The grid step also bounds every floor of the channel from below (q/√12).

/// Finite samples needed to claim a grid.
const MIN_SAMPLES: usize = 100;
/// Share of consecutive readings that must be equal for the grid to be coarse.
const MIN_REPEATED: f64 = 0.5;
/// How much coarser than the bus's resolution a logger's grid must be.
const MIN_COARSER: f64 = 1.5;

/// The grid step of `v`: the smallest spacing of its distinct values, when every distinct value
/// lies on that grid (to 10⁻⁶ of a step); `None` for a channel with fewer than two values or off
/// any grid.
pub fn grid_step(v: &[f64]) -> Option<f64> {
    let mut u: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if u.len() < MIN_SAMPLES {
        return None;
    }
    u.sort_by(f64::total_cmp);
    u.dedup();
    let q = u
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(f64::INFINITY, f64::min);
    if !(q.is_finite() && q > 0.0) {
        return None;
    }
    let tol = 1e-6 * q + 4.0 * f64::EPSILON * u[0].abs().max(u[u.len() - 1].abs());
    let on_grid = u.iter().all(|x| {
        let k = (x - u[0]) / q;
        ((k - k.round()) * q).abs() <= tol
    });
    on_grid.then_some(q)
}

/// Share of consecutive finite readings of `v` that are equal.
pub fn repeated(v: &[f64]) -> f64 {
    let pairs: Vec<bool> = v
        .windows(2)
        .filter(|w| w[0].is_finite() && w[1].is_finite())
        .map(|w| w[0].to_bits() == w[1].to_bits())
        .collect();
    pairs.iter().filter(|&&e| e).count() as f64 / pairs.len().max(1) as f64
}

/// `(step, share of repeated readings)` when `v`, on a grid of `grid` ([`grid_step`]) and
/// carried by the bus at `resolution`, is coarsely quantised.
pub fn coarse(v: &[f64], grid: Option<f64>, resolution: f64) -> Option<(f64, f64)> {
    let q = grid?;
    let r = repeated(v);
    (q > MIN_COARSER * resolution && r > MIN_REPEATED).then_some((q, r))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp_with_noise(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = crate::gap::fit::stats::Rng::new(seed);
        (0..n)
            .map(|k| 60.0 + 0.002 * k as f64 + 0.15 * rng.normal())
            .collect()
    }

    #[test]
    fn a_coarse_grid_is_found_and_a_fine_one_or_none_is_not_coarse() {
        let v = ramp_with_noise(5_000, 1);
        assert_eq!(grid_step(&v), None);
        assert_eq!(coarse(&v, grid_step(&v), 0.1), None);
        // The DBC's 0.1 °C: on a grid, but the noise still moves the reading.
        let fine: Vec<f64> = v.iter().map(|x| (x * 10.0).round() / 10.0).collect();
        let q = grid_step(&fine).expect("grid");
        assert!((q - 0.1).abs() < 1e-9, "{q}");
        assert_eq!(
            coarse(&fine, grid_step(&fine), 0.1),
            None,
            "repeated {}",
            repeated(&fine)
        );
        // A 1 °C logger channel: the reading sits still.
        let coarse_v: Vec<f64> = v.iter().map(|x| x.round()).collect();
        let (q, r) = coarse(&coarse_v, grid_step(&coarse_v), 0.1).expect("coarse");
        // The same grid as the bus's own resolution is not the logger's doing.
        assert_eq!(coarse(&coarse_v, grid_step(&coarse_v), 1.0), None);
        assert!((q - 1.0).abs() < 1e-9 && r > 0.5, "{q} {r}");
    }
}

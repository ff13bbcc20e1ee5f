//! Model-free operations on a record's measured series: the friction energy by the trapezoid
//! rule (the E of the energy-driven effects), a smoothed derivative, the mean of a series over a
//! replay step as the step's inputs (16) take it, and the sliding acceleration of a friction term
//! of that variable. Pure functions of the samples; no model parameter.

/// Friction energy dissipated up to each sample (J), from `e0` at the first, by the trapezoid
/// rule over the friction power `power` (W) sampled every `dt` s.
pub fn cumulative_energy<C: FromIterator<f64>>(power: &[f64], e0: f64, dt: f64) -> C {
    let mut e = e0;
    let steps = power.windows(2).map(move |w| {
        e += 0.5 * (w[0] + w[1]) * dt;
        e
    });
    std::iter::once(e0).chain(steps).take(power.len()).collect()
}

/// Smoothed derivative by a centred difference over ±`half` samples.
pub fn derivative(v: &[f64], dt: f64, half: usize) -> Vec<f64> {
    let n = v.len();
    (0..n)
        .map(|k| {
            let a = k.saturating_sub(half);
            let b = (k + half).min(n.saturating_sub(1));
            if b > a {
                (v[b] - v[a]) / ((b - a) as f64 * dt)
            } else {
                0.0
            }
        })
        .collect()
}

/// The mean of `v` over the step from sample `k0` to `k1` by the energy it delivers: the mean of
/// the per-sample midpoints (trapezoid rule), as [`thermal_replay_every`] averages its inputs.
#[inline]
pub fn window_mean(v: &[f64], k0: usize, k1: usize) -> f64 {
    let len = (k1 - k0) as f64;
    (v[k0] + 2.0 * v[k0 + 1..k1].iter().sum::<f64>() + v[k1]) / (2.0 * len)
}

/// Sliding acceleration d|ω_fc|/dt (rad/s²) by a centred difference over ±2 samples.
pub fn slide_acceleration(slip: &[f64], dt: f64) -> Vec<f64> {
    let a: Vec<f64> = slip.iter().map(|w| w.abs()).collect();
    derivative(&a, dt, 2)
}

//! Slow drift of a thermocouple (a cold junction warming, a sensor ageing): a random walk added
//! to the reading, unrelated to what the clutch does. Seen only against the model: the residual
//! of the channel (measured − predicted), averaged over blocks of [`BLOCK_S`], wanders; a model
//! gap of (16) wanders too, but its steps follow the physics — the heat the model moves (the
//! steps of the predicted plate and disk temperatures) and the heat it lets out (their excess
//! over the housing at the step's start) — while a drift's steps follow none of them. The
//! statistic is the share of the variance of the residual's block-to-block steps those explain
//! (R² of a least-squares fit with an intercept). Chance alone gives R² ≈ k/(n − 1) for k
//! variables and n steps (0.21 ± 0.10 for six variables over a 300 s record): a residual that
//! wanders by more than [`MIN_WANDER`] noise floors with R² below [`MAX_R2`] is a drift; with R²
//! above it, a gap of the model. On the independent generator's conduction-sign truth the
//! central disk's residual (a 9–29 °C wander) has R² 0.98–0.996; on drifting thermocouples
//! (1–2 °C) 0.12–0.35.

/// Block length over which the residual and the prediction are averaged (s).
pub const BLOCK_S: f64 = 10.0;

/// One block of a channel: the mean residual and the mean of each physics variable (the
/// predicted temperatures and their excess over the housing).
#[derive(Debug, Clone)]
pub struct Block {
    pub r: f64,
    pub x: Vec<f64>,
}

/// The block means of `(time, residual, physics variables)` samples (time ascending).
pub fn blocks(samples: impl IntoIterator<Item = (f64, f64, Vec<f64>)>) -> Vec<Block> {
    let mut out = Vec::new();
    let mut acc: Option<(f64, Vec<f64>, usize, f64)> = None;
    for (t, r, x) in samples {
        if let Some((sr, sx, n, t0)) = &acc {
            if t - t0 >= BLOCK_S {
                let n = *n as f64;
                out.push(Block {
                    r: sr / n,
                    x: sx.iter().map(|v| v / n).collect(),
                });
                acc = None;
            }
        }
        let a = acc.get_or_insert_with(|| (0.0, vec![0.0; x.len()], 0, t));
        a.0 += r;
        for (s, v) in a.1.iter_mut().zip(&x) {
            *s += v;
        }
        a.2 += 1;
    }
    out
}

/// `(R², wander)` of a channel's blocks: the share of the variance of the residual's steps the
/// physics explains (the steps of the variables and their levels at the step's start), and the
/// range of the block residuals (the channel's unit). `None` with too few steps.
pub fn statistic(b: &[Block]) -> Option<(f64, f64)> {
    let k = b.first()?.x.len() * 2;
    if b.len() < 3 * k + 3 {
        return None;
    }
    let rows: Vec<(f64, Vec<f64>)> = b
        .windows(2)
        .map(|w| {
            let mut x: Vec<f64> = w[1].x.iter().zip(&w[0].x).map(|(a, b)| a - b).collect();
            x.extend(w[0].x.iter().copied());
            (w[1].r - w[0].r, x)
        })
        .collect();
    let r2 = r_squared(&rows);
    let (lo, hi) = b
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(x.r), hi.max(x.r))
        });
    Some((r2, hi - lo))
}

/// R² of the least-squares fit of `y` on `x` and an intercept (normal equations on centred
/// data, solved by Gaussian elimination with partial pivoting; a singular column adds nothing).
fn r_squared(rows: &[(f64, Vec<f64>)]) -> f64 {
    let n = rows.len() as f64;
    let k = rows[0].1.len();
    let my = rows.iter().map(|r| r.0).sum::<f64>() / n;
    let mx: Vec<f64> = (0..k)
        .map(|i| rows.iter().map(|r| r.1[i]).sum::<f64>() / n)
        .collect();
    let mut a = vec![vec![0.0; k + 1]; k];
    let mut syy = 0.0;
    for (y, x) in rows {
        let y = y - my;
        syy += y * y;
        for i in 0..k {
            let xi = x[i] - mx[i];
            for j in 0..k {
                a[i][j] += xi * (x[j] - mx[j]);
            }
            a[i][k] += xi * y;
        }
    }
    if syy <= 0.0 {
        return 0.0;
    }
    let rhs: Vec<f64> = a.iter().map(|r| r[k]).collect();
    for c in 0..k {
        let p = (c..k)
            .max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))
            .unwrap_or(c);
        a.swap(c, p);
        if a[c][c].abs() < 1e-12 * (1.0 + a[c][k].abs()) {
            continue;
        }
        let pivot = a[c].clone();
        for (i, row) in a.iter_mut().enumerate() {
            if i != c {
                let f = row[c] / pivot[c];
                for (x, p) in row[c..].iter_mut().zip(&pivot[c..]) {
                    *x -= f * p;
                }
            }
        }
    }
    let explained: f64 = (0..k)
        .filter(|&i| a[i][i].abs() > 0.0)
        .map(|i| a[i][k] / a[i][i] * rhs[i])
        .sum();
    (explained / syy).clamp(0.0, 1.0)
}

/// A residual must wander by this many noise floors to be judged.
pub const MIN_WANDER: f64 = 2.0;
/// Largest R² of a drift.
pub const MAX_R2: f64 = 0.6;

/// What a channel's wandering residual is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Wander {
    /// Within the noise, or too short to judge.
    Quiet,
    /// A drift of the sensor: the range of the block residuals, and the R² of the physics.
    Drift { wander: f64, r2: f64 },
    /// A gap of the model: the physics explains the residual's steps.
    Physics,
}

/// Judges a channel's blocks against its noise floor `sigma`.
pub fn judge(b: &[Block], sigma: f64) -> Wander {
    match statistic(b) {
        Some((_, wander)) if wander <= MIN_WANDER * sigma => Wander::Quiet,
        Some((r2, wander)) if r2 < MAX_R2 => Wander::Drift { wander, r2 },
        Some(_) => Wander::Physics,
        None => Wander::Quiet,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_the_physics_makes_are_explained_and_a_random_walk_is_not() {
        let mut rng = crate::gap::fit::stats::Rng::new(5);
        // A heating-and-cooling prediction over 60 blocks.
        let y: Vec<f64> = (0..60)
            .map(|j| 40.0 * (1.0 + (j as f64 / 6.0).sin()))
            .collect();
        let x = |j: usize| vec![y[j] - 25.0];
        // A model gap: the residual steps by 2 % of the predicted step and cools with the excess.
        let mut r = 0.0;
        let gap: Vec<Block> = (0..60)
            .map(|j| {
                if j > 0 {
                    r += 0.02 * (y[j] - y[j - 1]) - 0.004 * (y[j - 1] - 25.0) + 0.01 * rng.normal();
                }
                Block { r, x: x(j) }
            })
            .collect();
        assert_eq!(judge(&gap, 0.1), Wander::Physics, "{:?}", statistic(&gap));
        let mut w = 0.0;
        let walk: Vec<Block> = (0..60)
            .map(|j| {
                w += 0.3 * rng.normal();
                Block { r: w, x: x(j) }
            })
            .collect();
        assert!(
            matches!(judge(&walk, 0.1), Wander::Drift { .. }),
            "{:?}",
            statistic(&walk)
        );
        let quiet: Vec<Block> = (0..60)
            .map(|j| Block {
                r: 0.01 * rng.normal(),
                x: x(j),
            })
            .collect();
        assert_eq!(judge(&quiet, 0.1), Wander::Quiet);
    }
}
